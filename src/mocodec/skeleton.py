"""The articulated skeleton: joints, their channels, rest offsets and body-part labels.

One representation serves BVH, ASF/AMC and the built-in human model:

* A joint is a *pivot*. Its ``offset`` is the rest-pose vector from the parent's pivot, in the
  world frame of the rest pose (BVH offsets are exactly this; an ASF bone contributes its
  ``direction * length`` as the offset of the bones hanging off its end).
* ``channels`` lists the joint's degrees of freedom in the order they are stored in a frame,
  named as in BVH: ``Xposition``, ``Yposition``, ``Zposition``, ``Xrotation``, ...
* ``rotation_order`` gives the rotation axes in matrix-product order (intrinsic, see
  :mod:`mocodec.rotations`): the local rotation is ``R[order[0]] @ R[order[1]] @ ...``. For BVH
  it is the order of the rotation channels; for ASF it is the ``dof`` list reversed. An axis may
  appear twice (proper Euler, e.g. a shoulder in spherical coordinates ``YZY``).
* ``axis`` / ``axis_order`` is a fixed pre-rotation ``C`` (intrinsic Euler, degrees): the joint
  rotates by ``C @ M @ C^-1``. It is the ASF bone ``axis``; identity for BVH.
* Joints without channels and without children are end sites (BVH ``End Site``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from mocodec import rotations
from mocodec.bodyparts import label_body_parts

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
CHANNEL_NAMES = POSITION_CHANNELS + ROTATION_CHANNELS

BODY_PARTS = ("torso", "head", "left_arm", "left_hand", "right_arm", "right_hand", "left_leg", "right_leg")

_NO_LIMIT = (-np.inf, np.inf)


@dataclass(frozen=True)
class Joint:
    """One pivot of the skeleton (see the module docstring for the conventions)."""

    name: str
    parent: int
    offset: tuple[float, ...]  # x, y, z
    channels: tuple[str, ...] = ()
    rotation_order: str = ""
    axis: tuple[float, ...] = (0.0, 0.0, 0.0)
    axis_order: str = "ZYX"
    limits: tuple[tuple[float, float], ...] = ()
    body_part: str | None = None

    def __post_init__(self):
        bad = [c for c in self.channels if c not in CHANNEL_NAMES]
        if bad:
            raise ValueError(f"joint {self.name!r}: unknown channel {bad[0]!r}")
        positions = [c for c in self.channels if c in POSITION_CHANNELS]
        if len(set(positions)) != len(positions):
            raise ValueError(f"joint {self.name!r}: repeated channel in {self.channels}")
        rot_axes = "".join(c[0] for c in self.channels if c in ROTATION_CHANNELS)
        if any(a == b for a, b in zip(self.rotation_order, self.rotation_order[1:])):
            raise ValueError(
                f"joint {self.name!r}: rotation order {self.rotation_order!r} repeats an axis twice in a row"
            )
        if sorted(rot_axes) != sorted(self.rotation_order):
            raise ValueError(
                f"joint {self.name!r}: rotation order {self.rotation_order!r} does not use the "
                f"rotation channels {rot_axes!r}"
            )
        if not self.limits:
            object.__setattr__(self, "limits", tuple(_NO_LIMIT for _ in self.channels))
        elif len(self.limits) != len(self.channels):
            raise ValueError(f"joint {self.name!r}: {len(self.limits)} limits for {len(self.channels)} channels")
        if self.body_part is not None and self.body_part not in BODY_PARTS:
            raise ValueError(f"joint {self.name!r}: unknown body part {self.body_part!r}")

    @property
    def has_axis(self) -> bool:
        return any(a != 0.0 for a in self.axis)

    def rotation_channel_indices(self) -> list[int]:
        """For each step of ``rotation_order``, the index of its channel in ``channels``.

        An axis may occur twice (proper Euler orders such as the shoulder's ``YZY``); its
        first occurrence in the order takes its first channel, and so on."""
        used: dict[str, int] = {}
        out = []
        for axis in self.rotation_order:
            k = used.get(axis, 0)
            out.append([i for i, c in enumerate(self.channels) if c == f"{axis}rotation"][k])
            used[axis] = k + 1
        return out


@dataclass(frozen=True, eq=False)
class Skeleton:
    """An ordered tree of joints (parents before children) and its unit of length.

    Two skeletons are equal (and hash alike) when their joints, unit and name are: the plans
    worked out per skeleton (channel tables, step groups, allocations) are then shared by every
    clip read with the same skeleton, not made again for each file (the metadata does not count)."""

    joints: tuple[Joint, ...]
    units_per_metre: float = 1.0
    name: str = ""
    metadata: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(self.joints))
        if not self.joints:
            raise ValueError("a skeleton needs at least one joint")
        names = set()
        for i, j in enumerate(self.joints):
            if j.name in names:
                raise ValueError(f"joint name {j.name!r} is used twice")
            names.add(j.name)
            if i == 0 and j.parent != -1:
                raise ValueError("the first joint must be the root (parent -1)")
            if i > 0 and not 0 <= j.parent < i:
                raise ValueError(f"joint {j.name!r}: parent index {j.parent} must come before it")
        if not self.units_per_metre > 0:
            raise ValueError("units_per_metre must be positive")

    @cached_property
    def _digest(self) -> bytes:
        """A 128-bit digest of what makes the skeleton (floats by their exact repr): equality is
        then one comparison of 16 bytes, as cached plans look skeletons up on every use."""
        return hashlib.blake2b(repr((self.joints, self.units_per_metre, self.name)).encode(), digest_size=16).digest()

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, Skeleton):
            return NotImplemented
        return self._digest == other._digest

    def __hash__(self) -> int:
        return int.from_bytes(self._digest[:8], "little", signed=True)

    # ----- structure -------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.joints)

    @cached_property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @cached_property
    def parents(self) -> np.ndarray:
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @cached_property
    def offsets(self) -> np.ndarray:
        return np.array([j.offset for j in self.joints], dtype=np.float64)

    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        kids: list[list[int]] = [[] for _ in self.joints]
        for i, j in enumerate(self.joints[1:], start=1):
            kids[j.parent].append(i)
        return tuple(tuple(k) for k in kids)

    @cached_property
    def end_sites(self) -> np.ndarray:
        """True for end sites: joints with neither channels nor children (BVH ``End Site``)."""
        return np.array([not j.channels and not k for j, k in zip(self.joints, self.children)], dtype=bool)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r}") from None

    @cached_property
    def depths(self) -> np.ndarray:
        """Depth in the tree: 0 for the root."""
        d = np.zeros(len(self), dtype=np.int64)
        for i, j in enumerate(self.joints[1:], start=1):
            d[i] = d[j.parent] + 1
        return d

    # ----- channels --------------------------------------------------------------------
    @cached_property
    def channel_offsets(self) -> np.ndarray:
        """Index of each joint's first channel in a frame; one more entry for the total."""
        counts = [len(j.channels) for j in self.joints]
        return np.concatenate(([0], np.cumsum(counts))).astype(np.int64)

    @property
    def num_channels(self) -> int:
        return int(self.channel_offsets[-1])

    @cached_property
    def channel_names(self) -> tuple[str, ...]:
        """``joint.channel`` for every channel, in frame order."""
        return tuple(f"{j.name}.{c}" for j in self.joints for c in j.channels)

    @cached_property
    def channel_joints(self) -> np.ndarray:
        """The joint index of every channel."""
        return np.repeat(np.arange(len(self)), np.diff(self.channel_offsets))

    @cached_property
    def rotation_mask(self) -> np.ndarray:
        """True for rotation channels (degrees), False for positions (skeleton units)."""
        return np.array([c in ROTATION_CHANNELS for j in self.joints for c in j.channels], dtype=bool)

    @cached_property
    def root_turn_mask(self) -> np.ndarray:
        """True for the root joint's rotation channels: the turn a game export's rotation-only
        root gives the whole skeleton (to the engine's axes), which its rest pose keeps."""
        mask = self.rotation_mask.copy()
        mask[self.channel_offsets[1] if len(self) else 0 :] = False
        return mask

    @cached_property
    def limits(self) -> np.ndarray:
        """Joint limits per channel, shape ``(channels, 2)``; +-inf where there is none."""
        if self.num_channels == 0:
            return np.zeros((0, 2))
        return np.array([lim for j in self.joints for lim in j.limits], dtype=np.float64)

    def channel_index(self, name: str) -> int:
        """Index of ``"joint.channel"`` in a frame."""
        try:
            return self.channel_names.index(name)
        except ValueError:
            raise KeyError(f"no channel named {name!r}") from None

    # ----- rest pose and derived geometry -----------------------------------------------
    @cached_property
    def rest_positions(self) -> np.ndarray:
        """Global pivot positions with every channel at zero, ``(joints, 3)``."""
        pos = np.zeros((len(self), 3))
        pos[0] = self.offsets[0]
        for i, j in enumerate(self.joints[1:], start=1):
            pos[i] = pos[j.parent] + self.offsets[i]
        return pos

    @cached_property
    def bone_lengths(self) -> np.ndarray:
        """Length (skeleton units) of the bone each joint's rotation swings: the largest distance
        from its pivot to its children's pivots; 0 for end sites and childless joints."""
        lengths = np.zeros(len(self))
        norms = np.linalg.norm(self.offsets, axis=1)
        for i, j in enumerate(self.joints[1:], start=1):
            lengths[j.parent] = max(lengths[j.parent], norms[i])
        return lengths

    @cached_property
    def axis_matrices(self) -> np.ndarray:
        """The fixed pre-rotation ``C`` of every joint, ``(joints, 3, 3)`` (the identity where a
        joint has none, without the trigonometry: most skeletons have none)."""
        out = np.tile(np.eye(3), (len(self.joints), 1, 1))
        for i, j in enumerate(self.joints):
            if j.has_axis:
                out[i] = rotations.euler_to_matrix(np.array(j.axis), j.axis_order)
        return out

    @cached_property
    def _part_labels(self) -> tuple[tuple[str, ...], np.ndarray]:
        return label_body_parts(self)

    @property
    def body_parts(self) -> tuple[str, ...]:
        """Body part (kinematic chain) of every joint, see :mod:`mocodec.bodyparts`."""
        return self._part_labels[0]

    @property
    def chain_depths(self) -> np.ndarray:
        """Depth of each joint within its body part's chain: 0 where the chain starts."""
        return self._part_labels[1]

    def height(self) -> float:
        """Vertical (Y) extent of the rest pose in skeleton units."""
        y = self.rest_positions[:, 1]
        return float(y.max() - y.min())

    def span(self) -> float:
        """The longest path along bones between two joints (skeleton units): fingertip to toe
        on a person, whatever the pose, so it tells the skeleton's size where its rest pose
        (lying down, folded) does not."""
        down = np.zeros(len(self))  # the longest path from each joint down to a descendant
        longest = 0.0
        norms = np.linalg.norm(self.offsets, axis=1)
        for i in range(len(self) - 1, 0, -1):  # children before parents
            parent, reach = self.joints[i].parent, down[i] + norms[i]
            longest = max(longest, down[parent] + reach)
            down[parent] = max(down[parent], reach)
        return float(longest)

    # ----- comparison and editing --------------------------------------------------------
    def isclose(self, other: Skeleton, atol: float = 1e-6) -> bool:
        """Same structure, names, channels, orders and limits; offsets and axes within ``atol``."""
        return self.difference(other, atol) is None

    def difference(self, other: Skeleton, atol: float = 1e-6, end_site_names: bool = True) -> str | None:
        """A one-line description of the first difference from ``other``, or None; with
        ``end_site_names`` False, two end sites' names may differ (a BVH's end sites have none:
        its reader names them after their parent, where an FBX or glTF named the leaf bone)."""
        if len(self) != len(other):
            return f"{len(self)} joints vs {len(other)}"
        if not np.isclose(self.units_per_metre, other.units_per_metre, rtol=1e-9):
            return f"units_per_metre {self.units_per_metre} vs {other.units_per_metre}"
        unnamed = self.end_sites & other.end_sites if not end_site_names else np.zeros(len(self), dtype=bool)
        for a, b, free in zip(self.joints, other.joints, unnamed):
            for attr in ("name", "parent", "channels", "rotation_order"):
                if getattr(a, attr) != getattr(b, attr) and not (free and attr == "name"):
                    return f"joint {a.name!r}: {attr} {getattr(a, attr)!r} vs {getattr(b, attr)!r}"
            for attr in ("offset", "limits"):
                x, y = np.asarray(getattr(a, attr), float), np.asarray(getattr(b, attr), float)
                if x.shape != y.shape or not np.allclose(x, y, atol=atol, rtol=0, equal_nan=True):
                    return f"joint {a.name!r}: {attr} {getattr(a, attr)} vs {getattr(b, attr)}"
            ca = rotations.euler_to_matrix(np.array(a.axis), a.axis_order)
            cb = rotations.euler_to_matrix(np.array(b.axis), b.axis_order)
            if not np.allclose(ca, cb, atol=max(atol, 1e-9)):
                return f"joint {a.name!r}: axis {a.axis} vs {b.axis}"
        return None
