"""Multi-resolution correlative scan matching (Olson 2009, "Real-time correlative scan
matching"; branch-and-bound over translation as in Hess et al. 2016).

Used to seed Gauss–Newton when the start estimate may lie outside GN's ±1-coarse-cell
basin (fast turns at low scan rates, time gaps, a poor match). It searches, on one map
level, every rotation in ``θ0 ± angular_window`` (step by Olson's rule: the farthest point
moves at most one cell) and every integer cell offset in ``±linear_window``, and returns
the exact maximiser of

    score(θ, t) = mean_i T(round(R(θ)s_i + t)) − w_t·|Δt|² − w_r·Δθ²

where T = max(0, 2p − 1) (0 for unknown/free, → 1 for occupied), smeared by half a value
into the 8-neighbourhood so that one-cell misses still count. The translation search is a
branch and bound: the table at height h holds the max of T over a 2^h × 2^h block, so the
score of a block of offsets bounds the score of every offset inside it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.slam.grid import GridLevel
from dynslam2d.slam.interp import cell_prob


def _score_table(prob: np.ndarray) -> np.ndarray:
    """T = max(0, 2p−1) with a 0.5-weighted 3×3 max smear (float32)."""
    t = np.maximum(2.0 * prob.astype(np.float32) - 1.0, 0.0)
    m = t.copy()
    m[:, 1:] = np.maximum(m[:, 1:], t[:, :-1])
    m[:, :-1] = np.maximum(m[:, :-1], t[:, 1:])
    m2 = m.copy()
    m2[1:, :] = np.maximum(m2[1:, :], m[:-1, :])
    m2[:-1, :] = np.maximum(m2[:-1, :], m[1:, :])
    return np.maximum(t, 0.5 * m2)


def _pyramid(t0: np.ndarray, max_height: int) -> np.ndarray:
    """(max_height+1, H, W): level h holds max of t0 over [x, x+2^h) × [y, y+2^h) (0 outside)."""
    out = np.zeros((max_height + 1,) + t0.shape, dtype=np.float32)
    out[0] = t0
    for h in range(1, max_height + 1):
        s = 1 << (h - 1)
        prev = out[h - 1]
        a = prev.copy()
        if s < a.shape[1]:
            a[:, :-s] = np.maximum(a[:, :-s], prev[:, s:])
        b = a.copy()
        if s < b.shape[0]:
            b[:-s, :] = np.maximum(b[:-s, :], a[s:, :])
        out[h] = b
    return out


@njit(cache=True)
def _score_pyramid(prob, max_height):  # pragma: no cover - numba
    """``_pyramid(_score_table(prob), max_height)`` in one kernel, ``prob`` a level's probability cache words
    ((H, W) uint32, slam/grid.py ``encode_probs``; decoded as read) (float32, the same values: the table's
    float32 2p − 1 and 0.5·m, and maxima, which are exact in any order; ``prob`` holds no NaN, and no value is
    −0: every value is a maximum with +0 or half of one).

    One pass per output (pass map20): a row's 3-wide maximum from its three cells, the table from the three rows'
    maxima, and pyramid level h from the four cells (x, y), (x + s, y), (x, y + s), (x + s, y + s) of level h − 1
    (s = 2^(h−1); the ones beyond the array's end left out, as the zeros outside would be) — instead of a
    copy and one maximum per neighbour, each a pass over the whole array; the loops read and write rows (1-D
    views). Cell x + s of a row is read as cell x of the row's view from s (pass neg71): the same cells, but with
    the kernels' one LLVM optimisation (``jitbox.one_llvm_optimisation``) only this form of the loop is
    vectorised (x + s indexing: ≈ 2.2× the time of the pyramid's levels on negative_2's crops). Every cell of the
    output is written, so it starts uninitialised. The loops are :func:`_search_table`'s (this kernel is that one
    with no margin, off the front end's path: the search's kernel alone is compiled on a cold run)."""
    hh, ww = prob.shape
    buf = np.empty((max_height + 3) * hh * ww, dtype=np.float32)
    tab, _ = _search_table(prob, 0, 0, hh, ww, max_height, 0, 0, hh, ww, buf)
    return tab.reshape(max_height + 1, hh, ww)


@njit(cache=True)
def _search_table(prob, r0, c0, ch, cw, max_height, y0, x0, hh, ww, buf):  # pragma: no cover - numba
    """:func:`correlative_search`'s table in one kernel: :func:`_score_pyramid` of the crop of ``prob`` (a level's
    whole cache; the crop's rows r0 … r0 + ch − 1, columns c0 … c0 + cw − 1, read as 1-D slices of ``prob``'s rows:
    contiguous where ``prob`` is, so that the loop vectorises — a 2-D view of the crop has strided rows, ≈ 2× the
    kernel's time on MIT CSAIL's searches) laid
    at rows y0 … and columns x0 … of a (max_height + 1, hh, ww) float32 table returned flat (C order; the caller
    reshapes it: numba's reshape is ≈ 0.1 s of the kernel's cold compile), zeros elsewhere (the same values as
    the pyramid copied into ``np.zeros``: no second array, no copy), and whether its level-0 maximum is ≤ 1 (as
    ``pyramid[0].max() <= 1.0``, NaN making it False) without another pass. The table and the pyramid's two
    (ch, cw) work arrays are views of ``buf`` (float32, at least (max_height + 1)·hh·ww + 2·ch·cw long; reused
    from call to call: no page of a fresh large array touched for the first time on every search). Row y of level
    h is the 1-D slice of the table from ((h·hh + y)·ww) (a contiguous view: the loops vectorise as on a 2-D
    array's rows); ``above`` counts the level-0 values not ≤ 1 (NaN included)."""
    n = (max_height + 1) * hh * ww
    flat = buf[:n]
    zero = np.float32(0.0)
    for h in range(max_height + 1):  # (only the cells outside the crop: the pyramid writes every cell inside)
        for y in range(hh):
            o = (h * hh + y) * ww
            row = flat[o:o + ww]
            if y < y0 or y >= y0 + ch:
                for x in range(ww):
                    row[x] = zero
            else:
                for x in range(x0):
                    row[x] = zero
                for x in range(x0 + cw, ww):
                    row[x] = zero
    tb = n  # the work rows: row y of t at tb + y·cw, of m at mb + y·cw (1-D slices: no reshape, whose
    mb = n + ch * cw  # implementation is ≈ 0.1 s of the kernel's cold compile)
    zero = np.float32(0.0)
    two = np.float32(2.0)
    one = np.float32(1.0)
    half = np.float32(0.5)
    for y in range(ch):
        pr = prob[r0 + y][c0:c0 + cw]
        tr = buf[tb + y * cw:tb + (y + 1) * cw]
        for x in range(cw):
            tr[x] = max(two * cell_prob(pr[x]) - one, zero)
        mr = buf[mb + y * cw:mb + (y + 1) * cw]  # 3-wide max along the row
        if cw == 1:
            mr[0] = tr[0]
        else:
            mr[0] = max(tr[0], tr[1])
            for x in range(1, cw - 1):
                mr[x] = max(max(tr[x - 1], tr[x]), tr[x + 1])
            mr[cw - 1] = max(tr[cw - 2], tr[cw - 1])
    above = 0
    for y in range(ch):  # then 3-high max along the column, halved, and at least the cell's own value
        b = buf[mb + y * cw:mb + (y + 1) * cw]
        a = buf[mb + (y - 1) * cw:mb + y * cw] if y >= 1 else b
        c = buf[mb + (y + 1) * cw:mb + (y + 2) * cw] if y + 1 < ch else b
        tr = buf[tb + y * cw:tb + (y + 1) * cw]
        o = (y0 + y) * ww + x0
        orow = flat[o:o + cw]
        for x in range(cw):
            v = max(tr[x], half * max(max(a[x], b[x]), c[x]))
            orow[x] = v
            above += 0 if v <= one else 1
    for h in range(1, max_height + 1):
        s = 1 << (h - 1)
        e = cw - s if cw > s else 0  # (the columns whose x + s is inside)
        for y in range(ch):  # max over [x, x + s] × [y, y + s] (0 outside: the values are ≥ 0)
            o = ((h - 1) * hh + y0 + y) * ww + x0
            ra = flat[o:o + cw]
            o = (h * hh + y0 + y) * ww + x0
            crow = flat[o:o + cw]
            if y + s < ch:
                o = ((h - 1) * hh + y0 + y + s) * ww + x0
                rb = flat[o:o + cw]
                ras = ra[s:]  # (cell x + s as cell x of a view: the loop vectorises, see _score_pyramid)
                rbs = rb[s:]
                for x in range(e):
                    crow[x] = max(max(ra[x], ras[x]), max(rb[x], rbs[x]))
                for x in range(e, cw):
                    crow[x] = max(ra[x], rb[x])
            else:
                ras = ra[s:]
                for x in range(e):
                    crow[x] = max(ra[x], ras[x])
                for x in range(e, cw):
                    crow[x] = ra[x]
    return flat, above == 0


#: the search tables' reused memory (:func:`_search_table`'s ``buf``), kept up to this many float32 values (1 MiB; a
#: larger table, a wide search of the loop closer, gets an array of its own instead of a large one kept). Pass mem107:
#: at 4 MiB the kept buffer held ≈ 3 MiB resident for the whole run (MIT CSAIL's largest search needs 774 150
#: values), +3 MiB on the AOT run's peak; at 1 MiB 19 of its 617 searches take a fresh array (as all did before)
_BUF_MAX = 1 << 18
_BUF: list[np.ndarray] = [np.empty(0, dtype=np.float32)]


def _table_buffer(size: int) -> np.ndarray:
    """A float32 array of at least ``size`` values: the module's reused one (grown to twice the need, at most
    ``_BUF_MAX``) or, beyond that, a fresh one. Its contents are overwritten by every search that uses it (the
    searches run one at a time; a table is not read after its search returns)."""
    buf = _BUF[0]
    if buf.shape[0] >= size:
        return buf
    if size > _BUF_MAX:
        return np.empty(size, dtype=np.float32)
    buf = _BUF[0] = np.empty(min(2 * size, _BUF_MAX), dtype=np.float32)
    return buf


#: np.iinfo(np.int64)'s bounds as plain constants (numba compiles np.iinfo's implementation for its one caller here).
_INT64_MAX = int(np.iinfo(np.int64).max)
_INT64_MIN = int(np.iinfo(np.int64).min)


@njit(cache=True)
def _rotated_cells(pc, c, s, mx, my):  # pragma: no cover - numba
    """Nearest cells (qx, qy) (nrot, n) int64 of the points ``pc`` (n ≥ 1, 2, cells) turned by each row's (cos
    ``c``, sin ``s``) and moved by (``mx``, ``my``): floor(c·x − s·y + mx + 0.5), floor(s·x + c·y + my + 0.5), the
    same float64 operations in the same order as the array expressions they replace; and their (min qx, max qx,
    min qy, max qy).

    The cells first, row by row from contiguous copies of the points' x and y, then the extremes in a second loop
    (pass map20): with the running extremes in the cells' loop it did not vectorise (≈ 3× the time). The loops are
    :func:`_search_cells`' (with no shift; off the front end's path: only the search's kernel is compiled on a cold
    run)."""
    return _search_cells(pc, c, s, mx, my, -1)


@njit(cache=True)
def _search_cells(pc, c, s, mx, my, w):  # pragma: no cover - numba
    """:func:`correlative_search`'s point cells in one kernel: :func:`_rotated_cells`' cells and extremes (min qx,
    max qx, min qy, max qy), the cells then moved into the search table's frame — less the crop's first column c0 =
    max(min qx − ``w`` − 1, 0) and the table's margin ox = min(0, min qx − c0 − ``w``), and the same in y (``w``
    cells: the linear window) — in one more loop, instead of two in-place array subtractions per axis in Python (the
    same int64 values: integer subtraction is exact). ``w`` < 0: the cells are not moved (:func:`_rotated_cells`)."""
    nrot = c.shape[0]
    n = pc.shape[0]
    qx = np.empty((nrot, n), dtype=np.int64)
    qy = np.empty((nrot, n), dtype=np.int64)
    px = np.empty(n)  # contiguous copies of x and y by a loop: numba's np.ascontiguousarray of a strided column
    py = np.empty(n)  # is a helper compiled for this kernel alone (≈ 0.12 s of a cold compile)
    for i in range(n):
        px[i] = pc[i, 0]
        py[i] = pc[i, 1]
    for k in range(nrot):
        ck = c[k]
        sk = s[k]
        rx = qx[k]
        ry = qy[k]
        for i in range(n):
            rx[i] = int(math.floor(ck * px[i] - sk * py[i] + mx + 0.5))
            ry[i] = int(math.floor(sk * px[i] + ck * py[i] + my + 0.5))
    x0 = y0 = _INT64_MAX
    x1 = y1 = _INT64_MIN
    fx = qx.ravel()
    fy = qy.ravel()
    for j in range(fx.shape[0]):
        x0 = min(x0, fx[j])
        x1 = max(x1, fx[j])
        y0 = min(y0, fy[j])
        y1 = max(y1, fy[j])
    sx = sy = 0
    if w >= 0:
        c0 = max(x0 - w - 1, 0)
        r0 = max(y0 - w - 1, 0)
        sx = c0 + min(0, x0 - c0 - w)
        sy = r0 + min(0, y0 - r0 - w)
    for j in range(fx.shape[0]):  # (fx, fy: the flat views of the extremes' loop)
        fx[j] -= sx
        fy[j] -= sy
    return qx, qy, x0, x1, y0, y1


@njit(cache=True)
def _search_points(pts, idx, r):  # pragma: no cover - numba
    """:func:`correlative_search`'s points in one kernel: ``pts[idx] / r`` ((k, 2) float64 cells, ``pts`` (n, 2)
    float64 m, ``idx`` (k ≥ 1,) int64 rows, ``r`` m a cell) and :func:`_percentile95` of their ranges
    (``np.hypot`` of each row: the C library's ``hypot``, as NumPy's), instead of a fancy-indexed copy, a division,
    a hypot and a partition in NumPy (≈ 40 µs of MIT CSAIL's searches). The two order statistics around the
    virtual index (k − 1)·0.95 are the smallest of the k − lo largest ranges, kept in ascending order by insertion
    (k − lo ≤ 0.05·k + 1 values: no sort or partition compiled), then :func:`_percentile95`'s interpolation, the same
    float64 operations (the kernels compile without ``fastmath``: no contraction)."""
    k = idx.shape[0]
    pc = np.empty((k, 2))
    vi = (k - 1) * 0.95
    lo = int(math.floor(vi))
    m = k - lo  # (sorted positions lo … k − 1: top[0] is position lo, top[1] position lo + 1)
    top = np.empty(m)
    nt = 0
    for i in range(k):
        j = idx[i]
        x = pts[j, 0] / r
        y = pts[j, 1] / r
        pc[i, 0] = x
        pc[i, 1] = y
        v = math.hypot(x, y)
        if nt < m:
            q = nt
            nt += 1
        elif v > top[0]:
            q = 0
            while q + 1 < m and top[q + 1] < v:  # (drop top[0]: shift the smaller ones down)
                top[q] = top[q + 1]
                q += 1
            top[q] = v
            continue
        else:
            continue
        while q > 0 and top[q - 1] > v:
            top[q] = top[q - 1]
            q -= 1
        top[q] = v
    a = top[0]
    b = top[1] if m > 1 else top[0]
    t = vi - lo
    d = b - a
    return pc, (b - d * (1 - t) if t >= 0.5 else a + d * t)


@njit(cache=True)
def _min_abs(lo, hi):  # pragma: no cover - numba
    if lo <= 0 <= hi:
        return 0
    return min(abs(lo), abs(hi))


@njit(cache=True)
def branch_and_bound(tab, ww, qx, qy, merge, w, dth, wt_cell2, wr, excl, floor,
                     stop):  # pragma: no cover - numba
    """Exact best (rotation index, dx, dy, score) over rotations (qx/qy rows) and offsets in [−w, w]².

    ``tab`` (Hmax+1, H·``ww``) float32: the score pyramid, each level flat, with zeros wherever a point's cell
    of some offset lies outside the searched map (every read is in range); ``qx, qy`` (nrot, n) int64 point
    cells at zero offset in that table. ``merge``: the table values are in [0, 1] — a rotation whose blocks are
    split is then read as its distinct cells with their point counts (built at its first split; the same sums, see
    below), else point by point. ``dth`` (nrot,) rotation
    offsets, rad; penalties ``wt_cell2`` per cell², ``wr`` per rad².
    ``excl`` (6,) int64 (k0, k1, dx0, dx1, dy0, dy1): candidates with k0 ≤ k ≤ k1, dx0 ≤ dx ≤ dx1 and dy0 ≤ dy ≤ dy1
    are left out (the runner-up search); k0 > k1 leaves nothing out.

    ``floor``: only scores above it count (the search starts with it as its best: blocks whose bound is at most
    ``floor`` are pruned; −1e300 = none). Returns score ``floor`` (and rotation / offsets 0) when no candidate
    scores above it. Where every bound is admissible (``_admissible``) the best above ``floor`` is the one the
    search without it finds, the same candidate among equal scores too (the first maximiser in the search's
    fixed order is reached either way: every block on the way to it has a bound ≥ its score > ``floor``).
    ``stop``: the search returns as soon as its best exceeds ``stop`` (that candidate, not necessarily the best:
    the caller only needs to know some candidate beats ``stop``); +inf = never.

    Every table read below is at an index ≥ 0 (the table holds every cell a point reads at any offset in
    [−w, w]², from its first row and column: ``correlative_search``), passed as an unsigned integer: numba then
    leaves out its negative-index wrap-around (a compare and select per read, ≈ 20 % of the far searches' time;
    the same element is read, so the same values).
    """
    hmax = tab.shape[0] - 1
    nrot = qx.shape[0]
    n = qx.shape[1]
    step = 1 << hmax
    # merged cell lists, built at a rotation's first split: entries rlo[k]:rhi[k] of cell / count (−1: none); a
    # rotation split once paid for its list too since the table reads are unsigned (docs/speed.md, pass loop20)
    rlo = np.empty(nrot, dtype=np.int64)
    for k in range(nrot):  # (element loops, not ``a[:] = v``: ≈ half its LLVM instructions to compile; pass cmp149)
        rlo[k] = -1
    rhi = np.empty(nrot, dtype=np.int64)
    cell = np.empty(nrot * n if merge else 0, dtype=np.int64)
    count = np.empty(nrot * n if merge else 0)
    cap = 16
    while cap < 2 * n:
        cap *= 2
    mask = cap - 1
    key = np.empty(cap, dtype=np.int64)
    owner = np.empty(cap, dtype=np.int64)  # the rotation whose cell a hash slot holds (−1: none yet)
    for i in range(cap):
        owner[i] = -1
    slot = np.empty(cap, dtype=np.int64)
    m = 0
    top = tab[hmax]
    na = (2 * w + 1 + step - 1) // step
    ntop = nrot * na * na
    top_k = np.empty(ntop, dtype=np.int64)
    top_dx = np.empty(ntop, dtype=np.int64)
    top_dy = np.empty(ntop, dtype=np.int64)
    top_s = np.empty(ntop)
    # the top blocks' offsets into the table and their translation penalties, the same for every rotation
    na2 = na * na
    toff = np.empty(na2, dtype=np.int64)
    tpen = np.empty(na2)
    for a in range(na):
        dx = -w + a * step
        mx = _min_abs(dx, min(dx + step - 1, w))
        for b in range(na):
            dy = -w + b * step
            my = _min_abs(dy, min(dy + step - 1, w))
            toff[a * na + b] = dy * ww + dx
            tpen[a * na + b] = wt_cell2 * (mx * mx + my * my)
    acc = np.empty(na2)
    c = 0
    for k in range(nrot):
        pr = wr * dth[k] * dth[k]
        # every top block of rotation k in one pass over the points: each block's sum gets the points in order,
        # as a pass of its own would add them (the same float64 values)
        if na == 2:  # (the usual case, four scalar sums)
            t0 = toff[0]
            t1 = toff[1]
            t2 = toff[2]
            t3 = toff[3]
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            a3 = 0.0
            for i in range(n):
                base = qy[k, i] * ww + qx[k, i]
                a0 += top[np.uint64(base + t0)]
                a1 += top[np.uint64(base + t1)]
                a2 += top[np.uint64(base + t2)]
                a3 += top[np.uint64(base + t3)]
            acc[0] = a0
            acc[1] = a1
            acc[2] = a2
            acc[3] = a3
        else:
            for q in range(na2):
                acc[q] = 0.0
            for i in range(n):
                base = qy[k, i] * ww + qx[k, i]
                for q in range(na2):
                    acc[q] += top[np.uint64(base + toff[q])]
        for a in range(na):
            for b in range(na):
                q = a * na + b
                top_k[c] = k
                top_dx[c] = -w + a * step
                top_dy[c] = -w + b * step
                top_s[c] = acc[q] / n - pr - tpen[q]
                c += 1
    # best bound first: a stable merge sort by descending bound (ties in block order), written out here
    # because numba's np.argsort compiles its quicksort machinery, about 1.5 s of a first run's compile
    # (docs/speed.md). Only equal bounds are ordered differently from numba's quicksort; the results of
    # all 2514 searches of a MIT CSAIL run are the same either way
    order = np.empty(ntop, dtype=np.int64)
    for t in range(ntop):  # (np.arange: a helper of numba's compiled for this kernel alone, ≈ 0.1 s of a cold run)
        order[t] = t
    buf = np.empty(ntop, dtype=np.int64)
    width = 1
    while width < ntop:
        for lo in range(0, ntop, 2 * width):
            mid = min(lo + width, ntop)
            hi = min(lo + 2 * width, ntop)
            i = lo
            j = mid
            for o in range(lo, hi):
                if j < hi and (i >= mid or top_s[order[j]] > top_s[order[i]]):
                    buf[o] = order[j]
                    j += 1
                else:
                    buf[o] = order[i]
                    i += 1
        order, buf = buf, order
        width *= 2
    best = floor
    bk = 0
    bdx = 0
    bdy = 0
    cap = 4 * (hmax + 2) + 8
    sk = np.empty(cap, dtype=np.int64)
    sdx = np.empty(cap, dtype=np.int64)
    sdy = np.empty(cap, dtype=np.int64)
    sh = np.empty(cap, dtype=np.int64)
    ss = np.empty(cap)
    cs = np.empty(4)
    sel = np.empty(4, dtype=np.int64)  # the children pushed, in push order
    cx = np.empty(4, dtype=np.int64)
    cy = np.empty(4, dtype=np.int64)
    for oi in range(ntop):
        t = order[oi]
        if top_s[t] <= best:
            break
        sp = 0
        sk[0] = top_k[t]
        sdx[0] = top_dx[t]
        sdy[0] = top_dy[t]
        sh[0] = hmax
        ss[0] = top_s[t]
        sp = 1
        while sp > 0:
            sp -= 1
            k = sk[sp]
            dx = sdx[sp]
            dy = sdy[sp]
            h = sh[sp]
            sc = ss[sp]
            if sc <= best:
                continue
            if h == 0:
                if (excl[0] <= k <= excl[1] and excl[2] <= dx <= excl[3] and excl[4] <= dy <= excl[5]):
                    continue
                best = sc
                bk = k
                bdx = dx
                bdy = dy
                if best > stop:
                    return bk, bdx, bdy, best
                continue
            half = 1 << (h - 1)
            pr = wr * dth[k] * dth[k]
            if merge and rlo[k] < 0:
                rlo[k] = m
                # its distinct cells in first-seen order with their point counts, found with an
                # open-addressing hash whose slots hold rotation k's cells where owner is k
                for i in range(n):
                    cc = qy[k, i] * ww + qx[k, i]
                    hs = np.uint64((cc * 2654435761) & mask)  # (a slot ≥ 0: unsigned, as the table reads)
                    while owner[hs] == k and key[hs] != cc:
                        hs = np.uint64((hs + 1) & mask)
                    if owner[hs] == k:
                        count[slot[hs]] += 1.0
                        continue
                    owner[hs] = k
                    key[hs] = cc
                    slot[hs] = m
                    cell[m] = cc
                    count[m] = 1.0
                    m += 1
                rhi[k] = m
            nc = 0
            tl = tab[h - 1]
            if dx + half <= w and dy + half <= w:
                # all four children: their four sums in one pass over the cells (each child's sum gets the same
                # terms in the same order as a pass of its own, so the same float64 values)
                off = dy * ww + dx
                o01 = off + half * ww
                o10 = off + half
                o11 = o01 + half
                b00 = 0.0
                b01 = 0.0
                b10 = 0.0
                b11 = 0.0
                if rlo[k] >= 0:  # (the sums over distinct cells: see below)
                    for j in range(np.uint64(rlo[k]), np.uint64(rhi[k])):
                        cj = cell[j]
                        q = count[j]
                        b00 += q * tl[np.uint64(cj + off)]
                        b01 += q * tl[np.uint64(cj + o01)]
                        b10 += q * tl[np.uint64(cj + o10)]
                        b11 += q * tl[np.uint64(cj + o11)]
                else:
                    for i in range(n):  # point by point, in order
                        cj = qy[k, i] * ww + qx[k, i]
                        b00 += tl[np.uint64(cj + off)]
                        b01 += tl[np.uint64(cj + o01)]
                        b10 += tl[np.uint64(cj + o10)]
                        b11 += tl[np.uint64(cj + o11)]
                mx0 = _min_abs(dx, dx + half - 1)
                mx1 = _min_abs(dx + half, min(dx + 2 * half - 1, w))
                my0 = _min_abs(dy, dy + half - 1)
                my1 = _min_abs(dy + half, min(dy + 2 * half - 1, w))
                cs[0] = b00 / n - pr - wt_cell2 * (mx0 * mx0 + my0 * my0)
                cs[1] = b01 / n - pr - wt_cell2 * (mx0 * mx0 + my1 * my1)
                cs[2] = b10 / n - pr - wt_cell2 * (mx1 * mx1 + my0 * my0)
                cs[3] = b11 / n - pr - wt_cell2 * (mx1 * mx1 + my1 * my1)
                cx[0] = dx
                cy[0] = dy
                cx[1] = dx
                cy[1] = dy + half
                cx[2] = dx + half
                cy[2] = dy
                cx[3] = dx + half
                cy[3] = dy + half
                nc = 4
            else:
                for ix in range(2):
                    cdx = dx + ix * half
                    if cdx > w:
                        continue
                    ex = min(cdx + half - 1, w)
                    mx = _min_abs(cdx, ex)
                    for iy in range(2):
                        cdy = dy + iy * half
                        if cdy > w:
                            continue
                        ey = min(cdy + half - 1, w)
                        my = _min_abs(cdy, ey)
                        off = cdy * ww + cdx
                        bs = 0.0
                        if rlo[k] >= 0:
                            # Σ count × value over the distinct cells: the same float64 sum as adding the points one
                            # by one in any order, because the table values are multiples of 2^−24 in [0, 1] (2p − 1
                            # of a float32 p ≥ 0.5 is exact, a multiple of 2^−23, its half a multiple of 2^−24) and
                            # n ≤ 2^29 of them (count × value ≤ n) sum without rounding
                            for j in range(rlo[k], rhi[k]):
                                bs += count[j] * tl[np.uint64(cell[j] + off)]
                        else:
                            for i in range(n):  # point by point, in order
                                bs += tl[np.uint64(qy[k, i] * ww + qx[k, i] + off)]
                        cs[nc] = bs / n - pr - wt_cell2 * (mx * mx + my * my)
                        cx[nc] = cdx
                        cy[nc] = cdy
                        nc += 1
            # push the children above best in ascending score, equal scores in child order (the order the former
            # selection of the first smallest each round gave), so the best is explored first: the survivors picked
            # first (in 62 % of the splits none survives) and sorted by insertion, strict comparisons keeping it stable
            ns = 0
            for q in range(nc):
                if cs[q] > best:
                    sel[ns] = q
                    ns += 1
            for p in range(1, ns):
                v = sel[p]
                cv = cs[v]
                r = p
                while r > 0 and cs[sel[r - 1]] > cv:
                    sel[r] = sel[r - 1]
                    r -= 1
                sel[r] = v
            for p in range(ns):
                j = sel[p]
                sk[sp] = k
                sdx[sp] = cx[j]
                sdy[sp] = cy[j]
                sh[sp] = h - 1
                ss[sp] = cs[j]
                sp += 1
    return bk, bdx, bdy, best


def _wrapped_rows(dth: np.ndarray, k: int, ek: int, step: float) -> np.ndarray | None:
    """Rows (rotation offsets ``dth``, rad, evenly ``step`` apart) within ±``ek`` steps of row ``k`` around the
    circle, as a mask; None when the window does not reach around (the plain index range ±``ek`` is exact).

    A window of ±π or more holds every orientation twice (rows k and k ± 2π/step): the index distance is taken
    modulo that period (the loop closure's far search, measured so). A window just short of ±π holds its two
    ends within the neighbourhood of each other around the circle: there the angles themselves decide.
    """
    if step <= 0.0:
        return None
    n = dth.shape[0]
    period = int(round(2.0 * math.pi / step))
    rows = np.arange(n)
    if period and n > period:
        off = np.abs(rows - k) % period
        return np.minimum(off, period - off) <= ek
    if 2.0 * math.pi - (dth[-1] - dth[0]) > ek * step:
        return None
    d = np.abs(np.remainder(dth - dth[k] + math.pi, 2.0 * math.pi) - math.pi)
    near = d <= ek * step * (1.0 + 1e-9)
    return None if np.array_equal(near, np.abs(rows - k) <= ek) else near


def _admissible(t0: np.ndarray, inside_x: bool, inside_y: bool, e: int) -> bool:
    """Whether every block bound of a search is at least the score of every offset inside the block, given the
    crop's score table ``t0`` (H, W) and whether no point is read at a negative column (``inside_x``) / row
    (``inside_y``) index for any offset. A block read at column x < 0 counts the point as 0, while an offset
    inside it (x + i, i < 2^h) may read column x + i ≥ 0 of the map, at most column 2^hmax − 2 (``e`` − 1,
    ``e`` = 2^hmax − 1): the bound holds where the table is 0 on those first ``e`` columns (rows alike). The lower
    edges are the only ones: beyond the upper ones both the block and its offsets read nothing."""
    return (inside_x or not t0[:, :e].any()) and (inside_y or not t0[:e, :].any())


@functools.lru_cache(maxsize=256)
def even_indices(n: int, k: int) -> np.ndarray:
    """(k,) read-only int64 indices of ``k`` points evenly spread over ``n`` (``np.linspace``, truncated): the same
    few scan sizes come back at every search and keyframe, so each is computed once. Computed as ``np.linspace``
    computes it for k ≥ 2 (``arange(k) · ((n − 1) / (k − 1))`` in float64, the last one set to n − 1, truncated)
    without its per-call overhead: the number of returns varies from scan to scan, so many sizes are new."""
    if k < 2:
        idx = np.linspace(0, n - 1, k).astype(np.int64)
    else:
        y = np.arange(k, dtype=np.float64)
        y *= (n - 1) / (k - 1)
        y[-1] = n - 1
        idx = y.astype(np.int64)
    idx.flags.writeable = False
    return idx


@functools.lru_cache(maxsize=256)
def _all_rows(n: int) -> np.ndarray:
    """(n,) read-only int64 indices 0 … n − 1 (:func:`_search_points`' rows when no subsample is taken)."""
    idx = np.arange(n, dtype=np.int64)
    idx.flags.writeable = False
    return idx


def _percentile95(v: np.ndarray) -> float:
    """``np.percentile(v, 95)`` of a 1-D float64 array without NaN (n ≥ 1), the same float64 operations: numpy's
    default "linear" method (Hyndman & Fan 1996, type 7) — virtual index (n − 1)·0.95, the two order statistics
    around it, and numpy's ``_lerp`` (from the upper one where the weight is ≥ 0.5) — without its per-call
    overhead (≈ 20 µs of a search's setup)."""
    n = v.shape[0]
    vi = (n - 1) * 0.95
    lo = math.floor(vi)
    hi = min(lo + 1, n - 1)
    part = np.partition(v, (lo, hi))
    a = float(part[lo])
    b = float(part[hi])
    t = vi - lo
    d = b - a
    return b - d * (1 - t) if t >= 0.5 else a + d * t


def _turn_first(tab: np.ndarray, ww: int, qx0: np.ndarray, qy0: np.ndarray, merge: bool, w: int, dth: np.ndarray,
                n_half: int, angular_window: float, accept_turn: float, wt_cell2: float, wr: float, floor: float,
                min_score: float, min_margin: float, ec: int, runner_up_angle: float,
                ) -> tuple[int, int, int, int, float, int, int, int, float]:
    """The search of :func:`correlative_search` with ``accept_turn`` rad: the rotations within it first (rows
    ``n_half`` ± j of ``dth``, a contiguous block of the search's own rows read from its own table, in the same
    order), then the others only as far as the caller's decision needs them.

    Returns (status, k, dx, dy, best, k2, dx2, dy2, runner-up score): status 0 = search every rotation as without
    ``accept_turn`` (the block is not much smaller than the whole, reaches half way round the circle — where the
    whole search's runner-up neighbourhood wraps around it, :func:`_wrapped_rows` — or its best lies within the
    runner-up neighbourhood of its edge, or a pose outside it scores at least as high); 1 = no pose of the whole
    search passes ``min_score``, ``min_margin`` and ``accept_turn``; 2 = the whole search's best and runner-up.

    With B the whole search's best and B' the block's (:func:`branch_and_bound` over the block's rows with the
    search's ``floor``; its rows, bounds and order are the whole search's, so the same pose):

    * B' below ``min_score``: B is below it too or outside the block, beyond ``accept_turn`` (refused either way);
    * B''s runner-up in the block (outside ±``ec`` cells / ±ek rows, cut short at the same ``stop``) within
      ``min_margin`` of it: it is a runner-up of B = B' in the whole search too (within a block narrower than π the
      plain row distance is the circular one), or B lies beyond ``accept_turn``;
    * the rows outside the block searched with that ``stop``: a pose above it is the whole search's best (beyond
      ``accept_turn``) or a runner-up of B' that loses the margin; otherwise their best is exact and below B''s
      score, so B = B' (the first maximiser: every outside score is lower), and the whole search's runner-up is the
      higher of the block's and theirs (the same score; the block's pose among equal scores).
    """
    none = (0, 0, 0, 0, 0.0, 0, 0, 0, 0.0)
    step = angular_window / max(n_half, 1)
    if step <= 0.0:
        return none
    j = int(math.floor(accept_turn / step))
    if j < 0 or 2 * j + 1 > (2 * n_half + 1) // 2 or 2.0 * j * step >= math.pi:
        return none
    lo, hi = n_half - j, n_half + j + 1
    qx = np.ascontiguousarray(qx0[lo:hi])
    qy = np.ascontiguousarray(qy0[lo:hi])
    d = dth[lo:hi]
    k, dx, dy, best = branch_and_bound(tab, ww, qx, qy, merge, w, d, wt_cell2, wr, _NO_EXCL, floor, math.inf)
    if best < min_score:
        return (1, *none[1:])
    ek = int(math.ceil(runner_up_angle / step))
    excl = np.array([k - ek, k + ek, dx - ec, dx + ec, dy - ec, dy + ec], dtype=np.int64)
    stop = best - min_margin + 1e-9
    k2, dx2, dy2, s2 = branch_and_bound(tab, ww, qx, qy, merge, w, d, wt_cell2, wr, excl, -1e300, stop)
    runner_up = float(s2) if s2 > -1e299 else 0.0
    if float(best) - runner_up < min_margin:
        return (1, *none[1:])
    if k - ek < 0 or k + ek >= hi - lo:  # outside rows within the best's neighbourhood: the whole search decides
        return none
    ox = np.concatenate((qx0[:lo], qx0[hi:]))
    oy = np.concatenate((qy0[:lo], qy0[hi:]))
    od = np.concatenate((dth[:lo], dth[hi:]))
    k3, dx3, dy3, s3 = branch_and_bound(tab, ww, ox, oy, merge, w, od, wt_cell2, wr, _NO_EXCL, -1e300, stop)
    if s3 > stop:  # the best beyond accept_turn, or a runner-up that loses the margin
        return (1, *none[1:])
    if s3 >= best:  # (only when min_margin ≤ 1e-9: equal scores, the order decides)
        return none
    if s3 > s2:
        k2, dx2, dy2, s2 = (k3 if k3 < lo else k3 + (hi - lo)), dx3, dy3, s3
    else:
        k2 += lo
    runner_up = float(s2) if s2 > -1e299 else 0.0
    if float(best) - runner_up < min_margin:
        return (1, *none[1:])
    return (2, k + lo, dx, dy, best, k2, dx2, dy2, s2)


#: Exclusion box that leaves nothing out (k0 > k1).
_NO_EXCL = np.array([1, 0, 0, 0, 0, 0], dtype=np.int64)


@dataclass(slots=True)
class CorrelativeResult:
    """Best pose of a correlative search.

    Attributes:
        pose: (3,) world pose (x m, y m, θ rad).
        score: penalised score in [0, 1] (mean smeared hit value of the points).
        n_rotations: rotations searched.
        runner_up: best penalised score outside ±``runner_up_distance`` / ±``runner_up_angle`` of
            the best (None unless asked for).
        runner_up_pose: (3,) world pose of the runner-up, or None.
    """

    pose: np.ndarray
    score: float
    n_rotations: int
    runner_up: float | None = None
    runner_up_pose: np.ndarray | None = None


def correlative_search(
    level: GridLevel,
    pts_m: np.ndarray,
    start_world: np.ndarray,
    linear_window: float,
    angular_window: float,
    angular_step: float | None = None,
    max_points: int = 240,
    max_height: int = 4,
    translation_weight: float = 0.05,
    rotation_weight: float = 0.05,
    runner_up_distance: float | None = None,
    runner_up_angle: float = 0.3,
    runner_up_wrap: bool = False,
    min_score: float | None = None,
    min_margin: float | None = None,
    accept_turn: float | None = None,
) -> CorrelativeResult | None:
    """Search ``level`` around ``start_world`` for the best pose of laser-frame points ``pts_m`` (n, 2, m).

    With ``runner_up_distance`` (m), a second branch-and-bound pass finds the best pose farther
    than that (or than ``runner_up_angle`` rad) from the best one. Returns None if the level is
    empty or there are no points.

    ``runner_up_wrap``: the runner-up's rotation neighbourhood wraps around the circle — a search over
    every rotation (window ≥ π) holds the best orientation at θ and θ ± 2π too, and without it the
    "runner-up" can be the best pose itself turned by 2π; a window just short of π holds its two ends within
    the neighbourhood of each other. Default False: the plain index neighbourhood (the front end's
    ``recovery_runner_up_wrap`` / ``relocalise_runner_up_wrap`` and the loop closure's ``runner_up_wrap``
    choose it per call site).

    ``min_score``: the caller refuses a best score below it; the search then returns None instead of a pose
    (and prunes the blocks whose bound is below it: the same pose as without it whenever it returns one).
    ``min_margin``: the caller refuses a runner-up closer than this below the best score; the runner-up search
    stops at the first pose that makes the margin (score − runner_up) smaller than it, and ``runner_up`` is then
    that pose's score (a lower bound of the runner-up's, enough to refuse). Where the margin is at least
    ``min_margin`` the runner-up is the one found without it.

    ``accept_turn`` (rad; with ``min_score``, ``min_margin`` and ``runner_up_distance``): the caller refuses a
    best pose more than this from ``start_world``'s heading too (the loop closer's far search: the correction
    the uncertainty allows, plus what its refinement may turn). The rotations within it are then searched first,
    the same rows of the same table, and the others only as far as the decision needs them (:func:`_turn_first`):
    None when no pose of the whole search passes ``min_score``, ``min_margin`` and ``accept_turn`` (a search without
    it may then return a pose the caller refuses); otherwise the result of the search without it (the same pose,
    score and runner-up score; the runner-up pose is one of those with that score).
    """
    if level.empty or pts_m.shape[0] == 0:
        return None
    r = level.resolution
    n = pts_m.shape[0]
    if angular_step is None and pts_m.dtype == np.float64:
        # the subsample, its cells and their ranges' 95th percentile in one kernel
        pc, p95 = _search_points(pts_m, even_indices(n, max_points) if n > max_points else _all_rows(n), float(r))
    else:
        if n > max_points:
            pts_m = pts_m[even_indices(n, max_points)]
        pc = pts_m / r
        p95 = _percentile95(np.hypot(pc[:, 0], pc[:, 1])) if angular_step is None else 0.0
    if angular_step is None:
        d = max(p95, 1.0)
        # Olson's rule: farthest point moves at most one cell
        angular_step = math.acos(max(-1.0, 1.0 - 1.0 / (2.0 * d * d)))
    n_half = int(math.ceil(angular_window / angular_step)) if angular_window > 0 else 0
    dth = np.arange(-n_half, n_half + 1, dtype=np.float64) * (angular_window / max(n_half, 1))
    th = start_world[2] + dth
    mp = level.pose_to_map(np.asarray(start_world, dtype=np.float64))
    w = int(math.ceil(linear_window / r))
    # the points' cells, already in the search table's frame (less c0 + ox, r0 + oy below)
    qx0, qy0, qx_min, qx_max, qy_min, qy_max = _search_cells(pc, np.cos(th), np.sin(th), float(mp[0]), float(mp[1]),
                                                             w)
    hmax = max(0, min(max_height, int(math.floor(math.log2(2 * w + 1))) if w > 0 else 0))
    H, W = level.shape
    c0 = max(qx_min - w - 1, 0)
    c1 = min(qx_max + w + 2, W)
    r0 = max(qy_min - w - 1, 0)
    r1 = min(qy_max + w + 2, H)
    if c1 <= c0 or r1 <= r0:
        return None
    # the crop's score pyramid (_pyramid(_score_table(crop), hmax), one pass per level in a kernel) laid into a table
    # that holds every cell a point reads at any offset (zeros outside the crop: where the search read nothing), so
    # that the search reads without range checks; where every table value is in [0, 1] (``merge``) the points on one
    # cell are counted once with their number (branch_and_bound: the same sums). One kernel call writes the pyramid
    # straight into the table and tests the values (no pyramid array copied into a zeroed one, no max() pass)
    ox = min(0, qx_min - c0 - w)
    oy = min(0, qy_min - r0 - w)
    ww = max(c1 - c0, qx_max - c0 + w + 1) - ox
    hh = max(r1 - r0, qy_max - r0 + w + 1) - oy
    tab, merge = _search_table(level.prob, r0, c0, r1 - r0, c1 - c0, hmax, -oy, -ox, hh, ww,
                               _table_buffer((hmax + 1) * hh * ww + 2 * (r1 - r0) * (c1 - c0)))
    tab = tab.reshape(hmax + 1, hh * ww)
    merge = bool(merge)
    floor = -1e300
    if min_score is not None and _admissible(tab[0].reshape(hh, ww)[-oy:r1 - r0 - oy, -ox:c1 - c0 - ox],
                                             qx_min - c0 >= w, qy_min - r0 >= w, (1 << hmax) - 1):
        # every block's bound is admissible: pruning the blocks below min_score keeps the result
        # (branch_and_bound's docstring); otherwise the search runs without it
        floor = math.nextafter(min_score, -math.inf)
    if accept_turn is not None and min_score is not None and min_margin is not None and runner_up_distance is not None:
        st, k, dx, dy, best, k2, dx2, dy2, s2 = _turn_first(
            tab, ww, qx0, qy0, merge, w, dth, n_half, angular_window, accept_turn, translation_weight * r * r,
            rotation_weight, floor, min_score, min_margin, int(math.ceil(runner_up_distance / r)), runner_up_angle)
        if st == 1:
            return None
        if st == 2:
            out = CorrelativeResult(level.pose_to_world(np.array([mp[0] + dx, mp[1] + dy, th[k]])), float(best),
                                    int(th.shape[0]))
            out.runner_up = float(s2) if s2 > -1e299 else 0.0
            out.runner_up_pose = level.pose_to_world(np.array([mp[0] + dx2, mp[1] + dy2, th[k2]]))
            return out
    k, dx, dy, best = branch_and_bound(tab, ww, qx0, qy0, merge, w, dth, translation_weight * r * r, rotation_weight,
                                       _NO_EXCL, floor, math.inf)
    if min_score is not None and best < min_score:
        return None
    pose_map = np.array([mp[0] + dx, mp[1] + dy, th[k]])
    out = CorrelativeResult(level.pose_to_world(pose_map), float(best), int(th.shape[0]))
    if runner_up_distance is not None:
        # the best pose outside a neighbourhood of the best: how clearly the best one wins
        ec = int(math.ceil(runner_up_distance / r))
        step = angular_window / max(n_half, 1)
        ek = int(math.ceil(runner_up_angle / step)) if step > 0 else 0
        excl = np.array([k - ek, k + ek, dx - ec, dx + ec, dy - ec, dy + ec], dtype=np.int64)
        # any runner-up above ``stop`` makes the margin smaller than min_margin (1e-9 above the exact limit: the
        # caller's rounded best − runner_up cannot reach min_margin there)
        stop = best - min_margin + 1e-9 if min_margin is not None else math.inf
        near = _wrapped_rows(dth, k, ek, step) if runner_up_wrap else None
        if near is not None:
            # the rows within ±ek of the best one around the circle go first, so that one contiguous
            # exclusion box covers all of them
            rows = np.arange(th.shape[0])
            perm = np.concatenate((rows[near], rows[~near]))
            excl[0], excl[1] = 0, int(near.sum()) - 1
            k2, dx2, dy2, s2 = branch_and_bound(tab, ww, np.ascontiguousarray(qx0[perm]),
                                                np.ascontiguousarray(qy0[perm]), merge, w, dth[perm],
                                                translation_weight * r * r, rotation_weight, excl, -1e300, stop)
            k2 = int(perm[k2])
        else:
            k2, dx2, dy2, s2 = branch_and_bound(tab, ww, qx0, qy0, merge, w, dth, translation_weight * r * r,
                                                rotation_weight, excl, -1e300, stop)
        out.runner_up = float(s2) if s2 > -1e299 else 0.0
        out.runner_up_pose = level.pose_to_world(np.array([mp[0] + dx2, mp[1] + dy2, th[k2]]))
    return out
