"""``mocodec bench``: every clip coded by every codec at every point, measured, stored as it
finishes (so a run resumes where it stopped) and gathered into one tidy table.

A task is one clip and one codec with all its points; it runs in a worker process and returns
one row per point. A row holds the size, ratio vs 32-bit floats (whole file, skeleton
included), bit rate, bits per DOF-sample, the quality measures of
:func:`mocodec.metrics.compare` and the encode and decode time per frame. A point a codec
cannot reach (rate control says so) gives a row with status ``unreachable``; a clip that
fails to load or a codec that crashes gives status ``failed`` and the run goes on; a clip
without channels (a rig whose joints never move: nothing to measure) gives one row with
status ``skipped``.
"""

from __future__ import annotations

import hashlib
import json
import math
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

from mocodec import moc
from mocodec.bench.points import Point, sweep_range
from mocodec.codecs import codec_class, get_codec
from mocodec.errors import CodecError, MocodecError
from mocodec.formats import READABLE, load
from mocodec.metrics import compare
from mocodec.motion import Motion
from mocodec.ratecontrol import tune

TARGET_OF = {"error": "max_error_cm", "ratio": "ratio", "bitrate": "bitrate"}
MEASURES = (
    "psnr_db",
    "vpsnr_db",
    "mean_joint_error_cm",
    "max_joint_error_cm",
    "mean_shell_error_cm",
    "max_shell_error_cm",
    "foot_slide_original_cm_s",
    "foot_slide_decoded_cm_s",
    "jerk_ratio",
)
COLUMNS = (
    "clip",
    "source",
    "format",
    "frames",
    "fps",
    "channels",
    "codec",
    "baseline",
    "point",
    "target",
    "knob",
    "knob_value",
    "status",
    "bytes",
    "ratio",
    "bitrate",
    "bits_per_dof_sample",
    *MEASURES,
    "encode_us_per_frame",
    "decode_us_per_frame",
    "message",
)
WARM_FRAMES = 64
SEARCH_RESOLUTION = 0.01  # rate control stops at knob steps of 1%: finer changes sizes by less
_warmed: set[str] = set()


@dataclass(frozen=True)
class Task:
    """One clip (``path``, shown as ``name``) and one codec at all its points."""

    path: str
    name: str
    codec: str
    points: tuple[Point, ...]
    knobs: tuple[tuple[str, str], ...] = ()  # (name, value) the codec is configured with

    @property
    def key(self) -> str:
        spec = [self.name, self.codec, [p.label for p in self.points]] + ([list(self.knobs)] if self.knobs else [])
        return hashlib.sha1(json.dumps(spec).encode()).hexdigest()[:16]

    def configured(self):
        """The task's codec with its knobs."""
        return get_codec(self.codec, **dict(self.knobs))


def find_clips(paths) -> list[tuple[str, str]]:
    """(path, name) of every readable clip in ``paths`` (files, or folders searched
    recursively), biggest first so parallel runs finish together; names are relative to the
    folder given."""
    found: dict[str, str] = {}
    for given in map(Path, paths):
        if given.is_dir():
            for p in sorted(given.rglob("*")):
                if p.suffix.lower() in READABLE and p.is_file():
                    found.setdefault(str(p), str(p.relative_to(given)))
        elif given.is_file():
            found.setdefault(str(given), given.name)
        else:
            raise MocodecError(f"{given}: no such file or folder")
    return sorted(found.items(), key=lambda pn: (-Path(pn[0]).stat().st_size, pn[1]))


def clip_source(name: str) -> str:
    """The pipeline a clip comes from, for tables that show sources side by side: the first
    folder of its name under the folder given and its format (``cmu bvh``, ``bandai bvh``), or
    its format alone."""
    path = Path(name)
    fmt = path.suffix.lstrip(".").lower()
    return f"{path.parts[0]} {fmt}" if len(path.parts) > 1 else fmt


def _warm(task: Task, motion: Motion) -> None:
    """Code a few frames once per process, so compile time is not counted as coding time."""
    if task.codec not in _warmed:
        _warmed.add(task.codec)
        try:
            moc.unpack(moc.pack(motion[:WARM_FRAMES], task.configured()))
        except MocodecError:
            pass


def _base_row(task: Task, motion: Motion | None, point: Point) -> dict:
    cls = codec_class(task.codec)
    knob = cls.quality.name if cls.quality else ""
    return {
        "clip": task.name,
        "source": clip_source(task.name),
        "format": Path(task.path).suffix.lstrip(".").lower(),
        "frames": motion.num_frames if motion else None,
        "fps": motion.fps if motion else None,
        "channels": motion.skeleton.num_channels if motion else None,
        "codec": task.codec,
        "baseline": cls.baseline,
        "point": point.kind,
        "target": None if point.kind == "knob" else point.value,
        "knob": knob,
        "knob_value": point.value if point.kind == "knob" and knob else None,
    }


def _measured(task: Task, motion: Motion, point: Point) -> dict:
    row = _base_row(task, motion, point)
    codec = task.configured()
    if point.kind == "knob" and row["knob"]:
        codec = codec.with_knob(row["knob"], point.value)
    elif point.kind != "knob":
        # error targets are searched in the sweep's range (the knob's far ends can be slow: VQ
        # codebooks of 4096 entries); size targets over the whole knob
        span = sweep_range(type(codec)) if point.kind == "error" else None
        codec = tune(
            codec, motion, TARGET_OF[point.kind], point.value, knob_range=span, resolution=SEARCH_RESOLUTION
        ).codec
        row["knob_value"] = codec.config[row["knob"]] if row["knob"] else None
    trip = moc.round_trip(motion, codec)
    size = len(trip.data)
    summary = compare(motion, trip.decoded).summary()
    samples = motion.num_frames * motion.skeleton.num_channels
    row.update(
        status="ok",
        bytes=size,
        ratio=motion.raw_bits / 8 / size,
        bitrate=size * 8 / motion.duration,
        bits_per_dof_sample=size * 8 / samples,
        encode_us_per_frame=trip.encode_s * 1e6 / motion.num_frames,
        decode_us_per_frame=trip.decode_s * 1e6 / motion.num_frames,
        **{k: summary[k] for k in MEASURES},
    )
    return row


def failed_row(task: Task, motion: Motion | None, point: Point, status: str, error: BaseException) -> dict:
    return {**_base_row(task, motion, point), "status": status, "message": one_line(error)}


def one_line(error: BaseException) -> str:
    """An error as one line: a MocodecError's own text, else its type, text and where it arose."""
    if isinstance(error, MocodecError):
        return str(error)
    where = traceback.extract_tb(error.__traceback__)[-1:] if error.__traceback__ else []
    at = f" at {Path(where[0].filename).name}:{where[0].lineno}" if where else ""
    return f"{type(error).__name__}: {error}{at}"


def run_task(task: Task) -> list[dict]:
    """Every row of a task (in a worker). Never raises."""
    try:
        motion = load(task.path)
    except Exception as e:  # noqa: BLE001 - the clip is reported and the run goes on
        return [failed_row(task, None, Point("knob", math.nan), "failed", e)]
    if not motion.skeleton.num_channels or not motion.num_frames:
        empty = "no channels (a rig whose joints never move)" if motion.num_frames else "no frames"
        nothing = CodecError(f"the clip has {empty}: nothing to measure")
        return [failed_row(task, motion, Point("knob", math.nan), "skipped", nothing)]
    _warm(task, motion)
    rows = []
    for point in task.points:
        try:
            rows.append(_measured(task, motion, point))
        except MocodecError as e:
            status = "unreachable" if point.kind != "knob" else "failed"
            rows.append(failed_row(task, motion, point, status, e))
        except Exception as e:  # noqa: BLE001
            rows.append(failed_row(task, motion, point, "failed", e))
    return rows


def task_failed(rows: list[dict]) -> bool:
    """A task that must run again on resume: nothing measured, or a crash."""
    return any(r["status"] == "failed" for r in rows)


class Store:
    """``rows.jsonl`` in the output folder: one line per finished task, appended and flushed as
    tasks finish, so an interrupted run loses at most the tasks in flight."""

    def __init__(self, folder: Path):
        self.path = folder / "rows.jsonl"
        self.done: dict[str, list[dict]] = {}
        if self.path.exists():
            for line in self.path.read_text().splitlines():
                try:
                    entry = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut short by an interrupted run
                if not task_failed(entry["rows"]):
                    self.done[entry["task"]] = entry["rows"]

    def add(self, task: Task, rows: list[dict]) -> None:
        with self.path.open("a") as f:
            f.write(json.dumps({"task": task.key, "spec": asdict(task), "rows": rows}, allow_nan=True) + "\n")
        if not task_failed(rows):
            self.done[task.key] = rows
