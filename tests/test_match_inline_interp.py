"""The matcher's support count and free fraction read the probability cache inline (pass mat71): the same values as
``interp_value_grad`` and ``fraction_below`` on random caches, with points outside the map, NaN points, points on
the map's last interpolable row / column and thresholds equal to interpolated values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.slam.grid import encode_probs
from dynslam2d.slam.interp import interp_value_grad
from dynslam2d.slam.matcher import (
    _N_BINS,
    _bearing_bin,
    _bearing_pos,
    _bin_at,
    _scaled_rows,
    _sums,
    _support_kernel,
    fraction_below,
)


def _cache(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """(h, w) probability cache words of random probabilities, a share of them exactly 0.5 / 0.0 / 1.0."""
    p = rng.uniform(0.0, 1.0, (h, w))
    pick = rng.uniform(size=(h, w))
    p[pick < 0.2] = 0.5
    p[pick > 0.95] = 1.0
    p[(pick > 0.9) & (pick <= 0.95)] = 0.0
    return encode_probs(p)


def _points(rng: np.random.Generator, n: int, reach: float) -> np.ndarray:
    """(n, 2) laser-frame points (m), some NaN, some at the origin."""
    pts = rng.uniform(-reach, reach, (n, 2))
    pts[rng.uniform(size=n) < 0.03] = np.nan
    pts[rng.uniform(size=n) < 0.01] = 0.0
    return pts


def _fraction_below_rows(prob: np.ndarray, xy: np.ndarray, x: float, y: float, th: float, thresh: float) -> float:
    """match_pyramid's free fraction: ``_sums``' count mode (pass mat148: not ``full``, ``stats``, the threshold in
    g[0]) over n points; H and g untouched."""
    H = np.full((3, 3), 7.0)
    g = np.array([thresh, 7.0, 7.0])
    _, summ, n = _sums(prob, xy, x, y, th, np.bool_(False), np.bool_(False), np.bool_(True), H, g)
    assert summ == 0.0 and np.all(H == 7.0) and g.tolist() == [thresh, 7.0, 7.0]
    return n / max(xy.shape[1], 1)


def _reference_support(prob: np.ndarray, pts: np.ndarray, stride: int, inv_res: float, x: float, y: float,
                       th: float, thresh: float) -> tuple[int, int]:
    """_support_kernel's definition: interp_value_grad's (value, inside) at each stride-th point, atan2 bins."""
    c, s = math.cos(th), math.sin(th)
    n = 0
    seen = set()
    for i in range(0, pts.shape[0], stride):
        sx = float(pts[i, 0]) * inv_res
        sy = float(pts[i, 1]) * inv_res
        m, _, _, inside = interp_value_grad(prob, c * sx - s * sy + x, s * sx + c * sy + y, False)
        if inside and m > thresh:
            n += 1
            seen.add(int(math.floor((math.atan2(pts[i, 1], pts[i, 0]) + math.pi) / (2.0 * math.pi) * _N_BINS))
                     % _N_BINS)
    return n, len(seen)


@pytest.mark.parametrize("seed", range(6))
def test_support_and_free_fraction_equal_their_definitions(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(2, 60)), int(rng.integers(2, 60))
    prob = _cache(rng, h, w)
    res = float(rng.choice([0.05, 0.1, 0.2]))
    for _ in range(40):
        pts = _points(rng, int(rng.integers(1, 400)), 0.6 * max(h, w) * res)
        x, y = rng.uniform(-5.0, w + 5.0), rng.uniform(-5.0, h + 5.0)
        th = rng.uniform(-math.pi, math.pi)
        # thresholds: the usual ones and interpolated values of these points themselves (ties: > and < are strict)
        m, _, _, inside = interp_value_grad(prob, x, y, False)
        for thresh in (0.5, 0.45, 0.65, 0.0, 1.0, float(m) if inside else 0.3):
            stride = int(rng.integers(1, 4))
            got = _support_kernel(prob, pts, stride, 1.0 / res, x, y, th, thresh, np.int64(_N_BINS))
            assert tuple(int(v) for v in got) == _reference_support(prob, pts, stride, 1.0 / res, x, y, th, thresh)
            want = fraction_below(prob, pts / res, x, y, th, thresh)
            assert _fraction_below_rows(prob, _scaled_rows(pts, res), x, y, th, thresh) == want


def test_points_on_the_last_interpolable_cells_are_inside() -> None:
    """Map points at exactly column w − 2 / row h − 2 (the last ones with four cells) and just beyond."""
    rng = np.random.default_rng(7)
    h, w = 9, 13
    prob = _cache(rng, h, w)
    grid = np.array([[px, py] for px in (0.0, 0.5, w - 2.0, w - 2.0 + 1e-9, -1e-12)
                     for py in (0.0, 3.25, h - 2.0, h - 2.0 + 1e-9, -0.0)])
    for thresh in (0.0, 0.3, 0.5, 0.99):
        got = _support_kernel(prob, grid, 1, 1.0, 0.0, 0.0, 0.0, thresh, np.int64(_N_BINS))
        assert tuple(int(v) for v in got) == _reference_support(prob, grid, 1, 1.0, 0.0, 0.0, 0.0, thresh)
        assert _fraction_below_rows(prob, _scaled_rows(grid, 1.0), 0.0, 0.0, 0.0, thresh) == fraction_below(
            prob, grid / 1.0, 0.0, 0.0, 0.0, thresh)


def test_branch_free_bearing_position_gives_the_bearing_bin() -> None:
    """The support's bearing bins (pass mat148: ``_bin_at`` of the branch-free ``_bearing_pos``) are
    ``_bearing_bin``'s on random points and on the axes, the diagonals (|x| = |y|), signed zeros, the origin and bin
    edges, for the support's 72 bins and others."""
    rng = np.random.default_rng(5)
    pts = [tuple(p) for p in rng.normal(size=(3000, 2)) * rng.choice([1e-3, 1.0, 30.0], size=(3000, 1))]
    for v in (0.0, -0.0, 1.0, -1.0, 2.5, -7.0):
        for u in (0.0, -0.0, 1.0, -1.0, 2.5, -7.0):
            pts.append((v, u))
    for k in range(72):  # points on the bin edges (atan2 = −π + k·5°)
        a = -math.pi + k * 2.0 * math.pi / 72
        pts.append((math.cos(a), math.sin(a)))
    for nb in (72, 64, 7):
        for x, y in pts:
            assert _bin_at(_bearing_pos(x, y, nb), x, y, nb) == _bearing_bin(x, y, nb), (x, y, nb)
