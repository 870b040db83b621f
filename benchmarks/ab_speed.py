"""The working tree against a git revision, in one process: kinwave's encode or decode of a
source clip by clip, or the relay's tick (benchmarks/bench_relay_tick.py), each tree in turn.
On a shared machine single runs move by 10-40% from minute to minute; two trees timed in
turn, item by item, see the same machine.

    NUMBA_NUM_THREADS=1 python benchmarks/ab_speed.py [encode|decode|relay] [--base REF]
        [--source NAME] [--rounds N] [--ticks N] [--compact]

The revision is a copy of its ``src/mocodec`` under another package name (``git archive``
into .cache/ab/, imports renamed; its NamedTuple classes too, or numba's types would mix the
two trees' classes and send every call down its slow path). Prints frames/s (the best time
of each clip over the rounds) or the tick's medians, for both, whether both give the same
bytes, and the ratio of the times.
"""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import tarfile
import time
from io import BytesIO

import numpy as np

from common import ROOT, shared_sources

NAME = "mocodec_ab"
NAMED_TUPLES = re.compile(r"^class (\w+)\(NamedTuple\)", re.M)


def revision_package(ref: str) -> str:
    """Make (once per commit) the copy of ``ref``'s package; returns the folder to import from."""
    commit = subprocess.run(["git", "rev-parse", ref], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    folder = ROOT / ".cache" / "ab" / commit.strip()[:12]
    if not (folder / NAME / "__init__.py").exists():
        archive = subprocess.run(["git", "archive", ref, "src/mocodec"], cwd=ROOT, capture_output=True, check=True)
        with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
            files = {m.name: tar.extractfile(m).read() for m in tar.getmembers() if m.isfile()}
        sources = {name: data.decode() for name, data in files.items() if name.endswith(".py")}
        tuples = {t for text in sources.values() for t in NAMED_TUPLES.findall(text)}
        renamed = re.compile(r"\b(" + "|".join(sorted(tuples)) + r")\b") if tuples else None
        for name, data in files.items():
            target = folder / NAME / name.removeprefix("src/mocodec/")
            target.parent.mkdir(parents=True, exist_ok=True)
            if name in sources:
                text = re.sub(r"\bmocodec(?=[.\s,)]|$)", NAME, sources[name], flags=re.M)
                text = renamed.sub(r"\1AB", text) if renamed else text
                target.write_text(text)
            else:
                target.write_bytes(data)
    return str(folder)


def kinwave(what: str, source: str, rounds: int) -> None:
    import mocodec
    import mocodec.codecs

    base = importlib.import_module(NAME)
    paths = shared_sources(0)[source]
    codecs = {
        "base": importlib.import_module(f"{NAME}.codecs").get_codec("kinwave"),
        "tree": mocodec.codecs.get_codec("kinwave"),
    }
    clips = {"base": [base.load(p) for p in paths], "tree": [mocodec.load(p) for p in paths]}
    bodies = {k: [codecs[k].encode(m) for m in clips[k]] for k in codecs}
    times = {k: np.full((rounds, len(paths)), np.inf) for k in codecs}
    for r in range(rounds):
        for i in range(len(paths)):
            for k in ("base", "tree") if (r + i) % 2 == 0 else ("tree", "base"):
                m, t0 = clips[k][i], time.perf_counter()
                if what == "encode":
                    codecs[k].encode(m)
                else:
                    codecs[k].decode(bodies[k][i], m.skeleton, m.num_frames, m.fps)
                times[k][r, i] = time.perf_counter() - t0
    frames = sum(m.num_frames for m in clips["tree"])
    same = bodies["base"] == bodies["tree"]
    print(f"kinwave {what}, {source} ({len(paths)} clips), {rounds} rounds; the same bytes: {same}")
    for k in codecs:
        print(f"  {k}: {frames / times[k].min(axis=0).sum():,.0f} frames/s ({sum(map(len, bodies[k])):,} bytes)")
    print(f"  time, tree / base: {times['tree'].min(axis=0).sum() / times['base'].min(axis=0).sum():.3f}")


def relay(ticks: int, compact: bool) -> None:
    from bench_relay_tick import WARM_UP, room_of, timed_tick
    from mocodec.stream.relay.server import quiet_collector

    quiet_collector()
    avatars, viewers, budget = 500, 50, 3e6
    rooms = {
        "base": room_of(
            avatars,
            viewers,
            budget,
            *(importlib.import_module(f"{NAME}.stream.{m}") for m in ("relay", "packets")),
            compact=compact,
        ),
        "tree": room_of(avatars, viewers, budget, compact=compact),
    }
    taken = {k: ([], []) for k in rooms}
    same = True
    for tick in range(ticks):
        sent = {}
        for k in ("base", "tree") if tick % 2 else ("tree", "base"):
            core, room, owner, message = rooms[k]
            ingest, dispatch, sent[k] = timed_tick(core, room, owner, message(tick))
            if tick >= WARM_UP:
                taken[k][0].append(ingest)
                taken[k][1].append(dispatch)
        same = same and sent["base"] == sent["tree"]
    form = "compact" if compact else "full"
    print(
        f"relay tick, {avatars} layered avatars ({form} packets), {viewers} viewers at {budget:g} bit/s; "
        f"the same batches: {same}"
    )
    for k in rooms:
        ingest, dispatch = (np.median(x) * 1e3 for x in taken[k])
        print(f"  {k}: taking in a tick's packets median {ingest:.2f} ms, dispatch median {dispatch:.2f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("encode", "decode", "relay"))
    parser.add_argument("--base", default="HEAD", help="the git revision to compare with (HEAD)")
    parser.add_argument("--source", default="game export", help="a source of shared_sources (game export)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds over the clips (3)")
    parser.add_argument("--ticks", type=int, default=300, help="relay ticks (300)")
    parser.add_argument("--compact", action="store_true", help="relay: senders' packets in the compact form")
    args = parser.parse_args()
    sys.path.insert(0, revision_package(args.base))
    if args.what == "relay":
        relay(args.ticks, args.compact)
    else:
        kinwave(args.what, args.source, args.rounds)


if __name__ == "__main__":
    main()
