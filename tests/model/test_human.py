import numpy as np
import pytest

from mocodec import BODY_PARTS, human_model
from mocodec.human import TABLE_5_1, segment_masses
from mocodec.kinematics import forward_kinematics


@pytest.fixture(scope="module")
def male():
    return human_model("male")


def test_table_3_1_joints_and_dofs(male):
    assert male.num_channels == 80
    idx = male.metadata["thesis_index"]
    assert len(idx) == 44 and sorted(idx.values()) == [i for i in range(46) if i not in (4, 42)]
    shoulder = male.joints[male.index("left_shoulder")]
    assert shoulder.rotation_order == "YZY" and shoulder.limits[1] == (-160, 0)
    assert male.joints[male.index("right_knee")].limits == ((0, 180),)


def test_groups_cover_table_5_1(male):
    dofs = {p: 0 for p in BODY_PARTS}
    joints = {p: 0 for p in BODY_PARTS}
    for i, j in enumerate(male.joints):
        dofs[male.body_parts[i]] += len(j.channels)
        joints[male.body_parts[i]] += bool(j.channels)
    assert sum(dofs.values()) == sum(t[3] for t in TABLE_5_1.values()) == 80
    for part in ("head", "left_hand", "right_hand", "left_leg", "right_leg"):
        assert dofs[part] == TABLE_5_1[part][3] and joints[part] == TABLE_5_1[part][1]


def test_standing_figure_has_plausible_heights(male):
    pos, _ = forward_kinematics(male, np.zeros((1, 80)))
    y = {
        n: pos[0, male.index(n), 1]
        for n in (
            "head_top",
            "root",
            "left_hip",
            "left_wrist",
            "right_wrist",
            "left_ankle",
            "left_toe",
            "left_shoulder",
        )
    }
    assert y["head_top"] == pytest.approx(1.74, abs=0.01)
    assert y["left_toe"] == pytest.approx(0.0, abs=1e-9)
    assert 0.85 < y["left_hip"] < 1.0 and 1.35 < y["left_shoulder"] < 1.5
    assert 0.75 < y["left_wrist"] < 0.95 and y["left_wrist"] == pytest.approx(y["right_wrist"])
    assert pos[0, male.index("left_wrist"), 0] > 0 > pos[0, male.index("right_wrist"), 0]  # left at +X


def test_segments_and_mass(male):
    assert sum(segment_masses(male).values()) == pytest.approx(75.0, abs=0.1)


def test_knee_bends_the_shin_backwards(male):
    ch = np.zeros((1, 80))
    ch[0, male.channel_index("left_knee.Xrotation")] = 90.0
    pos, _ = forward_kinematics(male, ch)
    knee, ankle = pos[0, male.index("left_knee")], pos[0, male.index("left_ankle")]
    np.testing.assert_allclose(ankle[1], knee[1], atol=1e-9)  # shin horizontal
    assert abs(ankle[2] - knee[2]) == pytest.approx(0.44)


def test_unknown_model():
    with pytest.raises(ValueError, match="available: 'male'"):
        human_model("giant")
