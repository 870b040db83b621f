"""The relay's limits (every count and rate a connection may reach), its token buckets, and
how it refuses a connection: :class:`Closing` with a close code and a reason."""

from __future__ import annotations

import time
from dataclasses import dataclass

#: Close codes (4000-4999 are the application's).
BAD_TOKEN, BAD_MESSAGE, RATE_LIMIT, TAKEN = 4003, 4400, 4429, 4409
TICK_HZ = 60.0  # batches a second to each viewer: twice the senders' packet rate halves the wait
QUEUED_S = 1.0 / 30.0  # batches a viewer may have queued, in seconds (one at 30 Hz, two at 60)


@dataclass
class Limits:
    max_message_bytes: int = 1 << 20
    publish_messages_per_s: float = 400.0
    publish_bytes_per_s: float = 8e6
    control_messages_per_s: float = 120.0  # settings and repair requests (one a tick, and some)
    max_control_bytes: int = 16384  # a viewer's message (MAX_REPAIRS pairs fit)
    repair_packets_per_s: float = 2000.0  # packets resent to one viewer; past it requests are ignored
    repair_bytes_per_s: float = 1e6  # bytes resent to one viewer (at most its budget)
    catchup_bytes_per_s: float = 2e6  # a late viewer's catch-up beyond the live packets (at most its budget)
    max_stream_kept_bytes: int = 4 << 20  # kept per stream for late viewers and repairs
    max_room_kept_bytes: int = 32 << 20  # kept per room
    burst_s: float = 2.0  # a bucket holds this many seconds of its rate
    slow_viewer_s: float = 5.0
    max_gop_packets: int = 512
    max_streams_per_room: int = 5000
    min_distance_m: float = 0.1
    max_connections: int = 2000
    max_connections_per_host: int = 200
    request_timeout_s: float = 10.0


class Bucket:
    """A token bucket: ``rate`` per second, up to ``rate * burst_s`` saved."""

    def __init__(self, rate: float, burst_s: float):
        self.rate, self.burst_s, self.capacity = rate, burst_s, rate * burst_s
        self.level, self.at = self.capacity, time.monotonic()

    def set_rate(self, rate: float) -> None:
        self.rate, self.capacity = rate, rate * self.burst_s
        self.level = min(self.level, self.capacity)

    def take(self, amount: float = 1.0) -> bool:
        now = time.monotonic()
        self.level = min(self.capacity, self.level + (now - self.at) * self.rate)
        self.at = now
        if self.level < amount:
            return False
        self.level -= amount
        return True


class Closing(Exception):
    """Close this connection with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str):
        super().__init__(reason)
        self.code, self.reason = code, reason
