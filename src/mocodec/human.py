"""The built-in human model of 000/003 chapter 3: Table 3-1 joints, Table 3-2 segments and the
eight groups of Table 5-1.

Readings of the thesis made here (its text is OCR and its figures are lost):

* Frame. The thesis uses a left-handed frame and row vectors, so its cascades (3-1)-(3-14)
  apply the leftmost matrix first. We use the right-handed, Y-up, +Z-forward frame of BVH/ASF
  (the figure's left at +X) with column vectors, so each cascade reads right to left: the root's
  ``Rz(t02) Rx(t01) Ry(t00) T`` is rotation order ``YXZ`` on channels (t00, t01, t02). Angle
  signs follow the table's limits literally.
* Offsets. Table 3-1's normalised offsets did not survive the OCR; we set them from the segment
  sizes of Table 3-2 (offset = normalised offset x parent segment size, as 3.2.2 defines) with
  the figure standing, arms hanging, palms facing the thighs: stature 1.74 m, hip joints
  0.96 m, shoulders 1.41 m, wrists 0.87 m.
* Numbering. Table 3-1 numbers its joints 0-45 but lists 44 (4 and 42 are absent; the text's
  hips ``i = 40, 44`` disagree with the table's 39, 43). We keep the 44 listed joints with the
  table's numbers (``THESIS_INDEX``), 80 DOFs in all, and add end sites (head top, toes,
  finger tips) so every segment has an end point.
* Thumb. (3-11), (3-12) rotate about the axes (0.5, 0, 1) and (1, 0, -0.5); we express them
  as ``C Rx Rz C^-1`` with a fixed frame ``C`` whose X is the second axis and Z the first
  (mirrored in X for the right hand).
* Table 5-1 gives the groups 7, 5, 8, 19, 8, 19, 7, 7 DOFs, while Table 3-1's joints give
  9, 5, 7, 19, 7, 19, 7, 7 (the same 80); the groups here follow the joints.
"""

from __future__ import annotations

import numpy as np

from mocodec import rotations
from mocodec.skeleton import Joint, Skeleton

INF = np.inf

# Table 3-2: segment -> (size x, y, z in metres, mass in kg, shape). Each joint drives one segment.
SEGMENTS: dict[str, tuple[tuple[float, float, float], float, str]] = {
    "hips": ((0.07, 0.1, 0.25), 15.0, "box"),
    "torso": ((0.32, 0.39, 0.3), 22.0, "box"),
    "neck": ((0.1, 0.07, 0.1), 1.0, "cylinder"),
    "head": ((0.15, 0.22, 0.2), 5.0, "sphere"),
    "upper_arm": ((0.15, 0.31, 0.15), 2.1, "truncated cone"),
    "lower_arm": ((0.1, 0.23, 0.1), 1.2, "truncated cone"),
    "palm": ((0.03, 0.085, 0.036), 0.25, "sphere"),
    "thumb1": ((0.01, 0.025, 0.01), 0.03, "cylinder"),
    "thumb2": ((0.01, 0.02, 0.01), 0.03, "cylinder"),
    "index1": ((0.01, 0.025, 0.01), 0.03, "cylinder"),
    "index2": ((0.01, 0.022, 0.01), 0.03, "cylinder"),
    "index3": ((0.01, 0.02, 0.01), 0.03, "cylinder"),
    "middle1": ((0.01, 0.028, 0.01), 0.03, "cylinder"),
    "middle2": ((0.01, 0.026, 0.01), 0.03, "cylinder"),
    "middle3": ((0.01, 0.02, 0.01), 0.03, "cylinder"),
    "ring1": ((0.01, 0.024, 0.01), 0.03, "cylinder"),
    "ring2": ((0.01, 0.022, 0.01), 0.03, "cylinder"),
    "ring3": ((0.01, 0.02, 0.01), 0.03, "cylinder"),
    "little1": ((0.01, 0.019, 0.01), 0.03, "cylinder"),
    "little2": ((0.01, 0.017, 0.01), 0.03, "cylinder"),
    "little3": ((0.01, 0.01, 0.01), 0.03, "cylinder"),
    "upper_leg": ((0.2, 0.47, 0.2), 7.5, "truncated cone"),
    "lower_leg": ((0.15, 0.44, 0.15), 3.5, "truncated cone"),
    "foot": ((0.1, 0.05, 0.15), 1.0, "box"),
}

# Table 5-1 as printed: group -> (reference number, joints, segments, DOFs).
TABLE_5_1 = {
    "torso": (0, 2, 2, 7),
    "head": (1, 2, 2, 5),
    "left_arm": (2, 3, 3, 8),
    "left_hand": (3, 14, 14, 19),
    "right_arm": (4, 3, 3, 8),
    "right_hand": (5, 14, 14, 19),
    "left_leg": (6, 3, 3, 7),
    "right_leg": (7, 3, 3, 7),
}

_FINGERS = (("index", 0.5), ("middle", 0.15), ("ring", -0.2), ("little", -0.5))


def _rot(axes: str) -> tuple[str, ...]:
    return tuple(f"{a}rotation" for a in axes)


def _thumb_axis(mirror: float) -> tuple[float, float, float]:
    """Euler angles (order ZYX) of the frame whose X is (1, 0, -0.5) and Z is (0.5, 0, 1)."""
    x = np.array([mirror * 1.0, 0.0, -0.5])
    z = np.array([mirror * 0.5, 0.0, 1.0])
    x, z = x / np.linalg.norm(x), z / np.linalg.norm(z)
    y = np.cross(z, x)
    frame = np.stack((x, y, z), axis=1)
    if np.linalg.det(frame) < 0:  # mirrored hand: keep a proper rotation
        frame[:, 1] *= -1
    about_z, about_y, about_x = (float(a) for a in rotations.matrix_to_euler(frame, "ZYX"))
    return about_z, about_y, about_x


class _ModelBuilder:
    def __init__(self):
        self.joints: list[Joint] = []
        self.segment: dict[str, str] = {}
        self.thesis_index: dict[str, int] = {}

    def add(
        self,
        name,
        parent,
        norm_offset,
        parent_segment,
        channels=(),
        order="",
        limits=(),
        part=None,
        segment=None,
        index=None,
        axis=(0.0, 0.0, 0.0),
    ) -> str:
        size = np.array(SEGMENTS[parent_segment][0]) if parent_segment else np.zeros(3)
        offset = tuple(float(v) for v in np.asarray(norm_offset) * size)
        p = self.names().index(parent) if parent else -1
        self.joints.append(Joint(name, p, offset, tuple(channels), order, axis, "ZYX", tuple(limits), part))
        if segment:
            self.segment[name] = segment
        if index is not None:
            self.thesis_index[name] = index
        return name

    def names(self) -> list[str]:
        return [j.name for j in self.joints]


def _arm(b: _ModelBuilder, side: str, sign: float, base: int) -> None:
    arm, hand = f"{side}_arm", f"{side}_hand"
    shoulder = b.add(
        f"{side}_shoulder",
        "torso",
        (sign * 0.6, 0.9, 0.0),
        "torso",
        _rot("YZY"),
        "YZY",
        ((-180, 180), (-160, 0), (-180, 180)),
        arm,
        "upper_arm",
        base,
    )
    elbow = b.add(
        f"{side}_elbow",
        shoulder,
        (0, -1, 0),
        "upper_arm",
        _rot("XY"),
        "XY",
        ((-180, 0), (-90, 90)),
        arm,
        "lower_arm",
        base + 1,
    )
    wrist = b.add(
        f"{side}_wrist", elbow, (0, -1, 0), "lower_arm", _rot("ZX"), "ZX", ((-60, 70), (-30, 30)), arm, "palm", base + 2
    )
    axis = _thumb_axis(sign)
    t1 = b.add(
        f"{side}_thumb1",
        wrist,
        (0, -0.35, 0.8),
        "palm",
        _rot("XZ"),
        "XZ",
        ((0, 60), (-20, 60)),
        hand,
        "thumb1",
        base + 3,
        axis,
    )
    t2 = b.add(f"{side}_thumb2", t1, (0, -1, 0), "thumb1", _rot("X"), "X", ((0, 60),), hand, "thumb2", base + 4, axis)
    b.add(f"{side}_thumb_tip", t2, (0, -1, 0), "thumb2", part=hand)
    for k, (finger, spread) in enumerate(_FINGERS):
        idx = base + 5 + 3 * k
        f1 = b.add(
            f"{side}_{finger}1",
            wrist,
            (0, -1, spread),
            "palm",
            _rot("XZ"),
            "XZ",
            ((-5, 5), (0, 60)),
            hand,
            f"{finger}1",
            idx,
        )
        f2 = b.add(
            f"{side}_{finger}2", f1, (0, -1, 0), f"{finger}1", _rot("Z"), "Z", ((0, 75),), hand, f"{finger}2", idx + 1
        )
        f3 = b.add(
            f"{side}_{finger}3", f2, (0, -1, 0), f"{finger}2", _rot("Z"), "Z", ((0, 45),), hand, f"{finger}3", idx + 2
        )
        b.add(f"{side}_{finger}_tip", f3, (0, -1, 0), f"{finger}3", part=hand)


def _leg(b: _ModelBuilder, side: str, sign: float, base: int) -> None:
    leg = f"{side}_leg"
    hip = b.add(
        f"{side}_hip",
        "root",
        (sign * 1.0, -1.0, 0.0),
        "hips",
        _rot("XYZ"),
        "XYZ",
        ((-90, 90), (-15, 15), (-30, 15)),
        leg,
        "upper_leg",
        base,
    )
    knee = b.add(f"{side}_knee", hip, (0, -1, 0), "upper_leg", _rot("X"), "X", ((0, 180),), leg, "lower_leg", base + 1)
    ankle = b.add(
        f"{side}_ankle",
        knee,
        (0, -1, 0),
        "lower_leg",
        _rot("XYZ"),
        "XYZ",
        ((-30, 30), (-30, 30), (-15, 15)),
        leg,
        "foot",
        base + 2,
    )
    b.add(f"{side}_toe", ankle, (0, -1, 1), "foot", part=leg)


def human_model(name: str = "male") -> Skeleton:
    """The thesis's simplified human figure (46 joint numbers, 44 joints, 80 DOFs), in metres.

    At zero channels it stands upright on the floor (y = 0), facing +Z.
    """
    if name != "male":
        raise ValueError(
            f"unknown human model {name!r}; available: 'male' (Table 3-2 gives only the male segment parameters)"
        )
    b = _ModelBuilder()
    pos = ("Xposition", "Yposition", "Zposition")
    b.joints.append(
        Joint(
            "root",
            -1,
            (0.0, 1.06, 0.0),
            _rot("YXZ") + pos,
            "YXZ",
            limits=((-180, 180), (-40, 40), (-30, 30), (-INF, INF), (-INF, INF), (-INF, INF)),
            body_part="torso",
        )
    )
    b.segment["root"], b.thesis_index["root"] = "hips", 0
    b.add(
        "torso", "root", (0, 0, 0), "hips", _rot("YXZ"), "YXZ", ((-30, 30), (-40, 40), (-30, 30)), "torso", "torso", 1
    )
    b.add("neck", "torso", (0, 1, 0), "torso", _rot("XZ"), "XZ", ((-30, 30), (-15, 15)), "head", "neck", 2)
    b.add("head", "neck", (0, 1, 0), "neck", _rot("YXZ"), "YXZ", ((-90, 90), (-50, 50), (-15, 15)), "head", "head", 3)
    b.add("head_top", "head", (0, 1, 0), "head", part="head")
    _arm(b, "left", 1.0, 5)
    _arm(b, "right", -1.0, 22)
    _leg(b, "left", 1.0, 39)
    _leg(b, "right", -1.0, 43)
    metadata = {"segments": dict(b.segment), "thesis_index": dict(b.thesis_index), "mass_kg": 75.0}
    return Skeleton(tuple(b.joints), units_per_metre=1.0, name="human-male", metadata=metadata)


def segment_masses(skeleton: Skeleton) -> dict[str, float]:
    """Mass (kg) of the segment each joint drives, for the built-in model."""
    return {joint: SEGMENTS[seg][1] for joint, seg in skeleton.metadata["segments"].items()}
