"""kinwave-live's stream encoder: each packet's layers coded closed loop down the tree at the
cheapest stride and scale that hold their bounds on every frame (checked on the decoding), and
where each layer ends in the packet, read back from its arithmetic code (:func:`layer_ends`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mocodec.codecs.base import Coded, StreamEncoder, continuous_frames
from mocodec.codecs.kinwave.live.predict import Cells, Layer, advance, fill, predict_tree, stream_layers
from mocodec.codecs.kinwave.live.syntax import (
    DRIFT,
    MAX_OFFSET,
    code_layer,
    code_restarts,
    coder_buffer,
    finish,
    layer_ends,
    packet_frames,
    strides,
)
from mocodec.codecs.shared import closedloop
from mocodec.coding.entropy import binarycoder as bc
from mocodec.errors import CodecError
from mocodec.kinematics import forward_kinematics
from mocodec.metrics.pose import worst_error
from mocodec.skeleton import Skeleton

if TYPE_CHECKING:
    from mocodec.codecs.kinwave.live.codec import KinwaveLiveCodec


MAX_RETRIES = 12  # codings of one packet, each 1/2 octave finer, before it is refused
SPARSE_RETRIES = 3  # ... at a stride above 1, before that stride is given up
FINER = 4  # 1/8 octaves a packet over its bound goes finer at each retry
COARSER_BELOW = 0.9  # a packet under this share of the bound lets the next start a code coarser
STILL_CM = 1e-3  # a translation that moves less than this in a packet stands still


class LiveEncoder(StreamEncoder):
    def __init__(self, codec: KinwaveLiveCodec, skeleton: Skeleton, fps: float):
        self.codec, self.skeleton, self.fps = codec, skeleton, fps
        self.layers = stream_layers(codec, skeleton)
        self.bounds = codec.layer_bounds
        self.size = packet_frames(fps)
        self.pending = np.zeros((0, skeleton.num_channels))
        self.previous: np.ndarray | None = None  # the last continuous frame
        self.offsets = [0] * len(self.layers)  # where each layer's next packet starts
        self.cm = 100.0 / skeleton.units_per_metre
        self.period, self.phases = codec.restart_frames(fps)
        self.frame = 0  # the first frame of the next packet
        self.last_values: np.ndarray | None = None  # the last packet's last original frame
        self.cut = len(self.layers) > 1  # a relay may cut its packets by layers

    def follow(self, previous: StreamEncoder) -> None:
        """Each layer's scale offset goes on from where the last stream left it (a restart codes
        it in full), rather than finding its way back from the allocation's a packet at a time."""
        if isinstance(previous, LiveEncoder) and len(previous.offsets) == len(self.offsets):
            self.offsets = list(previous.offsets)

    def code(self, frames: np.ndarray) -> list[Coded]:
        cont = continuous_frames(self.codec.id, self.skeleton, self.fps, frames, self.previous)
        if len(cont):
            self.previous = cont[-1]
            self.pending = np.vstack((self.pending, cont))
        out = []
        while len(self.pending) >= self.size:
            out.append(self._packet(self.pending[: self.size]))
            self.pending = self.pending[self.size :]
        return out

    def finish(self) -> list[Coded]:
        if not len(self.pending):
            return []
        packet = self._packet(self.pending)
        self.pending = self.pending[:0]
        return [packet]

    def _code(self, layer: Layer, values, goal, retarget, offset: int, stride: int, cells: Cells):
        """The integers, decoded coded frames and cells of one layer of a packet at ``offset``
        and ``stride`` (every ``stride``-th frame coded, down the tree), and all its decoded
        frames; ``goal`` is the packet's original positions and orientations (forward
        kinematics, once), ``retarget`` the channels the closed loop sets (:meth:`_retarget`)."""
        steps = layer.steps(offset)
        order = layer.orders()
        coded = np.ascontiguousarray(values[stride - 1 :: stride])
        ints = np.zeros(coded.shape, dtype=np.int64)
        decoded, cell_lo, cell_hi = np.zeros(coded.shape), np.zeros(coded.shape), np.zeros(coded.shape)
        lo, hi = cells.at(stride)
        pos, quats = (np.ascontiguousarray(g[stride - 1 :: stride]) for g in goal)

        history, trust = np.ascontiguousarray(layer.history), np.ascontiguousarray(layer.trust)
        lo, hi = np.ascontiguousarray(lo), np.ascontiguousarray(hi)
        loop = closedloop.tree_loop(self.skeleton, coded, retarget, quats, True, pos)
        predict_tree(
            loop, history, layer.count_history, layer.gap, stride, steps, order, trust, lo, hi, ints, decoded,
            cell_lo, cell_hi,
        )  # fmt: skip
        return ints, decoded, (cell_lo, cell_hi), fill(layer.history[1], decoded, stride)

    def _error(self, goal: tuple[np.ndarray, np.ndarray], decoded: np.ndarray) -> float:
        p0, q0 = goal
        p1, q1 = forward_kinematics(self.skeleton, decoded)
        return worst_error(self.skeleton, p0 * self.cm, q0, p1 * self.cm, q1, self.codec.config["error_measure"])

    def _fit(self, k: int, values, goal, retarget, stride: int, retries: int, cells: Cells):
        """(integers, coded frames, cells, offset, worst error) of layer ``k`` of the packet at
        ``stride``, from the layer's current offset and finer until its bound holds, or None."""
        offset = self.offsets[k]
        for tried in range(retries if stride > 1 else MAX_OFFSET):
            ints, coded, coded_cells, frames = self._code(self.layers[k], values, goal, retarget, offset, stride, cells)
            worst = self._error(goal, frames)
            if worst <= self.bounds[k]:
                return ints, coded, coded_cells, offset, worst
            if offset <= -MAX_OFFSET:
                return None
            # 1/2 octave finer a try; past ``retries`` (a scale that quiet motion let drift far
            # coarser), twice as far each time
            offset = max(offset - FINER * 2 ** max(tried + 1 - retries, 0), -MAX_OFFSET)
        return None

    def _trial_size(self, layer: Layer, ints: np.ndarray, frames: int, change: int, stride: int) -> int:
        """The bytes layer ``layer``'s part of a packet would take coded on its own (its
        contexts left as they are): what a stride is chosen by."""
        buf, st = coder_buffer([(layer, ints)]), bc.encoder_state()
        state, last = layer.state.copy(), layer.last_nonzero.copy()
        code_layer(st, buf, ints, frames, self.size, change, stride, layer.first, layer.count, state, last)
        return int(finish(st, buf))

    def _retarget(self, values: np.ndarray) -> np.ndarray:
        """The channels whose targets the closed loop sets: every one but the translations below
        the root that stand still through this packet (and since the last). A translation the
        motion moves (the body's root under a dummy root) restores its joint's position from its
        parent's decoded one; one that stands still (a MotionBuilder export's six channels on
        every joint repeat the offsets) is coded as it is, nearly for free, rather than made to
        carry its parents' quantisation errors in every frame."""
        since = values[0] if self.last_values is None else self.last_values
        moved = np.abs(values - since).max(axis=0) > STILL_CM / self.cm
        return ~self.layers[0].shifts | moved

    def _packet(self, values: np.ndarray) -> Coded:
        """One packet of every layer, with where each layer but the top one ends in it (read
        back from the arithmetic code, :func:`layer_ends`) and whether the base restarts."""
        goal = forward_kinematics(self.skeleton, values)
        retarget = self._retarget(values)
        cells = Cells(len(values), values.shape[1])
        restarts = [self._restart_flag(k, len(values)) for k in range(len(self.layers))]
        coded = [self._layer_packet(k, values, goal, retarget, cells, restarts[k]) for k in range(len(self.layers))]
        self.frame += len(values)
        self.last_values = values[-1]
        contexts = [(layer.state.copy(), layer.last_nonzero.copy()) for layer in self.layers] if self.cut else []
        buf, st = coder_buffer([(layer, ints) for layer, (ints, *_) in zip(self.layers, coded)]), bc.encoder_state()
        if self.period:
            code_restarts(st, buf, np.array(restarts, dtype=np.int64))
        for layer, (ints, change, stride) in zip(self.layers, coded):
            first, count, state, last = layer.first, layer.count, layer.state, layer.last_nonzero
            code_layer(st, buf, ints, len(values), self.size, change, stride, first, count, state, last)
        payload = buf[1 : finish(st, buf)].tobytes()  # the first byte is always 0
        ends = layer_ends(payload, self.layers, contexts, self.size, bool(self.period))[:-1] if self.cut else []
        return Coded(payload, len(values), tuple(ends), bool(restarts[0]))

    def _restart_flag(self, k: int, frames: int) -> int:
        """1 if layer ``k`` restarts in the packet of ``frames`` frames starting at
        ``self.frame`` (never without refresh, nor in the stream's first: every layer starts
        there), else 0."""
        if not self.period:
            return 0
        first = (self.phases[k] - self.frame) % self.period  # the packet's first restart frame
        return int(self.frame > 0 and first < frames)

    def _layer_packet(self, k: int, values: np.ndarray, goal, retarget, cells: Cells, restart: int):
        """Layer ``k`` of a packet, (integers, scale offset change, stride) to code: the
        cheapest stride that holds its bound on every frame, predicted within the cells of the
        layers below; the cells become its own. A layer that restarts here starts again from
        nothing: its history, contexts and scale offset."""
        layer = self.layers[k]
        if restart:
            layer.restart()
        sparse = layer.started and len(values) == self.size
        best = None
        for stride in strides(len(values)) if sparse else [1]:
            fit = self._fit(k, values, goal, retarget, stride, MAX_RETRIES if stride == 1 else SPARSE_RETRIES, cells)
            if fit is None:
                continue
            ints, coded, coded_cells, offset, worst = fit
            size = self._trial_size(layer, ints, len(values), offset - layer.offset, stride)
            if best is None or size < best[0]:
                best = (size, stride, ints, coded, coded_cells, offset, worst)
        if best is None:
            raise CodecError(f"kinwave-live cannot hold {self.bounds[k]:g} cm on a packet")
        _, stride, ints, coded, coded_cells, offset, worst = best
        self.offsets[k] = min(offset + DRIFT, MAX_OFFSET) if worst < COARSER_BELOW * self.bounds[k] else offset
        change = offset - layer.offset
        advance(layer, coded, stride, offset, cells)
        cells.update(stride, *coded_cells)
        return ints, change, stride
