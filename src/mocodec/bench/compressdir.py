"""``mocodec compress-dir``: a whole mocap library coded into .moc files on the benchmark's
engine (local cores or a Dask cluster). Each clip's file is written under a temporary name and
renamed, so a file that exists is complete; a rerun skips those, which makes runs resumable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from mocodec import moc, ratecontrol
from mocodec.bench.engine import find_clips, one_line
from mocodec.bench.runner import execute
from mocodec.codecs import get_codec
from mocodec.errors import MocodecError
from mocodec.formats import load
from mocodec.formats.fileio import atomic_write_bytes, one_source_each


@dataclass(frozen=True)
class FileTask:
    source: str
    target: str
    codec: str
    knobs: tuple[tuple[str, str], ...] = ()
    goal: tuple[str, float] | None = None  # a rate-control target, e.g. ("max_error_cm", 1.0)


@dataclass
class Outcome:
    written: list[dict] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)  # (source, message)
    wall_s: float = 0.0


def compress_file(task: FileTask) -> dict:
    """Code one clip into its .moc file (in a worker)."""
    t0 = time.perf_counter()
    motion = load(task.source)
    codec = get_codec(task.codec, **dict(task.knobs))
    data = ratecontrol.tune(codec, motion, *task.goal).data if task.goal else moc.pack(motion, codec)
    Path(task.target).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(task.target, data)
    return {
        "source": task.source,
        "target": task.target,
        "frames": motion.num_frames,
        "bytes": len(data),
        "raw_bytes": motion.raw_bits // 8,
        "seconds": time.perf_counter() - t0,
    }


def plan(in_dir, out_dir, codec: str, knobs: dict | None = None, goal=None) -> list[FileTask]:
    """A task for every clip under ``in_dir``: the same relative path under ``out_dir``, as .moc."""
    get_codec(codec, **(knobs or {}))  # a bad codec or knob fails here, not in every worker
    if not Path(in_dir).is_dir():
        raise MocodecError(f"{in_dir}: not a folder")
    pairs = [(source, str(Path(out_dir) / Path(name).with_suffix(".moc"))) for source, name in find_clips([in_dir])]
    one_source_each(pairs)
    tasks = [FileTask(source, target, codec, tuple(sorted((knobs or {}).items())), goal) for source, target in pairs]
    if not tasks:
        raise MocodecError(f"no .bvh or .amc clips in {in_dir}")
    return tasks


def compress_dir(
    in_dir,
    out_dir,
    codec: str,
    knobs: dict | None = None,
    goal=None,
    jobs: int | None = None,
    scheduler: str | None = None,
    dask: bool = False,
    progress: bool = False,
) -> Outcome:
    tasks = plan(in_dir, out_dir, codec, knobs, goal)
    done = {t.target for t in tasks if Path(t.target).exists()}
    out = Outcome(skipped=[t.target for t in tasks if t.target in done])
    todo = [t for t in tasks if t.target not in done]
    t0 = time.perf_counter()
    for task, result in execute(compress_file, todo, jobs, scheduler, dask, progress, "clip"):
        if isinstance(result, BaseException):
            out.failed.append((task.source, one_line(result)))
        else:
            out.written.append(result)
    out.wall_s = time.perf_counter() - t0
    out.written.sort(key=lambda r: r["source"])
    out.failed.sort()
    return out
