"""A motion: a skeleton, a frame rate and the channel values of every frame."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from mocodec import kinematics, rotations
from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton


def wrap_degrees(x: np.ndarray) -> np.ndarray:
    """Map angles to [-180, 180) (floor form: three times faster than ``%`` on arrays)."""
    x = np.asarray(x)
    return x - 360.0 * np.floor((x + 180.0) / 360.0)


#: Under a turned root, a joint's rotation in frame 0 is its rest pose's to within this cosine
#: of half the angle between them (about 1.6e-4 degrees: a float32 file's rounding).
REST_COSINE = 1.0 - 1e-12


def _same_turns(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the unit quaternions ``a`` and ``b`` (joints, 4) turn alike (REST_COSINE)."""
    return bool(np.abs(np.sum(a * b, axis=-1)).min(initial=1.0) >= REST_COSINE)


@dataclass(frozen=True, eq=False)
class Motion:
    """``channels`` is float64 ``(frames, skeleton.num_channels)``: degrees for rotations,
    skeleton units for translations, in the channel order of the skeleton."""

    skeleton: Skeleton
    fps: float
    channels: np.ndarray

    def __post_init__(self):
        ch = np.asarray(self.channels, dtype=np.float64)
        if ch.ndim != 2 or ch.shape[1] != self.skeleton.num_channels:
            raise ValueError(f"channels must be (frames, {self.skeleton.num_channels}), got {ch.shape}")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be positive, got {self.fps}")
        object.__setattr__(self, "channels", ch)
        object.__setattr__(self, "fps", float(self.fps))

    # ----- size -----------------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        return self.channels.shape[0]

    def __len__(self) -> int:
        return self.num_frames

    @property
    def num_channels(self) -> int:
        return self.channels.shape[1]

    @property
    def duration(self) -> float:
        """Seconds covered by the frames (``frames / fps``)."""
        return self.num_frames / self.fps

    @property
    def time_span(self) -> float:
        """Seconds from the first frame to the last (``(frames - 1) / fps``): the length of the
        animation the frames sample."""
        return max(self.num_frames - 1, 0) / self.fps

    @property
    def raw_bits(self) -> int:
        """Size at 32-bit floats for every channel of every frame: the compression reference."""
        return 32 * self.channels.size

    @property
    def raw_bitrate(self) -> float:
        """Bits per second at 32-bit floats."""
        return 32.0 * self.num_channels * self.fps

    # ----- selection ------------------------------------------------------------------
    def __getitem__(self, frames: slice) -> Motion:
        """Frames by a slice: ``motion[100:200]`` (steps allowed; fps divides by the step)."""
        if not isinstance(frames, slice):
            raise TypeError("index a Motion with a slice of frames, e.g. motion[10:20]")
        step = frames.step or 1
        if step < 1:
            raise ValueError("frame step must be positive")
        return Motion(self.skeleton, self.fps / step, self.channels[frames].copy())

    @property
    def starts_at_rest(self) -> bool:
        """Whether frame 0 is the skeleton's rest pose and frame 1 is not: the bind pose
        exporters write before a take. Every rotation is exactly 0 there; or a game export's
        rotation-only root turns it to the engine's axes (its rotations,
        :attr:`Skeleton.root_turn_mask`, frame 1's) and every joint below stands as at rest
        (:func:`kinematics.rest_frame`, to REST_COSINE)."""
        sk = self.skeleton
        rot, turn = sk.rotation_mask, sk.root_turn_mask
        if self.num_frames < 2 or not rot.any():
            return False
        first, second = self.channels[0], self.channels[1]
        if not first[turn].any():
            return not first[rot].any() and bool(second[rot].any())
        if not np.array_equal(first[turn], second[turn]):
            return False
        frames = np.vstack((kinematics.rest_frame(sk, second, turned=True), first, second))
        rest, zero, one = kinematics.local_quaternions(sk, frames)
        return _same_turns(rest[1:], zero[1:]) and not _same_turns(rest[1:], one[1:])

    def channel_indices(self, keys) -> np.ndarray:
        """Channel indices for ``keys``: ints, ``"joint.Xrotation"`` names or joint names (all
        channels of that joint)."""
        sk = self.skeleton
        out: list[int] = []
        for key in [keys] if isinstance(keys, (str, int, np.integer)) else keys:
            if isinstance(key, (int, np.integer)):
                if not -sk.num_channels <= key < sk.num_channels:
                    raise IndexError(f"channel {key} out of range ({sk.num_channels} channels)")
                out.append(int(key) % sk.num_channels)
            elif "." in key:
                out.append(sk.channel_index(key))
            else:
                j = sk.index(key)
                out.extend(range(sk.channel_offsets[j], sk.channel_offsets[j + 1]))
        return np.array(out, dtype=np.int64)

    def select_channels(self, keys) -> np.ndarray:
        """The ``(frames, k)`` values of the channels named by ``keys`` (see channel_indices)."""
        return self.channels[:, self.channel_indices(keys)]

    def with_channels(self, channels: np.ndarray) -> Motion:
        return replace(self, channels=np.asarray(channels, dtype=np.float64))

    # ----- kinematics -----------------------------------------------------------------
    def positions(self) -> np.ndarray:
        """Global pivot positions ``(frames, joints, 3)`` in skeleton units."""
        return kinematics.forward_kinematics(self.skeleton, self.channels)[0]

    def root_positions(self) -> np.ndarray:
        """Joint 0's world position ``(frames, 3)`` in skeleton units: its offset plus its
        translation channels (no forward kinematics: the root has no parent)."""
        root, first = self.skeleton.joints[0], self.skeleton.channel_offsets[0]
        out = np.tile(np.asarray(root.offset, dtype=np.float64), (self.num_frames, 1))
        for k, axis in enumerate("XYZ"):
            if f"{axis}position" in root.channels:
                out[:, k] += self.channels[:, first + root.channels.index(f"{axis}position")]
        return out

    def positions_m(self) -> np.ndarray:
        """Global pivot positions in metres."""
        return self.positions() / self.skeleton.units_per_metre

    def global_quaternions(self) -> np.ndarray:
        return kinematics.forward_kinematics(self.skeleton, self.channels)[1]

    # ----- comparison -----------------------------------------------------------------
    def difference(self, other: Motion, atol_degrees: float = 1e-6, atol_units: float = 1e-6) -> str | None:
        """A one-line description of the first difference, or None. Angles compare modulo 360."""
        d = self.skeleton.difference(other.skeleton, atol=atol_units)
        if d:
            return f"skeleton: {d}"
        if not np.isclose(self.fps, other.fps, rtol=1e-9):
            return f"fps {self.fps} vs {other.fps}"
        if self.channels.shape != other.channels.shape:
            return f"shape {self.channels.shape} vs {other.channels.shape}"
        diff = self.channels - other.channels
        rot = self.skeleton.rotation_mask
        diff[:, rot] = wrap_degrees(diff[:, rot])
        diff = np.abs(diff)
        tol = np.where(rot, atol_degrees, atol_units)
        bad = diff > tol
        if bad.any():
            f, c = np.argwhere(bad)[0]
            return (
                f"frame {f}, channel {self.skeleton.channel_names[c]}: "
                f"{self.channels[f, c]!r} vs {other.channels[f, c]!r}"
            )
        return None

    def isclose(self, other: Motion, atol_degrees: float = 1e-6, atol_units: float = 1e-6) -> bool:
        """Equal skeletons and fps, channels within the tolerances (angles modulo 360)."""
        return self.difference(other, atol_degrees, atol_units) is None

    def continuous(self) -> Motion:
        """The same poses with every angle curve as continuous as the Euler form allows.

        Each joint with three rotation channels takes, frame by frame, whichever of its two
        equivalent angle triples (shifted by turns of 360) lies nearest the previous frame's;
        other rotation channels are unwrapped. Forward kinematics is unchanged, but the 180
        and 360 degree jumps of captured data (gimbal flips, wraps at +-180) are gone, which
        is what transform and predictive coders need."""
        out = self.channels.copy()
        if self.num_frames < 2:
            return replace(self, channels=out)
        followed, proper, unwrapped = _followed_triples(self.skeleton)
        out[:, unwrapped] = np.unwrap(out[:, unwrapped], period=360.0, axis=0)
        _follow_all(np.ascontiguousarray(self.channels, dtype=np.float64), followed, proper, out)
        return replace(self, channels=out)

    def aligned_to(self, reference: Motion) -> Motion:
        """The same poses, each 3-axis joint's angles given as whichever equivalent triple
        (shifted by turns of 360) lies nearest ``reference``'s in that frame, and other angles
        wrapped to within 180 degrees of it. Channel-space errors then measure pose differences
        only, not the choice between equivalent Euler angles."""
        sk = self.skeleton
        rot = sk.rotation_mask
        out = self.channels.copy()
        out[:, rot] = reference.channels[:, rot] + wrap_degrees(out[:, rot] - reference.channels[:, rot])
        for j, joint in enumerate(sk.joints):
            if len(joint.rotation_order) != 3 or len(set(joint.rotation_order)) < 2:
                continue
            idx = sk.channel_offsets[j] + np.array(joint.rotation_channel_indices())
            out[:, idx] = _nearest_euler(self.channels[:, idx], joint.rotation_order, reference.channels[:, idx])
        return replace(self, channels=out)

    # ----- resampling -----------------------------------------------------------------
    def resample(self, fps: float) -> Motion:
        """The motion at another frame rate over the same time span.

        Joints with three rotation channels are interpolated by quaternion slerp and turned
        back into Euler angles, choosing of the two equivalent angle triples (and their 360
        degree turns) the one nearest the linear interpolation, so curves stay continuous.
        Translations and joints with one or two rotation axes interpolate linearly.
        """
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be positive, got {fps}")
        n_old = self.num_frames
        if n_old < 2:
            return replace(self, fps=float(fps))
        n_new = int(np.floor((n_old - 1) * fps / self.fps + 1e-9)) + 1
        src = np.arange(n_new) * (self.fps / fps)
        i0 = np.minimum(np.floor(src).astype(np.int64), n_old - 2)
        frac = src - i0
        sk = self.skeleton
        rot = sk.rotation_mask
        unwrapped = self.channels.copy()
        unwrapped[:, rot] = np.unwrap(unwrapped[:, rot], period=360.0, axis=0)
        linear = unwrapped[i0] * (1 - frac)[:, None] + unwrapped[i0 + 1] * frac[:, None]
        out = linear.copy()
        for j, joint in enumerate(sk.joints):
            if len(joint.rotation_order) != 3:
                continue
            first = sk.channel_offsets[j]
            idx = first + np.array(joint.rotation_channel_indices())
            q = rotations.euler_to_quat(self.channels[:, idx], joint.rotation_order)
            qs = rotations.quat_slerp(q[i0], q[i0 + 1], frac)
            out[:, idx] = _nearest_euler(
                rotations.quat_to_euler(qs, joint.rotation_order), joint.rotation_order, linear[:, idx]
            )
        return Motion(sk, float(fps), out)


@lru_cache(maxsize=64)
def _followed_triples(sk: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The channels ``(n, 3)`` of the joints :meth:`Motion.continuous` follows as triples (three
    rotation channels, two axes or more), whether each order is proper, and the other rotation
    channels, which it unwraps."""
    followed = [
        (sk.channel_offsets[j] + np.array(joint.rotation_channel_indices()), joint.rotation_order)
        for j, joint in enumerate(sk.joints)
        if len(joint.rotation_order) == 3 and len(set(joint.rotation_order)) >= 2
    ]
    idx = np.array([i for i, _ in followed], dtype=np.int64).reshape(-1, 3)
    proper = np.array([order[0] == order[2] for _, order in followed], dtype=np.bool_)
    unwrapped = sk.rotation_mask.copy()
    unwrapped[idx.ravel()] = False
    for array in (idx, proper, unwrapped):
        array.setflags(write=False)
    return idx, proper, unwrapped


@kernel
def _follow_all(channels, idx, proper, out):
    """:func:`follow_nearest` of each joint's triple ``channels[:, idx[j]]`` into ``out``."""
    for j in range(idx.shape[0]):
        triple = np.empty((channels.shape[0], 3))
        for m in range(3):
            triple[:, m] = channels[:, idx[j, m]]
        followed = follow_nearest(triple, proper[j])
        for m in range(3):
            out[:, idx[j, m]] = followed[:, m]


def continuous_triples(angles: np.ndarray, order: str) -> np.ndarray:
    """Euler triples ``(T, 3)`` in ``order``, each frame replaced by whichever of its two
    equivalent triples, shifted by turns of 360, lies nearest the previous frame's (frame 0
    stays): the same rotations, as continuous curves."""
    return follow_nearest(np.ascontiguousarray(angles, dtype=np.float64), order[0] == order[2])


@kernel
def follow_nearest(angles, proper):
    """Frame by frame, of the triple and its equivalent (a+180, 180-b, c+180), or (a+180, -b,
    c+180) for a ``proper`` Euler order, shifted by turns of 360, the one nearest the previous."""
    out = np.empty_like(angles)
    out[0] = angles[0]
    shifted = np.empty(3)
    cand = np.empty(3)
    for f in range(1, angles.shape[0]):
        best = np.inf
        for c in range(2):
            if c == 0:
                cand[0], cand[1], cand[2] = angles[f, 0], angles[f, 1], angles[f, 2]
            else:
                cand[0], cand[2] = angles[f, 0] + 180.0, angles[f, 2] + 180.0
                cand[1] = -angles[f, 1] if proper else 180.0 - angles[f, 1]
            cost = 0.0
            for k in range(3):
                d = cand[k] - out[f - 1, k]
                d -= 360.0 * np.floor((d + 180.0) / 360.0)
                shifted[k] = out[f - 1, k] + d
                cost += abs(d)
            if cost < best:
                best = cost
                out[f] = shifted
    return out


def _nearest_euler(angles: np.ndarray, order: str, reference: np.ndarray) -> np.ndarray:
    """Of the two Euler triples of each rotation, shifted by turns of 360, the one nearest
    ``reference``. Tait-Bryan: (a, b, c) ~ (a+180, 180-b, c+180); proper: (a+180, -b, c+180)."""
    alt = angles.copy()
    alt[:, 0] += 180.0
    alt[:, 2] += 180.0
    alt[:, 1] = (-angles[:, 1]) if order[0] == order[2] else (180.0 - angles[:, 1])
    best = reference + wrap_degrees(angles - reference)
    other = reference + wrap_degrees(alt - reference)
    take = np.abs(other - reference).sum(axis=1) < np.abs(best - reference).sum(axis=1)
    best[take] = other[take]
    return best
