"""``pwavelet``: the perceptually guided wavelet coder of 001 §3.2, in its nine steps.

1. The clip is cut into slices of W frames (the last may be shorter).
2. For each slice:
3. l_i, the bone length of channel i's joint over the longest bone of the skeleton; the root's
   channels (translation and rotation) count as the longest bone, since they move the whole
   figure (its own "bone", the pelvis, is short and would starve them);
4. v_i = sum |c_(i,p+1) - c_(i,p)| / W, the channel's variation in the slice (3.1);
5. A_i = l_i v_i (3.2);
6. K_i = max(alpha A_i N W / sum_j A_j, C) largest (absolute) Daubechies D4 coefficients kept
   per channel, the others set to zero; where K_i exceeds the channel's coefficients, the excess
   goes to the other channels in the same proportions (the thesis leaves it unused), so the
   slice keeps alpha N W coefficients in all; and the coarsest (approximation) band is always
   kept on top of K_i: it carries the channel's mean pose, and a channel given a handful of
   detail-sized coefficients would otherwise collapse towards 0 degrees between them;
7. the kept coefficients quantised linearly to QP bits: mid-tread, step = the channel's largest
   kept coefficient / (2^(QP-1) - 1), the step itself sent as a quarter-octave exponent, and
   never finer than 0.001 (so float noise in unused channels costs nothing);
8. zero runs of the quantised coefficients, in channel order;
9. entropy coding: instead of the thesis's LZW, our adaptive range coder
   (:func:`mocodec.coding.entropy.rangecoder.encode_ints`) on the run lengths, the values and the steps.

``allocation`` selects the ablations of tables 3.2 and 3.3: ``uniform`` (the same share for
every channel, "standard wavelet compression") and ``bone`` (bone length only). The angles are
made continuous first (:meth:`Motion.continuous`: no wraps at +-180, no gimbal flips), so
those jumps are not steps for the wavelets; decoded poses are the same, angles equivalent. The D4 transform mirrors the
slice ends (``symmetric``; the thesis does not say): periodisation would join a walk's end to
its start, and that jump alone eats the coefficient budget.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.coding.entropy.rle import ZeroRuns, decode_zero_runs, encode_zero_runs
from mocodec.coding.quantisation.quantisers import step_exponents, steps
from mocodec.coding.transforms import wavelets
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton

WAVELET = "d4"
MODE = "symmetric"  # mirrored ends: no jump where a slice ends elsewhere than it began


def channel_bone_lengths(skeleton: Skeleton) -> np.ndarray:
    """l_i per channel: the joint's bone length over the longest; 1 for the root's channels."""
    bones = skeleton.bone_lengths
    longest = bones.max() if bones.max() > 0 else 1.0
    l = bones[skeleton.channel_joints] / longest
    l[skeleton.channel_joints == 0] = 1.0
    return l


def importance(slice_channels: np.ndarray, bone: np.ndarray, allocation: str) -> np.ndarray:
    """A_i (3.2) for one slice ``(frames, channels)``, or its ablations."""
    if allocation == "uniform":
        return np.ones(slice_channels.shape[1])
    if allocation == "bone":
        return bone.copy()
    variation = np.abs(np.diff(slice_channels, axis=0)).sum(axis=0) / max(len(slice_channels), 1)  # (3.1)
    return bone * variation


def coefficient_counts(a: np.ndarray, alpha: float, frames: int, coefficients: int, minimum: int) -> np.ndarray:
    """K_i = max(alpha A_i N W / sum A_j, C), at most the slice's coefficients, the excess of
    capped channels shared out again in proportion to A (step 6)."""
    n = a.size
    budget = alpha * n * frames
    weights = a if a.sum() > 0 else np.ones(n)
    share = np.zeros(n)
    free = np.ones(n, dtype=bool)
    for _ in range(n):
        share[free] = (budget - share[~free].sum()) * weights[free] / max(weights[free].sum(), 1e-300)
        over = free & (share > coefficients)
        if not over.any():
            break
        share[over] = coefficients
        free &= ~over
    return np.clip(np.maximum(np.round(share), minimum), 0, coefficients).astype(np.int64)


def keep_largest(coeffs: np.ndarray, counts: np.ndarray, always: int = 0) -> np.ndarray:
    """Zero all but the first ``always`` coefficients and the ``counts[i]`` largest |other
    coefficients| of each row."""
    ranked = np.abs(coeffs)
    ranked[:, :always] = np.inf
    counts = counts + min(always, coeffs.shape[1])
    order = np.argsort(-ranked, axis=1, kind="stable")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(coeffs.shape[1])[None, :].repeat(len(coeffs), 0), axis=1)
    return np.where(rank < counts[:, None], coeffs, 0.0)


@register
class PWaveletCodec(Codec):
    id = "pwavelet"
    description = "perceptually guided wavelets: D4 per slice, coefficients kept by bone length x variation"
    knobs = (
        Knob("alpha", float, 0.05, "share of all wavelet coefficients kept", low=1e-4, high=1.0),
        Knob("qp", int, 9, "quantisation bits (the thesis: 7-11)", low=2, high=24),
        Knob("window", int, 256, "frames per slice W (the thesis: 64-256)", low=4, high=1 << 16),
        Knob("min_coeffs", int, 2, "C: coefficients kept per channel at least", low=0, high=1 << 16),
        Knob("allocation", str, "perceptual", "coefficient shares", choices=("perceptual", "bone", "uniform")),
    )
    quality = QualityKnob("alpha", higher_is_better=True, log_scale=True)

    def delay_frames(self) -> int:
        return self.config["window"]

    def segment_frames(self) -> int:
        return self.config["window"]

    def _slices(self, frames: int):
        w = self.config["window"]
        return [(a, min(a + w, frames)) for a in range(0, frames, w)]

    def _encode(self, motion) -> bytes:
        sk, cfg = motion.skeleton, self.config
        ch = motion.continuous().channels
        bone = channel_bone_lengths(sk)
        qs, exps = [], []
        for a, b in self._slices(len(ch)):
            n = b - a
            levels = wavelets.max_levels(n, WAVELET)
            coeffs = wavelets.forward(ch[a:b].T, WAVELET, levels, MODE)
            counts = coefficient_counts(
                importance(ch[a:b], bone, cfg["allocation"]), cfg["alpha"], n, coeffs.shape[1], cfg["min_coeffs"]
            )
            kept = keep_largest(coeffs, counts, wavelets.band_lengths(n, WAVELET, levels, MODE)[0] if levels else 0)
            e = step_exponents(kept, cfg["qp"])
            st = steps(e)
            q = np.zeros(kept.shape, dtype=np.int64)
            ok = st > 0
            q[ok] = np.round(kept[ok] / st[ok, None]).astype(np.int64)
            qs.append(q.ravel())
            exps.append(e)
        runs = encode_zero_runs(np.concatenate(qs) if qs else np.zeros(0, dtype=np.int64))
        parts = [
            encode_ints(np.concatenate(exps) if exps else np.zeros(0, np.int64)),
            encode_ints(runs.runs),
            encode_ints(runs.values),
            encode_ints(np.array([runs.tail])),
        ]
        return join_parts(parts)

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        exps, run_lengths, values, tail = (decode_ints(p) for p in split_parts(body, 4, "pwavelet body"))
        if tail.size != 1 or run_lengths.size != values.size:
            raise CorruptStreamError("pwavelet body: run and value streams do not pair up")
        n_ch = skeleton.num_channels
        slices = self._slices(frames)
        levels = [wavelets.max_levels(b - a, WAVELET) for a, b in slices]
        sizes = [sum(wavelets.band_lengths(b - a, WAVELET, lv, MODE)) for (a, b), lv in zip(slices, levels)]
        runs = ZeroRuns(run_lengths, values, int(tail[0]))
        if runs.length != n_ch * sum(sizes) or exps.size != n_ch * len(slices):
            raise CorruptStreamError("pwavelet body: coefficient count does not match the frames")
        q = decode_zero_runs(runs).astype(np.float64)
        out = np.empty((frames, n_ch))
        pos = 0
        for k, ((a, b), m, lv) in enumerate(zip(slices, sizes, levels)):
            coeffs = q[pos : pos + n_ch * m].reshape(n_ch, m) * steps(exps[k * n_ch : (k + 1) * n_ch])[:, None]
            out[a:b] = wavelets.inverse(coeffs, b - a, WAVELET, lv, MODE).T
            pos += n_ch * m
        return out
