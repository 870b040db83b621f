import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from mocodec import rotations as r


def _angles(order, n=50, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-179, 179, (n, 3))
    a[:, 1] = rng.uniform(1, 179, n) if order[0] == order[2] else rng.uniform(-89, 89, n)
    return a


@pytest.mark.parametrize("order", r.EULER_ORDERS)
def test_euler_matches_scipy_in_all_12_orders(order):
    a = _angles(order)
    ref = Rotation.from_euler(order, a, degrees=True)
    np.testing.assert_allclose(r.euler_to_matrix(a, order), ref.as_matrix(), atol=1e-12)
    q = r.euler_to_quat(a, order)
    q_ref = ref.as_quat()[:, [3, 0, 1, 2]]
    np.testing.assert_allclose(np.abs(np.sum(q * q_ref, axis=1)), 1.0, atol=1e-12)
    np.testing.assert_allclose(r.quat_to_euler(q, order), a, atol=1e-8)
    np.testing.assert_allclose(r.matrix_to_euler(ref.as_matrix(), order), a, atol=1e-8)


def test_matrix_quaternion_round_trip_any_leading_shape():
    q = r.quat_normalize(np.random.default_rng(1).normal(size=(4, 5, 4)))
    m = r.quat_to_matrix(q)
    assert m.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape), atol=1e-12)
    back = r.matrix_to_quat(m)
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=-1)), 1.0, atol=1e-12)
    ref = Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(m.shape)
    np.testing.assert_allclose(m, ref, atol=1e-12)


def test_gimbal_lock_still_reproduces_the_rotation():
    a = np.array([[30.0, 90.0, 40.0], [10.0, -90.0, -70.0]])
    back = r.quat_to_euler(r.euler_to_quat(a, "ZXY"), "ZXY")
    np.testing.assert_allclose(r.euler_to_matrix(back, "ZXY"), r.euler_to_matrix(a, "ZXY"), atol=1e-7)


def test_partial_orders_and_bad_orders():
    np.testing.assert_allclose(r.euler_to_matrix(np.array([90.0]), "X") @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    with pytest.raises(ValueError):
        r.euler_to_matrix(np.zeros(3), "XXY")
    with pytest.raises(ValueError):
        r.quat_to_euler(np.array([1.0, 0, 0, 0]), "XY")


def test_quat_rotate_matches_matrix():
    rng = np.random.default_rng(2)
    q = r.quat_normalize(rng.normal(size=(10, 4)))
    v = rng.normal(size=(10, 3))
    np.testing.assert_allclose(r.quat_rotate(q, v), np.einsum("nij,nj->ni", r.quat_to_matrix(q), v), atol=1e-12)


def test_slerp_is_constant_speed_on_the_short_arc():
    q0 = r.euler_to_quat(np.array([0.0]), "Z")
    q1 = -r.euler_to_quat(np.array([120.0]), "Z")  # the same rotation, other sign
    t = np.linspace(0, 1, 7)
    qs = r.quat_slerp(np.broadcast_to(q0, (7, 4)), np.broadcast_to(q1, (7, 4)), t)
    np.testing.assert_allclose(np.degrees(r.quat_distance(q0, qs)), 120.0 * t, atol=1e-9)


def test_distance_is_the_rotation_angle_and_sign_blind():
    q0 = r.euler_to_quat(np.array([10.0, 20.0, 30.0]), "XYZ")
    q1 = r.quat_multiply(q0, r.axis_angle_to_quat(np.array([1.0, 2.0, 3.0]), 37.0))
    assert np.degrees(r.quat_distance(q0, q1)) == pytest.approx(37.0)
    assert np.degrees(r.quat_distance(q0, -q1)) == pytest.approx(37.0)
    assert r.quat_distance(q0, q0) == pytest.approx(0.0, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (3,), elements=st.floats(-3.0, 3.0)))
def test_log_exp_inverse(v):
    if np.linalg.norm(v) >= np.pi:  # the log returns the short rotation
        v = v / np.linalg.norm(v) * 3.0
    q = r.quat_exp(v)
    np.testing.assert_allclose(np.linalg.norm(q), 1.0)
    np.testing.assert_allclose(r.quat_log(q), v, atol=1e-9)


@pytest.mark.parametrize("order", ["XZ", "ZX", "XY", "YX", "YZ", "ZY"])
def test_exact_euler_recovers_two_axis_angles_past_ninety_degrees(order):
    rng = np.random.default_rng(11)
    angles = rng.uniform(-179.0, 179.0, (2000, 2))
    angles[:10, 1] = [90.0, -90.0, 89.9999, 179.0, -179.0, 120.0, -135.0, 0.0, 90.0, -90.0]
    q = r.euler_to_quat(angles, order)
    back = r.quat_to_exact_euler(q, order)
    again = r.euler_to_quat(back, order)
    assert np.abs(np.abs(np.sum(q * again, axis=-1)) - 1.0).max() < 1e-12
    assert np.abs(back - angles).max() < 1e-9  # in (-180, 180): the angles themselves
