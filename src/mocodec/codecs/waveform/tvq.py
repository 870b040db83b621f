"""``tvq``: temporal vector quantisation (000 §7.9.2).

Each channel's samples, in degrees or centimetres, are cut into vectors of ``length`` = 6
(180 ms at 30 Hz, the thesis's choice); each vector is replaced by the index of its nearest
entry in an LBG codebook of ``size`` entries (the thesis: up to 256), shared by all channels.
``predictive`` (the default) codes each vector minus the channel's last decoded sample in a
closed loop, so one codebook of motion *shapes* serves every channel and level; without it the
vectors themselves are quantised, as the thesis did (its PSNR stays low: a codebook of 256
absolute 6-sample vectors cannot cover every channel's range). Indices are sorted by training
use and range coded per channel.

The codebook is ``codebook`` = a file made by ``mocodec model train codebook --vectors temporal``
(trained on other clips; encoder and decoder load the same file, the body names it by
fingerprint), or, by default, trained on the first frames coded and sent in the header as
float16 (self-contained, but the header costs ``size`` x ``length`` x 2 bytes). Delay:
``length`` - 1 frames.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.shared import vqbook
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation import vq
from mocodec.coding.transforms import blocks


class _State:
    def __init__(self, book: np.ndarray, first: np.ndarray, units: np.ndarray, predictive: bool):
        self.book, self.units, self.predictive = np.ascontiguousarray(book), units, predictive
        self.prev = first.copy()


@register
class TvqCodec(FramewiseCodec):
    id = "tvq"
    description = "temporal vector quantisation: 6-sample vectors per DOF, LBG codebook"
    knobs = (
        Knob("size", int, 256, "codebook entries (the thesis: 16-512)", low=2, high=4096),
        Knob("length", int, 6, "samples per vector (the coding delay + 1)", low=2, high=64),
        Knob("predictive", bool, True, "code each vector minus the channel's last decoded sample"),
        vqbook.CODEBOOK_KNOB,
    )
    quality = QualityKnob("size", higher_is_better=True, log_scale=True)

    def delay_frames(self) -> int:
        return self.config["length"] - 1

    def _ready(self, pending: int) -> int:
        return pending - pending % self.config["length"]

    def _setup(self, values, skeleton, fps):
        cfg = self.config
        units = vqbook.channel_units(skeleton)
        x = values * units
        if cfg["codebook"]:
            books, source = vqbook.shared_books(
                cfg["codebook"], "temporal", cfg["predictive"], cfg["length"], cfg["size"], skeleton
            )
        else:
            vectors = vqbook.temporal_vectors(x, cfg["length"], cfg["predictive"])
            if not len(vectors):
                vectors = np.zeros((1, cfg["length"]))
            books, source = vqbook.inband_books([vq.lbg(vectors, [cfg["size"]])[cfg["size"]]])
        header, first = vqbook.pack_header(source, x)
        return header, _State(books[0], first, units, cfg["predictive"])

    def _load(self, header, skeleton, fps):
        books, first = vqbook.read_header(
            header, [self.config["length"]], self.config["codebook"], skeleton, "tvq header"
        )
        return _State(books[0], first, vqbook.channel_units(skeleton), self.config["predictive"])

    def _code(self, state, frames, ahead):
        x = blocks.split(frames * state.units, self.config["length"])
        codes = np.zeros((len(x), x.shape[2]), dtype=np.int64)
        if len(frames):
            vq.run_temporal(x, codes, False, state.predictive, state.prev, state.book)
        return [codes], frames

    def _uncode(self, state, n, read, last):
        length, k = self.config["length"], state.units.size
        codes = np.clip(read(-(-n // length), k), 0, len(state.book) - 1)
        out = vq.run_temporal(np.zeros((0, length, k)), codes, True, state.predictive, state.prev, state.book)
        return out.reshape(-1, k)[:n] / state.units
