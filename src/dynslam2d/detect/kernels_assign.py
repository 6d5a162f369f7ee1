"""The association's assignment as one kernel call per scan (``Tracker._associate_update``): the gated cost
matrix, the established tracks' assignment, then the tentative tracks' on the detections left, each pair kept only
where the gates allow it.

The solver is SciPy's ``linear_sum_assignment`` (the shortest augmenting path algorithm of D. F. Crouse, "On
implementing 2D rectangular assignment algorithms", IEEE TAES 52(4):1679–1696, 2016, pp. 1685–1686, as implemented
in SciPy's ``scipy/optimize/rectangular_lsap/rectangular_lsap.cpp`` by P. M. Larsen, BSD licence) written again
step for step: the same column order, the same tie rule and the same floating-point operations in the same order,
so the same assignment bit for bit (``tests/test_detect_assign.py`` compares it with SciPy's). A Python call to
SciPy per group and the numpy glue around it (the sub-matrices, the index maps, the gate filter) cost ≈ 40–60 µs
per scan on the real recordings; the kernel does the same work in one call (docs/speed.md, pass trk21).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from dynslam2d.detect.kernels import cv_predict
from dynslam2d.detect.kernels_update import (
    UP_BIG,
    UP_MERGE_JUMP,
    UP_S_MAX,
    UP_S_STOP,
    association_gates,
    manage_scan,
    row_tables,
    update_pairs,
)
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle

#: status codes of :func:`lsap` / :func:`assign_groups` (SciPy raises ValueError with these messages)
LSAP_OK = 0
LSAP_INFEASIBLE = 1
LSAP_INVALID = 2
LSAP_MESSAGES = {LSAP_INFEASIBLE: "cost matrix is infeasible",
                 LSAP_INVALID: "matrix contains invalid numeric entries"}

#: whether the running interpreter's ``sum`` of floats is compensated (CPython 3.12 and later), so that
#: :func:`veto_merged` sums as the former Python veto did (a constant of the compiled code; numba's cache is per
#: interpreter version)
_COMPENSATED_SUM = sys.version_info >= (3, 12)


@njit(cache=True, inline="always")
def lsap(cost: np.ndarray) -> tuple:
    """SciPy's ``linear_sum_assignment(cost)`` (minimisation) of an (nr, nc) float64 matrix: (status, row indices,
    column indices), the rows increasing; status :data:`LSAP_OK`, or :data:`LSAP_INVALID` for a NaN or −inf entry,
    :data:`LSAP_INFEASIBLE` when no complete assignment has a finite cost (the index arrays are then empty). Crouse
    2016's shortest augmenting path, as SciPy implements it (module docstring). Written with ``np.empty`` and loops
    only (no ``np.full`` / ``np.argsort`` / slice assignment): each numpy helper a kernel uses is compiled once more
    per signature on a cold run (issue 13 item 2). The solver itself is :func:`lsap_flat` (inlined in each caller)."""
    nr0, nc0 = cost.shape
    transpose = nc0 < nr0  # a tall matrix is solved transposed
    c = np.empty(nr0 * nc0)  # (row-major, transposed for a tall matrix)
    for i in range(nr0):
        for j in range(nc0):
            if transpose:
                c[j * nr0 + i] = cost[i, j]
            else:
                c[i * nc0 + j] = cost[i, j]
    return lsap_flat(c, nr0, nc0)


@njit(cache=True, inline="always")
def lsap_flat(c: np.ndarray, nr0: int, nc0: int) -> tuple:
    """:func:`lsap` of the (nr0, nc0) cost matrix given as ``c``: its entries row-major, transposed (column-major)
    when the matrix is tall (nc0 < nr0), the layout the solver works in (``c`` is only read). For a caller that
    builds the matrix entry by entry (:func:`assign_groups`): no second copy of it."""
    k = min(nr0, nc0)
    a = np.empty(k, dtype=np.int64)
    b = np.empty(k, dtype=np.int64)
    if nr0 == 0 or nc0 == 0:
        return LSAP_OK, a, b
    transpose = nc0 < nr0
    if transpose:
        nr, nc = nc0, nr0
    else:
        nr, nc = nr0, nc0
    for q in range(nr * nc):
        x = c[q]
        if x != x or x == -np.inf:
            return LSAP_INVALID, a[:0], b[:0]
    u = np.empty(nr)
    col4row = np.empty(nr, dtype=np.int64)
    SR = np.empty(nr, dtype=np.bool_)
    for i in range(nr):
        u[i] = 0.0
        col4row[i] = -1
    v = np.empty(nc)
    spc = np.empty(nc)  # shortest path costs
    path = np.empty(nc, dtype=np.int64)
    row4col = np.empty(nc, dtype=np.int64)
    SC = np.empty(nc, dtype=np.bool_)
    remaining = np.empty(nc, dtype=np.int64)
    for j in range(nc):
        v[j] = 0.0
        path[j] = -1
        row4col[j] = -1
    for cur in range(nr):
        # augmenting path from row cur
        min_val = 0.0
        nrem = nc
        for it in range(nc):
            remaining[it] = nc - it - 1  # (reverse order: SciPy's, a constant matrix gives the identity)
            SC[it] = False
            spc[it] = np.inf
        for i in range(nr):
            SR[i] = False
        i = cur
        sink = -1
        while sink == -1:
            index = -1
            lowest = np.inf
            SR[i] = True
            base = i * nc
            ui = u[i]
            for it in range(nrem):
                j = remaining[it]
                r = min_val + c[base + j] - ui - v[j]
                if r < spc[j]:
                    path[j] = i
                    spc[j] = r
                # (ties: prefer a column that ends the path, SciPy's rule)
                if spc[j] < lowest or (spc[j] == lowest and row4col[j] == -1):
                    lowest = spc[j]
                    index = it
            min_val = lowest
            if min_val == np.inf:
                return LSAP_INFEASIBLE, a[:0], b[:0]
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            SC[j] = True
            nrem -= 1
            remaining[index] = remaining[nrem]
        # the dual variables
        u[cur] += min_val
        for i in range(nr):
            if SR[i] and i != cur:
                u[i] += min_val - spc[col4row[i]]
        for j in range(nc):
            if SC[j]:
                v[j] -= min_val - spc[j]
        # augment the previous solution along the path
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            jj = col4row[i]
            col4row[i] = j
            j = jj
            if i == cur:
                break
    if transpose:
        # by original row: the transposed problem's columns (original rows) in increasing order, each with its row
        # (original column); col4row's values are distinct, so any sort gives SciPy's order
        q = 0
        for r in range(nc):
            if row4col[r] >= 0:
                a[q] = r
                b[q] = row4col[r]
                q += 1
    else:
        for q in range(nr):
            a[q] = q
            b[q] = col4row[q]
    return LSAP_OK, a, b


@njit(cache=True)
def assign_groups(ok: np.ndarray, d2: np.ndarray, firm: np.ndarray, big: float) -> tuple:
    """The association's pairs (``Tracker._associate``): the cost ``np.where(ok, d2, big)`` of the (n tracks, m
    detections) gates ``ok`` and squared distances ``d2``; the established tracks (``firm``: (n,) bool, not
    tentative) choose first by :func:`lsap` over every detection, then the tentative ones over the detections they
    left (only those the established tracks' kept pairs took are removed); a pair stays only where ``ok`` allows it.
    Returns (status, track indices, detection indices): the established group's pairs by increasing track index,
    then the tentative group's; status as :func:`lsap` (the first group's failure stops)."""
    n, m = ok.shape
    k = min(n, m)
    ii = np.empty(k, dtype=np.int64)
    jj = np.empty(k, dtype=np.int64)
    npair = 0
    taken = np.empty(m, dtype=np.bool_)
    for j in range(m):
        taken[j] = False
    rows = np.empty(n, dtype=np.int64)
    cols = np.empty(m, dtype=np.int64)
    for g in range(2):  # the established tracks, then the tentative ones (one call site of the inlined solver)
        want = g == 0
        nrow = 0
        for i in range(n):
            if firm[i] == want:
                rows[nrow] = i
                nrow += 1
        if nrow == 0:
            continue
        ncol = 0
        for j in range(m):
            if not taken[j]:
                cols[ncol] = j
                ncol += 1
        if ncol == 0:
            continue
        # the group's cost matrix written straight in the solver's layout (lsap's copy of it, without a matrix
        # before it: one (nrow, ncol) buffer less per group)
        transpose = ncol < nrow
        c = np.empty(nrow * ncol)
        for r in range(nrow):
            ti = rows[r]
            for q in range(ncol):
                dj = cols[q]
                x = d2[ti, dj] if ok[ti, dj] else big
                if transpose:
                    c[q * nrow + r] = x
                else:
                    c[r * ncol + q] = x
        status, rr, cc = lsap_flat(c, nrow, ncol)
        if status != LSAP_OK:
            return status, ii[:0], jj[:0]
        for q in range(rr.shape[0]):
            ti = rows[rr[q]]
            dj = cols[cc[q]]
            if ok[ti, dj]:
                ii[npair] = ti
                jj[npair] = dj
                npair += 1
                taken[dj] = True
    return LSAP_OK, ii[:npair].copy(), jj[:npair].copy()


@njit(cache=True, inline="always")
def veto_merged(ok: np.ndarray, tsize: np.ndarray, det_ext: np.ndarray, rows: np.ndarray, vrows: np.ndarray,
                ms: np.ndarray, MEV: np.ndarray, WN: np.ndarray, stop: float, jump: float, smax: float) -> np.ndarray:
    """The veto of detections merged with structure (``Tracker._associate_update``; inlined in :func:`associate_scan`):
    ``ok`` ((n, m) bool, the gates) written False where a live track ``vrows[r]`` (indices of the tracks in M or
    merged, in their order) would take a candidate detection (``ms``: each detection's fraction of points on
    long-occupied map cells, ≥ ``stop``) whose longer side ``det_ext`` exceeds the track's larger size ``tsize`` by
    more than ``jump`` (m; a NaN size makes the threshold NaN, as ``float(tsize[i].max())``: nothing refused), if the
    track's own points were not on structure: its map-evidence window (``MEV[rows[i], :WN[rows[i], 0], 0]``, the
    structure fractions of its last updates) empty or of mean ≤ ``smax`` (summed as Python's ``sum`` of its floats
    sums them, on the running interpreter's version). Returns the vetoed tracks' indices, in ``vrows``' order (NaN
    compares False everywhere, as in the former Python test, docs/speed.md passes trk22, trk72)."""
    m = ok.shape[1]
    nv = vrows.shape[0]
    vetoed = np.empty(nv, dtype=np.int64)
    nhit = 0
    cand = np.empty(m if nv else 0, dtype=np.int64)
    nc = 0
    for j in range(cand.shape[0]):
        if ms[j] >= stop:
            cand[nc] = j
            nc += 1
    for r in range(nv if nc else 0):
        i = vrows[r]
        a = tsize[i, 0]
        b = tsize[i, 1]
        thr = (a if a >= b or a != a else b) + jump
        hit = False
        for c in range(nc):
            j = cand[c]
            if ok[i, j] and det_ext[j] > thr:
                hit = True
                break
        if not hit:
            continue
        row = rows[i]
        nm = WN[row, 0]
        if nm:
            # (Python's sum of the window's floats: 0 + the first, then the others left to right, compensated from
            # Python 3.12 on (Neumaier's improved Kahan–Babuška sum, CPython's ``builtin_sum_impl``: the compensation
            # added at the end where it is non-zero and finite))
            s = 0.0 + MEV[row, 0, 0]
            comp = 0.0
            for u in range(1, nm):
                x = MEV[row, u, 0]
                if _COMPENSATED_SUM:
                    t = s + x
                    if abs(s) >= abs(x):
                        comp += (s - t) + x
                    else:
                        comp += (x - t) + s
                    s = t
                else:
                    s += x
            if _COMPENSATED_SUM and comp != 0.0 and math.isfinite(comp):
                s += comp
            if not s / nm <= smax:
                continue
        for c in range(nc):
            j = cand[c]
            if ok[i, j] and det_ext[j] > thr:
                ok[i, j] = False
        vetoed[nhit] = i
        nhit += 1
    return vetoed[:nhit].copy()


@njit(cache=True)
def associate_scan(G: np.ndarray, Gi: np.ndarray, rows: np.ndarray, CI: np.ndarray, Xs: np.ndarray, Ps: np.ndarray,
                   Z: np.ndarray, R: np.ndarray, kind: np.ndarray, theta: np.ndarray, lohi: np.ndarray,
                   rel: np.ndarray, centroid: np.ndarray, circle: np.ndarray, px: np.ndarray, py: np.ndarray,
                   start: np.ndarray, npts: np.ndarray, q: np.ndarray, claimed: np.ndarray, vrows: np.ndarray,
                   ms: np.ndarray, MEV: np.ndarray, WN: np.ndarray, stop: float, jump: float, smax: float,
                   big: float) -> tuple:
    """``Tracker._associate`` in one call (docs/speed.md, pass trk75): :func:`~dynslam2d.detect.kernels_update.
    association_gates` (its arguments ``G`` … ``q``, the same function: the same floats), the detections another
    object claims taken out of every pair (``claimed``: (m,) bool, or empty for none: a dormant track's or a kept
    place's, found in Python), the veto of detections merged with structure, then :func:`assign_groups` with the
    cost ``big`` outside the gates.

    The veto: :func:`veto_merged` on the tracks ``vrows`` (empty without a map) with the thresholds ``stop``,
    ``jump`` (m), ``smax``. Returns (status, track indices, detection indices, missed, vetoed):
    :func:`assign_groups`' three, ``association_gates``' (n,) "missed their last scan" flags and the vetoed tracks'
    indices in ``vrows``' order (their ids join ``Tracker._merged``). One dispatch and no Python between the gates
    and the assignment instead of two kernel calls, the veto's list tests and the count of the
    pairs allowed (an empty gate gives no pair either way)."""
    tsize, d2, ok, det_ext, firm, missed = association_gates(G, Gi, rows, CI, Xs, Ps, Z, R, kind, theta, lohi, rel,
                                                             centroid, circle, px, py, start, npts, q)
    n, m = ok.shape
    if claimed.shape[0]:
        for j in range(m):
            if claimed[j]:
                for i in range(n):
                    ok[i, j] = False
    vetoed = veto_merged(ok, tsize, det_ext, rows, vrows, ms, MEV, WN, stop, jump, smax)
    status, ii, jj = assign_groups(ok, d2, firm, big)
    return status, ii, jj, missed, vetoed


@njit(cache=True)
def associate_update(F: np.ndarray, Fi: np.ndarray, Gi: np.ndarray, rows: np.ndarray, Z: np.ndarray, R: np.ndarray,
                     kind: np.ndarray, theta: np.ndarray, lohi: np.ndarray, rel: np.ndarray, centroid: np.ndarray,
                     circle: np.ndarray, px: np.ndarray, py: np.ndarray, start: np.ndarray, npts: np.ndarray,
                     q: np.ndarray, claimed: np.ndarray, vrows: np.ndarray, ms: np.ndarray, RIDE: np.ndarray,
                     bound: bool, lim: float, lim2: float, mfr: np.ndarray, kept: np.ndarray, first: np.ndarray,
                     second: np.ndarray, mnpts: np.ndarray, use_map: bool, lx: float, ly: float, c: float, s: float,
                     t: float, FQ: np.ndarray, predict: bool) -> tuple:
    """``Tracker._associate_update`` in one call: :func:`associate_scan` (its arguments by the same names), then,
    when it found pairs and its status is ``LSAP_OK``, :func:`dynslam2d.detect.kernels_update.update_pairs` on them
    (the pairs' track indices ``ii`` as its ``sel``, their detection indices ``jj`` as its ``dis``, the association's
    ``missed`` flags; ``X``, ``P``, ``CL``, ``RIDE``, ``bound`` … ``mnpts``, ``use_map``, the laser pose ``lx``,
    ``ly``, ``c``, ``s`` (m, map frame; cos and sin of its heading) and the stamp ``t`` (s) as that kernel's), the
    same two functions in the same order on the same arrays as the two calls they replace (nothing in Python between
    them fed the update: the same floats). Returns (status, vetoed, bounded rows, the longest riding window after the
    push, applied, unused, rejected pairs, man): :func:`associate_scan`'s status and vetoed tracks, ``update_pairs``'
    counts (0, 0 when no update ran), its pairs whose update applied with their ``info`` rows and the detections no
    such pair took (:func:`applied_pairs`: every detection when no update ran, none when the association failed),
    then ``update_pairs``' count of the pairs that did not apply (0 when no update ran). One dispatch and one unboxing
    of the ≈ 20 arrays both take instead of two, and no boxing of the pairs' arrays for the second call
    (docs/speed.md, pass trk108).

    Both kernels' predicted states ``Xs`` / ``Ps`` (the live tracks' rows, ``X[rows]``, ``P[rows]``: the prediction
    wrote them there, and nothing writes those rows before the association) are gathered here, and the merge veto's
    ``stop``, ``jump``, ``smax`` and the assignment's ``big`` read from ``q`` (columns ``UP_S_STOP`` …
    ``UP_BIG``, :func:`~dynslam2d.detect.kernels_update.update_params`): two arrays and four floats fewer to type
    and unbox a call (pass trk129). The tracker's row tables ``G``, ``X``, ``P``, ``CL``, ``MEV`` come as views of
    its float64 buffer ``F``, ``CI`` and ``WN`` of its int64 buffer ``Fi`` (:func:`~dynslam2d.detect.kernels_update.
    row_tables`, with ``Gi``'s row count): two arguments instead of seven (pass trk129).

    Then, with status ``LSAP_OK``, :func:`dynslam2d.detect.kernels_update.manage_scan` on the same ``rows`` at ``t``
    (``TrackManage._manage``'s counter tests, σ, speeds and bits of the live tracks: it reads only the state, counter
    and window rows, which nothing in Python writes between the update and the management; pass trk117): returned
    last as ``man`` (its four arrays), or empty arrays when the association failed (the caller raises).

    With ``predict``, first the scan's Kalman prediction of the live rows, ``Tracker._predict``'s
    :func:`~dynslam2d.detect.kernels.cv_predict` call (F = ``FQ[0]``, Q = ``FQ[1]``, (4, 4) each), which the tracker
    leaves to this call when nothing reads the rows between the two (no aspect prior, no stationary prediction):
    the same function on the same rows, so the same floats, one kernel dispatch a scan less (its arguments' unboxing
    in situ, where the dispatcher's per-signature code is not in the instruction cache, costs several times its warm
    price: docs/speed.md, pass trk145); its returned rows are ``Xs`` / ``Ps``."""
    X, P, G, CL, MEV, CI, WN = row_tables(F, Fi, Gi.shape[0])
    if predict:
        Xs, Ps = cv_predict(X, P, rows, FQ[0], FQ[1])
    else:
        Xs = X[rows]
        Ps = P[rows]
    status, ii, jj, missed, vetoed = associate_scan(G, Gi, rows, CI, Xs, Ps, Z, R, kind, theta, lohi, rel, centroid,
                                                    circle, px, py, start, npts, q, claimed, vrows, ms, MEV, WN,
                                                    q[UP_S_STOP], q[UP_MERGE_JUMP], q[UP_S_MAX], q[UP_BIG])
    if status != LSAP_OK:
        man0 = (np.empty(0, dtype=np.int8), np.empty(0), np.empty(0), np.empty(0, dtype=np.int64))
        return status, vetoed, 0, 0, np.empty((0, 6), dtype=np.int64), np.empty(0, dtype=np.int64), 0, man0
    nb, top, nrej = 0, 0, 0
    info = np.empty((0, 4), dtype=np.int64)
    if ii.shape[0]:
        nb, top, info, nrej = update_pairs(G, Gi, X, P, Xs, Ps, ii, rows, jj, missed, kind, theta, lohi, rel,
                                           centroid, circle, px, py, start, npts, q, bound, CI, CL, lim, lim2, mfr,
                                           kept, first, second, mnpts, MEV, RIDE, WN, use_map, lx, ly, c, s, t)
    man = manage_scan(P, X, CI, CL, WN, MEV, rows, q, t)
    applied, unused = applied_pairs(ii, jj, info, kind.shape[0])
    return status, vetoed, nb, top, applied, unused, nrej, man


@njit(cache=True, inline="always")
def applied_pairs(ii: np.ndarray, jj: np.ndarray, info: np.ndarray, m: int) -> tuple:
    """The pairs (track index ``ii``, detection index ``jj``) whose update applied, with their ``info`` rows
    (``update_pairs``': applied flag 1 or 2, the detection's first point and point count, its person's-circle flag),
    as one (na, 6) int64 array of rows [track index, detection index, flag, first point, point count, circle flag] in
    the pairs' order, and the indices of the ``m`` detections no applied pair took, increasing: what
    ``Tracker._update_tracks`` loops over and ``Tracker.update``'s unused detections (formerly a Python test of each
    pair's flag and of each detection against a set; pass trk138). Inlined in :func:`associate_update`."""
    n = ii.shape[0]
    na = 0
    for r in range(n):
        if info[r, 0] != 0:
            na += 1
    out = np.empty((na, 6), dtype=np.int64)
    taken = np.zeros(m, dtype=np.bool_)
    a = 0
    for r in range(n):
        if info[r, 0] != 0:
            out[a, 0] = ii[r]
            out[a, 1] = jj[r]
            for col in range(4):
                out[a, 2 + col] = info[r, col]
            taken[jj[r]] = True
            a += 1
    return out, np.flatnonzero(~taken).astype(np.int64)
