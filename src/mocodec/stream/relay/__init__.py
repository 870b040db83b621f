"""The relay: senders publish avatar streams into rooms, viewers watch rooms (``mocodec serve``).

One aiohttp server, one port: ``/ws`` is the WebSocket (``?room=R&role=publish|subscribe``,
the token in ``Authorization: Bearer T`` or ``&token=T``), ``/status`` a JSON summary, and
anything else the static files of the viewer. The relay greets an accepted connection with
``{"welcome": room, "role": role}`` and closes a refused one with code 4003 and the reason. A
sender's message is a batch of packets (:mod:`mocodec.stream.packets`); a viewer's messages
are JSON: settings, ``{"budget": bit/s, "camera": [x, y, z] (metres)}``, and requests to
resend packets it lost, ``{"repair": [[stream, sequence], ...]}``: the relay resends those it
still has (each stream's last REPAIR_PACKETS), up to ``repair_bytes_per_s`` (or the viewer's
budget), at its next tick, in a message before the
viewer's batch, with the layers the viewer gets now, so a receiver that holds the packets
after a gap decodes on in step instead of waiting for the next restart.

Every tick (TICK_HZ, 60 a second: a packet waits 17 ms at most) each viewer gets one batch with
everything new in its room. A viewer that declared a budget gets the scalable streams cut to
their shares by the crowd rule of 001: scores S = d_min / d (6.4), shares B S / sum S (6.5), d
the distance from its camera to each avatar's root. An embedded (``spiht``) stream is cut to its
share rounded down to a ladder of 4 rates per octave, so that viewers with nearly equal shares
share one cut; a layered (``kinwave-live`` with layers) stream keeps the most layers whose
measured rate fits the share (the base layer always), more only from a keyframe or a packet
where the layer restarts, since a layer's prediction needs its history: the share by distance is
spent as error bounds. Shares are worked out every few ticks (:data:`.cutting.LAYOUT_TICKS`)
and at once when a stream, a budget or a camera changes. Other streams pass whole. A viewer
that joins late gets every stream
header and catches up from each stream's last keyframe (or restart point, where the codec
stream restarts its base layer on its own), paced at ``catchup_bytes_per_s`` (or its budget)
beyond the live packets (:mod:`.retention` keeps them, capped in bytes per stream
and per room); a stream whose restart point is no longer kept starts live, and the viewer gets
a ``{"status": ...}`` message saying so. A stream ends with its END packet; if its sender
goes without one, the relay sends the END for it (and over the bus), so no viewer waits for a
stream that will not come back.

Limits: message size (the WebSocket refuses larger ones), per-connection rates of messages and
bytes (token buckets; over the limit closes that connection), streams per room, and at most
QUEUED_S of batches queued per viewer (two at 60 Hz): a slow viewer misses ticks and
resynchronises at the next keyframe, and missing ticks for ``slow_viewer_s`` drops it (its
connection is cut, as a close frame would wait behind the data its link cannot take), so memory
does not grow with slow links. A malformed message closes its connection only, with a close code
and the reason.
Connections are counted before HTTP parses anything (:class:`.server.ConnectionGuard`): at most
``max_connections`` in all and ``max_connections_per_host`` from one address, and one that has
not made its request within ``request_timeout_s`` is cut. A connection is closed when its
token expires. ``/status`` shows totals only: room names are for token holders.
Threat model: docs/security.md.

The package: :mod:`.core` (rooms, ingest, viewers, ticks; no network code) on :mod:`.rooms`
(the state), :mod:`.retention` (what is kept), :mod:`.cutting` (budgets and cuts) and
:mod:`.limits`; :mod:`.server` (aiohttp, the connection guard, the NATS bridge, ``run``).
"""

from mocodec.stream.relay.core import RelayCore
from mocodec.stream.relay.limits import BAD_MESSAGE, BAD_TOKEN, RATE_LIMIT, TAKEN, TICK_HZ, Bucket, Closing, Limits
from mocodec.stream.relay.rooms import Room, Viewer

__all__ = [
    "BAD_MESSAGE",
    "BAD_TOKEN",
    "RATE_LIMIT",
    "TAKEN",
    "TICK_HZ",
    "Bucket",
    "Closing",
    "Limits",
    "RelayCore",
    "Room",
    "Viewer",
]
