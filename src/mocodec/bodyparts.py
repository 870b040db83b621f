"""Body-part labels for any skeleton: torso, head, left/right arm, hand and leg.

The perceptual coders weight channels by the kinematic chain they belong to (001 ch. 3, 6), so
every joint of a CMU ASF, a BVH or the built-in model needs a label. Labels come, in order of
trust, from the joint itself (the built-in model states them), from its name (``lhumerus``,
``LeftArm``, ``rShldr``, ``mixamorig:LeftHand`` ...) and otherwise from the rest-pose
topology: subtrees of the torso whose end points hang below the root are legs, the subtree
holding the top of the figure is the spine, other subtrees reaching sideways are arms, and the
spine above the arms is the head.

The wrist belongs to the arm as in 000 Table 5-1 (shoulder, elbow, wrist); the joints beyond it
(palm, fingers, thumb) are the hand. A BVH ``Hand`` joint sits at the wrist (its offset is the
forearm), so it is labelled arm; an ASF ``hand`` bone hangs off the ``wrist`` bone and is hand.
The figure faces +Z with Y up, so its left side is +X (BVH and ASF convention).
"""

from __future__ import annotations

import re

import numpy as np

_LIMB_WORDS = (
    "hip",
    "femur",
    "tibia",
    "foot",
    "toe",
    "clavicle",
    "humerus",
    "radius",
    "ulna",
    "wrist",
    "hand",
    "finger",
    "thumb",
    "index",
    "mid",
    "ring",
    "pinky",
    "little",
    "shldr",
    "shoulder",
    "collar",
    "forearm",
    "arm",
    "leg",
    "upleg",
    "thigh",
    "shin",
    "knee",
    "ankle",
    "elbow",
    "buttock",
    "eye",
    "ear",
    "heel",
    "ball",
    "palm",
    "calf",
    "up",
    "low",
    "fore",
)
_HAND_WORDS = ("thumb", "index", "middle", "mid", "ring", "pinky", "little", "finger", "palm", "carpal", "hand")
_ARM_WORDS = ("clavicle", "collar", "shoulder", "shldr", "humerus", "arm", "radius", "ulna", "elbow", "wrist")
_LEG_WORDS = (
    "buttock",
    "hip",
    "femur",
    "thigh",
    "upleg",
    "leg",
    "knee",
    "shin",
    "tibia",
    "calf",
    "foot",
    "ankle",
    "toe",
    "heel",
)
_HEAD_WORDS = ("neck", "head", "eye", "jaw", "skull", "nose", "ear")
_TORSO_WORDS = ("pelvis", "hips", "hip", "root", "spine", "back", "abdomen", "chest", "thorax", "torso", "waist")


def _strip_namespace(name: str) -> str:
    return re.sub(r"^.*[:|]", "", name)


def name_side(name: str) -> str | None:
    """'left', 'right' or None from a joint name (``LeftArm``, ``lhumerus``, ``arm_L``)."""
    low = name.lower()
    if "left" in low:
        return "left"
    if "right" in low:
        return "right"
    bare = _strip_namespace(name)
    m = re.match(r"^([lLrR])[_\-. ]?([A-Za-z].*)$", bare)
    if m and m.group(2).lower().startswith(_LIMB_WORDS):
        return "left" if m.group(1) in "lL" else "right"
    m = re.search(r"[_\-. ]([lLrR])\d*$", bare)
    if m:
        return "left" if m.group(1) in "lL" else "right"
    return None


def name_chain(name: str, sided: bool) -> str | None:
    """'hand', 'arm', 'leg', 'head', 'torso' or None from a joint name."""
    low = _strip_namespace(name).lower()
    for chain, words in (("hand", _HAND_WORDS), ("arm", _ARM_WORDS), ("leg", _LEG_WORDS), ("head", _HEAD_WORDS)):
        if any(w in low for w in words):
            if chain == "leg" and not sided and re.search(r"hips?$", low):
                return "torso"  # a central 'Hips' is the pelvis, a sided 'LeftHip' the leg
            return chain
    if any(w in low for w in _TORSO_WORDS):
        return "torso"
    return None


def _subtree(skeleton, start: int) -> list[int]:
    out, stack = [], [start]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(skeleton.children[j])
    return out


def _topology_chain(skeleton, joint: int) -> tuple[str, str | None]:
    """Chain and side of a subtree leaving the torso at ``joint``, from the rest pose."""
    rest = skeleton.rest_positions - skeleton.rest_positions[0]
    height = max(skeleton.height(), 1e-9)
    sub = _subtree(skeleton, joint)
    leaves = [j for j in sub if not skeleton.children[j]]
    side = _side_of(skeleton, joint)
    if rest[leaves, 1].mean() < -0.15 * height:
        return "leg", side
    if int(np.argmax(rest[:, 1])) in sub:  # the spine carries the top of the figure
        return "torso", None
    if np.abs(rest[sub, 0]).max() > 0.12 * height:
        return "arm", side
    return "torso", None


def _side_of(skeleton, joint: int) -> str:
    """The side (+X is left) the subtree at ``joint`` lies on in the rest pose."""
    rest = skeleton.rest_positions - skeleton.rest_positions[0]
    return "left" if float(rest[_subtree(skeleton, joint), 0].mean()) > 0 else "right"


def label_body_parts(skeleton) -> tuple[tuple[str, ...], np.ndarray]:
    """Body part of every joint and its depth in that part's chain (0 where a chain starts)."""
    n = len(skeleton)
    chain: list[str | None] = [None] * n
    side: list[str | None] = [None] * n
    explicit = [j.body_part for j in skeleton.joints]
    for i, j in enumerate(skeleton.joints):
        if explicit[i]:
            part = explicit[i]
            chain[i], side[i] = (part.split("_")[1], part.split("_")[0]) if "_" in part else (part, None)
            continue
        parent = j.parent
        if i == 0:
            chain[i] = "torso"
            continue
        if skeleton.end_sites[i]:
            chain[i], side[i] = chain[parent], side[parent]
            continue
        s = name_side(j.name)
        c = name_chain(j.name, s is not None)
        if c is None:
            if chain[parent] == "torso":
                c, s_geo = _topology_chain(skeleton, i)
                s = s or s_geo
            else:
                c = chain[parent]
        if c in ("arm", "hand", "leg") and s is None:
            s = side[parent] or _side_of(skeleton, i)
        if c == "torso" and chain[parent] == "head":
            c = "head"
        chain[i], side[i] = c, (s if c in ("arm", "hand", "leg") else None)
    _split_wrists(skeleton, chain, explicit)
    _head_above_arms(skeleton, chain, explicit)
    parts = tuple(f"{side[i]}_{chain[i]}" if chain[i] in ("arm", "hand", "leg") else chain[i] for i in range(n))
    depth = np.zeros(n, dtype=np.int64)
    for i, j in enumerate(skeleton.joints[1:], start=1):
        depth[i] = depth[j.parent] + 1 if parts[j.parent] == parts[i] else 0
    return tuple(str(p) for p in parts), depth


def _split_wrists(skeleton, chain: list, explicit: list) -> None:
    """Make the wrist pivot arm and what lies beyond it hand.

    A joint named like a hand whose parent is a forearm (not a wrist bone) is the wrist pivot.
    An arm chain without any hand-named joint gets its hand at the first joint that branches
    (the fingers), the wrist itself staying arm.
    """
    for i, j in enumerate(skeleton.joints):
        if explicit[i] or i == 0:
            continue
        p = j.parent
        if chain[i] == "hand" and chain[p] == "arm" and "wrist" not in skeleton.joints[p].name.lower():
            low = _strip_namespace(j.name).lower()
            if "hand" in low and not any(w in low for w in _HAND_WORDS[:-1]):
                chain[i] = "arm"
    arm_starts = [
        i
        for i in range(1, len(chain))
        if chain[i] == "arm" and chain[skeleton.joints[i].parent] != "arm" and not explicit[i]
    ]
    for start in arm_starts:
        sub = _subtree(skeleton, start)
        if any(chain[j] == "hand" for j in sub):
            continue
        wrist = next((j for j in sorted(sub) if len(skeleton.children[j]) >= 2), None)
        if wrist is not None:
            for j in _subtree(skeleton, wrist)[1:]:
                chain[j] = "hand"


def _head_above_arms(skeleton, chain: list, explicit: list) -> None:
    """Without a head-named joint, the spine joints above the last arm branch form the head."""
    if "head" in chain or not any(c == "arm" for c in chain):
        return
    branch = max(
        i for i in range(len(chain)) if chain[i] == "torso" and any(chain[k] == "arm" for k in skeleton.children[i])
    )
    for k in skeleton.children[branch]:
        if chain[k] == "torso" and not explicit[k]:
            for j in _subtree(skeleton, k):
                chain[j] = "head"
