"""The preset dictionary that .moc headers are deflated with.

A short clip's header is mostly joint names and codec settings that every file on the same
kind of skeleton repeats; deflate with a preset dictionary (zlib's ``zdict``) codes such
strings as references into it, so they cost a few bytes instead of a few hundred. The
dictionary holds the name columns of the skeletons users have most (CMU ASF, the cgspeed BVH
conversions of CMU, Mixamo-style names, mocodec's built-in human model) laid out as
:func:`~mocodec.formats.skeleton_bin.pack_skeleton` writes them, and typical codec settings.

Both ends must hold the very same bytes: a dictionary is part of the file format and must
never change (a new one needs a new container version); a test checks their hashes.
:data:`DICTIONARIES` gives each container version's: version 2's ends with the settings of
kinwave's knobs as they are since its effort levels and chunk-long segments (in version 1's,
a kinwave header cost 16-35 bytes more); version 3's ends with the parent and channel columns
of common skeletons (about 50 bytes less for a CMU skeleton's header).
"""

from __future__ import annotations

import json


def _name_column(names: str) -> bytes:
    """Names as the compact skeleton writes them: each preceded by its length (one byte)."""
    return b"".join(bytes([len(n)]) + n.encode() for n in names.split())


def _parent_column(distances: str) -> bytes:
    """Parents as the compact skeleton writes them: each joint's distance back to its parent
    (0 for a root), a one-byte varint each."""
    return bytes(int(d) for d in distances.split())


def _channel_column(lists: str) -> bytes:
    """Channel lists as the compact skeleton writes them: a count, then each channel's index
    in ``Xposition Yposition Zposition Xrotation Yrotation Zrotation``; one word per joint,
    ``xyz`` for positions, ``XYZ`` for rotations, in their order, ``-`` for none."""
    return b"".join(bytes([len(w.strip("-"))] + ["xyzXYZ".index(c) for c in w.strip("-")]) for w in lists.split())


def _end_sites(names: str, ends: str) -> str:
    """``names`` with ``NAME_end`` after each joint named in ``ends`` (end sites)."""
    tips = set(ends.split())
    return " ".join(f"{n} {n}_end" if n in tips else n for n in names.split())


_CMU_ASF = _end_sites(
    "root lhipjoint lfemur ltibia lfoot ltoes rhipjoint rfemur rtibia rfoot rtoes lowerback upperback thorax "
    "lowerneck upperneck head lclavicle lhumerus lradius lwrist lhand lfingers lthumb rclavicle rhumerus rradius "
    "rwrist rhand rfingers rthumb",
    "ltoes rtoes head lfingers lthumb rfingers rthumb",
)
_DAZ_HANDS = " ".join(f"{s}{f}1 {s}{f}2 {s}{f}2_end" for s in "rl" for f in ("Thumb", "Index", "Mid", "Ring", "Pinky"))
_CMU_DAZ = (
    "hip abdomen chest neck head leftEye leftEye_end rightEye rightEye_end rCollar rShldr rForeArm rHand "
    + " ".join(_DAZ_HANDS.split()[:15])
    + " lCollar lShldr lForeArm lHand "
    + " ".join(_DAZ_HANDS.split()[15:])
    + " rButtock rThigh rShin rFoot rFoot_end lButtock lThigh lShin lFoot lFoot_end"
)
_CMU_MOTIONBUILDER = _end_sites(
    "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg RightFoot RightToeBase "
    "LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm LeftForeArm LeftHand LeftFingerBase "
    "LeftHandIndex1 LThumb RightShoulder RightArm RightForeArm RightHand RightFingerBase RightHandIndex1 RThumb",
    "LeftToeBase RightToeBase Head LeftHandIndex1 LThumb RightHandIndex1 RThumb",
)
_MIXAMO = " ".join(
    f"mixamorig:{n}"
    for n in (
        "Hips Spine Spine1 Spine2 Neck Head HeadTop_End LeftShoulder LeftArm LeftForeArm LeftHand RightShoulder "
        "RightArm RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot LeftToeBase LeftToe_End RightUpLeg RightLeg "
        "RightFoot RightToeBase RightToe_End"
    ).split()
)
_FINGERS = (
    "thumb1 thumb2 thumb_tip index1 index2 index3 index_tip middle1 middle2 middle3 middle_tip ring1 ring2 "
    "ring3 ring_tip little1 little2 little3 little_tip"
)
_HUMAN = " ".join(
    ["root torso neck head head_top"]
    + [f"{s}_shoulder {s}_elbow {s}_wrist " + " ".join(f"{s}_{f}" for f in _FINGERS.split()) for s in ("left", "right")]
    + [f"{s}_hip {s}_knee {s}_ankle {s}_toe" for s in ("left", "right")]
)

_SETTINGS = [
    {
        "codec": {
            "codec": "kinwave",
            "knobs": {
                "max_error_cm": 0.5,
                "error_measure": "joint",
                "bits_per_second": 0.0,
                "window": 128,
                "levels": 5,
                "wavelet": "cdf97",
                "deadzone": 0.4,
                "closed_loop": True,
                "allocation": "convex",
                "keyframes": False,
            },
        },
        "fps": 120.0,
        "frames": 1000,
        "chunk_frames": 1024,
    },
    {"codec": {"codec": "lossless", "knobs": {}}, "fps": 30.0, "frames": 1000, "chunk_frames": 1024},
]

# the defaults of the codecs most files use
_SETTINGS_DEFAULTS = [
    {
        "codec": {
            "codec": "spiht",
            "knobs": {
                "bits_per_second": 8000.0,
                "window": 128,
                "wavelet": "cdf97",
                "levels": 0,
                "allocation": "perceptual",
                "leg_score": 1.0,
                "upper_score": 0.5,
                "smooth_seams": True,
                "closed_loop": False,
            },
        },
        "fps": 120.0,
        "frames": 1000,
        "chunk_frames": 1024,
    },
    {
        "codec": {
            "codec": "kinwave",
            "knobs": {
                "max_error_cm": 0.5,
                "error_measure": "joint",
                "bits_per_second": 0.0,
                "window": 256,
                "levels": 5,
                "wavelet": "cdf97",
                "deadzone": 0.4,
                "closed_loop": True,
                "allocation": "convex",
                "joint_feedback": True,
                "segment_steps": True,
                "rotation_vectors": True,
                "keyframes": False,
            },
        },
        "fps": 120.0,
        "frames": 1000,
        "chunk_frames": 1024,
    },
]

# the naming conventions of more pipelines: Unity's humanoid bones (also with _L/_R suffixes),
# Unreal's mannequin, SMPL
_UNITY = _end_sites(
    "Hips Spine Chest UpperChest Neck Head LeftShoulder LeftUpperArm LeftLowerArm LeftHand RightShoulder "
    "RightUpperArm RightLowerArm RightHand LeftUpperLeg LeftLowerLeg LeftFoot LeftToes RightUpperLeg RightLowerLeg "
    "RightFoot RightToes",
    "Head LeftHand RightHand LeftToes RightToes",
)
_UNITY_SUFFIXED = _end_sites(
    "Hips Spine Chest Neck Head Shoulder_L UpperArm_L LowerArm_L Hand_L Shoulder_R UpperArm_R LowerArm_R Hand_R "
    "UpperLeg_L LowerLeg_L Foot_L Toes_L UpperLeg_R LowerLeg_R Foot_R Toes_R",
    "Head Hand_L Hand_R Toes_L Toes_R",
)
_UNREAL = (
    "root pelvis spine_01 spine_02 spine_03 neck_01 head clavicle_l upperarm_l lowerarm_l hand_l clavicle_r "
    "upperarm_r lowerarm_r hand_r thigh_l calf_l foot_l ball_l thigh_r calf_r foot_r ball_r"
)
_SMPL = (
    "pelvis left_hip right_hip spine1 left_knee right_knee spine2 left_ankle right_ankle spine3 left_foot "
    "right_foot neck left_collar right_collar head left_shoulder right_shoulder left_elbow right_elbow "
    "left_wrist right_wrist left_hand right_hand"
)
_SETTINGS_KEYFRAMES = [
    {
        "codec": {
            "codec": "kinwave",
            "knobs": {
                "max_error_cm": 0.5,
                "error_measure": "joint",
                "bits_per_second": 0.0,
                "window": 256,
                "levels": 0,
                "wavelet": "cdf97",
                "deadzone": 0.4,
                "closed_loop": True,
                "allocation": "convex",
                "joint_feedback": True,
                "segment_steps": True,
                "rotation_vectors": True,
                "keyframes": True,
            },
        },
        "fps": 30.0,
        "frames": 1000,
        "chunk_frames": 1024,
    },
]


def _settings(settings: list[dict]) -> bytes:
    return b"".join(json.dumps(s, separators=(",", ":")).encode() for s in settings)


# least likely first: deflate finds the end of a dictionary with the shortest distances. The
# codec settings make a kinwave file's header JSON cost 26-31 bytes instead of 64-70; the
# pipelines' joint names make a 22-joint Unity-style skeleton's names cost a few bytes
# instead of about 100.
DICTIONARY = b"".join(
    [
        _settings(_SETTINGS),
        _name_column(_MIXAMO),
        _name_column(_HUMAN),
        _name_column(_CMU_MOTIONBUILDER),
        _name_column(_CMU_ASF),
        _name_column(_CMU_DAZ),
        _settings(_SETTINGS_DEFAULTS),
        _name_column(_SMPL),
        _name_column(_UNREAL),
        _name_column(_UNITY),
        _name_column(_UNITY_SUFFIXED),
        _settings(_SETTINGS_KEYFRAMES),
    ]
)

# .moc version 2: kinwave's knobs as they are since the effort levels and the segments as long
# as a chunk (version 1's strings predate both), at a max shell bound at 30 fps and at the
# defaults at 120 fps, last: the nearest strings cost the fewest bits
_KINWAVE_KNOBS_2 = {
    "max_error_cm": 0.5,
    "error_measure": "joint",
    "bits_per_second": 0.0,
    "window": 1024,
    "levels": 0,
    "wavelet": "cdf97",
    "deadzone": 0.4,
    "closed_loop": True,
    "allocation": "convex",
    "joint_feedback": True,
    "segment_steps": False,
    "rotation_vectors": True,
    "effort": 2,
    "keyframes": True,
}
_SETTINGS_2 = [
    {
        "codec": {"codec": "kinwave", "knobs": {**_KINWAVE_KNOBS_2, "max_error_cm": 1.0, "error_measure": "shell"}},
        "fps": 30.0,
        "frames": 1000,
        "chunk_frames": 1024,
    },
    {"codec": {"codec": "kinwave", "knobs": _KINWAVE_KNOBS_2}, "fps": 120.0, "frames": 1000, "chunk_frames": 1024},
]

# .moc version 3: the hierarchies and channel lists of the common skeletons above, as the
# compact skeleton's parent and channel columns (their names cost a few bytes already; without
# these a parent column cost about 25 bytes and a channel column up to 30, of a 6-frame clip's
# 600-byte file). The CMU skeletons as the cgspeed BVH conversion writes them (end sites, ZXY),
# as Blender's FBX export of those writes them (no end sites, ZYX) and as an FBX pipeline into
# a game engine writes them (a rotation-only root above the hips, every joint translating:
# benchmarks/common.py's game exports); the CMU ASF skeletons; the Bandai Namco MotionBuilder
# skeleton (Unity's names with _L/_R suffixes). The most common last.
_CGSPEED_NO_ENDS = " ".join(n for n in _CMU_DAZ.split() if not n.endswith("_end"))
_CGSPEED_PARENTS = (
    "0 1 1 1 1 1 1 3 1 7 1 1 1 1 1 1 4 1 1 7 1 1 10 1 1 13 1 1 26 1 1 1 1 1 1 4 1 1 7 1 1 10 1 1 13 1 1 47 "
    "1 1 1 1 52 1 1 1 1"
)
_CGSPEED_CHANNELS = "xyzZYX ZXY ZXY ZXY ZXY ZXY - ZXY - " + " ".join(
    ["ZXY ZXY ZXY ZXY " + "ZXY ZXY - " * 5] * 2 + ["ZXY ZXY ZXY ZXY -"] * 2
)
_BLENDER_CMU_PARENTS = "0 1 1 1 1 1 2 5 1 1 1 1 1 3 1 5 1 7 1 9 1 19 1 1 1 1 1 3 1 5 1 7 1 9 1 35 1 1 1 39 1 1 1"
_BLENDER_CMU_CHANNELS = " ".join(["xyzZYX"] + ["ZYX"] * 42)
_GAME_CMU_CHANNELS = "ZXY xyzZYX " + " ".join("xyzZXY" if w != "-" else w for w in _CGSPEED_CHANNELS.split()[1:])
_CMU_ASF_PARENTS = "0 1 1 1 1 1 1 7 1 1 1 1 1 13 1 1 1 1 1 1 5 1 1 1 1 1 1 4 1 14 1 1 1 1 1 1 4 1"
_CMU_ASF_CHANNELS = (
    "xyzXYZ - XYZ X XZ X - - XYZ X XZ X - XYZ XYZ XYZ XYZ XYZ XYZ - YZ XYZ X Y XZ X - XZ - YZ XYZ X Y XZ X - XZ -"
)
_BANDAI_PARENTS = "0 1 1 1 1 1 1 4 1 1 1 1 9 1 1 1 1 16 1 1 1 1 21 1 1 1 1"
_BANDAI_CHANNELS = " ".join(["xyzZXY"] * 6 + ["-"] + (["xyzZXY"] * 4 + ["-"]) * 4)
_HIERARCHIES_3 = b"".join(
    [
        _parent_column(_CMU_ASF_PARENTS),
        _channel_column(_CMU_ASF_CHANNELS),
        _parent_column(_BANDAI_PARENTS),
        _channel_column(_BANDAI_CHANNELS),
        _name_column(_CGSPEED_NO_ENDS),
        _parent_column(_BLENDER_CMU_PARENTS),
        _channel_column(_BLENDER_CMU_CHANNELS),
        _parent_column("0 1" + _CGSPEED_PARENTS[1:]),  # a root above the hips
        _channel_column(_GAME_CMU_CHANNELS),
        _parent_column(_CGSPEED_PARENTS),
        _channel_column(_CGSPEED_CHANNELS),
    ]
)

#: Each .moc container version's preset dictionary.
DICTIONARIES = {1: DICTIONARY, 2: DICTIONARY + _settings(_SETTINGS_2)}
DICTIONARIES[3] = DICTIONARIES[2] + _HIERARCHIES_3
