"""kinwave-live's stream decoder: every layer a packet carries that it is in step with, and
where each ends (a relay's cut points)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mocodec.codecs.base import StreamDecoder
from mocodec.codecs.kinwave.live.predict import Cells, Layer, advance, fill, reconstruct, stream_layers
from mocodec.codecs.kinwave.live.syntax import (
    MAX_OFFSET,
    decode_head,
    decode_ints,
    packet_data,
    packet_frames,
    prefix_end,
    read_restarts,
)
from mocodec.coding.entropy import binarycoder as bc
from mocodec.errors import CorruptStreamError, OutOfStepError
from mocodec.skeleton import Skeleton

if TYPE_CHECKING:
    from mocodec.codecs.kinwave.live.codec import KinwaveLiveCodec


class LiveDecoder(StreamDecoder):
    """Decodes every layer a packet carries that it is in step with: a layer the packet lacks
    (a relay dropped it) or that followed a loss is out of step until it restarts (a packet
    whose head says so, with ``refresh_s``, or the next codec stream), and so are the
    layers above it, whose predictions lean on it."""

    def __init__(self, codec: KinwaveLiveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton = codec, skeleton
        self.layers = stream_layers(codec, skeleton)
        self.layer_in_step = [True] * len(self.layers)
        self.refresh = bool(codec.config["refresh_s"])
        self.size = packet_frames(fps)
        self.data = packet_data(b"")  # the last packet, and where the decoder stood after each layer of it
        self.read: list[tuple[int, int]] = []

    @property
    def in_step(self) -> bool:
        return self.layer_in_step[0]

    @property
    def layers_in_step(self) -> int:
        """How many layers the next packet can decode (those below an out-of-step one)."""
        return self.layer_in_step.index(False) if False in self.layer_in_step else len(self.layers)

    def lost(self) -> bool:
        self.layer_in_step = [False] * len(self.layers)
        return self.refresh

    def push_layers(self, packet: bytes, layers: int) -> np.ndarray:
        """The frames of ``packet``, which carries its stream's ``layers`` lowest layers (a
        relay's cut is said by the packet's frame, :attr:`mocodec.stream.packets.Packet.dropped`)."""
        return self.push(packet, layers)

    def push(self, packet: bytes, layers: int | None = None) -> np.ndarray:
        """The frames of ``packet``, which carries its stream's ``layers`` lowest layers (None: all)."""
        count = len(self.layers) if layers is None else layers
        if not 1 <= count <= len(self.layers):
            raise CorruptStreamError(f"kinwave-live packet: {count} layers of a stream of {len(self.layers)}")
        data = packet_data(packet)
        st = bc.start_decoder(data)
        restarts = (
            read_restarts(st, data, len(self.layers)) if self.refresh else np.zeros(len(self.layers), dtype=np.int64)
        )
        self.data, self.read = data, []
        cells = out = None
        below = True  # every layer below this one decoded this packet
        for k in range(len(self.layers)):
            if below and k < count and restarts[k]:
                self.layers[k].restart()
                self.layer_in_step[k] = True
            below = below and k < count and self.layer_in_step[k]
            if not below:
                self.layer_in_step[k] = False
                continue
            try:
                out, cells = self._layer(self.layers[k], st, data, cells)
            except CorruptStreamError:
                self.layer_in_step[k:] = [False] * (len(self.layers) - k)
                raise
            self.read.append((int(st[2]), int(st[0])))
        if out is None:
            raise OutOfStepError("kinwave-live: waiting for the base layer to restart")
        return out

    @property
    def layer_ends(self) -> list[int]:
        """Where each layer the last packet pushed decoded ends in it: the shortest prefix that
        decodes that layer and those below as the whole packet does (:func:`prefix_end`); the
        sender's cut table, by which a relay drops the top layers without decoding."""
        return [prefix_end(self.data, read, code) for read, code in self.read]

    def _layer(self, layer: Layer, st: np.ndarray, data: np.ndarray, cells: Cells | None):
        frames, change, stride = decode_head(st, data, self.size, layer.state)
        offset = layer.offset + change
        if not (
            1 <= frames <= self.size
            and abs(offset) <= MAX_OFFSET
            and 1 <= stride <= frames
            and frames % stride == 0
            and (stride == 1 or layer.started)
            and (cells is None or cells.lo.shape[0] == frames)
        ):
            raise CorruptStreamError(
                f"kinwave-live packet: {frames} frames at stride {stride} and scale offset "
                f"{offset} (the data is damaged)"
            )
        cells = cells or Cells(frames, self.skeleton.num_channels)
        coded_frames = frames // stride
        ints = np.zeros((coded_frames, self.skeleton.num_channels), dtype=np.int64)
        decode_ints(st, data, coded_frames, layer.first, layer.count, layer.state, layer.last_nonzero, ints)
        if np.abs(ints).max(initial=0) >= 1 << 40:
            raise CorruptStreamError("kinwave-live packet: an integer out of range (the data is damaged)")
        coded, cell_lo, cell_hi = reconstruct(layer, ints, offset, stride, cells)
        out = fill(layer.history[1], coded, stride)
        advance(layer, coded, stride, offset, cells)
        cells.update(stride, cell_lo, cell_hi)
        return out, cells
