"""The coding blocks under kinwave: the context-adaptive arithmetic coder, trend + wavelet
segments, closed-loop target angles, the convex step allocation and the compact skeleton."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import pywt
from hypothesis import given, strategies as st

from mocodec import rotations
from mocodec.codecs.kinwave import channelcode, kinalloc
from mocodec.codecs.shared import closedloop
from mocodec.coding.entropy import coefcoder
from mocodec.coding.transforms import trendwave, wavelets
from mocodec.errors import CorruptStreamError
from mocodec.formats import container, skeleton_bin
from mocodec.formats.skeleton_bin import pack_skeleton, unpack_skeleton
from mocodec.human import human_model
from mocodec.kinematics import channel_plan, forward_kinematics


@given(
    seed=st.integers(0, 2**32 - 1),
    frames=st.integers(1, 700),
    keyframe=st.booleans(),
    spread=st.sampled_from([0.0, 0.3, 3.0, 1e5]),
    rev=st.sampled_from([1, 2]),
)
def test_coefficient_coder_round_trips(seed, frames, keyframe, spread, rev):
    rng = np.random.default_rng(seed)
    lay = trendwave.layout(frames, 128, 4, keyframe)
    channels = 5
    const = (rng.random(channels) < 0.3).astype(np.int64)
    knots = np.cumsum(rng.integers(-3000, 3000, (channels, lay.num_knots)), axis=1)
    coeffs = np.round(
        rng.laplace(0, spread, (channels, lay.num_coeffs)) if spread else np.zeros((channels, lay.num_coeffs))
    ).astype(np.int64)
    coeffs[const == 1] = 0
    side = (rng.integers(0, 256, rng.integers(0, 50)), rng.integers(-128, 128, rng.integers(0, 9)))
    data = coefcoder.encode(const, knots, coeffs, lay.padded, lay.levels, revision=rev, side=side)
    out = coefcoder.decode(data, channels, lay.num_knots, lay.padded, lay.levels, rev, tuple(map(len, side)))
    c2, k2, co2, used = out.const, out.knots, out.coeffs, out.used
    assert all(np.array_equal(a, b) for a, b in zip(out.side, side))
    assert all(np.array_equal(t, np.diff(q, prepend=0)) for t, q in zip(out.terms, side))  # as coded
    assert used >= len(data) - 1 and np.array_equal(c2, const)
    live = const == 0
    assert np.array_equal(k2[live], knots[live]) and np.array_equal(k2[~live, 0], knots[~live, 0])
    assert np.array_equal(co2, coeffs)


@pytest.mark.parametrize("rev", [1, 2])
def test_group_sizes_are_each_groups_own_encoding(rev):
    rng = np.random.default_rng(5)
    lay = trendwave.layout(700, 256, 5, False)
    knots = np.cumsum(rng.integers(-50, 50, (12, lay.num_knots)), axis=1)
    coeffs = np.round(rng.laplace(0, rng.choice([0.2, 2.0, 40.0], (12, 1)), (12, lay.num_coeffs))).astype(np.int64)
    sizes = coefcoder.group_sizes(knots, coeffs, lay.padded, lay.levels, 3, revision=rev)
    one_by_one = [
        len(coefcoder.encode(np.zeros(3, np.int64), knots[a : a + 3], coeffs[a : a + 3], lay.padded, lay.levels, rev))
        for a in range(0, 12, 3)
    ]
    assert sizes.tolist() == one_by_one and len(set(one_by_one)) == 4


def test_differences_code_a_smooth_approximation_band_smaller():
    """Neighbouring approximation values that are alike cost fewer bits as differences
    (revision 2)."""
    lay = trendwave.layout(1024, 256, 5, False)
    rng = np.random.default_rng(3)
    coeffs = np.zeros((4, lay.num_coeffs), dtype=np.int64)
    for o, n, lev in zip(np.cumsum(np.r_[0, lay.padded[:-1]]), lay.padded, lay.levels):
        coeffs[:, o : o + (n >> lev)] = np.round(200 + np.cumsum(rng.normal(0, 3, (4, n >> lev)), axis=1))
    args = (np.zeros(4, np.int64), np.zeros((4, lay.num_knots), np.int64), coeffs, lay.padded, lay.levels)
    plain, delta = coefcoder.encode(*args), coefcoder.encode(*args, revision=2)
    assert len(delta) < 0.8 * len(plain)
    assert np.array_equal(coefcoder.decode(delta, 4, lay.num_knots, lay.padded, lay.levels, revision=2).coeffs, coeffs)


def test_warm_contexts_learn_a_skewed_source_sooner():
    """A warm context (counting estimator at first) codes 200 decisions of a 1-in-100 source
    in half the bytes of a cold one (beyond the 5 the coder's flush takes); after WARM_DONE
    decisions both adapt alike."""
    import numba

    from mocodec.coding.entropy import binarycoder as bc

    @numba.njit
    def code(bits, state):
        st, buf = bc.encoder_state(), np.empty(4096, dtype=np.uint8)
        for b in bits:
            bc.put(st, buf, state, 0, b)
        return bc.finish(st, buf)

    bits = (np.arange(200) % 100 == 99).astype(np.int64)
    warm, cold = bc.new_state(1, warm=True), bc.new_state(1)
    assert code(bits, warm) - 5 <= 0.5 * (code(bits, cold) - 5)
    code(np.zeros(bc.WARM_DONE, np.int64), warm)
    code(np.zeros(bc.WARM_DONE, np.int64), cold)
    assert warm[2, 0] == cold[2, 0] == bc.WARM_DONE


def test_coefficient_coder_adapts_to_sparse_data():
    """Mostly-zero coefficients cost a small fraction of a bit each; random bytes decode
    to something of the right shape without reading outside the buffer."""
    lay = trendwave.layout(1024, 128, 4, False)
    coeffs = np.zeros((10, lay.num_coeffs), dtype=np.int64)
    coeffs[:, ::97] = 3
    data = coefcoder.encode(
        np.zeros(10, np.int64), np.zeros((10, lay.num_knots), np.int64), coeffs, lay.padded, lay.levels
    )
    assert len(data) * 8 < 0.2 * coeffs.size  # 1% nonzero: about 0.09 bits of entropy each for the zero flags
    out = coefcoder.decode(bytes(range(256)) * 3, 10, lay.num_knots, lay.padded, lay.levels, 2, (5, 3))
    assert out.coeffs.shape == coeffs.shape and [len(q) for q in out.side] == [5, 3]


def test_layout_keyframe_and_knots():
    lay = trendwave.layout(300, 128, 4, True)
    assert lay.starts.tolist() == [0, 1, 129, 257]
    assert lay.knot_frames.tolist() == [0, 1, 129, 257, 299]
    assert lay.padded.tolist() == [0, 128, 128, 48] and lay.levels.tolist() == [0, 4, 4, 4]
    one = trendwave.layout(1, 128, 4, True)
    assert one.starts.tolist() == [0] and one.num_coeffs == 0 and one.num_knots == 1


@pytest.mark.parametrize("lead", [1, 2, 3])
def test_layout_lead_moves_the_grid_earlier(lead):
    """A lead shortens the first window and pads its block in front, so every later block
    starts ``lead`` frames earlier; the wavelets still reconstruct exactly, and a tail of at
    most ``lead`` frames joins the last window instead of costing a knot of its own."""
    lay = trendwave.layout(300, 128, 4, True, lead=lead)
    assert lay.starts.tolist() == [0, 1, 129 - lead, 257 - lead]
    assert lay.leads.tolist() == [0, lead, 0, 0] and lay.padded[1] == 128
    x = np.random.default_rng(lead).normal(size=(2, 300))
    back, knots_only = _round_trip(x, lay)
    assert np.allclose(back[:, 1:], x[:, 1:], atol=1e-10)
    assert np.array_equal(back[:, 0], knots_only[:, 0])  # the keyframe: its knot, no coefficient
    short = trendwave.layout(256, 128, 4, False, lead=lead)
    assert short.starts.tolist() == [0, 128 - lead] and short.lengths[-1] == 128 + lead
    assert short.knot_frames.tolist() == [0, 128 - lead, 255] and short.padded.tolist() == [128, 144]


def _resampled_walk(rng, frames, every):
    """A random walk drawn at every ``every``-th frame, joined linearly between."""
    coarse = np.cumsum(rng.normal(size=(6, frames // every + 2)), axis=1)
    return np.array([np.interp(np.arange(frames) / every, np.arange(coarse.shape[1]), row) for row in coarse])


@pytest.mark.parametrize("trim", [0, 1, 2, 3])
def test_grid_phase_finds_the_frames_of_a_lower_rate(trim):
    """Motion resampled from a quarter of the rate has its drawn samples every fourth frame:
    a clip cut ``trim`` frames later has them on frames -trim mod 4. Noise has no such frames."""
    rng = np.random.default_rng(trim)
    walk = _resampled_walk(rng, 1200, 4)[:, trim:] * 20.0
    assert trendwave.grid_phase(walk, "cdf97") == -trim % 4
    assert trendwave.grid_phase(rng.normal(size=(6, 1200)) * 20.0, "cdf97") is None
    assert trendwave.grid_phase(walk[:, :40], "cdf97") is None  # too short to tell


def _round_trip(x: np.ndarray, lay: trendwave.Layout) -> tuple[np.ndarray, np.ndarray]:
    """``x`` through kinwave's rows at a step of 1e-12 (as good as exact; the seams' smoothing is
    at most a step), and the trend alone (its knots, every coefficient 0)."""
    rows = x.shape[0]
    const, step, fraction, base = np.zeros(rows, bool), np.full(rows, 1e-12), np.ones(rows), np.zeros(rows)
    factors = (np.ones(lay.num_knots), np.ones(lay.num_coeffs), np.ones(max(lay.starts.size - 1, 0)))
    knots, coeffs, _ = channelcode.quantise(x, const, step, fraction, base, lay, factors, 0.5)
    back = channelcode.reconstruct(knots, coeffs, const, step, fraction, base, lay, factors, 1.0, 8)
    trend = channelcode.reconstruct(knots, np.zeros_like(coeffs), const, step, fraction, base, lay, factors, 1.0, 8)
    return back, trend


def test_trend_and_wavelets_reconstruct_exactly():
    rng = np.random.default_rng(1)
    lay = trendwave.layout(333, 64, 4, False)
    x = np.cumsum(rng.normal(size=(3, 333)), axis=1)
    back, tr = _round_trip(x, lay)
    knots = x[:, lay.knot_frames]
    assert np.allclose(tr[:, lay.knot_frames], knots)  # passes through its knots
    assert np.abs(np.diff(tr, axis=1)).max() < np.abs(np.diff(x, axis=1)).max() + np.ptp(x)  # no jumps
    residual = x - tr
    assert np.allclose(back, x, atol=1e-10)  # the trend and the wavelets of the residual
    # with the knots, a segment's residual is zero at its start
    assert np.allclose(residual[:, lay.starts], 0.0)


@pytest.mark.parametrize("wavelet", ["cdf97", "d4", "haar"])
def test_compiled_wavelets_give_pywavelets_floats(wavelet):
    """Every sum in PyWavelets' order: the same floats, bit for bit, so bodies keep their bytes
    (levels down to bands shorter than the filter, scales from 1e-3 to 1e3)."""
    w = pywt.Wavelet(wavelets.WAVELETS[wavelet])
    rng = np.random.default_rng(3)
    for levels in range(1, 10):
        for multiple in (1, 2, 3, 5):
            n = multiple << levels
            x = rng.normal(size=(3, n)) * 10.0 ** rng.uniform(-3, 3)
            with warnings.catch_warnings():  # (deep levels on short rows: what kinwave does)
                warnings.simplefilter("ignore", UserWarning)
                bands = pywt.wavedec(x, w, mode="periodization", level=levels, axis=-1)
            coeffs = wavelets.forward(x, wavelet, levels)
            assert np.array_equal(coeffs, np.concatenate(bands, axis=-1)), (levels, n)
            c = rng.normal(size=(3, n))
            split = np.split(c, np.cumsum(wavelets.band_lengths(n, wavelet, levels))[:-1], axis=-1)
            reference = pywt.waverec(split, w, mode="periodization", axis=-1)
            assert np.array_equal(wavelets.inverse(c, n, wavelet, levels), reference), (levels, n)


def test_compiled_rows_quantise_within_half_a_step_and_round_where_far():
    """rows.quantise then rows.reconstruct: plain rounding (dead zone 0.5) misses a smooth signal
    by at most about half a step; a wide dead zone misses by more, and code_depth, which rounds
    the coefficients reaching the frames it misses far to the nearest integer, brings them
    closer; without far rounding code_depth is quantise then reconstruct."""
    rng = np.random.default_rng(4)
    lay = trendwave.layout(300, 128, 4, 1)
    x = np.cumsum(rng.normal(size=(4, 300)), axis=1) * 3.0
    const = np.array([False, False, True, False])
    x[2] = 7.25
    step = np.array([0.05, 0.2, 0.1, 0.5])
    fraction, base = np.full(4, 0.125), np.zeros(4)
    factors = (np.ones(lay.num_knots), np.ones(lay.num_coeffs), np.ones(lay.starts.size - 1))
    knots, coeffs, scaled = channelcode.quantise(x, const, step, fraction, base, lay, factors, 0.5)
    assert (coeffs[const] == 0).all() and (knots[2] == 580).all()  # 7.25 in quanta of 0.0125
    out = channelcode.reconstruct(knots, coeffs, const, step, fraction, base, lay, factors, 1.0, 8)
    assert out[2] == pytest.approx(7.25)
    assert (np.abs(out - x).max(axis=1) < step * 1.5).all()
    _, coarse, coarse_scaled = channelcode.quantise(x, const, step, fraction, base, lay, factors, 0.2)
    assert np.count_nonzero(coarse) < np.count_nonzero(coeffs)
    rough = channelcode.reconstruct(knots, coarse, const, step, fraction, base, lay, factors, 1.0, 8)
    plain = channelcode.code_depth(x, const, step, fraction, base, lay, factors, 0.2, 1.0, 8, 0.0)
    assert np.array_equal(plain[1], coarse) and np.array_equal(plain[2], rough)
    _, nearest, fixed, _ = channelcode.code_depth(x, const, step, fraction, base, lay, factors, 0.2, 1.0, 8, 0.7)
    changed = (nearest != coarse).any(axis=1)
    assert changed.any() and not changed[2]
    assert (np.abs(nearest - coarse_scaled)[nearest != coarse] <= 0.5).all()  # the nearest integers
    assert np.array_equal(fixed[~changed], rough[~changed])
    assert (np.abs(fixed - x).max(axis=1) < np.abs(rough - x).max(axis=1) + 1e-12).all()


def test_a_depth_in_one_call_is_each_step_one_call_at_a_time():
    """code_depth with coding forms (a rotation vector about a mean, another Tait-Bryan order,
    a WORLD form turned by its parent), translations on the world's axes and isolated frames
    gives the same integers and floats as the conversions, quantise, reconstruct and the
    patches called one at a time (what the encoder did before)."""
    from mocodec.codecs.kinwave.body import apply_patches, on_axes
    from mocodec.codecs.shared import rotvec

    rng = np.random.default_rng(11)
    frames, lay = 90, trendwave.layout(90, 64, 3, 0)
    angles = np.cumsum(rng.normal(0.0, 4.0, (9, frames)), axis=1)  # three joints, file order ZXY
    translations = np.cumsum(rng.normal(0.0, 0.5, (3, frames)), axis=1)
    values = np.vstack([translations, np.full((1, frames), 12.5), angles])  # row 3: a constant
    orders, forms = ("ZXY",) * 3, np.array([rotvec.VECTOR, 2, rotvec.WORLD + 4])
    means = rotvec.mean_quats(np.array([[10, -4, 3], [0, 0, 0], [0, 0, 0]]), 2.0)
    pre = rotations.quat_normalize(rng.normal(size=(3, 4)))
    turn = rotations.quat_normalize(rng.normal(size=4))
    quats = rotvec.euler_quats(angles, orders)
    cols, moved_rows, isolated = np.arange(4, 13), np.array([[0, 1, 2]]), np.array([1, 40, 41])
    form_set = rotvec.FormSet(orders, forms, means)
    const, step = np.arange(13) == 3, np.full(13, 0.3)
    fraction, base = np.full(13, 0.125), np.zeros(13)
    factors = (np.ones(lay.num_knots), np.ones(lay.num_coeffs), np.ones(lay.starts.size - 1))
    knots, coeffs, out, patches = channelcode.code_depth(
        values, const, step, fraction, base, lay, factors, 0.4, 1.0, 8, 0.0,
        (cols, quats, form_set, pre), (moved_rows, turn[None]), isolated,
    )  # fmt: skip

    coded = values.copy()
    coded[cols] = form_set.to_forms(angles, quats, pre)
    coded[:3] = on_axes(coded[:3], turn)
    wanted = coded[:, isolated]
    coded[:, isolated] = (coded[:, isolated - 1] + coded[:, isolated + 1]) / 2.0
    k_int, c_int, _ = channelcode.quantise(coded, const, step, fraction, base, lay, factors, 0.4)
    rec = channelcode.reconstruct(k_int, c_int, const, step, fraction, base, lay, factors, 1.0, 8)
    patch = np.round((wanted - rec[:, isolated]) / (step[:, None] * trendwave.KEYFRAME_QUANTUM)).astype(np.int64)
    patch[const] = 0
    apply_patches(rec, step[:, None], isolated, patch)
    rec[:3] = on_axes(rec[:3], turn, inverse=True)
    rec[cols] = form_set.from_forms(rec[cols], pre)
    assert np.array_equal(knots, k_int) and np.array_equal(coeffs, c_int) and np.array_equal(patches, patch)
    assert np.array_equal(out, rec)
    assert patches.any() and np.abs(out[3] - 12.5).max() <= 0.3 * 0.125 / 2  # (its quantum)
    assert np.abs(out[:3] - values[:3]).max() < 1.0  # (the steps are 0.3)
    assert np.degrees(rotvec.mean_distances(quats, rotvec.euler_quats(out[cols], orders))).max() < 1.0


def test_closed_loop_targets_restore_the_global_orientation(walk_bvh, walk_amc):
    rng = np.random.default_rng(2)
    for motion in (walk_bvh[:50], walk_amc[:50]):
        sk = motion.skeleton
        plan = channel_plan(sk)
        _, quat = forward_kinematics(sk, motion.channels)
        for j in range(1, len(sk)):
            k = int((plan.rot_index[j] >= 0).sum())
            if not k:
                continue
            idx, axes = plan.rot_index[j, :k], plan.rot_axis[j, :k]
            p = sk.parents[j]
            # a parent decoded 2 degrees off about a random axis
            axis = rng.normal(size=3)
            wrong = rotations.quat_multiply(quat[:, p], rotations.axis_angle_to_quat(axis / np.linalg.norm(axis), 2.0))
            angles = closedloop.target_angles(
                motion.channels[:, idx], axes, np.ones(k, bool), plan.axis_quat[j], plan.has_axis[j], wrong, quat[:, j]
            )
            glob = closedloop.compose(angles, axes, plan.axis_quat[j], plan.has_axis[j], wrong)
            err = np.degrees(rotations.quat_distance(glob, quat[:, j]))
            before = np.degrees(
                rotations.quat_distance(
                    closedloop.compose(motion.channels[:, idx], axes, plan.axis_quat[j], plan.has_axis[j], wrong),
                    quat[:, j],
                )
            )
            if k == 3:  # one Gauss-Newton step: what is left is second order in the 2 degrees
                assert err.max() < 0.05 and (err < before / 40).all(), sk.names[j]
            else:  # fewer DOFs: the best reachable rotation, never worse than doing nothing
                assert (err <= before + 1e-9).all(), sk.names[j]


def test_compose_matches_forward_kinematics(walk_amc):
    sk = walk_amc.skeleton
    plan = channel_plan(sk)
    _, quat = forward_kinematics(sk, walk_amc.channels)
    for j in range(1, len(sk)):
        k = int((plan.rot_index[j] >= 0).sum())
        if k:
            q = closedloop.compose(
                walk_amc.channels[:, plan.rot_index[j, :k]],
                plan.rot_axis[j, :k],
                plan.axis_quat[j],
                plan.has_axis[j],
                quat[:, sk.parents[j]],
            )
            assert np.degrees(rotations.quat_distance(q, quat[:, j])).max() < 1e-4


@pytest.mark.parametrize("mode", kinalloc.MODES)
def test_allocation_meets_its_model_bound_and_favours_long_levers(walk_amc, mode):
    sk = walk_amc.skeleton
    angles = tuple(sum(c.endswith("rotation") for c in j.channels) for j in sk.joints)
    rot, trans = kinalloc.steps(sk, angles, 3, mode, True)
    coded = np.array(angles) > 0
    assert np.isfinite(rot[coded]).all() and np.isnan(rot[~coded]).all() and trans > 0
    # modelled error of every point (or the mean of its norm) is at most 1
    lev2 = kinalloc.points(sk, True, mode)
    u = np.where(coded, np.array(angles) * np.radians(np.nan_to_num(rot)) ** 2, 0.0)
    err2 = u @ lev2 + 3 * trans**2
    worst = np.sqrt(err2).mean() if mode == "mean" else err2.max()
    assert worst == pytest.approx(1.0, rel=1e-3)
    # a femur (long bones below) gets a finer step than a toe
    assert rot[sk.index("lfemur")] < rot[sk.index("ltoes")]
    # open loop must protect the hips more than closed loop does
    open_rot, _ = kinalloc.steps(sk, angles, 3, mode, False)
    assert open_rot[sk.index("lfemur")] < rot[sk.index("lfemur")]


@pytest.mark.parametrize("which", ["bvh", "amc", "human"])
def test_compact_skeleton_is_exact_and_small(which, walk_bvh, walk_amc):
    sk = {"bvh": walk_bvh.skeleton, "amc": walk_amc.skeleton, "human": human_model()}[which]
    data = pack_skeleton(sk)
    back = unpack_skeleton(data)
    assert container.skeleton_id(back) == container.skeleton_id(sk)
    import zlib

    assert len(zlib.compress(data, 9)) < 0.75 * len(zlib.compress(str(container.skeleton_to_dict(sk)).encode(), 9))


def test_compact_skeleton_keeps_mirrored_and_signed_zero_offsets_exact():
    from mocodec.skeleton import Joint, Skeleton

    joints = (
        Joint("root", -1, (0.0, 0.0, 0.0)),
        Joint("a", 0, (1.25, -0.0, 2.0)),
        Joint("b", 0, (-1.25, 0.0, 2.0)),
        Joint("c", 0, (-1.25, -0.0, 2.0)),
        Joint("d", 0, (0.6 * 2.68184, 0.1 * 2.68184, 0.3 * 2.68184)),
    )
    sk = Skeleton(joints, 100.0, "mirrors")
    back = unpack_skeleton(pack_skeleton(sk))
    assert [np.copysign(1.0, j.offset).tolist() for j in back.joints] == [
        np.copysign(1.0, j.offset).tolist() for j in joints
    ]
    assert container.skeleton_id(back) == container.skeleton_id(sk)


def test_rounded_offsets_are_written_in_fixed_point(walk_bvh, walk_amc):
    """Offsets rounded to 0.001 cm (a lossy file's) go as untagged integers at a fixed number
    of places: exact, and at least a seventh smaller than the tagged column."""
    import zlib

    from mocodec.formats.skeleton_bin import round_offsets

    for motion in (walk_bvh, walk_amc):
        rounded = round_offsets(motion.skeleton, 0.001)
        data = pack_skeleton(rounded)
        assert container.skeleton_id(unpack_skeleton(data)) == container.skeleton_id(rounded)
        offsets = [tuple(map(float, j.offset)) for j in rounded.joints]
        tagged = skeleton_bin.offset_column(offsets, None)
        fixed = skeleton_bin.offset_column(offsets, skeleton_bin.fixed_places(offsets))
        assert fixed[0] > 0 and fixed in data and len(zlib.compress(fixed)) < 6 / 7 * len(zlib.compress(tagged))


@pytest.mark.parametrize("form", [*range(1, 8), 8, 9, 12])
def test_every_coding_form_round_trips_continuously(walk_bvh, form):
    """Euler angle rows to a coding form (a rotation vector about the mean, Euler angles in a
    Tait-Bryan order, either of the rotation turned by a constant: WORLD) and back: the same
    rotations, as the very triples Motion.continuous gives (frame 0 of the walk is in the
    principal range), in the file's order or a proper one."""
    from mocodec.codecs.shared import rotvec
    from mocodec.reexpress import with_euler_orders

    for motion in (walk_bvh, with_euler_orders(walk_bvh, "YXY")):
        sk = motion.skeleton
        rows, orders = [], []
        for name in ("lShldr", "rThigh", "hip"):
            j = sk.index(name)
            rows.append(sk.channel_offsets[j] + np.array(sk.joints[j].rotation_channel_indices()))
            orders.append(sk.joints[j].rotation_order)
        orders = tuple(orders)
        euler = motion.continuous().channels[:, np.concatenate(rows)].T
        quats = rotvec.euler_quats(euler, orders)
        pre = rotations.quat_normalize(np.array([[0.3, 0.5, -0.2, 0.7]] * len(orders)))  # a WORLD form's turn
        if form >= rotvec.WORLD:
            quats = rotations.quat_multiply(pre[None], quats)
        means = rotvec.mean_quats(rotvec.mean_codes(quats, 2.0, 0.0), 2.0)
        quats = rotvec.euler_quats(euler, orders)
        forms = np.full(len(orders), form)
        back = rotvec.from_forms(rotvec.to_forms(euler, orders, forms, means, pre=pre), orders, forms, means, pre)
        turn = rotations.quat_distance(quats, rotvec.euler_quats(back, orders))
        assert turn.max() < 1e-6  # arccos: 3e-8 rad of noise
        if orders[0][0] != orders[0][2]:  # at a proper order's lock the split of its angles is free
            assert np.abs(back - euler).max() < 1e-9


def test_compact_skeleton_rejects_damage(walk_bvh):
    data = pack_skeleton(walk_bvh.skeleton)
    for bad in (data[:-3], data + b"\x00", b"\x07" + data[1:], data[:40]):
        with pytest.raises(CorruptStreamError):
            unpack_skeleton(bad)
