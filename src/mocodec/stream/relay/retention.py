"""What the relay keeps of each stream: the packets a late viewer catches up from (those since
the stream's last restart point) and those a viewer may ask for again (the last
REPAIR_PACKETS), capped in bytes per stream and per room (docs/security.md). A stream whose
restart point fell out of the cap is *partial*: a late viewer starts it live.

Packets carry ordinals (their place in the stream): a viewer catching up holds an ordinal, not
the packets, so what it waits for costs the relay nothing beyond what the room keeps."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from itertools import islice
from typing import Any

#: The packets of each stream the relay keeps to resend on a viewer's request (a second at 60 a second).
REPAIR_PACKETS = 64


@dataclass(frozen=True)
class Caps:
    stream_bytes: int  # kept per stream
    room_bytes: int  # kept per room, the oldest packets (any stream's) going first
    stream_packets: int  # kept per stream


class RoomHistory:
    """The room's kept bytes and its packets in arrival order (``(stream history, ordinal)``),
    so that the room's cap drops the oldest packets first, whichever stream they belong to.
    Entries of packets a stream dropped itself stay until they reach the front or the queue is
    compacted (at twice the packets kept), so each packet costs O(1)."""

    def __init__(self, caps: Caps):
        self.caps = caps
        self.bytes = 0
        self.packets = 0
        self.arrivals: deque[tuple[StreamHistory, int]] = deque()

    def stream(self) -> StreamHistory:
        return StreamHistory(self)

    def _added(self, history: StreamHistory, ordinal: int, size: int) -> None:
        self.bytes += size
        self.packets += 1
        self.arrivals.append((history, ordinal))
        while self.bytes > self.caps.room_bytes and self.arrivals:
            owner, at = self.arrivals.popleft()
            if owner.holds(at):
                owner.drop_oldest()
        if len(self.arrivals) > 2 * self.packets + 64:
            self.arrivals = deque(entry for entry in self.arrivals if entry[0].holds(entry[1]))


class StreamHistory:
    """One stream's kept packets (:class:`~mocodec.stream.relay.rooms.Forward`), oldest first."""

    def __init__(self, room: RoomHistory):
        self.room = room
        self.kept: deque[Any] = deque()
        self.bytes = 0
        self.first = 0  # the ordinal of kept[0]
        self.restart = 0  # the ordinal of the last restart point (0: the stream's start)
        self.closed = False

    @property
    def end(self) -> int:
        """The ordinal the next packet will have."""
        return self.first + len(self.kept)

    @property
    def partial(self) -> bool:
        """Whether the last restart point is no longer kept (a late viewer cannot start there)."""
        return self.restart < self.first

    def holds(self, ordinal: int) -> bool:
        return not self.closed and self.first <= ordinal < self.end

    def add(self, forward: Any, restart: bool) -> None:
        """Keep a packet; drop what neither a late viewer nor a repair needs, then the oldest
        past the caps (the newest packet stays, unless the room's cap takes it)."""
        ordinal, size, caps = self.end, len(forward.data), self.room.caps
        if restart:
            self.restart = ordinal
        self.kept.append(forward)
        self.bytes += size
        needed = min(self.restart, ordinal + 1 - REPAIR_PACKETS)
        while len(self.kept) > 1 and (
            self.first < needed or len(self.kept) > caps.stream_packets or self.bytes > caps.stream_bytes
        ):
            self.drop_oldest()
        self.room._added(self, ordinal, size)

    def drop_oldest(self) -> None:
        size = len(self.kept.popleft().data)
        self.first += 1
        self.bytes -= size
        self.room.bytes -= size
        self.room.packets -= 1

    def close(self) -> None:
        """The stream is over: its packets leave the room's count."""
        if not self.closed:
            self.room.bytes -= self.bytes
            self.room.packets -= len(self.kept)
            self.kept.clear()
            self.closed = True

    def since(self, ordinal: int, budget: float) -> tuple[list[Any], int]:
        """The kept packets from ``ordinal`` (at least the first kept) while ``budget`` bytes
        last (the first always), and the ordinal after them."""
        start = max(ordinal, self.first)
        out: list[Any] = []
        for f in islice(self.kept, start - self.first, None):
            if out and budget <= 0:
                break
            out.append(f)
            budget -= len(f.data)
        return out, start + len(out)

    def find(self, sequence: int) -> Any | None:
        """The kept packet with this sequence number among the last REPAIR_PACKETS, or None."""
        if not self.kept:
            return None
        at = (sequence - self.kept[-1].packet.sequence) & 0xFFFFFFFF
        back = (-at) & 0xFFFFFFFF  # how many packets before the newest
        if back >= min(len(self.kept), REPAIR_PACKETS):
            return None
        f = self.kept[len(self.kept) - 1 - back]
        return f if f.packet.sequence == sequence else None
