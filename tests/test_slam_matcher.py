"""Scan matcher: interpolation and gradient, Gauss–Newton/LM convergence, correlative search,
covariance (Kohlbrecher et al. 2011, §IV-B/C)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import paper_room_scan

from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.correlative import correlative_search
from dynslam2d.slam.grid import encode_probs
from dynslam2d.slam.interp import interpolate
from dynslam2d.slam.matcher import covariance_world, evaluate, match_multires
from dynslam2d.types import Pose2D, wrap_angle

scan_at = paper_room_scan


def mapped_slam(cfg: SlamConfig, pose: Pose2D = Pose2D(0.3, -0.4, 0.2)) -> tuple[HectorSlam, Pose2D]:
    """A processor whose map holds three scans around ``pose``; returns it and ``pose`` in map frame."""
    slam = HectorSlam(cfg)
    first = pose
    slam.update_map(scan_at(pose), Pose2D(), force=True)
    for d in (Pose2D(0.3, 0.1, 0.1), Pose2D(-0.2, 0.3, -0.15)):
        p = pose.compose(d)
        slam.update_map(scan_at(p), first.between(p), force=True)
    return slam, first


# --------------------------------------------------------------------------- interpolation

def _bilinear(P: np.ndarray, x: float, y: float) -> float:
    x0, y0 = int(math.floor(x)), int(math.floor(y))
    fx, fy = x - x0, y - y0
    return ((1 - fy) * ((1 - fx) * P[y0, x0] + fx * P[y0, x0 + 1])
            + fy * ((1 - fx) * P[y0 + 1, x0] + fx * P[y0 + 1, x0 + 1]))


def test_interpolation_value_and_gradient_match_finite_differences() -> None:
    rng = np.random.default_rng(1)
    P = rng.uniform(0, 1, (7, 9)).astype(np.float32)
    pts = np.column_stack((rng.uniform(0.05, 6.95, 200), rng.uniform(0.05, 4.95, 200)))
    # keep away from cell borders so the central difference stays inside one bilinear patch
    frac = pts - np.floor(pts)
    pts = pts[np.all((frac > 0.01) & (frac < 0.99), axis=1)]
    m, gx, gy = interpolate(encode_probs(P), pts, False)
    h = 1e-5
    for k, (x, y) in enumerate(pts):
        assert m[k] == pytest.approx(_bilinear(P, x, y), abs=1e-6)
        assert gx[k] == pytest.approx((_bilinear(P, x + h, y) - _bilinear(P, x - h, y)) / (2 * h), abs=1e-5)
        assert gy[k] == pytest.approx((_bilinear(P, x, y + h) - _bilinear(P, x, y - h)) / (2 * h), abs=1e-5)
    # at cell centres the value is the cell's probability
    m, _, _ = interpolate(encode_probs(P), np.array([[3.0, 2.0], [0.0, 0.0]]), False)
    np.testing.assert_allclose(m, [P[2, 3], P[0, 0]], atol=1e-7)


def test_swapped_gradient_option_reproduces_reference_bug() -> None:
    P = np.zeros((3, 3), dtype=np.float32)  # in bounds needs x ≤ W−2
    P[:2, :2] = [[0.0, 1.0], [0.2, 0.9]]
    x, y = 0.2, 0.7  # fx ≠ fy
    _, gx, gy = interpolate(encode_probs(P), np.array([[x, y]]), False)
    _, bx, by = interpolate(encode_probs(P), np.array([[x, y]]), True)
    p00, p10, p01, p11 = 0.0, 1.0, 0.2, 0.9
    assert gx[0] == pytest.approx((1 - y) * (p10 - p00) + y * (p11 - p01), abs=1e-6)
    assert bx[0] == pytest.approx((1 - x) * (p10 - p00) + x * (p11 - p01), abs=1e-6)  # §2.2 code form
    assert by[0] == pytest.approx((1 - y) * (p01 - p00) + y * (p11 - p10), abs=1e-6)
    assert abs(gx[0] - bx[0]) > 0.1 and abs(gy[0] - by[0]) > 0.01


def test_out_of_bounds_and_nan_points_contribute_nothing() -> None:
    P = np.full((4, 4), 0.9, dtype=np.float32)
    m, gx, gy = interpolate(encode_probs(P), np.array([[-0.1, 1.0], [2.5, 2.01], [np.nan, 1.0], [1.0, np.inf]]), False)
    np.testing.assert_array_equal(m, 0.0)
    np.testing.assert_array_equal(gx, 0.0)
    np.testing.assert_array_equal(gy, 0.0)


# --------------------------------------------------------------------------- Gauss–Newton

@pytest.mark.parametrize(("step_mode", "swapped"), [("lm", False), ("gauss_newton", False), ("lm", True)])
def test_gauss_newton_recovers_known_offset(step_mode: str, swapped: bool) -> None:
    cfg = SlamConfig(step_mode=step_mode, correlative_mode="never", hector_gradient_bug=swapped)
    slam, first = mapped_slam(cfg)
    true = first.between(first.compose(Pose2D(0.15, 0.05, 0.05)))
    pts, _ = slam.scan_points(scan_at(first.compose(Pose2D(0.15, 0.05, 0.05))))
    start = true.compose(Pose2D(0.1, -0.05, 0.05))  # 0.11 m, 0.05 rad off
    out = match_multires(slam.map.levels, pts, start.as_array(), 4, 6, swapped=swapped, use_lm=step_mode == "lm")
    assert math.hypot(out[0] - true.x, out[1] - true.y) < 0.01
    assert abs(wrap_angle(out[2] - true.theta)) < 0.003
    # and the start really was off
    assert math.hypot(start.x - true.x, start.y - true.y) > 0.1


def test_gauss_newton_on_empty_map_keeps_the_start() -> None:
    slam = HectorSlam(SlamConfig())
    pts, _ = slam.scan_points(scan_at(Pose2D()))
    start = np.array([0.1, 0.2, 0.3])
    slam.map.levels[0].ensure(-50, -50, 50, 50)  # allocated but never updated: all p = 0.5
    np.testing.assert_allclose(match_multires(slam.map.levels, pts, start, 4, 6), start, atol=1e-12)


def test_lm_step_never_increases_the_cost() -> None:
    slam, first = mapped_slam(SlamConfig())
    pts, _ = slam.scan_points(scan_at(first.compose(Pose2D(0.1, 0.0, 0.0))))
    lv = slam.map.levels[0]
    rng = np.random.default_rng(5)
    for _ in range(10):
        start = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-0.5, 0.5)])
        out = match_multires(slam.map.levels, pts, start, 4, 6, use_lm=True)
        assert evaluate(lv, pts, out).cost <= evaluate(lv, pts, start).cost + 1e-9
        assert np.all(np.isfinite(out))


# --------------------------------------------------------------------------- correlative search

def test_correlative_search_recovers_large_offset_gn_cannot() -> None:
    slam, first = mapped_slam(SlamConfig())
    true = first.between(first.compose(Pose2D(0.1, 0.1, 0.0)))
    pts, _ = slam.scan_points(scan_at(first.compose(Pose2D(0.1, 0.1, 0.0))))
    start = Pose2D(true.x + 0.35, true.y - 0.35, true.theta + 0.5)  # 0.5 m and 0.5 rad off
    gn = match_multires(slam.map.levels, pts, start.as_array(), 4, 6)
    assert math.hypot(gn[0] - true.x, gn[1] - true.y) > 0.1 or abs(wrap_angle(gn[2] - true.theta)) > 0.1
    cr = correlative_search(slam.map.levels[1], pts, start.as_array(), 0.6, 0.7)
    assert cr is not None
    assert math.hypot(cr.pose[0] - true.x, cr.pose[1] - true.y) < 0.15
    assert abs(wrap_angle(cr.pose[2] - true.theta)) < 0.03
    refined = match_multires(slam.map.levels, pts, cr.pose, 4, 6)
    assert math.hypot(refined[0] - true.x, refined[1] - true.y) < 0.01
    assert abs(wrap_angle(refined[2] - true.theta)) < 0.003


def test_correlative_branch_and_bound_equals_brute_force() -> None:
    slam, first = mapped_slam(SlamConfig())
    pts, _ = slam.scan_points(scan_at(first.compose(Pose2D(0.2, 0.0, 0.1))))
    lv = slam.map.levels[1]
    start = np.array([0.1, -0.1, 0.05])
    kw = dict(angular_step=0.02, max_points=120, translation_weight=0.05, rotation_weight=0.05)
    cr = correlative_search(lv, pts, start, 0.4, 0.1, max_height=3, **kw)
    flat = correlative_search(lv, pts, start, 0.4, 0.1, max_height=0, **kw)  # exhaustive
    assert cr is not None and flat is not None
    assert cr.score == pytest.approx(flat.score, abs=1e-6)
    np.testing.assert_allclose(cr.pose, flat.pose, atol=1e-9)


def test_processor_uses_correlative_search_on_large_offsets() -> None:
    delta = Pose2D(0.3, 0.2, 0.6)
    results = {}
    for mode in ("never", "always"):
        slam, first = mapped_slam(SlamConfig(correlative_mode=mode))
        true = first.between(first.compose(delta))
        res = slam.match(scan_at(first.compose(delta), stamp=0.1), predicted=Pose2D(), commit=False)
        results[mode] = (math.hypot(res.pose.x - true.x, res.pose.y - true.y), res)
    assert results["always"][0] < 0.01 and results["always"][1].used_correlative
    assert results["never"][0] > 0.1 or results["never"][1].rejected


# --------------------------------------------------------------------------- covariance

def test_covariance_world_units_and_singular_guard() -> None:
    H = np.diag([400.0, 100.0, 1e4])
    C = covariance_world(H, 0.01, 0.05)
    np.testing.assert_allclose(np.diag(C), [0.01 / 400 * 0.0025, 0.01 / 100 * 0.0025, 0.01 / 1e4], rtol=1e-9)
    # a corridor: no information along x → large but finite variance there
    Hc = np.array([[0.0, 0.0, 0.0], [0.0, 100.0, 5.0], [0.0, 5.0, 1e4]])
    Cc = covariance_world(Hc, 0.01, 0.05)
    assert np.all(np.isfinite(Cc)) and Cc[0, 0] > 1e3 * Cc[1, 1]
    assert np.all(np.linalg.eigvalsh(Cc) > 0)
    Cz = covariance_world(np.zeros((3, 3)), 0.01, 0.05)
    assert np.all(np.isfinite(Cz)) and Cz[0, 0] >= 1e6


def test_match_reports_covariance_and_hessian() -> None:
    slam, first = mapped_slam(SlamConfig())
    res = slam.match(scan_at(first.compose(Pose2D(0.05, 0.0, 0.0)), stamp=0.1), commit=False)
    assert not res.rejected
    assert res.hessian[0, 0] > 0 and res.hessian[2, 2] > 0
    sd = np.sqrt(np.diag(res.covariance))
    assert np.all(sd > 0) and sd[0] < 0.05 and sd[1] < 0.05 and sd[2] < 0.02
    assert res.score > 0.4
