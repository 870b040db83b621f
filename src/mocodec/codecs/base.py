"""The codec interface (docs/architecture.md): knobs, bodies, capabilities, the streaming pair.

Every codec subclasses :class:`Codec`, names its ``id``, ``description`` and ``knobs`` and
implements ``_encode(motion) -> body`` and ``_decode(body, skeleton, frames, fps) ->
channels``. A body holds the coded motion only: the frame count, the frame rate and the
integrity check are the framing's, which the .moc container (:mod:`mocodec.moc`) and the
stream packets (:mod:`mocodec.stream.packets`) carry once, with a CRC. Any failure inside a
decoder is reported as :class:`~mocodec.errors.CorruptStreamError`, never as another
exception. Encoding refuses NaN and infinite channels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mocodec import limits, sandbox
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MAX_FRAMES = limits.MAX_PAYLOAD_FRAMES


@dataclass(frozen=True)
class Knob:
    """A codec parameter: its type, default, valid range or choices, and what it does."""

    name: str
    kind: type
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None
    path: bool = False  # names a local file: never taken from a file or a stream (docs/security.md)

    def parse(self, value: Any) -> Any:
        try:
            if self.kind is bool and isinstance(value, str):
                v = value.lower() in ("1", "true", "yes", "on")
            else:
                v = self.kind(value)
        except (TypeError, ValueError, OverflowError):
            raise CodecError(f"knob {self.name}: expected {self.kind.__name__}, got {str(value)[:40]!r}") from None
        if self.kind is float and not np.isfinite(v):
            raise CodecError(f"knob {self.name}: {value!r} is not a finite number")
        if self.low is not None and v < self.low or self.high is not None and v > self.high:
            raise CodecError(f"knob {self.name}: {str(v)[:40]} is outside {self.low}..{self.high}")
        if self.choices is not None and v not in self.choices:
            raise CodecError(f"knob {self.name}: {v!r} is not one of {', '.join(map(str, self.choices))}")
        return v

    def describe(self) -> str:
        span = f" {self.low:g}..{self.high:g}" if self.low is not None and self.high is not None else ""
        choices = f" {{{','.join(map(str, self.choices))}}}" if self.choices else ""
        return f"{self.name}={self.default}{span}{choices}"


@dataclass(frozen=True)
class QualityKnob:
    """The knob rate control turns, and which way raises quality (and size)."""

    name: str
    higher_is_better: bool
    log_scale: bool = False


@dataclass(frozen=True)
class Coded:
    """One stream packet as its encoder made it, with what a sender tells a relay of it."""

    payload: bytes
    frames: int  # the frames a receiver's decoder gives out for it (what it completes)
    # where a relay may cut it: an embedded codec's channel streams' lengths, or a layered
    # codec's layer ends but the top one (empty for others)
    cuts: tuple[int, ...] = ()
    restart: bool = False  # the codec stream's base restarts in it (a receiver may join here)


class HeldFrames:
    """The frames out per packet of a decoder that holds back its newest ``hold`` frames until
    the next packet (a seam or block edge it smooths) and gives out everything with the last:
    what a stream encoder says of each packet it makes (:attr:`Coded.frames`)."""

    def __init__(self, hold: int):
        self.hold, self.held = hold, 0

    def out(self, frames: int, last: bool) -> int:
        total = self.held + frames
        self.held = 0 if last else min(self.hold, total)
        return total - self.held


class StreamEncoder:
    """Frames in, packets out (for codecs the theses call real-time). A codec's encoder
    implements :meth:`code` and :meth:`finish`; :meth:`push` and :meth:`flush` give the
    payloads alone."""

    def code(self, frames: np.ndarray) -> list[Coded]:
        """The packets ``frames`` complete, each with what it decodes to."""
        raise NotImplementedError

    def finish(self) -> list[Coded]:
        """The packets of whatever is left: the codec stream ends."""
        return []

    def push(self, frames: np.ndarray) -> list[bytes]:
        return [c.payload for c in self.code(frames)]

    def flush(self) -> list[bytes]:
        return [c.payload for c in self.finish()]

    def prime(self, frames: np.ndarray) -> None:
        """Frames from before the stream starts, which are not coded: a coder that picks its
        parameters from the first frames it sees may look at them too (a live stream's intra
        refresh starts a new stream in mid-motion). Call before the first push."""

    def follow(self, previous: StreamEncoder) -> None:
        """This stream starts where ``previous`` (of the same codec) ended, at a live stream's
        keyframe: take over what the sender learned that the receiver does not need (an
        encoder's rate or scale settings), never what the decoder would have to know. Call
        before the first push."""


def checked_frames(codec_id: str, skeleton: Skeleton, frames: np.ndarray) -> np.ndarray:
    """Pushed ``frames`` as a float64 ``(n, channels)`` array; CodecError unless they fit the
    skeleton and are finite."""
    frames = np.atleast_2d(np.asarray(frames, dtype=np.float64))
    if frames.shape[1] != skeleton.num_channels or not np.isfinite(frames).all():
        raise CodecError(f"{codec_id} stream: frames must be finite (n, {skeleton.num_channels}) arrays")
    return frames


def continuous_frames(
    codec_id: str, skeleton: Skeleton, fps: float, frames: np.ndarray, previous: np.ndarray | None
) -> np.ndarray:
    """Pushed ``frames`` checked (:func:`checked_frames`) and made continuous
    (:meth:`Motion.continuous`) carrying on from ``previous``, the last continuous frame of the
    earlier pushes (None at the start): what stream encoders of predictive and transform
    coders work on."""
    frames = checked_frames(codec_id, skeleton, frames)
    if not len(frames):
        return frames
    head = frames if previous is None else np.vstack((previous, frames))
    cont = Motion(skeleton, fps, head).continuous().channels
    return cont if previous is None else cont[1:]


class StreamDecoder:
    """Packets in, frames out."""

    def push(self, packet: bytes) -> np.ndarray:
        raise NotImplementedError

    def push_layers(self, packet: bytes, layers: int) -> np.ndarray:
        """The frames of a layered stream's ``packet`` that carries only its ``layers`` lowest
        layers (a relay cut the others off); CodecError for a codec without layers."""
        raise CodecError("a packet cut by layers, of a stream without layers")

    @property
    def in_step(self) -> bool:
        """Whether the next packet can decode (after :meth:`lost`, not until the codec stream
        has restarted enough of itself)."""
        return True

    def lost(self) -> bool:
        """Told that packets were lost (or one was damaged): True if the decoder finds its own
        way back (its codec stream restarts parts of itself; :meth:`push` raises
        :class:`~mocodec.errors.OutOfStepError` until it can decode again), False if it must be
        replaced at the next keyframe."""
        return False


class Codec:
    """Base of every codec. Construct with knobs: ``get_codec("raw")``, ``Codec(**knobs)``."""

    id: ClassVar[str] = ""
    description: ClassVar[str] = ""
    knobs: ClassVar[tuple[Knob, ...]] = ()
    quality: ClassVar[QualityKnob | None] = None
    lossless: ClassVar[bool] = False
    # the codec's number in stream packets (part of the wire format: a new codec takes the next
    # free one, docs/streaming.md); None: it does not stream live
    packet_number: ClassVar[int | None] = None
    streaming: ClassVar[bool] = False  # it has a packet number (set from it: never by hand)
    # bodies and stream packets cut to a lower rate by dropping bytes, never decoding
    # (truncator, packet_cuts, packet_cutter): a file is truncated, a relay cuts each viewer's rate
    embedded: ClassVar[bool] = False
    variable_delay: ClassVar[bool] = False  # the delay depends on the motion (000 ch. 8)
    baseline: ClassVar[bool] = False  # a generic float compressor, for comparison
    # kernels of the codec's that a second process may compile while ``mocodec warmup`` codes a
    # clip (module-level functions of no arguments)
    warm_parts: ClassVar[tuple[Callable[[], None], ...]] = ()
    native_decoder: ClassVar[bool] = False  # hands the body to a C library: untrusted bodies decode in a child
    # the revision of the codec's body and packet format; a config above 1 says it, and a reader
    # refuses another (docs/formats.md)
    revision: ClassVar[int] = 1

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.streaming = cls.packet_number is not None

    def __init__(self, **knobs):
        specs = {k.name: k for k in self.knobs}
        unknown = sorted(set(knobs) - set(specs))
        if unknown:
            have = ", ".join(specs) or "none"
            raise CodecError(f"codec {self.id}: unknown knob {unknown[0]!r} (knobs: {have})")
        self.config = {name: spec.parse(knobs.get(name, spec.default)) for name, spec in specs.items()}

    def __repr__(self) -> str:
        return f"{self.id}({', '.join(f'{k}={v!r}' for k, v in self.config.items())})"

    def __eq__(self, other: object) -> bool:
        """Codecs are equal when their configs are (the same id, revision and knobs)."""
        return isinstance(other, Codec) and self.get_config() == other.get_config()

    def __hash__(self) -> int:
        return hash((self.id, tuple(sorted(self.config.items()))))

    # ----- what it can do ---------------------------------------------------------------
    def delay_frames(self) -> int:
        """Frames between one going into the stream encoder and coming out of the decoder."""
        return 0

    @property
    def layers(self) -> int:
        """How many layers its stream packets carry, base first (1: no layers). A relay serves a
        viewer the lowest layers by cutting a packet after one (:attr:`Coded.cuts`); a
        receiver decodes them with :meth:`StreamDecoder.push_layers`."""
        return 1

    def layer_starts(self, payload: bytes) -> list[bool]:
        """For each layer a stream packet carries, whether the layer restarts in it (a receiver
        that did not have the layer may take it from this packet on); empty for a codec whose
        streams restart only at keyframes."""
        return []

    def at_rate(self, bits_per_second: float) -> Codec:
        """This codec coding at ``bits_per_second`` (its rate knob, whatever its name); CodecError
        for a codec without one."""
        raise CodecError(f"codec {self.id} has no bit rate knob")

    def segment_frames(self) -> int:
        """Frames a live stream's keyframe interval is rounded up to: the codec's segment or block, so a
        keyframe does not cut one short (1: any frame)."""
        return 1

    def truncator(
        self, body: bytes, skeleton: Skeleton, frames: int, fps: float
    ) -> Callable[[float], tuple[Codec, bytes]]:
        """An embedded codec's body cut: bits_per_second -> (the codec of that rate, the body cut
        to it)."""
        raise CodecError(f"codec {self.id} is not embedded: its files cannot be truncated")

    def packet_cuts(self, packet: bytes, skeleton: Skeleton) -> np.ndarray:
        """An embedded codec's stream packet: where each channel's stream ends (the sender works
        it out once)."""
        raise CodecError(f"codec {self.id} is not embedded")

    def packet_cutter(
        self, packet: bytes, skeleton: Skeleton, cuts: np.ndarray, fps: float
    ) -> Callable[[float], bytes]:
        """An embedded codec's stream packet cut: bits_per_second -> the packet cut to that rate
        (parsed once, cut for many viewers)."""
        raise CodecError(f"codec {self.id} is not embedded")

    # ----- configuration ----------------------------------------------------------------
    def get_config(self) -> dict:
        config = {"codec": self.id, "knobs": dict(self.config)}
        return config | {"revision": self.revision} if self.revision > 1 else config

    @classmethod
    def from_config(cls, config: dict) -> Codec:
        if config.get("codec") != cls.id:
            raise CodecError(f"config is for codec {config.get('codec')!r}, not {cls.id!r}")
        cls.check_revision(config)
        return cls(**config.get("knobs", {}))

    @classmethod
    def check_revision(cls, config: dict) -> None:
        """CodecError unless ``config`` is of the format revision this build reads (none given: 1)."""
        revision = config.get("revision", 1)
        if revision != cls.revision:
            raise CodecError(
                f"{cls.id} data of format revision {revision!r}; this mocodec reads revision {cls.revision}"
            )

    def with_knob(self, name: str, value) -> Codec:
        return type(self)(**{**self.config, name: value})

    def bound_knobs(self, target: str, value: float) -> dict | None:
        """Knobs with which the encoder itself guarantees an error target (``max_error_cm`` or
        ``mean_error_cm``), verifying it on the bytes it returns; None where it does not, and
        rate control must search (:func:`mocodec.ratecontrol.guaranteed`)."""
        return None

    # ----- whole clips ------------------------------------------------------------------
    def encode(self, motion: Motion, output_skeleton: Skeleton | None = None) -> bytes:
        """The body of ``motion`` (its frame count and rate are the framing's: the container's
        or the stream's). ``output_skeleton``: the skeleton the decoder will be given when it
        is not quite ``motion``'s own (a lossy .moc file stores offsets rounded,
        :func:`mocodec.moc.pack`); a codec that verifies an error bound verifies it on the
        joints that skeleton gives. A motion without channels (a rig whose joints never move,
        as some exporters write one) is an empty body."""
        if not motion.skeleton.num_channels:
            return b""
        if not np.isfinite(motion.channels).all():
            f, c = np.argwhere(~np.isfinite(motion.channels))[0]
            raise CodecError(
                f"cannot encode: frame {f}, channel {motion.skeleton.channel_names[c]} is {motion.channels[f, c]}"
            )
        if motion.num_frames > MAX_FRAMES:
            raise CodecError(
                f"cannot encode {motion.num_frames} frames in one body (limit {MAX_FRAMES}); "
                "use the container, which splits clips into chunks"
            )
        return self._encode(motion) if output_skeleton is None else self._encode_for(motion, output_skeleton)

    def decode(
        self,
        body: bytes,
        skeleton: Skeleton,
        frames: int,
        fps: float,
        max_values: int = limits.MAX_DECODED_VALUES,
        trusted: bool = False,
    ) -> Motion:
        """The motion of ``frames`` frames at ``fps`` in ``body`` (from :meth:`encode`), on
        ``skeleton``. More than ``max_values`` values (frames x channels) are refused before
        anything is allocated; decoded values are finite or the body is refused. ``trusted``:
        the body was encoded by this process, so a native decoder may run here rather than in
        a child (:mod:`mocodec.sandbox`)."""
        if not 0 <= frames <= MAX_FRAMES or not limits.fps_ok(fps):
            raise CorruptStreamError(f"{self.id} body: {frames} frames at {fps} fps is not plausible")
        if frames * skeleton.num_channels > max_values:
            raise CorruptStreamError(
                f"{self.id} body of {frames} frames of {skeleton.num_channels} channels is "
                f"over the limit of {max_values:,} values (raise it with --max-values)"
            )
        if not skeleton.num_channels and not body:  # (a motion without channels)
            return Motion(skeleton, fps, np.zeros((frames, 0)))
        try:
            if self.native_decoder and not trusted:
                channels = sandbox.call_isolated(self._decode, body, skeleton, frames, fps, what=f"{self.id} body")
            else:
                channels = self._decode(body, skeleton, frames, fps)
        except (CorruptStreamError, CodecError):
            raise
        except Exception as e:  # noqa: BLE001 - a body that does not parse
            raise CorruptStreamError(f"{self.id} body does not decode ({type(e).__name__}: {e})") from None
        channels = np.asarray(channels, dtype=np.float64)
        if channels.shape != (frames, skeleton.num_channels):
            raise CorruptStreamError(
                f"{self.id} body decodes to {channels.shape}, expected "
                f"({frames}, {skeleton.num_channels}): wrong skeleton?"
            )
        if not np.isfinite(channels).all():
            f, c = np.argwhere(~np.isfinite(channels))[0]
            raise CorruptStreamError(
                f"{self.id} body decodes to {channels[f, c]} at frame {f}, channel "
                f"{skeleton.channel_names[c]}: the data is damaged"
            )
        return Motion(skeleton, fps, channels)

    def _encode(self, motion: Motion) -> bytes:
        raise NotImplementedError

    def _encode_for(self, motion: Motion, output_skeleton: Skeleton) -> bytes:
        """The body for a decoder given ``output_skeleton`` (same structure as ``motion``'s, offsets
        rounded): for codecs that do not check the joints' error, :meth:`_encode` of the
        motion on that skeleton, so that whatever the codec derives from the skeleton (body
        parts, groups, lever arms) is what its decoder derives (rounding an offset of 1e-7 to
        0 can move a joint to another body part)."""
        return self._encode(Motion(output_skeleton, motion.fps, motion.channels))

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        raise NotImplementedError

    # ----- streaming --------------------------------------------------------------------
    def packet_frames(self, fps: float) -> int:
        """The frames every packet of this codec's stream codes but a stream's last, or 0
        where they vary (a live stream's header says it, so its packets need not)."""
        return 0

    def decoder_tables(self, skeleton: Skeleton, primer: np.ndarray | None = None) -> dict:
        """What a live stream's header carries for its decoders beyond the config and the
        skeleton (``StreamInfo.extra["decoder"]``): tables this codec derives by numerics a
        decoder in another language could not redo bit for bit (an optimiser's result), and
        what it takes from ``primer`` (frames like the ones to come) for every codec stream of
        the live stream (see :meth:`for_stream`). Empty for most codecs."""
        return {}

    def for_stream(self, skeleton: Skeleton, tables: dict) -> Codec:
        """This codec for one live stream whose header carries ``tables`` (from
        :meth:`decoder_tables`; hostile on a receiver: checked, CorruptStreamError): itself for
        most codecs."""
        return self

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        raise CodecError(f"codec {self.id} does not stream")

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        raise CodecError(f"codec {self.id} does not stream")
