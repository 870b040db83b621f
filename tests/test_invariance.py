"""The same motion in other pipelines' layouts (:mod:`mocodec.reexpress`): every joint stays
where it was, and kinwave codes it in about the same bytes with its bound held."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocodec import load, moc, reexpress
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors
from mocodec.motion import Motion
from mocodec.skeleton import Joint, Skeleton

DATA = Path(__file__).parent / "data"
BOUND = 1.0
GROWTH = 0.08                  # the worst case; its median target (3%) is the benchmark's


@pytest.fixture(scope="module")
def bvh():
    return load(DATA / "09_02.bvh")[:240]


@pytest.fixture(scope="module")
def amc():
    return load(DATA / "07_03.amc", asf=DATA / "07.asf")[:240]


def _joints_cm(motion: Motion) -> np.ndarray:
    pos, _ = forward_kinematics(motion.skeleton, motion.channels)
    return pos * (100.0 / motion.skeleton.units_per_metre)


def _same_places(a: Motion, b: Motion) -> None:
    """``b`` places every joint of ``a`` (its last joints: a dummy root comes first) where
    ``a`` does, to 1e-6 cm."""
    pa, pb = _joints_cm(a), _joints_cm(b)
    assert pa.shape[0] == pb.shape[0]
    np.testing.assert_allclose(pb[:, -pa.shape[1]:], pa, atol=1e-6)


def _shell_max(motion: Motion, decoded: Motion) -> float:
    """The max shell error (cm) of ``decoded`` (on its own, stored skeleton) against ``motion``."""
    sk = motion.skeleton
    cm = 100.0 / sk.units_per_metre
    p0, q0 = forward_kinematics(sk, motion.channels)
    p1, q1 = forward_kinematics(decoded.skeleton, decoded.channels)
    return shell_errors(sk, p0 * cm, q0, p1 * cm, q1).max


def _coded(motion: Motion, **knobs) -> tuple[int, float]:
    """The whole .moc file's size (skeleton included) and its decoded max shell error."""
    data = moc.pack(motion, get_codec("kinwave", max_error_cm=BOUND, error_measure="shell", **knobs))
    return len(data), _shell_max(motion, moc.unpack(data))


def _check_invariant(original: Motion, moved: Motion, growth: float = GROWTH) -> None:
    _same_places(original, moved)
    base, _ = _coded(original)
    size, error = _coded(moved)
    assert error <= BOUND
    assert size <= base * (1.0 + growth), f"{size} bytes against {base}"


turns = st.tuples(*[st.floats(-180.0, 180.0, allow_nan=False)] * 3)


@settings(max_examples=3)
@given(turn=st.one_of(turns, st.sampled_from([(0.0, -90.0, 0.0), (0.0, 90.0, 0.0)])))
def test_a_dummy_root_with_a_constant_rotation_changes_nothing(bvh, turn):
    _check_invariant(bvh, reexpress.with_dummy_root(bvh, turn))


@settings(max_examples=3)
@given(order=st.sampled_from(reexpress.EULER_ORDERS))
def test_any_euler_order_codes_the_same_pose(bvh, order):
    _check_invariant(bvh, reexpress.with_euler_orders(bvh, order))


def test_proper_euler_orders_on_an_asf_root(amc):
    _check_invariant(amc, reexpress.with_euler_orders(amc, "YXY"))


def test_six_channel_joints_with_constant_positions(bvh, amc):
    for motion in (bvh, amc):
        _check_invariant(motion, reexpress.with_position_channels(motion))


@pytest.mark.parametrize("factor", [0.01, 2.54])
def test_file_units_do_not_matter(bvh, factor):
    moved = reexpress.with_units(bvh, factor)
    np.testing.assert_allclose(_joints_cm(moved), _joints_cm(bvh), atol=1e-6)
    codec = get_codec("kinwave", max_error_cm=BOUND, error_measure="shell")
    assert codec.encode(moved) == codec.encode(bvh)          # the coded motion is the same, byte for byte
    _check_invariant(bvh, moved)


def test_translation_on_the_child_of_a_dummy_root(amc):
    _check_invariant(amc, reexpress.with_dummy_root(amc, position_channels=True))


def test_a_bind_pose_frame_is_coded_apart(amc):
    moved = reexpress.with_bind_frame(amc)
    _same_places(amc, moved[1:])
    base, _ = _coded(amc)
    size, error = _coded(moved)
    assert error <= BOUND
    assert size <= base * (1.0 + GROWTH)
    assert size < _coded(moved, keyframes=False)[0], "the keyframe should save bytes"


@pytest.mark.parametrize("fps", [24.0, 30.0, 60.0])
def test_a_lower_frame_rate_costs_no_more_and_keeps_the_bound(bvh, fps):
    resampled = bvh.resample(fps)
    size, error = _coded(resampled)
    assert error <= BOUND
    assert size <= _coded(bvh)[0]


def _chain(seed: int) -> Motion:
    """A generated five-joint chain in random Euler orders, 20 s of smooth random motion."""
    rng = np.random.default_rng(seed)
    joints = [Joint("root", -1, (0.0, 90.0, 0.0), ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation",
                                                   "Yrotation"), "ZXY")]
    for k in range(1, 5):
        order = "".join(rng.permutation(list("XYZ")))
        joints.append(Joint(f"j{k}", k - 1, tuple(rng.uniform(-20, 20, 3)), tuple(f"{a}rotation" for a in order),
                            order))
    sk = Skeleton(tuple(joints), 100.0)
    t = np.linspace(0.0, 20.0, 1200)[:, None]
    channels = np.zeros((1200, sk.num_channels))
    channels[:, :3] = np.hstack([30 * np.sin(t), 90 + 2 * np.sin(3 * t), 40 * t])
    channels[:, 3:] = rng.uniform(10, 40, sk.num_channels - 3) * np.sin(rng.uniform(0.5, 3, sk.num_channels - 3) * t
                                                                     + rng.uniform(0, 6, sk.num_channels - 3))
    return Motion(sk, 60.0, channels)


@settings(max_examples=4)
@given(seed=st.integers(0, 2 ** 16), turn=turns)
def test_generated_skeletons_under_a_rotated_dummy_root_keep_the_bound(seed, turn):
    motion = _chain(seed)
    moved = reexpress.with_dummy_root(motion, turn)
    _same_places(motion, moved)
    assert _coded(moved)[1] <= BOUND


@pytest.mark.xfail(strict=True, reason="the root's rotation vector is taken about the identity, not a per-window "
                   "mean rotation: a rotated dummy root costs a generated chain's 1 kB file up to 11% (docs/kinwave.md)")
@settings(max_examples=4)
@given(seed=st.integers(0, 2 ** 16), turn=turns)
def test_generated_skeletons_under_a_rotated_dummy_root_cost_no_more(seed, turn):
    motion = _chain(seed)
    _check_invariant(motion, reexpress.with_dummy_root(motion, turn))


def test_reexpressions_keep_every_joint_in_place(bvh, amc):
    for motion in (bvh, amc):
        for moved in (reexpress.with_dummy_root(motion, (10.0, -90.0, 30.0)), reexpress.with_position_channels(motion),
                      reexpress.with_euler_orders(motion, "ZYZ"), reexpress.with_dummy_root(motion, position_channels=True)):
            _same_places(motion, moved)


def test_reexpress_refuses_what_it_cannot_write(bvh):
    with pytest.raises(ValueError, match="unit factor"):
        reexpress.with_units(bvh, 0.0)
    with pytest.raises(ValueError, match="Euler order"):
        reexpress.with_euler_orders(bvh, "XXY")
