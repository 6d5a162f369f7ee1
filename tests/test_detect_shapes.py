"""Rectangle (Zhang 2017 search), circle and batch fits; the measurement geometry of a cluster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import FitConfig, fit_circle, fit_clusters, fit_rectangle, search_angles
from dynslam2d.detect.layout import SIZE_LOWER, SIZE_MEASURED
from dynslam2d.detect.reference import classify_and_bound, measure
from dynslam2d.detect.shapes import CRITERIA
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
