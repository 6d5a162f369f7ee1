"""Rectangle (Zhang 2017 search), circle and batch fits; the measurement geometry of a cluster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import FitConfig, fit_circle, fit_clusters, fit_rectangle, search_angles
from dynslam2d.detect.layout import SIZE_LOWER, SIZE_MEASURED
from dynslam2d.detect.reference import classify_and_bound, measure
from dynslam2d.detect.shapes import CRITERIA, _circle_reach, fit_cluster_rows
from dynslam2d.types import Box, wrap_angle


def l_shape(cx: float, cy: float, theta: float, length: float, width: float, n: int = 30,
            noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Points on the two sides of a box that face the origin-side corner (−l/2, −w/2)."""
    rng = np.random.default_rng(seed)
    a = np.column_stack((np.linspace(-length / 2, length / 2, n), np.full(n, -width / 2)))
    b = np.column_stack((np.full(n, -length / 2), np.linspace(-width / 2, width / 2, n)))
    local = np.vstack((a, b[1:]))
    c, s = math.cos(theta), math.sin(theta)
    pts = np.column_stack((cx + c * local[:, 0] - s * local[:, 1], cy + s * local[:, 0] + c * local[:, 1]))
    return pts + rng.normal(0.0, noise, pts.shape)


@pytest.mark.parametrize("criterion", ["variance", "closeness", "area"])
@pytest.mark.parametrize("theta", [0.0, 0.3, 0.9, 1.4])
def test_l_shape_recovers_heading_and_sides(criterion: str, theta: float) -> None:
    pts = l_shape(3.0, 1.0, theta, 1.2, 0.6, noise=0.003)
    if criterion == "area":
        # on an L the triangle's hypotenuse-aligned rectangle has the same area (Zhang 2017: area is the
        # weakest criterion); test it on a full outline instead
        box = Box(3.0, 1.0, theta, 1.2, 0.6)
        pts = np.vstack([np.linspace(box.corners()[i], box.corners()[(i + 1) % 4], 20) for i in range(4)])
    fit = fit_rectangle(pts, criterion)
    err = abs(float(wrap_angle(4 * (fit.theta - theta))) / 4)  # modulo 90°
    assert err < math.radians(1.5)
    assert sorted(fit.extent.round(2)) == pytest.approx([0.6, 1.2], abs=0.03)
    assert np.hypot(*(fit.center() - [3.0, 1.0])) < 0.03
    assert fit.rms < 0.01


def test_corners_are_clockwise_and_box_round_trip() -> None:
    box = Box(1.0, -2.0, 0.4, 2.0, 1.0)
    pts = np.vstack([np.linspace(box.corners()[i], box.corners()[(i + 1) % 4], 20) for i in range(4)])
    fit = fit_rectangle(pts, "area")  # a full outline: the area criterion (Zhang's others assume an L)
    c = fit.corners()
    # signed area of c0→c1→c2→c3 is negative for a clockwise polygon
    area = 0.5 * sum(c[i, 0] * c[(i + 1) % 4, 1] - c[(i + 1) % 4, 0] * c[i, 1] for i in range(4))
    assert area == pytest.approx(-2.0, rel=0.02)
    assert box.as_array().tolist() == [1.0, -2.0, 0.4, 2.0, 1.0]


def test_batch_kernel_matches_numpy_fit() -> None:
    clusters = [l_shape(2, 0, 0.2, 1.0, 0.5, 15, 0.005, 1), l_shape(-1, 4, 1.1, 0.4, 0.4, 8, 0.005, 2),
                l_shape(0, -3, 0.7, 2.0, 0.1, 25, 0.005, 3)]
    pts = np.vstack(clusters)
    offsets = np.cumsum([0] + [c.shape[0] for c in clusters])
    for criterion in ("variance", "closeness", "area"):
        out = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, np.ones(3, dtype=bool), search_angles(1.0),
                           CRITERIA[criterion], 0.01, 5)
        for c, cl in enumerate(clusters):
            ref = fit_rectangle(cl, criterion)
            assert out[c, 0] == pytest.approx(ref.theta, abs=1e-9)
            assert out[c, 1:5] == pytest.approx([ref.lo[0], ref.hi[0], ref.lo[1], ref.hi[1]], abs=1e-9)
            assert out[c, 5] == pytest.approx(ref.rms, abs=1e-9)
            assert out[c, 10:12] == pytest.approx(cl.mean(axis=0))
            coarse = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, np.ones(3, dtype=bool),
                                  search_angles(1.0), CRITERIA[criterion], 0.01, 5, 5)
            if criterion != "area":  # coarse-to-fine finds the same optimum on L-shapes
                assert coarse[c, 0] == pytest.approx(ref.theta, abs=math.radians(1.01))


def _plain_rect_row(x: list[float], y: list[float], cos_t: list[float], sin_t: list[float], criterion: int,
                    d0: float, stride: int) -> list[float]:
    """θ, lo1, hi1, lo2, hi2, rms of one cluster with every angle scored in plain float arithmetic: the sums of
    squares to both edges taken point by point in order (the decision the kernel may take from the bound of
    shapes._near_side_known instead), the same coarse-to-fine order and tie rules."""
    n, kk = len(x), len(cos_t)

    def project(c: float, s: float) -> tuple:
        c1 = [c * x[i] + s * y[i] for i in range(n)]
        c2 = [-s * x[i] + c * y[i] for i in range(n)]
        lo1, hi1, lo2, hi2 = math.inf, -math.inf, math.inf, -math.inf
        for u, v in zip(c1, c2):
            lo1, hi1, lo2, hi2 = min(lo1, u), max(hi1, u), min(lo2, v), max(hi2, v)
        return c1, c2, lo1, hi1, lo2, hi2

    def score(k: int) -> float:
        c1, c2, lo1, hi1, lo2, hi2 = project(cos_t[k], sin_t[k])
        if criterion == 0:
            return -(hi1 - lo1) * (hi2 - lo2)
        sa1 = sb1 = sa2 = sb2 = 0.0
        for u, v in zip(c1, c2):
            sa1 += (hi1 - u) ** 2
            sb1 += (u - lo1) ** 2
            sa2 += (hi2 - v) ** 2
            sb2 += (v - lo2) ** 2
        h1, h2 = sa1 < sb1, sa2 < sb2
        d = [(hi1 - u if h1 else u - lo1, hi2 - v if h2 else v - lo2) for u, v in zip(c1, c2)]
        if criterion == 1:
            sc = 0.0
            for d1, d2 in d:
                sc += 1.0 / max(min(d1, d2), d0)
            return sc
        s1 = q1 = s2 = q2 = 0.0
        m1 = m2 = 0
        for d1, d2 in d:
            if d1 < d2:
                s1, q1, m1 = s1 + d1, q1 + d1 * d1, m1 + 1
            else:
                s2, q2, m2 = s2 + d2, q2 + d2 * d2, m2 + 1
        v1 = q1 / m1 - (s1 / m1) ** 2 if m1 > 0 else 0.0
        v2 = q2 / m2 - (s2 / m2) ** 2 if m2 > 0 else 0.0
        return -v1 - v2

    best, best_k = -math.inf, 0
    for k in range(0, kk, stride):
        sc = score(k)
        if sc > best + 1e-12:
            best, best_k = sc, k
    if stride > 1:
        centre = best_k
        for dk in range(-stride + 1, stride):
            if dk:
                k = (centre + dk) % kk
                sc = score(k)
                if sc > best + 1e-12 or (abs(sc - best) <= 1e-12 and k < best_k):
                    best, best_k = sc, k
    c1, c2, lo1, hi1, lo2, hi2 = project(cos_t[best_k], sin_t[best_k])
    ss = 0.0
    for u, v in zip(c1, c2):
        r = min(min(hi1 - u, u - lo1), min(hi2 - v, v - lo2))
        ss += r * r
    return [math.atan2(sin_t[best_k], cos_t[best_k]), lo1, hi1, lo2, hi2, math.sqrt(ss / n)]


def test_batch_kernel_is_bit_identical_to_plain_sums_also_on_ties() -> None:
    """The kernel decides each axis' nearer edge from a bound when the sums of squares cannot compare otherwise
    (shapes._near_side_known) and sums them where they might: its rows equal the plain sums' bit for bit, on noisy
    L-shapes far from the origin (map frame) and on clusters built so that the two sums tie (points symmetric about
    their middle along an axis: equal sums in exact arithmetic, the bound must leave them to the sums)."""
    rng = np.random.default_rng(11)
    clusters = [l_shape(rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(0, math.pi), rng.uniform(0.1, 2.0),
                        rng.uniform(0.05, 1.0), int(rng.integers(3, 40)), 0.01, q) for q in range(40)]
    for q in range(12):  # symmetric point sets: ties of the sums at several angles (0°, 45°, 90° of a square grid)
        g = np.arange(-(q % 4) - 1, (q % 4) + 2, dtype=float) * 0.05
        xx, yy = np.meshgrid(g, g if q % 2 else g[:2])
        clusters.append(np.column_stack((xx.ravel() + (q - 6) * 3.0, yy.ravel() + 12.5)))
    clusters.append(np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]]))  # zero width: always the sums
    pts = np.vstack(clusters)
    offsets = np.cumsum([0] + [c.shape[0] for c in clusters])
    # (the kernel scores two angles per pass over the points, pass sim36: 1° with stride 4 has 23 coarse angles and
    # 7° with stride 1 has 13, so a lone last angle in the coarse search and in the whole search; stride 7 has 12
    # fine angles, stride 5 eight)
    for step_deg, strides in ((1.0, (1, 4, 5, 7)), (7.0, (1, 2))):
        angles = search_angles(step_deg)
        cos_t, sin_t = np.cos(angles).tolist(), np.sin(angles).tolist()
        for criterion in (0, 1, 2):
            for stride in strides:
                out = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, np.ones(len(clusters), dtype=bool),
                                   angles, criterion, 0.01, 5, stride)
                for c, cl in enumerate(clusters):
                    want = _plain_rect_row(cl[:, 0].tolist(), cl[:, 1].tolist(), cos_t, sin_t, criterion, 0.01,
                                           stride)
                    assert out[c, :6].tolist() == want, (step_deg, criterion, stride, c)


@pytest.mark.parametrize("pts", [np.zeros((0, 2)), np.array([[1.0, 2.0]]), np.array([[1.0, 2.0], [1.0, 2.0]]),
                                 np.column_stack((np.linspace(0, 1, 5), np.zeros(5)))])
def test_degenerate_clusters_never_give_nan(pts: np.ndarray) -> None:
    fit = fit_rectangle(pts)
    assert np.isfinite([fit.theta, fit.rms, *fit.lo, *fit.hi]).all()
    cx, cy, r, rms = fit_circle(pts)
    assert math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r)
    if pts.shape[0] >= 1:
        out = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), np.array([0, pts.shape[0]]), np.ones(1, dtype=bool),
                           search_angles(1.0), 2, 0.01, 5)
        assert np.isfinite(out[0, :9]).all()


def test_circle_fit_on_a_half_arc() -> None:
    a = np.linspace(math.pi / 2, 3 * math.pi / 2, 20)
    rng = np.random.default_rng(4)
    pts = np.column_stack((5 + 0.22 * np.cos(a), 1 + 0.22 * np.sin(a))) + rng.normal(0, 0.003, (20, 2))
    cx, cy, r, rms = fit_circle(pts)
    assert math.hypot(cx - 5, cy - 1) < 0.01 and abs(r - 0.22) < 0.01 and rms < 0.006


def _scan_geometry(pts: np.ndarray, sensor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fake 'scan' arrays for classify_and_bound: the cluster as beams 10.. with empty neighbours."""
    n = pts.shape[0]
    ranges = np.full(n + 20, np.inf)
    ranges[10:10 + n] = np.hypot(*(pts - sensor).T)
    valid = np.isfinite(ranges)
    allpts = np.zeros((n + 20, 2))
    allpts[10:10 + n] = pts
    return ranges, valid, allpts


def _detect(pts: np.ndarray, sensor: np.ndarray, cfg: FitConfig):
    pts = pts[np.argsort(np.arctan2(pts[:, 1] - sensor[1], pts[:, 0] - sensor[0]))]  # scan order
    row = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), np.array([0, pts.shape[0]]), np.ones(1, dtype=bool),
                       search_angles(1.0), 2, 0.01, cfg.circle_min_points)[0]
    ranges, valid, allpts = _scan_geometry(pts, sensor)
    return classify_and_bound(np.arange(10, 10 + pts.shape[0]), pts, row, sensor, ranges, valid, allpts, False, 1,
                              20.0, cfg, math.radians(0.5))


def test_l_shape_centre_is_measured_in_both_axes() -> None:
    cfg = FitConfig()
    pts = l_shape(4.0, 0.0, 0.0, 1.0, 0.6, 40)  # corner (3.5, -0.3) faces the sensor diagonally
    det = _detect(pts, np.array([2.0, -2.0]), cfg)
    assert det.kind == "rect" and det.rel.all()
    m = measure(det, None, None, cfg)
    assert np.hypot(*(m.z - [4.0, 0.0])) < 0.02
    assert m.size_kind.tolist() == [SIZE_MEASURED, SIZE_MEASURED]
    assert np.allclose(np.sort(m.H[:, :2], axis=None), np.sort(np.eye(2), axis=None))


def test_single_face_uses_tracked_depth_behind_the_face() -> None:
    cfg = FitConfig()
    face = np.column_stack((np.full(40, 3.5), np.linspace(-0.5, 0.5, 40)))  # the x = 3.5 side of a 1×1 box
    det = _detect(face, np.zeros(2), cfg)
    m = measure(det, np.array([1.0, 1.0]), None, cfg)
    assert np.hypot(*(m.z - [4.0, 0.0])) < 0.02  # centre 0.5 m behind the face, away from the sensor
    kinds = sorted(m.size_kind.tolist())
    assert kinds == [SIZE_LOWER, SIZE_MEASURED]


def test_grazing_wall_piece_gives_no_position_along_the_wall() -> None:
    """A piece of wall whose ends continue as the same surface: along the wall only a
    zero-velocity pseudo-measurement, never a position."""
    cfg = FitConfig()
    sensor = np.zeros(2)
    wall = np.column_stack((np.linspace(2.0, 2.6, 20), np.full(20, 1.0)))
    n = wall.shape[0]
    ranges = np.full(n + 20, np.inf)
    allpts = np.zeros((n + 20, 2))
    # the wall continues on both sides (beams 9 and 10+n hit it too)
    ext = np.column_stack((np.array([1.8, 2.8]), np.array([1.0, 1.0])))
    allpts[10:10 + n] = wall
    allpts[9], allpts[10 + n] = ext
    ranges[9:11 + n] = np.hypot(*allpts[9:11 + n].T)
    valid = np.isfinite(ranges)
    row = fit_clusters(wall[:, 0].copy(), wall[:, 1].copy(), np.array([0, n]), np.ones(1, dtype=bool),
                       search_angles(1.0), 2, 0.01, 5)[0]
    det = classify_and_bound(np.arange(10, 10 + n), wall, row, sensor, ranges, valid, allpts, False, 1, 20.0, cfg,
                             math.radians(0.5))
    m = measure(det, None, None, cfg)
    along = np.array([1.0, 0.0])
    pos_rows = [h for h in m.H if np.any(h[:2])]
    vel_rows = [h for h in m.H if np.any(h[2:])]
    assert len(pos_rows) == 1 and abs(pos_rows[0][:2] @ along) < 1e-6  # only the normal (y) is measured
    assert len(vel_rows) == 1 and abs(abs(vel_rows[0][2:] @ along) - 1) < 1e-6


def test_round_cluster_uses_circle_model_and_true_centre() -> None:
    cfg = FitConfig()
    a = np.linspace(math.pi / 2 + 0.2, 3 * math.pi / 2 - 0.2, 18)
    pts = np.column_stack((3 + 0.22 * np.cos(a), 0.22 * np.sin(a)))
    det = _detect(pts, np.zeros(2), cfg)
    assert det.kind == "circle"
    m = measure(det, None, None, cfg)
    assert np.hypot(*(m.z - [3.0, 0.0])) < 0.01
    assert np.hypot(*(det.centroid - [3.0, 0.0])) > 0.1  # the centroid alone would be biased


def _plain_circle(x: list[float], y: list[float]) -> list[float]:
    """The circle fit of ``shapes._circle_one`` as plain Python on floats, with its Gauss–Newton loop in the form it
    had before pass trk22 (distance, Jacobian and sums in one loop per point): cx, cy, r, rms."""
    from dynslam2d.detect.shapes import _lu_solve3

    n = len(x)
    mx = my = 0.0
    for i in range(n):
        mx += x[i]
        my += y[i]
    mx /= n
    my /= n
    suu = suv = svv = suuu = svvv = suvv = svuu = 0.0
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
    if n < 3 or abs(det) < 1e-12:
        return [mx, my, 0.0, math.inf]
    b1 = 0.5 * (suuu + suvv)
    b2 = 0.5 * (svvv + svuu)
    uc = (b1 * svv - b2 * suv) / det
    vc = (suu * b2 - suv * b1) / det
    cx, cy = uc + mx, vc + my
    r = math.sqrt(uc * uc + vc * vc + (suu + svv) / n)
    a = np.empty((3, 3))
    step = np.empty(3)
    for _ in range(5):
        h00 = h01 = h02 = h11 = h12 = h22 = g0 = g1 = g2 = 0.0
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
            h02 += -j0
            h11 += j1 * j1
            h12 += -j1
            h22 += 1.0
            g0 += j0 * res
            g1 += j1 * res
            g2 += -res
        a[:] = [[h00 + 1e-9, h01, h02], [h01, h11 + 1e-9, h12], [h02, h12, h22 + 1e-9]]
        step[:] = [-g0, -g1, -g2]
        if abs(_lu_solve3.py_func(a, step)) < 1e-15:
            break
        s0, s1, s2 = step.tolist()
        cx += s0
        cy += s1
        r += s2
        if abs(s0) + abs(s1) + abs(s2) < 1e-6:
            break
    if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r)) or r <= 0.0:
        return [mx, my, 0.0, math.inf]
    ss = 0.0
    for i in range(n):
        dx = x[i] - cx  # ((x[i] - cx) ** 2 in the kernel: numba squares by a product; Python's ** calls pow)
        dy = y[i] - cy
        d = math.sqrt(dx * dx + dy * dy) - r
        ss += d * d
    return [cx, cy, r, math.sqrt(ss / n)]


def test_circle_fits_are_bit_identical_to_the_plain_gauss_newton_loop() -> None:
    """``_circle_one`` (its Gauss–Newton distances and Jacobians from a vectorised loop, ``_gn_terms``, pass trk22)
    equals the plain one-loop fit bit for bit — through ``fit_circle`` and in ``fit_clusters``' circle columns, whose
    work space is the rectangle search's (reused after it): noisy arcs of people and poles far from the origin, full
    circles, a point at the centre (d = 0, skipped), collinear and repeated points (degenerate)."""
    rng = np.random.default_rng(23)
    clusters = []
    for _q in range(120):
        n = int(rng.integers(3, 60))
        a0 = rng.uniform(0, 2 * math.pi)
        a = a0 + np.linspace(0.0, rng.uniform(0.3, 2 * math.pi), n)
        c = rng.uniform(-60, 60, 2)
        r = rng.uniform(0.03, 0.6)
        clusters.append(np.column_stack((c[0] + r * np.cos(a), c[1] + r * np.sin(a))) + rng.normal(0, 0.004, (n, 2)))
    sq = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    clusters.append(np.vstack((sq, [[0.0, 0.0]])))  # a point at the fitted centre: its d is 0, it is skipped
    clusters.append(np.column_stack((np.linspace(0, 1, 7), np.zeros(7))))  # collinear
    clusters.append(np.array([[2.0, 3.0]] * 5))  # repeated
    pts = np.vstack(clusters)
    offsets = np.cumsum([0] + [c.shape[0] for c in clusters])
    out = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, np.ones(len(clusters), dtype=bool),
                       search_angles(1.0), 2, 0.01, 3, 5)
    for c, cl in enumerate(clusters):
        want = _plain_circle(cl[:, 0].tolist(), cl[:, 1].tolist())
        got = fit_circle(cl)
        assert [float(v) for v in got] == want or (math.isnan(want[0]) and math.isnan(got[0])), c
        assert out[c, 6:10].tolist() == want, c


def _reach_clusters(rng: np.random.Generator) -> list[np.ndarray]:
    """Arcs (radius 0.05–0.6 m, 20°–360°, noise up to 5 cm, some with an outlier), noisy walls and L-shapes, far
    from the origin as in the map frame."""
    out = []
    for q in range(160):
        cx, cy = rng.uniform(-60, 60, 2)
        n = int(rng.integers(5, 80))
        if q % 3:
            r = rng.uniform(0.05, 0.6)
            a0 = rng.uniform(0, 2 * math.pi)
            a = a0 + np.linspace(0.0, math.radians(rng.uniform(20, 360)), n)
            pts = np.column_stack((cx + r * np.cos(a), cy + r * np.sin(a))) + rng.normal(0, rng.uniform(0, 0.05),
                                                                                          (n, 2))
            if q % 5 == 0:
                pts[n // 2] += rng.uniform(-0.5, 0.5, 2)
        else:
            pts = l_shape(cx, cy, rng.uniform(0, math.pi), rng.uniform(0.3, 4.0), rng.uniform(0.0, 1.0),
                          max(n // 2, 3), rng.uniform(0, 0.04), q)
        out.append(pts)
    return out


def test_circle_reach_is_a_bound_of_the_circle_fits() -> None:
    """Pass fit34: on every cluster the rectangle's longest side is at most 2r + √(2n)·rms of its circle fit (r its
    radius, rms its residual: shapes._circle_reach's lemma, here on the full fits of arcs, walls and L-shapes), so a
    side from ``_circle_reach`` on can have no circle with r ≤ the maximum radius, short side ≥ depth ratio · r and
    rms < ratio · the rectangle's rms; and the bound does skip clusters."""
    rng = np.random.default_rng(34)
    clusters = _reach_clusters(rng)
    pts = np.vstack(clusters)
    offsets = np.cumsum([0] + [c.shape[0] for c in clusters])
    out = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, np.ones(len(clusters), dtype=bool),
                       search_angles(1.0), CRITERIA["variance"], 0.01, 5, 5)
    skipped = 0
    for c in range(len(clusters)):
        n = int(offsets[c + 1] - offsets[c])
        th, lo1, hi1, lo2, hi2, rect_rms, _, _, r, rms, mx, my = out[c].tolist()
        side = max(hi1 - lo1, hi2 - lo2)
        short = min(hi1 - lo1, hi2 - lo2)
        if r > 0.0:
            assert side <= 2.0 * r + math.sqrt(2.0 * n) * rms * (1.0 + 1e-12) + 1e-12, c
        for max_r, depth, ratio in ((0.45, 0.5, 0.6), (0.6, 0.0, 1.0), (0.3, 1.0, 3.0), (0.45, 0.25, 0.6)):
            if side >= _circle_reach(n, rect_rms, mx, my, side, short, max_r, depth, ratio):
                skipped += 1
                assert not (r <= max_r and short >= depth * r and rms < ratio * rect_rms), (c, max_r, depth, ratio)
    assert skipped > 80


def test_kept_trig_table_gives_the_same_rows() -> None:
    """Pass fit34: ``fit_cluster_rows`` fills a new (NaN) table with the angles' cos, sin and atan2 (libm's, as
    Python's math), and calls with the kept table give ``fit_clusters``' rows bit for bit (every criterion and
    stride), as does the first call."""
    rng = np.random.default_rng(5)
    clusters = _reach_clusters(rng)[:60]
    pts = np.vstack(clusters)
    offsets = np.cumsum([0] + [c.shape[0] for c in clusters])
    angles = search_angles(1.0)
    mask = np.ones(len(clusters), dtype=bool)
    trig = np.full((3, angles.shape[0]), np.nan)
    for criterion in (0, 1, 2):
        for stride in (1, 5):
            want = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), offsets, mask, angles, criterion, 0.01, 5, stride)
            got = fit_cluster_rows(pts[:, 0].copy(), pts[:, 1].copy(), offsets, mask, angles, trig, criterion, 0.01,
                                   5, stride, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            assert got.tobytes() == want.tobytes(), (criterion, stride)
    a = angles.tolist()
    assert trig[0].tolist() == [math.cos(t) for t in a] and trig[1].tolist() == [math.sin(t) for t in a]
    assert trig[2].tolist() == [math.atan2(math.sin(t), math.cos(t)) for t in a]


def test_four_lane_search_is_the_scalar_search_bit_for_bit() -> None:
    """Pass det39: ``fit_cluster_rows`` scores the angles four at a time as lanes of one vector value
    (``shapes._fit_vec`` / ``_score4``); its six rectangle values equal the former scalar kernel's
    (``shapes._fit_one``, two angles a pass) bit for bit: noisy L-shapes, walls, arcs and single points far from
    the origin, clusters of 1–70 points, clusters symmetric about their middle (ties of the edge sums, ties of
    the scores), a zero-width cluster (the undecided edge, always summed), every criterion, angle counts and
    strides whose coarse and fine lists are not multiples of four (the last group filled up)."""
    from dynslam2d.detect.shapes import _fit_one, _fit_vec

    rng = np.random.default_rng(39)
    clusters = []
    for q in range(60):
        n = int(rng.integers(1, 70))
        cx, cy = rng.uniform(-60, 60, 2)
        kind = q % 4
        if kind == 0:
            clusters.append(l_shape(cx, cy, rng.uniform(0, math.pi), rng.uniform(0.1, 4.0), rng.uniform(0.05, 2.0),
                                    max(n // 2, 2), rng.uniform(0, 0.03), q))
        elif kind == 1:
            a = rng.uniform(0, math.pi, n)
            r = rng.uniform(0.05, 0.5)
            clusters.append(np.column_stack((cx + r * np.cos(a), cy + r * np.sin(a))) + rng.normal(0, 0.005, (n, 2)))
        elif kind == 2:
            t = np.linspace(0, rng.uniform(0.5, 6.0), n)
            h = rng.uniform(0, math.pi)
            clusters.append(np.column_stack((cx + t * math.cos(h), cy + t * math.sin(h))) + rng.normal(0, 0.01, (n, 2)))
        else:
            clusters.append(rng.normal(0, 0.05, (n, 2)) + [cx, cy])
    for q in range(8):  # symmetric grids: equal sums and equal scores at several angles
        g = np.arange(-(q % 4) - 1, (q % 4) + 2, dtype=float) * 0.05
        xx, yy = np.meshgrid(g, g if q % 2 else g[:2])
        clusters.append(np.column_stack((xx.ravel() + (q - 4) * 3.0, yy.ravel() - 7.5)))
    clusters.append(np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]]))  # zero width
    for step_deg, strides in ((1.0, (1, 3, 4, 5, 6, 7)), (7.0, (1, 2, 3)), (2.5, (5,))):
        angles = search_angles(step_deg)
        trig = np.vstack((np.cos(angles), np.sin(angles), np.arctan2(np.sin(angles), np.cos(angles))))
        for criterion in (0, 1, 2):
            for stride in strides:
                for c, cl in enumerate(clusters):
                    x, y = cl[:, 0].copy(), cl[:, 1].copy()
                    n = x.shape[0]
                    want, got = np.empty(6), np.empty(6)
                    order = np.empty(angles.shape[0] + 2 * stride, dtype=np.int64)
                    _fit_one(x, y, trig, criterion, 0.01, want, stride, np.empty((6, n)), order)
                    _fit_vec(x, y, trig, criterion, 0.01, got, stride, np.empty(8 * n), order.copy(),
                             np.empty(order.shape[0]), np.empty(n), np.empty(n))
                    assert got.tobytes() == want.tobytes(), (step_deg, criterion, stride, c)


def test_four_lane_edge_decision_is_the_scalar_one() -> None:
    """Pass det40: ``shapes._edges4`` decides the nearer edges of four lanes and both axes at once; it says "known"
    exactly when ``_near_side_known`` decides every lane of both axes (not −1), and then gives its flags, so the search
    takes the scalar rule's edges: projections whose sums sit on either side of the error bound (a factor 10^−0.5 …
    10^2 around it), ties, zero and tiny widths, huge and non-finite bounds, 1–200 points, on either axis."""
    from dynslam2d.detect.shapes import _U, _edges4, _near_side_known
    from dynslam2d.jitbox import njit
    from dynslam2d.jitvec import vget, vset

    @njit
    def lanes(n, b):  # (b: rows lo1, hi1, t1, lo2, hi2, t2 of four lanes)
        use1, use2, known = _edges4(n, vset(b[0, 0], b[0, 1], b[0, 2], b[0, 3]),
                                    vset(b[1, 0], b[1, 1], b[1, 2], b[1, 3]), vset(b[2, 0], b[2, 1], b[2, 2], b[2, 3]),
                                    vset(b[3, 0], b[3, 1], b[3, 2], b[3, 3]), vset(b[4, 0], b[4, 1], b[4, 2], b[4, 3]),
                                    vset(b[5, 0], b[5, 1], b[5, 2], b[5, 3]))
        out = np.empty((2, 4))
        for j in range(4):
            out[0, j] = vget(use1, j)
            out[1, j] = vget(use2, j)
        return out, known

    rng = np.random.default_rng(40)

    def row(n: int) -> tuple[float, float, float]:
        lo = rng.normal(0, 10) * 10.0 ** rng.integers(-3, 4)
        hi = lo + abs(rng.normal(0, 1)) * 10.0 ** rng.integers(-8, 3)
        w, m = hi - lo, max(abs(hi), abs(lo))
        bound = 8.0 * (n + 4) * _U * (4.0 * n * m + n * w)
        e = rng.choice([-1.0, 1.0]) * bound * 10.0 ** rng.uniform(-0.5, 2)
        return lo, hi, (n * (hi + lo) - e) / 2.0

    special = [(1.0, 1.0), (0.0, 1e-101), (-1e101, 1.0), (0.0, np.inf), (np.nan, 1.0), (-np.inf, np.inf)]
    counts = [0, 0]
    for q in range(3000):
        n = int(rng.choice([1, 2, 7, 19, 200])) if q % 10 else int(rng.integers(1, 200))
        rows = [row(n) for _ in range(4)]
        if q % 50 == 0:  # (a special lane: never decided)
            lo, hi = special[(q // 50) % len(special)]
            rows[q % 4] = (lo, hi, n * (lo + hi) / 2.0)
        fill = [(0.0, 1.0, 0.1 * n)] * 4  # (the other axis: decided, the near edge lo for any n)
        axis = q % 2
        b = np.array((rows + fill) if axis == 0 else (fill + rows)).reshape(2, 4, 3).transpose(0, 2, 1).reshape(6, 4)
        with np.errstate(all="ignore"):
            got, known = lanes(n, b)
        want = [_near_side_known(n, *r) for r in rows]
        assert known == all(f >= 0 for f in want), (n, rows, want)
        counts[known] += 1
        if known:
            assert got[axis].tolist() == [float(f) for f in want], (n, rows, want, got)
            assert got[1 - axis].tolist() == [float(_near_side_known(n, *fill[0]))] * 4
    assert min(counts) > 300  # (both outcomes often)
