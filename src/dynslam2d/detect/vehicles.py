"""Vehicle-size clusters: tracked only where the SLAM map has seen free space (docs/maps.md).

``detect.segment.max_extent`` (3 m) makes every cluster whose fitted rectangle has a longer side
static structure: that keeps walls out of the tracker, but also a 4 m car or a 5 m van.
A cluster longer than ``max_extent`` and at most ``vehicle_max_extent`` is kept as a detection
only where the map is the witness that the object is not a wall (the same per-point evidence
as the tracker's, :mod:`dynslam2d.detect.mapevidence`):

* at most ``vehicle_max_structure`` of its points lie on long-occupied map cells (a wall the
  robot has mapped is long-occupied; a vehicle that stood long enough to be written into the
  map is too, so a parked vehicle stays structure until it has left its place), and
* at least ``vehicle_min_free`` of its points lie in cells earlier scans saw through (a vehicle
  driving over the floor; a wall seen for the first time is in unknown cells, never free).

Without a map (the first scan, or ``detect.tracker.map_evidence: false``) no long cluster is kept.
Frames: map frame; units m.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.layout import F_HI1, F_HI2, F_LO1, F_LO2
from dynslam2d.detect.mapevidence import MapView, map_evidence_kernel
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle


def extent_limit(config: DetectConfig) -> float:
    """The longest fitted rectangle side any cluster may have to be classified, m."""
    seg = config.segment
    return max(seg.max_extent, seg.vehicle_max_extent)


@njit(cache=True, inline="always")
def long_kept(keep: np.ndarray, fits: np.ndarray, max_extent: float) -> np.ndarray:
    """Indices (ascending, int64) of the kept clusters (``keep``) whose fitted rectangle (``fits`` rows,
    :func:`~dynslam2d.detect.shapes.fit_clusters`) has a side longer than ``max_extent`` (m): numpy's
    ``flatnonzero(keep & (maximum(hi1 − lo1, hi2 − lo2) > max_extent))`` in one pass (a NaN side is never longer,
    as ``np.maximum`` propagates it)."""
    out = np.empty(keep.shape[0], dtype=np.int64)
    m = 0
    for c in range(keep.shape[0]):
        if not keep[c]:
            continue
        e1 = fits[c, F_HI1] - fits[c, F_LO1]
        e2 = fits[c, F_HI2] - fits[c, F_LO2]
        if e1 != e1 or e2 != e2:
            continue
        if e1 > max_extent or e2 > max_extent:
            out[m] = c
            m += 1
    return out[:m]


@njit(cache=True, inline="always")
def _admit_long(keep: np.ndarray, fits: np.ndarray, offsets: np.ndarray, px: np.ndarray, py: np.ndarray,
                max_extent: float, has_map: bool, logodds: np.ndarray, i0: int, j0: int, res: float, occ_thr: float,
                free_thr: float, free_radius: int, max_structure: float, min_free: float) -> int:
    """:func:`admit_long_clusters` in one call (``has_map`` False: no map view, ``logodds`` unused). The long clusters'
    points are tested by :func:`~dynslam2d.detect.mapevidence.map_evidence_kernel` in one batch, as
    :func:`~dynslam2d.detect.mapevidence.map_evidence` tests them; a cluster's shares are its point counts over its
    point count (exact integers in float64, as numpy's ``add.reduceat`` of the 0 / 1 flags sums them), compared
    with the limits as numpy compares them (a NaN share, 0 / 0, is never within them)."""
    long_ = long_kept(keep, fits, max_extent)
    nl = long_.shape[0]
    if nl == 0:
        return 0
    if not has_map:
        for q in range(nl):
            keep[long_[q]] = False
        return 0
    total = 0
    for q in range(nl):
        total += offsets[long_[q] + 1] - offsets[long_[q]]
    qx = np.empty(total)
    qy = np.empty(total)
    o = 0
    for q in range(nl):
        for i in range(offsets[long_[q]], offsets[long_[q] + 1]):
            qx[o] = px[i]
            qy[o] = py[i]
            o += 1
    structure = np.empty(total, dtype=np.bool_)  # (the kernel writes every entry of the three)
    free = np.empty(total, dtype=np.bool_)
    unknown = np.empty(total, dtype=np.bool_)
    map_evidence_kernel(qx, qy, logodds, i0, j0, res, occ_thr, free_thr, free_radius, structure, free, unknown)
    kept = 0
    o = 0
    for q in range(nl):
        c = long_[q]
        n = offsets[c + 1] - offsets[c]
        ns = 0
        nf = 0
        for i in range(o, o + n):
            if structure[i]:
                ns += 1
            if free[i]:
                nf += 1
        o += n
        if n > 0 and float(ns) / float(n) <= max_structure and float(nf) / float(n) >= min_free:
            kept += 1
        else:
            keep[c] = False
    return kept


@njit(cache=True, inline="always")
def _three_point_side(px: np.ndarray, py: np.ndarray, a: int, b: int, trig: np.ndarray, low: float) -> float:
    """The minimum over the table ``trig``'s angles (rows cos, sin) of the longer span of three points' projections
    (points ``a``, ``b`` and the one of ``a`` … ``b`` farthest from their chord; map frame, m), each projection the
    expression of :func:`~dynslam2d.detect.shapes._project`: a lower bound of the longer side of the cluster's
    fitted rectangle, whatever angle the search picks (:func:`doomed_clusters`). Stops at the first angle whose span
    is ``low`` or less (and returns it): such a cluster is not doomed."""
    xa = px[a]
    ya = py[a]
    dx = px[b] - xa
    dy = py[b] - ya
    m = a
    far = -1.0
    for i in range(a + 1, b):
        d = abs(dx * (py[i] - ya) - dy * (px[i] - xa))
        if d > far:
            far = d
            m = i
    xb = px[b]
    yb = py[b]
    xm = px[m]
    ym = py[m]
    best = math.inf
    for k in range(trig.shape[1]):
        c = trig[0, k]
        s = trig[1, k]
        u0 = c * xa + s * ya
        u1 = c * xb + s * yb
        u2 = c * xm + s * ym
        v0 = -s * xa + c * ya
        v1 = -s * xb + c * yb
        v2 = -s * xm + c * ym
        su = max(max(u0, u1), u2) - min(min(u0, u1), u2)
        sv = max(max(v0, v1), v2) - min(min(v0, v1), v2)
        span = max(su, sv)
        if not span > low:
            return span
        best = min(best, span)
    return best


@njit(cache=True, inline="always")
def doomed_clusters(px: np.ndarray, py: np.ndarray, offsets: np.ndarray, structure: np.ndarray, trig: np.ndarray,
                    ext_lim: float, admit: bool, max_extent: float, has_map: bool, logodds: np.ndarray, i0: int,
                    j0: int, res: float, occ_thr: float, free_thr: float, free_radius: int, max_structure: float,
                    min_free: float) -> np.ndarray:
    """(k,) bool: the clusters marked as ``structure`` and those the classification drops whatever their rectangle
    fit (:func:`~dynslam2d.detect.kernels.classify_batch`'s side test against ``ext_lim`` and, where ``admit``,
    :func:`_admit_long`'s map test of the clusters longer than ``max_extent``), found before the fit so that the
    tracker does not fit them (pass det118). ``px``, ``py``: the clusters' map-frame points (m), cluster c's
    ``offsets[c]`` … ``offsets[c + 1] − 1``; the map and its thresholds as :func:`_admit_long` takes them.

    Bound: the fit's box holds every point, so along its two axes the first and last points are at least their
    chord's components apart, and the larger component is at least chord / √2: the longer fitted side ≥ chord / √2
    at every angle the search may choose. The floats (each side a difference of two rounded projections, the
    table's cos / sin of norm 1 within 2⁻⁵²) stay within a relative 2⁻⁵⁰ and an absolute 2⁻⁵⁰·(|x| + |y|) of that:
    the margin below (10⁻⁹ relative and 10⁻⁹·(1 + the end points' |coordinates|) m) covers them. Where that bound
    decides nothing but the chord is longer than the lower limit, a tighter one without margin: the search picks one
    angle of the table ``trig`` (rows cos, sin: :func:`~dynslam2d.detect.shapes.fit_cluster_rows`' table, filled;
    a NaN table: not used), and at each angle the fit's sides are the spans of the points' projections, computed
    as :func:`~dynslam2d.detect.shapes._project` computes them, so they are at least the spans of three of them
    (the end points and the point farthest from their chord: an L's corner), bit for bit; the minimum over the
    table's angles of the longer of those two spans bounds the side the classification reads. A cluster whose
    bound is above ``ext_lim`` is too long for the classification; one above ``max_extent`` (with ``admit``) is
    one of the long clusters :func:`_admit_long` tests, and is dropped where its points fail that test (the same
    kernel per point, the same comparisons; without a map every long cluster fails). A non-finite chord: never
    doomed."""
    k = structure.shape[0]
    doomed = np.empty(k, dtype=np.bool_)
    for c in range(k):
        doomed[c] = structure[c]
        a = offsets[c]
        b = offsets[c + 1] - 1
        if structure[c] or b <= a:
            continue
        xa = px[a]
        ya = py[a]
        xb = px[b]
        yb = py[b]
        dx = xb - xa
        dy = yb - ya
        side = (math.sqrt(dx * dx + dy * dy) * 0.7071067811865476 * (1.0 - 1e-9)
                - 1e-9 * (1.0 + abs(xa) + abs(ya) + abs(xb) + abs(yb)))
        if not side < math.inf:
            continue
        low = max_extent if admit else ext_lim
        if side <= low and math.sqrt(dx * dx + dy * dy) > low and trig[0, 0] == trig[0, 0]:
            side = _three_point_side(px, py, a, b, trig, low)
        if side > ext_lim:
            doomed[c] = True
        elif admit and side > max_extent:
            if not has_map:
                doomed[c] = True
                continue
            n = b + 1 - a
            qx = np.empty(n)
            qy = np.empty(n)
            for i in range(n):
                qx[i] = px[a + i]
                qy[i] = py[a + i]
            st = np.empty(n, dtype=np.bool_)
            fr = np.empty(n, dtype=np.bool_)
            un = np.empty(n, dtype=np.bool_)
            map_evidence_kernel(qx, qy, logodds, i0, j0, res, occ_thr, free_thr, free_radius, st, fr, un)
            ns = 0
            nf = 0
            for i in range(n):
                if st[i]:
                    ns += 1
                if fr[i]:
                    nf += 1
            doomed[c] = not (float(ns) / float(n) <= max_structure and float(nf) / float(n) >= min_free)
    return doomed


_NO_MAP = np.zeros((0, 0), dtype=np.float32)


def admit_long_clusters(keep: np.ndarray, fits: np.ndarray, offsets: np.ndarray, px: np.ndarray, py: np.ndarray,
                        view: MapView | None, config: DetectConfig) -> int:
    """In place: ``keep[c]`` = False for every kept cluster ``c`` longer than ``segment.max_extent`` whose
    points fail the map test of the module docstring. ``fits`` are the rows of
    :func:`~dynslam2d.detect.shapes.fit_clusters`, ``offsets`` the segmentation's, ``px``/``py`` the
    clusters' map-frame points (m). Returns the number of long clusters left kept. One kernel call
    (:func:`_admit_long`; none long on most scans)."""
    seg, tc = config.segment, config.tracker
    if view is None:
        return _admit_long(keep, fits, offsets, px, py, float(seg.max_extent), False, _NO_MAP, 0, 0, 1.0, 0.0, 0.0,
                           0, 0.0, 0.0)
    return _admit_long(keep, fits, offsets, px, py, float(seg.max_extent), True, view.logodds, int(view.i0),
                       int(view.j0), float(view.resolution), float(tc.map_occupied_logodds),
                       float(tc.map_free_logodds), int(tc.map_free_radius), float(seg.vehicle_max_structure),
                       float(seg.vehicle_min_free))


__all__ = ["admit_long_clusters", "doomed_clusters", "extent_limit", "long_kept"]
