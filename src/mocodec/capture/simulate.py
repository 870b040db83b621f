"""Sensor logs made from motions, so the capture chain runs without hardware.

A motion of the built-in human model gives its tracker frames exactly by forward kinematics.
A clip on another skeleton (CMU BVH or ASF/AMC) is read by its joints' positions: scaled to the
model's stature and set on the floor, the hips, head and forearms give tracker frames (the
hips' frame from the line between the hip joints, the head's from the neck-to-head direction,
each forearm's along the elbow-to-wrist direction). The transmitter sits at a random place,
each tracker but the hips' is strapped on a little askew, and noise is added to every reading:
all of it seeded, so the same call gives the same log.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mocodec import rotations
from mocodec.capture.converter import MOUNTS, Converter, glove_channels, pose, rot_x, rot_y, rot_z
from mocodec.capture.sensors import FINGERS, TRACKERS, SensorLog
from mocodec.errors import MocodecError
from mocodec.human import human_model
from mocodec.kinematics import forward_kinematics
from mocodec.motion import Motion

GLOVE_NOISE = 0.016  # sigma of a normalised glove value (1.1 deg of 70, 003 §4.2.2)

#: Joints of other skeletons a tracker frame is made from: hips (left, right), neck, head,
#: (elbow, wrist) per side. CMU BVH names first, then CMU ASF names.
SOURCES: tuple[dict[str, Any], ...] = (
    {
        "hips": ("lThigh", "rThigh"),
        "neck": "neck",
        "head": "head",
        "left": ("lForeArm", "lHand"),
        "right": ("rForeArm", "rHand"),
    },
    {
        "hips": ("lfemur", "rfemur"),
        "neck": "lowerneck",
        "head": "head",
        "left": ("lradius", "lwrist"),
        "right": ("rradius", "rwrist"),
    },
)


def _random_rotation(rng, sigma_deg: float, n: int | None = None) -> np.ndarray:
    shape = (3,) if n is None else (n, 3)
    v = rng.normal(0.0, np.radians(sigma_deg), shape)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    axis = np.where(angle > 0, v / np.maximum(angle, 1e-300), [1.0, 0.0, 0.0])
    q = np.concatenate([np.cos(angle / 2), axis * np.sin(angle / 2)], axis=-1)
    return rotations.quat_to_matrix(q)


def model_frames(motion: Motion) -> dict[str, np.ndarray]:
    """Tracker segment frames (n, 4, 4) of a motion of the built-in model, by FK."""
    sk = motion.skeleton
    pos, quat = forward_kinematics(sk, motion.channels)
    rot = rotations.quat_to_matrix(quat)
    return {t: pose(rot[:, sk.index(seg)], pos[:, sk.index(at)]) for t, (seg, at) in MOUNTS.items()}


def _frame(y: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotations whose y axis is ``y`` and whose x axis is as near ``x_hint`` as can be."""
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    x = x_hint - np.einsum("ij,ij->i", x_hint, y)[:, None] * y
    x = x / np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=2)


def retargeted_frames(motion: Motion) -> dict[str, np.ndarray]:
    """Tracker segment frames of a clip on another skeleton (see the module doc)."""
    sk = motion.skeleton
    names = next((m for m in SOURCES if all(n in sk.names for n in _joint_names(m))), None)
    if names is None:
        raise MocodecError(
            f"cannot simulate sensors on skeleton {sk.name or '(unnamed)'}: it lacks the joints of "
            "a CMU BVH or ASF skeleton (hips, neck, head, forearms, wrists)"
        )
    pos = motion.positions_m()
    at = {n: pos[:, sk.index(n)] for n in _joint_names(names)}
    model = human_model()
    rest = forward_kinematics(model, np.zeros((1, model.num_channels)))[0][0]
    source_height = np.ptp(motion.skeleton.rest_positions[:, 1]) / sk.units_per_metre
    scale = float(np.ptp(rest[:, 1]) / source_height)
    floor = pos[:, :, 1].min()
    lhip, rhip = (at[n] for n in names["hips"])
    root = (lhip + rhip) / 2
    offset = np.array([0.0, rest[model.index("root"), 1] - scale * (np.median(root[:, 1]) - floor), 0.0])

    def place(p):
        return scale * (p - [0.0, floor, 0.0]) + offset

    across = lhip - rhip  # toward the figure's left: +X of the model
    up = np.tile([0.0, 1.0, 0.0], (len(root), 1))
    frames = {"hips": pose(_frame(up, across), place(root))}
    head_dir = at[names["head"]] - at[names["neck"]]
    head_top = place(at[names["head"]]) + 0.1 * head_dir / np.linalg.norm(head_dir, axis=1, keepdims=True)
    frames["head"] = pose(_frame(head_dir, across), head_top)
    for side in ("left", "right"):
        elbow, wrist = (at[n] for n in names[side])
        frames[f"{side}_wrist"] = pose(_frame(elbow - wrist, across), place(wrist))
    return frames


def _joint_names(names: dict) -> list[str]:
    return [*names["hips"], names["neck"], names["head"], *names["left"], *names["right"]]


def simulate(
    motion: Motion, noise_deg: float = 0.5, noise_cm: float = 0.3, seed: int = 0, glove_noise: float = GLOVE_NOISE
) -> SensorLog:
    """The sensor log the minimal configuration would record of ``motion``."""
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    model = human_model()
    on_model = sk.isclose(model)
    frames = model_frames(motion) if on_model else retargeted_frames(motion)
    transmitter = pose(_random_rotation(rng, 30.0), rng.uniform(-1.0, 1.0, 3))  # sensor world in model world
    # strapped on askew, but for the hip tracker: its reading also fixes the transmitter's frame
    # in calibration, and the two cannot both be told from it (003 §4.3.3)
    mounts = {
        t: np.eye(4) if t == "hips" else pose(_random_rotation(rng, 5.0), rng.normal(0.0, 0.01, 3)) for t in TRACKERS
    }
    rest = model_frames(Motion(model, motion.fps, np.zeros((1, model.num_channels))))
    to_sensor = np.linalg.inv(transmitter)
    n = motion.num_frames
    trackers, calibration = {}, {}
    for t in TRACKERS:
        calibration[t] = to_sensor @ rest[t][0] @ mounts[t]
        reading = to_sensor @ frames[t] @ mounts[t]
        reading[:, :3, :3] = reading[:, :3, :3] @ _random_rotation(rng, noise_deg, n)
        reading[:, :3, 3] += rng.normal(0.0, noise_cm / 100.0, (n, 3))
        trackers[t] = reading
    gloves = (
        {
            f"{side}_glove": np.clip(_glove(motion, side) + rng.normal(0.0, glove_noise, (n, len(FINGERS))), 0, 1)
            for side in ("left", "right")
        }
        if on_model
        else {f"{side}_glove": np.full((n, len(FINGERS)), 0.2) for side in ("left", "right")}
    )
    return SensorLog(np.arange(n) / motion.fps, trackers, gloves, calibration)


def _glove(motion: Motion, side: str) -> np.ndarray:
    """Each finger's mean flexion, normalised to its joints' limits (what a glove reports)."""
    sk = motion.skeleton
    out = []
    for finger in FINGERS:
        idx = [sk.channel_index(n) for n in glove_channels(side, finger)]
        lim = sk.limits[idx]
        out.append(((motion.channels[:, idx] - lim[:, 0]) / (lim[:, 1] - lim[:, 0])).mean(axis=1))
    return np.clip(np.stack(out, axis=1), 0.0, 1.0)


def random_poses(frames: int, seed: int = 0) -> Motion:
    """Poses of the human model within its limits and within what the minimal configuration
    can tell (for round-trip tests): the spine bent evenly between root and torso and the
    head's pitch and roll shared with the neck (4-15), wrists and hip twist at zero, the feet
    where they stand at calibration (the hips turn at most 25 degrees), fingers bent as a glove
    reports them (each finger's joints at one fraction of their ranges)."""
    rng = np.random.default_rng(seed)
    sk = human_model()
    ch = np.zeros((frames, sk.num_channels))
    at = {name: k for k, name in enumerate(sk.channel_names)}

    def put(name, values):
        ch[:, at[name]] = values

    yaw, pitch, roll = rng.uniform(-25, 25, frames), rng.uniform(-30, 30, frames), rng.uniform(-20, 20, frames)
    for joint in ("root", "torso"):
        put(f"{joint}.Xrotation", pitch / 2)
        put(f"{joint}.Zrotation", roll / 2)
    put("root.Yrotation", yaw)
    put("root.Yposition", -rng.uniform(0.0, 0.15, frames))  # a slight crouch
    hx, hz = rng.uniform(-40, 40, frames), rng.uniform(-20, 20, frames)
    for joint in ("neck", "head"):
        put(f"{joint}.Xrotation", hx / 2)
        put(f"{joint}.Zrotation", hz / 2)
    put("head.Yrotation", rng.uniform(-60, 60, frames))
    for side in ("left", "right"):
        first = sk.channel_offsets[sk.index(f"{side}_shoulder")]
        ch[:, first : first + 3] = np.stack(
            [rng.uniform(-180, 180, frames), rng.uniform(-120, -10, frames), rng.uniform(-90, 90, frames)], 1
        )
        put(f"{side}_elbow.Xrotation", rng.uniform(-140, -20, frames))
        put(f"{side}_elbow.Yrotation", rng.uniform(-60, 60, frames))
        for finger in FINGERS:
            s = rng.uniform(0, 1, frames)
            for name in glove_channels(side, finger):
                low, high = sk.limits[at[name]]
                put(name, low + s * (high - low))
    rest = forward_kinematics(sk, np.zeros((1, sk.num_channels)))[0][0]
    r_root = rot_y(np.radians(yaw)) @ rot_x(np.radians(pitch / 2)) @ rot_z(np.radians(roll / 2))
    p_root = rest[sk.index("root")] + ch[:, 3:6]
    legs = Converter(sk)
    for side in ("left", "right"):
        legs.solve_leg(side, rest[sk.index(f"{side}_ankle")], p_root, r_root, ch)
    rot = sk.rotation_mask
    ch[:, rot] = np.clip(ch[:, rot], sk.limits[rot, 0], sk.limits[rot, 1])
    return Motion(sk, 120.0, ch)
