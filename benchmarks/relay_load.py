"""Load test of the relay on loopback: N avatars streaming at 30 Hz to M viewers.

The relay runs as `mocodec serve` in its own process (or two relays joined by a NATS server
with --nats); publishers and viewers run in other processes. Each avatar replays the live
packets of a real clip (07_03, dpcm, spiht or kinwave-live, keyframes every --keyframe-s seconds), restamped with its
stream id, sequence number and the send time; viewers read every batch's timestamps and
sequence numbers in bulk and report delivered and lost packets and the end-to-end latency
(send -> receipt, which includes waiting for the relay's next tick, 60 Hz or --tick-hz). With --loss P each
viewer drops packets at random (an emulated lossy link) and a sample of viewers follows every
stream as a receiver would: after a loss it waits for the next keyframe or restart point; the
time from the first lost frame to it is the resync time. Server CPU (share of one core) and
memory (RSS) are read with psutil.

    .venv/bin/python benchmarks/relay_load.py                     # 500 avatars, 50 viewers, 20 s
    .venv/bin/python benchmarks/relay_load.py --loss 0.1
    .venv/bin/python benchmarks/relay_load.py --nats              # two relays over NATS
    .venv/bin/python benchmarks/relay_load.py --codec kinwave-live --layers 3 --budget 200000

With --budget each viewer declares that many bit/s from a random camera in the crowd: the relay
cuts spiht streams to their crowd shares and keeps the layers of kinwave-live streams that fit
them; the viewers report the bit/s they received.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import multiprocessing as mp
import os
import queue
import shutil
import socket
import struct
import subprocess
import sys
import time
import zlib
from dataclasses import replace

import numpy as np

from common import DATA
from mocodec.stream.client import REPAIR_AGAIN_S, REPAIR_HOLD_S
from mocodec.stream.live import MAX_MISSING
from mocodec.stream.packets import KEYFRAME, MAX_REPAIRS, RESTART
from mocodec.stream.relay import TICK_HZ

SECRET = "load-test-relay-secret"
RESUMES = KEYFRAME | RESTART  # the flags of a packet a receiver can start decoding from
BINS_MS = 0.1  # latency histogram resolution
MAX_MS = 5000.0
CAPACITY_P99_MS = 50.0  # --capacity: the latency a room must keep
_STAMP = struct.Struct("<IIQI")  # stream, sequence, timestamp, first frame: bytes 6..26 of a packet


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_port(port: int, seconds: float = 20.0) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return
        time.sleep(0.05)
    raise SystemExit(f"nothing listens on port {port} after {seconds} s")


def codec_of(codec_id: str, bits_per_second: float, layers: int, refresh_s: float, layer_ratio: float = 2.0):
    from mocodec.codecs import get_codec

    if codec_id == "spiht":
        return get_codec("spiht", bits_per_second=bits_per_second)
    if codec_id == "kinwave-live":
        return get_codec("kinwave-live", layers=layers, refresh_s=refresh_s, layer_ratio=layer_ratio)
    return get_codec(codec_id)


def templates(codec: tuple, keyframe_s: float):
    """The clip's live stream as a sender makes it: (header, [(tick, packet bytes)], ticks, frames),
    the last packet's END flag cleared so the clip can loop (every loop starts at a keyframe)."""
    from mocodec import load
    from mocodec.stream.live import END, clip_encoder, tick_frames

    motion = load(DATA / "07_03.bvh")
    enc = clip_encoder(motion, codec_of(*codec), 0, keyframe_s)
    step = tick_frames(motion.fps)
    ticks = -(-motion.num_frames // step)
    timed = [(k, p) for k in range(ticks) for p in enc.push(motion.channels[k * step : (k + 1) * step], 0)]
    timed += [(ticks - 1, p) for p in enc.close(0) if p.frames]
    # the full packet form: the load test restamps its fields in place, at fixed offsets
    data = [(k, replace(p, flags=p.flags & ~END, compact=False).to_bytes()) for k, p in timed]
    return enc.header(0).to_bytes(), data, ticks, motion.num_frames


def restamp(template: bytes, stream: int, seq: int, ts_us: int, first: int, x: float, z: float) -> bytes:
    buf = bytearray(template)
    _STAMP.pack_into(buf, 6, stream, seq, ts_us, first)
    y = struct.unpack_from("<f", buf, 32)[0]
    struct.pack_into("<3f", buf, 28, x, y, z)
    struct.pack_into("<I", buf, len(buf) - 4, zlib.crc32(memoryview(buf)[:-4]))
    return bytes(buf)


def place(stream: int) -> tuple[float, float]:
    """Where an avatar stands: a grid 2 m apart, 25 to a row."""
    return 2.0 * (stream % 25), 2.0 * (stream // 25)


# ----- publishers ------------------------------------------------------------------------------------
def publisher(url: str, token: str, streams: list[int], seconds: float, template: tuple, out, offset: float) -> None:
    """Send ``streams``' packets at 30 Hz for ``seconds``, at ``offset`` (0..1) of each 30 Hz
    period of the wall clock: the publishers spread their sends over the period, as
    independent senders do (all in step, every other 60 Hz tick of the relay had nothing new
    in some runs and not in others, and its sends moved by half)."""
    import aiohttp

    from mocodec.stream.packets import pack_batch

    header, data, ticks, clip_frames = template
    by_tick: dict[int, list[tuple[int, bytes, int]]] = {}
    for idx, (k, d) in enumerate(data):
        by_tick.setdefault(k, []).append((idx, d, struct.unpack_from("<I", d, 22)[0]))
    rng = np.random.default_rng(streams[0])
    phase = {s: int(rng.integers(ticks)) for s in streams}

    async def run() -> None:
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(
                f"{url}/ws?room=load&role=publish", headers={"Authorization": f"Bearer {token}"}, max_msg_size=64 << 20
            )
            await ws.receive()  # welcome
            await ws.send_bytes(pack_batch([restamp(header, s, 0, 0, 0, *place(s)) for s in streams]))
            now = time.time()
            await asyncio.sleep((math.floor(now * 30.0) + 1.0 + offset) / 30.0 - now)
            start = time.monotonic()
            tick, sent = 0, 0
            while time.monotonic() - start < seconds:
                now_us = time.time_ns() // 1000
                batch = []
                for s in streams:
                    loop, k = divmod(phase[s] + tick, ticks)
                    for idx, d, first in by_tick.get(k, ()):
                        batch.append(
                            restamp(d, s, loop * len(data) + idx, now_us, loop * clip_frames + first, *place(s))
                        )
                if batch:
                    await ws.send_bytes(pack_batch(batch))
                sent += len(batch)
                tick += 1
                await asyncio.sleep(max(start + tick / 30.0 - time.monotonic(), 0.0))
            await ws.close()
            out.put(("sent", sent))

    asyncio.run(run())


# ----- viewers ---------------------------------------------------------------------------------------
class Follower:
    """What a receiver does with flags only: after a loss it is out of step until a keyframe or
    a restart point (where a self-refreshing codec stream's base layer restarts); with
    ``hold_s`` it first waits that long (in stream frames, from its oldest gap) for the missing
    packets to be resent, as :class:`~mocodec.stream.live.LiveDecoder` does, and is in step
    again once they are all in."""

    def __init__(self, fps: float, hold_s: float = 0.0):
        self.fps, self.hold_frames = fps, hold_s * fps
        self.expected: dict[int, int] = {}
        self.last_end: dict[int, int] = {}  # stream -> the frame after the last one received
        self.lost_at: dict[int, int] = {}  # stream -> first frame lost
        self.gaps: dict[int, dict[int, int]] = {}  # stream -> the sequence numbers waited for -> their first frames
        self.resync_s: list[float] = []

    def see(self, stream: int, seq: int, resumes: bool, first: int, frames: int) -> None:
        exp = self.expected.get(stream)
        if exp is not None and seq < exp:  # resent
            gap = self.gaps.get(stream)
            if gap is not None and seq in gap:
                del gap[seq]
                if not gap:
                    del self.gaps[stream]
                    self._back(stream, self.last_end[stream])
            return
        if exp is not None and seq > exp:
            end = self.last_end.get(stream, first)
            missing = {m: end + (m - exp) * frames for m in range(exp, seq)}
            if stream not in self.lost_at:
                self.lost_at[stream] = end
                if self.hold_frames:
                    self.gaps[stream] = missing
            elif stream in self.gaps:
                self.gaps[stream].update(missing)
        self.expected[stream] = seq + 1
        self.last_end[stream] = first + frames
        if stream in self.gaps and not resumes:
            if first + frames - min(self.gaps[stream].values()) > self.hold_frames:  # the oldest gap given up
                del self.gaps[stream]
            return
        self.gaps.pop(stream, None)  # a packet to start from: the gap does not matter now
        if stream in self.lost_at and resumes:
            self._back(stream, first)

    def _back(self, stream: int, frame: int) -> None:
        self.resync_s.append((frame - self.lost_at.pop(stream)) / self.fps)


class Repairs:
    """What a lossy viewer asks the relay to resend: every gap in a stream's sequence, asked
    for again as :meth:`~mocodec.stream.client.Watcher.repairs` does (after REPAIR_AGAIN_S,
    then twice as long each time) until it is filled or REPAIR_HOLD_S has passed."""

    def __init__(self):
        self.expected = np.full(1 << 12, -1, dtype=np.int64)
        self.asked: dict[tuple[int, int], tuple[float, float, float]] = {}  # -> (first asked, last, wait)

    def resent(self, streams: np.ndarray, seqs: np.ndarray) -> np.ndarray:
        """Which packets of a batch are behind their stream's newest (resent ones)."""
        exp = self.expected[streams]
        return (exp >= 0) & (seqs < exp)

    def see(self, streams: np.ndarray, seqs: np.ndarray, resent: np.ndarray, now: float) -> list[list[int]]:
        """The kept packets of a batch in; the ``[stream, sequence]`` pairs to ask for now."""
        for s, q in zip(streams[resent].tolist(), seqs[resent].tolist()):
            self.asked.pop((s, q), None)
        fresh_streams, fresh_seqs = streams[~resent], seqs[~resent]
        for s, q in zip(fresh_streams.tolist(), fresh_seqs.tolist()):
            exp = int(self.expected[s])
            if exp >= 0:
                for m in range(exp, min(q, exp + MAX_MISSING)):
                    self.asked.setdefault((s, m), (now, -np.inf, REPAIR_AGAIN_S / 2))
            self.expected[s] = max(exp, q + 1)
        due = []
        for key, (first, last, wait) in list(self.asked.items()):
            if now - first > REPAIR_HOLD_S:
                del self.asked[key]
            elif now - last >= wait and len(due) < MAX_REPAIRS:
                self.asked[key] = (first, now, 2 * wait)
                due.append(list(key))
        return due


def viewers(
    url: str,
    token: str,
    count: int,
    seconds: float,
    loss: float,
    follow: int,
    seed: int,
    out,
    warmup_s: float,
    budget: float,
    repair: bool,
) -> None:
    import aiohttp

    from mocodec.stream.packets import (
        SEQUENCE_OFFSET,
        STREAM_OFFSET,
        TIMESTAMP_OFFSET,
        batch_offsets,
        read_u32,
        read_u64,
    )

    hist = np.zeros(int(MAX_MS / BINS_MS) + 1, dtype=np.int64)
    tally = {"received": 0, "dropped": 0, "batches": 0, "lost": 0, "bytes": 0, "resent": 0}
    followers = [Follower(120.0, REPAIR_HOLD_S if repair else 0.0) for _ in range(follow)]
    rng = np.random.default_rng(seed)

    async def one(k: int, session) -> None:
        ws = await session.ws_connect(
            f"{url}/ws?room=load&role=subscribe", headers={"Authorization": f"Bearer {token}"}, max_msg_size=256 << 20
        )
        await ws.receive()
        if budget:  # somewhere in the crowd, looking at it
            x, z = rng.uniform(0, 50), rng.uniform(0, 40)
            await ws.send_str(json.dumps({"budget": budget, "camera": [x, 1.6, z]}))
        repairs = Repairs()
        counts = np.zeros(1 << 12, dtype=np.int64)
        lo = np.full(1 << 12, np.iinfo(np.int64).max)
        hi = np.full(1 << 12, -1, dtype=np.int64)
        measure_from = time.monotonic() + warmup_s
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                msg = await ws.receive(timeout=max(end - time.monotonic(), 0.01))
            except TimeoutError:
                break
            if msg.type != aiohttp.WSMsgType.BINARY:
                break
            now_us = time.time_ns() // 1000
            if time.monotonic() < measure_from:
                continue
            data = msg.data
            tally["bytes"] += len(data)
            offsets = batch_offsets(data)[:-1]
            ts = read_u64(data, offsets, TIMESTAMP_OFFSET)
            live = ts > 0  # stream headers carry no time
            offsets, ts = offsets[live], ts[live]
            streams = read_u32(data, offsets, STREAM_OFFSET).astype(np.int64)
            seqs = read_u32(data, offsets, SEQUENCE_OFFSET).astype(np.int64)
            resent = repairs.resent(streams, seqs)  # counted apart: their time stamps are old
            tally["resent"] += int(resent.sum())
            new_streams, new_seqs = streams[~resent], seqs[~resent]
            n = np.bincount(new_streams)  # what the relay delivered
            counts[: len(n)] += n
            if n.max(initial=0) > 1:  # a late joiner's keyframe run
                np.minimum.at(lo, new_streams, new_seqs)
                np.maximum.at(hi, new_streams, new_seqs)
            else:
                lo[new_streams] = np.minimum(lo[new_streams], new_seqs)
                hi[new_streams] = np.maximum(hi[new_streams], new_seqs)
            ages = (now_us - ts[~resent].astype(np.int64)) // int(BINS_MS * 1000)
            lat = np.bincount(np.clip(ages, 0, len(hist) - 1))
            hist[: len(lat)] += lat
            tally["received"] += len(new_seqs)
            if loss:  # the emulated lossy link
                keep = rng.random(len(offsets)) >= loss
                tally["dropped"] += int((~keep[~resent]).sum())
                offsets, streams, seqs, resent = offsets[keep], streams[keep], seqs[keep], resent[keep]
            if repair and (asks := repairs.see(streams, seqs, resent, time.monotonic())):
                await ws.send_str(json.dumps({"repair": asks}))
            tally["batches"] += 1
            if k < follow:
                raw = np.frombuffer(data, dtype=np.uint8)
                flags = raw[offsets + 4]
                firsts = read_u32(data, offsets, 22)
                frames = raw[offsets + 26].astype(np.int64) | (raw[offsets + 27].astype(np.int64) << 8)
                f = followers[k]
                for s, q, fl, a, n in zip(
                    streams.tolist(), seqs.tolist(), flags.tolist(), firsts.tolist(), frames.tolist()
                ):
                    f.see(s, q, bool(fl & RESUMES), a, n)
        await ws.close()
        got = counts > 0
        tally["lost"] += int((hi[got] - lo[got] + 1).sum() - counts[got].sum())

    async def run() -> None:
        async with aiohttp.ClientSession() as session:
            await asyncio.gather(*(one(k, session) for k in range(count)))

    asyncio.run(run())
    resync = [s for f in followers for s in f.resync_s]
    out.put(("viewers", tally, hist, resync))


# ----- the run ---------------------------------------------------------------------------------------
def percentile(hist: np.ndarray, q: float) -> float:
    c = np.cumsum(hist)
    return float(np.searchsorted(c, q * c[-1]) * BINS_MS) if c[-1] else float("nan")


def relay_cores(args) -> int:
    """How many relay processes a run has (--pin gives each a core of its own)."""
    return 2 if args.nats else args.workers


def pin(args, pids: list[int], relay: bool) -> None:
    """With --pin, the relay's processes on its cores (0, 1, ...; a process's children inherit
    them), anything else on the rest."""
    if not args.pin:
        return
    n = relay_cores(args)
    for pid in pids:
        os.sched_setaffinity(pid, args.cores[:n] if relay else args.cores[n:])


def relay_processes(pr) -> list:
    """A relay's processes: ``mocodec serve`` itself, or with --workers its workers (not the
    NATS server it started, whose CPU is reported apart)."""
    children = [c for c in pr.children(recursive=True) if "nats" not in c.name()]
    return children or [pr]


def drive(args, token: str, relays: list) -> tuple[list, list, list]:
    """Start the publishers and viewers, watch the relays (:func:`_watch`), collect what they report."""

    out = mp.Queue()
    total = args.seconds + 3.0
    ids = list(range(args.avatars))
    codec = (args.codec, args.bits_per_second, args.layers, args.refresh_s, args.layer_ratio)
    template = templates(codec, args.keyframe_s)  # coded once, here: the publishers only restamp it
    workers = [
        mp.Process(
            target=publisher,
            args=(relays[0][0], token, ids[k :: args.publishers], total + 1.0, template, out, k / args.publishers),
        )
        for k in range(args.publishers)
    ]
    per = -(-args.viewers // args.viewer_procs)
    for k in range(args.viewer_procs):
        n = min(per, args.viewers - k * per)
        url = relays[k % len(relays)][0] if args.nats else relays[0][0]
        workers.append(
            mp.Process(
                target=viewers,
                args=(
                    url,
                    token,
                    n,
                    total + 1.0,
                    args.loss,
                    2 if args.loss else 0,
                    k,
                    out,
                    4.0,
                    args.budget,
                    args.repair,
                ),
            )
        )
    for w in workers[args.publishers :]:
        w.start()
    time.sleep(1.0)
    for w in workers[: args.publishers]:
        w.start()
    try:
        results, cpu, peak_rss = _watch(args, workers, relays, out)
    except BaseException:  # (a worker that failed: the others would keep this process from ending)
        for w in workers:
            w.terminate()
        raise
    for w in workers:
        w.join(30)
    return results, cpu, peak_rss


def _watch(args, workers: list, relays: list, out) -> tuple[list, list, list]:
    """Measure the relays while the load runs; what the publishers and viewers report."""
    import psutil

    pin(args, [w.pid for w in workers], relay=False)
    time.sleep(3.0)
    clients = [psutil.Process(w.pid) for w in workers]
    serving = [relay_processes(pr) for _, pr in relays]  # each relay's processes (its workers)
    for pr in [pr for group in serving for pr in group] + clients:
        pr.cpu_percent(None)
    t0 = time.monotonic()
    peak_rss = [0] * len(relays)
    while time.monotonic() - t0 < args.seconds:
        time.sleep(1.0)
        for k, group in enumerate(serving):
            peak_rss[k] = max(peak_rss[k], sum(pr.memory_info().rss for pr in group))
    cpu = [sum(pr.cpu_percent(None) for pr in group) for group in serving]
    busy = [c.cpu_percent(None) for c in clients]
    print(
        f"  client CPU (% of one core): publishers {sum(busy[: args.publishers]):.0f}, viewer processes "
        f"{', '.join(f'{b:.0f}' for b in busy[args.publishers :])}"
    )
    try:
        results = [out.get(timeout=60) for _ in workers]
    except queue.Empty:
        raise SystemExit("a publisher or viewer failed (see above)") from None
    return results, cpu, peak_rss


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--avatars", type=int, default=500)
    ap.add_argument("--viewers", type=int, default=50)
    ap.add_argument("--seconds", type=float, default=20.0, help="measured time (after a 3 s start)")
    ap.add_argument("--loss", type=float, default=0.0, help="packet loss each viewer emulates (0..1)")
    ap.add_argument(
        "--repair",
        action="store_true",
        help="lossy viewers ask the relay to resend what they lost, and their receivers wait "
        "REPAIR_HOLD_S for it before they wait for a restart",
    )
    ap.add_argument("--keyframe-s", type=float, default=0.5)
    ap.add_argument(
        "--codec", choices=("dpcm", "spiht", "kinwave-live"), default="dpcm", help="the avatars' codec (default dpcm)"
    )
    ap.add_argument("--layers", type=int, default=3, help="kinwave-live's layers (default 3: 4, 2 and 1 cm)")
    ap.add_argument("--refresh-s", type=float, default=0.0, help="kinwave-live's refresh_s (default 0)")
    ap.add_argument("--layer-ratio", type=float, default=2.0, help="kinwave-live's layer_ratio (default 2)")
    ap.add_argument("--bits-per-second", type=float, default=16000, help="spiht's rate as sent (default 16000)")
    ap.add_argument(
        "--budget",
        type=float,
        default=0.0,
        help="each viewer's bandwidth (bit/s) from a random camera in the crowd: spiht streams are cut "
        "to their crowd shares, kinwave-live streams keep the layers that fit them (default 0: all whole)",
    )
    ap.add_argument("--publishers", type=int, default=10, help="sending connections (avatars spread over them)")
    ap.add_argument("--tick-hz", type=float, default=TICK_HZ, help="the relay's batches per second to each viewer")
    ap.add_argument("--viewer-procs", type=int, default=1)
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="relay processes behind the one port (serve --workers; they share the room through the "
        "NATS server serve starts)",
    )
    ap.add_argument(
        "--nats",
        action="store_true",
        help="two relays sharing the room through a NATS server: senders on the first, viewers split over both",
    )
    ap.add_argument(
        "--pin",
        action="store_true",
        help="the relay's processes on cores of their own (one each: cores 0, 1, ...), the load generators "
        "on the others (sched_setaffinity; needs more cores than relay processes)",
    )
    ap.add_argument(
        "--capacity",
        action="store_true",
        help="the largest room that keeps p99 under 50 ms with nothing lost: runs with 25, 50, 75, 100, "
        "150 and 200 viewers (each --seconds long) until one fails",
    )
    args = ap.parse_args()
    if args.nats:
        args.viewer_procs = max(args.viewer_procs, 2)  # viewers on both relays
    args.cores = sorted(os.sched_getaffinity(0))  # (before --pin moves this process)
    if args.pin and len(args.cores) <= relay_cores(args):
        raise SystemExit(f"--pin needs more than {relay_cores(args)} cores (one a relay process, one for the load)")

    if not args.capacity:
        run_once(args)
        return
    largest = None
    for viewers in (25, 50, 75, 100, 150, 200):
        p99, lost = run_once(replace_viewers(args, viewers))
        if p99 >= CAPACITY_P99_MS or lost:
            break
        largest = viewers
    room = f"{args.avatars} avatars x {largest} viewers" if largest else "none of the rooms tried"
    print(f"capacity: {room} at 30 Hz keep p99 under {CAPACITY_P99_MS:g} ms with nothing lost")


def replace_viewers(args, viewers: int):
    """``args`` with another viewer count (one viewer process per 25)."""
    return argparse.Namespace(
        **{**vars(args), "viewers": viewers, "viewer_procs": max(args.viewer_procs, viewers // 25)}
    )


def run_once(args) -> tuple[float, int]:
    """One load run with ``args``, its figures printed; (p99 latency in ms, packets lost)."""
    import psutil

    from mocodec.stream import tokens

    token = tokens.issue(SECRET, "load", ttl_s=3600)
    pin(args, [os.getpid()], relay=False)  # (this process, and the NATS server it starts)
    procs, relays = [], []
    nats_url = None
    if args.nats:
        binary = shutil.which("nats-server", path="/usr/sbin:/usr/bin:/usr/local/bin")
        if binary is None:
            raise SystemExit("--nats needs nats-server (apt-get install nats-server)")
        nport = free_port()
        procs.append(
            subprocess.Popen(
                [binary, "-a", "127.0.0.1", "-p", str(nport)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
        )
        wait_port(nport)
        nats_url = f"nats://127.0.0.1:{nport}"
    for _ in range(2 if args.nats else 1):
        port = free_port()
        cmd = [
            sys.executable,
            "-m",
            "mocodec",
            "serve",
            "--port",
            str(port),
            "--secret",
            SECRET,
            "--max-messages-per-s",
            "1000",
            "--max-bytes-per-s",
            "1e8",
            "--tick-hz",
            str(args.tick_hz),
        ]
        if nats_url:
            cmd += ["--bus", nats_url]
        if args.workers > 1:
            cmd += ["--workers", str(args.workers)]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        pin(args, [p.pid], relay=True)
        procs.append(p)
        assert p.stdout is not None
        for _ in range(2 if args.workers > 1 else 1):  # its address; with workers, that all listen
            p.stdout.readline()
        wait_port(port)
        relays.append((f"ws://127.0.0.1:{port}", psutil.Process(p.pid)))
    try:
        results, cpu, peak_rss = drive(args, token, relays)
    finally:
        for p in reversed(procs):  # relays first, then NATS
            p.terminate()
            p.wait(10)
    sent = sum(r[1] for r in results if r[0] == "sent")
    hist = sum(r[2] for r in results if r[0] == "viewers")
    kinds = ("received", "dropped", "batches", "lost", "bytes", "resent")
    tally = {k: sum(r[1][k] for r in results if r[0] == "viewers") for k in kinds}
    resync = np.array([s for r in results if r[0] == "viewers" for s in r[3]])
    setup = (
        f"{args.avatars} {args.codec}"
        + (f" ({args.layers} layers, ratio {args.layer_ratio:g})" if args.codec == "kinwave-live" else "")
        + f" avatars at 30 Hz -> {args.viewers} viewers"
        + (f" of {args.budget:g} bit/s each" if args.budget else "")
        + (", two relays over NATS" if args.nats else "")
        + (f", {args.workers} workers" if args.workers > 1 else "")
        + (", relay processes pinned to cores of their own" if args.pin else "")
    )
    print(
        f"relay load: {setup}, {args.seconds:g} s measured, loss {args.loss:.0%}, keyframes every {args.keyframe_s:g} s"
    )
    print(
        f"  packets sent {sent:,}; delivered to viewers {tally['received']:,} in {tally['batches']:,} batches "
        f"({tally['batches'] / (args.viewers * args.tick_hz * args.seconds):.0%} of the ticks: a tick with nothing "
        "new sends none); "
        f"lost on the way {tally['lost']:,}"
        + (f"; dropped by the emulated link {tally['dropped']:,}" if args.loss else "")
        + (f"; resent on request {tally['resent']:,}" if args.repair else "")
    )
    print(f"  each viewer received {tally['bytes'] * 8 / args.viewers / args.seconds / 1000:,.0f} kbit/s")
    print(
        f"  latency p50 {percentile(hist, 0.5):.1f} ms, p99 {percentile(hist, 0.99):.1f} ms, "
        f"max {percentile(hist, 1.0):.1f} ms"
    )
    for k, (c, rss) in enumerate(zip(cpu, peak_rss)):
        print(f"  relay {k + 1}: CPU {c:.0f}% of one core, peak RSS {rss / 2**20:.0f} MiB")
    per_s = tally["received"] / args.seconds
    print(
        f"  deliveries {per_s:,.0f} a second, {per_s / max(sum(cpu) / 100.0, 1e-9):,.0f} a second per relay core "
        f"({sum(cpu) / 100.0 * 1e6 / max(per_s, 1e-9):.2f} us of relay CPU each)"
    )
    if args.loss:
        if len(resync):
            print(
                f"  resync after a loss ({len(resync):,} events): p50 {np.median(resync):.2f} s, "
                f"p99 {np.quantile(resync, 0.99):.2f} s, max {resync.max():.2f} s; "
                f"within 1 s: {np.mean(resync <= 1.0):.1%}"
            )

    return percentile(hist, 0.99), tally["lost"]


if __name__ == "__main__":
    main()
