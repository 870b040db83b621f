"""``svq``: spatial vector quantisation (000 §7.9.1).

Each frame, the channels of every body-part group (Table 5-1; the root's translation a group of
its own), in degrees or centimetres, form a vector replaced by the index of its nearest entry
in the group's LBG codebook of ``size`` entries (the thesis: 32-256). On a skeleton with
fingers the hand groups are the thesis's hand-gesture case. ``predictive`` (the default) codes
each group's change from its last decoded frame in a closed loop; without it the posture
itself is quantised, as the thesis did (whose PSNR was a few dB: a few hundred postures cannot
cover a body's). Indices are sorted by training use and range coded per group.

The codebook is ``codebook`` = a file made by ``mocodec model train codebook --vectors spatial`` on clips
with the same channel layout (encoder and decoder load the same file; the body names it by
fingerprint), or, by default, trained on the first frames coded and sent in the header as
float16 (self-contained, but the header costs ``size`` x channels x 2 bytes). No delay.
"""

from __future__ import annotations

import numpy as np

from mocodec.codecs.base import Knob, QualityKnob
from mocodec.codecs.registry import register
from mocodec.codecs.shared import vqbook
from mocodec.codecs.waveform.framewise import FramewiseCodec
from mocodec.coding.quantisation import vq


class _State:
    def __init__(
        self, books: list[np.ndarray], groups: list[np.ndarray], first: np.ndarray, units: np.ndarray, predictive: bool
    ):
        self.units, self.predictive = units, predictive
        self.columns = np.concatenate(groups).astype(np.int64)
        self.starts = np.concatenate([[0], np.cumsum([len(g) for g in groups])]).astype(np.int64)
        self.book_starts = np.concatenate([[0], np.cumsum([len(b) for b in books])]).astype(np.int64)
        self.entries = np.array([len(b) for b in books])
        self.books = np.zeros((self.book_starts[-1], max(len(g) for g in groups)))
        for b, a in zip(books, self.book_starts):
            self.books[a : a + len(b), : b.shape[1]] = b
        self.prev = first.copy()

    def run(self, x: np.ndarray, codes: np.ndarray, decode: bool) -> np.ndarray:
        return vq.run_spatial(
            x, codes, decode, self.predictive, self.prev, self.columns, self.starts, self.books, self.book_starts
        )


@register
class SvqCodec(FramewiseCodec):
    id = "svq"
    description = "spatial vector quantisation: one vector per body-part group and frame, LBG codebooks"
    knobs = (
        Knob("size", int, 32, "entries of each group's codebook (the thesis: 16-512)", low=2, high=4096),
        Knob("predictive", bool, True, "code each group's change from its last decoded frame"),
        vqbook.CODEBOOK_KNOB,
    )
    quality = QualityKnob("size", higher_is_better=True, log_scale=True)

    def _setup(self, values, skeleton, fps):
        cfg = self.config
        units = vqbook.channel_units(skeleton)
        x = values * units
        groups = [cols for _, cols in vqbook.spatial_groups(skeleton)]
        if cfg["codebook"]:
            books, source = vqbook.shared_books(cfg["codebook"], "spatial", cfg["predictive"], 1, cfg["size"], skeleton)
        else:
            books = []
            for cols in groups:
                vectors = vqbook.spatial_vectors(x, cols, cfg["predictive"])
                vectors = vectors if len(vectors) else np.zeros((1, cols.size))
                books.append(vq.lbg(vectors, [cfg["size"]])[cfg["size"]])
            books, source = vqbook.inband_books(books)
        header, first = vqbook.pack_header(source, x)
        return header, _State(books, groups, first, units, cfg["predictive"])

    def _load(self, header, skeleton, fps):
        groups = [cols for _, cols in vqbook.spatial_groups(skeleton)]
        books, first = vqbook.read_header(
            header, [len(g) for g in groups], self.config["codebook"], skeleton, "svq header"
        )
        return _State(books, groups, first, vqbook.channel_units(skeleton), self.config["predictive"])

    def _code(self, state, frames, ahead):
        codes = np.zeros((len(frames), len(state.entries)), dtype=np.int64)
        if len(frames):
            state.run(np.ascontiguousarray(frames * state.units), codes, False)
        return [codes], frames

    def _uncode(self, state, n, read, last):
        codes = np.clip(read(n, len(state.entries)), 0, state.entries - 1)
        return state.run(np.zeros((0, state.units.size)), codes, True) / state.units
