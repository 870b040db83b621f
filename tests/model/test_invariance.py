"""The same motion in other pipelines' layouts (:mod:`mocodec.reexpress`): every joint stays
where it was, and kinwave codes it in about the same bytes with its bound held."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from conftest import DATA  # noqa: E402
from mocodec import load, moc, reexpress
from mocodec.codecs import get_codec
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import shell_errors
from mocodec.motion import Motion
from mocodec.skeleton import Joint, Skeleton

BOUND = 1.0
GROWTH = 0.15  # any one re-expression of one short test clip (the search lands anywhere in 90-100%
# of the bound, a few percent of bytes either way)
MEDIAN_GROWTH = 0.03  # over all the re-expressions of a clip: the median target
DUMMY_GROWTH = 0.10  # a dummy root: the body is coded as without it (WORLD forms, world-axis translations);
# the dummy joint itself costs 20-30 bytes of skeleton, 2% of a 1.2 KB file, and one generated clip's
# two searches land apart by a few percent (seed 0 under a 1-degree turn: 1,318 against 1,233 bytes,
# +6.9%, before effort 2 accepted 90-100% of the bound; 1,326 against 1,217, +9.0%, since)


@pytest.fixture(scope="module")
def bvh():
    return load(DATA / "07_03.bvh")


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
    np.testing.assert_allclose(pb[:, -pa.shape[1] :], pa, atol=1e-6)


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


def _check_invariant(original: Motion, moved: Motion, growth: float = GROWTH) -> float:
    """Every joint in place, the bound held on the moved clip; returns the file's growth."""
    _same_places(original, moved)
    base, _ = _coded(original)
    size, error = _coded(moved)
    assert error <= BOUND
    assert size <= base * (1.0 + growth), f"{size} bytes against {base}"
    return size / base - 1.0


def _all_reexpressions(motion: Motion):
    yield reexpress.with_dummy_root(motion, (0.0, -90.0, 0.0))
    yield reexpress.with_dummy_root(motion, (30.0, 20.0, 10.0))
    for order in reexpress.EULER_ORDERS:
        yield reexpress.with_euler_orders(motion, order)
    yield reexpress.with_position_channels(motion)
    yield reexpress.with_dummy_root(motion, position_channels=True)


@pytest.mark.slow
@pytest.mark.parametrize("clip", ["bvh", "amc"])
def test_the_median_re_expression_costs_at_most_3_percent(clip, request):
    motion = request.getfixturevalue(clip)
    growth = [_check_invariant(motion, moved) for moved in _all_reexpressions(motion)]
    assert np.median(growth) <= MEDIAN_GROWTH, np.round(growth, 3)


turns = st.tuples(*[st.floats(-180.0, 180.0, allow_nan=False)] * 3)


@settings(max_examples=3)
@given(turn=st.one_of(turns, st.sampled_from([(0.0, -90.0, 0.0), (0.0, 90.0, 0.0)])))
def test_a_dummy_root_with_a_constant_rotation_changes_nothing(bvh, turn):
    _check_invariant(bvh, reexpress.with_dummy_root(bvh, turn), DUMMY_GROWTH)


@pytest.mark.parametrize("factor", [0.01, 2.54])
def test_file_units_do_not_matter(bvh, factor):
    moved = reexpress.with_units(bvh, factor)
    np.testing.assert_allclose(_joints_cm(moved), _joints_cm(bvh), atol=1e-6)
    codec = get_codec("kinwave", max_error_cm=BOUND, error_measure="shell")
    assert codec.encode(moved) == codec.encode(bvh)  # the coded motion is the same, byte for byte
    _check_invariant(bvh, moved)


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
    joints = [
        Joint(
            "root",
            -1,
            (0.0, 90.0, 0.0),
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
            "ZXY",
        )
    ]
    for k in range(1, 5):
        order = "".join(rng.permutation(list("XYZ")))
        joints.append(
            Joint(f"j{k}", k - 1, tuple(rng.uniform(-20, 20, 3)), tuple(f"{a}rotation" for a in order), order)
        )
    sk = Skeleton(tuple(joints), 100.0)
    t = np.linspace(0.0, 20.0, 1200)[:, None]
    channels = np.zeros((1200, sk.num_channels))
    channels[:, :3] = np.hstack([30 * np.sin(t), 90 + 2 * np.sin(3 * t), 40 * t])
    channels[:, 3:] = rng.uniform(10, 40, sk.num_channels - 3) * np.sin(
        rng.uniform(0.5, 3, sk.num_channels - 3) * t + rng.uniform(0, 6, sk.num_channels - 3)
    )
    return Motion(sk, 60.0, channels)


@settings(max_examples=4)
@given(seed=st.integers(0, 2**16), turn=turns)
def test_generated_skeletons_under_a_rotated_dummy_root_keep_the_bound(seed, turn):
    motion = _chain(seed)
    moved = reexpress.with_dummy_root(motion, turn)
    _same_places(motion, moved)
    assert _coded(moved)[1] <= BOUND


@settings(max_examples=4)
@given(seed=st.integers(0, 2**16), turn=turns)
def test_generated_skeletons_under_a_rotated_dummy_root_cost_about_the_same(seed, turn):
    motion = _chain(seed)
    _check_invariant(motion, reexpress.with_dummy_root(motion, turn), DUMMY_GROWTH)


def test_reexpressions_keep_every_joint_in_place(bvh, amc):
    for motion in (bvh, amc):
        for moved in (
            reexpress.with_dummy_root(motion, (10.0, -90.0, 30.0)),
            reexpress.with_position_channels(motion),
            reexpress.with_euler_orders(motion, "ZYZ"),
            reexpress.with_dummy_root(motion, position_channels=True),
        ):
            _same_places(motion, moved)


def test_reexpress_refuses_what_it_cannot_write(bvh):
    with pytest.raises(ValueError, match="unit factor"):
        reexpress.with_units(bvh, 0.0)
    with pytest.raises(ValueError, match="Euler order"):
        reexpress.with_euler_orders(bvh, "XXY")
