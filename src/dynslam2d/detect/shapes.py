"""Shape fitting of clusters: search-based rectangle (L-shape), circle, point.

Rectangle (Zhang, Xu, Dong, Dolan, IV 2017; datmo's ``Cluster::rectangleFitting``): for every candidate
axis angle θ in [0, π/2) with a 1° step, project the points on e1 = (cos θ, sin θ) and
e2 = (−sin θ, cos θ) and score the projection with the area, closeness or variance criterion;
the best θ gives the bounds [lo1, hi1] × [lo2, hi2] of the rectangle in (e1, e2) coordinates.
:func:`fit_rectangle` is the numpy version vectorised over all angles at once (one (n×2)·(2×K)
product); :func:`fit_clusters` does the same for every cluster of a scan in one numba pass, four angles at a
time as the lanes of one vector value (:mod:`dynslam2d.jitvec`).

Circle: algebraic (Kåsa) fit refined by Gauss–Newton on the geometric residual — round
movers (people) show an arc whose centroid lies ≈2R/π in front of the true centre.

All coordinates are in whatever frame the points are given in (the tracker uses the map
frame); lengths in m, angles in rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynslam2d.detect.layout import (
    F_CENTROID_X,
    F_CENTROID_Y,
    F_CIRCLE_RMS,
    F_CIRCLE_X,
    F_CIRCLE_Y,
    F_RECT_RMS,
    F_THETA,
    N_FIT_COLS,
)
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.jitvec import (
    vabs,
    vadd,
    vall,
    vdiv,
    vec4,
    vget,
    vload,
    vmax,
    vmin,
    vmul,
    vneg,
    vset,
    vsplat,
    vstore,
    vsub,
    vwhere,
    vwhere_lt,
)

CRITERIA = {"area": 0, "closeness": 1, "variance": 2}


@dataclass(frozen=True, slots=True)
class RectFit:
    """Result of a rectangle fit, in the frame of the input points.

    Attributes:
        theta: axis angle of e1, rad in [0, π/2).
        lo, hi: (2,) bounds of the points along e1 and e2, m (the rectangle's sides).
        rms: RMS distance of the points to the nearest rectangle side, m.
    """

    theta: float
    lo: np.ndarray
    hi: np.ndarray
    rms: float

    @property
    def extent(self) -> np.ndarray:
        """(2,) side lengths along e1, e2, m."""
        return self.hi - self.lo

    def center(self) -> np.ndarray:
        """(2,) centre of the bounding rectangle, m."""
        u = 0.5 * (self.lo + self.hi)
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])

    def corners(self) -> np.ndarray:
        """(4, 2) corners in datmo's clockwise order c0..c3 (datmo's src/cluster.cpp):
        (hi1, lo2), (lo1, lo2), (lo1, hi2), (hi1, hi2) in (e1, e2) coordinates."""
        uv = np.array([[self.hi[0], self.lo[1]], [self.lo[0], self.lo[1]], [self.lo[0], self.hi[1]],
                       [self.hi[0], self.hi[1]]])
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.column_stack((c * uv[:, 0] - s * uv[:, 1], s * uv[:, 0] + c * uv[:, 1]))


def search_angles(step_deg: float) -> np.ndarray:
    """Candidate axis angles θ_k = k·step over [0, π/2), rad."""
    k = int(math.ceil(90.0 / step_deg - 1e-9))
    return np.arange(k) * math.radians(step_deg)


def fit_rectangle(points: np.ndarray, criterion: str = "variance", step_deg: float = 1.0,
                  d0: float = 0.01) -> RectFit:
    """Search-based rectangle fit of (n, 2) points, vectorised over all angles.

    Degenerate input never gives NaN: one point gives a zero-size rectangle at the point,
    an empty array a zero rectangle at the origin with rms 0.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return RectFit(0.0, np.zeros(2), np.zeros(2), 0.0)
    th = search_angles(step_deg)
    c, s = np.cos(th), np.sin(th)
    c1 = pts @ np.vstack((c, s))  # (n, K) projections on e1
    c2 = pts @ np.vstack((-s, c))  # (n, K) projections on e2
    lo1, hi1, lo2, hi2 = c1.min(0), c1.max(0), c2.min(0), c2.max(0)
    # Zhang: each axis' points go, as a group, to the nearer of its two parallel edges
    a1, b1 = hi1 - c1, c1 - lo1
    d1 = np.where((a1 * a1).sum(0) < (b1 * b1).sum(0), a1, b1)
    a2, b2 = hi2 - c2, c2 - lo2
    d2 = np.where((a2 * a2).sum(0) < (b2 * b2).sum(0), a2, b2)
    if criterion == "area":
        score = -(hi1 - lo1) * (hi2 - lo2)
    elif criterion == "closeness":
        score = (1.0 / np.maximum(np.minimum(d1, d2), d0)).sum(0)
    elif criterion == "variance":
        m1 = d1 < d2
        n1, n2 = m1.sum(0), (~m1).sum(0)
        e1 = np.where(m1, d1, 0.0)
        e2 = np.where(~m1, d2, 0.0)
        mean1 = e1.sum(0) / np.maximum(n1, 1)
        mean2 = e2.sum(0) / np.maximum(n2, 1)
        var1 = np.where(m1, (d1 - mean1) ** 2, 0.0).sum(0) / np.maximum(n1, 1)
        var2 = np.where(~m1, (d2 - mean2) ** 2, 0.0).sum(0) / np.maximum(n2, 1)
        score = -var1 - var2
    else:
        raise ValueError(f"unknown criterion {criterion!r}")
    k = int(np.argmax(score))  # first maximum = smallest θ on ties (as datmo's rectangleFitting)
    r = np.minimum(np.minimum(a1[:, k], b1[:, k]), np.minimum(a2[:, k], b2[:, k]))  # distance to the nearest side
    return RectFit(float(th[k]), np.array([lo1[k], lo2[k]]), np.array([hi1[k], hi2[k]]),
                   float(np.sqrt(np.mean(r * r))))


@njit(cache=True)
def _project(x: np.ndarray, y: np.ndarray, c: float, s: float, c1: np.ndarray,
             c2: np.ndarray) -> tuple[float, float, float, float]:
    """Project points on the axes (cos c, sin s) and its normal into ``c1``, ``c2``; return
    their ranges (lo1, hi1, lo2, hi2), m."""
    lo1 = np.inf
    hi1 = -np.inf
    lo2 = np.inf
    hi2 = -np.inf
    for i in range(x.shape[0]):
        u = c * x[i] + s * y[i]
        v = -s * x[i] + c * y[i]
        c1[i] = u
        c2[i] = v
        lo1 = min(lo1, u)
        hi1 = max(hi1, u)
        lo2 = min(lo2, v)
        hi2 = max(hi2, v)
    return lo1, hi1, lo2, hi2


#: unit roundoff of float64 (2^-53), for the error bound of :func:`_near_side_known`
_U = 2.0 ** -53


@njit(cache=True)
def _near_side_known(n: int, lo: float, hi: float, total: float) -> int:
    """Which edge the points of one axis go to, without the pass over them when the float sums cannot disagree:
    1 when Σ(hi − cᵢ)² < Σ(cᵢ − lo)² computed in sequence (the far edge ``hi``), 0 when not, −1 when undecided.

    ``lo``/``hi`` are the smallest / largest of the n projections cᵢ and ``total`` their sum taken in order. Over the
    reals SA − SB = w·E with w = hi − lo and E = n(hi + lo) − 2Σcᵢ, and SA + SB ≤ n·w². Each float sum of n
    non-negative terms (each term one subtraction and one product) is within γ_{n+2}·SA of SA (Higham, Accuracy and
    Stability of Numerical Algorithms, §3.1 and §4.2: γ_k = ku / (1 − ku), u = 2^-53), so when
    |SA − SB| > γ_{n+2}·(SA + SB) the float comparison has the sign of the real one; E computed from ``total`` is
    within γ_{n+3}·8nM of E (M = max(|lo|, |hi|)). The bound below holds both with a factor 4 to spare; otherwise
    (ties, degenerate or non-finite values) −1 and the caller sums as before, so the flag is always the one of the
    sums in sequence."""
    w = hi - lo
    m = max(abs(hi), abs(lo))
    if not (w > 1e-100 and m < 1e100):  # (w² and the terms stay normal floats; no overflow; NaN fails too)
        return -1
    e = n * (hi + lo) - 2.0 * total
    g = 8.0 * (n + 4) * _U
    if abs(e) > g * (4.0 * n * m + n * w):
        return 1 if e < 0.0 else 0
    return -1


@njit(cache=True)
def _near_sides(w: np.ndarray, r: int, n: int, lo1: float, hi1: float, lo2: float, hi2: float) -> tuple[bool, bool]:
    """The edges the points of one angle go to when :func:`_near_side_known` cannot tell (rows ``r``, ``r + 1`` of
    ``w``: the n projections on the two axes, bounds ``lo``/``hi``): Σ(hi − cᵢ)² < Σ(cᵢ − lo)² per axis, the sums in
    sequence."""
    sa1 = 0.0
    sb1 = 0.0
    sa2 = 0.0
    sb2 = 0.0
    for i in range(n):
        sa1 += (hi1 - w[r, i]) ** 2
        sb1 += (w[r, i] - lo1) ** 2
        sa2 += (hi2 - w[r + 1, i]) ** 2
        sb2 += (w[r + 1, i] - lo2) ** 2
    return sa1 < sb1, sa2 < sb2


@njit(cache=True)
def _fit_one(x: np.ndarray, y: np.ndarray, trig: np.ndarray, criterion: int, d0: float, out: np.ndarray,
             stride: int, w: np.ndarray, order: np.ndarray) -> None:
    """Best angle over the table ``trig`` (rows cos θ, sin θ, atan2(sin θ, cos θ): :func:`fit_cluster_rows`) by
    the Zhang et al. 2017 criterion (larger is better): every angle (stride 1), or every stride-th angle and then
    the angles around the best one (coarse-to-fine). ``w`` (6 rows ≥ n) and ``order`` (≥ K + 2·stride) are work
    space. The scalar form: :func:`fit_cluster_rows` runs :func:`_fit_vec` (four angles as vector lanes, pass
    det39), which ``tests/test_detect_shapes.py`` checks against this one bit for bit.

    One loop scores the angles to score (listed in ``order``, the fine ones appended once the coarse best is known)
    two at a time: each pass over the points serves two angles, whose sums are independent chains of additions, so
    the two overlap in the processor instead of each waiting for its own (pass sim36; every sum is still taken in
    the points' order, and the angles are compared in the order of ``order``: the same floats and the same best
    angle as one angle at a time). Each point's edge is decided per axis from the sums of squares to both edges
    (Zhang: the group goes to the nearer edge), by :func:`_near_side_known` when the float comparison is certain,
    else by the sums themselves. The best angle's projections and bounds are kept as it is scored (three row pairs
    of ``w``: the best angle's and the two being scored), so the result's bounds and rms need no projection of
    their own."""
    n = x.shape[0]
    kk = trig.shape[1]
    step = max(stride, 1)
    nq = 0
    for k in range(0, kk, step):
        order[nq] = k
        nq += 1
    ncoarse = nq
    best = -np.inf
    best_k = 0
    bst = 2  # (row pair bst of w, rows 2·bst and 2·bst + 1: best_k's projections, once kept)
    kept = False
    blo1 = bhi1 = blo2 = bhi2 = 0.0
    q = 0
    while q < nq:
        two = q + 1 < nq  # (a lone last angle is scored twice and compared once)
        ka = order[q]
        kb = order[q + 1] if two else ka
        ra = 2 * ((bst + 1) % 3)  # (the rows of the two row pairs that are not the best angle's)
        rb = 2 * ((bst + 2) % 3)
        ca = trig[0, ka]
        sa = trig[1, ka]
        cb = trig[0, kb]
        sb = trig[1, kb]
        lo1a = np.inf
        hi1a = -np.inf
        lo2a = np.inf
        hi2a = -np.inf
        lo1b = np.inf
        hi1b = -np.inf
        lo2b = np.inf
        hi2b = -np.inf
        t1a = 0.0
        t2a = 0.0
        t1b = 0.0
        t2b = 0.0
        for i in range(n):
            xi = x[i]  # (read once: the stores into w below could alias x, y for the compiler, which reloaded them)
            yi = y[i]
            u = ca * xi + sa * yi
            v = -sa * xi + ca * yi
            w[ra, i] = u
            w[ra + 1, i] = v
            t1a += u
            t2a += v
            lo1a = min(lo1a, u)
            hi1a = max(hi1a, u)
            lo2a = min(lo2a, v)
            hi2a = max(hi2a, v)
            u = cb * xi + sb * yi
            v = -sb * xi + cb * yi
            w[rb, i] = u
            w[rb + 1, i] = v
            t1b += u
            t2b += v
            lo1b = min(lo1b, u)
            hi1b = max(hi1b, u)
            lo2b = min(lo2b, v)
            hi2b = max(hi2b, v)
        if criterion == 0:
            sca = -(hi1a - lo1a) * (hi2a - lo2a)
            scb = -(hi1b - lo1b) * (hi2b - lo2b)
        else:
            f1 = _near_side_known(n, lo1a, hi1a, t1a)
            f2 = _near_side_known(n, lo2a, hi2a, t2a)
            if f1 < 0 or f2 < 0:
                use_hi1a, use_hi2a = _near_sides(w, ra, n, lo1a, hi1a, lo2a, hi2a)
            else:
                use_hi1a = f1 == 1
                use_hi2a = f2 == 1
            f1 = _near_side_known(n, lo1b, hi1b, t1b)
            f2 = _near_side_known(n, lo2b, hi2b, t2b)
            if f1 < 0 or f2 < 0:
                use_hi1b, use_hi2b = _near_sides(w, rb, n, lo1b, hi1b, lo2b, hi2b)
            else:
                use_hi1b = f1 == 1
                use_hi2b = f2 == 1
            if criterion == 1:
                sca = 0.0
                scb = 0.0
                for i in range(n):
                    d1 = hi1a - w[ra, i] if use_hi1a else w[ra, i] - lo1a
                    d2 = hi2a - w[ra + 1, i] if use_hi2a else w[ra + 1, i] - lo2a
                    sca += 1.0 / max(min(d1, d2), d0)
                    d1 = hi1b - w[rb, i] if use_hi1b else w[rb, i] - lo1b
                    d2 = hi2b - w[rb + 1, i] if use_hi2b else w[rb + 1, i] - lo2b
                    scb += 1.0 / max(min(d1, d2), d0)
            else:
                s1a = 0.0
                q1a = 0.0
                m1a = 0
                s2a = 0.0
                q2a = 0.0
                m2a = 0
                s1b = 0.0
                q1b = 0.0
                m1b = 0
                s2b = 0.0
                q2b = 0.0
                m2b = 0
                for i in range(n):
                    d1 = hi1a - w[ra, i] if use_hi1a else w[ra, i] - lo1a
                    d2 = hi2a - w[ra + 1, i] if use_hi2a else w[ra + 1, i] - lo2a
                    if d1 < d2:
                        s1a += d1
                        q1a += d1 * d1
                        m1a += 1
                    else:
                        s2a += d2
                        q2a += d2 * d2
                        m2a += 1
                    d1 = hi1b - w[rb, i] if use_hi1b else w[rb, i] - lo1b
                    d2 = hi2b - w[rb + 1, i] if use_hi2b else w[rb + 1, i] - lo2b
                    if d1 < d2:
                        s1b += d1
                        q1b += d1 * d1
                        m1b += 1
                    else:
                        s2b += d2
                        q2b += d2 * d2
                        m2b += 1
                v1 = q1a / m1a - (s1a / m1a) ** 2 if m1a > 0 else 0.0
                v2 = q2a / m2a - (s2a / m2a) ** 2 if m2a > 0 else 0.0
                sca = -v1 - v2
                v1 = q1b / m1b - (s1b / m1b) ** 2 if m1b > 0 else 0.0
                v2 = q2b / m2b - (s2b / m2b) ** 2 if m2b > 0 else 0.0
                scb = -v1 - v2
        # (the two angles compared in their order, as one at a time)
        if q < ncoarse:
            take = sca > best + 1e-12
        else:
            take = sca > best + 1e-12 or (abs(sca - best) <= 1e-12 and ka < best_k)
        if take:
            best = sca
            best_k = ka
            blo1, bhi1, blo2, bhi2 = lo1a, hi1a, lo2a, hi2a
            bst = ra // 2
            kept = True
        if two:
            if q + 1 < ncoarse:
                take = scb > best + 1e-12
            else:
                take = scb > best + 1e-12 or (abs(scb - best) <= 1e-12 and kb < best_k)
            if take:
                best = scb
                best_k = kb
                blo1, bhi1, blo2, bhi2 = lo1b, hi1b, lo2b, hi2b
                bst = rb // 2
                kept = True
        q += 2 if two else 1
        if q == ncoarse and step > 1:  # the fine angles: within one coarse step of the coarse best
            for dk in range(-step + 1, step):
                if dk != 0:
                    order[nq] = (best_k + dk) % kk
                    nq += 1
    r = 2 * bst
    if kept:  # (the same products and bounds as _project's of best_k, made when best_k was scored)
        lo1, hi1, lo2, hi2 = blo1, bhi1, blo2, bhi2
    else:  # (no angle accepted: NaN scores)
        lo1, hi1, lo2, hi2 = _project(x, y, trig[0, best_k], trig[1, best_k], w[r], w[r + 1])
    ss = 0.0
    for i in range(n):
        d = min(min(hi1 - w[r, i], w[r, i] - lo1), min(hi2 - w[r + 1, i], w[r + 1, i] - lo2))
        ss += d * d
    out[0] = trig[2, best_k]
    out[1] = lo1
    out[2] = hi1
    out[3] = lo2
    out[4] = hi2
    out[5] = math.sqrt(ss / n)


@njit(cache=True)
def _lane_edges(w: np.ndarray, j: int, n: int, lo1: float, hi1: float, t1: float, lo2: float, hi2: float,
                t2: float) -> tuple[float, float]:
    """The edges the points of lane ``j`` of :func:`_score4` go to per axis, 1.0 for the far edge ``hi`` (Σ(hi − cᵢ)²
    < Σ(cᵢ − lo)²), else 0.0: as :func:`_fit_one`, :func:`_near_side_known` from the bounds and the projections' sum
    ``t`` when it is certain for both axes, else the sums in sequence (:func:`_near_sides`, the lane's projections
    read from ``w``)."""
    f1 = _near_side_known(n, lo1, hi1, t1)
    f2 = _near_side_known(n, lo2, hi2, t2)
    if f1 < 0 or f2 < 0:
        sa1 = 0.0
        sb1 = 0.0
        sa2 = 0.0
        sb2 = 0.0
        for i in range(n):
            sa1 += (hi1 - w[8 * i + j]) ** 2
            sb1 += (w[8 * i + j] - lo1) ** 2
            sa2 += (hi2 - w[8 * i + 4 + j]) ** 2
            sb2 += (w[8 * i + 4 + j] - lo2) ** 2
        return 1.0 if sa1 < sb1 else 0.0, 1.0 if sa2 < sb2 else 0.0
    return 1.0 if f1 == 1 else 0.0, 1.0 if f2 == 1 else 0.0


@njit(cache=True)
def _edges4(n: int, lo1: vec4, hi1: vec4, t1: vec4, lo2: vec4, hi2: vec4, t2: vec4) -> tuple:
    """:func:`_near_side_known` of the four lanes of both axes at once, with the same float operations per lane (each
    lane's bounds ``lo``, ``hi`` and projections' sum ``t`` of n points): ``(use1, use2, known)``, the flags as lanes
    of 1.0 (the far edge ``hi``) / 0.0, and True when every lane is decided on both axes (none where
    :func:`_near_side_known` returns −1); when not, the caller takes each lane's :func:`_lane_edges`."""
    one = vsplat(1.0)
    zero = vsplat(0.0)
    nv = vsplat(float(n))
    n4 = vsplat(4.0 * n)
    two = vsplat(2.0)
    gv = vsplat(8.0 * (n + 4) * _U)
    tiny = vsplat(1e-100)
    huge = vsplat(1e100)
    w = vsub(hi1, lo1)
    m = vmax(vabs(hi1), vabs(lo1))
    ok = vwhere_lt(m, huge, vwhere_lt(tiny, w, one, zero), zero)  # (w² and the terms normal; NaN: not ok)
    e = vsub(vmul(nv, vadd(hi1, lo1)), vmul(two, t1))
    known1 = vwhere_lt(vmul(gv, vadd(vmul(n4, m), vmul(nv, w))), vabs(e), ok, zero)
    use1 = vwhere_lt(e, zero, one, zero)
    w = vsub(hi2, lo2)
    m = vmax(vabs(hi2), vabs(lo2))
    ok = vwhere_lt(m, huge, vwhere_lt(tiny, w, one, zero), zero)
    e = vsub(vmul(nv, vadd(hi2, lo2)), vmul(two, t2))
    known2 = vwhere_lt(vmul(gv, vadd(vmul(n4, m), vmul(nv, w))), vabs(e), ok, zero)
    return use1, vwhere_lt(e, zero, one, zero), vall(known1) and vall(known2)


@njit(cache=True)
def _score4(x: np.ndarray, y: np.ndarray, trig: np.ndarray, criterion: int, d0: float, k0: int, k1: int, k2: int,
            k3: int, w: np.ndarray) -> tuple[float, float, float, float]:
    """The Zhang et al. 2017 scores (larger is better) of the four angles ``k0``…``k3`` of the table ``trig`` for
    the points ``x``, ``y`` (m): :func:`_fit_one`'s score of each, the four angles as the lanes of one
    ``<4 x double>`` value (:mod:`dynslam2d.jitvec`), so each pass over the points is one vector instruction per
    operation for four angles (pass det39). Every lane is the same IEEE operation on the same operands as the
    scalar code, every sum in the points' order: the same floats. The nearer edges of the four lanes are decided
    at once by :func:`_edges4` when its error bound is certain for every lane, else per lane (:func:`_lane_edges`);
    the variance scores are lanes too (pass det40). ``w`` (≥ 8n) is work space: per point the four projections on
    e1, then the four on e2."""
    n = x.shape[0]
    c = vset(trig[0, k0], trig[0, k1], trig[0, k2], trig[0, k3])
    s = vset(trig[1, k0], trig[1, k1], trig[1, k2], trig[1, k3])
    ns = vneg(s)
    lo1 = vsplat(np.inf)
    hi1 = vsplat(-np.inf)
    lo2 = vsplat(np.inf)
    hi2 = vsplat(-np.inf)
    t1 = vsplat(0.0)
    t2 = vsplat(0.0)
    for i in range(n):
        xi = vsplat(x[i])
        yi = vsplat(y[i])
        u = vadd(vmul(c, xi), vmul(s, yi))  # (c·x + s·y and −s·x + c·y, as _fit_one)
        v = vadd(vmul(ns, xi), vmul(c, yi))
        vstore(w, 8 * i, u)
        vstore(w, 8 * i + 4, v)
        t1 = vadd(t1, u)
        t2 = vadd(t2, v)
        lo1 = vmin(lo1, u)
        hi1 = vmax(hi1, u)
        lo2 = vmin(lo2, v)
        hi2 = vmax(hi2, v)
    if criterion == 0:
        sc = vmul(vneg(vsub(hi1, lo1)), vsub(hi2, lo2))
        return vget(sc, 0), vget(sc, 1), vget(sc, 2), vget(sc, 3)
    # each axis' nearer edge per lane (1.0: the far edge hi): _near_side_known of the four lanes at once (_edges4:
    # the same float operations per lane) when it is certain for every lane, else each lane's _lane_edges (its
    # _near_side_known, or the sums when that cannot tell); the lane index as np.int64, not a literal constant: numba
    # would compile _lane_edges once per literal (four times)
    use1, use2, known = _edges4(n, lo1, hi1, t1, lo2, hi2, t2)
    if not known:
        a0, b0 = _lane_edges(w, np.int64(0), n, vget(lo1, 0), vget(hi1, 0), vget(t1, 0),
                             vget(lo2, 0), vget(hi2, 0), vget(t2, 0))
        a1, b1 = _lane_edges(w, np.int64(1), n, vget(lo1, 1), vget(hi1, 1), vget(t1, 1),
                             vget(lo2, 1), vget(hi2, 1), vget(t2, 1))
        a2, b2 = _lane_edges(w, np.int64(2), n, vget(lo1, 2), vget(hi1, 2), vget(t1, 2),
                             vget(lo2, 2), vget(hi2, 2), vget(t2, 2))
        a3, b3 = _lane_edges(w, np.int64(3), n, vget(lo1, 3), vget(hi1, 3), vget(t1, 3),
                             vget(lo2, 3), vget(hi2, 3), vget(t2, 3))
        use1 = vset(a0, a1, a2, a3)
        use2 = vset(b0, b1, b2, b3)
    if criterion == 1:
        acc = vsplat(0.0)
        one = vsplat(1.0)
        d0v = vsplat(d0)
        for i in range(n):
            u = vload(w, 8 * i)
            v = vload(w, 8 * i + 4)
            d1 = vwhere(use1, vsub(hi1, u), vsub(u, lo1))
            d2 = vwhere(use2, vsub(hi2, v), vsub(v, lo2))
            acc = vadd(acc, vdiv(one, vmax(vmin(d1, d2), d0v)))  # (1 / max(min(d1, d2), d0))
        return vget(acc, 0), vget(acc, 1), vget(acc, 2), vget(acc, 3)
    s1 = vsplat(0.0)
    q1 = vsplat(0.0)
    m1 = vsplat(0.0)
    s2 = vsplat(0.0)
    q2 = vsplat(0.0)
    one = vsplat(1.0)
    for i in range(n):
        u = vload(w, 8 * i)
        v = vload(w, 8 * i + 4)
        d1 = vwhere(use1, vsub(hi1, u), vsub(u, lo1))
        d2 = vwhere(use2, vsub(hi2, v), vsub(v, lo2))
        # (the point's group: each sum either gains the term or keeps its value, per lane; the branch's bits)
        s1 = vwhere_lt(d1, d2, vadd(s1, d1), s1)
        q1 = vwhere_lt(d1, d2, vadd(q1, vmul(d1, d1)), q1)
        m1 = vwhere_lt(d1, d2, vadd(m1, one), m1)
        s2 = vwhere_lt(d1, d2, s2, vadd(s2, d2))
        q2 = vwhere_lt(d1, d2, q2, vadd(q2, vmul(d2, d2)))
    # each group's variance q / m − (s / m)², 0 for an empty group (x ** 2 of a float is numba's x · x), and the
    # score −v1 − v2, as _fit_one
    m2 = vsub(vsplat(float(n)), m1)  # (the other points: counts are exact integers)
    zero = vsplat(0.0)
    r1 = vdiv(s1, m1)
    r2 = vdiv(s2, m2)
    v1 = vwhere_lt(zero, m1, vsub(vdiv(q1, m1), vmul(r1, r1)), zero)
    v2 = vwhere_lt(zero, m2, vsub(vdiv(q2, m2), vmul(r2, r2)), zero)
    sc = vsub(vneg(v1), v2)
    return vget(sc, 0), vget(sc, 1), vget(sc, 2), vget(sc, 3)


@njit(cache=True)
def _fit_vec(x: np.ndarray, y: np.ndarray, trig: np.ndarray, criterion: int, d0: float, out: np.ndarray,
             stride: int, w: np.ndarray, order: np.ndarray, sc: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> None:
    """:func:`_fit_one`'s result (θ, lo1, hi1, lo2, hi2, rms into ``out``) with the angles scored four at a time
    (:func:`_score4`): the coarse angles (every stride-th), then the fine ones within one coarse step of the coarse
    best, a last group of fewer than four filled up with its last angle (scored again, its score not read); the
    scores compared in the same order with the same tie rules, and the best angle's bounds and rms from
    :func:`_project`'s projections (the products and bounds its scoring made). Work space: ``w`` (≥ 8n),
    ``order`` and ``sc`` (≥ K + 2·stride), ``c1``, ``c2`` (≥ n)."""
    n = x.shape[0]
    kk = trig.shape[1]
    step = max(stride, 1)
    nq = 0
    for k in range(0, kk, step):
        order[nq] = k
        nq += 1
    best = -np.inf
    best_k = 0
    q0 = 0
    for phase in range(2):
        for q in range(q0, nq, 4):
            last = order[nq - 1]
            k1 = order[q + 1] if q + 1 < nq else last
            k2 = order[q + 2] if q + 2 < nq else last
            k3 = order[q + 3] if q + 3 < nq else last
            r0, r1, r2, r3 = _score4(x, y, trig, criterion, d0, order[q], k1, k2, k3, w)
            sc[q] = r0
            if q + 1 < nq:
                sc[q + 1] = r1
            if q + 2 < nq:
                sc[q + 2] = r2
            if q + 3 < nq:
                sc[q + 3] = r3
        for q in range(q0, nq):
            if phase == 0:
                take = sc[q] > best + 1e-12
            else:
                take = sc[q] > best + 1e-12 or (abs(sc[q] - best) <= 1e-12 and order[q] < best_k)
            if take:
                best = sc[q]
                best_k = order[q]
        if phase == 1 or step == 1:
            break
        q0 = nq  # the fine angles: within one coarse step of the coarse best
        for dk in range(-step + 1, step):
            if dk != 0:
                order[nq] = (best_k + dk) % kk
                nq += 1
    lo1, hi1, lo2, hi2 = _project(x, y, trig[0, best_k], trig[1, best_k], c1, c2)
    ss = 0.0
    for i in range(n):
        d = min(min(hi1 - c1[i], c1[i] - lo1), min(hi2 - c2[i], c2[i] - lo2))
        ss += d * d
    out[0] = trig[2, best_k]
    out[1] = lo1
    out[2] = hi1
    out[3] = lo2
    out[4] = hi2
    out[5] = math.sqrt(ss / n)


@njit(cache=True)
def _lu_solve3(a: np.ndarray, b: np.ndarray) -> float:
    """Solve the 3×3 system a·x = b in place (x → b; a is overwritten by its LU factors) by Gaussian
    elimination with partial pivoting, as LAPACK getrf/getrs; returns det(a) (0 when singular, b then
    unchanged). Allocation-free replacement of ``np.linalg.det`` + ``np.linalg.solve``."""
    sign = 1.0
    for c in range(3):
        p = c
        for q in range(c + 1, 3):
            if abs(a[q, c]) > abs(a[p, c]):
                p = q
        if a[p, c] == 0.0:
            return 0.0
        if p != c:
            sign = -sign
            for q in range(3):
                t = a[c, q]
                a[c, q] = a[p, q]
                a[p, q] = t
            t = b[c]
            b[c] = b[p]
            b[p] = t
        inv = 1.0 / a[c, c]
        for q in range(c + 1, 3):
            a[q, c] *= inv
        for q in range(c + 1, 3):
            for w in range(c + 1, 3):
                a[q, w] -= a[q, c] * a[c, w]
    det = sign * a[0, 0] * a[1, 1] * a[2, 2]
    if det == 0.0:
        return 0.0
    b[1] -= a[1, 0] * b[0]
    b[2] -= a[2, 0] * b[0] + a[2, 1] * b[1]
    b[2] /= a[2, 2]
    b[1] = (b[1] - a[1, 2] * b[2]) / a[1, 1]
    b[0] = (b[0] - a[0, 1] * b[1] - a[0, 2] * b[2]) / a[0, 0]
    return det


@njit(cache=True, error_model="numpy")
def _gn_terms(x: np.ndarray, y: np.ndarray, cx: float, cy: float, wd: np.ndarray, w0: np.ndarray,
              w1: np.ndarray) -> None:
    """Per point of ``x, y`` (m): the distance d to the centre (``cx``, ``cy``) into ``wd`` and the Jacobian of
    |p − c| − R with respect to the centre, −dx / d and −dy / d, into ``w0``, ``w1`` (≥ n each; the Gauss–Newton step
    of :func:`_circle_one`, which skips points with d < 1e-9, where these are inf / NaN: ``error_model="numpy"``,
    no ZeroDivisionError branch, so the loop vectorises; each value is the same correctly rounded operation as in
    a scalar loop)."""
    for i in range(x.shape[0]):
        dx = x[i] - cx
        dy = y[i] - cy
        d = math.sqrt(dx * dx + dy * dy)
        wd[i] = d
        w0[i] = -dx / d
        w1[i] = -dy / d


@njit(cache=True)
def _circle_one(x: np.ndarray, y: np.ndarray, out: np.ndarray, wd: np.ndarray, w0: np.ndarray,
                w1: np.ndarray) -> None:
    """Kåsa algebraic circle fit + 5 Gauss–Newton steps on |p − c| − R. out = cx, cy, r, rms
    (NaN-free: r = 0 and rms = inf when the fit is degenerate). ``wd``, ``w0``, ``w1``: work space (≥ n each)."""
    n = x.shape[0]
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += x[i]
        my += y[i]
    mx /= n
    my /= n
    # centred coordinates for conditioning
    suu = 0.0
    suv = 0.0
    svv = 0.0
    suuu = 0.0
    svvv = 0.0
    suvv = 0.0
    svuu = 0.0
    for i in range(n):
        u = x[i] - mx
        v = y[i] - my
        suu += u * u
        suv += u * v
        svv += v * v
        suuu += u * u * u
        svvv += v * v * v
        suvv += u * v * v
        svuu += v * u * u
    det = suu * svv - suv * suv
    out[0] = mx
    out[1] = my
    out[2] = 0.0
    out[3] = np.inf
    if n < 3 or abs(det) < 1e-12:
        return
    b1 = 0.5 * (suuu + suvv)
    b2 = 0.5 * (svvv + svuu)
    uc = (b1 * svv - b2 * suv) / det
    vc = (suu * b2 - suv * b1) / det
    cx = uc + mx
    cy = vc + my
    r = math.sqrt(uc * uc + vc * vc + (suu + svv) / n)
    a = np.empty((3, 3))
    step = np.empty(3)
    for _ in range(5):  # Gauss–Newton on the geometric distance
        h00 = 0.0
        h01 = 0.0
        h02 = 0.0
        h11 = 0.0
        h12 = 0.0
        h22 = 0.0
        g0 = 0.0
        g1 = 0.0
        g2 = 0.0
        # (each point's distance and Jacobian first, in a loop without sums: numba vectorises its square roots and
        # divisions; then the sums in the points' order, as before: the same values, docs/speed.md pass trk22)
        _gn_terms(x, y, cx, cy, wd, w0, w1)
        for i in range(n):
            d = wd[i]
            if d < 1e-9:
                continue
            j0 = w0[i]
            j1 = w1[i]
            res = d - r
            h00 += j0 * j0
            h01 += j0 * j1
            h02 += -j0
            h11 += j1 * j1
            h12 += -j1
            h22 += 1.0
            g0 += j0 * res
            g1 += j1 * res
            g2 += -res
        a[0, 0] = h00 + 1e-9
        a[0, 1] = h01
        a[0, 2] = h02
        a[1, 0] = h01
        a[1, 1] = h11 + 1e-9
        a[1, 2] = h12
        a[2, 0] = h02
        a[2, 1] = h12
        a[2, 2] = h22 + 1e-9
        step[0] = -g0
        step[1] = -g1
        step[2] = -g2
        if abs(_lu_solve3(a, step)) < 1e-15:
            break
        cx += step[0]
        cy += step[1]
        r += step[2]
        if abs(step[0]) + abs(step[1]) + abs(step[2]) < 1e-6:
            break
    if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r)) or r <= 0.0:
        return
    ss = 0.0
    for i in range(n):
        d = math.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r
        ss += d * d
    out[0] = cx
    out[1] = cy
    out[2] = r
    out[3] = math.sqrt(ss / n)


@njit(cache=True, inline="always")
def _circle_reach(n: int, rect_rms: float, mx: float, my: float, ext: float, short: float, max_radius: float,
                  depth_ratio: float, ratio: float) -> float:
    """A side length (m) from which a cluster of ``n`` points whose rectangle fit has rms ``rect_rms`` (m), longest
    side ``ext`` and shortest side ``short`` (m) cannot be a circle the classification accepts (``classify_batch``:
    radius r ≤ ``max_radius``, ``short`` ≥ ``depth_ratio`` · r and circle rms < ``ratio`` · ``rect_rms``); ``mx``,
    ``my``: the cluster's centroid, m.

    With c the circle's centre, Dᵢ = |pᵢ − c| and δᵢ = Dᵢ − r: the two points a, b at the ends of a side of the
    rectangle are that side's length apart along a unit axis, so side ≤ D_a + D_b ≤ 2r + |δ_a| + |δ_b|
    ≤ 2r + √(2(δ_a² + δ_b²)) ≤ 2r + √(2·Σδᵢ²) = 2r + √(2n)·rms, and an accepted circle has r ≤ ``max_radius``,
    r ≤ ``short`` / ``depth_ratio`` (when > 0) and rms < ``ratio`` · ``rect_rms``. The float values (the sides
    from the rounded projections, the rms from rounded distances summed in order, the products with the ratios)
    are within a relative n·2⁻⁵² and an absolute 2⁻⁵⁰·(|x| + |y|) of those: the margin below (10⁻⁹ relative,
    10⁻⁹·(1 + |mx| + |my| + ext) m) covers clusters of up to 10⁶ points. NaN or inf ``rect_rms`` gives NaN or
    inf: never reached."""
    r = max_radius
    if depth_ratio > 0.0:
        r = min(r, short / depth_ratio)
    reach = (2.0 * r + math.sqrt(2.0 * n) * ratio * rect_rms) * (1.0 + 1e-9)
    return reach + 1e-9 * (1.0 + abs(mx) + abs(my) + ext)


@njit(cache=True)  # (fit_cluster_rows without the skip; the tracker calls that one)
def fit_clusters(x: np.ndarray, y: np.ndarray, offsets: np.ndarray, fit_mask: np.ndarray, angles: np.ndarray,
                 criterion: int, d0: float, circle_min_points: int, stride: int = 1) -> np.ndarray:
    """Fit every cluster ``c`` with ``fit_mask[c]`` (points ``x, y[offsets[c]:offsets[c+1]]``).

    ``stride`` > 1 searches every stride-th angle first, then the neighbours of the best one.
    Returns (k, 12): theta, lo1, hi1, lo2, hi2, rect_rms, circle cx, cy, r, circle_rms,
    centroid x, y (columns named in :mod:`dynslam2d.detect.layout`, ``F_*``). Unfitted clusters
    hold only their centroid (other entries 0, rms inf).
    """
    trig = np.empty((3, angles.shape[0]))
    trig[0, 0] = np.nan  # (a new table: fit_cluster_rows fills it)
    return fit_cluster_rows(x, y, offsets, fit_mask, angles, trig, criterion, d0, circle_min_points, stride, False,
                            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True)
def fit_cluster_rows(x: np.ndarray, y: np.ndarray, offsets: np.ndarray, fit_mask: np.ndarray, angles: np.ndarray,
                     trig: np.ndarray, criterion: int, d0: float, circle_min_points: int, stride: int, skip: bool,
                     point_max_points: float, point_max_extent: float, max_extent: float, thin: float,
                     circle_max_radius: float, depth_ratio: float, residual_ratio: float) -> np.ndarray:
    """:func:`fit_clusters`; where ``skip``, without the circle fit of a cluster whose circle the tracker's
    classification (:func:`dynslam2d.detect.kernels.classify_batch`, the same expressions) never reads: a point
    (n ≤ ``point_max_points`` or both sides < ``point_max_extent``), one not kept (a side > ``max_extent``, its
    ``max_extent``) or one too thin to be a circle (short side < ``thin`` = ``circle_min_depth_ratio`` ·
    ``circle_min_radius``: a circle needs short side ≥ ratio · r ≥ ratio · min radius) or one too long for any
    circle the classification accepts (:func:`_circle_reach`, with ``circle_max_radius``,
    ``circle_min_depth_ratio`` as ``depth_ratio`` and ``circle_residual_ratio`` as ``residual_ratio``). Such a row's
    four circle
    columns are NaN (never a fit's value: a degenerate fit gives r = 0, rms = inf), which the classification's
    radius test refuses; :class:`dynslam2d.detect.measure.ScanDetection` fits them when its ``circle`` is read.

    ``trig``: (3, len(angles)) table of the angles' cos, sin and atan2(sin, cos) (the result's θ), which this fills
    when ``trig[0, 0]`` is NaN (a new table) and otherwise reads as it is: a caller that keeps it for its next calls
    with the same ``angles`` saves 3 transcendental functions per angle and call (docs/speed.md, pass fit34)."""
    k = offsets.shape[0] - 1
    out = np.empty((k, N_FIT_COLS))
    out[:] = 0.0
    if np.isnan(trig[0, 0]):
        for j in range(angles.shape[0]):  # (np.cos / np.sin of the angles, then θ = atan2 of the pair, as before)
            trig[0, j] = np.cos(angles[j])
            trig[1, j] = np.sin(angles[j])
        for j in range(angles.shape[0]):
            trig[2, j] = math.atan2(trig[1, j], trig[0, j])
    tmp = np.empty(6)
    tmpc = np.empty(4)
    nmax = 0
    for c in range(k):
        nmax = max(nmax, offsets[c + 1] - offsets[c])
    c1 = np.empty(nmax)  # (work space of _fit_one, once per call)
    c2 = np.empty(nmax)
    c3 = np.empty(nmax)
    w8 = np.empty(8 * nmax)
    order = np.empty(angles.shape[0] + 2 * max(stride, 1), dtype=np.int64)
    sc = np.empty(order.shape[0])
    for c in range(k):
        a = offsets[c]
        b = offsets[c + 1]
        n = b - a
        if n == 0:
            out[c, F_RECT_RMS] = np.inf
            out[c, F_CIRCLE_RMS] = np.inf
            continue
        xs = x[a:b]
        ys = y[a:b]
        sx = 0.0  # sequential sums, as numba's ndarray.mean (no array-method compile)
        sy = 0.0
        for i in range(n):
            sx += xs[i]
            sy += ys[i]
        out[c, F_CENTROID_X] = sx / n
        out[c, F_CENTROID_Y] = sy / n
        if not fit_mask[c]:
            out[c, F_RECT_RMS] = np.inf
            out[c, F_CIRCLE_RMS] = np.inf
            continue
        _fit_vec(xs, ys, trig, criterion, d0, tmp, stride, w8, order, sc, c1, c2)
        for q in range(6):  # θ, lo1, hi1, lo2, hi2, rms (the order of _fit_one); element-wise: a slice
            out[c, F_THETA + q] = tmp[q]  # assignment compiles numba's shape-error formatting (~4 s cold)
        if n >= circle_min_points and skip:
            e0 = tmp[2] - tmp[1]  # (hi1 − lo1, hi2 − lo2: the fit's sides, as classify_batch computes them)
            e1 = tmp[4] - tmp[3]
            if n <= point_max_points or max(e0, e1) < point_max_extent or max(e0, e1) > max_extent or \
                    min(e0, e1) < thin or max(e0, e1) >= _circle_reach(n, tmp[5], out[c, F_CENTROID_X],
                                                                       out[c, F_CENTROID_Y], max(e0, e1),
                                                                       min(e0, e1), circle_max_radius,
                                                                       depth_ratio, residual_ratio):
                for q in range(4):
                    out[c, F_CIRCLE_X + q] = np.nan
                continue
        if n >= circle_min_points:
            _circle_one(xs, ys, tmpc, c1, c2, c3)  # (c1, c2, c3: free again after _fit_one)
            for q in range(4):  # cx, cy, r, rms (the order of _circle_one)
                out[c, F_CIRCLE_X + q] = tmpc[q]
        else:
            out[c, F_CIRCLE_X] = out[c, F_CENTROID_X]
            out[c, F_CIRCLE_Y] = out[c, F_CENTROID_Y]
            out[c, F_CIRCLE_RMS] = np.inf
    return out


def fit_circle(points: np.ndarray) -> tuple[float, float, float, float]:
    """Circle fit of (n, 2) points: (cx, cy, r, rms) in m; r = 0, rms = inf if degenerate."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out = np.empty(4)
    if pts.shape[0] == 0:
        return 0.0, 0.0, 0.0, math.inf
    n = pts.shape[0]
    _circle_one(pts[:, 0].copy(), pts[:, 1].copy(), out, np.empty(n), np.empty(n), np.empty(n))
    return float(out[0]), float(out[1]), float(out[2]), float(out[3])


@njit(cache=True)
def circle_center_fixed_radius(x: np.ndarray, y: np.ndarray, cx: float, cy: float, r: float) -> tuple:
    """Gauss–Newton for the centre of a circle of known radius ``r`` through the points
    (start (cx, cy)); returns (cx, cy, rms)."""
    n = x.shape[0]
    for _ in range(5):
        h00 = 1e-9
        h01 = 0.0
        h11 = 1e-9
        g0 = 0.0
        g1 = 0.0
        for i in range(n):
            dx = x[i] - cx
            dy = y[i] - cy
            d = math.sqrt(dx * dx + dy * dy)
            if d < 1e-9:
                continue
            j0 = -dx / d
            j1 = -dy / d
            res = d - r
            h00 += j0 * j0
            h01 += j0 * j1
            h11 += j1 * j1
            g0 += j0 * res
            g1 += j1 * res
        det = h00 * h11 - h01 * h01
        if abs(det) < 1e-15:
            break
        s0 = -(h11 * g0 - h01 * g1) / det
        s1 = -(-h01 * g0 + h00 * g1) / det
        cx += s0
        cy += s1
        if abs(s0) + abs(s1) < 1e-6:
            break
    ss = 0.0
    for i in range(n):
        d = math.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r
        ss += d * d
    return cx, cy, math.sqrt(ss / max(n, 1))
