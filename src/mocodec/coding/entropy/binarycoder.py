"""The binary range coder shared by the context-adaptive coders (coefcoder, intcoder).

The carry-less byte-wise binary coder of LZMA (32-bit range, 64-bit low with a cached carry
byte), with 16-bit probabilities that mix a fast (1/16) and a slow (1/128) adaptation rate.
An integer becomes binary decisions (:func:`put_int`): zero or not, a size class
``k = floor(log2 |v|)`` in unary, the ``k`` mantissa bits below the leading one (the top one
adaptive, the rest at probability 1/2) and the sign; the caller names the context of each.

State: the encoder's ``st`` is [low, range, cache, cache size, bytes written] and it writes
into a caller-sized buffer; the decoder's is [code, range, read position] and it reads zeros
past the end of its data, so damaged input gives garbage, never an out-of-bounds read.
"""

from __future__ import annotations

import numba
import numpy as np

TOP = 1 << 24
HALF = 1 << 15
FAST, SLOW = 4, 7
INIT = 1 << 15
MAX_CLASS = 62  # |v| < 2^62
WARM_DONE = 126  # decisions after which a warm context adapts at the fixed rates
_WARM_SHIFT = np.array([min((n + 2).bit_length(), SLOW) for n in range(WARM_DONE + 1)], dtype=np.int64)


@numba.njit(inline="always")
def encoder_state():
    return np.array([0, 0xFFFFFFFF, 0, 1, 0], dtype=np.int64)


@numba.njit(inline="always")
def shift_low(st, buf):
    low = st[0]
    if low < 0xFF000000 or low >= (1 << 32):
        carry = low >> 32
        temp = st[2]
        while True:
            buf[st[4]] = (temp + carry) & 0xFF
            st[4] += 1
            temp = 0xFF
            st[3] -= 1
            if st[3] == 0:
                break
        st[2] = (low >> 24) & 0xFF
    st[3] += 1
    st[0] = (low & 0x00FFFFFF) << 8


def new_state(contexts: int, warm: bool = False) -> np.ndarray:
    """Adaptive state of ``contexts`` binary contexts: rows fast probability, slow probability
    (of a 0, out of 65536) and decisions seen. ``warm`` contexts start adapting at 1/4 and slow
    down to their rates as decisions come (a context learns its first symbols at once, as a
    counting estimator would; docs/kinwave.md). Without, they adapt at the fixed rates from the
    start."""
    state = np.full((3, contexts), INIT, dtype=np.int64)
    state[2] = 0 if warm else WARM_DONE
    return state


@numba.njit(inline="always")
def _adapt(state, ctx, mask):
    """Move the context's probabilities of a 0 towards 0 (mask -1: a 1 was coded) or 65536
    (mask 0), without a branch: coded bits are unpredictable, so branches cost more."""
    n = state[2, ctx]
    fast, slow = min(FAST, _WARM_SHIFT[n]), _WARM_SHIFT[n]
    f, s = state[0, ctx], state[1, ctx]
    state[0, ctx] = f + (((65536 - f) >> fast) & ~mask) - ((f >> fast) & mask)
    state[1, ctx] = s + (((65536 - s) >> slow) & ~mask) - ((s >> slow) & mask)
    state[2, ctx] = min(n + 1, WARM_DONE)


@numba.njit(inline="always")
def put(st, buf, state, ctx, bit):
    rng = st[1]
    bound = (rng >> 16) * ((state[0, ctx] + state[1, ctx]) >> 1)
    mask = -np.int64(bit)
    st[0] += bound & mask
    rng = (bound & ~mask) | ((rng - bound) & mask)
    _adapt(state, ctx, mask)
    while rng < TOP:
        rng <<= 8
        shift_low(st, buf)
    st[1] = rng


@numba.njit(inline="always")
def put_even(st, buf, bit):
    bound = (st[1] >> 16) * HALF
    if bit == 0:
        st[1] = bound
    else:
        st[0] += bound
        st[1] -= bound
    while st[1] < TOP:
        st[1] <<= 8
        shift_low(st, buf)


@numba.njit(inline="always")
def get(st, data, state, ctx):
    rng = st[1]
    bound = (rng >> 16) * ((state[0, ctx] + state[1, ctx]) >> 1)
    bit = np.int64(st[0] >= bound)
    mask = -bit
    st[0] -= bound & mask
    rng = (bound & ~mask) | ((rng - bound) & mask)
    _adapt(state, ctx, mask)
    while rng < TOP:
        rng <<= 8
        nxt = data[st[2]] if st[2] < data.size else 0
        st[2] += 1
        st[0] = ((st[0] << 8) | nxt) & 0xFFFFFFFF
    st[1] = rng
    return bit


@numba.njit(inline="always")
def get_even(st, data):
    bound = (st[1] >> 16) * HALF
    if st[0] < bound:
        st[1] = bound
        bit = 0
    else:
        st[0] -= bound
        st[1] -= bound
        bit = 1
    while st[1] < TOP:
        st[1] <<= 8
        nxt = data[st[2]] if st[2] < data.size else 0
        st[2] += 1
        st[0] = ((st[0] << 8) | nxt) & 0xFFFFFFFF
    return bit


# ----- integers -----------------------------------------------------------------------------
@numba.njit(inline="always")
def put_int(st, buf, state, v, zctx, uctx, ulen, mctx, sctx):
    """``v`` as: a zero flag; then the class k of |v| in unary (k ones, a zero below
    MAX_CLASS); the top mantissa bit in its class's context; the other k - 1 mantissa bits at
    even odds; the sign. The adaptive decisions go through one call of :func:`put` (the
    compiled code of a caller inlines it once, not at every kind of decision)."""
    m = -v if v < 0 else v
    k = 0
    while (m >> (k + 1)) != 0:
        k += 1
    unary = (k + (1 if k < MAX_CLASS else 0)) if v != 0 else 0
    top = 1 if v != 0 and k > 0 else 0
    for step in range(1 + unary + top):
        if step == 0:
            ctx, bit = zctx, 1 if v != 0 else 0
        elif step <= unary:
            ctx, bit = uctx + min(step - 1, ulen - 1), 1 if step <= k else 0
        else:
            ctx, bit = mctx + k, (m >> (k - 1)) & 1
        put(st, buf, state, ctx, bit)
    if v == 0:
        return
    for b in range(k - 2, -1, -1):
        put_even(st, buf, (m >> b) & 1)
    put(st, buf, state, sctx, 1 if v < 0 else 0)


@numba.njit(inline="always")
def get_int(st, data, state, zctx, uctx, ulen, mctx, sctx):
    """Inverse of :func:`put_int`, its adaptive decisions through one call of :func:`get`."""
    k, m, phase = 0, 1, 0  # phases: 0 the zero flag, 1 the class in unary, 2 the top mantissa bit
    while phase < 3:
        ctx = zctx if phase == 0 else (uctx + min(k, ulen - 1) if phase == 1 else mctx + k)
        bit = get(st, data, state, ctx)
        if phase == 0:
            if bit == 0:
                return 0
            phase = 1
        elif phase == 1:
            k += bit
            if bit == 0 or k == MAX_CLASS:
                phase = 2 if k > 0 else 3
        else:
            m = (m << 1) | bit
            phase = 3
    for _ in range(k - 1):
        m = (m << 1) | get_even(st, data)
    return -m if get(st, data, state, sctx) == 1 else m


@numba.njit(inline="always")
def start_decoder(data):
    st = np.array([0, 0xFFFFFFFF, 0], dtype=np.int64)  # code, range, read position
    for _ in range(5):
        nxt = data[st[2]] if st[2] < data.size else 0
        st[2] += 1
        st[0] = ((st[0] << 8) | nxt) & 0xFFFFFFFF
    return st


@numba.njit(inline="always")
def finish(st, buf):
    for _ in range(5):
        shift_low(st, buf)
    return st[4]


@numba.njit(inline="always")
def finish_short(st, buf):
    """Like :func:`finish`, for short streams (a live packet): the final value is the one in
    ``[low, low + range)`` with the most trailing zero bits, and the zero bytes it ends with
    are not counted, since a decoder reads zeros past the end of its data. The first byte is
    always 0 (nothing carries into it) and a caller may drop it too (:func:`start_decoder`
    then needs it back). Returns the bytes written."""
    low, rng = st[0], st[1]
    for k in range(32, -1, -1):
        mask = (np.int64(1) << k) - 1
        v = (low + mask) & ~mask
        if v < low + rng:
            st[0] = v
            break
    for _ in range(5):
        shift_low(st, buf)
    n = st[4]
    while n > 1 and buf[n - 1] == 0:
        n -= 1
    return n


def int_decisions(values: np.ndarray) -> int:
    """An upper bound on the decisions :func:`put_int` makes for ``values``."""
    m = np.abs(np.asarray(values, dtype=np.int64)).ravel()
    if m.size and m.max() >= 1 << MAX_CLASS:
        raise ValueError("integer too large to code")
    nz = m[m > 0]
    return m.size + 2 * int(np.ceil(np.log2(nz + 1)).sum()) + 2 * nz.size


def buffer_for(decisions: int) -> np.ndarray:
    """An output buffer for that many decisions (probabilities stay above 2^-10, so a decision
    costs at most about 10 bits)."""
    return np.empty(64 + (10 * decisions) // 8, dtype=np.uint8)
