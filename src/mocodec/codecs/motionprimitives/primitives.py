"""``primitives``: the motion-primitive coder of 001 ch. 5 (with the representation of ch. 4).

Each joint's rotation is a unit quaternion signal (:mod:`mocodec.codecs.motionprimitives.quatseg`), cut at
zero crossings of its angular acceleration into segments of 15 to ``max_segment`` (S_M)
frames and resampled by slerp to 16 frames. Per segment the encoder sends its length and the
index of the closest candidate (distance (5.4)); if that is further than the joint's
threshold t_j (``t_lower`` for the root and the legs, ``upper_factor`` x ``t_lower`` for the
rest: 5.3.5), the difference (5.7) is coded with 4-level CDF 9/7 wavelets, quantised to
``bits`` bits and thresholded until the segment is within t_j
(:mod:`mocodec.codecs.motionprimitives.primresidual`). The translation channels go in windows of 32 frames (at
most S_M), CDF 9/7, the smallest half of the coefficients zeroed, ``bits``-bit quantisation.
The segment coefficients go through the context-adaptive coefficient coder
(:func:`mocodec.codecs.motionprimitives.primresidual.pack`, smaller than zero runs); every other
integer stream is range coded (:func:`mocodec.coding.entropy.rangecoder.encode_ints`; zero runs for
the translation coefficients).

The candidates of a joint's segment are:

* the primitives of a database trained offline (``db``: a file from ``mocodec primitives
  train``, which both ends load; the body names it by fingerprint): the thesis's coder;
* beyond the thesis, the last ``history`` segments of the same joint as the decoder rebuilt
  them, and the last decoded pose held still. A repeated beat then refers to the one before
  it, so rhythmic motion codes well without a database, and joints a database does not know
  still code. ``history 0`` with a database is the thesis's coder exactly.

The threshold is checked where the thesis checks it, on the 16 normalised frames; resampling
back to the segment's length adds the error of the slerp between them, so the joint position
errors the measures report are a little larger than t_j alone would give.

Streaming: a segment is known at most S_M frames after its first frame, so the coding delay is
``max_segment`` frames. A whole clip is one packet of the stream, so both decode the same.
"""

from __future__ import annotations

import struct

import numba
import numpy as np

from mocodec.codecs.base import (
    Codec,
    Coded,
    Knob,
    QualityKnob,
    StreamDecoder,
    StreamEncoder,
    checked_frames,
    continuous_frames,
)
from mocodec.codecs.motionprimitives import primresidual, quatseg
from mocodec.codecs.motionprimitives.primdb import PrimitiveDB
from mocodec.codecs.registry import register
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.coding.entropy.rle import ZeroRuns, decode_zero_runs, encode_zero_runs
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.kernels import kernel
from mocodec.skeleton import Skeleton

TRANSLATION_WINDOW = 32
_PARTS = 12


@register
class PrimitivesCodec(Codec):
    id = "primitives"
    packet_number = 8
    description = "motion primitives: quaternion segments replaced by database primitives, CDF 9/7 residuals"
    knobs = (
        Knob(
            "t_lower",
            float,
            0.01,
            "t_L: largest rotation error (rad, (5.3)) of a lower-body joint's segment",
            low=1e-5,
            high=1.0,
        ),
        Knob("upper_factor", float, 2.0, "t_U / t_L (the thesis: 2)", low=0.1, high=100.0),
        Knob(
            "max_segment",
            int,
            32,
            "S_M: longest segment in frames, the coding delay (the thesis: 16, 32, 64)",
            low=quatseg.MIN_SEGMENT,
            high=256,
        ),
        Knob("bits", int, 10, "quantisation bits of the wavelet coefficients", low=4, high=20),
        Knob("db", str, "", "a primitive database file (mocodec model train primitives); empty: none", path=True),
        Knob(
            "history",
            int,
            16,
            "earlier decoded segments of the joint offered as candidates (0: the thesis)",
            low=0,
            high=256,
        ),
        Knob(
            "smooth",
            int,
            0,
            "M: frames each side of a seam searched by the smoothing of 5.3.4 (0: none)",
            low=0,
            high=quatseg.MIN_SEGMENT // 2,
        ),
    )
    quality = QualityKnob("t_lower", higher_is_better=False, log_scale=True)

    def delay_frames(self) -> int:
        return self.config["max_segment"] + self.config["smooth"]

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _Encoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _Decoder(self, skeleton, fps)

    def _encode(self, motion) -> bytes:
        enc = _Encoder(self, motion.skeleton, motion.fps)
        enc.append(motion.channels)
        return enc.packet(final=True)[0].payload

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        out = _Decoder(self, skeleton, fps).push(body)
        if len(out) != frames:
            raise CorruptStreamError(f"primitives body holds {len(out)} frames, its header says {frames}")
        return out

    def database(self) -> PrimitiveDB | None:
        return PrimitiveDB.load(self.config["db"]) if self.config["db"] else None


class _Candidates:
    """What both ends offer a joint's next segment: the held pose (slot 0), the last
    ``history`` decoded segments (a ring), the database's primitives. Kept in step by
    :meth:`update` with each decoded segment."""

    def __init__(self, lay: quatseg.Layout, books: list[np.ndarray], history: int):
        self.history = history
        width = 1 + history + max((len(b) for b in books), default=0)
        self.cand = np.zeros((lay.count, width, quatseg.NORMAL_FRAMES, 4))
        self.cand[:, :, :, 0] = 1.0
        self.valid = np.zeros((lay.count, width), dtype=bool)
        self.valid[:, 0] = True
        for r, b in enumerate(books):
            self.cand[r, 1 + history : 1 + history + len(b)] = b
            self.valid[r, 1 + history : 1 + history + len(b)] = True
        self.filled = np.zeros(lay.count, dtype=np.int64)

    def nearest(self, joints: np.ndarray, segs: np.ndarray) -> np.ndarray:
        dots = quatseg.min_abs_dot(segs[:, None], self.cand[joints])
        return np.argmax(np.where(self.valid[joints], dots, -1.0), axis=1)

    def update(self, joints: np.ndarray, decoded: np.ndarray) -> None:
        _remember_all(
            np.asarray(joints, dtype=np.int64),
            np.ascontiguousarray(decoded),
            self.cand,
            self.valid,
            self.filled,
            self.history,
        )


@kernel
def _rebuild(joints, index, decoded, cand, valid, filled, history):
    """The decoder's side of the candidates, in place: each segment's residual rotations
    ``decoded`` become the segment (5.8), ``cand[joint, index] * residual``, which then updates
    the candidates (:func:`_remember`, as :meth:`_Candidates.update` does). Joints do not share candidates, so the
    segments go in their joint-major order. Returns the first segment that refers to a
    candidate not yet sent, or -1."""
    for s in range(len(joints)):
        r, k = joints[s], index[s]
        if not valid[r, k]:
            return s
        for f in range(decoded.shape[1]):
            pw, px, py, pz = cand[r, k, f, 0], cand[r, k, f, 1], cand[r, k, f, 2], cand[r, k, f, 3]
            qw, qx, qy, qz = decoded[s, f, 0], decoded[s, f, 1], decoded[s, f, 2], decoded[s, f, 3]
            decoded[s, f, 0] = pw * qw - px * qx - py * qy - pz * qz
            decoded[s, f, 1] = pw * qx + px * qw + py * qz - pz * qy
            decoded[s, f, 2] = pw * qy - px * qz + py * qw + pz * qx
            decoded[s, f, 3] = pw * qz + px * qy - py * qx + pz * qw
        _remember(r, decoded[s], cand, valid, filled, history)
    return -1


@kernel
def _remember_all(joints, decoded, cand, valid, filled, history):
    for s in range(len(joints)):
        _remember(joints[s], decoded[s], cand, valid, filled, history)


@numba.njit(inline="always")
def _remember(r, segment, cand, valid, filled, history):
    """Joint ``r``'s decoded ``segment`` into its candidates: its last frame held (slot 0) and,
    with a ``history``, the segment itself in the ring's next slot."""
    for f in range(segment.shape[0]):
        cand[r, 0, f] = segment[-1]
    if history:
        slot = 1 + filled[r] % history
        cand[r, slot] = segment
        valid[r, slot] = True
        filled[r] += 1


def _rounds(joints: np.ndarray) -> list[np.ndarray]:
    """Positions of a joint-major segment list grouped into rounds: round t holds every joint's
    t-th segment, so the segments of one round depend only on earlier rounds."""
    order = np.argsort(joints, kind="stable")
    rank = np.empty(len(joints), dtype=np.int64)
    starts = np.searchsorted(joints[order], joints[order])
    rank[order] = np.arange(len(joints)) - starts
    return [np.flatnonzero(rank == t) for t in range(int(rank.max()) + 1 if len(rank) else 0)]


class _Shared:
    """State both ends build the same way from the codec's settings and the skeleton."""

    def __init__(self, codec: PrimitivesCodec, skeleton: Skeleton, fps: float):
        cfg = codec.config
        self.cfg, self.skeleton, self.fps = cfg, skeleton, fps
        self.lay = quatseg.layout(skeleton)
        db = codec.database()
        self.fingerprint = db.fingerprint if db else 0
        books = db.for_layout(self.lay, f"primitive database {cfg['db']}") if db else []
        if db and abs(db.fps - fps) > 1e-6 * fps:
            raise CodecError(f"primitive database {cfg['db']} was trained at {db.fps:g} Hz, the motion is {fps:g} Hz")
        self.candidates = _Candidates(self.lay, books, cfg["history"])
        self.bound = np.where(self.lay.lower, 1.0, cfg["upper_factor"]) * cfg["t_lower"]
        self.window = min(TRANSLATION_WINDOW, cfg["max_segment"])
        self.before: np.ndarray | None = None  # last decoded translation; the first frame's, sent as float32


class _Encoder(StreamEncoder, _Shared):
    def __init__(self, codec: PrimitivesCodec, skeleton: Skeleton, fps: float):
        _Shared.__init__(self, codec, skeleton, fps)
        self.q = np.zeros((0, self.lay.count, 4))  # joint quaternions from frame `base` on
        self.t = np.zeros((0, len(self.lay.translation)))  # translations from `t_base` on
        self.base = self.t_base = 0
        self.starts = np.zeros(self.lay.count, dtype=np.int64)  # open segment start, absolute
        self.decided = np.zeros(self.lay.count, dtype=np.int64)  # frames each joint's segments reach
        self.t_decided = 0  # frames the translation windows reach
        self.given = 0  # frames the decoder has given out

    def append(self, frames: np.ndarray) -> None:
        frames = checked_frames(PrimitivesCodec.id, self.skeleton, frames)
        q = quatseg.joint_quaternions(self.lay, frames)
        if len(self.q):  # carry on in the hemisphere of the last frame
            q *= np.where(np.sum(q[:1] * self.q[-1:], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        self.q = np.concatenate((self.q, q))
        self.t = np.concatenate((self.t, frames[:, self.lay.translation]))

    def code(self, frames: np.ndarray) -> list[Coded]:
        self.append(frames)
        return self.packet(final=False)

    def finish(self) -> list[Coded]:
        return self.packet(final=True)

    def packet(self, final: bool) -> list[Coded]:
        """The packet of the segments and translation windows the frames so far decide (all, if
        ``final``; none if nothing is decided), and the frames the decoder gives out for it:
        those every joint's segments and the translation windows have reached, less the
        ``smooth`` frames a later seam may still change."""
        g = quatseg.speed_change(self.q, self.fps)
        local = self.starts - self.base
        segs = np.array(quatseg.chop(g, local, self.cfg["max_segment"], final), dtype=np.int64).reshape(-1, 3)
        self.starts = local + self.base
        parts = self._segments(segs) + self._windows(final)
        keep = max(int(self.starts.min()) - self.base - 2, 0)
        self.q, self.base = self.q[keep:], self.base + keep
        if not final and not len(segs) and not parts[-1] and not parts[5]:  # nothing decided, no start
            return []
        self.decided += np.bincount(segs[:, 0], segs[:, 2] - segs[:, 1], self.lay.count).astype(np.int64)
        self.t_decided += sum(parts[-1])
        reached = [*self.decided.tolist(), *([self.t_decided] if len(self.lay.translation) else [])]
        out = max(min(reached) - self.given - (0 if final else self.cfg["smooth"]), 0) if reached else 0
        self.given += out
        return [Coded(join_parts([*parts[:-1], encode_ints(parts[-1]), b"\x01" if final else b""]), out)]

    def _segments(self, segs: np.ndarray) -> list[bytes]:
        joints = segs[:, 0]
        normal = quatseg.normalise(self.q, segs)
        index = np.zeros(len(segs), dtype=np.int64)
        exps = np.zeros(len(segs), dtype=np.int64)
        coeffs = np.zeros((len(segs), primresidual.COEFFS), dtype=np.int64)
        for rows in _rounds(joints):
            r = joints[rows]
            index[rows] = self.candidates.nearest(r, normal[rows])
            ref = self.candidates.cand[r, index[rows]]
            exps[rows], coeffs[rows], decoded = primresidual.fit(normal[rows], ref, self.bound[r], self.cfg["bits"])
            self.candidates.update(r, decoded)
        counts = np.bincount(joints, minlength=self.lay.count)
        return [
            encode_ints(counts),
            encode_ints(segs[:, 2] - segs[:, 1]),
            encode_ints(index),
            encode_ints(exps),
            primresidual.pack(coeffs[exps != primresidual.NO_RESIDUAL]),
        ]

    def _windows(self, final: bool) -> list:
        w = self.window
        lengths, exps, ints = [], [], []
        first = b""
        if self.before is None and len(self.t):  # the first frame: database fingerprint, translation
            first = struct.pack("<I", self.fingerprint) + self.t[0].astype("<f4").tobytes()
            self.before = np.frombuffer(first, "<f4", offset=4).astype(np.float64)
        while len(self.t) >= w or (final and len(self.t)):
            n = min(w, len(self.t))
            assert self.before is not None  # set with the first frame above
            e, q, decoded = primresidual.fit_window(self.t[:n], self.before, self.cfg["bits"])
            self.before = decoded[-1]
            lengths.append(n)
            exps.append(e)
            ints.append(q.ravel())
            self.t = self.t[n:]
        flat = np.concatenate(ints) if ints else np.zeros(0, dtype=np.int64)
        runs = encode_zero_runs(flat)
        return [
            first,
            encode_ints(np.concatenate(exps) if exps else np.zeros(0, np.int64)),
            encode_ints(runs.runs),
            encode_ints(runs.values),
            encode_ints(np.array([runs.tail])),
            lengths,
        ]


class _Decoder(StreamDecoder, _Shared):
    def __init__(self, codec: PrimitivesCodec, skeleton: Skeleton, fps: float):
        _Shared.__init__(self, codec, skeleton, fps)
        self.pending = [np.zeros((0, 4)) for _ in range(self.lay.count)]
        self.pending_t = np.zeros((0, len(self.lay.translation)))
        self.last_start = np.zeros(self.lay.count, dtype=np.int64)  # of each joint's last segment, in pending
        self.started = np.zeros(self.lay.count, dtype=bool)  # the joint has had a segment
        self.final = False
        self.previous: np.ndarray | None = None

    def push(self, packet: bytes) -> np.ndarray:
        where = "primitives packet"
        p = split_parts(packet, _PARTS, where)
        counts, lengths, index, exps = (decode_ints(x) for x in p[:4])
        t_exps, t_runs, t_values, t_tail, t_lengths = (decode_ints(x) for x in p[6:11])
        if self.final or p[11] not in (b"", b"\x01"):
            raise CorruptStreamError(f"{where}: {'a packet after the last one' if self.final else 'bad end mark'}")
        self.final = p[11] == b"\x01"
        self._start(p[5], where, bool(counts.sum() or t_lengths.size))
        if counts.size != self.lay.count or counts.min(initial=0) < 0 or lengths.size != counts.sum():
            raise CorruptStreamError(f"{where}: segment counts do not match the skeleton")
        if index.size != lengths.size or exps.size != lengths.size or lengths.min(initial=1) < 1:
            raise CorruptStreamError(f"{where}: segment streams do not pair up")
        self._segments(counts, lengths, index, exps, p[4], where)
        self._windows(t_lengths, t_exps, ZeroRuns(t_runs, t_values, int(t_tail[0])), where)
        return self._ready()

    def _start(self, part: bytes, where: str, carries_frames: bool) -> None:
        if part and self.before is not None:
            raise CorruptStreamError(f"{where}: the stream's start is repeated")
        if not part:
            if self.before is None and carries_frames:
                raise CorruptStreamError(f"{where}: the stream's start is missing")
            return
        if len(part) != 4 + 4 * len(self.lay.translation):
            raise CorruptStreamError(f"{where}: a {len(part)}-byte stream start does not match the skeleton")
        (fingerprint,) = struct.unpack_from("<I", part)
        if fingerprint != self.fingerprint:
            coded = f"primitive database {fingerprint:08x}" if fingerprint else "no primitive database"
            have = f"{self.cfg['db']} is {self.fingerprint:08x}" if self.fingerprint else "none is given (--db FILE)"
            raise CodecError(f"{where}: the motion was coded with {coded}; {have}")
        self.before = np.frombuffer(part, "<f4", offset=4).astype(np.float64)

    def _segments(self, counts, lengths, index, exps, packed, where) -> None:
        joints = np.repeat(np.arange(self.lay.count), counts)
        has = exps != primresidual.NO_RESIDUAL
        coeffs = np.zeros((len(joints), primresidual.COEFFS), dtype=np.int64)
        if has.any():
            coeffs[has] = primresidual.unpack(packed, int(has.sum()))
        cands = self.candidates
        if len(index) and (index.min() < 0 or index.max() >= cands.cand.shape[1]):
            raise CorruptStreamError(f"{where}: a candidate index is out of range")
        decoded = primresidual.differences(exps, coeffs)
        bad = _rebuild(joints, index, decoded, cands.cand, cands.valid, cands.filled, cands.history)
        if bad >= 0:
            raise CorruptStreamError(f"{where}: segment {bad} refers to a candidate not yet sent")
        frames = quatseg.denormalise(decoded, lengths)  # joint-major, like the segments
        bounds = np.concatenate(([0], np.cumsum(np.bincount(joints, lengths, self.lay.count)))).astype(np.int64)
        first = np.concatenate(([0], np.cumsum(counts)))
        for r in np.flatnonzero(counts):
            self._append(int(r), frames[bounds[r] : bounds[r + 1]], np.cumsum(lengths[first[r] : first[r + 1]]))

    def _append(self, r: int, frames: np.ndarray, ends: np.ndarray) -> None:
        """Joint ``r``'s next segments (ending at ``ends`` in ``frames``) after its pending
        frames, with their seams smoothed (5.3.4) when ``smooth`` is on."""
        before = len(self.pending[r])
        q = np.concatenate((self.pending[r], frames))
        starts = before + np.concatenate(([0], ends[:-1]))
        m = self.cfg["smooth"]
        if m:
            seams = slice(0, None) if self.started[r] else slice(1, None)
            lefts = np.concatenate(([max(self.last_start[r], 0)], starts[:-1]))
            quatseg.smooth_seams(q, starts[seams], lefts[seams], before + ends[seams], m, self.fps)
        self.pending[r] = q
        self.last_start[r], self.started[r] = starts[-1], True

    def _windows(self, lengths, exps, runs, where) -> None:
        channels = len(self.lay.translation)
        sizes = [primresidual.window_coefficients(int(n)) + 1 for n in lengths]
        flat = decode_zero_runs(runs)
        if lengths.min(initial=1) < 1 or exps.size != channels * len(lengths) or flat.size != channels * sum(sizes):
            raise CorruptStreamError(f"{where}: translation windows do not match their coefficients")
        pos, out = 0, [self.pending_t]
        for k, (n, m) in enumerate(zip(lengths, sizes)):
            ints = flat[pos : pos + channels * m].reshape(channels, m)
            pos += channels * m
            if self.before is None:
                raise CorruptStreamError(f"{where}: translation windows before the first frame")
            decoded = primresidual.rebuild_window(self.before, exps[k * channels : (k + 1) * channels], ints, int(n))
            self.before = decoded[-1]
            out.append(decoded)
        self.pending_t = np.concatenate(out)

    def _ready(self) -> np.ndarray:
        have = [len(p) for p in self.pending]
        if len(self.lay.translation):
            have.append(len(self.pending_t))
        n = max(min(have) - (0 if self.final else self.cfg["smooth"]), 0) if have else 0
        q = np.stack([p[:n] for p in self.pending], axis=1) if self.pending else np.zeros((n, 0, 4))
        # a rig without translations sends no translation window: there are none to wait for
        translation = self.pending_t[:n] if len(self.lay.translation) else np.zeros((n, 0))
        channels = quatseg.quaternions_to_channels(self.lay, q, translation, self.skeleton.num_channels)
        self.pending = [p[n:] for p in self.pending]
        self.last_start -= n
        self.pending_t = self.pending_t[n:]
        out = continuous_frames(PrimitivesCodec.id, self.skeleton, self.fps, channels, self.previous)
        if len(out):
            self.previous = out[-1:]
        return out
