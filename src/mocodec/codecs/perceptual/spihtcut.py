"""Cutting ``spiht`` data to a lower rate without decoding it: a body's every channel stream
kept to the prefix its smaller budget allows (a file truncated, :func:`truncator`), and a
stream packet the same way for each viewer of a relay (:func:`packet_cutter`, from the cut
table the sender works out once, :func:`packet_cuts`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mocodec import perception
from mocodec.codecs.perceptual.spihtlayout import (
    F_LEVELS,
    N0_BITS,
    PACKET,
    U32,
    level_weights,
    packet_total,
)
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CorruptStreamError
from mocodec.skeleton import Skeleton

if TYPE_CHECKING:
    from mocodec.codecs.perceptual.spiht import SpihtCodec


def truncator(codec: SpihtCodec, body: bytes, skeleton: Skeleton, frames: int, fps: float):
    """A function bits_per_second -> (the codec of that rate, the body cut to it, without
    re-encoding: every segment budget shrinks by bits_per_second / the codec's rate, and
    every channel stream keeps the prefix its new budget allows). The streams are
    decoded once to find where each ends, so a rate search cuts many times cheaply."""
    if frames == 0:
        return lambda bps: (codec.smaller(bps), body)
    parts, _, levels_f, totals, bits = codec.parse_body(body, skeleton, frames)
    n_ch = skeleton.num_channels
    streams = [(k, c, start, used) for k, c, start, used, _, _ in codec.walk_streams(levels_f, totals, bits, n_ch)]
    rate_coded = np.array_equal(totals, codec.segment_budgets(frames, fps))

    def cut(bits_per_second: float) -> tuple[SpihtCodec, bytes]:
        smaller = codec.smaller(bits_per_second)
        if rate_coded:
            new_totals = smaller.segment_budgets(frames, fps)  # as if encoded at the new rate
        else:  # explicit (crowd) budgets scale
            new_totals = np.floor(totals * (bits_per_second / codec.config["bits_per_second"])).astype(np.int64)
        budgets = [
            perception.allocate(level_weights(levels_f[k * n_ch : (k + 1) * n_ch]), int(t))
            for k, t in enumerate(new_totals)
        ]
        keep = [
            bits[start : start + min(used, int(budgets[k][c]))]
            for k, c, start, used in streams
            if budgets[k][c] > N0_BITS
        ]
        new_bits = np.concatenate(keep) if keep else np.zeros(0, dtype=np.uint8)
        new_parts = [
            parts[0],
            parts[1],
            encode_ints(np.diff(new_totals, prepend=0)),
            U32.pack(new_bits.size) + np.packbits(new_bits).tobytes(),
        ]
        return smaller, join_parts(new_parts)

    return cut


def packet_cuts(codec: SpihtCodec, packet: bytes, skeleton: Skeleton) -> np.ndarray:
    """The bits each channel stream of a stream packet uses, in stream order: what
    :meth:`packet_cutter` needs to cut the packet without decoding it (a sender works it
    out once, a relay then cuts for every viewer)."""
    _, _, levels, total, bits = packet_fields(codec, packet, skeleton)
    return np.array(
        [used for _, _, used, _, _ in codec.segment_streams(levels, total, bits, 0, "the packet")], dtype=np.int64
    )


def packet_cutter(codec: SpihtCodec, packet: bytes, skeleton: Skeleton, cuts: np.ndarray, fps: float):
    """A function bits_per_second -> the packet cut to that rate (if below its own): every
    channel keeps the prefix of its embedded stream its new share allows, so it decodes to a
    coarser segment with no re-encoding, the same bytes as coding at that rate;
    the packet is parsed once, so cutting it for many viewers costs a few array operations
    each."""
    head, parts, levels, total, bits = packet_fields(codec, packet, skeleton)
    frames = PACKET.unpack_from(head)[1]
    weights = level_weights(levels)
    present = np.flatnonzero(perception.allocate(weights, total) > N0_BITS)
    if cuts.size != present.size or cuts.min(initial=0) < 0 or cuts.sum() != bits.size:
        raise CorruptStreamError("spiht packet: the cut table does not match the packet's streams")
    starts = np.cumsum(cuts) - cuts

    def cut(bits_per_second: float) -> bytes:
        total_bits = max(int(np.floor(bits_per_second * frames / fps)), 0)
        if total_bits >= total:
            return packet
        new = perception.allocate(weights, total_bits)[present]
        keep = np.where(new > N0_BITS, np.minimum(cuts, new), 0)
        # the kept prefixes, gathered in one indexing: work in proportion to what is kept
        kept = bits[np.arange(keep.sum()) + np.repeat(starts - (np.cumsum(keep) - keep), keep)]
        return head + join_parts([*parts[:-2], U32.pack(total_bits), U32.pack(kept.size) + np.packbits(kept).tobytes()])

    return cut


def packet_fields(codec: SpihtCodec, packet: bytes, skeleton: Skeleton):
    """(packet header bytes, parts, levels, segment budget, bits) of a stream packet."""
    if len(packet) < PACKET.size:
        raise CorruptStreamError(f"spiht packet of {len(packet)} bytes is shorter than its header")
    parts = split_parts(packet, None, "spiht packet", start=PACKET.size)
    if len(parts) not in (4, 5):
        raise CorruptStreamError(f"spiht packet: {len(parts)} parts, expected 4 or 5")
    levels = decode_ints(parts[-3])
    total = packet_total(parts[-2])
    if len(parts[-1]) < U32.size:
        raise CorruptStreamError(
            f"spiht packet: its bit stream part is {len(parts[-1])} bytes, shorter than its 4-byte length"
        )
    (n_bits,) = U32.unpack_from(parts[-1])
    bits = np.unpackbits(np.frombuffer(parts[-1], dtype=np.uint8, offset=4))[:n_bits]
    if (
        levels.size != skeleton.num_channels
        or bits.size != n_bits
        or levels.min(initial=0) < 0
        or levels.max(initial=0) >= F_LEVELS
    ):
        raise CorruptStreamError("spiht packet: levels or bits do not fit the skeleton")
    return packet[: PACKET.size], parts, levels, int(total), bits
