"""1-D SPIHT (set partitioning in hierarchical trees), 001 §6.3.2 after Said & Pearlman (1996).

Coefficients are a multi-level wavelet decomposition laid out coarsest first: the approximation
band [0, A), then the detail bands, the finest [N/2, N). The trees: an approximation node j has
one child, the detail coefficient A + j at the same position (the 1-D form of the 2-D rule that
the top band's roots point into the detail bands); a detail node j is the parent of 2j and
2j + 1; finest-band nodes have none. D(j) is the set of all descendants, L(j) = D(j) minus the
children.

The coder keeps the three lists of the original algorithm: LIP (insignificant pixels), LIS
(insignificant sets, type A = D(j), type B = L(j)) and LSP (significant pixels). At each bit
plane n, from the top down, the sorting pass sends the significance of every LIP entry and LIS
set (with signs of newly significant coefficients and the splitting of significant sets), and the
refinement pass sends bit n of every coefficient that became significant at an earlier plane.
The output is embedded: every prefix decodes, to the midpoints of the remaining uncertainty.
Encoding stops after ``budget`` bits; the decoder stops at the same place, so channel streams
can simply be concatenated.

Coefficients are integers (the caller quantises); ``encode`` returns the bits (one per byte)
and the top plane n0 (-1 when every coefficient is zero).
"""

from __future__ import annotations

import numpy as np

from mocodec.kernels import kernel


@kernel
def _children(j, n, approx):
    """(first child, count) of node j."""
    if j < approx:
        return (approx + j, 1) if approx + j < n else (0, 0)
    if 2 * j < n:
        return (2 * j, 2)
    return (0, 0)


@kernel
def _descendant_maxima(mag, approx):
    """max |c| over D(j) and over L(j), for every node."""
    n = mag.size
    max_d = np.zeros(n, dtype=np.int64)
    max_l = np.zeros(n, dtype=np.int64)
    for j in range(n - 1, -1, -1):
        first, count = _children(j, n, approx)
        for k in range(first, first + count):
            max_d[j] = max(max_d[j], mag[k], max_d[k])
            max_l[j] = max(max_l[j], max_d[k])
    return max_d, max_l


@kernel
def top_plane(coeffs):
    m = 0
    for v in coeffs:
        m = max(m, abs(v))
    n0 = -1
    while m > 0:
        m >>= 1
        n0 += 1
    return n0


@kernel
def encode(coeffs, approx, budget):
    """SPIHT bits (uint8, one bit each, at most ``budget``) of integer ``coeffs``, and n0."""
    n = coeffs.size
    mag = np.abs(coeffs)
    out = np.zeros(max(budget, 0), dtype=np.uint8)
    n0 = top_plane(coeffs)
    if n0 < 0 or budget <= 0:
        return out[:0], n0
    max_d, max_l = _descendant_maxima(mag, approx)
    lip = np.empty(n, dtype=np.int64)
    lsp = np.empty(n, dtype=np.int64)
    lis = np.empty(2 * n, dtype=np.int64)
    lis_type = np.empty(2 * n, dtype=np.int64)
    n_lip, n_lsp, n_lis = 0, 0, 0
    for j in range(min(approx, n)):
        lip[n_lip] = j
        n_lip += 1
        if _children(j, n, approx)[1]:
            lis[n_lis] = j
            lis_type[n_lis] = 0
            n_lis += 1
    nb = 0
    for plane in range(n0, -1, -1):
        t = np.int64(1) << plane
        lsp_before = n_lsp
        # sorting pass: LIP
        keep = 0
        for a in range(n_lip):
            j = lip[a]
            sig = mag[j] >= t
            out[nb] = sig
            nb += 1
            if nb == budget:
                return out[:nb], n0
            if sig:
                out[nb] = coeffs[j] < 0
                nb += 1
                lsp[n_lsp] = j
                n_lsp += 1
                if nb == budget:
                    return out[:nb], n0
            else:
                lip[keep] = j
                keep += 1
        n_lip = keep
        # sorting pass: LIS (entries appended during the pass are examined in it)
        a = 0
        while a < n_lis:
            j = lis[a]
            if lis_type[a] == 0:
                sig = max_d[j] >= t
                out[nb] = sig
                nb += 1
                if nb == budget:
                    return out[:nb], n0
                if sig:
                    first, count = _children(j, n, approx)
                    for k in range(first, first + count):
                        s = mag[k] >= t
                        out[nb] = s
                        nb += 1
                        if nb == budget:
                            return out[:nb], n0
                        if s:
                            out[nb] = coeffs[k] < 0
                            nb += 1
                            lsp[n_lsp] = k
                            n_lsp += 1
                            if nb == budget:
                                return out[:nb], n0
                        else:
                            lip[n_lip] = k
                            n_lip += 1
                    has_l = False
                    for k in range(first, first + count):
                        if _children(k, n, approx)[1]:
                            has_l = True
                    if has_l:
                        lis[n_lis] = j
                        lis_type[n_lis] = 1
                        n_lis += 1
                    lis_type[a] = -1
            elif lis_type[a] == 1:
                sig = max_l[j] >= t
                out[nb] = sig
                nb += 1
                if nb == budget:
                    return out[:nb], n0
                if sig:
                    first, count = _children(j, n, approx)
                    for k in range(first, first + count):
                        lis[n_lis] = k
                        lis_type[n_lis] = 0
                        n_lis += 1
                    lis_type[a] = -1
            a += 1
        keep = 0
        for a in range(n_lis):
            if lis_type[a] >= 0:
                lis[keep] = lis[a]
                lis_type[keep] = lis_type[a]
                keep += 1
        n_lis = keep
        # refinement pass
        for a in range(lsp_before):
            out[nb] = (mag[lsp[a]] >> plane) & 1
            nb += 1
            if nb == budget:
                return out[:nb], n0
    return out[:nb], n0


@kernel
def decode(bits, start, budget, n, approx, n0):
    """Coefficients (float, in quantum units) from ``bits[start:start + budget]``, the number
    of bits used, and the bit plane the stream stopped in (-1 when it was complete): every
    coefficient is then known to within 2^(plane + 1) quanta. Unknown low bits are filled with
    the midpoint of what remains possible."""
    known = np.zeros(n, dtype=np.int64)
    low = np.full(n, -1, dtype=np.int64)  # lowest known plane of a significant coefficient
    negative = np.zeros(n, dtype=np.bool_)
    out = np.zeros(n)
    end = min(start + max(budget, 0), bits.size)
    if n0 < 0:
        return out, 0, -1
    if end <= start:
        return out, 0, n0 + 1
    lip = np.empty(n, dtype=np.int64)
    lsp = np.empty(n, dtype=np.int64)
    lis = np.empty(2 * n, dtype=np.int64)
    lis_type = np.empty(2 * n, dtype=np.int64)
    n_lip, n_lsp, n_lis = 0, 0, 0
    for j in range(min(approx, n)):
        lip[n_lip] = j
        n_lip += 1
        if _children(j, n, approx)[1]:
            lis[n_lis] = j
            lis_type[n_lis] = 0
            n_lis += 1
    pos = start
    done = False
    stopped = -1
    for plane in range(n0, -1, -1):
        stopped = plane
        t = np.int64(1) << plane
        lsp_before = n_lsp
        keep = 0
        a = 0
        while a < n_lip:
            j = lip[a]
            a += 1
            if pos >= end:
                done = True
                break
            sig = bits[pos]
            pos += 1
            if sig:
                if pos >= end:  # the sign did not make it: leave the coefficient at 0
                    done = True
                    break
                known[j] = t
                low[j] = plane
                lsp[n_lsp] = j
                n_lsp += 1
                negative[j] = bits[pos]
                pos += 1
            else:
                lip[keep] = j
                keep += 1
        if done:
            break
        n_lip = keep
        a = 0
        while a < n_lis and not done:
            j = lis[a]
            if lis_type[a] == 0:
                if pos >= end:
                    done = True
                    break
                sig = bits[pos]
                pos += 1
                if sig:
                    first, count = _children(j, n, approx)
                    for k in range(first, first + count):
                        if pos >= end:
                            done = True
                            break
                        s = bits[pos]
                        pos += 1
                        if s:
                            if pos >= end:
                                done = True
                                break
                            known[k] = t
                            low[k] = plane
                            lsp[n_lsp] = k
                            n_lsp += 1
                            negative[k] = bits[pos]
                            pos += 1
                        else:
                            lip[n_lip] = k
                            n_lip += 1
                    if done:
                        break
                    has_l = False
                    for k in range(first, first + count):
                        if _children(k, n, approx)[1]:
                            has_l = True
                    if has_l:
                        lis[n_lis] = j
                        lis_type[n_lis] = 1
                        n_lis += 1
                    lis_type[a] = -1
            elif lis_type[a] == 1:
                if pos >= end:
                    done = True
                    break
                sig = bits[pos]
                pos += 1
                if sig:
                    first, count = _children(j, n, approx)
                    for k in range(first, first + count):
                        lis[n_lis] = k
                        lis_type[n_lis] = 0
                        n_lis += 1
                    lis_type[a] = -1
            a += 1
        if done:
            break
        keep = 0
        for a in range(n_lis):
            if lis_type[a] >= 0:
                lis[keep] = lis[a]
                lis_type[keep] = lis_type[a]
                keep += 1
        n_lis = keep
        for a in range(lsp_before):
            if pos >= end:
                done = True
                break
            j = lsp[a]
            known[j] |= np.int64(bits[pos]) << plane
            low[j] = plane
            pos += 1
        if done:
            break
    for j in range(n):
        if low[j] >= 0:
            mag = known[j] + ((np.int64(1) << low[j]) >> 1)
            out[j] = -mag if negative[j] else mag
    return out, pos - start, stopped if done else -1
