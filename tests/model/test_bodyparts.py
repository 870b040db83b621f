from dataclasses import replace

import pytest

from mocodec import Skeleton
from mocodec.bodyparts import name_side


def parts(sk):
    return dict(zip(sk.names, sk.body_parts))


def test_cmu_bvh_labels(walk_bvh):
    p = parts(walk_bvh.skeleton)
    assert p["hip"] == p["abdomen"] == p["chest"] == "torso"
    assert p["neck"] == p["head"] == p["leftEye"] == "head"
    assert p["lCollar"] == p["lShldr"] == p["lForeArm"] == p["lHand"] == "left_arm"  # lHand is the wrist
    assert p["lThumb1"] == p["lIndex2"] == "left_hand"
    assert p["rThigh"] == p["rFoot"] == "right_leg" and p["rHand"] == "right_arm"


def test_cmu_asf_labels_and_depths(walk_amc):
    sk = walk_amc.skeleton
    p = parts(sk)
    assert p["lhumerus"] == p["lradius"] == p["lwrist"] == "left_arm"
    assert p["lhand"] == p["lfingers"] == p["lthumb"] == "left_hand"
    assert p["rfemur"] == p["rtoes"] == "right_leg" and p["upperneck"] == "head"
    assert sk.chain_depths[sk.index("lclavicle")] == 0 and sk.chain_depths[sk.index("lwrist")] == 3
    assert sk.bone_lengths[sk.index("lfemur")] / sk.units_per_metre == pytest.approx(0.40, abs=0.05)


@pytest.mark.parametrize("fixture", ["walk_bvh", "walk_amc"])
def test_topology_gives_the_same_chains_without_names(fixture, request):
    sk = request.getfixturevalue(fixture).skeleton
    anonymous = Skeleton(tuple(replace(j, name=f"j{i}") for i, j in enumerate(sk.joints)), sk.units_per_metre)
    named, anon = sk.body_parts, anonymous.body_parts
    same = sum(a == b for a, b in zip(named, anon))
    assert same / len(sk) > 0.9, [(n, a, b) for n, a, b in zip(sk.names, named, anon) if a != b]
    for side in ("left", "right"):
        for chain in ("arm", "hand", "leg"):
            assert f"{side}_{chain}" in anon


@pytest.mark.parametrize(
    "name, side",
    [
        ("LeftArm", "left"),
        ("mixamorig:RightHand", "right"),
        ("lhumerus", "left"),
        ("rShldr", "right"),
        ("arm_L", "left"),
        ("lowerback", None),
        ("root", None),
        ("rradius", "right"),
    ],
)
def test_name_sides(name, side):
    assert name_side(name) == side


def test_arms_named_without_a_side_take_the_side_they_lie_on():
    """As in RiggedFigure: 'arm_joint_L_1' names no side the names rule reads, and the raised
    arm holds the top of the figure, so the rest pose alone would call it the spine."""
    from mocodec.skeleton import Joint

    joints = [Joint("pelvis", -1, (0, 100, 0)), Joint("spine", 0, (0, 30, 0)), Joint("head", 1, (0, 30, 0))]
    joints += [Joint("arm_a", 1, (20, 0, 0)), Joint("arm_a_2", 3, (0, 80, 0))]
    joints += [Joint("arm_b", 1, (-20, 0, 0)), Joint("arm_b_2", 5, (-25, 0, 0))]
    p = parts(Skeleton(tuple(joints), 100.0))
    assert p["arm_a"] == p["arm_a_2"] == "left_arm" and p["arm_b"] == p["arm_b_2"] == "right_arm"
