"""Error measures: known answers on synthetic signals, the VMSE properties the thesis relies
on, pose measures on real clips, and the pairing checks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocodec import Joint, Motion, Skeleton, human_model
from mocodec.metrics import (
    MismatchError,
    band_split,
    compare,
    dof_errors,
    groups as grp,
    natural as nat,
    pose,
    visual_errors,
    weighted_error,
)

FPS = 120.0


def _psnr_pair(x, y, fps=FPS):
    dof = dof_errors(x[:, None], y[:, None])
    vis = visual_errors(y[:, None] - x[:, None], dof.range, fps)
    return float(dof.psnr[0]), float(vis.vpsnr[0])


# ----- (6-1) to (6-8) ------------------------------------------------------------------------
def test_waveform_measures_known_answers():
    n = 1200
    t = np.arange(n) / FPS
    x = 40.0 * np.sin(2 * np.pi * 0.5 * t)  # range 80, energy per sample 800
    c = 2.0
    dof = dof_errors(x[:, None], x[:, None] + c)
    assert dof.mse[0] == pytest.approx(c * c)
    assert dof.rmse[0] == pytest.approx(c)
    assert dof.nmse[0] == pytest.approx(c * c / 800.0, rel=1e-3)
    assert dof.range[0] == pytest.approx(80.0, rel=1e-4)
    assert dof.pmse[0] == pytest.approx(c * c / 80.0**2, rel=1e-3)
    assert dof.psnr[0] == pytest.approx(20 * np.log10(80.0 / c), abs=1e-3)
    assert dof.nsnr[0] == pytest.approx(-10 * np.log10(c * c / 800.0), abs=1e-2)
    assert dof.max_abs[0] == pytest.approx(c) and dof.mean_abs[0] == pytest.approx(c)


def test_rotation_errors_wrap_and_translations_do_not():
    orig = np.array([[179.0, 179.0], [0.0, 0.0]])
    dec = np.array([[-179.0, -179.0], [0.0, 0.0]])
    dof = dof_errors(orig, dec, rotation_mask=np.array([True, False]))
    assert dof.max_abs[0] == pytest.approx(2.0)
    assert dof.max_abs[1] == pytest.approx(358.0)


def test_constant_and_exact_dofs_are_reported_apart():
    t = np.arange(200) / FPS
    orig = np.stack([np.sin(t), np.full_like(t, 5.0), np.cos(t) * 10, t * 1e-9], axis=1)
    dec = orig + np.array([0.01, 0.5, 0.0, 0.0])
    dof = dof_errors(orig, dec)
    assert dof.constant.tolist() == [False, True, False, True]  # 1e-9 range is float noise
    assert dof.exact.tolist() == [False, False, True, False]
    assert np.isnan(dof.pmse[1]) and np.isinf(dof.psnr[2])
    assert dof.body_psnr == pytest.approx(dof.psnr[0])  # only the varying, inexact DOF
    assert np.isfinite(dof.pooled_psnr)
    assert dof_errors(orig, orig).body_psnr == np.inf


# ----- the visual MSE (6-15) to (6-17) ---------------------------------------------------------
def test_unit_weights_make_vmse_the_mse():
    err = np.random.default_rng(1).normal(size=(700, 5)).cumsum(axis=0) * 0.1
    for fps in (30.0, 60.0, 120.0, 12.0):
        vis = visual_errors(err, np.ones(5), fps, weights=(1, 1, 1, 1))
        assert np.allclose(vis.vmse, np.square(err).mean(axis=0), rtol=1e-12)


def test_bands_separate_frequencies():
    t = np.arange(2400) / FPS
    for freq, band in ((0.4, 0), (2.0, 1), (5.0, 2), (20.0, 3)):
        e = np.sin(2 * np.pi * freq * t)[:, None]
        energy = [float(np.square(b[200:-200]).mean()) for b in band_split(e, FPS)]
        assert energy[band] > 0.9 * sum(energy), (freq, energy)
        ratio = np.square(weighted_error(e, FPS)[200:-200]).mean() / np.square(e[200:-200]).mean()
        assert ratio == pytest.approx((0.25, 0.5, 1.0, 2.25)[band] ** 2, rel=0.15)


def test_edges_above_nyquist_leave_empty_bands():
    e = np.random.default_rng(2).normal(size=(100, 2))
    bands = band_split(e, 10.0)  # Nyquist 5 Hz: the 7 Hz edge is dropped
    assert not bands[3].any()
    assert np.allclose(sum(bands), e)


def test_short_signals_still_measure():
    for n in (1, 2, 5):
        vis = visual_errors(np.ones((n, 1)), np.ones(1), FPS)
        assert np.isfinite(vis.vmse).all()


def test_time_shift_costs_less_vpsnr_than_psnr():
    """Fig. 6-2: phase errors of smooth motion are forgiven by the VPSNR."""
    t = np.arange(3600) / FPS
    x = 30 * np.sin(2 * np.pi * 0.3 * t) + 10 * np.sin(2 * np.pi * 0.8 * t + 1)
    for shift in (2, 6, 12):
        y = np.roll(x, shift)
        psnr, vpsnr = _psnr_pair(x[100:-100], y[100:-100])
        assert vpsnr > psnr + 6.0, (shift, psnr, vpsnr)


def test_quantisation_noise_costs_more_vpsnr_than_psnr():
    """Fig. 6-2: white amplitude noise is punished by the VPSNR."""
    t = np.arange(3600) / FPS
    x = 30 * np.sin(2 * np.pi * 0.3 * t) + 10 * np.sin(2 * np.pi * 0.8 * t + 1)
    for step in (0.5, 1.0, 2.0):
        y = np.round(x / step) * step
        psnr, vpsnr = _psnr_pair(x, y)
        assert vpsnr < psnr - 3.0, (step, psnr, vpsnr)


# ----- group measures (6-9) to (6-14) ------------------------------------------------------------
@pytest.fixture(scope="module")
def human():
    sk = human_model()
    rng = np.random.default_rng(4)
    lim = sk.limits
    lo, hi = np.where(np.isfinite(lim[:, 0]), lim[:, 0], -10), np.where(np.isfinite(lim[:, 1]), lim[:, 1], 10)
    base = (lo + hi) / 2
    chans = base + 0.2 * (hi - lo) * np.sin(np.arange(240)[:, None] / 20 + rng.uniform(0, 6, sk.num_channels))
    return Motion(sk, 30.0, chans)


def test_vector_errors_known_answer(human):
    sk = human.skeleton
    c = int(grp.group_channels(sk)["left_arm"][2])
    n_arm = len(grp.group_channels(sk)["left_arm"])
    err = np.zeros_like(human.channels)
    err[:, c] = 3.0
    width = sk.limits[c, 1] - sk.limits[c, 0]
    w = grp.vector_error(sk, human.channels, err)
    m = grp.max_vector_error(sk, human.channels, err)
    g = w.groups.index("left_arm")
    assert w.mean[g] == pytest.approx((3.0 / width) ** 2 / n_arm)
    assert m.max[g] == pytest.approx(3.0 / width)
    assert np.delete(w.mean, g).max() == 0
    heavier = grp.vector_error(sk, human.channels, err, weights={sk.channel_names[c]: 4.0}, ranges=1.0)
    assert heavier.mean[g] == pytest.approx(4 * 9.0 / n_arm)
    with pytest.raises(KeyError):
        grp.vector_error(sk, human.channels, err, weights={"nope.Xrotation": 1})


def test_root_translation_moves_positions_but_not_configurations(human):
    """(6-12) sees a shifted figure everywhere; (6-14) fixes each group's base, so only the
    torso group, which holds the root translation DOFs, sees it."""
    sk = human.skeleton
    moved = human.channels.copy()
    moved[:, sk.channel_index(sk.names[0] + ".Xposition")] += 0.05  # metres
    result = compare(human, human.with_channels(moved))
    assert result.position.mean == pytest.approx(np.full(len(result.position.groups), 0.05**2))
    conf = dict(zip(result.configuration.groups, result.configuration.mean))
    assert conf["torso"] > 0
    assert max(v for g, v in conf.items() if g != "torso") < 1e-20
    assert result.joints.mean == pytest.approx(5.0) and result.joints.max == pytest.approx(5.0)
    assert result.shell.max == pytest.approx(5.0)


def test_configuration_error_sees_twist_that_positions_miss():
    """The upper-arm twist of §6.1.4: the elbow stays put, the joint angles do not."""
    sk = Skeleton(
        [
            Joint("root", -1, (0, 0, 0), ("Xrotation",), "X"),
            Joint("arm", 0, (0, 1, 0), ("Yrotation",), "Y", body_part="left_arm"),
            Joint("elbow", 1, (0, 1, 0), (), "", body_part="left_arm"),
        ],
        units_per_metre=1.0,
    )
    orig = Motion(sk, 30.0, np.zeros((10, 2)))
    twisted = orig.with_channels(np.column_stack([np.zeros(10), np.full(10, 30.0)]))
    result = compare(orig, twisted)
    g = result.position.groups.index("left_arm")
    assert result.position.mean[g] == pytest.approx(0.0, abs=1e-24)
    assert result.configuration.mean[list(result.configuration.groups).index("left_arm")] > 0
    assert result.shell.max > 1.0  # 3 cm points off the arm turn by 30 degrees


# ----- pose measures ---------------------------------------------------------------------------
def test_shell_error_of_a_quarter_turn():
    sk = Skeleton(
        [Joint("a", -1, (0, 0, 0), ("Zrotation",), "Z"), Joint("b", 0, (0, 10, 0), (), "")], units_per_metre=100.0
    )
    pos = np.zeros((1, 2, 3))
    q = np.tile([1.0, 0, 0, 0], (1, 2, 1))
    turned = q.copy()
    turned[0, 0] = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]  # 90 degrees about z
    shell = pose.shell_errors(sk, pos, q, pos, turned, shell_cm=3.0)
    assert shell.max == pytest.approx(3.0 * np.sqrt(2))


def test_pose_measures_on_a_real_walk(walk_amc):
    same = compare(walk_amc, walk_amc)
    assert same.joints.max == 0 and same.shell.max == 0
    assert same.feet is not None and 0.1 < same.feet.contact_fraction < 0.9
    assert same.feet.excess_cm_s == pytest.approx(0.0)
    assert same.jerk.ratio == pytest.approx(1.0)
    sk = walk_amc.skeleton
    drift = walk_amc.channels.copy()
    units_per_cm = sk.units_per_metre / 100.0
    drift[:, sk.channel_index("root.Xposition")] += np.arange(len(drift)) / walk_amc.fps * 50 * units_per_cm
    slid = compare(walk_amc, walk_amc.with_channels(drift))
    assert slid.feet.decoded_cm_s > same.feet.original_cm_s + 35  # 50 cm/s added drift
    noisy = walk_amc.with_channels(walk_amc.channels + np.random.default_rng(5).normal(0, 0.3, drift.shape))
    assert compare(walk_amc, noisy).jerk.ratio > 2


def test_up_axis_and_feet():
    sk = human_model()
    assert pose.up_axis(sk) == (1, 1.0)
    names = {sk.names[i] for i in pose.foot_points(sk)}
    assert names and all(sk.body_parts[sk.index(n)].endswith("_leg") for n in names)


def test_rms_jerk_of_a_cubic():
    t = np.arange(50) / FPS
    p = np.zeros((50, 1, 3))
    p[:, 0, 0] = 100 * t**3  # 100 cm * t^3: jerk 6 m/s^3
    assert pose.rms_jerk(p, FPS) == pytest.approx(6.0, rel=1e-6)


# ----- natural movement (6.2.1) ---------------------------------------------------------------
def test_limit_violations_and_derivative_outliers(human):
    sk = human.skeleton
    c = int(np.flatnonzero(np.isfinite(sk.limits[:, 1]) & sk.rotation_mask)[0])
    bad = human.channels.copy()
    bad[100, c] = sk.limits[c, 1] + 5
    n = nat.naturalness(sk, human.channels, bad)
    assert n.limit_violations == 1 and n.original_limit_violations == 0
    assert n.velocity_outliers >= 1 and n.acceleration_outliers >= 1
    assert nat.naturalness(sk, human.channels, human.channels).velocity_outliers == 0


# ----- compare() ------------------------------------------------------------------------------
def test_compare_rejects_bad_pairs(walk_bvh, walk_amc):
    with pytest.raises(MismatchError, match="skeleton"):
        compare(walk_bvh, walk_amc)
    with pytest.raises(MismatchError, match="frame counts"):
        compare(walk_amc, walk_amc[:100])
    with pytest.raises(MismatchError, match="frame rates"):
        compare(walk_amc, Motion(walk_amc.skeleton, 60.0, walk_amc.channels))
    nan = walk_amc.channels.copy()
    nan[3, 3] = np.nan
    with pytest.raises(MismatchError, match="NaN"):
        compare(walk_amc, walk_amc.with_channels(nan))


def test_compare_reports_serialise(walk_bvh):
    noisy = walk_bvh.with_channels(walk_bvh.channels + np.random.default_rng(6).normal(0, 0.2, walk_bvh.channels.shape))
    result = compare(walk_bvh, noisy)
    data = json.loads(json.dumps(result.as_dict(per_joint=True), allow_nan=False))
    assert data["summary"]["constant_dofs"] > 0
    assert len(data["joints"]) == len(walk_bvh.skeleton) and len(data["dofs"]) == walk_bvh.num_channels
    assert 10 < data["summary"]["psnr_db"] < 60
    assert data["summary"]["vpsnr_db"] < data["summary"]["psnr_db"]  # white noise: VPSNR is harsher
    text = result.table()
    assert "VPSNR" in text and "left_arm" in text
    assert "rShldr" in result.per_joint_table()
