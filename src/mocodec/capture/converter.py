"""Sensor data to the joint angles of the built-in human model (003 §4.3.3, §4.4).

Closed-form inverse kinematics, vectorised over frames (no iterations, 003 §4.3.2):

* **Calibration** (4-3): in the calibration posture (the model's zero posture: standing, arms
  hanging) each tracker reads C. The hip tracker fixes the transmitter's frame against the
  model's world (W); every tracker's mounting is then O = F0^-1 W C, with F0 the segment frame
  it is strapped to in that posture, and a later reading S gives the segment frame W S O^-1.
  The thesis's caveat holds: a skew placement or a skew calibration posture can be absorbed,
  not both.
* **Spine** (4-4 to 4-15): the root's yaw from the hip tracker (4-8); the bend of the straight
  root-to-head chain from the head's position (4-11, 4-12), split evenly between root and
  torso (4-15); the neck takes half the head's pitch and roll (4-15) and the head the rest of
  its orientation, exactly (the thesis's (4-13), (4-14) with the split made exact). The thesis
  neglects that the neck's lean moves the head; we solve the spine a few times more, each time
  for the chain ending at the neck as it now leans, so the head lands on its tracker.
* **Arms** (4-16 to 4-32): the elbow by the cosine rule (4-19), the elbow position from the
  forearm tracker (4-20), the shoulder's first two angles from it (4-22), the upper-arm twist
  from the wrist position (4-25), the forearm twist from what remains (4-28), and the wrist
  correction that rotates the shoulder so the wrist lands on the tracker (4-29 to 4-32). The
  wrist joint itself is not measured (the thesis's five-DOF arm) and stays at zero.
* **Legs** (4-33 to 4-37): the feet stay where they stood at calibration, flat; the knee by the
  cosine rule, the hip's flexion and abduction from the ankle-to-hip vector, hip twist zero,
  and the ankle keeps the foot flat and facing as at calibration (the intent of (4-36), (4-37)).
* **Hands** (4-38): each finger's flexion joints at L + s (U - L) of their limits for the glove
  value s (the thesis's printed formula divides by U - L again; we read it as this linear map).
  Abduction is not measured and stays at zero.
* **Joint limits** (4-39, 4-40): every angle, and every acos argument, is soft-clipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec import rotations
from mocodec.capture.sensors import FINGERS, TRACKERS, SensorLog
from mocodec.capture.softclip import soft_clip
from mocodec.errors import MocodecError
from mocodec.human import human_model
from mocodec.kinematics import forward_kinematics
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

#: The segment frame each tracker is strapped to, and where on it (a joint's position).
MOUNTS = {
    "hips": ("root", "root"),
    "head": ("head", "head_top"),
    "left_wrist": ("left_elbow", "left_wrist"),
    "right_wrist": ("right_elbow", "right_wrist"),
}
ANGLE_MARGIN_DEG = 5.0  # soft-clip margin at joint limits
ACOS_MARGIN = 0.02  # soft-clip margin of acos arguments at +-1
SPINE_PASSES = 4  # the spine solved again with the neck's lean (the thesis: one pass)


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _apply(m: np.ndarray, v) -> np.ndarray:
    return np.einsum("...ij,...j->...i", m, np.broadcast_to(np.asarray(v, dtype=np.float64), m.shape[:-1]))


def _t(m: np.ndarray) -> np.ndarray:
    return np.swapaxes(m, -1, -2)


def _acos(x: np.ndarray) -> np.ndarray:
    return np.arccos(soft_clip(x, -1.0, 1.0, ACOS_MARGIN))


def pose(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    out = np.zeros(rot.shape[:-2] + (4, 4))
    out[..., :3, :3], out[..., :3, 3], out[..., 3, 3] = rot, pos, 1.0
    return out


@dataclass
class Calibration:
    """What the calibration posture tells (4-3): the transmitter's frame against the model's
    world, each tracker's mounting, and where the feet stand."""

    world: np.ndarray  # (4, 4): sensor world -> model world
    mounts: dict[str, np.ndarray]  # tracker -> O (4, 4)
    ankles: dict[str, np.ndarray]  # side -> (3,) fixed ankle position

    @classmethod
    def from_reference(cls, readings: dict[str, np.ndarray], skeleton: Skeleton) -> Calibration:
        pos, quat = forward_kinematics(skeleton, np.zeros((1, skeleton.num_channels)))
        rot = rotations.quat_to_matrix(quat[0])
        frames = {t: pose(rot[skeleton.index(seg)], pos[0, skeleton.index(at)]) for t, (seg, at) in MOUNTS.items()}
        world = frames["hips"] @ np.linalg.inv(readings["hips"])
        mounts = {t: np.linalg.inv(frames[t]) @ world @ readings[t] for t in TRACKERS}
        ankles = {side: pos[0, skeleton.index(f"{side}_ankle")] for side in ("left", "right")}
        return cls(world, mounts, ankles)

    def segment_frames(self, log: SensorLog) -> dict[str, np.ndarray]:
        """Each tracker's segment frame per frame (n, 4, 4), in the model's world."""
        return {t: self.world @ log.trackers[t] @ np.linalg.inv(self.mounts[t]) for t in TRACKERS}


class Converter:
    """Sensor logs to motions of the human model (see the module doc)."""

    def __init__(self, skeleton: Skeleton | None = None, wrist_correction: bool = True):
        self.sk = skeleton or human_model()
        self.wrist_correction = wrist_correction
        off = {j.name: np.array(j.offset) for j in self.sk.joints}
        self.off = off
        self.spine = float(off["torso"][1] + off["neck"][1] + off["head"][1])  # t + n + h
        self.head_len = float(off["head_top"][1])
        self.channel = {name: k for k, name in enumerate(self.sk.channel_names)}
        self.limits = self.sk.limits

    def convert(self, log: SensorLog, calibration: Calibration | None = None) -> Motion:
        cal = calibration or Calibration.from_reference(log.calibration, self.sk)
        frames = cal.segment_frames(log)
        n = log.num_frames
        ch = np.zeros((n, self.sk.num_channels))
        r_root, r_torso = self._spine(frames, ch)
        for side in ("left", "right"):
            self._arm(side, frames[f"{side}_wrist"], r_torso, frames["hips"][:, :3, 3], r_root, ch)
            self.solve_leg(side, cal.ankles[side], frames["hips"][:, :3, 3], r_root, ch)
            self._hand(side, log.gloves[f"{side}_glove"], ch)
        rot = self.sk.rotation_mask
        ch[:, rot] = soft_clip(ch[:, rot], self.limits[rot, 0], self.limits[rot, 1], ANGLE_MARGIN_DEG)
        return Motion(self.sk, log.fps, ch)

    def _set(self, ch: np.ndarray, joint: str, values: dict[str, np.ndarray]) -> None:
        for axis, v in values.items():
            ch[:, self.channel[f"{joint}.{axis}rotation"]] = np.degrees(v)

    # ----- spine (4-4 to 4-15) -------------------------------------------------------------------
    def _spine(self, frames, ch):
        hips, head = frames["hips"], frames["head"]
        p_root = hips[:, :3, 3]
        yaw = np.arctan2(hips[:, 0, 2], hips[:, 2, 2])  # (4-8)
        r_head = head[:, :3, :3]
        head_base = head[:, :3, 3] - _apply(r_head, (0.0, self.head_len, 0.0))  # (4-10)
        neck_top = head_base  # first as the thesis: a straight root-to-head chain
        length = self.spine
        for _ in range(SPINE_PASSES):
            v = _apply(_t(rot_y(yaw)), neck_top - p_root)  # (4-11)
            roll = np.arcsin(soft_clip(-v[:, 0] / length, -1.0, 1.0, ACOS_MARGIN))  # (4-12)
            pitch = np.arctan2(v[:, 2], v[:, 1])
            r_root = rot_y(yaw) @ rot_x(pitch / 2) @ rot_z(roll / 2)  # (4-15)
            r_torso = r_root @ rot_x(pitch / 2) @ rot_z(roll / 2)
            residual = _t(r_torso) @ r_head  # (4-13)
            hy, hx, hz = np.radians(rotations.matrix_to_euler(residual, "YXZ")).T  # (4-14)
            r_neck = r_torso @ rot_x(hx / 2) @ rot_z(hz / 2)
            # then again with the neck as it now leans: the chain ends where the neck does
            neck_top = head_base - _apply(r_neck, self.off["head"])
            length = self.spine - float(self.off["head"][1])
        ch[:, [self.channel[f"root.{a}position"] for a in "XYZ"]] = p_root - self.off["root"]
        self._set(ch, "root", {"Y": yaw, "X": pitch / 2, "Z": roll / 2})
        self._set(ch, "torso", {"X": pitch / 2, "Z": roll / 2})
        self._set(ch, "neck", {"X": hx / 2, "Z": hz / 2})
        y, x, z = np.radians(rotations.matrix_to_euler(_t(r_neck) @ r_head, "YXZ")).T
        self._set(ch, "head", {"Y": y, "X": x, "Z": z})
        return r_root, r_torso

    # ----- arms (4-16 to 4-32) ---------------------------------------------------------------------
    def _arm(self, side, wrist, r_torso, p_root, r_root, ch):
        u = -float(self.off[f"{side}_elbow"][1])
        lo = -float(self.off[f"{side}_wrist"][1])
        shoulder = p_root + _apply(r_root, self.off["torso"]) + _apply(r_torso, self.off[f"{side}_shoulder"])
        r_fore, w = wrist[:, :3, :3], wrist[:, :3, 3]
        w_loc = _apply(_t(r_torso), w - shoulder)
        d2 = np.einsum("ij,ij->i", w_loc, w_loc)
        elbow = -(np.pi - _acos((u * u + lo * lo - d2) / (2 * u * lo)))  # (4-19)
        e_loc = _apply(_t(r_torso), w - _apply(r_fore, (0.0, -lo, 0.0)) - shoulder)  # (4-20)
        rho = np.hypot(e_loc[:, 0], e_loc[:, 2])
        a2 = -np.arctan2(rho, -e_loc[:, 1])  # (4-22), (4-23)
        a1 = np.arctan2(e_loc[:, 2], -e_loc[:, 0])
        r = _apply(_t(rot_z(a2)) @ _t(rot_y(a1)), w_loc)  # (4-24)
        sign = np.where(-lo * np.sin(elbow) >= 0, 1.0, -1.0)
        a3 = np.arctan2(sign * r[:, 0], sign * r[:, 2])  # (4-25)
        r_sh = rot_y(a1) @ rot_z(a2) @ rot_y(a3)
        if self.wrist_correction:  # (4-29)-(4-32)
            reach = _apply(r_sh, (0.0, -u, 0.0)) + _apply(r_sh @ rot_x(elbow), (0.0, -lo, 0.0))
            r_sh = _rotation_between(reach, w_loc) @ r_sh
            a1, a2, a3 = _shoulder_angles(r_sh)
        m = _t(r_torso @ r_sh @ rot_x(elbow)) @ r_fore  # (4-26), (4-27)
        twist = np.arctan2(m[:, 0, 2], m[:, 0, 0])  # (4-28)
        first = self.sk.channel_offsets[self.sk.index(f"{side}_shoulder")]  # Y, Z, Y: by position
        ch[:, first : first + 3] = np.degrees(np.stack([a1, a2, a3], 1))
        self._set(ch, f"{side}_elbow", {"X": elbow, "Y": twist})

    # ----- legs (4-33 to 4-37) ---------------------------------------------------------------------
    def solve_leg(self, side, ankle, p_root, r_root, ch):
        """The leg of ``side`` reaching the fixed ``ankle`` position with the foot flat (into ``ch``)."""
        u = -float(self.off[f"{side}_knee"][1])
        lo = -float(self.off[f"{side}_ankle"][1])
        hip = p_root + _apply(r_root, self.off[f"{side}_hip"])
        h = _apply(_t(r_root), ankle - hip)  # hip to ankle, in the root's frame
        d2 = np.einsum("ij,ij->i", h, h)
        knee = np.pi - _acos((u * u + lo * lo - d2) / (2 * u * lo))  # (4-33), (4-35)
        y0, z0 = -u - lo * np.cos(knee), -lo * np.sin(knee)
        roll = np.arcsin(soft_clip(-h[:, 0] / y0, -1.0, 1.0, ACOS_MARGIN))  # (4-36)
        pitch = _wrap(np.arctan2(h[:, 2], h[:, 1]) - np.arctan2(z0, y0 * np.cos(roll)))  # (4-34), (4-35)
        r_leg = r_root @ rot_x(pitch) @ rot_z(roll) @ rot_x(knee)
        ax, ay, az = np.radians(rotations.matrix_to_euler(_t(r_leg), "XYZ")).T  # foot flat, (4-37)
        self._set(ch, f"{side}_hip", {"X": pitch, "Z": roll})
        self._set(ch, f"{side}_knee", {"X": knee})
        self._set(ch, f"{side}_ankle", {"X": ax, "Y": ay, "Z": az})

    # ----- hands (4-38) -----------------------------------------------------------------------------
    def _hand(self, side, glove, ch):
        for k, finger in enumerate(FINGERS):
            for name in glove_channels(side, finger):
                c = self.channel[name]
                low, high = self.limits[c]
                ch[:, c] = low + glove[:, k] * (high - low)


def glove_channels(side: str, finger: str) -> tuple[str, ...]:
    """The flexion channels a glove sensor drives (4-38): the thumb's two, a finger's three."""
    if finger == "thumb":
        return f"{side}_thumb1.Xrotation", f"{side}_thumb2.Xrotation"
    return tuple(f"{side}_{finger}{j}.Zrotation" for j in (1, 2, 3))


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotations taking the directions of ``a`` to those of ``b`` (4-29 to 4-31)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, np.einsum("ij,ij->i", a, b))
    axis = np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-300)[:, None], [1.0, 0.0, 0.0])
    q = np.concatenate([np.cos(angle / 2)[:, None], axis * np.sin(angle / 2)[:, None]], axis=1)
    return rotations.quat_to_matrix(q)


def _shoulder_angles(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """YZY angles of shoulder rotations, on the branch with the second angle <= 0 (the limits)."""
    a1, a2, a3 = np.radians(rotations.matrix_to_euler(r, "YZY")).T
    flip = a2 > 0
    return np.where(flip, _wrap(a1 + np.pi), a1), np.where(flip, -a2, a2), np.where(flip, _wrap(a3 + np.pi), a3)


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles (radians) in [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def convert(log: SensorLog, wrist_correction: bool = True) -> Motion:
    """The motion a sensor log captures, on the built-in human model."""
    if log.num_frames == 0:
        raise MocodecError("the sensor log has no frames")
    return Converter(wrist_correction=wrist_correction).convert(log)
