"""Batched numba kernels of the tracker's per-scan work (one call per scan, not per object).

The readable reference versions are :func:`dynslam2d.detect.reference.classify_and_bound`,
:func:`dynslam2d.detect.reference.measure` and
:class:`dynslam2d.detect.freespace.FreeTest`; the kernels here do the
same arithmetic for every cluster / pair / point of a scan in one pass, so that
``Tracker.update`` pays the Python overhead once per scan instead of once per detection
(issue 4, Speed). ``tests/test_detect_kernels.py`` checks them against the reference versions.

Frames: map frame (points already transformed with the scan's pose). Units m, rad.
Fit parameters travel as one float array built by :func:`fit_params` (fewer kernel arguments,
less dispatch overhead). The columns of the packed ``fits`` / ``lohi`` arrays and the kind codes are
named in :mod:`dynslam2d.detect.layout`.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.config import FitConfig
from dynslam2d.detect.layout import (
    F_CENTROID_X,
    F_CENTROID_Y,
    F_CIRCLE_R,
    F_CIRCLE_RMS,
    F_CIRCLE_X,
    F_CIRCLE_Y,
    F_HI1,
    F_HI2,
    F_LO1,
    F_LO2,
    F_RECT_RMS,
    F_THETA,
    K_CIRCLE,
    K_POINT,
    K_RECT,
    L_HI1,
    L_HI2,
    L_LO1,
    L_LO2,
    SIZE_LOWER,
    SIZE_MEASURED,
)
from dynslam2d.detect.mapevidence import map_evidence_kernel
from dynslam2d.detect.shapes import circle_center_fixed_radius
from dynslam2d.detect.vehicles import _admit_long
from dynslam2d.jitbox import njit, numba_import  # numba's njit (or the AOT kernels'), numba's names

_lir, _nbtypes, _intrinsic = numba_import("llvmlite.ir", "numba.core.types", "numba.extending.intrinsic")

# indices into the fit-parameter array
_P_POINT_MAX_POINTS = 0
_P_POINT_MAX_EXTENT = 1
_P_CIRCLE_MIN_POINTS = 2
_P_CIRCLE_MIN_RADIUS = 3
_P_CIRCLE_MAX_RADIUS = 4
_P_CIRCLE_RES_RATIO = 5
_P_CIRCLE_DEPTH_RATIO = 6
_P_FACE_TOL = 7
_P_MIN_FACE_SPAN = 8
_P_MIN_SIDE_POINTS = 9
_P_EDGE_MAX_GAP = 10
_P_EDGE_RANGE_JUMP = 11
_P_EDGE_LINE_TOL = 12
_P_SIGMA_POSITION = 13
_P_SIGMA_POINT = 14
_P_SIGMA_UNOBS = 15
_P_SIGMA_UNOBS_SPEED = 16
_P_DEFAULT_DEPTH = 17
_P_DEFAULT_DEPTH_RATIO = 18
_N_PARAMS = 19


def fit_params(cfg: FitConfig) -> np.ndarray:
    """The fit parameters the kernels need, packed in one float64 array."""
    p = np.empty(_N_PARAMS)
    p[_P_POINT_MAX_POINTS] = cfg.point_max_points
    p[_P_POINT_MAX_EXTENT] = cfg.point_max_extent
    p[_P_CIRCLE_MIN_POINTS] = cfg.circle_min_points
    p[_P_CIRCLE_MIN_RADIUS] = cfg.circle_min_radius
    p[_P_CIRCLE_MAX_RADIUS] = cfg.circle_max_radius
    p[_P_CIRCLE_RES_RATIO] = cfg.circle_residual_ratio
    p[_P_CIRCLE_DEPTH_RATIO] = cfg.circle_min_depth_ratio
    p[_P_FACE_TOL] = cfg.face_tolerance
    p[_P_MIN_FACE_SPAN] = cfg.min_face_span
    p[_P_MIN_SIDE_POINTS] = cfg.min_side_points
    p[_P_EDGE_MAX_GAP] = cfg.edge_max_gap
    p[_P_EDGE_RANGE_JUMP] = cfg.edge_range_jump
    p[_P_EDGE_LINE_TOL] = cfg.edge_line_tolerance
    p[_P_SIGMA_POSITION] = cfg.sigma_position
    p[_P_SIGMA_POINT] = cfg.sigma_point
    p[_P_SIGMA_UNOBS] = cfg.sigma_unobserved
    p[_P_SIGMA_UNOBS_SPEED] = cfg.sigma_unobserved_speed
    p[_P_DEFAULT_DEPTH] = cfg.default_depth
    p[_P_DEFAULT_DEPTH_RATIO] = cfg.default_depth_ratio
    return p


#: columns of :func:`detect_params`' array (``Tracker._det_p``): :func:`fit_params`' columns, then the detection
#: configuration's values :func:`detect_rows` reads, fixed for a tracker's life
DR_MAX_SKIP = _N_PARAMS  # SegmentConfig.max_skip_beams (an integer, exact in a float64)
DR_EXT_LIM = _N_PARAMS + 1  # vehicles.extent_limit: the classification's longest side, m
DR_ADMIT = _N_PARAMS + 2  # 1.0 where SegmentConfig.vehicle_max_extent > max_extent (the vehicle test runs), else 0.0
DR_SEG_MAX_EXTENT = _N_PARAMS + 3  # SegmentConfig.max_extent, m
DR_MAX_STRUCTURE = _N_PARAMS + 4  # SegmentConfig.vehicle_max_structure
DR_MIN_FREE = _N_PARAMS + 5  # SegmentConfig.vehicle_min_free
DR_OCC = _N_PARAMS + 6  # TrackerConfig.map_occupied_logodds
DR_FREE = _N_PARAMS + 7  # TrackerConfig.map_free_logodds
DR_FREE_RADIUS = _N_PARAMS + 8  # TrackerConfig.map_free_radius, cells (an integer, exact in a float64)
DR_MERGE = _N_PARAMS + 9  # 1.0 where FitConfig.person_merge, else 0.0
DR_LEG_MAX_EXTENT = _N_PARAMS + 10  # FitConfig.leg_max_extent, m
DR_PAIR_DISTANCE = _N_PARAMS + 11  # FitConfig.leg_pair_distance, m
_DR_N = _N_PARAMS + 12


def detect_params(fit_p: np.ndarray, sc, fc: FitConfig, tc, ext_lim: float) -> np.ndarray:
    """The parameters :func:`detect_rows` reads, packed in one float64 array built once per tracker: ``fit_p``
    (:func:`fit_params`' array, which the classification and ``measure_batch`` read; its columns first), then
    (columns ``DR_*``) the values of ``sc`` (the tracker's ``SegmentConfig``), ``fc`` (its ``FitConfig``), ``tc`` (its
    ``TrackerConfig``) and ``ext_lim`` (``vehicles.extent_limit``, m). One array argument instead of twelve scalars,
    each converted in Python and typed and unboxed by numba's dispatcher on every call (≈ 0.1 µs each in situ;
    docs/speed.md, passes trk48, trk49). The values are the same floats the scalars were; the integers and flags
    exact in a float64."""
    q = np.empty(_DR_N)
    q[:_N_PARAMS] = fit_p
    q[DR_MAX_SKIP] = int(sc.max_skip_beams)
    q[DR_EXT_LIM] = float(ext_lim)
    q[DR_ADMIT] = 1.0 if sc.vehicle_max_extent > sc.max_extent else 0.0
    q[DR_SEG_MAX_EXTENT] = float(sc.max_extent)
    q[DR_MAX_STRUCTURE] = float(sc.vehicle_max_structure)
    q[DR_MIN_FREE] = float(sc.vehicle_min_free)
    q[DR_OCC] = float(tc.map_occupied_logodds)
    q[DR_FREE] = float(tc.map_free_logodds)
    q[DR_FREE_RADIUS] = int(tc.map_free_radius)
    q[DR_MERGE] = 1.0 if fc.person_merge else 0.0
    q[DR_LEG_MAX_EXTENT] = float(fc.leg_max_extent)
    q[DR_PAIR_DISTANCE] = float(fc.leg_pair_distance)
    return q


@njit(cache=True)
def _pairwise_leaf(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's pairwise summation of a[lo:lo+n] for n ≤ 128 (8 interleaved partial sums)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0 = a[lo]
    r1 = a[lo + 1]
    r2 = a[lo + 2]
    r3 = a[lo + 3]
    r4 = a[lo + 4]
    r5 = a[lo + 5]
    r6 = a[lo + 6]
    r7 = a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's pairwise summation of a[lo:lo+n] (same rounding as ``ndarray.sum`` / ``mean``):
    blocks of ≤ 128 as :func:`_pairwise_leaf`, larger ranges split in two halves (n/2 rounded down
    to a multiple of 8). Iterative with an explicit stack (numba cannot cache recursive functions)."""
    if n <= 128:
        return _pairwise_leaf(a, lo, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    state = np.empty(64, dtype=np.int8)
    state[:] = 0
    vals = np.empty(64)
    top = 0
    vtop = 0
    los[0] = lo
    ns[0] = n
    while top >= 0:
        start = los[top]
        m = ns[top]
        if m <= 128:
            vals[vtop] = _pairwise_leaf(a, start, m)
            vtop += 1
            top -= 1
            continue
        n2 = m // 2
        n2 -= n2 % 8
        if state[top] == 0:
            state[top] = 1
            top += 1
            los[top], ns[top], state[top] = start, n2, 0
        elif state[top] == 1:
            state[top] = 2
            top += 1
            los[top], ns[top], state[top] = start + n2, m - n2, 0
        else:
            vals[vtop - 2] = vals[vtop - 2] + vals[vtop - 1]
            vtop -= 1
            top -= 1
    return vals[0]


@njit(cache=True)
def _endpoint_real(u: np.ndarray, v: np.ndarray, pos: int, k: int, lo_k: float, hi_k: float, beam: int, step: int,
                   ranges: np.ndarray, valid: np.ndarray, ax: np.ndarray, ay: np.ndarray, c: float, s: float,
                   wrapped: bool, max_skip: int, range_max: float, p: np.ndarray, su: float, sv: float,
                   dphi: float) -> bool:
    """Kernel twin of :func:`dynslam2d.detect.reference._endpoint_real` (uv split in u, v arrays)."""
    n = ranges.shape[0]
    r0 = u[pos] - su
    r1 = v[pos] - sv
    rn = math.hypot(r0, r1)
    if rn > 0.0:
        sin_b = abs(r1 if k == 0 else r0) / rn
        if rn * dphi / max(sin_b, 1e-3) > p[_P_EDGE_MAX_GAP]:
            return False
    j = beam
    found = -1
    for _ in range(max_skip + 1):
        j += step
        if wrapped:
            j %= n
        elif j < 0 or j >= n:
            return False
        if valid[j]:
            found = j
            break
    r_e = ranges[beam]
    if found < 0:
        return r_e < 0.95 * range_max
    r_j = ranges[found]
    if r_j < r_e - p[_P_EDGE_RANGE_JUMP]:
        return False
    qu = c * ax[found] + s * ay[found]
    qv = -s * ax[found] + c * ay[found]
    qk, qo = (qu, qv) if k == 0 else (qv, qu)
    wo = v[pos] if k == 0 else u[pos]
    tol = p[_P_FACE_TOL]
    if abs(qo - wo) < p[_P_EDGE_LINE_TOL] and (qk < lo_k + tol or qk > hi_k - tol):
        return False
    return True


@njit(cache=True, inline="always")  # (inlined into the segmentation kernel: compiled once there, pass det25)
def world_points(ranges: np.ndarray, valid: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray, c: float, s: float,
                 x: float, y: float, beams: np.ndarray) -> tuple:
    """The scan's beams in the map frame (pose ``x, y`` and cos / sin ``c, s`` of its θ; ``cos_a``, ``sin_a``: the
    beam angles' cos / sin; beams not ``valid`` at the pose's origin): (ax, ay) per beam, (px, py) = (ax, ay) of
    ``beams`` and the same as (m, 2) points, m. The arithmetic of :meth:`dynslam2d.types.Pose2D.transform_points`
    on ``r·(cos, sin)`` in the same order (one pass instead of eight numpy temporaries)."""
    n = ranges.shape[0]
    ax = np.empty(n)
    ay = np.empty(n)
    for i in range(n):
        r = ranges[i] if valid[i] else 0.0
        lx = r * cos_a[i]
        ly = r * sin_a[i]
        ax[i] = c * lx - s * ly + x
        ay[i] = s * lx + c * ly + y
    m = beams.shape[0]
    px = np.empty(m)
    py = np.empty(m)
    pts = np.empty((m, 2))
    for q in range(m):
        px[q] = ax[beams[q]]
        py[q] = ay[beams[q]]
        pts[q, 0] = px[q]
        pts[q, 1] = py[q]
    return ax, ay, px, py, pts


@njit(cache=True, inline="always")
def mask_fractions(masks: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(q, k) fraction of True in each segment ``masks[r, offsets[c]:offsets[c+1]]`` of each row r (0 for an empty
    segment): the count over the length, which is the value of :func:`segment_means` of the mask as 0 / 1 floats
    (every partial sum of 0 / 1 values is an exact integer, in any order)."""
    q = masks.shape[0]
    k = offsets.shape[0] - 1
    out = np.empty((q, k))
    out[:] = 0.0
    for r in range(q):
        for c in range(k):
            a = offsets[c]
            n = offsets[c + 1] - a
            if n > 0:
                cnt = 0
                for i in range(a, a + n):
                    if masks[r, i]:
                        cnt += 1
                out[r, c] = cnt / n
    return out


@njit(cache=True, inline="always")  # (inlined into merge_legs: compiled once there)
def merge_leg_pairs(first: np.ndarray, second: np.ndarray, px: np.ndarray, py: np.ndarray, beams: np.ndarray,
                    starts: np.ndarray, npts: np.ndarray, kinds: np.ndarray, fits: np.ndarray, lohi: np.ndarray,
                    rel: np.ndarray) -> tuple:
    """The per-detection arrays after ``Tracker._merge_legs`` merged the leg pairs (``first[r]``, ``second[r]``) into
    people (map frame, m): the detections in no pair first, in their order, then one per pair, in pair order.

    A person is measured with the point model at the middle of the legs' centroids, 0.5·(c_a + c_b), with the
    bounding box of both legs' points (lo = min, hi = max per coordinate; rectangle axis angle 0, no real bound);
    its points (``px``, ``py``) and ``beams`` are the first leg's then the second's, appended after the scan's
    points. Returns (kept detection indices, kinds, fits, lohi, rel, starts, npts, px, py, the persons' beams
    concatenated)."""
    m = first.shape[0]
    k = starts.shape[0]
    paired = np.empty(k, dtype=np.bool_)
    paired[:] = False
    added = 0
    for r in range(m):
        paired[first[r]] = True
        paired[second[r]] = True
        added += npts[first[r]] + npts[second[r]]
    nk = k - 2 * m
    ki = np.empty(nk, dtype=np.int64)
    q = 0
    for j in range(k):
        if not paired[j]:
            ki[q] = j
            q += 1
    nf = fits.shape[1]
    kinds2 = np.empty(nk + m, dtype=np.int8)
    kinds2[:] = 0
    fits2 = np.empty((nk + m, nf))
    fits2[:] = 0.0
    lohi2 = np.empty((nk + m, 4))
    rel2 = np.empty((nk + m, 2, 2), dtype=np.bool_)
    rel2[:] = False
    starts2 = np.empty(nk + m, dtype=np.int64)
    npts2 = np.empty(nk + m, dtype=np.int64)
    for q in range(nk):
        j = ki[q]
        kinds2[q] = kinds[j]
        for c in range(nf):
            fits2[q, c] = fits[j, c]
        for c in range(4):
            lohi2[q, c] = lohi[j, c]
        for u in range(2):
            for w in range(2):
                rel2[q, u, w] = rel[j, u, w]
        starts2[q] = starts[j]
        npts2[q] = npts[j]
    n0 = px.shape[0]
    px2 = np.empty(n0 + added)
    py2 = np.empty(n0 + added)
    mbeams = np.empty(added, dtype=np.int64)
    for i in range(n0):
        px2[i] = px[i]
        py2[i] = py[i]
    o = n0
    for r in range(m):
        row = nk + r
        lo0 = np.inf
        lo1 = np.inf
        hi0 = -np.inf
        hi1 = -np.inf
        starts2[row] = o
        for leg in range(2):
            j = first[r] if leg == 0 else second[r]
            a = starts[j]
            for i in range(a, a + npts[j]):
                x = px[i]
                y = py[i]
                px2[o] = x
                py2[o] = y
                mbeams[o - n0] = beams[i]
                o += 1
                lo0 = min(lo0, x)
                hi0 = max(hi0, x)
                lo1 = min(lo1, y)
                hi1 = max(hi1, y)
        npts2[row] = o - starts2[row]
        a = first[r]
        b = second[r]
        mx = 0.5 * (fits[a, F_CENTROID_X] + fits[b, F_CENTROID_X])
        my = 0.5 * (fits[a, F_CENTROID_Y] + fits[b, F_CENTROID_Y])
        fits2[row, F_CIRCLE_X] = mx
        fits2[row, F_CIRCLE_Y] = my
        fits2[row, F_CENTROID_X] = mx
        fits2[row, F_CENTROID_Y] = my
        lohi2[row, L_LO1] = lo0
        lohi2[row, L_LO2] = lo1
        lohi2[row, L_HI1] = hi0
        lohi2[row, L_HI2] = hi1
    return ki, kinds2, fits2, lohi2, rel2, starts2, npts2, px2, py2, mbeams


@njit(cache=True, inline="always")  # (inlined into detect_rows: compiled once there, pass fus40)
def merge_legs(px: np.ndarray, py: np.ndarray, beams: np.ndarray, starts: np.ndarray, npts: np.ndarray,
               kinds: np.ndarray, fits: np.ndarray, lohi: np.ndarray, rel: np.ndarray, mev: np.ndarray,
               leg_max_extent: float, pair_distance: float) -> tuple:
    """``Tracker._merge_legs``'s two kernels in one dispatch (docs/speed.md, pass detp5): the pairs of
    :func:`leg_pairs` (``leg_max_extent``, ``pair_distance``; m) and, when there is one, :func:`merge_leg_pairs` of
    them. Returns (first, second) followed by :func:`merge_leg_pairs`' ten results, the persons' points ``pts``
    ((added, 2): ``px2``, ``py2`` after the first ``len(px)``, m) and the merged rows' map evidence ``mmev``
    (3, nk + m): column nk + r of pair r is the point-weighted mean (na·e_a + nb·e_b) / (na + nb) of the legs'
    columns of ``mev`` (the detections' (3, nd) map evidence; (3, 0) without a map, then ``mmev`` is (3, 0) too; the
    kept rows' columns 0 … nk − 1 are not written: the kept detections read their own ``mev``). Without a pair the
    argument arrays themselves (numba returns an argument as its own Python object; ``mev`` as ``mmev``) and empty
    index / beam / point arrays (docs/speed.md, pass det33: the points and the evidence here, not per pair in
    Python)."""
    first, second = leg_pairs(lohi, npts, fits, leg_max_extent, pair_distance)
    if first.shape[0] == 0:
        return first, second, first, kinds, fits, lohi, rel, starts, npts, px, py, first, np.empty((0, 2)), mev
    ki, kinds2, fits2, lohi2, rel2, starts2, npts2, px2, py2, mbeams = merge_leg_pairs(
        first, second, px, py, beams, starts, npts, kinds, fits, lohi, rel)
    n0 = px.shape[0]
    added = mbeams.shape[0]
    pts = np.empty((added, 2))
    for i in range(added):
        pts[i, 0] = px2[n0 + i]
        pts[i, 1] = py2[n0 + i]
    m = first.shape[0]
    nk = ki.shape[0]
    if mev.shape[1] == 0:
        mmev = np.empty((3, 0))
    else:
        mmev = np.empty((3, nk + m))
        for r in range(m):
            a = first[r]
            b = second[r]
            na = npts[a]
            nb = npts[b]
            n = na + nb
            for e in range(3):
                mmev[e, nk + r] = (na * mev[e, a] + nb * mev[e, b]) / n
    return first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2, px2, py2, mbeams, pts, mmev


@njit(cache=True, inline="always")  # (inlined into detect_rows: compiled once there, pass fus40)
def classify_batch(px: np.ndarray, py: np.ndarray, beams: np.ndarray, offsets: np.ndarray, fits: np.ndarray,
                   structure: np.ndarray, sx: float, sy: float, ranges: np.ndarray, valid: np.ndarray,
                   ax: np.ndarray, ay: np.ndarray, wrapped: bool, max_skip: int, range_max: float, dphi: float,
                   max_extent: float, p: np.ndarray) -> tuple:
    """:func:`~dynslam2d.detect.reference.classify_and_bound` for every cluster of a scan.

    Args:
        px, py: map-frame points of the clusters (concatenated like ``beams``), m.
        beams, offsets, structure: the :class:`~dynslam2d.detect.segment.Segmentation`.
        fits: (k, N_FIT_COLS) rows of :func:`~dynslam2d.detect.shapes.fit_clusters` (columns
            :mod:`dynslam2d.detect.layout` ``F_*``).
        sx, sy: sensor position, map frame, m.
        ranges, valid: the scan's ranges (m) and beams with a return.
        ax, ay: map-frame points of all beams (0 range where invalid), m.
        max_extent: clusters whose fitted box is longer than this are structure, m.
        p: :func:`fit_params`.

    Returns:
        ``(keep, kind, lohi, rel)``: (k,) bool (a detection, not structure), (k,) int8 kind code
        (``K_*``), (k, 4) refined bounds lo1, lo2, hi1, hi2 (m; columns ``L_*``), (k, 2, 2) bool real bounds.
    """
    kc = offsets.shape[0] - 1
    keep = np.empty(kc, dtype=np.bool_)
    keep[:] = False
    kind = np.empty(kc, dtype=np.int8)
    kind[:] = 0
    lohi = np.empty((kc, 4))
    lohi[:] = 0.0
    rel = np.empty((kc, 2, 2), dtype=np.bool_)
    rel[:] = False
    tol = p[_P_FACE_TOL]
    span = p[_P_MIN_FACE_SPAN]
    nmax = 0
    for c in range(kc):
        nmax = max(nmax, offsets[c + 1] - offsets[c])
    u = np.empty(nmax)
    v = np.empty(nmax)
    sel = np.empty(nmax)
    for c in range(kc):
        if structure[c]:
            continue
        f = fits[c]
        if max(f[F_HI1] - f[F_LO1], f[F_HI2] - f[F_LO2]) > max_extent:
            continue
        keep[c] = True
        a = offsets[c]
        n = offsets[c + 1] - a
        theta = f[F_THETA]
        lo0, hi0, lo1, hi1 = f[F_LO1], f[F_HI1], f[F_LO2], f[F_HI2]
        ext0 = hi0 - lo0
        ext1 = hi1 - lo1
        lohi[c, L_LO1] = lo0
        lohi[c, L_LO2] = lo1
        lohi[c, L_HI1] = hi0
        lohi[c, L_HI2] = hi1
        if n <= p[_P_POINT_MAX_POINTS] or max(ext0, ext1) < p[_P_POINT_MAX_EXTENT]:
            kind[c] = K_POINT
            continue
        cr = f[F_CIRCLE_R]
        if (n >= p[_P_CIRCLE_MIN_POINTS] and p[_P_CIRCLE_MIN_RADIUS] <= cr <= p[_P_CIRCLE_MAX_RADIUS]
                and f[F_CIRCLE_RMS] < p[_P_CIRCLE_RES_RATIO] * f[F_RECT_RMS]
                and min(ext0, ext1) >= p[_P_CIRCLE_DEPTH_RATIO] * cr
                and math.hypot(f[F_CIRCLE_X] - sx, f[F_CIRCLE_Y] - sy)
                > math.hypot(f[F_CENTROID_X] - sx, f[F_CENTROID_Y] - sy)):
            kind[c] = K_CIRCLE
            continue
        kind[c] = K_RECT
        cs = math.cos(theta)
        sn = math.sin(theta)
        for i in range(n):
            u[i] = cs * px[a + i] + sn * py[a + i]
            v[i] = -sn * px[a + i] + cs * py[a + i]
        su = cs * sx + sn * sy
        sv = -sn * sx + cs * sy
        ext = (ext0, ext1)
        for k in range(2):
            wk = u if k == 0 else v
            wo = v if k == 0 else u
            sk = su if k == 0 else sv
            lok = lo0 if k == 0 else lo1  # (this axis' bounds as scalars, written back below: no arrays per cluster)
            hik = hi0 if k == 0 else hi1
            near = -1
            if sk < lok:
                near = 0
            elif sk > hik:
                near = 1
            face = False
            face_line = 0.0
            if near >= 0:
                b = lok if near == 0 else hik
                cnt = np.int64(0)  # not a literal 0: numba would type a first call with Literal[int](0)
                omin = np.inf
                omax = -np.inf
                for i in range(n):
                    if abs(wk[i] - b) < tol:
                        sel[cnt] = wk[i]
                        cnt += 1
                        omin = min(omin, wo[i])
                        omax = max(omax, wo[i])
                if cnt >= 2:
                    face = omax - omin >= span
                    # np.int64(0), not 0: a literal argument compiles another specialisation
                    face_line = _pairwise_sum(sel, np.int64(0), cnt) / cnt
                    if face:
                        if near == 0:
                            lok = face_line
                        else:
                            hik = face_line
            for side in range(2):
                b = lok if side == 0 else hik
                if face and side == near:
                    rel[c, k, side] = True
                    continue
                d0 = abs(wk[0] - b)
                d1 = abs(wk[n - 1] - b)
                if min(d0, d1) >= tol:
                    rel[c, k, side] = (not face) and ext[k] >= span
                    continue
                if face and ext[k] < span:
                    continue
                if face:
                    off = 0
                    for i in range(n):
                        if abs(wk[i] - face_line) > tol:
                            off += 1
                    if off < p[_P_MIN_SIDE_POINTS]:
                        continue
                pos = 0 if d0 <= d1 else n - 1
                step = -1 if pos == 0 else 1
                rel[c, k, side] = _endpoint_real(u, v, pos, k, lok, hik, beams[a + pos], step, ranges, valid,
                                                 ax, ay, cs, sn, wrapped, max_skip, range_max, p, su, sv, dphi)
            if k == 0:
                lo0 = lok
                hi0 = hik
            else:
                lo1 = lok
                hi1 = hik
        lohi[c, L_LO1] = lo0
        lohi[c, L_LO2] = lo1
        lohi[c, L_HI1] = hi0
        lohi[c, L_HI2] = hi1
    return keep, kind, lohi, rel


@njit(cache=True, inline="always")  # (inlined into detect_rows: compiled once there, pass fus40)
def select_detections(keep: np.ndarray, kinds: np.ndarray, lohi: np.ndarray, rel: np.ndarray, fits: np.ndarray,
                      offsets: np.ndarray, px: np.ndarray, py: np.ndarray, admit: bool, max_extent: float,
                      max_structure: float, min_free: float, has_map: bool, logodds: np.ndarray, i0: int, j0: int,
                      res: float, occ_thr: float, free_thr: float, free_radius: int) -> tuple:
    """The detections among a scan's classified clusters in one call: where ``admit`` the vehicle-size clusters' map
    test (:func:`~dynslam2d.detect.vehicles._admit_long` with ``max_extent``, ``max_structure``, ``min_free``; in
    place on ``keep``), then the kept clusters' rows and, where ``has_map``, their points' map evidence
    (:func:`~dynslam2d.detect.mapevidence.map_evidence_kernel` on ``logodds`` / ``i0`` / ``j0`` / ``res`` with the
    thresholds; map frame, m) as per-detection fractions (:func:`mask_fractions`). ``keep``, ``kinds``, ``lohi``,
    ``rel``: :func:`classify_batch`'s results; ``fits``, ``offsets``, ``px``, ``py``: its arguments. (The
    classification itself stays a call of its own: a kernel calling it would compile its body a second time.)

    Returns ``(starts, npts, kinds, lohi, rel, fits, fractions)``: the kept clusters' first point index into
    ``px`` / ``py`` and point counts (int64), their kind codes, bounds, real-bound flags and fit rows (copies of the
    kept rows), and (3, nd) fractions of their points on structure, free and unknown (zeros (3, 0) without a map)."""
    if admit:
        _admit_long(keep, fits, offsets, px, py, max_extent, has_map, logodds, i0, j0, res, occ_thr, free_thr,
                    free_radius, max_structure, min_free)
    k = keep.shape[0]
    nd = 0
    for c in range(k):
        if keep[c]:
            nd += 1
    idx = np.empty(nd, dtype=np.int64)
    q = 0
    for c in range(k):
        if keep[c]:
            idx[q] = c
            q += 1
    starts = np.empty(nd, dtype=np.int64)
    npts = np.empty(nd, dtype=np.int64)
    s_kinds = np.empty(nd, dtype=np.int8)
    s_lohi = np.empty((nd, lohi.shape[1]))
    s_rel = np.empty((nd, rel.shape[1], rel.shape[2]), dtype=np.bool_)
    s_fits = np.empty((nd, fits.shape[1]))
    total = 0
    for q in range(nd):
        c = idx[q]
        starts[q] = offsets[c]
        npts[q] = offsets[c + 1] - offsets[c]
        total += npts[q]
        s_kinds[q] = kinds[c]
        for a in range(lohi.shape[1]):
            s_lohi[q, a] = lohi[c, a]
        for a in range(rel.shape[1]):
            for b in range(rel.shape[2]):
                s_rel[q, a, b] = rel[c, a, b]
        for a in range(fits.shape[1]):
            s_fits[q, a] = fits[c, a]
    if not has_map:
        return starts, npts, s_kinds, s_lohi, s_rel, s_fits, np.empty((3, 0))
    det_px = np.empty(total)
    det_py = np.empty(total)
    det_off = np.empty(nd + 1, dtype=np.int64)
    det_off[0] = 0
    o = 0
    for q in range(nd):
        a = starts[q]
        for i in range(a, a + npts[q]):
            det_px[o] = px[i]
            det_py[o] = py[i]
            o += 1
        det_off[q + 1] = o
    ev = np.empty((3, total), dtype=np.bool_)
    ev[:] = False
    map_evidence_kernel(det_px, det_py, logodds, i0, j0, res, occ_thr, free_thr, free_radius, ev[0], ev[1], ev[2])
    return starts, npts, s_kinds, s_lohi, s_rel, s_fits, mask_fractions(ev, det_off)


@njit(cache=True)
def detect_rows(px: np.ndarray, py: np.ndarray, beams: np.ndarray, offsets: np.ndarray, fits: np.ndarray,
                structure: np.ndarray, sx: float, sy: float, ranges: np.ndarray, valid: np.ndarray, ax: np.ndarray,
                ay: np.ndarray, wrapped: bool, range_max: float, dphi: float, p: np.ndarray, has_map: bool,
                logodds: np.ndarray, i0: int, j0: int, res: float) -> tuple:
    """``Tracker._detect``'s three kernels that always run back to back in one call (docs/speed.md, pass fus40: each
    small kernel costs 2-4x its warm time inside a scan): :func:`classify_batch` (its 18 arguments, ``max_skip``
    and ``max_extent`` the columns ``DR_MAX_SKIP``, ``DR_EXT_LIM`` of ``p``), :func:`select_detections` (``admit``,
    its ``max_extent``, ``max_structure``, ``min_free`` and the map thresholds from ``p``'s ``DR_*`` columns,
    ``has_map`` and the map ``logodds`` / ``i0`` / ``j0`` / ``res``; map frame) and, where ``p[DR_MERGE]`` and there
    are two detections or more, :func:`merge_legs` (``leg_max_extent``, ``pair_distance`` from ``p``, m) on the
    selected rows and their map evidence. ``p``: :func:`detect_params`' array (the configuration's values, built once
    per tracker: one argument instead of twelve, docs/speed.md pass trk49).

    Returns ``select_detections``' seven results (the scan's detections: starts, npts, kinds, lohi, rel, fits,
    fractions), ``merge_legs``' fourteen (first, second, ki, kinds, fits, lohi, rel, starts, npts, px, py, mbeams,
    pts, mmev; with no pair: empty ``first`` / ``second`` / ``ki`` / ``mbeams`` / ``pts`` and the selected rows'
    arrays, ``px``, ``py`` and the fractions in the other places) and the final rows' (merged where a pair was
    merged) ``theta`` (nf,), ``centroid`` (nf, 2) and ``circle`` (nf, 3) fit columns as C-contiguous copies
    (``DetectionBatch``'s columns), then the final rows' default measurements, :func:`measure_batch`'s seven results
    (``MeasureRows``' fields) with no track prior (rows ``0 … nf − 1``, sizes 0 not given, radius −1, size σ 0)."""
    keep, kinds0, lohi0, rel0 = classify_batch(px, py, beams, offsets, fits, structure, sx, sy, ranges, valid, ax, ay,
                                               wrapped, int(p[DR_MAX_SKIP]), range_max, dphi, p[DR_EXT_LIM], p)
    starts, npts, kinds, lohi, rel, sfits, mfr = select_detections(
        keep, kinds0, lohi0, rel0, fits, offsets, px, py, p[DR_ADMIT] != 0.0, p[DR_SEG_MAX_EXTENT],
        p[DR_MAX_STRUCTURE], p[DR_MIN_FREE], has_map, logodds, i0, j0, res, p[DR_OCC], p[DR_FREE],
        int(p[DR_FREE_RADIUS]))
    if p[DR_MERGE] != 0.0 and starts.shape[0] > 1:
        first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2, px2, py2, mbeams, pts, mmev = merge_legs(
            px, py, beams, starts, npts, kinds, sfits, lohi, rel, mfr, p[DR_LEG_MAX_EXTENT], p[DR_PAIR_DISTANCE])
    else:
        first = np.empty(0, dtype=np.int64)
        second = first
        ki = first
        kinds2, fits2, lohi2, rel2, starts2, npts2, px2, py2 = kinds, sfits, lohi, rel, starts, npts, px, py
        mbeams = first
        pts = np.empty((0, 2))
        mmev = mfr
    nf = fits2.shape[0]
    theta = np.empty(nf)
    centroid = np.empty((nf, 2))
    circle = np.empty((nf, 3))
    # (and the default measurements' "no track prior" arguments below: every row its own detection, no sizes, no
    # radius, size σ 0 — np.empty and this loop rather than np.arange / np.zeros / np.full, whose implementations
    # would be compiled for this kernel alone)
    det = np.empty(nf, dtype=np.int64)
    sizes = np.empty((nf, 2))
    has_sizes = np.empty(nf, dtype=np.bool_)
    radius = np.empty(nf)
    size_sigma = np.empty(nf)
    for q in range(nf):
        theta[q] = fits2[q, F_THETA]
        centroid[q, 0] = fits2[q, F_CENTROID_X]
        centroid[q, 1] = fits2[q, F_CENTROID_Y]
        circle[q, 0] = fits2[q, F_CIRCLE_X]
        circle[q, 1] = fits2[q, F_CIRCLE_Y]
        circle[q, 2] = fits2[q, F_CIRCLE_R]
        det[q] = q
        sizes[q, 0] = 0.0
        sizes[q, 1] = 0.0
        has_sizes[q] = False
        radius[q] = -1.0
        size_sigma[q] = 0.0
    # the final rows' default measurements, as Tracker._measure_rows made them in a call of its own (pass trk41)
    z, R, H, zm, Rm, size_obs, size_kind = measure_batch(det, kinds2, theta, lohi2, rel2, centroid, circle, px2, py2,
                                                         starts2, npts2, sizes, has_sizes, radius, size_sigma, p)
    return (starts, npts, kinds, lohi, rel, sfits, mfr, first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2,
            px2, py2, mbeams, pts, mmev, theta, centroid, circle, z, R, H, zm, Rm, size_obs, size_kind)


@njit(cache=True)
def measure_batch(det: np.ndarray, kind: np.ndarray, theta: np.ndarray, lohi: np.ndarray, rel: np.ndarray,
                  centroid: np.ndarray, circle: np.ndarray, px: np.ndarray, py: np.ndarray, start: np.ndarray,
                  npts: np.ndarray, sizes: np.ndarray, has_sizes: np.ndarray, radius: np.ndarray,
                  size_sigma: np.ndarray, p: np.ndarray) -> tuple:
    """:func:`~dynslam2d.detect.reference.measure` for many (detection, track prior) rows.

    Row r measures detection ``det[r]`` (indices into the per-detection arrays ``kind``,
    ``theta``, ``lohi`` (lo1, lo2, hi1, hi2), ``rel``, ``centroid``, ``circle`` (the fields of
    :class:`dynslam2d.detect.tracker.DetectionBatch`) and its points
    ``px, py[start:start+npts]``) with the track's ``sizes[r]`` along the fit axes when
    ``has_sizes[r]`` (else the detection's default sizes), the track's ``radius[r]`` for circles
    when > 0, and ``size_sigma[r]`` (m).

    Returns:
        ``(z, R, H, zm, Rm, size_obs, size_kind)`` with the shapes of :class:`Measurement`
        stacked over rows: (r, 2), (r, 2, 2), (r, 2, 4), (r, 2), (r, 2, 2), (r, 2), (r, 2) int8.
    """
    nr = det.shape[0]
    z = np.empty((nr, 2))
    z[:] = 0.0
    R = np.empty((nr, 2, 2))
    R[:] = 0.0
    H = np.empty((nr, 2, 4))
    H[:] = 0.0
    zm = np.empty((nr, 2))
    zm[:] = 0.0
    Rm = np.empty((nr, 2, 2))
    Rm[:] = 0.0
    size_obs = np.empty((nr, 2))
    size_obs[:] = 0.0
    size_kind = np.empty((nr, 2), dtype=np.int8)
    size_kind[:] = 0
    sp2 = p[_P_SIGMA_POSITION] ** 2
    su2 = p[_P_SIGMA_UNOBS] ** 2
    sus2 = p[_P_SIGMA_UNOBS_SPEED] ** 2
    uv = np.empty(2)
    uv[:] = 0.0
    var = np.empty(2)
    var[:] = 0.0
    obs = np.empty(2, dtype=np.bool_)
    obs[:] = False
    sz = np.empty(2)
    sz[:] = 0.0
    for r in range(nr):
        j = det[r]
        kd = kind[j]
        if kd == K_POINT:
            s2 = p[_P_SIGMA_POINT] ** 2
            z[r, 0] = zm[r, 0] = centroid[j, 0]
            z[r, 1] = zm[r, 1] = centroid[j, 1]
            R[r, 0, 0] = R[r, 1, 1] = Rm[r, 0, 0] = Rm[r, 1, 1] = s2
            H[r, 0, 0] = H[r, 1, 1] = 1.0
            continue
        if kd == K_CIRCLE:
            cx, cy, cr = circle[j, 0], circle[j, 1], circle[j, 2]
            if radius[r] > 0:
                a = start[j]
                b = a + npts[j]
                cx, cy, _ = circle_center_fixed_radius(px[a:b].copy(), py[a:b].copy(), cx, cy, radius[r])
            s2 = (1.5 * p[_P_SIGMA_POSITION]) ** 2
            size_obs[r, 0] = size_obs[r, 1] = 2.0 * cr
            size_kind[r, 0] = size_kind[r, 1] = SIZE_MEASURED
            z[r, 0] = zm[r, 0] = cx
            z[r, 1] = zm[r, 1] = cy
            R[r, 0, 0] = R[r, 1, 1] = Rm[r, 0, 0] = Rm[r, 1, 1] = s2
            H[r, 0, 0] = H[r, 1, 1] = 1.0
            continue
        lo0, lo1, hi0, hi1 = lohi[j, L_LO1], lohi[j, L_LO2], lohi[j, L_HI1], lohi[j, L_HI2]
        ext0 = hi0 - lo0
        ext1 = hi1 - lo1
        if has_sizes[r]:
            sz[0] = sizes[r, 0]
            sz[1] = sizes[r, 1]
        else:  # Detection.default_sizes
            sz[0] = ext0
            sz[1] = ext1
            if not (rel[j, 0, 0] and rel[j, 0, 1]):
                sz[0] = max(ext0, min(p[_P_DEFAULT_DEPTH], p[_P_DEFAULT_DEPTH_RATIO] * max(ext1, 0.0)))
            if not (rel[j, 1, 0] and rel[j, 1, 1]):
                sz[1] = max(ext1, min(p[_P_DEFAULT_DEPTH], p[_P_DEFAULT_DEPTH_RATIO] * max(ext0, 0.0)))
        for k in range(2):
            lok = lo0 if k == 0 else lo1
            hik = hi0 if k == 0 else hi1
            ext_k = ext0 if k == 0 else ext1
            rl = rel[j, k, 0]
            rh = rel[j, k, 1]
            size_k = max(sz[k], ext_k)
            if has_sizes[r] and rl != rh:
                # one real bound: anchor on it with the track's own size; a view that grew past that size
                # re-anchors the track (Tracker._update_track), it is no motion (docs/tracking.md)
                size_k = sz[k]
            obs[k] = True
            size_kind[r, k] = SIZE_LOWER
            if rl and rh:
                uv[k] = 0.5 * (lok + hik)
                var[k] = sp2
                size_kind[r, k] = SIZE_MEASURED
            elif rl or rh:
                uv[k] = lok + 0.5 * size_k if rl else hik - 0.5 * size_k
                unc = size_sigma[r] if has_sizes[r] else 0.5 * size_k
                var[k] = sp2 + 0.25 * unc * unc
            else:
                uv[k] = 0.5 * (lok + hik)
                var[k] = su2
                obs[k] = False
        c = math.cos(theta[j])
        s = math.sin(theta[j])
        z[r, 0] = c * uv[0] - s * uv[1]
        z[r, 1] = s * uv[0] + c * uv[1]
        v0 = var[0]
        v1 = var[1]
        R[r, 0, 0] = c * c * v0 + s * s * v1
        R[r, 0, 1] = R[r, 1, 0] = c * s * (v0 - v1)
        R[r, 1, 1] = s * s * v0 + c * c * v1
        for k in range(2):
            e0, e1 = (c, s) if k == 0 else (-s, c)
            if obs[k]:
                H[r, k, 0] = e0
                H[r, k, 1] = e1
                zm[r, k] = uv[k]
                Rm[r, k, k] = var[k]
            else:
                H[r, k, 2] = e0
                H[r, k, 3] = e1
                Rm[r, k, k] = sus2
        size_obs[r, 0] = ext0
        size_obs[r, 1] = ext1
    return z, R, H, zm, Rm, size_obs, size_kind


@njit(cache=True, inline="always")
def kalman_update_batch(X: np.ndarray, P: np.ndarray, H: np.ndarray, zm: np.ndarray, Rm: np.ndarray) -> tuple:
    """Kalman updates of many tracks with 2-row linear measurements.

    ``S = H P Hᵀ + R``, ``K = P Hᵀ S⁻¹``, ``x ← x + K (z − H x)``, ``P ← sym(P − K H P)``.
    X (r, 4), P (r, 4, 4), H (r, 2, 4), zm (r, 2), Rm (r, 2, 2). Returns ``(X_new, P_new, ok)``;
    ok[i] is False (and row i untouched) when S is singular or the result is not finite.
    """
    nr = X.shape[0]
    Xn = X.copy()
    Pn = P.copy()
    ok = np.empty(nr, dtype=np.bool_)
    ok[:] = False
    PHt = np.empty((4, 2))
    K = np.empty((4, 2))
    KHP = np.empty((4, 4))
    HP = np.empty((2, 4))
    xn = np.empty(4)
    pn = np.empty((4, 4))
    for r in range(nr):
        h = H[r]
        pr = P[r]
        for i in range(4):
            for q in range(2):
                acc = 0.0
                for t in range(4):
                    acc += pr[i, t] * h[q, t]
                PHt[i, q] = acc
        s00 = Rm[r, 0, 0]
        s01 = Rm[r, 0, 1]
        s10 = Rm[r, 1, 0]
        s11 = Rm[r, 1, 1]
        for t in range(4):
            s00 += h[0, t] * PHt[t, 0]
            s01 += h[0, t] * PHt[t, 1]
            s10 += h[1, t] * PHt[t, 0]
            s11 += h[1, t] * PHt[t, 1]
        det = s00 * s11 - s01 * s10
        if det == 0.0 or not math.isfinite(det):
            continue
        i00 = s11 / det
        i01 = -s01 / det
        i10 = -s10 / det
        i11 = s00 / det
        y0 = zm[r, 0]
        y1 = zm[r, 1]
        for t in range(4):
            y0 -= h[0, t] * X[r, t]
            y1 -= h[1, t] * X[r, t]
        for i in range(4):
            K[i, 0] = PHt[i, 0] * i00 + PHt[i, 1] * i10
            K[i, 1] = PHt[i, 0] * i01 + PHt[i, 1] * i11
            xn[i] = X[r, i] + K[i, 0] * y0 + K[i, 1] * y1
        for q in range(2):
            for i in range(4):
                acc = 0.0
                for t in range(4):
                    acc += h[q, t] * pr[t, i]
                HP[q, i] = acc
        good = True
        for i in range(4):
            for q in range(4):
                KHP[i, q] = K[i, 0] * HP[0, q] + K[i, 1] * HP[1, q]
                pn[i, q] = pr[i, q] - KHP[i, q]
        for i in range(4):
            if not math.isfinite(xn[i]):
                good = False
            for q in range(4):
                val = 0.5 * (pn[i, q] + pn[q, i])
                if not math.isfinite(val):
                    good = False
                Pn[r, i, q] = val
        if not good:  # element-wise copies: no slice assignment (its shape-error formatting costs ~4 s cold)
            for i in range(4):
                for q in range(4):
                    Pn[r, i, q] = pr[i, q]
            continue
        for i in range(4):
            Xn[r, i] = xn[i]
        ok[r] = True
    return Xn, Pn, ok


@njit(cache=True)
def seen_through_refs(pts: np.ndarray, ranges_a: np.ndarray, par_a: np.ndarray, ranges_b: np.ndarray,
                      par_b: np.ndarray, nref: int, margin: float, free: np.ndarray) -> int:
    """OR into ``free`` the (n, 2) map-frame points ``pts`` that one of ``nref`` (1 or 2) reference scans saw
    through; returns how many points ``free`` then holds (the count of a detection's fraction: the references of
    a test in one call, no mask per reference; more references: further calls OR-ing into the same ``free``).

    Reference a (b): its ranges ``ranges_a`` (no return = inf) and ``par_a`` = (ix, iy, ith: the inverse of its
    laser pose, map → reference sensor frame; angle_min, increment, rad; full fan 1 / 0; reach: a no-return beam saw
    through everything closer, m). A reference with increment 0 or not finite has no beam
    geometry and sees nothing. The test of a point and a reference (:mod:`dynslam2d.detect.freespace`'s docstring):
    bearing and range in the reference sensor frame, the nearest beam and its two neighbours all farther than
    ρ + ``margin`` (or no return within reach); outside a partial fan is unknown.
    """
    n = pts.shape[0]
    ca = math.cos(par_a[2])
    sa = math.sin(par_a[2])
    cb = math.cos(par_b[2])
    sb = math.sin(par_b[2])
    count = 0
    for i in range(n):
        if free[i]:
            count += 1
            continue
        x = pts[i, 0]
        y = pts[i, 1]
        for r in range(nref):
            ranges = ranges_a if r == 0 else ranges_b
            par = par_a if r == 0 else par_b
            increment = par[4]
            if increment == 0.0 or not math.isfinite(increment):
                continue
            c = ca if r == 0 else cb
            s = sa if r == 0 else sb
            lx = c * x - s * y + par[0]
            ly = s * x + c * y + par[1]
            rho = math.hypot(lx, ly)
            phi = math.atan2(ly, lx)
            angle_min = par[3]
            m = ranges.shape[0]
            idx = int(np.rint((phi - angle_min) / increment))
            if par[5] != 0.0:
                idx %= m
            else:
                if idx < 0 or idx >= m:
                    idx = int(np.rint((phi + 2.0 * math.pi - angle_min) / increment))
                if not (idx >= 1 and idx < m - 1):
                    continue
            lo = (idx - 1) % m
            hi = (idx + 1) % m
            rmin = min(min(ranges[idx], ranges[lo]), ranges[hi])
            if math.isinf(rmin):
                beyond = rho < par[6] - margin
            else:
                beyond = rmin > rho + margin
            if beyond:
                free[i] = True
                count += 1
                break
    return count


@njit(cache=True)
def segment_means(values: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(k,) mean of ``values[offsets[c]:offsets[c+1]]`` (0 for an empty segment)."""
    k = offsets.shape[0] - 1
    out = np.empty(k)
    out[:] = 0.0
    for c in range(k):
        n = offsets[c + 1] - offsets[c]
        if n > 0:
            out[c] = _pairwise_sum(values, offsets[c], n) / n
    return out


@njit(cache=True, inline="always")
def fragment_hosts(px: np.ndarray, py: np.ndarray, start: np.ndarray, npts: np.ndarray, det: np.ndarray,
                   tx: np.ndarray, ty: np.ndarray, tth: np.ndarray, ts0: np.ndarray, ts1: np.ndarray,
                   margin: float) -> np.ndarray:
    """For each detection ``det[r]`` (points ``px, py[start:start+npts]``, map frame): the index of the
    box (centre tx, ty, axis angle tth, sizes ts0 along it and ts1 across, m) that holds every point
    with the least overshoot, when that overshoot is below ``margin`` (m); −1 for none. The overshoot
    of a point is max(|u| − s0/2, |v| − s1/2) in the box frame; ties keep the first box."""
    nr = det.shape[0]
    nt = tx.shape[0]
    out = np.empty(nr, dtype=np.int64)
    out[:] = -1
    for r in range(nr):
        j = det[r]
        a = start[j]
        n = npts[j]
        best_d = np.inf
        for i in range(nt):
            c = math.cos(tth[i])
            s = math.sin(tth[i])
            h0 = 0.5 * ts0[i]
            h1 = 0.5 * ts1[i]
            d = -np.inf
            for q in range(a, a + n):
                rx = px[q] - tx[i]
                ry = py[q] - ty[i]
                u = abs(rx * c + ry * s) - h0
                v = abs(-rx * s + ry * c) - h1
                d = max(d, max(u, v))
            if d < margin and d < best_d:
                best_d = d
                out[r] = i
    return out


@njit(cache=True, inline="always")
def gate_costs(Xs: np.ndarray, Ps: np.ndarray, reach: np.ndarray, rect_trk: np.ndarray, theta_box: np.ndarray,
               tsize: np.ndarray, Z: np.ndarray, R: np.ndarray, gate_distance: float, gate_chi2: float,
               kind: np.ndarray, theta: np.ndarray, lohi: np.ndarray, rel: np.ndarray, centroid: np.ndarray,
               circle: np.ndarray, px: np.ndarray, py: np.ndarray, start: np.ndarray, npts: np.ndarray,
               p: np.ndarray) -> tuple:
    """Association costs of n tracks × m detections (the tracker's gate, docs/tracking.md).

    d2[i, j]: Mahalanobis distance² of the centre innovation (predicted track i: state Xs, covariance
    Ps; detection j: default measurement Z, R). For a rectangle detection near a rectangle track with a
    heading (``rect_trk``), the detection is measured again with the track's own sizes (``tsize``
    along the track axis ``theta_box``, swapped when the fit axes are turned by 90°; size σ 0.05 m)
    and the smaller distance counts. near[i, j]: the detection's centroid lies within
    ``gate_distance`` + ``reach[i]`` of the track (m). ok = finite & d2 < ``gate_chi2`` & near.
    The remaining arguments are the detections' arrays as in :func:`measure_batch`.
    Returns ``(d2, near, ok)``.
    """
    n = Xs.shape[0]
    m = Z.shape[0]
    d2 = np.empty((n, m))
    near = np.empty((n, m), dtype=np.bool_)
    near[:] = False
    pi = np.empty(n * m, dtype=np.int64)
    pj = np.empty(n * m, dtype=np.int64)
    npair = 0
    for i in range(n):
        x0 = Xs[i, 0]
        x1 = Xs[i, 1]
        p00 = Ps[i, 0, 0]
        p01 = Ps[i, 0, 1]
        p10 = Ps[i, 1, 0]
        p11 = Ps[i, 1, 1]
        lim = gate_distance + reach[i]
        # the distance gate hypot(dx, dy) < lim without the hypot where dx² + dy² (float) decides it: that sum is
        # within 2.3e-16 relative of the exact one and libm's hypot within an ulp of its root, so a squared distance
        # 1e-9 relative below / above lim² (lim well inside the normal range) gives hypot's answer; else hypot
        lim2_in = -1.0
        lim2_out = np.inf
        if 1e-100 < lim < 1e100:
            lim2 = lim * lim
            lim2_in = lim2 * (1.0 - 1e-9)
            lim2_out = lim2 * (1.0 + 1e-9)
        for j in range(m):
            s00 = p00 + R[j, 0, 0]
            s01 = p01 + R[j, 0, 1]
            s10 = p10 + R[j, 1, 0]
            s11 = p11 + R[j, 1, 1]
            e0 = Z[j, 0] - x0
            e1 = Z[j, 1] - x1
            det_s = s00 * s11 - s01 * s10
            num = s11 * e0 ** 2 - 2.0 * s01 * e0 * e1 + s00 * e1 ** 2
            if det_s != 0.0:
                d2[i, j] = num / det_s
            elif num != 0.0 and not math.isnan(num):
                d2[i, j] = math.copysign(np.inf, num) * math.copysign(1.0, det_s)
            else:
                d2[i, j] = np.nan
            dx = centroid[j, 0] - x0
            dy = centroid[j, 1] - x1
            q = dx * dx + dy * dy
            if q < lim2_in:
                near[i, j] = True
            elif not q > lim2_out:  # (NaN or close to the limit: hypot decides)
                near[i, j] = math.hypot(dx, dy) < lim
            if near[i, j] and rect_trk[i] and kind[j] == K_RECT:
                pi[npair] = i
                pj[npair] = j
                npair += 1
    if npair:
        pi = pi[:npair]
        pj = pj[:npair]
        sizes = np.empty((npair, 2))
        for r in range(npair):
            i = pi[r]
            # Tracker._swapped: round half to even, as Python's round()
            q = np.int64(np.rint((theta[pj[r]] - theta_box[i]) / (0.5 * math.pi)))
            if q % 2 == 1:
                sizes[r, 0] = tsize[i, 1]
                sizes[r, 1] = tsize[i, 0]
            else:
                sizes[r, 0] = tsize[i, 0]
                sizes[r, 1] = tsize[i, 1]
        has = np.empty(npair, dtype=np.bool_)
        has[:] = True
        no_radius = np.empty(npair)
        no_radius[:] = -1.0
        sigma0 = np.empty(npair)
        sigma0[:] = 0.05
        res = measure_batch(pj, kind, theta, lohi, rel, centroid, circle, px, py, start, npts, sizes,
                            has, no_radius, sigma0, p)
        z2 = res[0]
        R2 = res[1]
        for r in range(npair):
            i = pi[r]
            j = pj[r]
            s00 = Ps[i, 0, 0] + R2[r, 0, 0]
            s01 = Ps[i, 0, 1] + R2[r, 0, 1]
            s10 = Ps[i, 1, 0] + R2[r, 1, 0]
            s11 = Ps[i, 1, 1] + R2[r, 1, 1]
            e0 = z2[r, 0] - Xs[i, 0]
            e1 = z2[r, 1] - Xs[i, 1]
            dd = s00 * s11 - s01 * s10
            if dd == 0.0:
                continue
            alt = (s11 * e0 ** 2 - (s01 + s10) * e0 * e1 + s00 * e1 ** 2) / dd  # e2ᵀ s2⁻¹ e2
            if not d2[i, j] <= alt:
                d2[i, j] = alt
    ok = np.empty((n, m), dtype=np.bool_)
    ok[:] = False
    for i in range(n):
        for j in range(m):
            ok[i, j] = math.isfinite(d2[i, j]) and d2[i, j] < gate_chi2 and near[i, j]
    return d2, near, ok


@njit(cache=True, inline="always")  # (inlined into merge_legs: compiled once there)
def leg_pairs(lohi: np.ndarray, npts: np.ndarray, fits: np.ndarray, leg_max_extent: float,
              pair_distance: float) -> tuple:
    """The pairs of legs that ``Tracker._merge_legs`` merges into people, in one pass (map frame, m).

    Legs: detections with ≥ 2 points whose extent (``lohi``, columns L_*) is at most ``leg_max_extent`` on both
    axes. Pairs: the leg pairs whose centroids (columns F_CENTROID_* of ``fits``, (m, N_FIT_COLS)) lie within
    ``pair_distance`` of each other, taken greedily nearest first (a stable sort of the distances in the row-major
    order of the legs' distance matrix), each leg at most once. Returns (first, second) detection indices of the
    pairs in the order taken, first < second. The distances are ``np.hypot`` of the coordinate differences (libm's
    hypot, as numpy's; not CPython's ``math.hypot``, whose last bit can differ)."""
    m = npts.shape[0]
    small = np.empty(m, dtype=np.int64)
    ns = 0
    for j in range(m):
        if npts[j] >= 2 and lohi[j, L_HI1] - lohi[j, L_LO1] <= leg_max_extent and \
                lohi[j, L_HI2] - lohi[j, L_LO2] <= leg_max_extent:
            small[ns] = j
            ns += 1
    empty = np.empty(0, dtype=np.int64)
    if ns < 2:
        return empty, empty
    flat = np.empty(ns * ns, dtype=np.int64)
    dist = np.empty(ns * ns)
    nc = 0
    for a in range(ns):
        ja = small[a]
        for b in range(ns):
            if a == b:
                continue  # (the diagonal: inf, never within reach)
            jb = small[b]
            d = np.hypot(fits[ja, F_CENTROID_X] - fits[jb, F_CENTROID_X],
                         fits[ja, F_CENTROID_Y] - fits[jb, F_CENTROID_Y])
            if d <= pair_distance:
                flat[nc] = a * ns + b
                dist[nc] = d
                nc += 1
    if nc == 0:
        return empty, empty
    # nearest first: a stable bottom-up merge sort of dist[:nc] (equal distances keep the row-major order), the
    # order np.argsort(kind="mergesort") gives (distances are ≤ pair_distance, never NaN), written out because
    # numba's argsort compiles its merge-sort machinery, about 1 s of a first run's compile (docs/speed.md)
    order = np.empty(nc, dtype=np.int64)
    for q in range(nc):
        order[q] = q
    buf = np.empty(nc, dtype=np.int64)
    width = 1
    while width < nc:
        for lo in range(0, nc, 2 * width):
            mid = min(lo + width, nc)
            hi = min(lo + 2 * width, nc)
            i = lo
            j = mid
            for o in range(lo, hi):
                if j < hi and (i >= mid or dist[order[j]] < dist[order[i]]):
                    buf[o] = order[j]
                    j += 1
                else:
                    buf[o] = order[i]
                    i += 1
        order, buf = buf, order
        width *= 2
    used = np.empty(ns, dtype=np.bool_)
    used[:] = False
    first = np.empty(ns // 2, dtype=np.int64)
    second = np.empty(ns // 2, dtype=np.int64)
    npair = 0
    for q in range(nc):
        f = flat[order[q]]
        a = f // ns
        b = f - a * ns
        if used[a] or used[b] or a > b:
            continue
        used[a] = True
        used[b] = True
        first[npair] = small[a]
        second[npair] = small[b]
        npair += 1
    return first[:npair], second[:npair]


@njit(cache=True, inline="always")
def size_jump_gate(ok: np.ndarray, lohi: np.ndarray, tmax: np.ndarray, known: np.ndarray, ratio: float,
                   jump: float) -> tuple:
    """The association's size-jump test (``Tracker._associate``) in one pass: (ok', det_ext) where det_ext (m,) is
    each detection's longer extent max(hi1 − lo1, hi2 − lo2) (m; NaN as numpy's maximum) and ok' = ok minus the
    pairs of a track whose size is ``known`` and a detection longer than ``ratio`` × the track's longest side
    ``tmax`` (m) + ``jump`` (m). ``ok`` is not written."""
    n, m = ok.shape
    ext = np.empty(m)
    for j in range(m):
        e1 = lohi[j, L_HI1] - lohi[j, L_LO1]
        e2 = lohi[j, L_HI2] - lohi[j, L_LO2]
        ext[j] = e1 if (e1 >= e2 or e1 != e1) else e2  # (np.maximum)
    out = np.empty((n, m), dtype=np.bool_)
    for i in range(n):
        lim = ratio * tmax[i] + jump
        kn = known[i]
        for j in range(m):
            out[i, j] = ok[i, j] and (ext[j] <= lim or not kn)
    return out, ext


@njit(cache=True, inline="always")
def accel_candidates(X_prior: np.ndarray, X_new: np.ndarray, lim2: float) -> np.ndarray:
    """Rows r whose velocity change from ``X_prior`` to ``X_new`` ((r, 4) states [x, y, vx, vy], m/s) has a squared
    norm above ``lim2`` ((m/s)²): the only rows the acceleration bound of ``Tracker._bound_acceleration`` tests
    exactly."""
    n = X_prior.shape[0]
    out = np.empty(n, dtype=np.int64)
    m = 0
    for r in range(n):
        dvx = X_new[r, 2] - X_prior[r, 2]
        dvy = X_new[r, 3] - X_prior[r, 3]
        if dvx * dvx + dvy * dvy > lim2:
            out[m] = r
            m += 1
    return out[:m]


# ------------------------------------------------------------------ the tracker's per-track shape state (rows)
# Columns of the tracker's per-track shape arrays (``Tracker._G`` float64, ``Tracker._Gi`` int8; one row per live
# track, the row of its Kalman state): the box's axis angle and sizes along it (tracks' own axes), the circle radius,
# the largest partial views per axis (m, rad, map frame); the kind code of its last detection, has-heading and the
# known-size flags per axis (0 / 1).
G_THETA, G_SIZE0, G_SIZE1, G_RADIUS, G_LB0, G_LB1 = 0, 1, 2, 3, 4, 5
N_G = 6
GI_KIND, GI_HEADING, GI_KNOWN0, GI_KNOWN1 = 0, 1, 2, 3
N_GI = 4
_HALF_PI = 0.5 * math.pi
_QUARTER_PI = 0.25 * math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True)
def pair_priors(G: np.ndarray, Gi: np.ndarray, rows: np.ndarray, det: np.ndarray, kind: np.ndarray,
                theta: np.ndarray) -> tuple:
    """The track priors of ``measure_batch`` for associated (track row ``rows[r]``, detection ``det[r]``) pairs, with
    the detections' kind codes and axis angles (rad) of the scan: (swap (r,) bool: the detection's first axis is the
    track's second (90° ambiguity of a box's axes), sizes (r, 2) the track's sizes along the detection's axes (m),
    has (r,) bool, radius (r,) the track's circle radius (m; −1: none)). A rectangle detection gets the sizes of a
    track that has a heading, a circle the radius of a circle track (the arithmetic of the tracker's pairs update,
    ``Tracker._associate_update``)."""
    n = rows.shape[0]
    swap = np.empty(n, dtype=np.bool_)
    swap[:] = False
    sizes = np.empty((n, 2))
    sizes[:] = 0.0
    has = np.empty(n, dtype=np.bool_)
    has[:] = False
    radius = np.empty(n)
    radius[:] = -1.0
    for r in range(n):
        k = rows[r]
        j = det[r]
        dk = kind[j]
        if dk == K_RECT:
            if Gi[k, GI_HEADING] != 0:
                sw = int(round((theta[j] - G[k, G_THETA]) / _HALF_PI)) % 2 == 1
                swap[r] = sw
                if sw:
                    sizes[r, 0] = G[k, G_SIZE1]
                    sizes[r, 1] = G[k, G_SIZE0]
                else:
                    sizes[r, 0] = G[k, G_SIZE0]
                    sizes[r, 1] = G[k, G_SIZE1]
                has[r] = True
        elif dk == K_CIRCLE and Gi[k, GI_KIND] == K_CIRCLE and G[k, G_RADIUS] > 0:
            radius[r] = G[k, G_RADIUS]
    return swap, sizes, has, radius


@njit(cache=True)
def _py_max(a: float, b: float) -> float:
    """Python's ``max(a, b)`` of two floats (the first unless the second is larger)."""
    return b if b > a else a


@njit(cache=True)
def shape_update(G: np.ndarray, Gi: np.ndarray, X: np.ndarray, rows: np.ndarray, det: np.ndarray,
                 applied: np.ndarray, kind: np.ndarray, theta: np.ndarray, lohi: np.ndarray, rel: np.ndarray,
                 circle: np.ndarray, size_obs: np.ndarray, size_kind: np.ndarray, swap: np.ndarray,
                 default_depth: float, default_depth_ratio: float, heading_gain: float, size_gain: float,
                 mfr: np.ndarray, kept: np.ndarray, first: np.ndarray, second: np.ndarray, npts: np.ndarray,
                 MEV: np.ndarray, RIDE: np.ndarray, WN: np.ndarray, use_map: bool, px: float, py: float, c: float,
                 s: float, t: float, ride_time: float, ride_n: int, ride_r2: float) -> int:
    """The shape update of the tracks of associated pairs (track row ``rows[r]``, detection ``det[r]``, where
    ``applied[r]``), in place on their rows of ``G`` / ``Gi`` (columns above) and, for a box grown past a partial
    view, of the states ``X`` (rows [x, y, vx, vy], m): a rectangle sets or smooths the heading (90° ambiguity;
    only an informative view: a real bound on each axis, or an extent longer than 0.3 m) and the sizes along the
    track's axes (measured: smoothed by ``size_gain``; a lower bound raises the largest partial view and grows the
    box away from its one real bound, its centre moving with it); a circle smooths the radius; a point detection of
    a point track takes its extent (at least 0.05 m). The kind becomes the detection's. ``size_obs`` / ``size_kind``
    / ``swap``: the measurement's per-axis sizes and kinds (``measure_batch``) and :func:`pair_priors`' swaps; the
    arithmetic, in order, of ``Tracker._update_tracks`` before the per-track arrays (docs/tracking.md, item 2).

    Then, in the same loop (one kernel call per scan: docs/speed.md, pass trk26), the riding and map-evidence
    windows of the updated track, pushed in place on its rows (``Tracker._update_tracks``' per-track lists before
    pass trk26). Each window is left-aligned: entries 0 … n − 1 of the row, oldest first; ``WN`` (rows, 3) holds
    per row n of ``MEV``, n of ``RIDE`` and the riding pre-test.

    * ``RIDE`` (rows, R, 5): (laser-frame x, y, map-frame x, y of the centre (m), stamp t (s)) per update; the centre
      is the row of ``X`` after the update (and the box growth above), the laser pose ``px``, ``py`` with cos / sin
      ``c``, ``s`` of its heading (map frame). The oldest entries are dropped while more than ``MEV.shape[1]``
      (sustain_updates) remain and the oldest is older than ``ride_time`` s. ``WN[k, 2]``: the riding test's
      pre-test of the new window — 0 fewer than ``ride_n`` entries (it cannot ride), 1 the last laser-frame centre
      farther than √``ride_r2`` from the laser, 2 near (``Tracker._manage`` asks ``_rides_with_laser``).
    * ``MEV`` (rows, sustain_updates, 3): the detection's map evidence (its fractions of points on long-occupied,
      observed-free, never-observed cells), the last sustain_updates kept; only with ``use_map``. ``mfr`` (3, nd):
      the scan's detections' before the leg merge (``select_detections``); with ``first`` not empty, a merge made
      detection j from detection ``kept[j]`` for j < len(kept), and the later ones from the pairs (``first[p]``,
      ``second[p]``): the point-weighted means of ``Tracker._merge_legs`` (``npts``: the points of the detections
      before the merge), in its Python order of operations.

    Returns the longest riding window after the push (the caller grows ``RIDE`` before it can overflow)."""
    nsus = MEV.shape[1]
    nkept = kept.shape[0]
    nmerged = first.shape[0]
    ns = -s
    top = 0
    for r in range(rows.shape[0]):
        if not applied[r]:
            continue
        k = rows[r]
        j = det[r]
        dk = kind[j]
        if dk == K_RECT:
            if Gi[k, GI_HEADING] == 0 or Gi[k, GI_KIND] != K_RECT:
                G[k, G_THETA] = theta[j]
                Gi[k, GI_HEADING] = 1
                # Detection.default_sizes: the extent where both bounds are real, else
                # max(extent, min(default_depth, default_depth_ratio · max(other extent, 0)))
                e0 = lohi[j, L_HI1] - lohi[j, L_LO1]
                e1 = lohi[j, L_HI2] - lohi[j, L_LO2]
                if rel[j, 0, 0] and rel[j, 0, 1]:
                    G[k, G_SIZE0] = e0
                else:
                    v = default_depth_ratio * _py_max(e1, 0.0)
                    G[k, G_SIZE0] = _py_max(e0, v if v < default_depth else default_depth)
                if rel[j, 1, 0] and rel[j, 1, 1]:
                    G[k, G_SIZE1] = e1
                else:
                    v = default_depth_ratio * _py_max(e0, 0.0)
                    G[k, G_SIZE1] = _py_max(e1, v if v < default_depth else default_depth)
                Gi[k, GI_KNOWN0] = 1 if size_kind[r, 0] == SIZE_MEASURED else 0
                Gi[k, GI_KNOWN1] = 1 if size_kind[r, 1] == SIZE_MEASURED else 0
            else:
                sw = swap[r]
                informative = (rel[j, 0, 0] or rel[j, 0, 1]) and (rel[j, 1, 0] or rel[j, 1, 1])
                if not informative:
                    informative = _py_max(lohi[j, L_HI1] - lohi[j, L_LO1], lohi[j, L_HI2] - lohi[j, L_LO2]) > 0.3
                if informative:
                    tb = G[k, G_THETA]
                    th = tb + heading_gain * ((theta[j] - tb + _QUARTER_PI) % _HALF_PI - _QUARTER_PI)
                    G[k, G_THETA] = (th + math.pi) % _TWO_PI - math.pi  # wrap_angle
                for a in range(2):
                    ta = 1 - a if sw else a
                    obs = size_obs[r, a]
                    sk = size_kind[r, a]
                    if sk == SIZE_MEASURED:
                        if Gi[k, GI_KNOWN0 + ta] != 0:
                            G[k, G_SIZE0 + ta] += size_gain * (obs - G[k, G_SIZE0 + ta])
                        else:
                            G[k, G_SIZE0 + ta] = obs
                            Gi[k, GI_KNOWN0 + ta] = 1
                    elif sk == SIZE_LOWER:
                        if obs > G[k, G_LB0 + ta]:
                            G[k, G_LB0 + ta] = obs
                        if obs > G[k, G_SIZE0 + ta]:
                            grow = obs - G[k, G_SIZE0 + ta]
                            lo_real = rel[j, a, 0]
                            if lo_real != rel[j, a, 1]:
                                sgn = 0.5 * grow if lo_real else -0.5 * grow
                                tha = theta[j] + a * _HALF_PI
                                X[k, 0] += sgn * math.cos(tha)
                                X[k, 1] += sgn * math.sin(tha)
                            G[k, G_SIZE0 + ta] = obs
        elif dk == K_CIRCLE:
            rad = circle[j, 2]
            kr = G[k, G_RADIUS]
            if Gi[k, GI_KIND] != K_CIRCLE or kr <= 0:
                G[k, G_RADIUS] = rad
            else:
                G[k, G_RADIUS] = kr + size_gain * (rad - kr)
            G[k, G_SIZE0] = 2.0 * G[k, G_RADIUS]
            G[k, G_SIZE1] = 2.0 * G[k, G_RADIUS]
        elif dk == K_POINT and Gi[k, GI_KIND] == K_POINT:
            G[k, G_SIZE0] = _py_max(lohi[j, L_HI1] - lohi[j, L_LO1], 0.05)
            G[k, G_SIZE1] = _py_max(lohi[j, L_HI2] - lohi[j, L_LO2], 0.05)
        Gi[k, GI_KIND] = dk
        # the windows (the former append, then `while len(ride) > nsus and t - ride[0][4] > ride_time: del ride[0]`:
        # the new entry is never older than ride_time, so the dropped ones are found before it is written)
        x0 = X[k, 0]
        x1 = X[k, 1]
        dx = x0 - px
        dy = x1 - py
        n = WN[k, 1]
        d = 0
        while n + 1 - d > nsus and t - RIDE[k, d, 4] > ride_time:
            d += 1
        if d:
            for q in range(n - d):
                for col in range(5):
                    RIDE[k, q, col] = RIDE[k, q + d, col]
            n -= d
        lx = c * dx + s * dy  # (no FMA: numba compiles without fast-math, as the former Python floats)
        ly = ns * dx + c * dy
        RIDE[k, n, 0] = lx
        RIDE[k, n, 1] = ly
        RIDE[k, n, 2] = x0
        RIDE[k, n, 3] = x1
        RIDE[k, n, 4] = t
        n += 1
        WN[k, 1] = n
        if n > top:
            top = n
        WN[k, 2] = 0 if n < ride_n else (1 if lx * lx + ly * ly > ride_r2 else 2)
        if use_map:
            m = WN[k, 0]
            if m == nsus:
                for q in range(m - 1):
                    for col in range(3):
                        MEV[k, q, col] = MEV[k, q + 1, col]
                m -= 1
            if nmerged == 0:
                for col in range(3):
                    MEV[k, m, col] = mfr[col, j]
            elif j < nkept:
                for col in range(3):
                    MEV[k, m, col] = mfr[col, kept[j]]
            else:
                a = first[j - nkept]
                b = second[j - nkept]
                na = npts[a]
                nb = npts[b]
                for col in range(3):
                    MEV[k, m, col] = (na * mfr[col, a] + nb * mfr[col, b]) / (na + nb)
            WN[k, 0] = m + 1
    return top


@njit(cache=True, inline="always")
def box_row(out: np.ndarray, i: int, X: np.ndarray, G: np.ndarray, k: int, circle: bool, moving: bool) -> None:
    """Row ``i`` of the reported boxes ``out`` (centre x, y, heading, length, width; m, rad, map frame) from the state
    row ``k``: a moving track headed along its velocity (a box: the axis nearest it, its sides swapped when that is
    the second axis), a still box along its longer side, a still circle at 0; a box's heading wrapped to [−π, π)
    (``Tracker._report``'s arithmetic; shared by :func:`report_boxes` and ``kernels_update.report_rows``)."""
    vx = X[k, 2]
    vy = X[k, 3]
    out[i, 0] = X[k, 0]
    out[i, 1] = X[k, 1]
    if circle:
        out[i, 2] = math.atan2(vy, vx) if moving else 0.0
        out[i, 3] = out[i, 4] = 2.0 * G[k, G_RADIUS]
        return
    sa = G[k, G_SIZE0]
    sb = G[k, G_SIZE1]
    tb = G[k, G_THETA]
    if moving:
        q = int(round(((math.atan2(vy, vx) - tb + math.pi) % _TWO_PI - math.pi) / _HALF_PI))
        theta = tb + q * _HALF_PI
        if q % 2 == 0:
            out[i, 3] = sa
            out[i, 4] = sb
        else:
            out[i, 3] = sb
            out[i, 4] = sa
    elif sb > sa:
        theta = tb + _HALF_PI
        out[i, 3] = sb
        out[i, 4] = sa
    else:
        theta = tb
        out[i, 3] = sa
        out[i, 4] = sb
    out[i, 2] = (theta + math.pi) % _TWO_PI - math.pi  # wrap_angle


@njit(cache=True)
def report_boxes(G: np.ndarray, Gi: np.ndarray, X: np.ndarray, rows: np.ndarray, slow: float,
                 fast: np.ndarray) -> tuple:
    """The reported boxes of the tracks of state rows ``rows``: (n, 5) centre x, y, heading, length, width (m, rad,
    map frame) and (n,) bool "undecided". A moving track (speed above ``slow``, m/s) is headed along its velocity (a
    box: the axis nearest it, its sides swapped when that is the second axis), a still box along its longer side, a
    still circle at 0; the heading of a box is wrapped to [−π, π) (``Tracker._report``'s arithmetic). ``fast`` (n,)
    int8: 1 / 0 the moving test's outcome given, −1 to test here; a speed within 1e-12 relative of ``slow`` is left
    undecided (its row not written: the caller decides with Python's ``math.hypot``, which may differ from this
    one by an ulp, and calls again)."""
    n = rows.shape[0]
    out = np.empty((n, 5))
    undecided = np.empty(n, dtype=np.bool_)
    undecided[:] = False
    for i in range(n):
        k = rows[i]
        vx = X[k, 2]
        vy = X[k, 3]
        f = fast[i]
        if f < 0:
            h = math.hypot(vx, vy)
            if abs(h - slow) <= 1e-12 * slow:
                undecided[i] = True
                continue
            moving = h > slow
        else:
            moving = f == 1
        box_row(out, i, X, G, k, Gi[k, GI_KIND] == K_CIRCLE, moving)
    return out, undecided


@njit(cache=True, inline="always")
def association_rows(G: np.ndarray, Gi: np.ndarray, rows: np.ndarray, missed: np.ndarray) -> tuple:
    """The association's per-track inputs from the shape rows ``rows`` of the live tracks (in their order):
    (sizes (n, 2) m, longest side (n,) m as numpy's maximum, rectangle with a heading (n,) bool, axis angle (n,) rad,
    size known (n,) bool: a track that ``missed`` its last scan and is not a rectangle or knows both sizes — the
    size-jump gate applies to it)."""
    n = rows.shape[0]
    tsize = np.empty((n, 2))
    tmax = np.empty(n)
    rect = np.empty(n, dtype=np.bool_)
    theta = np.empty(n)
    known = np.empty(n, dtype=np.bool_)
    for i in range(n):
        k = rows[i]
        s0 = G[k, G_SIZE0]
        s1 = G[k, G_SIZE1]
        tsize[i, 0] = s0
        tsize[i, 1] = s1
        tmax[i] = s0 if (s0 >= s1 or s0 != s0) else s1  # (np.maximum)
        kr = Gi[k, GI_KIND] == K_RECT
        rect[i] = kr and Gi[k, GI_HEADING] != 0
        theta[i] = G[k, G_THETA]
        known[i] = missed[i] and (not kr or (Gi[k, GI_KNOWN0] != 0 and Gi[k, GI_KNOWN1] != 0))
    return tsize, tmax, rect, theta, known


@njit(cache=True)
def manage_rows(P: np.ndarray, X: np.ndarray, rows: np.ndarray, speed: np.ndarray, max_sig: float) -> tuple:
    """The management's per-track tests from the state rows ``rows`` of the live tracks (in their order) and their
    ``speed`` (n,) m/s (Python's ``math.hypot`` of the velocity, given: libm's hypot here can differ by an ulp):
    (n,) bool "covariance fails" (an entry of P not finite, or sqrt(max(P[0, 0], P[1, 1])) > ``max_sig``, m) and
    (n,) σ of the speed along the velocity, m/s (uᵀ P_v u with u = v / speed, or sqrt(max(P[2, 2], P[3, 3])) at a
    speed ≤ 1e-9; 0 where the covariance fails). ``Tracker._manage``'s former Python arithmetic in the same order
    (each operation rounded alone; max(a, b) is a unless b > a)."""
    n = rows.shape[0]
    bad = np.empty(n, dtype=np.bool_)
    bad[:] = False
    sig = np.empty(n)
    sig[:] = 0.0
    for i in range(n):
        k = rows[i]
        fin = True
        for a in range(4):
            for b in range(4):
                if not np.isfinite(P[k, a, b]):
                    fin = False
        p00 = P[k, 0, 0]
        p11 = P[k, 1, 1]
        if not fin or math.sqrt(p11 if p11 > p00 else p00) > max_sig:
            bad[i] = True
            continue
        p22 = P[k, 2, 2]
        p33 = P[k, 3, 3]
        s = speed[i]
        if s > 1e-9:
            u0 = X[k, 2] / s
            u1 = X[k, 3] / s
            q = (u0 * p22 + u1 * P[k, 3, 2]) * u0 + (u0 * P[k, 2, 3] + u1 * p33) * u1
            sig[i] = math.sqrt(0.0 if 0.0 > q else q)
        else:
            sig[i] = math.sqrt(p33 if p33 > p22 else p22)
    return bad, sig


@_intrinsic
def _fma(typingctx, a, b, c):
    """a·b + c rounded once (LLVM's ``llvm.fma.f64``, the FMA instruction where the CPU has one): the operation the
    BLAS dgemm kernels (OpenBLAS) accumulate a matrix product with."""
    sig = _nbtypes.float64(_nbtypes.float64, _nbtypes.float64, _nbtypes.float64)

    def codegen(context, builder, signature, args):
        d = _lir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], _lir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True)
def cv_predict(X: np.ndarray, P: np.ndarray, rows: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple:
    """The Kalman prediction x' = F x, P' = F P Fᵀ + Q of the state rows ``rows`` (n ≥ 2 of them) of ``X`` (rows, 4)
    and ``P`` (rows, 4, 4), map frame; F, Q (4, 4) the constant-velocity transition and noise. Returns the predicted
    (n, 4) states and (n, 4, 4) covariances (arrays of their own), and writes them into the rows too.

    Bit for bit numpy's ``X[rows] @ F.T`` and ``F @ P[rows] @ F.T + Q`` with OpenBLAS: each entry of a product is
    its dgemm kernel's sum over k = 0 … 3 from 0.0, one FMA per term (fma(a_ik, b_kj, acc)), the product F P
    rounded before it is multiplied by Fᵀ, Q added after. (With one row numpy takes the matrix-vector path, gemv,
    whose sums are not these: the caller keeps numpy's products for n < 2.)"""
    n = rows.shape[0]
    Xo = np.empty((n, 4))
    Po = np.empty((n, 4, 4))
    T = np.empty((4, 4))
    for r in range(n):
        q = rows[r]
        for i in range(4):
            acc = 0.0
            for k in range(4):
                acc = _fma(X[q, k], F[i, k], acc)
            Xo[r, i] = acc
        for i in range(4):
            for j in range(4):
                acc = 0.0
                for k in range(4):
                    acc = _fma(F[i, k], P[q, k, j], acc)
                T[i, j] = acc
        for i in range(4):
            for j in range(4):
                acc = 0.0
                for k in range(4):
                    acc = _fma(T[i, k], F[j, k], acc)
                Po[r, i, j] = acc + Q[i, j]
        for i in range(4):
            X[q, i] = Xo[r, i]
            for j in range(4):
                P[q, i, j] = Po[r, i, j]
    return Xo, Po
