"""The preset dictionaries that .moc headers (versions 2 and 3) are deflated with.

A short clip's header is mostly joint names and codec settings that every file on the same
kind of skeleton repeats; deflate with a preset dictionary (zlib's ``zdict``) codes such
strings as references into it, so they cost a few bytes instead of a few hundred. The
dictionary holds the name columns of the skeletons users have most (CMU ASF, the cgspeed BVH
conversions of CMU, Mixamo-style names, mocodec's built-in human model) laid out as
:func:`~mocodec.formats.skeleton_bin.pack_skeleton` writes them, and typical codec settings.

Both ends must hold the very same bytes: a dictionary is part of the file format and must
never change (a new one needs a new container version); a test checks their hashes.
"""

from __future__ import annotations

import json


def _name_column(names: str) -> bytes:
    """Names as the compact skeleton writes them: each preceded by its length (one byte)."""
    return b"".join(bytes([len(n)]) + n.encode() for n in names.split())


def _end_sites(names: str, ends: str) -> str:
    """``names`` with ``NAME_end`` after each joint named in ``ends`` (end sites)."""
    tips = set(ends.split())
    return " ".join(f"{n} {n}_end" if n in tips else n for n in names.split())


_CMU_ASF = _end_sites(
    "root lhipjoint lfemur ltibia lfoot ltoes rhipjoint rfemur rtibia rfoot rtoes lowerback upperback thorax "
    "lowerneck upperneck head lclavicle lhumerus lradius lwrist lhand lfingers lthumb rclavicle rhumerus rradius "
    "rwrist rhand rfingers rthumb", "ltoes rtoes head lfingers lthumb rfingers rthumb")
_DAZ_HANDS = " ".join(f"{s}{f}1 {s}{f}2 {s}{f}2_end" for s in "rl" for f in ("Thumb", "Index", "Mid", "Ring", "Pinky"))
_CMU_DAZ = ("hip abdomen chest neck head leftEye leftEye_end rightEye rightEye_end rCollar rShldr rForeArm rHand "
            + " ".join(_DAZ_HANDS.split()[:15]) + " lCollar lShldr lForeArm lHand " + " ".join(_DAZ_HANDS.split()[15:])
            + " rButtock rThigh rShin rFoot rFoot_end lButtock lThigh lShin lFoot lFoot_end")
_CMU_MOTIONBUILDER = _end_sites(
    "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg RightFoot RightToeBase "
    "LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm LeftForeArm LeftHand LeftFingerBase "
    "LeftHandIndex1 LThumb RightShoulder RightArm RightForeArm RightHand RightFingerBase RightHandIndex1 RThumb",
    "LeftToeBase RightToeBase Head LeftHandIndex1 LThumb RightHandIndex1 RThumb")
_MIXAMO = " ".join(f"mixamorig:{n}" for n in (
    "Hips Spine Spine1 Spine2 Neck Head HeadTop_End LeftShoulder LeftArm LeftForeArm LeftHand RightShoulder "
    "RightArm RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot LeftToeBase LeftToe_End RightUpLeg RightLeg "
    "RightFoot RightToeBase RightToe_End").split())
_FINGERS = ("thumb1 thumb2 thumb_tip index1 index2 index3 index_tip middle1 middle2 middle3 middle_tip ring1 ring2 "
            "ring3 ring_tip little1 little2 little3 little_tip")
_HUMAN = " ".join(
    ["root torso neck head head_top"]
    + [f"{s}_shoulder {s}_elbow {s}_wrist " + " ".join(f"{s}_{f}" for f in _FINGERS.split()) for s in ("left", "right")]
    + [f"{s}_hip {s}_knee {s}_ankle {s}_toe" for s in ("left", "right")])

_SETTINGS = [
    {"codec": {"codec": "kinwave", "knobs": {"max_error_cm": 0.5, "error_measure": "joint", "bits_per_second": 0.0,
                                             "window": 128, "levels": 5, "wavelet": "cdf97", "deadzone": 0.4,
                                             "closed_loop": True, "allocation": "convex", "keyframes": False}},
     "fps": 120.0, "frames": 1000, "chunk_frames": 1024},
    {"codec": {"codec": "lossless", "knobs": {}}, "fps": 30.0, "frames": 1000, "chunk_frames": 1024},
]

# the defaults when .moc version 3 came, closest to the end: what most files' headers hold
_SETTINGS_3 = [
    {"codec": {"codec": "spiht", "knobs": {"bits_per_second": 8000.0, "window": 128, "wavelet": "cdf97", "levels": 0,
                                           "allocation": "perceptual", "leg_score": 1.0, "upper_score": 0.5,
                                           "smooth_seams": True, "closed_loop": False}},
     "fps": 120.0, "frames": 1000, "chunk_frames": 1024},
    {"codec": {"codec": "kinwave", "knobs": {"max_error_cm": 0.5, "error_measure": "joint", "bits_per_second": 0.0,
                                             "window": 256, "levels": 5, "wavelet": "cdf97", "deadzone": 0.4,
                                             "closed_loop": True, "allocation": "convex", "joint_feedback": True,
                                             "segment_steps": True, "rotation_vectors": True, "keyframes": False}},
     "fps": 120.0, "frames": 1000, "chunk_frames": 1024},
]

# least likely first: deflate finds the end of a dictionary with the shortest distances
DICTIONARY = b"".join([
    *(json.dumps(s, separators=(",", ":")).encode() for s in _SETTINGS),
    _name_column(_MIXAMO),
    _name_column(_HUMAN),
    _name_column(_CMU_MOTIONBUILDER),
    _name_column(_CMU_ASF),
    _name_column(_CMU_DAZ),
])
DICTIONARY_3 = DICTIONARY + b"".join(json.dumps(s, separators=(",", ":")).encode() for s in _SETTINGS_3)


def dictionary(version: int) -> bytes:
    """The preset dictionary of .moc ``version`` (2 or 3): version 3 adds the codec settings
    of its day, so a kinwave file's header JSON costs 26-31 bytes instead of 64-70."""
    return DICTIONARY_3 if version >= 3 else DICTIONARY
