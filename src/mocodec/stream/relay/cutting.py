"""Cutting a room's scalable streams to each viewer's budget: the tick's crowd (which streams
scale, where they are, their layers' rates), each viewer's shares of it (:mod:`mocodec.crowd`),
and the packets cut to them. An embedded (``spiht``) packet is cut to its share rounded down to
the ladder; a layered (``kinwave-live``) packet keeps the layers whose measured rate fits,
more only where a layer restarts. Cuts are made once a tick for every viewer that shares them."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from operator import itemgetter

import numpy as np

from mocodec.crowd import layers_within, on_ladder, viewer_shares
from mocodec.errors import MocodecError
from mocodec.stream.packets import length_varint
from mocodec.stream.relay.rooms import Forward, Room, StreamState, Viewer

log = logging.getLogger("mocodec.relay")


@dataclass
class Round:
    """The tick's fresh layered packets that are the ``k``-th of their stream this tick (a
    stream's packets go in order, one round each): their streams, rows in the crowd, slots and
    keyframe flags, and their variants with 1, 2, ... layers (``variants[i * width +
    k - 1]``, the whole packet from its own layer count on) with the varint of each one's
    length (``heads``)."""

    layered: list[Forward]
    streams: list[int]
    rows: np.ndarray
    slots: np.ndarray
    keyframes: np.ndarray
    variants: list[bytes]
    heads: list[bytes]


#: Ticks a room's layout (:class:`Layout`) is kept for while its streams and its viewers'
#: budgets and cameras stay the same: 0.1 s at 60 Hz, in which avatars move a few centimetres
#: and the layers' measured rates (averaged over a second) little.
LAYOUT_TICKS = 6


@dataclass
class Layout:
    """A room's scalable streams (embedded or layered) and its budgeted viewers' shares of
    them, worked out every LAYOUT_TICKS ticks or when a stream, a budget or a camera changes:
    each stream's row and each viewer's column (by ``id``) in ``shares`` (bit/s, 6.4 and 6.5,
    by the distance from the viewer's camera to the stream's position) and ``fits`` (the layers
    whose measured rates fit them, at least one), ``(streams, viewers)``; ``width``: the most
    layers a stream has."""

    key: tuple
    row: dict[int, int]
    width: int
    column: dict[int, int]
    shares: np.ndarray
    fits: np.ndarray
    age: int = 0


@dataclass
class Crowd:
    """A tick's scalable streams, worked out once for every viewer: the room's
    :class:`Layout`, the tick's fresh layered packets in rounds (:class:`Round`), and its other
    fresh packets (``others``)."""

    layout: Layout
    rounds: list[Round]
    together: set[int]
    others: list[Forward]


def layout_of(room: Room, viewers: list[Viewer], min_distance: float) -> Layout:
    """The room's layout for the budgeted ``viewers``: the one kept in ``room.layout`` while
    it is younger than LAYOUT_TICKS and its streams, budgets and cameras are the same, else a
    new one."""
    key = (tuple(map(id, room.streams.values())), tuple((id(v), v.budget, v.camera) for v in viewers))
    kept = room.layout
    if isinstance(kept, Layout) and kept.key == key and kept.age < LAYOUT_TICKS:
        kept.age += 1
        return kept
    scalable = {k: s for k, s in room.streams.items() if s.embedded or s.layered}
    states = scalable.values()
    where = np.array([s.position for s in states], dtype=np.float64).reshape(-1, 3)
    width = max((s.layers for s in states), default=1)
    rates = np.array([s.layer_rates + [np.inf] * (width - s.layers) for s in states], dtype=np.float64)
    rates = rates.reshape(-1, width)
    if scalable and viewers:
        cameras = np.array([v.camera for v in viewers], dtype=np.float64)
        shares = viewer_shares(where, cameras, np.array([int(v.budget) for v in viewers]), min_distance)
        fits = layers_within(rates, shares)
    else:
        shares, fits = np.zeros((len(scalable), len(viewers))), np.ones((len(scalable), len(viewers)), dtype=np.int64)
    room.layout = Layout(
        key,
        {k: i for i, k in enumerate(scalable)},
        width,
        {id(v): i for i, v in enumerate(viewers)},
        shares,
        fits,
    )
    return room.layout


def crowd_of(room: Room, fresh: list[Forward], layout: Layout) -> Crowd:
    row = layout.row
    seen: Counter[int] = Counter()
    grouped: list[list[Forward]] = []
    for f in fresh:
        if f.layer_ends is not None and f.packet.stream in row:
            k = seen[f.packet.stream]
            seen[f.packet.stream] += 1
            if k == len(grouped):
                grouped.append([])
            grouped[k].append(f)
    rounds = [_round(room, row, layout.width, packets) for packets in grouped]
    together = {id(f) for packets in grouped for f in packets}
    return Crowd(layout, rounds, together, [f for f in fresh if id(f) not in together])


def _round(room: Room, row: dict[int, int], width: int, layered: list[Forward]) -> Round:
    """A round's arrays, and every packet's variants with 1 to ``width`` layers (those past its
    own count the whole packet)."""
    streams = [f.packet.stream for f in layered]
    variants = [f.layer_variants[min(keep, len(f.layer_variants)) - 1] for f in layered for keep in range(1, width + 1)]
    return Round(
        layered,
        streams,
        np.array([row[k] for k in streams], dtype=np.int64),
        np.array([room.streams[k].slot for k in streams], dtype=np.int64),
        np.array([f.packet.keyframe for f in layered], dtype=bool),
        variants,
        [length_varint(len(v)) for v in variants],
    )


def choose_layers(room: Room, crowd: Crowd, viewers: list[Viewer], fits: np.ndarray) -> list[np.ndarray]:
    """Per round of the tick's fresh layered packets, ``(packets, viewers)``: which variant of
    each (indices into the round's ``variants``) each viewer gets, for every viewer at once, the
    viewers' tables of layers updated (:func:`layers_for`, in arrays; ``fits``: the layers within
    each viewer's share of each crowd stream, ``(streams, viewers)``). A packet's layers depend
    only on what the viewer had of its stream, which the round before it has set."""
    return [_choose_round(room, crowd.layout.width, r, viewers, fits) for r in crowd.rounds]


def _choose_round(room: Room, width: int, r: Round, viewers: list[Viewer], fits: np.ndarray) -> np.ndarray:
    count = len(r.streams)
    if not viewers or not count:
        return np.zeros((count, len(viewers)), dtype=np.int64)
    top = int(r.slots.max())
    for v in viewers:
        v.hold_slot(top)
    had = np.stack([v.layers[r.slots] for v in viewers], axis=1).astype(np.int64)
    fit = fits[r.rows]
    keep = np.where(r.keyframes[:, None] | (had == 0) | (had >= fit), fit, had)
    grow = np.nonzero(keep < fit)  # a layer may come back where it restarts
    if grow[0].size:
        reach = _reach(room, width, r, np.unique(grow[0]))
        keep[grow] = np.minimum(fit[grow], reach[grow[0], had[grow]])
    for k, viewer in enumerate(viewers):
        viewer.layers[r.slots] = keep[:, k]
    return np.arange(count)[:, None] * width + keep - 1


def _reach(room: Room, width: int, r: Round, packets: np.ndarray) -> np.ndarray:
    """``(packets, width + 1)`` for a round's packets (rows ``packets`` filled): the layers a
    viewer that had ``h`` may take from each (:func:`regained`)."""
    reach = np.tile(np.arange(width + 1), (len(r.layered), 1))
    for i in packets.tolist():
        f = r.layered[i]
        starts = restarts_of(f, room.streams[f.packet.stream])
        reach[i, : len(starts)] = [regained(starts, h) for h in range(len(starts))]
    return reach


def regained(starts: list[bool], had: int) -> int:
    """The layers a viewer that had ``had`` may take from a packet whose layers restart where
    ``starts`` says: the next ones as far as each restarts in it (a layer it missed has lost
    its prediction's history until it restarts)."""
    keep = had
    while keep < len(starts) and starts[keep]:
        keep += 1
    return keep


def restarts_of(f: Forward, state: StreamState) -> list[bool]:
    """Which layers restart in a layered packet (read once, kept; none if it does not parse)."""
    if f.layer_starts is None:
        try:
            f.layer_starts = state.codec.layer_starts(f.packet.payload)
        except MocodecError:
            f.layer_starts = []
    return f.layer_starts


def cut_for(
    room: Room,
    crowd: Crowd,
    viewer: Viewer,
    items: list[Forward],
    pending: int,
    cache: dict,
    chosen: list[np.ndarray] | None = None,
) -> tuple[list[bytes], list[bytes]]:
    """The viewer's packets, the scalable streams cut to its shares of the crowd (bit/s per
    stream, and the layers within each: its column of the layout), and the varint of each
    one's length. The tick's fresh layered packets (``crowd.rounds``) are the variants
    ``chosen`` for the viewer (:func:`choose_layers`); the rest, and what the viewer has
    pending, one by one."""
    column = crowd.layout.column[id(viewer)]
    shares, fits = crowd.layout.shares[:, column], crowd.layout.fits[:, column]
    together = chosen is not None and pending < len(items) and bool(crowd.together)
    out = []
    for f in items[:pending] + (crowd.others if together else items[pending:]):
        r = crowd.layout.row.get(f.packet.stream)
        if r is None or (f.cuts is None and f.layer_ends is None):
            out.append(f.data)
        elif f.layer_ends is not None:
            out.append(drop_layers(f, layers_for(viewer, f, room.streams[f.packet.stream], int(fits[r]))))
        else:
            rate = on_ladder(float(shares[r]))
            key = (id(f), rate)
            if key not in cache:
                cache[key] = cut_embedded(f, room.streams[f.packet.stream], rate)
            out.append(cache[key])
    heads = [length_varint(len(b)) for b in out]
    if together:
        assert chosen is not None
        for group, picks in zip(crowd.rounds, chosen):
            pick = _picker(picks.tolist())
            heads += pick(group.heads)
            out += pick(group.variants)
    return out, heads


def _picker(indices: list[int]) -> Callable[[list], tuple]:
    """A function that takes the items at ``indices`` of a list, as a tuple (in one C call:
    ``itemgetter`` of one index gives the item, not a tuple)."""
    if len(indices) == 1:
        (only,) = indices
        return lambda items: (items[only],)
    return itemgetter(*indices)


def layers_for(viewer: Viewer, f: Forward, state: StreamState, fits: int) -> int:
    """The layers of a layered stream's packet a viewer gets: the ``fits`` whose rate fits its
    share (at least the base), more than it had only from a keyframe or a packet where the next
    layer restarts (a layer it missed has lost its prediction's history)."""
    had = viewer.layer_of(state.slot)
    keep = fits if f.packet.keyframe or not had or had >= fits else min(fits, regained(restarts_of(f, state), had))
    viewer.set_layer(state.slot, keep)
    return keep


def resent(viewer: Viewer, f: Forward, state: StreamState | None) -> bytes:
    """A packet a viewer asked for again: a layered one with the layers the viewer gets now
    (all, without a budget), anything else whole."""
    if f.layer_ends is None or viewer.budget <= 0 or state is None:
        return f.data
    return drop_layers(f, min(viewer.layer_of(state.slot) or 1, len(f.layer_ends)))


def drop_layers(f: Forward, keep: int) -> bytes:
    """A layered packet with its lowest ``keep`` layers."""
    return f.layer_variants[min(keep, len(f.layer_variants)) - 1]


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
