"""Live avatars at a guaranteed max joint error: kinwave-live against offline kinwave and
deadreckoning, per source (CMU BVH and ASF/AMC at 120 fps, Bandai Namco at 30 fps).

    python benchmarks/bench_live.py [--clips N] [--bound 1.0] [--keyframe-s 1] [--refresh-s 0] [--loss 0.1]
                                    [--layers 3] [--layer-ratio 2] [--round-trip-s 0.05] [--hold-s 0.2] [--jobs 2]

Per clip: kbit/s of one codec stream's packets alone, and of the live stream as a sender sends
it (stream/live.py: keyframes every second, each restarting the codec stream, and the compact
packet framing with each packet's length in its batch, header packet left out); the coding delay
(how long a packet holds its first frame back); the measured max and mean joint error of every
decoded frame; for deadreckoning the threshold rate control finds for the bound (its delay: 3
frames), for offline kinwave the whole clip at the bound (its delay: the 256-frame segment); and
the resync time under random packet loss (seeded): for every lost packet, from its first frame
until the receiver decodes the stream exactly again (the next keyframe it gets), and the same
for a receiver that asks a relay to resend what it lost (``--round-trip-s``, ``--hold-s``). With
``--refresh-s`` the codec stream refreshes itself instead (kinwave-live's ``refresh_s``: each
layer restarts on its own, spread over that time) and keyframes come only every minute. Then the
layered stream (``--layers``, each layer ``--layer-ratio`` times the bound of the next, the top one at the bound):
per layer, kbit/s of the live stream a relay sends a viewer that gets that layer and those below
it (framing included), and the max and mean joint error of its decoding. Prints the medians per
source, and the 99th percentile of the resync times.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from functools import partial

import numpy as np

from common import shared_sources
from mocodec import load, ratecontrol
from mocodec.codecs import get_codec
from mocodec.codecs.kinwave import live
from mocodec.formats import varint
from mocodec.kinematics import forward_kinematics
from mocodec.stream.client import REPAIR_AGAIN_S, REPAIR_HOLD_S
from mocodec.stream.live import LiveDecoder, stream_clip
from mocodec.stream.packets import CUTS, HEADER, StreamInfo, layer_ends


def joint_errors(motion, channels) -> np.ndarray:
    sk, cm = motion.skeleton, 100.0 / motion.skeleton.units_per_metre
    p0, _ = forward_kinematics(sk, motion.channels)
    p1, _ = forward_kinematics(sk, channels)
    return np.linalg.norm(p1 - p0, axis=2) * cm


def framing_bytes(p) -> int:
    """What a packet costs around its payload on the wire: its compact frame and its length in
    the batch that carries it (one message may hold many avatars' packets)."""
    size = len(p.to_bytes())
    return size - len(p.payload) + len(varint.pack(size))


NO_KEYFRAMES_S = 60.0  # keyframes of a stream that refreshes itself


def layers_in_step(dec: LiveDecoder) -> int:
    if not dec.in_sync:
        return 0
    return getattr(dec.decoder, "layers_in_step", 1)


def resync_times(motion, packets, loss: float, seed: int, layers: int = 1) -> list[float]:
    """Seconds from each lost packet's first frame until the receiver decodes ``layers``
    layers (all of a single-layer stream) exactly again."""
    rng = np.random.default_rng(seed)
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
    times, waiting = [], []
    for p in packets[1:]:
        if rng.random() < loss:
            waiting.append(p.first_frame)
            continue
        dec.push(p)
        if layers_in_step(dec) >= layers and waiting:
            times += [(p.first_frame - f) / motion.fps for f in waiting]
            waiting = []
    return times + [(packets[-1].first_frame + packets[-1].frames - f) / motion.fps for f in waiting]


def repaired_resync_times(
    motion, packets, loss: float, seed: int, round_trip_s: float, hold_s: float = REPAIR_HOLD_S
) -> list[float]:
    """As :func:`resync_times`, for a receiver that asks for what it lost (a relay's repair,
    docs/streaming.md): a packet arrives when its last frame is in (its first frame plus its
    frames); a lost one is asked for when the next arrives and resent ``round_trip_s`` later,
    and asked for again while the resent one is lost too (as the Watcher does), until
    ``hold_s``; the receiver holds the packets after a gap that long (:class:`LiveDecoder` ``hold_s``). Seconds
    from each lost packet's first frame until the receiver decodes the stream exactly again."""
    rng = np.random.default_rng(seed)
    data = packets[1:]
    sent_at = [(p.first_frame + p.frames) / motion.fps for p in data]
    lost = rng.random(len(data)) < loss
    arrivals = [(sent_at[i], i) for i in range(len(data)) if not lost[i]]
    pending = np.nonzero(lost)[0].tolist()
    for i in pending:
        after = next((j for j in range(i + 1, len(data)) if not lost[j]), None)
        if after is None:
            continue
        ask, wait = 0.0, REPAIR_AGAIN_S
        while ask <= hold_s:  # asked for again after REPAIR_AGAIN_S, then twice as long each time
            if rng.random() >= loss:
                arrivals.append((sent_at[after] + ask + round_trip_s, i))
                break
            ask, wait = ask + wait, 2 * wait
    arrivals.sort()
    dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload), hold_s=hold_s)
    times, waiting, k = [], [], 0
    for t, i in arrivals:
        while k < len(pending) and sent_at[pending[k]] <= t:
            waiting.append(data[pending[k]].first_frame)
            k += 1
        dec.push(data[i])
        if waiting and dec.in_sync and not dec.wanted():
            times += [t - f / motion.fps for f in waiting]
            waiting = []
    end = (data[-1].first_frame + data[-1].frames) / motion.fps
    return times + [end - f / motion.fps for f in waiting]


def layer_rows(
    motion, bound: float, layers: int, ratio: float, keyframe_s: float, refresh_s: float, loss: float, seed: int
) -> dict:
    """Per layer kept (1..layers): the live stream's kbit/s cut to it, the max and mean
    joint error of the clip's packets cut to it, and the resync times under loss."""
    codec = get_codec("kinwave-live", max_error_cm=bound, layers=layers, layer_ratio=ratio, refresh_s=refresh_s)
    enc = codec.encoder(motion.skeleton, motion.fps)
    packets = enc.push(motion.channels) + enc.flush()
    ends = decoded_ends(codec, motion, packets)
    sent = stream_clip(motion, codec, keyframe_s=keyframe_s)
    stream = [p.without_cuts() for p in sent if p.kind != HEADER]
    sent_ends = [sent_layer_ends(p, layers) for p in sent if p.kind != HEADER]
    framing = sum(map(framing_bytes, stream))
    kbps, max_cm, mean_cm = [], [], []
    for keep in range(1, layers + 1):
        dec = codec.decoder(motion.skeleton, motion.fps)
        err = joint_errors(motion, np.concatenate([dec.push(p[: e[keep - 1]], keep) for p, e in zip(packets, ends)]))
        max_cm.append(float(err.max()))
        mean_cm.append(float(err.mean()))
        size = framing + sum(e[keep - 1] for e in sent_ends)
        kbps.append(size * 8 / motion.duration / 1000)
    return {
        "layer_kbps": kbps,
        "layer_max_cm": max_cm,
        "layer_mean_cm": mean_cm,
        "layer_resync_s": [resync_times(motion, sent, loss, seed, keep) for keep in (1, layers)],
    }


def decoded_ends(codec, motion, packets: list[bytes]) -> list[list[int]]:
    """Where each layer of each packet of a kinwave-live codec stream ends, as its decoder finds."""
    dec, out = codec.decoder(motion.skeleton, motion.fps), []
    for p in packets:
        dec.push(p)
        out.append(dec.layer_ends)
    return out


def sent_layer_ends(p, layers: int) -> list[int]:
    """Where each layer of a sent kinwave-live packet ends: its cut table (a packet without
    frames has none: every layer ends at its end)."""
    return layer_ends(p, layers) if p.flags & CUTS else [len(p.codec_payload)] * layers


def measure(
    path: str,
    bound: float,
    keyframe_s: float = 1.0,
    loss: float = 0.1,
    layers: int = 3,
    layer_ratio: float = 2.0,
    refresh_s: float = 0.0,
    round_trip_s: float = 0.05,
    hold_s: float = REPAIR_HOLD_S,
) -> dict:
    motion = load(path)
    seconds = motion.duration
    codec = get_codec("kinwave-live", max_error_cm=bound, refresh_s=refresh_s)
    keyframe_s = NO_KEYFRAMES_S if refresh_s else keyframe_s
    seed = sum(map(ord, path))
    enc = codec.encoder(motion.skeleton, motion.fps)
    packets = enc.push(motion.channels) + enc.flush()
    dec = codec.decoder(motion.skeleton, motion.fps)
    decoded = np.concatenate([dec.push(p) for p in packets])
    err = joint_errors(motion, decoded)
    payload = sum(map(len, packets))
    sent = stream_clip(motion, codec, keyframe_s=keyframe_s)
    stream = [p for p in sent if p.kind != HEADER]
    framing = sum(map(framing_bytes, stream)) / len(stream)
    offline = get_codec("kinwave", max_error_cm=bound)
    offline_bytes = len(offline.encode(motion))
    dr = ratecontrol.tune(get_codec("deadreckoning"), motion, "max_error_cm", bound, whole_file=False)
    return {
        "live_kbps": payload * 8 / seconds / 1000,
        "framed_kbps": sum(len(p.payload) + framing_bytes(p) for p in stream) * 8 / seconds / 1000,
        "framing_bytes": framing,
        "delay_ms": 1000 * (live.packet_frames(motion.fps) - 1) / motion.fps,
        "max_cm": float(err.max()),
        "mean_cm": float(err.mean()),
        "offline_kbps": offline_bytes * 8 / seconds / 1000,
        "offline_delay_ms": 1000 * offline.config["window"] / motion.fps,
        "dr_kbps": dr.bitrate / 1000,
        "dr_max_cm": dr.max_error_cm,
        "resync_s": resync_times(motion, sent, loss, seed),
        "repaired_resync_s": repaired_resync_times(motion, sent, loss, seed, round_trip_s, hold_s),
        **(layer_rows(motion, bound, layers, layer_ratio, keyframe_s, refresh_s, loss, seed) if layers > 1 else {}),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=6, help="clips per source (0: all)")
    ap.add_argument("--bound", type=float, default=1.0, help="max joint error, cm")
    ap.add_argument("--keyframe-s", type=float, default=1.0, help="seconds between keyframes (default 1)")
    ap.add_argument("--refresh-s", type=float, default=0.0, help="the codec refreshes itself (default: keyframes)")
    ap.add_argument("--loss", type=float, default=0.1, help="packet loss for the resync times (default 0.1)")
    ap.add_argument("--layers", type=int, default=3, help="layers of the layered stream (1: none; default 3)")
    ap.add_argument(
        "--round-trip-s",
        type=float,
        default=0.05,
        help="a repair's round trip, request to resent packet (default 0.05: a relay tick and a network's)",
    )
    ap.add_argument(
        "--hold-s",
        type=float,
        default=REPAIR_HOLD_S,
        help=f"how long the receiver waits for a resent packet (default {REPAIR_HOLD_S:g})",
    )
    ap.add_argument("--layer-ratio", type=float, default=2.0, help="each layer's bound over the next's (default 2)")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    with ProcessPoolExecutor(args.jobs) as pool:
        for name, paths in shared_sources().items():
            paths = paths[:: max(1, len(paths) // args.clips)][: args.clips] if args.clips else paths
            one = partial(
                measure,
                bound=args.bound,
                keyframe_s=args.keyframe_s,
                loss=args.loss,
                layers=args.layers,
                layer_ratio=args.layer_ratio,
                refresh_s=args.refresh_s,
                round_trip_s=args.round_trip_s,
                hold_s=args.hold_s,
            )
            rows = list(pool.map(one, map(str, paths)))
            resync = np.concatenate([r["resync_s"] for r in rows])
            repaired = np.concatenate([r["repaired_resync_s"] for r in rows])

            def med(key: str) -> float:
                return float(np.median([r[key] for r in rows]))

            ratio = np.median([r["live_kbps"] / r["offline_kbps"] for r in rows])
            refresh = (
                f"refresh every {args.refresh_s:g} s" if args.refresh_s else f"keyframes every {args.keyframe_s:g} s"
            )

            vs_dr = np.median([r["live_kbps"] / r["dr_kbps"] for r in rows])
            print(
                f"{name} ({len(rows)} clips) at {args.bound:g} cm: kinwave-live {med('live_kbps'):.2f} kbit/s "
                f"({med('framed_kbps'):.2f} as a live stream, {med('framing_bytes'):.1f} bytes of framing a packet), "
                f"delay {med('delay_ms'):.0f} ms, "
                f"max {max(r['max_cm'] for r in rows):.3f} cm, mean {med('mean_cm'):.3f} cm | offline kinwave "
                f"{med('offline_kbps'):.2f} kbit/s (delay {med('offline_delay_ms'):.0f} ms), "
                f"live/offline x{ratio:.2f} | "
                f"deadreckoning {med('dr_kbps'):.2f} kbit/s (max {max(r['dr_max_cm'] for r in rows):.3f} cm), "
                f"live/deadreckoning x{vs_dr:.2f} | {refresh}, {100 * args.loss:g}% loss: "
                f"resync median {np.median(resync):.2f} s, 99th percentile {np.percentile(resync, 99):.2f} s; "
                f"with repair (round trip {args.round_trip_s:g} s, hold {args.hold_s:g} s) "
                f"{np.median(repaired):.2f} s, {np.percentile(repaired, 99):.2f} s",
                flush=True,
            )
            if args.layers > 1:
                print_layers(name, rows, live.layer_bounds(args.bound, args.layers, args.layer_ratio))


def print_layers(name: str, rows: list[dict], bounds: list[float]) -> None:
    kbps = np.median([r["layer_kbps"] for r in rows], axis=0)
    base_share = np.median([r["layer_kbps"][0] / r["layer_kbps"][-1] for r in rows])
    over_single = np.median([r["layer_kbps"][-1] / r["framed_kbps"] for r in rows])
    worst = np.max([r["layer_max_cm"] for r in rows], axis=0)
    mean = np.median([r["layer_mean_cm"] for r in rows], axis=0)
    base, full = (np.concatenate([r["layer_resync_s"][k] for r in rows]) for k in (0, 1))
    print(
        f"{name} layers {'/'.join(f'{b:g}' for b in bounds)} cm: live stream "
        f"{'/'.join(f'{k:.2f}' for k in kbps)} kbit/s, base {100 * base_share:.0f}% of the full stream, "
        f"full / single layer x{over_single:.2f}, max {'/'.join(f'{w:.3f}' for w in worst)} cm, "
        f"mean {'/'.join(f'{m:.3f}' for m in mean)} cm | resync base median {np.median(base):.2f} s, "
        f"99th percentile {np.percentile(base, 99):.2f} s; all layers {np.median(full):.2f} s, "
        f"{np.percentile(full, 99):.2f} s",
        flush=True,
    )


if __name__ == "__main__":
    main()
