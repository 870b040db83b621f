"""``deadreckoning``: threshold-driven updates of an extrapolated ghost model (000 §7.7).

The coder of :mod:`mocodec.coding.quantisation.deadreckon` on every channel (``measure=dof``, as the
thesis's results) or on groups (``measure=group``: a joint's rotation channels, and the root
translation, compared by the Euclidean norm of their errors, the "weighed mutual error" the
thesis suggests). The threshold is in degrees (cm for translations); an update sends each
channel's difference to the ghost quantised with a step of ``position_step`` thresholds and
its change of velocity with ``velocity_step`` thresholds per frame (and of acceleration with
``acceleration=True``, steps of ``velocity_step / 8`` thresholds per frame^2). Update flags
and values are range coded with adaptive models. Delay: 3 frames (the centred 7-sample fit).

:func:`update_intervals` gives the histogram of frames between updates (fig. 7-13).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation import deadreckon
from mocodec.coding.quantisation.predictive import ChannelParams
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton

MAX_INTERVAL = 64  # longer intervals share the histogram's last bin


class _State:
    """Both ends' ghost model: parameters, groups, and the ghost state."""

    def __init__(self, codec: DeadReckoningCodec, params: ChannelParams, skeleton: Skeleton):
        cfg = codec.config
        active = params.active
        groups = _groups(skeleton, active, cfg["measure"])
        self.params, self.active = params, active
        self.groups = np.concatenate(groups).astype(np.int64) if groups else np.zeros(0, dtype=np.int64)
        self.group_start = np.concatenate([[0], np.cumsum([len(g) for g in groups])]).astype(np.int64)
        cm = skeleton.units_per_metre / 100.0
        unit = np.where(skeleton.rotation_mask, 1.0, cm)[active]
        self.thr = cfg["threshold"] * unit
        self.pstep = self.thr * cfg["position_step"]
        self.vstep = self.thr * cfg["velocity_step"]
        self.astep = self.vstep / 8.0
        self.use_acc = cfg["acceleration"]
        self.base = params.centre[active].copy()
        self.vel = np.zeros(active.size)
        self.acc = np.zeros(active.size)
        self.age = np.zeros(len(groups), dtype=np.int64)
        self.hist = np.zeros(MAX_INTERVAL + 1, dtype=np.int64)
        self.past: np.ndarray | None = None  # the last 3 input frames (encoder)

    @property
    def columns(self) -> int:
        return 3 if self.use_acc else 2

    def run(self, x_ext, flags, values, decode):
        out = np.empty((len(flags), self.params.centre.size))
        out[:] = self.params.centre
        decoded, rows = deadreckon.run(
            x_ext,
            flags,
            values,
            decode,
            self.groups,
            self.group_start,
            self.thr,
            self.pstep,
            self.vstep,
            self.astep,
            self.use_acc,
            self.base,
            self.vel,
            self.acc,
            self.age,
            self.hist,
        )
        out[:, self.active] = decoded
        return out, rows


def _groups(skeleton: Skeleton, active: np.ndarray, measure: str) -> list[np.ndarray]:
    """Positions in ``active`` of each group's channels."""
    if measure == "dof":
        return [np.array([i]) for i in range(active.size)]
    position = {int(c): i for i, c in enumerate(active)}
    rot = skeleton.rotation_mask
    out = []
    for j, joint in enumerate(skeleton.joints):
        first = skeleton.channel_offsets[j]
        chans = range(first, first + len(joint.channels))
        for kind in (False, True):
            g = [position[c] for c in chans if c in position and rot[c] == kind]
            if g:
                out.append(np.array(g))
    return out


@register
class DeadReckoningCodec(FramewiseCodec):
    id = "deadreckoning"
    packet_number = 4
    description = "dead reckoning: a ghost model with threshold updates of quantised difference and velocity"
    knobs = (
        Knob(
            "threshold",
            float,
            0.5,
            "update threshold, degrees (cm for translations) (the thesis: 0.0125-16)",
            low=1e-4,
            high=360.0,
        ),
        Knob(
            "measure",
            str,
            "dof",
            "error measure: per channel, or per joint (norm of its channels' errors)",
            choices=("dof", "group"),
        ),
        Knob("acceleration", bool, False, "also send the acceleration in each update"),
        Knob(
            "position_step", float, 0.5, "quantiser step of the position difference, in thresholds", low=1e-3, high=10.0
        ),
        Knob(
            "velocity_step",
            float,
            0.125,
            "quantiser step of the velocity change, thresholds per frame",
            low=1e-4,
            high=10.0,
        ),
    )
    quality = QualityKnob("threshold", higher_is_better=False, log_scale=True)
    lookahead = deadreckon.HALF_WINDOW

    def _setup(self, values, skeleton, fps):
        constant = np.ptp(values, axis=0) <= 0
        params = ChannelParams(constant, values[0], np.ones(values.shape[1]), np.zeros(values.shape[1]))
        return params.pack(), _State(self, params, skeleton)

    def _load(self, header, skeleton, fps):
        return _State(self, ChannelParams.unpack(header, skeleton.num_channels), skeleton)

    def _code(self, state, frames, ahead):
        x = frames[:, state.active]
        future = ahead[:, state.active]
        if state.past is None:
            state.past = np.repeat(x[:1], deadreckon.HALF_WINDOW, axis=0)
        tail = np.vstack((x, future))
        pad = np.repeat(tail[-1:], deadreckon.HALF_WINDOW - len(future), axis=0)
        x_ext = np.ascontiguousarray(np.vstack((state.past, tail, pad)))
        state.past = np.vstack((state.past, x))[-deadreckon.HALF_WINDOW :]
        flags = np.zeros((len(x), len(state.group_start) - 1), dtype=np.int64)
        values = np.zeros((x.size, state.columns), dtype=np.int64)
        decoded, rows = state.run(x_ext, flags, values, False)
        return [flags, values[:rows]], decoded

    def _uncode(self, state, n, read, last):
        flags = read(n, len(state.group_start) - 1)
        sizes = np.diff(state.group_start)
        rows = int(((flags == 1) * sizes).sum())
        values = np.ascontiguousarray(read(rows, state.columns))
        decoded, _ = state.run(np.zeros((0, state.active.size)), np.ascontiguousarray(flags), values, True)
        return decoded


def update_intervals(codec: DeadReckoningCodec, motion: Motion) -> np.ndarray:
    """How many updates came 0, 1, ..., 64 or more frames after the previous one of their group
    (fig. 7-13), from coding ``motion``."""
    enc: Any = codec.encoder(motion.skeleton, motion.fps)  # a frame encoder, whose state keeps the histogram
    enc.push(motion.channels)
    enc.flush()
    return enc.state.hist.copy()
