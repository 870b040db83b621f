"""The relay without its network: rooms of streams and viewers, what a sender's message does
to a room (:meth:`RelayCore.ingest`), a viewer joining, its settings and repair requests, and
the tick that gives every viewer one batch (:meth:`RelayCore.dispatch`). The server
(:mod:`.server`) calls these from its handlers and its tick loop; tests, the fuzzer and the
tick benchmark call them directly."""

from __future__ import annotations

import json
import logging
import math
import time

import numpy as np

from mocodec.errors import CorruptStreamError, MocodecError
from mocodec.stream.packets import (
    CUTS,
    HEADER,
    MAX_REPAIRS,
    Packet,
    Prepared,
    batch_of,
    cut_table,
    layer_ends,
    pack_batch,
    parse,
    stripped,
    truncated,
)
from mocodec.stream.relay.cutting import choose_layers, crowd_of, cut_for, layout_of, resent
from mocodec.stream.relay.limits import BAD_MESSAGE, QUEUED_S, RATE_LIMIT, TAKEN, TICK_HZ, Bucket, Closing, Limits
from mocodec.stream.relay.retention import RoomHistory
from mocodec.stream.relay.rooms import Forward, Room, StreamState, Viewer, caps_of, read_message, stream_setup

log = logging.getLogger("mocodec.relay")

COUNTERS = (
    "packets_in",
    "batches_out",
    "missed_ticks",
    "closed_bad",
    "closed_rate",
    "closed_expired",
    "dropped_slow",
    "repairs",
    "repairs_missed",
    "catchups_partial",
)


class RelayCore:
    """Every room of one relay, ticked ``tick_hz`` times a second, within ``limits``; ``clock``
    (seconds) times how long a viewer has been missing ticks."""

    def __init__(self, limits: Limits | None = None, tick_hz: float = TICK_HZ, clock=time.monotonic):
        self.limits, self.tick_s, self.clock = limits or Limits(), 1.0 / tick_hz, clock
        self.queued = max(1, round(QUEUED_S * tick_hz))  # batches a viewer may have queued
        self.rooms: dict[str, Room] = {}
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.ticks = 0

    def room(self, name: str) -> Room:
        """The room called ``name``, made empty if there is none."""
        room = self.rooms.get(name)
        if room is None:
            room = self.rooms[name] = Room(RoomHistory(caps_of(self.limits)))
        return room

    def status(self) -> dict:
        """Totals only: a room's name is what its tokens are issued for."""
        rooms = self.rooms.values()
        return {
            "rooms": len(self.rooms),
            "streams": sum(len(r.streams) for r in rooms),
            "viewers": sum(len(r.viewers) for r in rooms),
            **self.counters,
        }

    # ----- senders -----------------------------------------------------------------------------
    def ingest(self, room: Room, data: bytes, owner: object) -> None:
        """The packets of one sender message into the room; Closing if it is malformed."""
        try:
            packets, raw, prepared = read_message(room, data)
        except MocodecError as e:
            raise Closing(BAD_MESSAGE, f"bad message: {e}") from None
        for k, (p, r) in enumerate(zip(packets, raw)):
            self.counters["packets_in"] += 1
            state = room.streams.get(p.stream)
            if state is not None and state.owner is not owner:
                raise Closing(TAKEN, f"stream {p.stream} is published by another sender")
            if p.kind == HEADER:
                try:
                    info, codec = stream_setup(p.payload)
                except MocodecError as e:
                    raise Closing(BAD_MESSAGE, f"stream {p.stream}: {e}") from None
                if state is None and len(room.streams) >= self.limits.max_streams_per_room:
                    raise Closing(RATE_LIMIT, f"room is full ({self.limits.max_streams_per_room} streams)")
                if state is not None:
                    room.end_stream(p.stream)
                slot = room.take_slot()
                room.streams[p.stream] = StreamState(
                    owner, Forward(p, bytes(r)), info, codec, room.history.stream(), slot
                )
                room.fresh.append(room.streams[p.stream].header)
                continue
            if state is None:
                raise Closing(BAD_MESSAGE, f"stream {p.stream}: data before its header")
            if p.dropped:
                raise Closing(BAD_MESSAGE, f"stream {p.stream}: packet {p.sequence}: a sender's packet is whole")
            forward = _forwarded(p, r, state, prepared.get(k))
            if forward.layer_ends is not None:
                state.measure_layers(p, forward.layer_ends)
            state.position = p.position
            state.next_sequence, state.next_frame = (p.sequence + 1) & 0xFFFFFFFF, p.first_frame + p.frames
            state.history.add(forward, p.restart)  # a late joiner starts at the last keyframe or restart
            room.fresh.append(forward)
            state.ended = state.ended or p.end  # removed after this tick's dispatch

    def sender_left(self, room: Room, owner: object) -> bytes | None:
        """A sender has gone: the END packets of its streams that it did not end, ingested, as
        one batch (for the bus); None if it ended them all."""
        ends = [s.end_packet(k).to_bytes() for k, s in room.streams.items() if s.owner is owner and not s.ended]
        if not ends:
            return None
        batch = pack_batch(ends)
        self.ingest(room, batch, owner)
        return batch

    # ----- viewers -----------------------------------------------------------------------------
    def join(self, room: Room, viewer: Viewer) -> None:
        """A viewer joins: it gets every stream's header and catches up from its last restart
        point (:meth:`_catch_up`), or starts a stream live where that point is no longer kept."""
        viewer.repair_volume = Bucket(self.limits.repair_bytes_per_s, self.limits.burst_s)
        viewer.capacity = self.queued
        for key, state in room.streams.items():
            if state.ended:
                continue
            viewer.pending.append(state.header)
            if state.history.partial:
                self._starts_live(viewer, key, "its last restart point is no longer kept")
            else:
                viewer.behind[key] = (state, state.history.restart)
        room.viewers.append(viewer)

    def leave(self, room: Room, viewer: Viewer) -> None:
        """A viewer has gone (the room goes at the next tick if nothing else is in it)."""
        room.viewers.remove(viewer)

    def control(self, room: Room, viewer: Viewer, text: str, repairs: Bucket) -> None:
        """A viewer's message: its settings, and the packets it asks for again (within
        ``repairs``, its bucket of repaired packets); Closing if it is malformed."""
        if len(text) > self.limits.max_control_bytes:
            raise Closing(BAD_MESSAGE, f"a viewer's message is at most {self.limits.max_control_bytes} bytes")
        doc = apply_settings(viewer, text)
        viewer.repair_volume.set_rate(self._pace(viewer, self.limits.repair_bytes_per_s))
        if "repair" in doc:
            self.resend(room, viewer, doc["repair"], repairs)

    def resend(self, room: Room, viewer: Viewer, pairs: object, bucket: Bucket) -> None:
        """Queue the packets a viewer asks for again (``[[stream, sequence], ...]``) that the
        relay still has (the last REPAIR_PACKETS of each stream), while its repair buckets last,
        ``bucket`` in packets and the viewer's own in bytes (past them, requests are ignored:
        the viewer's receivers wait for the next restart)."""
        if not (isinstance(pairs, list) and len(pairs) <= MAX_REPAIRS):
            raise Closing(BAD_MESSAGE, f"repair must be a list of at most {MAX_REPAIRS} [stream, sequence] pairs")
        for pair in pairs:
            if not (
                isinstance(pair, list) and len(pair) == 2 and all(type(x) is int and 0 <= x <= 0xFFFFFFFF for x in pair)
            ):
                raise Closing(BAD_MESSAGE, "a repair pair is [stream, sequence], two integers 0 to 2**32 - 1")
            state = room.streams.get(pair[0])
            found = None if state is None else state.history.find(pair[1])
            if found is None or not bucket.take() or not viewer.repair_volume.take(len(found.data)):
                self.counters["repairs_missed"] += 1
                continue
            viewer.resends.append(found)
            self.counters["repairs"] += 1

    def _pace(self, viewer: Viewer, rate: float) -> float:
        """Bytes a second of catch-up or repairs for a viewer: ``rate``, or its budget if lower."""
        return rate if viewer.budget <= 0 else min(rate, viewer.budget / 8.0)

    def _starts_live(self, viewer: Viewer, stream: int, why: str) -> None:
        """A late viewer gets ``stream`` from its latest packets on, decodable from its next
        restart point; it is told so in a status message."""
        self.counters["catchups_partial"] += 1
        status = f"stream {stream}: {why}; live from its latest packets, decoded from its next restart"
        viewer.notes.append(json.dumps({"status": status}))

    # ----- ticks -------------------------------------------------------------------------------
    def tick(self) -> None:
        """Dispatch every room (one room's fault does not stop the others), then forget the idle ones."""
        for name, room in list(self.rooms.items()):
            try:
                self.dispatch(room)
            except Exception:  # noqa: BLE001 - one room's fault must not stop the others
                log.exception("dispatching room %s failed", name)
        for name in [n for n, r in self.rooms.items() if r.idle]:
            del self.rooms[name]
        self.ticks += 1

    def dispatch(self, room: Room) -> None:
        """One tick of a room: every viewer gets one batch of what is new (:meth:`offer`). What
        does not depend on the viewer is worked out once: the batch of every viewer that gets
        the tick's packets whole, and, for those with a budget, their shares and the layers of
        every layered packet (:func:`.cutting.choose_layers`), whose variants each batch joins."""
        fresh, room.fresh = room.fresh, []
        shared: bytes | None = None  # the batch of every viewer with nothing of its own
        cut_cache: dict[tuple[int, float], bytes] = {}
        crowd = None  # the scalable streams and where they are, this tick
        viewers = [v for v in room.viewers if not v.dropped]
        in_step = {id(v) for v in viewers if not v.behind}  # they get the tick's fresh packets as they are
        chosen_of: dict[int, list[np.ndarray]] = {}  # the variants of the tick's layered packets each gets
        scalable = any(f.scalable for f in fresh)
        for viewer in viewers:
            pending, viewer.pending = viewer.pending, []
            resends, viewer.resends = viewer.resends, []
            notes, viewer.notes = viewer.notes, []
            caught, live = self._catch_up(room, viewer, fresh) if viewer.behind else ([], fresh)
            pending += caught
            items = pending + live
            # status, and what it asked for again, go first, in messages of their own: the tick's batch stays shared
            batches: list[bytes | str] = [*notes]
            if resends:
                batches.append(pack_batch([resent(viewer, f, room.streams.get(f.packet.stream)) for f in resends]))
            if viewer.budget > 0 and (scalable or any(f.scalable for f in pending)):
                if crowd is None:
                    budgeted = [v for v in viewers if v.budget > 0]
                    crowd = crowd_of(room, fresh, layout_of(room, budgeted, self.limits.min_distance_m))
                    together = [v for v in budgeted if id(v) in in_step]
                    columns = [crowd.layout.column[id(v)] for v in together]
                    picked = choose_layers(room, crowd, together, crowd.layout.fits[:, columns])
                    chosen_of = {id(v): [p[:, k] for p in picked] for k, v in enumerate(together)}
                own = len(items) - len(fresh) if live is fresh else len(items)  # the tick's fresh packets go together
                bodies, heads = cut_for(room, crowd, viewer, items, own, cut_cache, chosen_of.get(id(viewer)))
                batches.append(batch_of(bodies, heads))
            elif pending or live is not fresh:  # joined late: its streams' last packets before the tick's
                if items:
                    batches.append(pack_batch([f.data for f in items]))
            elif fresh:
                shared = shared or pack_batch([f.data for f in fresh])
                batches.append(shared)
            if batches:
                self.offer(viewer, tuple(batches), items)
        for key in [k for k, state in room.streams.items() if state.ended]:
            room.end_stream(key)

    def _catch_up(self, room: Room, viewer: Viewer, fresh: list[Forward]) -> tuple[list[Forward], list[Forward]]:
        """A late viewer's catch-up this tick: the kept packets of each stream it is behind on,
        from where it got to, paced at :meth:`_pace` beyond the live packets of those streams
        (which the history holds too, in order); and the tick's fresh packets it gets as they
        are (the other streams', and new streams' headers)."""
        for key, (state, _) in list(viewer.behind.items()):
            if room.streams.get(key) is not state:  # ended, or a new header: that comes fresh
                del viewer.behind[key]
        live: list[Forward] = []
        out: list[Forward] = []
        owed = 0
        for f in fresh:
            if f.packet.kind == HEADER or f.packet.stream not in viewer.behind:
                live.append(f)
            else:
                owed += len(f.data)
        rate = self._pace(viewer, self.limits.catchup_bytes_per_s)
        viewer.credit = min(viewer.credit + rate * self.tick_s, rate * self.limits.burst_s) + owed
        for key, (state, at) in list(viewer.behind.items()):
            history = state.history
            if at < history.first:  # dropped before it got there (it was too slow)
                del viewer.behind[key]
                self._starts_live(viewer, key, "its catch-up fell out of what the relay keeps")
                continue
            if viewer.credit <= 0 and not state.ended:
                continue
            got, at = history.since(at, math.inf if state.ended else viewer.credit)
            viewer.credit -= sum(len(f.data) for f in got)
            out += got
            if at >= history.end:
                del viewer.behind[key]
            else:
                viewer.behind[key] = (state, at)
        if not viewer.behind:
            viewer.credit = 0.0
        return out, live

    def offer(self, viewer: Viewer, batches: tuple[bytes | str, ...], items: list[Forward]) -> None:
        """Queue a viewer's batches, or miss the tick if its outbox is full: it keeps the stream
        headers for the next tick and drops the rest (its receivers resynchronise at the next
        keyframe). A viewer that misses ticks for ``slow_viewer_s`` is dropped: its link is
        full, so a close frame would wait behind the data, and its connection is aborted."""
        if len(viewer.outbox) < viewer.capacity:
            viewer.outbox.append(batches)
            viewer.missed_since = None
            viewer.sent += 1
            self.counters["batches_out"] += 1
            viewer.wake()
            return
        viewer.missed += 1
        self.counters["missed_ticks"] += 1
        viewer.pending = [f for f in items if f.packet.kind == HEADER]
        now = self.clock()
        viewer.missed_since = viewer.missed_since or now
        if now - viewer.missed_since > self.limits.slow_viewer_s and not viewer.dropped:
            self.counters["dropped_slow"] += 1
            viewer.dropped = True
            log.info("dropping a viewer that missed ticks for %.1f s", now - viewer.missed_since)
            viewer.abort()


def apply_settings(viewer: Viewer, text: str) -> dict:
    """Apply a viewer's settings (``{"budget": bit/s, "camera": [x, y, z]}``); the message,
    parsed. Closing if it is not such JSON."""
    try:
        doc = json.loads(text)
        budget = float(doc.get("budget", viewer.budget))
        camera = tuple(float(x) for x in doc.get("camera", viewer.camera))
    except (ValueError, TypeError, AttributeError, OverflowError, RecursionError):
        raise Closing(BAD_MESSAGE, 'settings must be JSON like {"budget": 8000, "camera": [0, 1.6, 5]}') from None
    if not (math.isfinite(budget) and budget >= 0) or len(camera) != 3 or not all(map(math.isfinite, camera)):
        raise Closing(BAD_MESSAGE, "budget must be >= 0 bit/s and camera three finite numbers")
    viewer.budget, viewer.camera = budget, camera
    return doc


def _forwarded(p: Packet, raw: memoryview, state: StreamState, prepared: Prepared | None) -> Forward:
    """The packet as forwarded, its cut table stripped and read: a layered packet's layers
    (where each ends, and its bytes with its lowest 1, 2, ... layers: a layered stream's data
    needs a table of them), or an embedded codec's channel streams' lengths; Closing if it does
    not parse. A packet read with its layers (``prepared``, for the stream's layer count when
    its message was read) is forwarded as read; one read for another count (a header before it
    in its message changed the stream) is read again."""
    try:
        if prepared is not None:
            ends, variants = prepared
            if state.layered and len(ends) == state.layers:
                return Forward(p, variants[-1], layer_ends=ends, layer_variants=variants)
            p = parse(raw, "packet")
        if state.layered and p.frames:
            ends = layer_ends(p, state.layers)
            plain, data = stripped(p, raw)
            cut = (truncated(plain, data, end, len(ends) - keep) for keep, end in enumerate(ends[:-1], 1))
            return Forward(plain, data, layer_ends=ends, layer_variants=(*cut, data))
        cuts = cut_table(p) if p.flags & CUTS and not state.layered else None
        return Forward(*stripped(p, raw), cuts=cuts)
    except CorruptStreamError as e:
        raise Closing(BAD_MESSAGE, f"stream {p.stream}: packet {p.sequence}: {e}") from None
