"""The waveform coders of 000 ch. 7: quant, dpcm, adpcm, deadreckoning, dct, subband, svq, tvq."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec import ratecontrol
from mocodec.codecs import get_codec
from mocodec.codecs.waveform.deadreckoning import update_intervals
from mocodec.coding.entropy import intcoder
from mocodec.coding.quantisation import predictive
from mocodec.coding.quantisation.quantisers import MuLawQuantiser, UniformQuantiser
from mocodec.coding.transforms import blockdct, blocks, subbands
from mocodec.metrics import compare
from mocodec.motion import Motion

WAVEFORM = ("quant", "dpcm", "adpcm", "deadreckoning", "dct", "subband", "svq", "tvq")


def _sine(walk_amc, frames=600, amplitude=40.0, period=90.0):
    """The walk's skeleton with every channel a slow sine (different phases), at 30 fps."""
    t = np.arange(frames)[:, None]
    phase = np.arange(walk_amc.num_channels)[None, :]
    return Motion(walk_amc.skeleton, 30.0, amplitude * np.sin(2 * np.pi * t / period + phase))


# ----- entropy coder and kernels ------------------------------------------------------------
def test_intcoder_round_trips_and_models_carry_across_packets():
    rng = np.random.default_rng(0)
    values = np.round(rng.laplace(0, [0.2, 3, 12, 0.0], (3000, 4))).astype(np.int64)
    data = intcoder.encode(values)
    assert np.array_equal(intcoder.decode(data, *values.shape), values)
    counts = [np.unique(values[:, c], return_counts=True)[1] for c in range(4)]
    entropy_bytes = sum(-(n * np.log2(n / n.sum())).sum() for n in counts) / 8
    assert len(data) < 1.06 * entropy_bytes + 16  # adaptive, per-channel: near the entropy
    enc, dec = intcoder.Model(4), intcoder.Model(4)
    parts = [
        intcoder.decode(intcoder.encode(values[a : a + 250], enc), len(values[a : a + 250]), 4, dec)
        for a in range(0, 3000, 250)
    ]
    assert np.array_equal(np.vstack(parts), values)


@pytest.mark.parametrize("levels", [2, 5, 64, 1000])
def test_intcoder_bounded_codes_round_trip_across_packets_near_their_conditional_entropy(levels):
    rng = np.random.default_rng(1)
    half = levels // 2
    walk = np.cumsum(rng.integers(-1, 2, (4000, 3)), axis=0)  # slow: the previous code helps
    values = np.clip(walk, -half, levels - half - 1)
    values[:, 2] = rng.integers(-half, levels - half, 4000)  # the whole range, uniform
    enc, dec = intcoder.Model(3, levels), intcoder.Model(3, levels)
    data = [intcoder.encode(values[a : a + 500], enc) for a in range(0, 4000, 500)]
    parts = [intcoder.decode(d, 500, 3, dec) for d in data]
    assert np.array_equal(np.vstack(parts), values)
    assert np.array_equal(
        intcoder.decode(intcoder.encode(values, intcoder.Model(3, levels)), 4000, 3, intcoder.Model(3, levels)), values
    )
    fixed = 4000 * np.log2(levels) / 8  # bytes of fixed-length codes for one channel
    cost = [len(intcoder.encode(values[:, [c]], intcoder.Model(1, levels))) / fixed for c in range(3)]
    assert cost[0] < 0.6 and cost[1] < 0.6  # slow channels: the previous code's context pays
    assert cost[2] < 1.06  # uniform codes: little above fixed length
    with pytest.raises(ValueError, match="outside"):
        intcoder.encode(np.array([[levels - half]]), intcoder.Model(1, levels))


@pytest.mark.parametrize(
    "quantiser", [UniformQuantiser(-1.0, 1.0, 8), UniformQuantiser(-1.0, 1.0, 5), MuLawQuantiser(8.0, 1.0, 16)]
)
def test_quantiser_tables_agree_with_the_quantisers(quantiser):
    decisions, levels = quantiser.table()
    x = np.linspace(-1.3, 1.3, 1001)
    assert np.array_equal(np.searchsorted(decisions, x, side="right"), quantiser.quantise(x))
    assert np.allclose(levels, quantiser.reconstruct(np.arange(quantiser.levels)))


def test_closed_loop_does_not_accumulate_error():
    # a random walk: open-loop DPCM would drift by the sum of the errors; fig. 7-4's loop
    # keeps every sample within half a step of the input while the steps are not overloaded
    rng = np.random.default_rng(2)
    x = np.cumsum(rng.uniform(-0.9, 0.9, (5000, 3)), axis=0)  # |d| <= 0.9 + 1/16: no overload
    decisions, levels = UniformQuantiser(-1.0, 1.0, 16).table()
    codes = np.zeros(x.shape, dtype=np.int64)
    centre = np.zeros(3)
    out = predictive.run_table(x, codes, False, centre.copy(), centre, np.ones(3), np.ones(3), decisions, levels)
    assert np.abs(out - x).max() <= 1.0 / 16 + 1e-12  # half of the step 2/16
    again = predictive.run_table(
        np.zeros((5000, 0)), codes, True, centre.copy(), centre, np.ones(3), np.ones(3), decisions, levels
    )
    assert np.array_equal(again, out)  # the decoder's output, bit for bit


def test_adaptive_predictor_uses_the_autocorrelation_method():
    x = np.sin(2 * np.pi * np.arange(400) / 37.0)[:, None] * 30.0
    beta = np.r_[np.full(4, 0.9), np.geomspace(1.1, 2.4, 4)]
    params = predictive.ChannelParams([False], [0.0], [0.5], [0.0])
    coder = predictive.AdaptiveCoder(params, 16, 2, 60, 4, beta)
    codes, out = coder.code(x)
    # the last update (at sample 396) solved (7-16) with the autocorrelations (7-17, 7-18) of
    # the 60 decoded samples before it, about their mean
    v = out[336:396, 0] - out[336:396, 0].mean()
    r = [np.dot(v[k:], v[: v.size - k]) for k in range(3)]
    expected = np.linalg.solve([[r[0], r[1]], [r[1], r[0]]], [r[1], r[2]])
    assert np.allclose(coder.coef[0, 1:], expected) and np.isclose(coder.coef[0, 0], out[336:396, 0].mean())
    # and it predicts better than the first-order adaptive predictor
    first = predictive.AdaptiveCoder(params, 16, 1, 60, 4, beta)
    _, out1 = first.code(x)
    assert np.abs(out - x)[200:].mean() < np.abs(out1 - x)[200:].mean()
    again = predictive.AdaptiveCoder(params, 16, 2, 60, 4, beta).uncode(codes)
    assert np.array_equal(again, out)


# ----- codecs ---------------------------------------------------------------------------------
@pytest.mark.parametrize("cid", WAVEFORM)
def test_round_trips_real_clips(cid, walk_amc, walk_bvh):
    for motion in (walk_amc.resample(30.0), walk_bvh):
        codec = get_codec(cid)
        payload = codec.encode(motion)
        decoded = codec.decode(payload, motion.skeleton, motion.num_frames, motion.fps)
        assert decoded.channels.shape == motion.channels.shape
        assert payload == codec.encode(motion)  # deterministic
        assert compare(motion, decoded).summary()["psnr_db"] > 20
        assert len(payload) < motion.num_frames * motion.num_channels * 4


def test_quant_uniform_error_is_half_a_step(walk_amc):
    for levels in (8, 64):
        codec = get_codec("quant", levels=levels)
        decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps).channels
        ch = walk_amc.continuous().channels
        half_step = np.ptp(ch, axis=0) / (2 * levels)
        assert (np.abs(decoded - ch) <= half_step * (1 + 1e-3) + 1e-4).all()


def test_quant_laws_and_limits(walk_amc):
    for knobs in ({"law": "mulaw"}, {"law": "adaptive"}, {"range": "limits"}):
        codec = get_codec("quant", levels=32, **knobs)
        decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
        assert compare(walk_amc, decoded).summary()["psnr_db"] > 20, knobs


@pytest.mark.parametrize("cid", ("quant", "dpcm", "adpcm"))
def test_more_levels_more_bits_less_error(cid, walk_amc):
    clip = walk_amc.resample(30.0)
    sizes, errors = [], []
    for levels in (4, 16, 64):
        codec = get_codec(cid, levels=levels)
        payload = codec.encode(clip)
        sizes.append(len(payload))
        errors.append(
            compare(clip, codec.decode(payload, clip.skeleton, clip.num_frames, clip.fps)).summary()["psnr_db"]
        )
    assert sizes[0] < sizes[1] < sizes[2] and errors[0] < errors[1] < errors[2]


def test_dpcm_beats_direct_quantisation(walk_amc):
    # 000 7.5: 8-level prediction about as good as 64-level direct quantisation, in fewer bits
    clip = walk_amc.resample(30.0)
    q, d = get_codec("quant", levels=64), get_codec("dpcm", levels=8)
    pq, pd = q.encode(clip), d.encode(clip)
    assert len(pd) < 0.7 * len(pq)
    assert compare(clip, d.decode(pd, clip.skeleton, clip.num_frames, clip.fps)).summary()["psnr_db"] > 30


@pytest.mark.parametrize("threshold", (0.2, 2.0))
def test_dead_reckoning_holds_its_threshold(walk_amc, threshold):
    codec = get_codec("deadreckoning", threshold=threshold)
    decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps).channels
    err = np.abs(decoded - walk_amc.continuous().channels)
    rot = walk_amc.skeleton.rotation_mask
    assert err[:, rot].max() <= threshold * (1 + 1e-9)
    cm = walk_amc.skeleton.units_per_metre / 100.0
    assert err[:, ~rot].max() <= threshold * cm * (1 + 1e-9)


def test_dead_reckoning_groups_and_update_histogram(walk_amc):
    group = get_codec("deadreckoning", threshold=1.0, measure="group")
    decoded = group.decode(group.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps).channels
    sk = walk_amc.skeleton
    err = decoded - walk_amc.continuous().channels
    for j, joint in enumerate(sk.joints):
        idx = [
            c for c in range(sk.channel_offsets[j], sk.channel_offsets[j] + len(joint.channels)) if sk.rotation_mask[c]
        ]
        if idx:
            assert np.linalg.norm(err[:, idx], axis=1).max() <= 1.0 + 1e-9
    fine = update_intervals(get_codec("deadreckoning", threshold=0.1), walk_amc)
    coarse = update_intervals(get_codec("deadreckoning", threshold=2.0), walk_amc)
    assert coarse.sum() < fine.sum()
    mean_interval = lambda h: (np.arange(h.size) * h).sum() / h.sum()  # noqa: E731
    assert mean_interval(coarse) > mean_interval(fine)


def test_dct_tables_order_rate_and_quality(walk_amc):
    clip = walk_amc.resample(30.0)
    sizes, psnr = [], []
    for table in range(5):
        codec = get_codec("dct", table=table)
        payload = codec.encode(clip)
        sizes.append(len(payload))
        psnr.append(compare(clip, codec.decode(payload, clip.skeleton, clip.num_frames, clip.fps)).summary()["psnr_db"])
    assert sizes == sorted(sizes, reverse=True) and psnr == sorted(psnr, reverse=True)


def test_dct_constant_and_linear_blocks():
    values = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 5.0, 5.0, 5.0]]).T
    assert np.allclose(blockdct.inverse(blockdct.forward(values[None]))[0], values)
    assert np.allclose(blockdct.forward(values[None])[0, 1:, 1], 0.0)  # a constant block is all DC
    assert blockdct.bits(1, 16).tolist() == blockdct.BITS[1].tolist()
    assert blockdct.bits(1, 32)[::2].tolist() == blockdct.BITS[1].tolist()


def test_subband_split_is_exact_and_follows_the_visual_bands():
    rng = np.random.default_rng(4)
    for n, levels in ((16, 3), (16, 4), (2, 1), (64, 5), (8, 0)):
        x = rng.normal(size=(3, n, 5))
        assert np.allclose(subbands.inverse(subbands.forward(x, levels), levels), x, atol=1e-12)
    ramp = np.arange(16.0)[None, :, None]
    assert np.allclose(subbands.forward(ramp, 3)[0, 8:15, 0], 0.0)  # a ramp has no fine detail (but at the mirror)
    assert subbands.band_bounds(16, 3) == [(0, 2), (2, 4), (4, 8), (8, 16)]
    assert subbands.visual_levels(16, 30.0, 1.0) == 3 and subbands.visual_levels(64, 120.0, 1.0) == 5
    weights = subbands.visual_weights(16, 3, 30.0, (1.0, 3.0, 7.0), (0.25, 0.5, 1.0, 2.25))
    assert weights.tolist() == [0.25, 0.5, 1.0, 2.25]
    with pytest.raises(ValueError, match="power of two"):
        subbands.forward(np.zeros((1, 12, 1)), 2)


@pytest.mark.parametrize("emphasis", (0.0, 0.5, 1.0))
def test_subband_coefficient_errors_are_within_half_a_step(walk_amc, emphasis):
    # each band's closed loop keeps every coefficient within half its step (6-15 weighting)
    clip = walk_amc.resample(30.0).continuous()
    step = 0.05
    codec = get_codec("subband", step=step, emphasis=emphasis, smooth=False)
    decoded = codec.decode(codec.encode(clip), clip.skeleton, clip.num_frames, clip.fps).channels
    n = 16
    gains = subbands.synthesis_gains(n, 3)
    weights = np.array([0.25, 0.5, 1.0, 2.25]) ** emphasis
    live = np.ptp(clip.channels, axis=0) > 0
    spread = np.ptp(clip.channels, axis=0)[live] * (1 + 1e-3)  # float16 rounds the range up
    error = subbands.forward(blocks.split(decoded[:, live] - clip.channels[:, live], n), 3)
    for (a, b), w, g in zip(subbands.band_bounds(n, 3), weights, gains):
        bound = step * spread / (w * g) / 2
        assert (np.abs(error[:-1, a:b]) <= bound + 1e-9).all()  # the last block is padded
    assert (np.abs(error[:-1, 8:]) > 0.3 * step * spread / (2.25**emphasis * gains[3]) / 2).any()


def test_subband_wavelet_variant_keeps_the_largest(walk_amc):
    clip = walk_amc.resample(30.0)
    sizes, errors = [], []
    for keep in (2, 6, 16):
        codec = get_codec("subband", variant="wavelet", keep=keep, step=0.03)
        payload = codec.encode(clip)
        sizes.append(len(payload))
        errors.append(
            compare(clip, codec.decode(payload, clip.skeleton, clip.num_frames, clip.fps)).summary()["psnr_db"]
        )
    assert sizes == sorted(sizes) and errors == sorted(errors)
    everything = get_codec("subband", variant="wavelet", keep=0, step=0.03).encode(clip)
    assert len(everything) == sizes[-1]  # keeping all 16 of 16 is keeping all


@pytest.mark.parametrize("cid", WAVEFORM)
def test_streams_frame_by_frame_within_the_delay(cid, walk_amc, codebooks):
    # a live VQ sender uses a codebook trained beforehand (at its frame rate, 30 Hz here), not
    # one trained on its first push
    vq = cid in ("svq", "tvq")
    codec = get_codec(cid, **({"codebook": codebooks[cid, True], "size": 256} if vq else {}))
    clip = walk_amc.resample(30.0) if vq else walk_amc
    whole = codec.encode(clip)
    enc = codec.encoder(clip.skeleton, clip.fps)
    assert b"".join(_joined(enc.push(clip.channels) + enc.flush())) == whole  # a clip is its stream pushed at once
    enc, dec = codec.encoder(clip.skeleton, clip.fps), codec.decoder(clip.skeleton, clip.fps)
    out, pushed = [], 0
    for k in range(0, clip.num_frames, 40):
        for packet in enc.push(clip.channels[k : k + 40]):
            out.append(dec.push(packet))
        pushed = min(k + 40, clip.num_frames)
        assert pushed - sum(len(o) for o in out) <= codec.delay_frames()
    out += [dec.push(p) for p in enc.flush()]
    streamed = Motion(clip.skeleton, clip.fps, np.concatenate(out))
    assert streamed.num_frames == clip.num_frames
    # ranges come from the first push (40 frames here), so quant clips what lies beyond; svq's
    # codebooks here come from one 73-frame clip of another motion (docs: train on many)
    assert compare(clip, streamed).summary()["psnr_db"] > {"quant": 15, "svq": 10}.get(cid, 20)


def _joined(packets):
    from mocodec.coding.entropy.parts import join_parts

    return [join_parts(packets)]


@pytest.mark.parametrize("cid", WAVEFORM)
def test_rate_control_turns_the_quality_knob(cid, walk_amc):
    clip = walk_amc.resample(30.0)
    coarse = ratecontrol.tune(get_codec(cid), clip, "ratio", 6.0)
    fine = ratecontrol.tune(get_codec(cid), clip, "ratio", 3.0)
    assert coarse.ratio > fine.ratio
    assert coarse.mean_error_cm > fine.mean_error_cm


def test_slow_sines_are_coded_closely(walk_amc):
    clip = _sine(walk_amc)
    for cid, knobs in (("dpcm", {"levels": 64}), ("adpcm", {"levels": 64}), ("dct", {"table": 0, "adaptive": False})):
        codec = get_codec(cid, **knobs)
        decoded = codec.decode(codec.encode(clip), clip.skeleton, clip.num_frames, clip.fps)
        err = np.abs(decoded.channels - clip.continuous().channels)
        assert err.max() < 0.02 * 80 and err.mean() < 0.005 * 80, cid  # of the 80-degree swing
