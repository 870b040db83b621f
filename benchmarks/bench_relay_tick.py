"""The relay's tick in one process: how long ``RelayCore.dispatch`` takes to serve every viewer of
a room of layered avatars, each viewer with its own budget and camera (no sockets, so the figure
is the relay's own work, free of the load generators that share the machine in relay_load.py).

    python benchmarks/bench_relay_tick.py [--avatars 500] [--viewers 50] [--budget 3000000] [--ticks 200] [--compact]

Avatars replay the live stream of tests/data/07_03.bvh (kinwave-live, 3 layers, keyframes every
0.5 s) at random phases on a 2 m grid; viewers stand at random places (seeded). Prints the
median, 90th percentile and maximum time of a tick's dispatch after 50 warm-up ticks, and the
time to take in a tick's packets. The cyclic collector is set as in a relay process
(:func:`~mocodec.stream.relay.server.quiet_collector`).
"""

from __future__ import annotations

import argparse
import struct
import time
from dataclasses import replace

import numpy as np

import mocodec.stream.packets
import mocodec.stream.relay
from mocodec.stream.relay.server import quiet_collector
from relay_load import place, restamp, templates

SEED = 29
WARM_UP = 50


def room_of(
    avatars: int,
    viewers: int,
    budget: float,
    relay=mocodec.stream.relay,
    packets=mocodec.stream.packets,
    compact: bool = False,
):
    """A relay core and its room: ``viewers`` viewers of ``budget`` bit/s at seeded cameras, the
    avatars' stream headers taken in; and a function giving each tick's sender message (with
    ``compact``, its data packets in the compact form, as a sender's ``LiveEncoder`` sends them,
    the position on keyframes). ``relay`` and ``packets``: the modules to build it with
    (another tree's, in ab_speed.py)."""
    header, data, clip_ticks, clip_frames = templates(("kinwave-live", 0.0, 3, 0.0), 0.5)
    usual = packets.parse(header).frames
    by_tick: dict[int, list[tuple[int, bytes, int]]] = {}
    for idx, (k, d) in enumerate(data):
        by_tick.setdefault(k, []).append((idx, d, struct.unpack_from("<I", d, 22)[0]))
    core, owner = relay.RelayCore(), object()
    room = core.room("bench")
    rng = np.random.default_rng(SEED)
    for _ in range(viewers):
        camera = (float(rng.uniform(0, 48)), 1.6, float(rng.uniform(0, 2 * avatars / 25)))
        core.join(room, relay.Viewer(budget=budget, camera=camera))
    core.ingest(room, packets.pack_batch([restamp(header, s, 0, 0, 0, *place(s)) for s in range(avatars)]), owner)
    phase = rng.integers(clip_ticks, size=avatars)

    def message(tick: int) -> bytes:
        batch = []
        for s in range(avatars):
            loop, k = divmod(int(phase[s]) + tick, clip_ticks)
            for idx, d, first in by_tick.get(k, ()):
                batch.append(restamp(d, s, loop * len(data) + idx + 1, 0, loop * clip_frames + first, *place(s)))
        if compact:
            full = [packets.parse(b) for b in batch]
            batch = [replace(p, compact=True, sends_position=p.keyframe, usual_frames=usual).to_bytes() for p in full]
        return packets.pack_batch(batch)

    return core, room, owner, message


def timed_tick(core, room, owner, data: bytes) -> tuple[float, float, list]:
    """One tick: the sender message ``data`` taken in, the room dispatched; the seconds each
    took, and what the viewers were offered (their outboxes, emptied)."""
    t0 = time.perf_counter()
    core.ingest(room, data, owner)
    t1 = time.perf_counter()
    core.dispatch(room)
    t2 = time.perf_counter()
    sent = [item for viewer in room.viewers for item in viewer.outbox]
    for viewer in room.viewers:
        viewer.outbox.clear()
    return t1 - t0, t2 - t1, sent


def run(avatars: int, viewers: int, budget: float, ticks: int, compact: bool) -> tuple[np.ndarray, np.ndarray]:
    relay, room, owner, message = room_of(avatars, viewers, budget, compact=compact)
    ingest, dispatch = np.array([timed_tick(relay, room, owner, message(tick))[:2] for tick in range(ticks)]).T
    return dispatch[WARM_UP:] * 1e3, ingest[WARM_UP:] * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--avatars", type=int, default=500)
    parser.add_argument("--viewers", type=int, default=50)
    parser.add_argument("--budget", type=float, default=3e6, help="bit/s per viewer (0: no budgets)")
    parser.add_argument("--ticks", type=int, default=200)
    parser.add_argument("--compact", action="store_true", help="senders' data packets in the compact form")
    args = parser.parse_args()
    quiet_collector()  # as a relay process runs
    dispatch, ingest = run(args.avatars, args.viewers, args.budget, args.ticks, args.compact)
    form = "compact" if args.compact else "full"
    print(
        f"relay tick, {args.avatars} layered avatars ({form} packets), {args.viewers} viewers at "
        f"{args.budget:g} bit/s: "
        f"dispatch median {np.median(dispatch):.2f} ms, p90 {np.percentile(dispatch, 90):.2f} ms, "
        f"max {dispatch.max():.2f} ms; taking in a tick's packets median {np.median(ingest):.2f} ms"
    )


if __name__ == "__main__":
    main()
