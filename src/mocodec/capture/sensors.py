"""Sensor frames and recorded sensor logs (003 §4.2-4.3).

The minimal configuration of 003 §4.3.2: four 6-DOF electromagnetic trackers (the centre of the
hips, the top of the head, the top of each wrist) and two data gloves with one 0..1 flex value
per finger (thumb, index, middle, ring, little). A tracker frame is a 4x4 position/orientation
matrix in metres. The thesis works in a left-handed frame with row vectors (the position in the
bottom row, (4-1), (4-7)); a log stores its matrices that way, and they are converted at this
boundary (z mirrored and transposed: M = F T^T F, F = diag(1, 1, -1, 1)) to the right-handed,
Y-up, column-vector frames of the rest of mocodec.

A log is an NPZ file: ``time`` (n,) seconds, strictly increasing; ``hips``, ``head``,
``left_wrist``, ``right_wrist`` (n, 4, 4); ``left_glove``, ``right_glove`` (n, 5) in [0, 1];
and ``calibration_<tracker>`` (4, 4), the frames read in the calibration posture (§4.3.3).
The reader refuses a malformed log with the file, the array and the frame that is wrong.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocodec.errors import FormatError
from mocodec.formats.fileio import atomic_write_bytes

TRACKERS = ("hips", "head", "left_wrist", "right_wrist")
GLOVES = ("left_glove", "right_glove")
FINGERS = ("thumb", "index", "middle", "ring", "little")
MIRROR_Z = np.diag([1.0, 1.0, -1.0, 1.0])
ORTHONORMAL_TOLERANCE = 1e-3


def from_thesis(t: np.ndarray) -> np.ndarray:
    """A left-handed, row-vector frame of the thesis as a right-handed, column-vector one."""
    return MIRROR_Z @ np.swapaxes(t, -1, -2) @ MIRROR_Z


def to_thesis(m: np.ndarray) -> np.ndarray:
    """The inverse of :func:`from_thesis`."""
    return np.swapaxes(MIRROR_Z @ m @ MIRROR_Z, -1, -2)


@dataclass
class SensorLog:
    """Tracker frames and glove values over time, right-handed, metres."""

    time: np.ndarray  # (n,)
    trackers: dict[str, np.ndarray]  # name -> (n, 4, 4)
    gloves: dict[str, np.ndarray]  # name -> (n, 5)
    calibration: dict[str, np.ndarray]  # name -> (4, 4)

    @property
    def num_frames(self) -> int:
        return int(self.time.size)

    @property
    def fps(self) -> float:
        return float(1.0 / np.median(np.diff(self.time))) if self.time.size > 1 else 30.0

    def to_bytes(self) -> bytes:
        arrays = {"time": self.time}
        arrays.update({k: to_thesis(v) for k, v in self.trackers.items()})
        arrays.update(self.gloves)
        arrays.update({f"calibration_{k}": to_thesis(v) for k, v in self.calibration.items()})
        out = io.BytesIO()
        np.savez_compressed(out, **arrays)  # type: ignore[arg-type]  # numpy's stub types allow_pickle as **kwds
        return out.getvalue()


def write_log(log: SensorLog, path: str | Path) -> None:
    atomic_write_bytes(path, log.to_bytes())


def read_log(path: str | Path) -> SensorLog:
    """The log at ``path``; FormatError naming what is wrong."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (OSError, ValueError) as e:
        raise FormatError(path, None, f"not a readable NPZ sensor log ({e})") from None
    need = ["time", *TRACKERS, *GLOVES, *(f"calibration_{t}" for t in TRACKERS)]
    missing = [k for k in need if k not in data]
    if missing:
        raise FormatError(path, None, f"missing array {missing[0]!r} (a log holds {', '.join(need)})")
    time = np.asarray(data["time"], dtype=np.float64)
    n = time.size
    if time.ndim != 1 or n == 0:
        raise FormatError(path, None, "array 'time': expected a non-empty (n,) array of seconds")
    _finite(path, "time", time)
    bad = np.flatnonzero(np.diff(time) <= 0)
    if bad.size:
        raise FormatError(
            path,
            None,
            f"array 'time': frame {bad[0] + 1} is not after frame {bad[0]} ({time[bad[0] + 1]} <= {time[bad[0]]})",
        )
    trackers = {t: _frames(path, t, data[t], (n, 4, 4)) for t in TRACKERS}
    calibration = {t: _frames(path, f"calibration_{t}", data[f"calibration_{t}"], (4, 4)) for t in TRACKERS}
    gloves = {}
    for g in GLOVES:
        values = np.asarray(data[g], dtype=np.float64)
        if values.shape != (n, len(FINGERS)):
            raise FormatError(path, None, f"array {g!r}: expected shape ({n}, {len(FINGERS)}), got {values.shape}")
        _finite(path, g, values)
        out = np.flatnonzero(((values < 0) | (values > 1)).any(axis=1))
        if out.size:
            raise FormatError(
                path,
                None,
                f"array {g!r}: frame {out[0]}: glove values must be in [0, 1], got {values[out[0]].tolist()}",
            )
        gloves[g] = values
    return SensorLog(time, trackers, gloves, calibration)


def _finite(path, name: str, values: np.ndarray) -> None:
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        raise FormatError(path, None, f"array {name!r}: frame {bad[0][0]}: a value is not finite")


def _frames(path, name: str, values: np.ndarray, shape: tuple) -> np.ndarray:
    """Thesis frames checked and converted (see the module doc)."""
    values = np.asarray(values, dtype=np.float64)
    if values.shape != shape:
        raise FormatError(path, None, f"array {name!r}: expected shape {shape}, got {values.shape}")
    _finite(path, name, values)
    values = from_thesis(values)
    frames = values.reshape(-1, 4, 4)
    rot = frames[:, :3, :3]
    error = np.abs(rot @ np.swapaxes(rot, 1, 2) - np.eye(3)).max(axis=(1, 2))
    bottom = np.abs(frames[:, 3] - [0, 0, 0, 1]).max(axis=1)
    bad = np.flatnonzero((error > ORTHONORMAL_TOLERANCE) | (bottom > 1e-9) | (np.linalg.det(rot) < 0))
    if bad.size:
        raise FormatError(
            path,
            None,
            f"array {name!r}: frame {bad[0]}: not a rigid 4x4 pose (rotation part "
            "orthonormal with determinant +1, last column 0 0 0 1)",
        )
    return values
