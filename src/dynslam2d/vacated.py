"""The pipeline's per-scan vacated-footprint trace in one kernel call (docs/maps.md, "Vacated footprints").

:class:`VacatedTrace` gives the map view the tracker's map evidence reads for one scan: the finest map level, with
the outlines of long-occupied cells that this scan sees through (a parked vehicle driving off) counted as observed
free. It is :func:`dynslam2d.slam.cleanup.scan_clearing` followed by
:func:`dynslam2d.detect.mapevidence.vacated_outlines`, :meth:`VacatedHistory.persistent` and
:func:`yielding_view`, with the same values, but the scan's clearing geometry, the trace through the map and the
outlines' growth run in one kernel call on parameters packed once per pipeline and on work buffers kept between
scans (the separate calls cost about as much Python and allocation as the trace itself; docs/speed.md).

Frames and units: the laser pose in the map frame (m, rad); the clearing geometry in world cell units (m / the
level's resolution), as in :mod:`dynslam2d.slam.cleanup`.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.mapevidence import MapView, VacatedHistory, VacatedOutlines, vacated_core, yielding_view
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.cleanup import _scan_geometry
from dynslam2d.types import Pose2D, Scan

#: Index of each parameter in :attr:`VacatedTrace.params` (what :func:`vacated_scan_kernel` reads).
_RES, _MARGIN, _GRAZING, _MIN_SIN, _CORE, _OCC, _DEPTH, _NEAR, _OCC32, _MAX_SIDE, _MIN_CELLS, _MIN_EXTENT, \
    _MIN_SHARE = range(13)
#: The per-scan choice's cost model, in cells of the walk's first pass (≈ 0.85–1.0 ns each): the walk costs its
#: cells (Σ over the clearing beams of their longer axis' extent less the depth) + ``_WALK_BEAM`` a beam; the inverse
#: form ``_INV_WORD`` a bitmap word of the reach's box + ``_INV_CELL`` a long-occupied cell enumerated in it (fitted by
#: least squares on every call of sim:paper, sim:crowd, negative_2 /right, positive_1 and MIT CSAIL with both forms
#: timed; it picks the faster form on all but ≈ 1 % of their total time; docs/speed.md, pass vac83)
_WALK_BEAM = 9.0
_INV_WORD = 4.0
_INV_CELL = 30.0
#: After a count of the cells over the budget, the choice keeps the walk for this many scans less one without looking
#: (the count costs about as much as the inverse form's enumeration; the cells in reach change slowly between scans)
_RECOUNT = 8
#: Long-occupied cells the inverse form takes at most, per beam (beyond: the walk)
_CELLS_PER_BEAM = 16
#: de Bruijn sequence and table: the index of a 64-bit word's lowest set bit from one multiplication (Leiserson,
#: Prokop & Randall, "Using de Bruijn sequences to index a 1 in a computer word", 1998)
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_DB_TABLE = np.array([0, 1, 48, 2, 57, 49, 28, 3, 61, 58, 50, 42, 38, 29, 17, 4, 62, 55, 59, 36, 53, 51, 43, 22, 45, 39,
                      33, 30, 24, 18, 12, 5, 63, 47, 56, 27, 60, 41, 37, 16, 54, 35, 52, 21, 44, 32, 23, 11, 46, 26, 40,
                      15, 34, 20, 31, 10, 25, 14, 19, 9, 13, 8, 7, 6], dtype=np.int64)


@njit(cache=True, inline="always")
def _atan2_approx(y: float, x: float) -> float:  # pragma: no cover - numba
    """atan2(``y``, ``x``) within 1.2e-5 rad, in (−π, π]: a degree-9 odd polynomial in the octant's ratio (|z| ≤ 1;
    Abramowitz & Stegun, Handbook of Mathematical Functions, 4.4.49's form). Branch-free (selects only), so a loop
    calling it vectorises; the octant's ratio min / max is the smaller coordinate over the larger (0 at the origin)."""
    ax = abs(x)
    ay = abs(y)
    hi = max(ax, ay)
    z = min(ax, ay) / (hi if hi > 0.0 else 1.0)
    z2 = z * z
    t = z * (0.9998660 + z2 * (-0.3302995 + z2 * (0.1801410 + z2 * (-0.0851330 + z2 * 0.0208351))))
    t = 0.5 * math.pi - t if ax < ay else t
    t = math.pi - t if x < 0.0 else t
    return -t if y < 0.0 else t


@njit(cache=True, error_model="numpy")
def seen_through_inverse(logodds: np.ndarray, i0: int, j0: int, ox: float, oy: float, cx: np.ndarray, cy: np.ndarray,
                         clear: np.ndarray, core: float, occ_thr: float, depth: float, bits: np.ndarray, ang0: float,
                         inc: float, th: float, out_r: np.ndarray, out_c: np.ndarray, iw: np.ndarray, fw: np.ndarray,
                         cell: float) -> int:  # pragma: no cover - numba
    """:func:`dynslam2d.detect.mapevidence.seen_through_structure_kernel`'s cells (the same cells with the same
    repeats, in another order) found from the other side, or −1 (nothing found) where its walk costs less.

    The walk steps along every clearing ray from the laser (``ox``, ``oy``, world cells) to find the few cells with
    log-odds ≥ ``occ_thr`` it passes. Here the cells whose bit is set in ``bits`` (the level's long-occupied bitmap,
    a superset of them: ``GridLevel.occ_bits`` for a threshold ≤ ``occ_thr``) within the largest clearing reach are
    enumerated (their log-odds re-read: a stale bit is left out) and each is tested against the beams that can pass
    it, with the walk's own terms: the walk records cell (a, ib) (a on the beam's major axis) at step a when ``ib =
    floor(b + 0.5)`` with ``b = n0 + slope · (a − m0)``, ``|b − ib| ≤ core``, a in its walked range and the cell within
    the reach (the first pass only bounds the second; the free steps near the laser only leave out steps without such
    a cell). Such a beam passes within ``core`` ≤ 0.5 of the cell's centre, so its direction (beam k at ``th +
    ang0 + k · inc``, rad: a scan's beams are uniform) is within asin(core / d) ≤ 1.003 · core / d (d ≥ 4 cells from
    the laser) of the cell's, found to 1.2e-5 rad (:func:`_atan2_approx`; + 8e-6 rad for the beams' own rounding);
    every beam is tested for d < 4.

    Runs only where the cost model (``_WALK_BEAM``, ``_INV_WORD``; ``cell``: the cost of an enumerated cell, ≤ 0:
    always) says it costs less than the walk and the cells fit the buffer ``iw`` (int64, 2 · ``_CELLS_PER_BEAM`` ·
    beams + 3 · beams; ``fw`` float64, 2 · beams, + 2 kept between scans: the last count, for its callers' checks,
    and the scans left to decline: after a count over the budget the next ``_RECOUNT`` − 1 scans decline at once);
    −1 else, and when more than ``out_r``' length are found (the walk's cap then decides which it keeps)."""
    h, w = logodds.shape
    nb = cx.shape[0]
    if nb < 3:
        return -1
    mem = fw.shape[0] >= 2 * nb + 2
    if mem and cell > 0.0 and fw[2 * nb + 1] > 0.0:  # (a count over the budget fewer than _RECOUNT scans ago)
        fw[2 * nb + 1] -= 1.0
        return -1
    # (1) the walk's cost (Σ of the clearing rays' longer extents short of ``depth``, cells) and the largest clearing
    # distance
    span = 0.0
    r2max = 0.0
    for k in range(nb):
        dx = cx[k] - ox
        dy = cy[k] - oy
        span += max(max(abs(dx), abs(dy)) - depth, 0.0) if clear[k] else 0.0
        r2max = max(r2max, dx * dx + dy * dy if clear[k] else 0.0)
    rmax = math.sqrt(r2max) - depth
    if not rmax > 0.0:
        return -1
    # (2) the long-occupied cells within rmax + 1 of the laser, as many as the walk's cost leaves room for
    r_lo = max(int(math.floor(oy - rmax)) - 1 - j0, 0)
    r_hi = min(int(math.ceil(oy + rmax)) + 1 - j0, h - 1)
    c_lo = max(int(math.floor(ox - rmax)) - 1 - i0, 0)
    c_hi = min(int(math.ceil(ox + rmax)) + 1 - i0, w - 1)
    capc = _CELLS_PER_BEAM * nb
    most = capc
    if cell > 0.0:  # (cell ≤ 0: always, if the buffer holds them)
        budget = span + _WALK_BEAM * nb - _INV_WORD * max(r_hi - r_lo + 1, 0) * max((c_hi >> 6) - (c_lo >> 6) + 1, 0)
        most = min(capc, int(budget / cell)) if budget > 0.0 else -1
        if mem:  # (the count if it stops over the budget, and the scans to decline then; both reset below)
            fw[2 * nb] = most + 1.0
            fw[2 * nb + 1] = _RECOUNT - 1.0
        if most < 0:
            return -1
    m = 0
    for r in range(r_lo, r_hi + 1):
        for wd in range(c_lo >> 6, (c_hi >> 6) + 1):
            word = bits[r, wd]
            while word != 0:
                low = word & (~word + np.uint64(1))
                word ^= low
                c = (wd << 6) + _DB_TABLE[(low * _DEBRUIJN) >> np.uint64(58)]
                if c < c_lo or c > c_hi or logodds[r, c] < occ_thr:
                    continue
                if m >= most:
                    return -1
                iw[2 * m] = r
                iw[2 * m + 1] = c
                m += 1
    if mem:
        fw[2 * nb] = m
        fw[2 * nb + 1] = 0.0
    # (3) every beam's walk as the walk sets it up: axis, slope, walked major range [alo, ahi], reach²
    # (xm, alo, ahi: iw from ``ixm``, ``ixm + nb``, ``ixm + 2 nb``; sl, rr2: fw from 0 and nb, indexed there rather
    # than as five slices, each ≈ 180 LLVM instructions to compile; pass cmp149)
    ixm = 2 * capc
    ilo = ixm + nb
    ihi = ilo + nb
    for k in range(nb):
        fw[nb + k] = -1.0  # (no walk: the distance test below fails for it)
    for k in range(1, nb - 1):
        if not (clear[k] and clear[k - 1] and clear[k + 1]):
            continue
        reach = math.sqrt(min(min((cx[k - 1] - ox) ** 2 + (cy[k - 1] - oy) ** 2,
                                  (cx[k + 1] - ox) ** 2 + (cy[k + 1] - oy) ** 2),
                              (cx[k] - ox) ** 2 + (cy[k] - oy) ** 2)) - depth
        if not reach > 0.0:
            continue
        dx = cx[k] - ox
        dy = cy[k] - oy
        x_major = abs(dx) >= abs(dy)
        if x_major:
            a0 = int(math.floor(ox + 0.5))
            a1 = int(math.floor(cx[k] + 0.5))
            slope = dy / dx if dx != 0.0 else 0.0
            m0 = ox
            a_off, a_len = i0, w
        else:
            a0 = int(math.floor(oy + 0.5))
            a1 = int(math.floor(cy[k] + 0.5))
            slope = dx / dy
            m0 = oy
            a_off, a_len = j0, h
        along = (reach + 0.5) / math.sqrt(1.0 + slope * slope)
        if a1 >= a0:
            start = max(a0, a_off)
            cnt = min(min(a1, int(math.floor(m0 + along)) + 1), a_off + a_len - 1) - start + 1
            lo, hi = start, start + cnt - 1
        else:
            start = min(a0, a_off + a_len - 1)
            cnt = start - max(max(a1, int(math.ceil(m0 - along)) - 1), a_off) + 1
            lo, hi = start - cnt + 1, start
        if cnt <= 0:
            continue
        iw[ixm + k] = 1 if x_major else 0
        fw[k] = slope
        iw[ilo + k] = lo
        iw[ihi + k] = hi
        fw[nb + k] = reach * reach
    # (4) each cell against the beams that can pass it
    cap = out_r.shape[0]
    n = 0
    two_pi = 2.0 * math.pi
    inv_2pi = 1.0 / two_pi
    inv_inc = 1.0 / inc
    inv_abs = abs(inv_inc)
    turn = two_pi * inv_inc  # (beams a turn; floor / ceil with a window of ≥ 1 beam absorb this product's rounding)
    # (4a) each cell's distance², beam index and half window (beams) in one branch-free loop (it vectorises: the
    # kernel's error model lets its divisions go unchecked; none divides by zero but the unused 1 / d at the laser)
    kw = np.empty(3 * m)
    cw = 1.003 * core
    for q in range(m):
        ddx = (iw[2 * q + 1] + i0) - ox
        ddy = (iw[2 * q] + j0) - oy
        d2 = ddx * ddx + ddy * ddy
        phi = _atan2_approx(ddy, ddx) - th - ang0
        phi -= two_pi * math.floor(phi * inv_2pi)  # [0, 2π)
        kw[3 * q] = d2
        kw[3 * q + 1] = phi * inv_inc
        kw[3 * q + 2] = (cw / math.sqrt(d2) + 2e-5) * inv_abs
    # (4b) the beams of each cell's window (the wrapped windows, sh = ±1, only where they can hold a beam)
    for q in range(m):
        r = iw[2 * q]
        c = iw[2 * q + 1]
        x = c + i0
        y = r + j0
        d2 = kw[3 * q]
        d = math.sqrt(d2)
        if d > rmax + 1.0:
            continue
        near = d < 4.0
        kc = kw[3 * q + 1]
        hw = kw[3 * q + 2]
        for sh in range(0 if near else -1, 1 if near else 2):
            if near:
                k_lo, k_hi = 1, nb - 2
            else:
                kk = kc + sh * turn
                if (sh < 0 and not kk + hw > 0.0) or (sh > 0 and not kk - hw < nb - 1.0):
                    continue  # (ceil(kk + hw) < 1, floor(kk − hw) > nb − 2: empty)
                k_lo = max(int(math.floor(kk - hw)), 1)
                k_hi = min(int(math.ceil(kk + hw)), nb - 2)
            for k in range(k_lo, k_hi + 1):
                # (the walk's last test first: (a − m0)² + (ib − n0)² is this sum in either axis order)
                if not d2 <= fw[nb + k]:
                    continue
                if iw[ixm + k]:
                    a, ibc, m0, n0 = x, y, ox, oy
                else:
                    a, ibc, m0, n0 = y, x, oy, ox
                if a < iw[ilo + k] or a > iw[ihi + k]:
                    continue
                b = n0 + fw[k] * (a - m0)
                ib = int(math.floor(b + 0.5))
                if ib != ibc or abs(b - ib) > core:
                    continue
                if n >= cap:
                    return -1
                out_r[n] = r
                out_c[n] = c
                n += 1
    return n


@njit(cache=True)
def vacated_scan_kernel(ranges: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray, valid: np.ndarray, px: float,
                        py: float, th: float, logodds: np.ndarray, i0: int, j0: int, params: np.ndarray,
                        work: np.ndarray, window: np.ndarray, fwork: np.ndarray, bits: np.ndarray, bits_thr: float,
                        ang0: float, inc: float) -> tuple[int, int, np.ndarray]:  # pragma: no cover - numba
    """One scan's vacated outlines: the clearing geometry of the beams (``ranges``, m, with their ``cos_a`` /
    ``sin_a`` and ``valid`` returns) from the laser at (``px``, ``py``, ``th``) (map frame, m, rad) as
    :func:`dynslam2d.slam.cleanup.scan_clearing` makes it, then :func:`vacated_core` on the map ``logodds``
    (column 0 / row 0 at absolute cell ``i0`` / ``j0``) with the parameters ``params`` (indices ``_RES`` …
    ``_MIN_SHARE``: the arguments of :func:`dynslam2d.detect.mapevidence.vacated_outlines_kernel` that do not
    change between scans) and the buffers ``work`` (int64, at least 2 · 64 · beams + 2 · (max_side² + 1)) and
    ``window`` (uint8, all 0, (2 · max_side + 1)²).
    With the map's long-occupied bitmap ``bits`` (``GridLevel.occ_bits`` of ``logodds`` for ``bits_thr`` ≤ the
    parameters' threshold; else a (0, 0) array), the scan's first beam angle ``ang0`` and increment ``inc`` (rad),
    the seen-through cells come from :func:`seen_through_inverse` where it costs less than the walk (the same cells:
    the same result), with ``work`` longer by 2 · ``_CELLS_PER_BEAM`` · beams + 3 · beams and ``fwork`` (float64,
    2 · beams + 2, the last 2 kept between scans: 0 at first).

    Returns the number of distinct seen-through cells, the number of yielding outlines and, when there are any,
    one array holding their rows, their columns and their sizes one after the other (else an empty one)."""
    res = params[_RES]
    max_side = int(params[_MAX_SIDE])
    n = ranges.shape[0]
    # (``removed`` only makes the geometry's ``kept``, which is not read here: ``valid`` stands in for it)
    _, _, cx, cy, _, clear = _scan_geometry(ranges, cos_a, sin_a, valid, valid, px, py, th, res, params[_MARGIN],
                                            params[_GRAZING], params[_MIN_SIN])
    c = 64 * n
    g = max_side * max_side + 1
    ox = px / res
    oy = py / res
    n_seen = -1
    w_a = work[:c]  # (each slice once: a slice is ≈ 180 LLVM instructions to compile; pass cmp149)
    w_b = work[c:2 * c]
    if bits.shape[0] == logodds.shape[0] and bits.shape[1] == (logodds.shape[1] + 63) >> 6 and \
            bits_thr <= params[_OCC]:
        n_seen = seen_through_inverse(logodds, i0, j0, ox, oy, cx, cy, clear, params[_CORE], params[_OCC],
                                      params[_DEPTH], bits, ang0, inc, th, w_a, w_b, work[2 * c + 2 * g:], fwork,
                                      _INV_CELL)
    rows, cols, sizes, nc = vacated_core(
        logodds, i0, j0, ox, oy, cx, cy, clear, params[_CORE], params[_OCC], params[_DEPTH],
        params[_NEAR], np.float32(params[_OCC32]), max_side, int(params[_MIN_CELLS]), res, params[_MIN_EXTENT],
        params[_MIN_SHARE], w_a, w_b, work[2 * c:2 * c + g], work[2 * c + g:2 * c + 2 * g], window,
        n_seen)
    k = sizes.shape[0]
    if k == 0:
        return nc, 0, w_a[:0]
    total = rows.shape[0]
    out = np.empty(2 * total + k, dtype=np.int64)
    for q in range(total):  # (loops: a slice assignment compiles numba's shape-mismatch message, ≈ 17 helpers)
        out[q] = rows[q]
        out[total + q] = cols[q]
    for q in range(k):
        out[2 * total + q] = sizes[q]
    return nc, k, out


class VacatedTrace:
    """The vacated-footprint trace of one pipeline: its parameters, work buffers and persistence history.

    Args:
        clean: the clean-up pass's beam geometry (margins, grazing incidence, ray core; docs/maps.md).
        occupied_logodds: long-occupied threshold of the map evidence (``detect.tracker.map_occupied_logodds``).
        min_cells, max_extent, min_depth_m, min_share, scans: ``detect.tracker.map_vacate_*`` (m where a length).
        min_extent: an outline must be longer than this to yield, m (``detect.segment.max_extent``).
        near_logodds: log-odds above which a cell belongs to an outline.

    The parameters are read once, here; :meth:`view` is called once per scan, in time order.
    """

    def __init__(self, clean: CleanConfig, *, occupied_logodds: float, min_cells: int, max_extent: float,
                 min_depth_m: float, min_extent: float, min_share: float, scans: int,
                 near_logodds: float = 0.5) -> None:
        self.clean = clean
        self.occupied_logodds = float(occupied_logodds)
        self.min_cells = int(min_cells)
        self.max_extent = float(max_extent)
        self.min_depth_m = float(min_depth_m)
        self.min_extent = float(min_extent)
        self.min_share = float(min_share)
        self.near_logodds = float(near_logodds)
        self.history = VacatedHistory(scans)
        self.params = np.zeros(0)  # made for the map's resolution at the first scan (_prepare)
        self._res = math.nan
        self._beams = -1
        self._work = np.zeros(0, dtype=np.int64)
        self._fwork = np.zeros(0)
        self._window = np.zeros((0, 0), dtype=np.uint8)

    def _prepare(self, res: float, beams: int) -> None:
        """The parameters for cells of ``res`` (m) and buffers for ``beams`` beams (the values
        :func:`dynslam2d.detect.mapevidence.vacated_outlines` passes its kernel)."""
        if res != self._res:
            c = self.clean
            max_side = max(int(math.ceil(self.max_extent / res)), 1)
            self.params = np.array([res, float(c.margin_m), float(c.grazing_cells),
                                    math.sin(math.radians(c.min_incidence_deg)), float(c.ray_core),
                                    self.occupied_logodds, self.min_depth_m / res, self.near_logodds,
                                    float(np.float32(self.occupied_logodds)), float(max_side), float(self.min_cells),
                                    self.min_extent, self.min_share], dtype=np.float64)
            self._res = res
            self._window = np.zeros((2 * max_side + 1, 2 * max_side + 1), dtype=np.uint8)
        g = int(self.params[_MAX_SIDE]) ** 2 + 1
        self._work = np.empty(128 * beams + 2 * g + (2 * _CELLS_PER_BEAM + 3) * beams, dtype=np.int64)
        self._fwork = np.zeros(2 * beams + 2)  # (+ 2: the choice's last count)
        self._beams = beams

    def view(self, view: MapView, scan: Scan, pose: Pose2D) -> MapView:
        """``view`` (the finest map level) as the tracker's map evidence reads it for ``scan`` at ``pose``: the
        outlines that yield and persisted (:class:`VacatedHistory`) count as observed free (a copy; else ``view``
        itself). Remembers this scan's candidates."""
        ranges = scan.ranges
        n = ranges.shape[0]
        if self.min_cells <= 0:
            return view
        if n == 0:  # (a scan without beams has no candidate: it breaks a persistence run)
            self.history.none()
            return view
        res = view.resolution
        if res != self._res or n != self._beams:
            self._prepare(res, n)
        cos_a, sin_a = scan.trig()
        valid = scan.valid_view()  # (the kernel only reads it: no copy)
        nc, k, out = vacated_scan_kernel(ranges, cos_a, sin_a, valid, float(pose.x), float(pose.y),
                                         float(pose.theta), view.logodds, view.i0, view.j0, self.params, self._work,
                                         self._window, self._fwork, view.occ_bits, view.occ_bits_thr,
                                         float(scan.angle_min), float(scan.angle_increment))
        if k == 0:  # no candidate (most scans)
            self.history.none()
            return view
        total = (out.shape[0] - k) // 2
        vac = VacatedOutlines(out[:total], out[total:2 * total], nc, k, tuple(out[2 * total:].tolist()))
        return yielding_view(view, self.history.persistent(view, vac))

