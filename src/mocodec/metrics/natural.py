"""Natural-movement checks (000 §6.2.1): values and derivatives of the decoded joint angles
that are out of bounds compared with the original.

- Joint-limit violations: decoded samples outside the skeleton's joint limits, counted beside
  the original's own violations (captured data is not always within its stated limits).
- Derivative outliers: decoded first and second differences whose magnitude exceeds the
  largest one of the same DOF in the original by more than ``margin`` (10% by default), the
  discontinuities and spikes that "indicate something has gone wrong in the coding process".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.motion import wrap_degrees
from mocodec.skeleton import Skeleton

DERIVATIVE_MARGIN = 0.10
LIMIT_TOLERANCE_DEG = 1e-6


@dataclass(frozen=True)
class Naturalness:
    limit_violations: int  # decoded samples outside the joint limits
    original_limit_violations: int
    velocity_outliers: int  # decoded first differences beyond the original's maximum
    acceleration_outliers: int  # decoded second differences beyond the original's maximum


def limit_violations(skeleton: Skeleton, channels: np.ndarray, tolerance: float = LIMIT_TOLERANCE_DEG) -> int:
    """Samples outside the (finite) joint limits."""
    lim = skeleton.limits
    if channels.size == 0 or not np.isfinite(lim).any():
        return 0
    return int(((channels < lim[:, 0] - tolerance) | (channels > lim[:, 1] + tolerance)).sum())


def _differences(channels: np.ndarray, rotation_mask: np.ndarray, order: int) -> np.ndarray:
    d = np.diff(channels, axis=0)
    d[:, rotation_mask] = wrap_degrees(d[:, rotation_mask])
    return np.diff(d, n=order - 1, axis=0) if order > 1 else d


def derivative_outliers(
    original: np.ndarray, decoded: np.ndarray, rotation_mask: np.ndarray, order: int, margin: float = DERIVATIVE_MARGIN
) -> int:
    """Decoded ``order``-th differences larger than (1 + margin) x the original's largest."""
    if original.shape[0] <= order:
        return 0
    bound = np.abs(_differences(original, rotation_mask, order)).max(axis=0) * (1.0 + margin)
    return int((np.abs(_differences(decoded, rotation_mask, order)) > bound + 1e-9).sum())


def naturalness(
    skeleton: Skeleton, original: np.ndarray, decoded: np.ndarray, margin: float = DERIVATIVE_MARGIN
) -> Naturalness:
    rot = skeleton.rotation_mask
    return Naturalness(
        limit_violations(skeleton, decoded),
        limit_violations(skeleton, original),
        derivative_outliers(original, decoded, rot, 1, margin),
        derivative_outliers(original, decoded, rot, 2, margin),
    )
