"""A whole benchmark run: tasks for every clip and codec, run where asked, stored as they
finish, then ``results.csv`` (one tidy row per clip, codec and point), ``meta.json`` (machine,
versions, command, wall time) and the report."""

from __future__ import annotations

import csv
import importlib.util
import io
import json
import math
import platform
import sys
import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from mocodec.bench import engine
from mocodec.bench.points import DEFAULT_BITRATES, DEFAULT_ERRORS_CM, DEFAULT_KINDS, DEFAULT_RATIOS, points_for
from mocodec.bench.runner import default_jobs, execute
from mocodec.codecs import codec_class, codec_ids
from mocodec.errors import MocodecError
from mocodec.formats.fileio import atomic_write

SKIPPED_BY_DEFAULT = ("raw",)  # the reference itself: ratio 1 by definition
PACKAGES = (
    "mocodec",
    "numpy",
    "scipy",
    "PyWavelets",
    "numba",
    "constriction",
    "zstandard",
    "pysz",
    "zfpy",
    "fpzip",
    "matplotlib",
    "dask",
    "distributed",
)


@dataclass
class BenchResult:
    rows: list[dict]
    meta: dict
    failures: list[dict] = field(default_factory=list)


def default_codecs() -> list[str]:
    """Every registered codec but the reference, less baselines whose package is missing."""
    return [c for c in codec_ids() if c not in SKIPPED_BY_DEFAULT and _installed(codec_class(c))]


def _installed(cls) -> bool:
    package = getattr(cls, "package", "")
    return not package or importlib.util.find_spec(package) is not None


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def run(
    paths,
    out_dir,
    codecs=None,
    kinds=DEFAULT_KINDS,
    errors=DEFAULT_ERRORS_CM,
    ratios=DEFAULT_RATIOS,
    bitrates=DEFAULT_BITRATES,
    jobs: int | None = None,
    scheduler: str | None = None,
    dask: bool = False,
    progress: bool = False,
    report: bool = True,
    command: str | None = None,
    knobs: dict | None = None,
) -> BenchResult:
    """Benchmark ``codecs`` (default: all but ``raw``) on every clip under ``paths``, each
    configured with those of ``knobs`` it has (e.g. kinwave's ``effort``); skip the tasks
    ``out_dir`` already holds from an earlier run with the same points and knobs."""
    codecs = list(codecs or default_codecs())
    plan = {c: tuple(points_for(c, kinds, errors, ratios, bitrates)) for c in codecs}
    clips = engine.find_clips(paths)
    if not clips:
        raise MocodecError(f"no .bvh or .amc clips in {', '.join(map(str, paths))}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    store = engine.Store(out)
    given = {c: tuple(sorted((k, str(v)) for k, v in (knobs or {}).items() if k in _knob_names(c))) for c in codecs}
    unused = sorted(set(knobs or {}) - {k for c in codecs for k in _knob_names(c)})
    if unused:
        raise MocodecError(f"no codec of this run has the knob {unused[0]!r}")
    tasks = [engine.Task(p, n, c, plan[c], given[c]) for p, n in clips for c in codecs]
    todo = [t for t in tasks if t.key not in store.done]
    started = time.time()
    t0 = time.perf_counter()
    fresh: dict[str, list[dict]] = {}
    for task, result in execute(engine.run_task, todo, jobs, scheduler, dask, progress, "task"):
        if isinstance(result, BaseException):  # the worker itself died
            result = [engine.failed_row(task, None, task.points[0], "failed", result)]
        store.add(task, result)
        fresh[task.key] = result
    wall = time.perf_counter() - t0
    earlier = _earlier_wall(out) if len(todo) < len(tasks) else 0.0
    rows = [r for t in tasks for r in (store.done.get(t.key) or fresh.get(t.key, []))]
    meta = {
        "command": command or " ".join(sys.argv),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(started)),
        "wall_s": round(wall, 1),
        "wall_s_total": round(earlier + wall, 1),
        "jobs": jobs or default_jobs(),
        "scheduler": scheduler or ("dask local" if dask else "local"),
        "clips": len(clips),
        "codecs": codecs,
        "knobs": {c: dict(k) for c, k in given.items() if k},
        "tasks": len(tasks),
        "tasks_run": len(todo),
        "tasks_resumed": len(tasks) - len(todo),
        "points": {c: [p.label for p in ps] for c, ps in plan.items()},
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cores": default_jobs(),
            "python": platform.python_version(),
        },
        "versions": versions(),
    }
    result = BenchResult(rows, meta, [r for r in rows if r["status"] == "failed"])
    atomic_write(out / "results.csv", to_csv(rows))
    atomic_write(out / "meta.json", json.dumps(meta, indent=2) + "\n")
    if report:
        from mocodec.bench.report import write_report

        write_report(rows, meta, out)
    return result


def _knob_names(codec_id: str) -> set[str]:
    return {k.name for k in codec_class(codec_id).knobs}


def _earlier_wall(out: Path) -> float:
    """The wall time the runs before this one spent on the folder (0 if unknown)."""
    try:
        meta = json.loads((out / "meta.json").read_text())
        return float(meta.get("wall_s_total", meta.get("wall_s", 0.0)))
    except (OSError, ValueError, TypeError):
        return 0.0


def to_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=engine.COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _cell(r.get(k)) for k in engine.COLUMNS})
    return buf.getvalue()


def _cell(v):
    if isinstance(v, float):
        return "" if math.isnan(v) else ("inf" if math.isinf(v) else f"{v:.6g}")
    return "" if v is None else v


def read_rows(out_dir) -> list[dict]:
    """The rows of an earlier run's ``results.csv``, numbers as numbers."""
    path = Path(out_dir) / "results.csv"
    if not path.exists():
        raise MocodecError(f"{path}: no results here (run mocodec bench first)")
    with path.open() as f:
        return [{k: _parsed(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _parsed(v: str):
    if v == "":
        return None
    if v in ("True", "False"):
        return v == "True"
    try:
        return float(v)
    except ValueError:
        return v
