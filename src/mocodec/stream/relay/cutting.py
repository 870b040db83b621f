"""Cutting a room's scalable streams to each viewer's budget: the tick's crowd (which streams
scale, where they are, their layers' rates), each viewer's shares of it (:mod:`mocodec.crowd`),
and the packets cut to them. An embedded (``spiht``) packet is cut to its share rounded down to
the ladder; a layered (``kinwave-live``) packet keeps the layers whose measured rate fits,
more only where a layer restarts. Cuts are made once a tick for every viewer that shares them."""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass
from itertools import repeat

import numpy as np

from mocodec.crowd import layers_within, on_ladder, viewer_shares
from mocodec.errors import MocodecError
from mocodec.stream.packets import truncated
from mocodec.stream.relay.rooms import Forward, Room, StreamState, Viewer

log = logging.getLogger("mocodec.relay")


@dataclass
class Crowd:
    """A tick's scalable streams (embedded or layered), worked out once for every viewer: each
    stream's row in ``where`` (its position) and in ``rates`` (the bit/s of its layers up to
    each, infinite past its own), and the tick's fresh layered packets, one per stream: their
    streams, rows, keyframe flags and their variants with 1, 2, ... layers (``variants[i *
    width + k - 1]``, and their lengths), and the tick's other fresh packets (``others``)."""

    row: dict[int, int]
    where: np.ndarray
    rates: np.ndarray
    layered: list[Forward]
    streams: list[int]
    rows: np.ndarray
    keyframes: np.ndarray
    width: int
    variants: list[bytes]
    lengths: np.ndarray
    together: set[int]
    others: list[Forward]


def crowd_of(room: Room, fresh: list[Forward]) -> Crowd:
    scalable = [k for k, s in room.streams.items() if s.embedded or s.layered]
    where = np.array([room.streams[k].position for k in scalable], dtype=np.float64).reshape(-1, 3)
    width = max((room.streams[k].layers for k in scalable), default=1)
    rates = np.full((len(scalable), width), np.inf)
    for i, k in enumerate(scalable):
        state = room.streams[k]
        rates[i, : state.layers] = state.layer_rates
    row = {k: i for i, k in enumerate(scalable)}
    count = Counter(f.packet.stream for f in fresh)  # a stream's packets keep their order: one by one
    alone = [f for f in fresh if count[f.packet.stream] < 2]
    layered = [f for f in alone if f.layer_ends is not None and f.packet.stream in row]
    streams = [f.packet.stream for f in layered]
    variants: list[bytes] = []
    for f in layered:
        own = layer_variants(f)
        variants += own + own[-1:] * (width - len(own))
    together = {id(f) for f in layered}
    return Crowd(
        row,
        where,
        rates,
        layered,
        streams,
        np.array([row[k] for k in streams], dtype=np.int64),
        np.array([f.packet.keyframe for f in layered], dtype=bool),
        width,
        variants,
        np.fromiter(map(len, variants), dtype="<u4", count=len(variants)),
        together,
        [f for f in fresh if id(f) not in together],
    )


def shares_of(crowd: Crowd, viewers: list[Viewer], min_distance: float) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """For every viewer with a budget (by id), its shares of the crowd's streams (6.4, 6.5) and
    the layers of each stream within its share (at least one), worked out for all at once."""
    streams = len(crowd.row)
    if not streams or not viewers:
        return {id(v): (np.zeros(streams), np.ones(streams, dtype=np.int64)) for v in viewers}
    cameras = np.array([v.camera for v in viewers], dtype=np.float64)
    shares = viewer_shares(crowd.where, cameras, np.array([int(v.budget) for v in viewers]), min_distance)
    fits = layers_within(crowd.rates, shares)
    return {id(v): (shares[:, k], fits[:, k]) for k, v in enumerate(viewers)}


def cut_for(
    room: Room,
    crowd: Crowd,
    viewer: Viewer,
    shares: np.ndarray,
    fits: np.ndarray,
    items: list[Forward],
    pending: int,
    cache: dict,
) -> tuple[list[bytes], np.ndarray | None]:
    """The viewer's packets, the scalable streams cut to its ``shares`` of the crowd (bit/s
    per stream; ``fits``: the layers within each), and their lengths (None: not worked
    out). The tick's fresh layered packets (``crowd.layered``) go at once, in arrays; the
    rest, and what the viewer has pending, one by one."""
    together = pending < len(items) and bool(crowd.together)
    out = []
    for f in items[:pending] + (crowd.others if together else items[pending:]):
        r = crowd.row.get(f.packet.stream)
        if r is None or (f.cuts is None and f.layer_ends is None):
            out.append(f.data)
        elif f.layer_ends is not None:
            keep = layers_for(viewer, f, room.streams[f.packet.stream], int(fits[r]))
            key: tuple[int, float] = (id(f), -keep)
            if key not in cache:
                cache[key] = drop_layers(f, keep)
            out.append(cache[key])
        else:
            rate = on_ladder(float(shares[r]))
            key = (id(f), rate)
            if key not in cache:
                cache[key] = cut_embedded(f, room.streams[f.packet.stream], rate)
            out.append(cache[key])
    if not together:
        return out, None
    chosen = _cut_layered(room, crowd, viewer, fits[crowd.rows])
    lengths = np.concatenate((np.fromiter(map(len, out), dtype="<u4", count=len(out)), crowd.lengths[chosen]))
    return out + list(map(crowd.variants.__getitem__, chosen.tolist())), lengths


def _cut_layered(room: Room, crowd: Crowd, viewer: Viewer, fits: np.ndarray) -> np.ndarray:
    """Which variant of each of the tick's fresh layered packets a viewer gets (indices into
    ``crowd.variants``; :func:`layers_for`, in arrays): the only packet of its stream this
    tick, so its layers depend only on what the viewer had."""
    count = len(crowd.streams)
    had = np.fromiter(map(viewer.layers.get, crowd.streams, repeat(0, count)), dtype=np.int64, count=count)
    keep = np.where(crowd.keyframes | (had == 0), fits, np.minimum(fits, had))
    for i in np.nonzero(keep < fits)[0].tolist():  # a layer may come back where it restarts
        f = crowd.layered[i]
        keep[i] = layers_for(viewer, f, room.streams[f.packet.stream], int(fits[i]))
    viewer.layers.update(zip(crowd.streams, keep.tolist()))
    return np.arange(count) * crowd.width + keep - 1


def layers_for(viewer: Viewer, f: Forward, state: StreamState, fits: int) -> int:
    """The layers of a layered stream's packet a viewer gets: the ``fits`` whose rate fits its
    share (at least the base), more than it had only from a keyframe or a packet where the next
    layer restarts (a layer it missed has lost its prediction's history)."""
    stream = f.packet.stream
    had = viewer.layers.get(stream)
    keep = fits if f.packet.keyframe or had is None else min(fits, had)
    if keep < fits:
        if f.layer_starts is None:
            try:
                f.layer_starts = state.codec.layer_starts(f.packet.payload)
            except MocodecError:
                f.layer_starts = []
        starts = f.layer_starts
        while keep < min(fits, len(starts)) and starts[keep]:
            keep += 1
    viewer.layers[stream] = keep
    return keep


def resent(viewer: Viewer, f: Forward) -> bytes:
    """A packet a viewer asked for again: a layered one with the layers the viewer gets now
    (all, without a budget), anything else whole."""
    if f.layer_ends is None or viewer.budget <= 0:
        return f.data
    return drop_layers(f, min(viewer.layers.get(f.packet.stream, 1), len(f.layer_ends)))


def drop_layers(f: Forward, keep: int) -> bytes:
    """A layered packet with its lowest ``keep`` layers."""
    assert f.layer_ends is not None
    if keep >= len(f.layer_ends):
        return f.data
    return truncated(f.packet, f.data, f.layer_ends[keep - 1], len(f.layer_ends) - keep)


def layer_variants(f: Forward) -> list[bytes]:
    """A layered packet with 1, 2, ... of its layers (all of them: the packet)."""
    assert f.layer_ends is not None
    return [drop_layers(f, keep) for keep in range(1, len(f.layer_ends) + 1)]


def cut_embedded(f: Forward, state: StreamState, rate: float) -> bytes:
    """An embedded stream's packet cut to ``rate`` bit/s by its codec's packet cutter (made at
    the first cut, kept for every other viewer); whole if its cut table does not fit it."""
    try:
        if f.cutter is None:
            f.cutter = state.codec.packet_cutter(f.packet.payload, state.info.skeleton, f.cuts, state.info.fps)
        payload = f.cutter(rate)
    except Exception as e:  # noqa: BLE001 - a cut table that does not fit the payload: pass it whole
        log.warning("stream %d: packet %d not cut: %s", f.packet.stream, f.packet.sequence, e)
        f.cuts = None
        return f.data
    return f.data if payload is f.packet.payload else f.packet.with_payload(payload).to_bytes()
