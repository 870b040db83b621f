"""Pieces every benchmark script uses: where the shared clips are (and the game-export stand-in
set made from them), timing, free loopback ports, and long clips made by repeating a short one."""

from __future__ import annotations

import argparse
import os
import socket
import time
from pathlib import Path

import numpy as np

from mocodec import Motion, load, reexpress
from mocodec.formats import to_bvh_form, write_bvh

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
SHARED = next((p for p in (ROOT.parent / "shared" / "data", Path("/work/shared/data")) if (p / "cmu").is_dir()), None)


GAME_EXPORT = "game export"
#: Where the game-export stand-in set is written (made on first use, not committed).
GAME_EXPORT_DIR = Path(os.environ.get("MOCODEC_BENCH_CACHE", ROOT / ".cache")) / "game-export-v1"


def shared_sources(clips: int = 0, game_export: bool = True) -> dict[str, list[Path]]:
    """The shared clips of each source (CMU BVH, CMU ASF/AMC, Bandai Namco, and with
    ``game_export`` the stand-in set :func:`game_export_set` makes from the CMU clips), sorted,
    the first ``clips`` of each (0: all); exits with a message where ../shared/data is absent."""
    if SHARED is None:
        raise SystemExit("../shared/data is absent")
    sources = {
        "CMU BVH": sorted((SHARED / "cmu" / "bvh").glob("*.bvh")),
        "CMU ASF/AMC": sorted((SHARED / "cmu" / "asf_amc").glob("*.amc")),
        "Bandai Namco": sorted((SHARED / "bandai").rglob("*.bvh")),
    }
    if game_export:
        sources[GAME_EXPORT] = game_export_set(sources["CMU BVH"] + sources["CMU ASF/AMC"])
    return {name: paths[:clips] if clips else paths for name, paths in sources.items()}


def as_game_export(motion: Motion, fps: float, seed: int) -> Motion:
    """``motion`` as an FBX pipeline into a game engine writes it: in centimetres, resampled to ``fps``, a bind
    pose in frame 0, translation channels on every bone holding its offset, a rotation-only
    root turned (0, -90, 0) above the old root (which keeps the translation), and every channel
    stored as float32, the bones' translations with the noise of a float32 matrix
    decomposition (a few units in the last place, seeded)."""
    game = to_bvh_form(motion)
    game = reexpress.with_units(game, 100.0 / game.skeleton.units_per_metre)  # centimetres
    game = reexpress.with_bind_frame(game.resample(fps))
    game = reexpress.with_dummy_root(reexpress.with_position_channels(game), (0.0, -90.0, 0.0))
    channels = game.channels.astype(np.float32)
    bones = ~game.skeleton.rotation_mask
    bones[: game.skeleton.channel_offsets[2]] = False  # the dummy root's and the hips' own
    ulp = np.spacing(np.abs(channels[:, bones])).astype(np.float32)
    noise = np.random.default_rng(seed).integers(-3, 4, size=ulp.shape).astype(np.float32)
    channels[:, bones] += noise * ulp
    return game.with_channels(channels.astype(np.float64))


def game_export_set(paths: list[Path]) -> list[Path]:
    """The game-export stand-in set: each CMU clip through :func:`as_game_export`, every other
    one at 24 fps and the rest at 30, written as BVH with 7 decimals (below float32's last place) into
    GAME_EXPORT_DIR the first time and read from there after."""
    GAME_EXPORT_DIR.mkdir(parents=True, exist_ok=True)
    out = []
    for k, path in enumerate(sorted(paths, key=lambda p: p.name)):
        fps = 24.0 if k % 2 == 0 else 30.0
        target = GAME_EXPORT_DIR / f"{path.stem}_{fps:g}fps.bvh"
        if not target.exists():
            partial = target.with_suffix(".part")
            write_bvh(as_game_export(load(path), fps, seed=k), partial, decimals=7)
            partial.replace(target)
        out.append(target)
    return sorted(out)


def free_port() -> int:
    """A loopback port nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def best_of(fn, repeats: int = 5) -> float:
    """The fastest of ``repeats`` runs of ``fn``, in seconds (the least disturbed by others)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def tile(motion: Motion, frames: int) -> Motion:
    """``motion`` repeated to exactly ``frames`` frames."""
    reps = -(-frames // motion.num_frames)
    return motion.with_channels(np.tile(motion.channels, (reps, 1))[:frames])


def options(doc: str | None) -> argparse.Namespace:
    """The command line of a script that takes no options but ``--help`` (which prints ``doc``)."""
    return argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
