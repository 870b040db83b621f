"""How far a written file's joints are from the motion it was written from: ``convert``'s check
that it never writes motion other than what it read.

A writer may rename joints (an ASF root is ``root``, a BVH or ASF end site is named after its
parent) and add some (ASF link bones), so each joint is found by name where it kept it, else as
the written joint whose path is closest to its own.
"""

from __future__ import annotations

import numpy as np

from mocodec.motion import Motion

#: The least precision a written file is checked to: 1e-4 cm.
TOLERANCE_M = 1e-6


def joint_error_m(original: Motion, written: Motion) -> float:
    """The largest distance (metres), over frames and joints, between a joint of ``original``
    and its counterpart read back from a written file (``written``)."""
    if written.num_frames != original.num_frames:
        return float("inf")
    ours = original.positions() / original.skeleton.units_per_metre
    theirs = written.positions() / written.skeleton.units_per_metre
    names = {name: k for k, name in enumerate(written.skeleton.names)}
    worst = 0.0
    for k, name in enumerate(original.skeleton.names):
        candidates = theirs[:, [names[name]]] if name in names else theirs
        distance = np.linalg.norm(candidates - ours[:, k : k + 1], axis=2).max(axis=0, initial=0.0)
        worst = max(worst, float(distance.min(initial=np.inf)))
    return worst


def tolerance_m(motion: Motion) -> float:
    """What a written file of ``motion`` must keep: 1e-4 cm, or the precision of the file it was
    read from where that is coarser (``skeleton.metadata["precision_m"]``)."""
    return max(TOLERANCE_M, float(motion.skeleton.metadata.get("precision_m", 0.0)))
