"""Live streams: a codec's stream encoder and decoder wrapped in packets, with keyframes and
loss concealment.

Every ``keyframe_s`` seconds (rounded up to the codec's block, so a segment coder is not cut
short) the sender ends the codec stream and starts a new one; the first packet of each is a
*keyframe*, decodable with nothing before it. A frame-recursive coder's new stream is primed
with the last second of input so its parameters fit the motion (:meth:`StreamEncoder.prime`).
A receiver that joins late, or loses a packet, drops what it cannot decode until the next
keyframe and conceals the frames in between, so it is back in step within one keyframe interval.

Each packet says which frames it completes at the receiver (``first_frame``, ``frames``): the
codec's stream encoder says how many its decoder gives out for each packet
(:class:`~mocodec.codecs.base.Coded`), whatever it holds back, so a receiver knows how many
frames to conceal for a lost packet.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from mocodec.codecs import packet_codecs
from mocodec.codecs.base import Codec, Coded, StreamDecoder, StreamEncoder, checked_frames
from mocodec.errors import CodecError, OutOfStepError
from mocodec.motion import Motion
from mocodec.skeleton import POSITION_CHANNELS, Skeleton
from mocodec.stream.packets import (
    CUTS,
    DATA,
    END,
    HEADER,
    KEYFRAME,
    RESTART,
    Packet,
    StreamInfo,
    header_packet,
    with_cut_table,
)

#: A sender's tick (Hz): frames are pushed, and packets sent, this often.
TICK_HZ = 30.0
#: Seconds of earlier input a restarted stream is primed with.
POSITION_STEP_M = 0.5  # a compact packet carries the root position when it moved this far (m)
PRIMER_S = 1.0
#: How far extrapolation runs on before it holds (seconds), and the frames its velocity is
#: measured over.
EXTRAPOLATE_S = 0.25
VELOCITY_FRAMES = 5
#: The longest gap a receiver fills with concealed frames (seconds, and values: frames x
#: channels); a packet further ahead (a hostile first_frame of 2**32 - 200) restarts the
#: frame count there instead, so a packet cannot make a receiver allocate without bound.
MAX_CONCEAL_S = 10.0
MAX_CONCEAL_VALUES = 1 << 22
#: A receiver that repairs losses (``hold_s`` > 0) waits for at most this many missing packets
#: of one stream, and holds at most this many packets behind them.
MAX_MISSING = 64
MAX_HELD = 256


def now_us() -> int:
    return time.time_ns() // 1000


def root_position(skeleton: Skeleton, frame: np.ndarray) -> tuple[float, float, float]:
    """The root's position in metres from one frame of channels (0 where it has no channel),
    as the float32 a packet carries."""
    out = [0.0, 0.0, 0.0]
    root = skeleton.joints[0]
    first = int(skeleton.channel_offsets[0])
    for k, name in enumerate(root.channels):
        if name in POSITION_CHANNELS:
            out[POSITION_CHANNELS.index(name)] = float(frame[first + k]) / skeleton.units_per_metre
    x, y, z = (float(np.float32(v)) for v in out)
    return x, y, z


def tick_frames(fps: float) -> int:
    """Frames a sender pushes per tick."""
    return max(int(round(fps / TICK_HZ)), 1)


def keyframe_frames(codec: Codec, fps: float, keyframe_s: float) -> int:
    """Frames between keyframes: ``keyframe_s`` rounded up to the codec's segment or block."""
    block = codec.segment_frames()
    n = max(int(round(keyframe_s * fps)), 1)
    return -(-n // block) * block


class LiveEncoder:
    """Frames in, packets out, for one stream (one avatar). ``primer``: frames like the ones
    to come (a calibration take, or a clip's first second), which the first stream's
    parameters may look at; without it a frame-recursive coder fits its first stream to the
    first push alone, and is coarse until the first keyframe."""

    def __init__(
        self,
        codec: Codec,
        skeleton: Skeleton,
        fps: float,
        stream: int,
        keyframe_s: float = 1.0,
        name: str = "",
        primer: np.ndarray | None = None,
        compact: bool = True,
    ):
        if not codec.streaming:
            raise CodecError(
                f"codec {codec.id} has no packet number: it does not stream live (streaming codecs: "
                f"{', '.join(packet_codecs())})"
            )
        if not keyframe_s > 0:
            raise CodecError(f"keyframe interval must be positive, got {keyframe_s}")
        if not skeleton.num_channels:
            raise CodecError("a skeleton without channels has nothing to stream (its joints never move)")
        primer = None if primer is None else checked_frames(codec.id, skeleton, primer)
        tables = codec.decoder_tables(skeleton, primer)
        self.codec = codec.for_stream(skeleton, tables)
        self.skeleton, self.fps, self.stream = skeleton, fps, stream
        self.info = StreamInfo(skeleton, fps, codec.get_config(), name, {"decoder": tables} if tables else {})
        self.keyframe_every = keyframe_frames(codec, fps, keyframe_s)
        self.usual_frames = codec.packet_frames(fps)  # the header says it once
        self.primer_frames = max(int(round(PRIMER_S * fps)), 1)
        self.recent = np.zeros((0, skeleton.num_channels)) if primer is None else primer[-self.primer_frames :]
        self.sequence = 0
        self.out_frames = 0  # frames the receiver has been told about
        self.in_group = 0  # input frames in the current codec stream
        self.encoder: StreamEncoder | None = None
        self.ended: StreamEncoder | None = None  # the last codec stream's encoder
        self.cuttable = codec.embedded or codec.layers > 1  # its packets carry a cut table for relays
        self.keyframe_due = True
        self.position = (0.0, 0.0, 0.0)
        self.compact = compact  # data packets in the compact wire form (packets.Packet.to_compact)
        self.sent_position: tuple[float, float, float] | None = None  # the root position last sent

    def header(self, timestamp_us: int | None = None) -> Packet:
        ts = now_us() if timestamp_us is None else timestamp_us
        return header_packet(self.stream, self.info, ts, self.usual_frames)

    def push(self, frames: np.ndarray, timestamp_us: int | None = None) -> list[Packet]:
        frames = checked_frames(self.codec.id, self.skeleton, frames)
        ts = now_us() if timestamp_us is None else timestamp_us
        out: list[Packet] = []
        while len(frames):
            encoder = self.encoder or self._start()
            take = min(len(frames), self.keyframe_every - self.in_group)
            chunk, frames = frames[:take], frames[take:]
            self.position = root_position(self.skeleton, chunk[-1])
            out += self._wrap(encoder.code(chunk), ts)
            self.in_group += take
            self.recent = np.vstack((self.recent, chunk))[-self.primer_frames :]
            if self.in_group == self.keyframe_every:
                out += self._wrap(encoder.finish(), ts)
                self.ended, self.encoder = encoder, None
        return out

    def close(self, timestamp_us: int | None = None) -> list[Packet]:
        """The stream's last packets (the last one flagged END)."""
        ts = now_us() if timestamp_us is None else timestamp_us
        out = self._wrap(self.encoder.finish(), ts) if self.encoder is not None else []
        self.encoder = None
        if out:
            out[-1] = out[-1].with_payload(out[-1].payload, out[-1].flags | END)
        else:
            out = [self._packet(b"", 0, ts, END)]
        return out

    def _start(self) -> StreamEncoder:
        """A new codec stream (at a keyframe): its encoder, primed with the recent frames."""
        encoder = self.encoder = self.codec.encoder(self.skeleton, self.fps)
        if len(self.recent):
            encoder.prime(self.recent)
        if self.ended is not None:
            encoder.follow(self.ended)
        self.in_group = 0
        self.keyframe_due = True
        return encoder

    def _wrap(self, coded: list[Coded], ts: int) -> list[Packet]:
        """Packets of what the codec stream coded: the first of a codec stream a keyframe, one
        where its base restarts flagged so, and a cut table where a relay may cut."""
        out = []
        for c in coded:
            flags = KEYFRAME if self.keyframe_due else (RESTART if c.restart else 0)
            payload = c.payload
            if self.cuttable:
                payload, flags = with_cut_table(payload, c.cuts), flags | CUTS
            out.append(self._packet(payload, c.frames, ts, flags))
            self.keyframe_due = False
        return out

    def _packet(self, payload: bytes, frames: int, ts: int, flags: int) -> Packet:
        sends = (
            bool(flags & (KEYFRAME | RESTART))
            or self.sent_position is None
            or math.dist(self.position, self.sent_position) >= POSITION_STEP_M
        )
        if sends:
            self.sent_position = self.position
        p = Packet(
            self.stream,
            self.sequence,
            ts,
            self.codec.id,
            self.out_frames,
            frames,
            payload,
            DATA,
            flags,
            self.position if sends else (self.sent_position or self.position),
            compact=self.compact,
            sends_position=sends,
            usual_frames=self.usual_frames,
        )
        self.sequence = (self.sequence + 1) & 0xFFFFFFFF
        self.out_frames += frames
        return p


@dataclass
class ReceiverStats:
    packets: int = 0
    lost: int = 0  # packets missing from the sequence
    dropped: int = 0  # received but not decodable (waiting for a keyframe, damaged)
    concealed_frames: int = 0
    resyncs: int = 0
    repaired: int = 0  # missing packets that came later (resent), and were decoded in order


class LiveDecoder:
    """Packets in, frames out, for one stream. Never raises on a bad or missing packet: it
    conceals (``hold`` the last frame, or ``extrapolate`` the velocity of the last few frames
    for a quarter second, then hold) until the next keyframe. The stream header is checked
    when the decoder is made (CorruptStreamError for one no codec can be made of; a knob naming
    a local file is the caller's ``local_files`` entry, never the header's).

    With ``hold_s`` > 0 a decoder in step that sees a gap in the sequence first waits for the
    missing packets (:meth:`wanted`: a relay resends them on request, docs/streaming.md): it
    holds the packets after the gap, up to ``hold_s`` of frames past the last frame out, and
    decodes them in order up to the next gap as each gap is filled, so nothing is concealed
    and the decoder stays in step. Past ``hold_s``, or at a keyframe or restart point after
    the gap, it gives the gap up and goes on as without it."""

    def __init__(self, info: StreamInfo, conceal: str = "hold", local_files: dict | None = None, hold_s: float = 0.0):
        if conceal not in ("hold", "extrapolate"):
            raise CodecError(f"concealment must be hold or extrapolate, got {conceal!r}")
        if not (0.0 <= hold_s <= MAX_CONCEAL_S):
            raise CodecError(f"hold_s must be 0 to {MAX_CONCEAL_S:g} seconds, got {hold_s!r}")
        self.hold_frames = int(math.ceil(hold_s * info.fps))
        self.missing: set[int] = set()  # sequence numbers of a gap being waited for
        self.held: dict[int, Packet] = {}  # the packets after it
        self.info = info
        self.codec = info.stream_codec(local_files)
        self.max_gap = max(min(int(MAX_CONCEAL_S * info.fps), MAX_CONCEAL_VALUES // info.skeleton.num_channels), 1)
        self.conceal = conceal
        self.decoder: StreamDecoder | None = None
        self.resyncs: bool | None = None  # the codec's decoders find their way into a stream under way
        self.expected: int | None = None  # next sequence number
        self.next_frame: int | None = None  # next frame number to output
        self.tail = np.zeros((0, info.skeleton.num_channels))  # the last frames out
        self.stats = ReceiverStats()
        self.ended = False

    @property
    def in_sync(self) -> bool:
        return self.decoder is not None and self.decoder.in_step

    def wanted(self) -> list[int]:
        """The sequence numbers of the packets this decoder waits for (``hold_s``), oldest first."""
        return sorted(self.missing, key=self._ahead)

    def _ahead(self, sequence: int) -> int:
        return (sequence - (self.expected or 0)) & 0xFFFFFFFF

    def push(self, packet: Packet) -> np.ndarray:
        """The frames up to the end of this packet's range: decoded, or concealed (none for
        a gap over :data:`MAX_CONCEAL_S`); with ``hold_s``, none while it waits for a gap
        before this packet, and then every frame held."""
        if not self.hold_frames or packet.kind != DATA or self.expected is None:
            return self._push_safely(packet)
        ahead = self._ahead(packet.sequence)
        if ahead >= 1 << 31 and packet.sequence not in self.missing:
            return self._push_safely(packet)  # old or repeated: dropped there
        if not self.missing:
            if ahead == 0 or ahead > MAX_MISSING or not self.in_sync:
                return self._push_safely(packet)
            self.missing = {(self.expected + k) & 0xFFFFFFFF for k in range(ahead)}
        elif packet.sequence in self.missing:
            self.missing.discard(packet.sequence)
            self.stats.repaired += 1
        elif packet.keyframe or packet.restart:  # decodable without the gap: wait no more
            self.held[packet.sequence] = packet
            return self._release()
        else:
            last = max(self.held, key=self._ahead)
            beyond = self._ahead(packet.sequence) - self._ahead(last)
            if beyond > 1:  # another gap behind the first
                self.missing |= {(last + k) & 0xFFFFFFFF for k in range(1, min(beyond, MAX_MISSING + 1))}
        self.held[packet.sequence] = packet
        out = [np.zeros((0, self.info.skeleton.num_channels))]
        while self.expected in self.held:  # the packets up to the next gap, once the first is filled
            out.append(self._push_safely(self.held.pop(self.expected)))
        if self.held:
            newest = max(self.held.values(), key=lambda p: self._ahead(p.sequence))
            late = newest.first_frame + newest.frames - (self.next_frame or 0) > self.hold_frames
            if late or len(self.held) > MAX_HELD or len(self.missing) > MAX_MISSING:
                out.append(self._release())
        return np.vstack(out)

    def _release(self) -> np.ndarray:
        """Every held packet in sequence order (the gaps left, if any, given up)."""
        held = sorted(self.held.values(), key=lambda p: self._ahead(p.sequence))
        self.held, self.missing = {}, set()
        out = [self._push_safely(p) for p in held]
        return np.vstack(out) if out else np.zeros((0, self.info.skeleton.num_channels))

    def _push_safely(self, packet: Packet) -> np.ndarray:
        try:
            return self._push(packet)
        except Exception:  # noqa: BLE001 - a hostile packet must not take the receiver down
            self.decoder = None
            self.stats.dropped += 1
            return np.zeros((0, self.info.skeleton.num_channels))

    def _push(self, packet: Packet) -> np.ndarray:
        empty = np.zeros((0, self.info.skeleton.num_channels))
        if packet.kind != DATA or packet.codec != self.codec.id:
            self.stats.dropped += 1
            return empty
        if self.expected is not None:
            ahead = (packet.sequence - self.expected) & 0xFFFFFFFF
            if ahead >= 1 << 31:  # old or repeated
                return empty
            if ahead:
                self.stats.lost += ahead
                if self.decoder is not None and not self.decoder.lost():
                    self.decoder = None
        self.expected = (packet.sequence + 1) & 0xFFFFFFFF
        self.stats.packets += 1
        self.ended = self.ended or packet.end
        if packet.keyframe:  # a new codec stream starts here
            self.stats.resyncs += self.decoder is None and self.next_frame is not None
            self.decoder = self.codec.decoder(self.info.skeleton, self.info.fps)
        elif self.decoder is None:
            self.decoder = self._resyncing_decoder()
            if self.decoder is None:
                self.stats.dropped += 1
                return self._concealed(packet.first_frame + packet.frames)
        head = self._concealed(packet.first_frame)
        try:
            payload = packet.codec_payload
            frames = self._decode(packet, payload) if payload or packet.frames else empty
            if len(frames) != packet.frames:
                raise CodecError(
                    f"packet {packet.sequence} decodes to {len(frames)} frames, its header says {packet.frames}"
                )
            if not np.isfinite(frames).all():
                raise CodecError(f"packet {packet.sequence} decodes to values that are not finite")
        except OutOfStepError:  # the codec finds its own way back: keep it, conceal meanwhile
            self.stats.dropped += 1
            if not len(self.tail):
                self.next_frame = None  # nothing out yet: start where the first decoded frame is
            return np.vstack((head, self._concealed(packet.first_frame + packet.frames)))
        except Exception:  # noqa: BLE001 - whatever a damaged payload does to a codec, conceal
            if not self.decoder.lost():
                self.decoder = None
            self.stats.dropped += 1
            return np.vstack((head, self._concealed(packet.first_frame + packet.frames)))
        if packet.end:
            self.decoder = None
        return np.vstack((head, self._emit(frames)))

    def _decode(self, packet: Packet, payload: bytes) -> np.ndarray:
        """The frames of a packet's codec ``payload``: of a layered stream's, those of the
        layers it carries (the relay may have cut some off); a cut packet of another stream is
        damaged."""
        assert self.decoder is not None
        if packet.dropped:
            if packet.dropped >= self.codec.layers:
                raise CodecError(
                    f"packet {packet.sequence}: {packet.dropped} layers cut off a stream of {self.codec.layers}"
                )
            return np.asarray(self.decoder.push_layers(payload, self.codec.layers - packet.dropped), dtype=np.float64)
        return np.asarray(self.decoder.push(payload), dtype=np.float64)

    def _resyncing_decoder(self) -> StreamDecoder | None:
        """A decoder that finds its way into a codec stream already under way (one whose
        codec restarts parts of itself), or None: wait for a keyframe."""
        if self.resyncs is False:
            return None
        decoder = self.codec.decoder(self.info.skeleton, self.info.fps)
        resyncs = decoder.lost()
        self.resyncs = resyncs
        return decoder if resyncs else None

    def _emit(self, frames: np.ndarray) -> np.ndarray:
        if self.next_frame is None:
            self.next_frame = 0
        self.next_frame += len(frames)
        if len(frames):
            self.tail = np.vstack((self.tail, frames))[-VELOCITY_FRAMES:]
        return frames

    def _concealed(self, upto: int) -> np.ndarray:
        """Concealed frames from the next one to frame ``upto`` (nothing before the first
        decoded frame: there is nothing to hold)."""
        n_ch = self.info.skeleton.num_channels
        if self.next_frame is None or not len(self.tail) or upto <= self.next_frame:
            if self.next_frame is None and upto > 0 and self.decoder is not None:
                self.next_frame = upto  # joined mid-stream: start at the keyframe
            return np.zeros((0, n_ch))
        n = upto - self.next_frame
        if n > self.max_gap:  # too far ahead to fill: count on from there
            self.next_frame = upto
            return np.zeros((0, n_ch))
        last = self.tail[-1]
        out = np.repeat(last[None], n, axis=0)
        if self.conceal == "extrapolate" and len(self.tail) == VELOCITY_FRAMES:
            steps = np.minimum(np.arange(1, n + 1), int(EXTRAPOLATE_S * self.info.fps))
            velocity = (self.tail[-1] - self.tail[0]) / (VELOCITY_FRAMES - 1)  # smooths coding noise
            out = last + steps[:, None] * velocity
        self.stats.concealed_frames += n
        return self._emit(out)


def clip_encoder(motion: Motion, codec: Codec, stream: int = 0, keyframe_s: float = 1.0, name: str = "") -> LiveEncoder:
    """The live encoder of a clip played as a stream, primed with the clip's first second."""
    return LiveEncoder(
        codec,
        motion.skeleton,
        motion.fps,
        stream,
        keyframe_s,
        name,
        primer=motion.channels[: int(round(PRIMER_S * motion.fps))],
    )


def stream_clip(
    motion: Motion, codec: Codec, stream: int = 0, keyframe_s: float = 1.0, frames_per_packet: int | None = None
) -> list[Packet]:
    """A clip as the live packets a sender would send (header first), pushing
    ``frames_per_packet`` frames at a time (default: a 30 Hz tick), primed with its first
    second."""
    enc = clip_encoder(motion, codec, stream, keyframe_s)
    step = frames_per_packet or tick_frames(motion.fps)
    packets = [enc.header(0)]
    for a in range(0, motion.num_frames, step):
        packets += enc.push(motion.channels[a : a + step], timestamp_us=int(a * 1e6 / motion.fps))
    return packets + enc.close(timestamp_us=int(motion.num_frames * 1e6 / motion.fps))


def receive_clip(packets: list[Packet], conceal: str = "hold") -> Motion:
    """The motion a receiver gets from ``packets`` (a stream header first)."""
    if not packets or packets[0].kind != HEADER:
        raise CodecError("a stream starts with its header packet")
    info = StreamInfo.from_payload(packets[0].payload)
    dec = LiveDecoder(info, conceal)
    out = [dec.push(p) for p in packets[1:]]
    channels = np.vstack(out) if out else np.zeros((0, info.skeleton.num_channels))
    return Motion(info.skeleton, info.fps, channels)
