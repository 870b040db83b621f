"""The binary range coder shared by the context-adaptive coders (coefcoder, intcoder).

The carry-less byte-wise binary coder of LZMA (32-bit range, 64-bit low with a cached carry
byte), with 16-bit probabilities that mix a fast (1/16) and a slow (1/128) adaptation rate.
An integer becomes binary decisions (:func:`put_int`): zero or not, a size class
``k = floor(log2 |v|)`` in unary, the ``k`` mantissa bits below the leading one (the top one
adaptive, the rest at probability 1/2) and the sign; the caller names the context of each.

State: the encoder's ``st`` is [low, range, cache, cache size, bytes written] and it writes
into a caller-sized buffer; the decoder's is [code, range, read position] and it reads zeros
past the end of its data, so damaged input gives garbage, never an out-of-bounds read. The
``*_s`` primitives take and return that state as scalars (``put_s``: (low, range, cache, cache
size, position); ``get_s``: (bit, code, range, position)), which a compiled loop keeps in
registers: a coder that codes a whole payload in one loop (coefcoder) goes 1.6 times as fast
with them as through the array, which can alias its output buffer. The array functions wrap
them, for callers that carry the state from call to call.
"""

from __future__ import annotations

import numba
import numpy as np

from mocodec.kernels import kernel

TOP = 1 << 24
HALF = 1 << 15
FAST, SLOW = 4, 7
INIT = 1 << 15
MAX_CLASS = 62  # |v| < 2^62
WARM_DONE = 126  # decisions after which a warm context adapts at the fixed rates
_WARM_SHIFT = np.array([min((n + 2).bit_length(), SLOW) for n in range(WARM_DONE + 1)], dtype=np.int64)


@numba.njit(inline="always")
def encoder_start():
    """A new encoder's state as scalars: (low, range, cache, cache size, position)."""
    return np.int64(0), np.int64(0xFFFFFFFF), np.int64(0), np.int64(1), np.int64(0)


@numba.njit(inline="always")
def encoder_state():
    low, rng, cache, size, pos = encoder_start()
    return np.array([low, rng, cache, size, pos], dtype=np.int64)


@numba.njit(inline="always")
def shift_low_s(low, cache, size, pos, buf):
    """The encoder's low byte out (carries resolved through the cached bytes): (low, cache,
    cache size, position)."""
    if low < 0xFF000000 or low >= (1 << 32):
        carry = low >> 32
        temp = cache
        while True:
            buf[pos] = (temp + carry) & 0xFF
            pos += 1
            temp = 0xFF
            size -= 1
            if size == 0:
                break
        cache = (low >> 24) & 0xFF
    return (low & 0x00FFFFFF) << 8, cache, size + 1, pos


@numba.njit(inline="always")
def shift_low(st, buf):
    st[0], st[2], st[3], st[4] = shift_low_s(st[0], st[2], st[3], st[4], buf)


@kernel
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
def put_s(low, rng, cache, size, pos, buf, state, ctx, bit):
    bound = (rng >> 16) * ((state[0, ctx] + state[1, ctx]) >> 1)
    mask = -np.int64(bit)
    low += bound & mask
    rng = (bound & ~mask) | ((rng - bound) & mask)
    _adapt(state, ctx, mask)
    while rng < TOP:
        rng <<= 8
        low, cache, size, pos = shift_low_s(low, cache, size, pos, buf)
    return low, rng, cache, size, pos


@numba.njit(inline="always")
def put(st, buf, state, ctx, bit):
    st[0], st[1], st[2], st[3], st[4] = put_s(st[0], st[1], st[2], st[3], st[4], buf, state, ctx, bit)


@numba.njit(inline="always")
def put_even_s(low, rng, cache, size, pos, buf, bit):
    bound = (rng >> 16) * HALF
    if bit == 0:
        rng = bound
    else:
        low += bound
        rng -= bound
    while rng < TOP:
        rng <<= 8
        low, cache, size, pos = shift_low_s(low, cache, size, pos, buf)
    return low, rng, cache, size, pos


@numba.njit(inline="always")
def put_even(st, buf, bit):
    st[0], st[1], st[2], st[3], st[4] = put_even_s(st[0], st[1], st[2], st[3], st[4], buf, bit)


@numba.njit(inline="always")
def _next_byte(code, pos, data):
    nxt = data[pos] if pos < data.size else 0
    return ((code << 8) | nxt) & 0xFFFFFFFF, pos + 1


@numba.njit(inline="always")
def get_s(code, rng, pos, data, state, ctx):
    bound = (rng >> 16) * ((state[0, ctx] + state[1, ctx]) >> 1)
    bit = np.int64(code >= bound)
    mask = -bit
    code -= bound & mask
    rng = (bound & ~mask) | ((rng - bound) & mask)
    _adapt(state, ctx, mask)
    while rng < TOP:
        rng <<= 8
        code, pos = _next_byte(code, pos, data)
    return bit, code, rng, pos


@numba.njit(inline="always")
def get(st, data, state, ctx):
    bit, st[0], st[1], st[2] = get_s(st[0], st[1], st[2], data, state, ctx)
    return bit


@numba.njit(inline="always")
def get_even_s(code, rng, pos, data):
    bound = (rng >> 16) * HALF
    if code < bound:
        rng = bound
        bit = 0
    else:
        code -= bound
        rng -= bound
        bit = 1
    while rng < TOP:
        rng <<= 8
        code, pos = _next_byte(code, pos, data)
    return bit, code, rng, pos


@numba.njit(inline="always")
def get_even(st, data):
    bit, st[0], st[1], st[2] = get_even_s(st[0], st[1], st[2], data)
    return bit


# ----- integers -----------------------------------------------------------------------------
@numba.njit(inline="always")
def put_int_s(low, rng, cache, size, pos, buf, state, v, zctx, uctx, ulen, mctx, sctx):
    """``v`` as: a zero flag; then the class k of |v| in unary (k ones, a zero below
    MAX_CLASS); the top mantissa bit in its class's context; the other k - 1 mantissa bits at
    even odds; the sign. The adaptive decisions go through one call of :func:`put_s` (the
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
        low, rng, cache, size, pos = put_s(low, rng, cache, size, pos, buf, state, ctx, bit)
    if v == 0:
        return low, rng, cache, size, pos
    for b in range(k - 2, -1, -1):
        low, rng, cache, size, pos = put_even_s(low, rng, cache, size, pos, buf, (m >> b) & 1)
    return put_s(low, rng, cache, size, pos, buf, state, sctx, 1 if v < 0 else 0)


@numba.njit(inline="always")
def put_int(st, buf, state, v, zctx, uctx, ulen, mctx, sctx):
    """:func:`put_int_s` on an array state."""
    st[0], st[1], st[2], st[3], st[4] = put_int_s(
        st[0], st[1], st[2], st[3], st[4], buf, state, v, zctx, uctx, ulen, mctx, sctx
    )


@numba.njit(inline="always")
def get_int_s(code, rng, pos, data, state, zctx, uctx, ulen, mctx, sctx):
    """Inverse of :func:`put_int_s`, its adaptive decisions through one call of :func:`get_s`:
    (value, code, range, position)."""
    k, m, phase = 0, 1, 0  # phases: 0 the zero flag, 1 the class in unary, 2 the top mantissa bit
    while phase < 3:
        ctx = zctx if phase == 0 else (uctx + min(k, ulen - 1) if phase == 1 else mctx + k)
        bit, code, rng, pos = get_s(code, rng, pos, data, state, ctx)
        if phase == 0:
            if bit == 0:
                return 0, code, rng, pos
            phase = 1
        elif phase == 1:
            k += bit
            if bit == 0 or k == MAX_CLASS:
                phase = 2 if k > 0 else 3
        else:
            m = (m << 1) | bit
            phase = 3
    for _ in range(k - 1):
        bit, code, rng, pos = get_even_s(code, rng, pos, data)
        m = (m << 1) | bit
    negative, code, rng, pos = get_s(code, rng, pos, data, state, sctx)
    return (-m if negative == 1 else m), code, rng, pos


@numba.njit(inline="always")
def get_int(st, data, state, zctx, uctx, ulen, mctx, sctx):
    """:func:`get_int_s` on an array state."""
    v, st[0], st[1], st[2] = get_int_s(st[0], st[1], st[2], data, state, zctx, uctx, ulen, mctx, sctx)
    return v


@numba.njit(inline="always")
def start_decoder_s(data):
    """A decoder's state after its first five bytes, as scalars: (code, range, position)."""
    code, pos = np.int64(0), np.int64(0)
    for _ in range(5):
        code, pos = _next_byte(code, pos, data)
    return code, np.int64(0xFFFFFFFF), pos


@numba.njit(inline="always")
def start_decoder(data):
    code, rng, pos = start_decoder_s(data)
    return np.array([code, rng, pos], dtype=np.int64)  # code, range, read position


@numba.njit(inline="always")
def finish_s(low, cache, size, pos, buf):
    """The encoder's last bytes out: the bytes written in all."""
    for _ in range(5):
        low, cache, size, pos = shift_low_s(low, cache, size, pos, buf)
    return pos


@numba.njit(inline="always")
def finish(st, buf):
    return finish_s(st[0], st[2], st[3], st[4], buf)


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
