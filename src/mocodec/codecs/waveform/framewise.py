"""Base of the frame-recursive coders of 000 ch. 7 (quant, dpcm, adpcm, deadreckoning): a clip
is a stream.

A subclass says how to choose its per-channel parameters from the first frames it sees
(``_setup``: a header and the encoder's state), how to read them back (``_load``), and how to
code frames into integer arrays (``_code``) and back (``_uncode``), carrying its state. This
base turns that into packets: one per ``push``, holding the frames the coder could complete
(all but its ``lookahead``), the header in the first, each integer array range coded by
:mod:`mocodec.coding.entropy.intcoder` with adaptive models that carry on from packet to packet. A
whole clip is the same stream pushed at once, its packets joined; so a clip decodes exactly as
its stream does. Angles are made continuous on the way in (:meth:`Motion.continuous`, carried
across pushes), as predictive coders need.

Parameters come from the first push: a live sender should push a representative first block
(a second or more), or the coder works with the ranges that block showed (the closed loop
recovers from overload, at the cost of error while it lasts). A stream restarted in mid-motion
(a live stream's keyframe) is *primed* with the frames before it, which the parameters see
too (time-reversed behind the first block, so the first frame stays the centre).
"""

from __future__ import annotations

import itertools
import struct
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from mocodec import limits
from mocodec.codecs.base import Codec, Coded, HeldFrames, StreamDecoder, StreamEncoder, continuous_frames
from mocodec.coding.entropy import intcoder
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

_PACKET = struct.Struct("<BI")  # flags (1: carries the header, 2: ends the stream), frames
Reader = Callable[[int, int], np.ndarray]


class FramewiseCodec(Codec):
    lookahead: ClassVar[int] = 0  # frames the encoder must see past the ones it codes
    bounded_codes: ClassVar[bool] = False  # the sample coder's codes are coded as its N levels
    holds_frames: ClassVar[bool] = False  # the decoder keeps frames back until the next packet or the end

    def delay_frames(self) -> int:
        return self.lookahead

    # ----- what a coder provides -----------------------------------------------------------
    def _setup(self, values: np.ndarray, skeleton: Skeleton, fps: float) -> tuple[bytes, Any]:
        """(header, encoder state) from the first frames ``(n, C)``."""
        raise NotImplementedError

    def _load(self, header: bytes, skeleton: Skeleton, fps: float) -> Any:
        """The decoder's state from a header (CorruptStreamError if it does not parse)."""
        raise NotImplementedError

    def _code(self, state: Any, frames: np.ndarray, ahead: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """(integer arrays, decoded frames) of ``frames (n, C)``; ``ahead`` are the frames
        that follow (up to ``lookahead``; fewer at the end of the stream). By default the
        state is a sample coder (:class:`~mocodec.coding.quantisation.predictive.TableCoder` and the like):
        one array of codes, one column per active channel."""
        codes, decoded = state.code(frames)
        return [codes], decoded

    def _uncode(self, state: Any, n: int, read: Reader, last: bool) -> np.ndarray:
        """The decoded frames of a packet of ``n`` frames (``last``: the stream ends with it),
        reading the integer arrays with ``read(rows, cols)`` in the order ``_code`` made them.
        A coder that ``holds_frames`` may return fewer or more than ``n``."""
        return state.uncode(read(n, state.active.size))

    def _ready(self, pending: int) -> int:
        """How many of the ``pending`` frames to code now (all but the lookahead)."""
        return pending - self.lookahead

    def _levels(self, state: Any, part: int) -> int:
        """The number of values integer array ``part`` can take (a quantiser's levels), so it
        is coded as a bounded alphabet (:class:`~mocodec.coding.entropy.intcoder.Model`); 0: unbounded.
        By default, with ``bounded_codes``, the sample coder's levels."""
        return state.levels if self.bounded_codes else 0

    # ----- clips are streams ---------------------------------------------------------------
    def _encode(self, motion: Motion) -> bytes:
        enc = self.encoder(motion.skeleton, motion.fps)
        return join_parts(enc.push(motion.channels) + enc.flush())

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        dec = self.decoder(skeleton, fps)
        out = [dec.push(p) for p in split_parts(body, None, f"{self.id} body")]
        return np.concatenate(out) if out else np.zeros((0, skeleton.num_channels))

    def encoder(self, skeleton: Skeleton, fps: float) -> StreamEncoder:
        return _FrameEncoder(self, skeleton, fps)

    def decoder(self, skeleton: Skeleton, fps: float) -> StreamDecoder:
        return _FrameDecoder(self, skeleton, fps)


class BlockwiseCodec(FramewiseCodec):
    """A frame-recursive coder of whole blocks (dct, subband): knobs ``block`` (frames, a power
    of two) and ``smooth`` (the decoder's block-edge smoothing, which holds the newest frame
    back). Frames go out a block at a time; the delay is a block, plus the held frame."""

    def __init__(self, **knobs):
        super().__init__(**knobs)
        n = self.config["block"]
        if n & (n - 1):
            raise CodecError(f"codec {self.id}: block must be a power of two, got {n}")

    @property
    def holds_frames(self) -> bool:  # type: ignore[override]
        return self.config["smooth"]

    def delay_frames(self) -> int:
        return self.config["block"] - 1 + int(self.config["smooth"])

    def segment_frames(self) -> int:
        return self.config["block"]

    def _ready(self, pending: int) -> int:
        return pending - pending % self.config["block"]


class _FrameEncoder(StreamEncoder):
    def __init__(self, codec: FramewiseCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.pending = np.zeros((0, skeleton.num_channels))
        self.last: np.ndarray | None = None  # the last continuous frame seen
        self.state: Any = None
        self.models: list[intcoder.Model] = []
        self.primer = np.zeros((0, skeleton.num_channels))
        self.out = HeldFrames(1 if codec.holds_frames else 0)  # the decoder's edge smoothing holds one

    def prime(self, frames: np.ndarray) -> None:
        if self.state is not None or len(self.pending):
            raise CodecError(f"{self.codec.id} stream: prime before the first push")
        self.primer = continuous_frames(self.codec.id, self.skeleton, self.fps, frames, None)
        self.last = self.primer[-1] if len(self.primer) else None

    def code(self, frames: np.ndarray) -> list[Coded]:
        cont = continuous_frames(self.codec.id, self.skeleton, self.fps, frames, self.last)
        if not len(cont):
            return []
        self.last = cont[-1]
        self.pending = np.vstack((self.pending, cont))
        n = self.codec._ready(len(self.pending))
        if n <= 0:
            return []
        packet = self._packet(self.pending[:n], self.pending[n:])
        self.pending = self.pending[n:]
        return [Coded(packet, self.out.out(n, last=False))]

    def finish(self) -> list[Coded]:
        if not len(self.pending) and not (self.codec.holds_frames and self.state is not None):
            return []
        n = len(self.pending)
        packet = self._packet(self.pending, self.pending[:0], last=True)
        self.pending = self.pending[:0]
        return [Coded(packet, self.out.out(n, last=True))]

    def _packet(self, frames: np.ndarray, ahead: np.ndarray, last: bool = False) -> bytes:
        header = []
        if self.state is None:
            seen = np.vstack((frames, ahead, self.primer[::-1]))
            setup, self.state = self.codec._setup(seen, self.skeleton, self.fps)
            header = [setup]
        arrays, _ = self.codec._code(self.state, frames, ahead)
        while len(self.models) < len(arrays):
            k = len(self.models)
            self.models.append(intcoder.Model(arrays[k].shape[1], self.codec._levels(self.state, k)))
        coded = [intcoder.encode(a, m) for a, m in zip(arrays, self.models)]
        return _PACKET.pack(int(bool(header)) | 2 * int(last), len(frames)) + join_parts(header + coded)


class _FrameDecoder(StreamDecoder):
    """Packets in, frames out. A packet that does not parse raises CorruptStreamError; the
    stream cannot go on after it (the coders' state depends on every packet). A decoder that
    lacks what the stream needs (the codebook file a header names) raises CodecError."""

    def __init__(self, codec: FramewiseCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.state: Any = None
        self.models: list[intcoder.Model] = []

    def push(self, packet: bytes) -> np.ndarray:
        try:
            return self._push(packet)
        except (CorruptStreamError, CodecError):
            raise
        except Exception as e:  # noqa: BLE001 - a packet that does not parse
            raise CorruptStreamError(f"{self.codec.id} packet does not decode ({type(e).__name__}: {e})") from None

    def _push(self, packet: bytes) -> np.ndarray:
        if len(packet) < _PACKET.size:
            raise CorruptStreamError(f"{self.codec.id} packet of {len(packet)} bytes is shorter than its header")
        flags, n = _PACKET.unpack_from(packet)
        parts = split_parts(packet, None, f"{self.codec.id} packet", start=_PACKET.size)
        if flags & 1:
            if self.state is not None:
                raise CorruptStreamError(f"{self.codec.id} stream: a second header packet")
            self.state = self.codec._load(parts.pop(0), self.skeleton, self.fps)
        elif self.state is None:
            raise CorruptStreamError(f"{self.codec.id} stream: the first packet carries no header")
        if n * self.skeleton.num_channels > limits.MAX_DECODED_VALUES:
            raise CorruptStreamError(
                f"{self.codec.id} packet claims {n} frames, over the limit of {limits.MAX_DECODED_VALUES:,} values"
            )
        counter = itertools.count()

        def read(rows: int, cols: int) -> np.ndarray:
            k = next(counter)
            if k >= len(parts):
                raise CorruptStreamError(f"{self.codec.id} packet has {len(parts)} coded parts, the coder reads more")
            if k == len(self.models):
                self.models.append(intcoder.Model(cols, self.codec._levels(self.state, k)))
            return intcoder.decode(parts[k], rows, cols, self.models[k])

        out = self.codec._uncode(self.state, n, read, bool(flags & 2))
        if out.shape[1:] != (self.skeleton.num_channels,) or (out.shape[0] != n and not self.codec.holds_frames):
            raise CorruptStreamError(f"{self.codec.id} packet decodes to {out.shape}")
        return out
