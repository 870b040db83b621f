"""``kinwave``: the project's own error-bounded, skeleton-aware wavelet codec (kinwave.md).

Per body of T frames:

1. Angles are made continuous (:meth:`Motion.continuous`); channels constant to 1e-6 are
   collapsed to one knot (1/8 of a step; a translation about its joint's offset); leading
   frames that jump away (a bind pose, a T-pose) may be coded as one-frame segments
   (keyframes) where a trial pass says it is cheaper; an isolated frame far from both its
   neighbours (a glitch) is coded apart as a patch on the neighbours' mean. Each three-angle joint is coded in the
   form that costs least (:mod:`mocodec.codecs.shared.rotvec`: its Euler angles, a rotation vector
   about its mean rotation, Euler angles in another order), so the file's Euler order, a
   gimbal lock or a rotated dummy root above it do not change what is coded.
2. Joints are coded parents first. Each joint's angles are the *closed-loop* target: the
   angles that restore its original global orientation on top of its parent's decoded one
   (:mod:`mocodec.codecs.shared.closedloop`), so errors do not pile up along chains. The root's
   translations (in cm) are coded as they are; a translated joint below the root restores its
   original position from its parent's decoded one.
3. Every channel becomes knots at segment starts plus a wavelet-coded residual per segment of
   ``window`` frames (:mod:`mocodec.coding.transforms.trendwave`: CDF 9/7, ``levels`` deep, periodised),
   quantised with a dead zone by its joint's step, and the integers go through the
   context-adaptive binary arithmetic coder of :mod:`mocodec.coding.entropy.coefcoder`. Segments
   share their knots but their residuals' errors are independent, so the decoded curve steps
   where they meet; the reconstruction (on both ends) spreads each seam's step over 8 frames
   each side (:func:`mocodec.coding.transforms.seams.smooth_seams`, at most one step of the channel's
   quantiser): jerk at the seams falls and, as the step was error, the files shrink.
4. Steps: the shape per joint comes from the convex allocation of
   :mod:`mocodec.codecs.kinwave.kinalloc` for the chosen error measure; one scale multiplies it. With
   ``max_error_cm`` the scale is predicted from the model and corrected by a secant in log-log
   space on the *decoded* output (the encoder reconstructs through the decoder's own
   functions), so the bound holds on what the decoder will produce, verified on the final bytes;
   with ``bits_per_second`` the same search aims at the body's byte budget within 2%.
5. Under a max-error bound a first pass corrects the model's step per joint by the slack it
   measured at the points the joint moves (the model overstates quiet joints' errors), and
   the coefficients that reach a frame far off its target round to the nearest integer
   instead of through the dead zone (the few frames that set a max bound). With the knob
   ``segment_steps`` a body of 4 segments or more gets time-adaptive steps: each segment a
   step offset of its own (1/8 octave), searched on its own worst error.

The body format is :mod:`.body`'s, the encoder :mod:`.encoder`'s and the search of
the steps :mod:`.search`'s.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Coded, Knob, QualityKnob, StreamDecoder, StreamEncoder
from mocodec.codecs.kinwave import kinalloc
from mocodec.codecs.kinwave.body import (
    REST_AT_ZERO,
    WAVELET_IDS,
    decode_body,
    rest_kind,
    rest_pose,
    with_more,
)
from mocodec.codecs.kinwave.search import BoundSearch
from mocodec.codecs.registry import register
from mocodec.coding.entropy import coefcoder
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.formats import varint
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import worst_error
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

SHORTER_WINDOW = 4  # the highest effort also tries segments this many times shorter


@register
class KinwaveCodec(Codec):
    id = "kinwave"
    packet_number = 9
    warm_parts = (coefcoder.warm,)
    description = (
        "project codec: closed-loop wavelet coding down the kinematic tree, convex step allocation, "
        "context-adaptive arithmetic coding, guaranteed error bound (kinwave.md)"
    )
    knobs = (
        Knob("max_error_cm", float, 0.5, "error bound in cm, held on the decoded output", 1e-4, 1000.0),
        Knob(
            "error_measure",
            str,
            "joint",
            "what the bound limits: shell = points 3 cm off every bone (worst), "
            "joint = max joint position error, mean = mean joint position error",
            choices=kinalloc.MODES,
        ),
        Knob("bits_per_second", float, 0.0, "code to this bit rate instead of an error bound (0: off)", 0.0, 1e9),
        Knob(
            "window",
            int,
            1024,
            "segment length in frames (a power of two): a .moc chunk's 1024 by default, where "
            "files are smallest (fewer seams); a stream sends a packet per segment, so "
            "streaming wants 64-256 (the delay)",
            8,
            4096,
        ),
        Knob(
            "levels",
            int,
            0,
            "wavelet levels per segment (0: by the frame rate, the coarsest band about 1/4 s "
            "apart: 5 at 120 fps, 4 at 60, 3 at 30 and 24)",
            0,
            10,
        ),
        Knob("wavelet", str, "cdf97", "segment transform", choices=WAVELET_IDS),
        Knob("deadzone", float, 0.4, "rounding offset of the dead-zone quantiser (0.5: plain rounding)", 0.0, 0.5),
        Knob("closed_loop", bool, True, "code each joint against its parent's decoded orientation"),
        Knob(
            "allocation",
            str,
            "convex",
            "per-joint steps: convex program, or one step for every angle",
            choices=("convex", "uniform"),
        ),
        Knob(
            "joint_feedback",
            bool,
            True,
            "under a max-error bound, correct each joint's step by the slack a first "
            "pass measured at the points it moves",
        ),
        Knob(
            "segment_steps",
            bool,
            False,
            "under a max-error bound, give each segment its own step offset (time-"
            "adaptive steps, from 4 segments on: pair it with a window of 256 or less): quiet "
            "stretches get coarser steps "
            "(off: since coefficients round plainly where a frame is far off, one scale is smaller)",
        ),
        Knob(
            "rotation_vectors",
            bool,
            True,
            "code each 3-angle joint in the form that costs least: its Euler "
            "angles, a rotation vector about its mean rotation, or Euler angles in another order (off: the file's "
            "Euler angles always; ASF skeletons under a max bound: the root and joints near gimbal lock only)",
        ),
        Knob(
            "effort",
            int,
            2,
            "how hard a max-error bound's search works: 1 one search aiming at 85-100% of the bound, "
            "no slack rounds (fastest); 2 one search at 90-100%, the codes to blame corrected, and the "
            "slack rounds (a second landing where the corrections miss); 3 also three "
            "landings of a short body's joint feedback and segments of a quarter window, the "
            "smallest kept (smallest files; bytes and speed per level: docs/kinwave.md)",
            1,
            3,
        ),
        Knob(
            "keyframes",
            bool,
            True,
            "code the first one or two frames on their own where they jump far from the "
            "rest (a bind pose or T-pose in frame 0), so they do not cost the wavelet",
        ),
    )
    quality = QualityKnob("max_error_cm", higher_is_better=False, log_scale=True)

    def __init__(self, **knobs):
        super().__init__(**knobs)
        w = self.config["window"]
        if w & (w - 1):
            raise CodecError(f"codec kinwave: window must be a power of two, got {w}")

    def delay_frames(self) -> int:
        return self.config["window"]

    def segment_frames(self) -> int:
        return self.config["window"]

    def at_rate(self, bits_per_second: float) -> Codec:
        return self.with_knob("bits_per_second", bits_per_second)

    def bound_knobs(self, target: str, value: float) -> dict | None:
        if target == "max_error_cm":
            measure = self.config["error_measure"]
            return {
                "max_error_cm": value,
                "bits_per_second": 0.0,
                "error_measure": "joint" if measure == "mean" else measure,
            }
        if target == "mean_error_cm":
            return {"max_error_cm": value, "bits_per_second": 0.0, "error_measure": "mean"}
        return None

    def target_knobs(self, target: str, value: float, motion: Motion, overhead_bytes: int = 0) -> dict | None:
        """Knobs that make the encoder itself meet a size target (:mod:`ratecontrol`; error
        targets: :meth:`bound_knobs`)."""
        if target in ("ratio", "bitrate"):
            bits = motion.raw_bits / value if target == "ratio" else value * motion.duration
            return {"bits_per_second": max((bits - 8 * overhead_bytes) / max(motion.duration, 1e-9), 1.0)}
        return None

    # ----- encoding -----------------------------------------------------------------------
    def _encode(self, motion: Motion) -> bytes:
        return self._encode_for(motion, motion.skeleton)

    def _encode_for(self, motion: Motion, output_skeleton: Skeleton) -> bytes:
        """:meth:`_encode_body`; at the highest effort under a bound, a body longer than a
        quarter window is also coded in segments of a quarter window, and the smaller wins
        (a seam where the motion changes can cost less than one long segment whose search
        lands worse: docs/kinwave.md). Each body names its own window, so both decode."""
        body = self._encode_body(motion, output_skeleton)
        short = self.config["window"] // SHORTER_WINDOW
        if self.config["effort"] < 3 or self.config["bits_per_second"] > 0 or motion.num_frames <= short or short < 8:
            return body
        other = KinwaveCodec(**{**self.config, "window": short})._encode_body(motion, output_skeleton)
        return other if len(other) < len(body) else body

    def _encode_body(self, motion: Motion, output_skeleton: Skeleton) -> bytes:
        """A leading rest pose (:func:`.body.rest_kind`) is a flag, the other frames the
        body, where frame 0 then holds the bound; else the whole motion is the body."""
        kind = rest_kind(motion) if self.config["keyframes"] else 0
        if kind:
            search = BoundSearch(self, Motion(motion.skeleton, motion.fps, motion.channels[1:]), output_skeleton)
            body = search.run()
            # (a bit rate's search checks no bound: frame 0's is not checked either)
            if (
                kind == REST_AT_ZERO
                or self.config["bits_per_second"] > 0
                or self._rest_holds(motion, search.decoded_frame(body, 0), output_skeleton, kind)
            ):
                return with_more(body, kind)
        return BoundSearch(self, motion, output_skeleton).run()

    def _rest_holds(self, motion: Motion, frame1: np.ndarray, output_skeleton: Skeleton, kind: int) -> bool:
        """Whether the rest pose of ``kind`` that takes its translations (and a turned root's
        angles) from the decoded ``frame1`` holds the bound at frame 0 (its other rotations
        are exact, the rest those of frame 1, whose errors the joints below may add up
        differently there)."""
        bound = self.config["max_error_cm"]
        cm = 100.0 / motion.skeleton.units_per_metre
        p0, q0 = forward_kinematics(motion.skeleton, motion.channels[:1])
        p1, q1 = forward_kinematics(output_skeleton, rest_pose(output_skeleton, kind, frame1)[None])
        return worst_error(motion.skeleton, p0 * cm, q0, p1 * cm, q1, self.config["error_measure"]) <= bound

    # ----- decoding -----------------------------------------------------------------------
    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        return decode_body(body, skeleton, frames)

    # ----- streaming ------------------------------------------------------------------------
    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _SegmentEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _SegmentDecoder(self, skeleton, fps)


class _SegmentEncoder(StreamEncoder):
    """One packet per ``window`` frames, each decoding on its own: a varint frame count, then
    the body."""

    def __init__(self, codec: KinwaveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.pending = np.zeros((0, skeleton.num_channels))

    def _packet(self, frames: np.ndarray) -> Coded:
        body = varint.pack(len(frames)) + self.codec.encode(Motion(self.skeleton, self.fps, frames))
        return Coded(body, len(frames))

    def code(self, frames: np.ndarray) -> list[Coded]:
        self.pending = np.vstack([self.pending, np.atleast_2d(frames)])
        w = self.codec.config["window"]
        out = []
        while len(self.pending) >= w:
            out.append(self._packet(self.pending[:w]))
            self.pending = self.pending[w:]
        return out

    def finish(self) -> list[Coded]:
        if not len(self.pending):
            return []
        out = [self._packet(self.pending)]
        self.pending = self.pending[:0]
        return out


class _SegmentDecoder(StreamDecoder):
    def __init__(self, codec: KinwaveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps

    def push(self, packet: bytes) -> np.ndarray:
        try:
            frames, start = varint.unpack(packet, 0, 4)
        except ValueError as e:
            raise CorruptStreamError(f"kinwave packet: its frame count: {e}") from None
        return self.codec.decode(packet[start:], self.skeleton, frames, self.fps).channels
