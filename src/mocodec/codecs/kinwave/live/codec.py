"""``kinwave-live``: kinwave's low-delay mode for live avatars (docs/streaming.md).

A packet codes ``packet_frames`` frames (at most 50 ms: 6 at 120 fps, 1 at 30 fps) as soon as
they are in, with the pose representation of offline kinwave:

1. Joints are coded parents first, each against its parent's *decoded* orientation
   (:func:`~mocodec.codecs.shared.closedloop.code_down_tree`), so a joint's orientation error is
   its own quantisation error and errors do not pile up along the chains. A translation below
   the root that moves restores its joint's position from its parent's decoded one; one that
   stands still is coded as it is (:meth:`.encoder.LiveEncoder._retarget`).
2. Each channel is predicted from its last two decoded frames (order 2, a straight line, or
   order 1, the last value) and the difference is quantised with its joint's step: the decoded
   angle is within half a step of its target on every frame, whatever came before. Both ends
   choose the order per channel from the decoded frames alone (:func:`.predict.update_misses`: the
   one that missed them less lately), so the choice costs no bits.
3. The steps' shape per joint is the convex allocation of :mod:`.kinalloc` for the max joint
   error; one scale offset per packet (1/8 octave) multiplies it. The encoder decodes each
   packet bit-exactly and checks the max joint (or shell) error of every frame against
   ``max_error_cm``; a packet over it is coded again finer, and a packet well under it lets the
   next start coarser.
4. The integers go through the context-adaptive binary arithmetic coder of
   :mod:`mocodec.coding.entropy.binarycoder`: per joint a flag "all zero in this packet", per
   channel and frame an integer whose zero flag is in the context of the channel's previous
   integer. The contexts carry over from packet to packet (a codec stream's packets depend on
   each other; the live stream restarts the codec at each keyframe, docs/streaming.md).
5. **Layers** (knob ``layers``): the stream may carry up to four layers, base first, each at
   ``layer_ratio`` (2) times the bound of the next (``layers=3`` at 1 cm: 4, 2 and 1 cm). Each
   layer is coded as above with its own history, steps and contexts, and closed-loop on the
   layers below: its prediction is clamped to the interval the nearest layer below that coded
   the frame puts the target in (the quantiser cell of that layer's integer), for the channels
   whose decoded values fell in those cells in the last packet (both ends judge this alike,
   nothing is sent). Its bound is checked on the decoding of it and the layers below.

A packet is one arithmetic-coded stream (:func:`~mocodec.coding.entropy.binarycoder.finish_short`,
its always-zero first byte left out): with ``refresh_s``, each layer's restart flag in a fixed
context; then per layer, base first, whether the packet is short (and its frame count), the
change of the scale offset, the stride, then per joint its "any nonzero" flag and its
integers. The layers are not delimited: a decoder of the whole packet finds where each ends,
the shortest prefix that decodes it and those below as the whole does (:func:`.syntax.prefix_end`),
which the sender gives the relay as the packet's cut table; a relay serves a viewer the lowest
layers by cutting there, and says how many it cut off in the packet's frame.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Codec, Knob, QualityKnob, StreamDecoder, StreamEncoder
from mocodec.codecs.kinwave import kinalloc
from mocodec.codecs.kinwave.body import code_channels, rotation_joints, step_codes, step_groups
from mocodec.codecs.kinwave.encoder import bone_skeleton
from mocodec.codecs.kinwave.live.decoder import LiveDecoder
from mocodec.codecs.kinwave.live.encoder import LiveEncoder
from mocodec.codecs.kinwave.live.predict import joint_tables
from mocodec.codecs.kinwave.live.syntax import MAX_LAYERS, packet_data, packet_frames, read_restarts
from mocodec.codecs.registry import register
from mocodec.coding.entropy import binarycoder as bc
from mocodec.errors import CorruptStreamError
from mocodec.formats import varint
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MAX_REFERENCE = 1e9  # the largest reference value a stream header may give


def layer_bounds(max_error_cm: float, layers: int, ratio: float = 2.0) -> list[float]:
    """The bounds of a stream's layers, base first: each ``ratio`` times the next, the last
    ``max_error_cm``."""
    return [max_error_cm * ratio ** (layers - 1 - k) for k in range(layers)]


def base_codes(skeleton: Skeleton, bound_cm: float, measure: str) -> np.ndarray:
    """The step codes (one per rotation joint, then the translations) whose modelled max error
    is ``bound_cm`` (:func:`.kinalloc.steps`, closed loop): where a stream's scale starts."""
    counts = [0] * len(skeleton)
    translations = 0
    for g in step_groups(skeleton):
        if g.rotation:
            counts[g.joint] = g.channels.size
        else:
            translations += g.channels.size
    rot, trans = kinalloc.steps(skeleton, tuple(counts), translations, "shell" if measure == "shell" else "joint", True)
    rot = np.where(np.isfinite(rot), rot, np.nanmin(rot) if np.isfinite(rot).any() else 1.0)
    steps = np.append(rot[rotation_joints(skeleton)], trans if translations else [])
    return step_codes(np.asarray(steps) * bound_cm)


@register
class KinwaveLiveCodec(Codec):
    id = "kinwave-live"
    packet_number = 10
    description = (
        "kinwave for live avatars: closed-loop prediction down the kinematic tree, packets of at most "
        "50 ms, context-adaptive arithmetic coding across packets, guaranteed max error on every frame, "
        "layers a relay drops by cutting"
    )
    knobs = (
        Knob("max_error_cm", float, 1.0, "error bound in cm, held on every decoded frame", 1e-3, 1000.0),
        Knob(
            "error_measure",
            str,
            "joint",
            "joint: max joint position error; shell: points 3 cm off every bone",
            choices=("joint", "shell"),
        ),
        Knob(
            "layers",
            int,
            1,
            "layers of the stream, each at layer_ratio times the bound of the next (3: 4, 2 and 1 cm at "
            "max_error_cm 1)",
            1,
            MAX_LAYERS,
        ),
        Knob(
            "layer_ratio",
            float,
            2.0,
            "each layer's bound over the next one's (2 layers at 32: 32 and 1 cm); a coarser base "
            "costs the full stream less (measured: docs/streaming.md)",
            1.0,
            1000.0,
        ),
        Knob(
            "refresh_s",
            float,
            0.0,
            "seconds between restarts of each layer inside the codec stream, the layers' restarts "
            "spread over that time (0: none; the live stream's keyframes restart the whole stream)",
            0.0,
            60.0,
        ),
    )
    quality = QualityKnob("max_error_cm", higher_is_better=False, log_scale=True)
    # 2: the predictor orders are no longer sent (both ends choose them, update_misses);
    # 3: the head codes a still packet's usual values as zeros (full flag, drift, stride index)
    revision = 3
    reference: np.ndarray | None = None  # the stream's reference pose (for_stream)
    codes: np.ndarray | None = None  # the stream's base step codes per layer (for_stream)

    def delay_frames(self) -> int:
        return 0  # plus the packet's own frames: packet_frames(fps) - 1 at most

    def bound_knobs(self, target: str, value: float) -> dict | None:
        """Its bound holds on every decoded frame of the full stream (the finest layer)."""
        return {"max_error_cm": value} if target == "max_error_cm" else None

    @property
    def layers(self) -> int:
        return self.config["layers"]

    @property
    def layer_bounds(self) -> list[float]:
        """Each layer's bound in cm, base first."""
        return layer_bounds(self.config["max_error_cm"], self.config["layers"], self.config["layer_ratio"])

    def layer_starts(self, payload: bytes) -> list[bool]:
        layers = self.config["layers"]
        if not self.config["refresh_s"]:
            return [False] * layers
        data = packet_data(payload)
        return [bool(flag) for flag in read_restarts(bc.start_decoder(data), data, layers)]

    def restart_frames(self, fps: float) -> tuple[int, list[int]]:
        """(period, phase of each layer) in frames of the layers' restarts inside a codec stream:
        layer k restarts in the packet that holds a frame ``f`` with ``f % period == phase[k]``
        (0: never)."""
        if not self.config["refresh_s"]:
            return 0, []
        period = max(int(round(self.config["refresh_s"] * fps)), packet_frames(fps))
        layers = self.config["layers"]
        return period, [k * period // layers for k in range(layers)]

    def packet_frames(self, fps: float) -> int:
        return packet_frames(fps)

    def decoder_tables(self, skeleton: Skeleton, primer: np.ndarray | None = None) -> dict:
        """Each layer's base step codes (:func:`base_codes`, base layer first): the convex
        allocation's result, which a decoder elsewhere cannot recompute exactly; and with a
        ``primer``, its first frame as the stream's *reference pose* (to 1e-4 of a degree or a
        skeleton unit), from which every codec stream of the live stream predicts its first
        frame (:meth:`for_stream`): a keyframe then codes how the pose moved since, not the
        pose. The allocation's levers are then the motion's own bones (the offsets plus the
        reference's translations below the root, :func:`.encoder.bone_skeleton`: a skeleton
        that keeps its bones in position channels has zero offsets)."""
        measure = self.config["error_measure"]
        levers = skeleton
        tables: dict = {}
        if primer is not None and len(primer):
            tables["reference"] = [round(float(v), 4) for v in primer[0]]
            levers = bone_skeleton(skeleton, np.array(tables["reference"])[:, None], joint_tables(skeleton)[3])
        tables["base_codes"] = [base_codes(levers, b, measure).tolist() for b in self.layer_bounds]
        return tables

    def for_stream(self, skeleton: Skeleton, tables: dict) -> KinwaveLiveCodec:
        """This codec with a live stream header's base step codes and reference pose
        (:meth:`decoder_tables`), where it gives them: CorruptStreamError for codes that are
        not a list per layer of one integer 0-255 per step, or a reference that is not a
        finite value per channel within MAX_REFERENCE."""
        if not isinstance(tables, dict) or not ("base_codes" in tables or "reference" in tables):
            return self
        bound = type(self)(**self.config)
        if "base_codes" in tables:
            bound.codes = _checked_codes(tables["base_codes"], skeleton, len(self.layer_bounds))
        if "reference" in tables:
            bound.reference = _checked_reference(tables["reference"], skeleton)
        return bound

    def layer_codes(self, skeleton: Skeleton) -> list[np.ndarray]:
        """Each layer's base step codes: a stream header's (:meth:`for_stream`), else those of
        the skeleton's offsets."""
        if self.codes is not None:
            return list(self.codes)
        return [base_codes(skeleton, b, self.config["error_measure"]) for b in self.layer_bounds]

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return LiveEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return LiveDecoder(self, skeleton, fps)

    def _encode(self, motion: Motion) -> bytes:
        """A clip is its stream: every packet after its length (a varint)."""
        enc = self.encoder(motion.skeleton, motion.fps)
        return b"".join(varint.pack(len(p)) + p for p in enc.push(motion.channels) + enc.flush())

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        dec = self.decoder(skeleton, fps)
        out, pos = [], 0
        while pos < len(body):
            try:
                size, pos = varint.unpack(body, pos, 4)
            except ValueError as e:
                raise CorruptStreamError(f"kinwave-live body: a packet length: {e}") from None
            if pos + size > len(body):
                raise CorruptStreamError(f"kinwave-live body: a {size}-byte packet at byte {pos} runs past the end")
            out.append(dec.push(body[pos : pos + size]))
            pos += size
        return np.concatenate(out) if out else np.zeros((0, skeleton.num_channels))


def _checked_codes(codes: object, skeleton: Skeleton, layers: int) -> np.ndarray:
    count = len(code_channels(skeleton))
    if not (
        isinstance(codes, list)
        and len(codes) == layers
        and all(
            isinstance(row, list)
            and len(row) == count
            and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255 for v in row)
            for row in codes
        )
    ):
        raise CorruptStreamError(
            f"kinwave-live stream header: base_codes must be {layers} lists of {count} step codes 0-255"
        )
    return np.array(codes, dtype=np.int64)


def _checked_reference(reference: object, skeleton: Skeleton) -> np.ndarray:
    if (
        not isinstance(reference, list)
        or len(reference) != skeleton.num_channels
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in reference)
    ):
        raise CorruptStreamError(
            f"kinwave-live stream header: the reference pose must be {skeleton.num_channels} numbers"
        )
    values = np.array(reference, dtype=np.float64)
    if not (np.isfinite(values).all() and np.abs(values).max(initial=0.0) <= MAX_REFERENCE):
        raise CorruptStreamError(f"kinwave-live stream header: a reference value beyond {MAX_REFERENCE:g}")
    return values
