"""The matcher's fused kernels give exactly what the plain computation gives (issues 9/13, matching pass 8):
the whole pyramid in one kernel call (``match_pyramid``) against the per-level loop of ``match_level`` calls,
``evaluate`` and ``free_fraction`` at the result, the polynomial bearing bin against ``atan2``, and the correlative
search's score pyramid and rotated point cells against their array expressions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam
from numba import njit

from dynslam2d.slam.correlative import _pyramid, _rotated_cells, _score_pyramid, _score_table
from dynslam2d.slam.grid import decode_probs, encode_probs
from dynslam2d.slam.matcher import _bearing_bin, _split_xy, _sums, evaluate, free_fraction, match_level, match_multires
from dynslam2d.types import Pose2D, wrap_angle

scan_at = paper_room_scan


mapped = paper_room_slam


def level_loop(levels, pts, start, it_coarse, it_finest, swapped, use_lm, prior_world=None, prior_info=None):
    """The coarse-to-fine loop written out with one ``match_level`` call per level (the reference): (world pose,
    level 0's map pose before the conversion to the world)."""
    pose = np.array(start, dtype=np.float64)
    out = None
    for k in range(len(levels) - 1, -1, -1):
        lv = levels[k]
        n_iter = it_finest if k == 0 else it_coarse
        if lv.empty or n_iter <= 0:
            continue
        mp = lv.pose_to_map(pose)
        if prior_info is not None:
            pp = lv.pose_to_map(prior_world)
            pp[2] = mp[2] + (pp[2] - mp[2] + math.pi) % (2.0 * math.pi) - math.pi
            S = np.diag([lv.resolution, lv.resolution, 1.0])
            lam = S @ prior_info @ S
        else:
            pp, lam = mp, np.zeros((3, 3))
        out, _ = match_level(lv.prob, pts / lv.resolution, mp, n_iter, swapped, use_lm, 0.1, 1e4, 0.2, 2.0, pp, lam)
        pose = lv.pose_to_world(out)
        pose[2] = (pose[2] + math.pi) % (2.0 * math.pi) - math.pi
    return pose, out


@pytest.mark.parametrize("n_levels", [1, 2, 3])
def test_pyramid_kernel_equals_the_level_loop_and_evaluate(n_levels: int) -> None:
    slam, first = mapped(n_levels)
    levels = slam.map.levels
    pts = slam.scan_points(scan_at(first.compose(Pose2D(0.12, -0.08, 0.05))))[0]
    prior_info = np.array([[30.0, 2.0, 0.5], [2.0, 10.0, 0.1], [0.5, 0.1, 40.0]])
    reused = computed = 0
    frees: list[float] = []
    for off in ((0.0, 0.0, 0.0), (0.15, -0.1, 0.08), (-0.2, 0.05, -0.12), (0.03, 0.03, 0.3), (0.0, 0.0, 3.1)):
        start = np.array(off)
        for swapped in (False, True):
            for use_lm in (True, False):
                for prior in (False, True):
                    kw = dict(prior_world=start + np.array([0.02, -0.01, 0.03]), prior_info=prior_info) if prior \
                        else {}
                    fit: list = []
                    got = match_multires(levels, pts, start, 4, 6, swapped, use_lm, fit=fit, free_thresh=0.45, **kw)
                    want, last0 = level_loop(levels, pts, start, 4, 6, swapped, use_lm, **kw)
                    np.testing.assert_array_equal(got, want)  # bit-identical, not merely close
                    ev = evaluate(levels[0], pts, want)
                    f, free = fit
                    np.testing.assert_array_equal(f.hessian, ev.hessian)
                    assert (f.cost, f.score, f.n_inside) == (ev.cost, ev.score, ev.n_inside)
                    at = Pose2D(float(want[0]), float(want[1]), float(wrap_angle(want[2]))).as_array()
                    assert free == free_fraction(levels[min(1, n_levels - 1)], pts, at, 0.45)
                    frees.append(free)
                    # the kernel's two ways to the evaluation (the last iteration's sums when level 0's map pose
                    # survives the round trip through the world frame unchanged, else a fresh pass): both occur
                    if not swapped:
                        if np.array_equal(last0, levels[0].pose_to_map(want)):
                            reused += 1
                        else:
                            computed += 1
    assert reused > 0 and computed > 0
    assert len(set(frees)) > 1  # the free fraction is not a constant here


def test_pyramid_without_points_or_iterations_returns_the_start() -> None:
    slam, first = mapped(3)
    start = np.array([0.1, 0.2, 0.3])
    fit: list = []
    np.testing.assert_array_equal(match_multires(slam.map.levels, np.zeros((0, 2)), start, 4, 6, fit=fit), start)
    assert fit == []
    pts = slam.scan_points(scan_at(first))[0]
    np.testing.assert_array_equal(match_multires(slam.map.levels, pts, start, 0, 0, fit=fit), start)
    ev = evaluate(slam.map.levels[0], pts, start)
    np.testing.assert_array_equal(fit[0].hessian, ev.hessian)
    assert fit[0].score == ev.score and fit[1] == free_fraction(slam.map.levels[1], pts, start, 0.5)


@njit(cache=False)
def _bins_differ(xs, ys, nb):  # pragma: no cover - numba
    bad = 0
    for i in range(xs.shape[0]):
        want = int(math.floor((math.atan2(ys[i], xs[i]) + math.pi) / (2.0 * math.pi) * nb)) % nb
        if _bearing_bin(xs[i], ys[i], nb) != want:
            bad += 1
    return bad


def test_polynomial_bearing_bin_equals_atan2_bin() -> None:
    rng = np.random.default_rng(1)
    a = rng.uniform(-math.pi, math.pi, 200_000)
    r = rng.uniform(0.01, 30.0, a.size)
    assert _bins_differ(r * np.cos(a), r * np.sin(a), 72) == 0
    # at and around every bin edge (where the polynomial alone would pick the wrong bin), both signs of zero
    edges = -math.pi + np.arange(73) * (2.0 * math.pi / 72)
    a = (edges[:, None] + np.linspace(-2e-4, 2e-4, 2001)[None, :]).ravel()
    r = rng.uniform(0.1, 20.0, a.size)
    assert _bins_differ(r * np.cos(a), r * np.sin(a), 72) == 0
    special = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 3.0])
    x, y = np.meshgrid(special, special)
    assert _bins_differ(x.ravel(), y.ravel(), 72) == 0
    # the polynomial's error bound the edge margin relies on (Abramowitz & Stegun 4.4.49)
    z = np.linspace(0.0, 1.0, 200_001)
    z2 = z * z
    poly = z * (0.9998660 + z2 * (-0.3302995 + z2 * (0.1801410 + z2 * (-0.0851330 + z2 * 0.0208351))))
    assert np.abs(poly - np.arctan(z)).max() < 1.2e-5


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (5, 1), (2, 2), (3, 3), (17, 40), (40, 17), (120, 95)])
def test_score_pyramid_kernel_equals_the_array_table_and_pyramid(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(2)
    big = rng.uniform(0.0, 1.0, (shape[0] + 4, shape[1] + 6)).astype(np.float32)
    big[rng.uniform(size=big.shape) < 0.3] = 0.5  # unknown
    big[rng.uniform(size=big.shape) < 0.1] = 1.0
    crop = big[2:2 + shape[0], 3:3 + shape[1]]  # a strided crop, as the search passes
    for hmax in range(7):  # (up to blocks wider and higher than the array: 2^(h−1) ≥ its sides)
        want = _pyramid(_score_table(crop), hmax)
        words = encode_probs(big)[2:2 + shape[0], 3:3 + shape[1]]  # (the cache's words)
        for got in (_score_pyramid(words, hmax), _score_pyramid(np.ascontiguousarray(words), hmax)):
            assert got.dtype == want.dtype == np.float32  # (a strided crop, and a whole level's rows: contiguous)
            np.testing.assert_array_equal(got.view(np.int32), want.view(np.int32))  # (bit for bit)
    if min(shape) >= 3:
        t0 = _score_pyramid(encode_probs(big)[2:2 + shape[0], 3:3 + shape[1]], 0)[0]
        assert np.any((t0 > 0.0) & (np.maximum(2.0 * crop - 1.0, 0.0) == 0.0))  # the half-value smear reached


@pytest.mark.parametrize("n", [1, 7, 240])
def test_rotated_cells_kernel_equals_the_array_expressions(n: int) -> None:
    rng = np.random.default_rng(3)
    pc = rng.uniform(-300.0, 300.0, (n, 2))
    pc[::3] = np.round(pc[::3] * 2.0) / 2.0  # half-cell values, where the rounding of floor(v + 0.5) decides
    th = 0.3 + np.arange(-20, 21) * 0.01
    mp = (123.25, -50.5)
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    want_x = np.floor(c * pc[None, :, 0] - s * pc[None, :, 1] + mp[0] + 0.5).astype(np.int64)
    want_y = np.floor(s * pc[None, :, 0] + c * pc[None, :, 1] + mp[1] + 0.5).astype(np.int64)
    qx, qy, x0, x1, y0, y1 = _rotated_cells(pc, np.cos(th), np.sin(th), mp[0], mp[1])
    np.testing.assert_array_equal(qx, want_x)
    np.testing.assert_array_equal(qy, want_y)
    assert (x0, x1, y0, y1) == (want_x.min(), want_x.max(), want_y.min(), want_y.max())


@njit(cache=False)
def _sums_one_loop(prob, pts, x, y, th, swapped, full, H, g):  # pragma: no cover - numba
    """The matcher's pass as one loop over the points (``matcher._sums`` before pass front21, verbatim but for the
    names): the reference its blocked, vectorised form must equal bit for bit."""
    c = math.cos(th)
    s = math.sin(th)
    h, w = prob.shape
    flat = np.ascontiguousarray(prob).reshape(-1)
    xmax = w - 2
    ymax = h - 2
    cost = 0.0
    summ = 0.0
    n_in = 0
    g0 = g1 = g2 = h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    for i in range(pts.shape[0]):
        sx = pts[i, 0]
        sy = pts[i, 1]
        qx = c * sx - s * sy + x
        qy = s * sx + c * sy + y
        if not (qx >= 0.0 and qy >= 0.0 and qx <= xmax and qy <= ymax):
            cost += 1.0
            continue
        x0 = int(qx)
        y0 = int(qy)
        fx = qx - x0
        fy = qy - y0
        k = np.uint64(y0) * np.uint64(w) + np.uint64(x0)
        p00 = flat[k]
        p10 = flat[k + np.uint64(1)]
        p01 = flat[k + np.uint64(w)]
        p11 = flat[k + np.uint64(w + 1)]
        m = (1.0 - fy) * ((1.0 - fx) * p00 + fx * p10) + fy * ((1.0 - fx) * p01 + fx * p11)
        r = 1.0 - m
        cost += r * r
        if not full:
            continue
        if swapped:
            mx = (1.0 - fx) * (p10 - p00) + fx * (p11 - p01)
            my = (1.0 - fy) * (p01 - p00) + fy * (p11 - p10)
        else:
            mx = (1.0 - fy) * (p10 - p00) + fy * (p11 - p01)
            my = (1.0 - fx) * (p01 - p00) + fx * (p11 - p10)
        summ += m
        n_in += 1
        dth = (-s * sx - c * sy) * mx + (c * sx - s * sy) * my
        g0 += r * mx
        g1 += r * my
        g2 += r * dth
        h00 += mx * mx
        h01 += mx * my
        h02 += mx * dth
        h11 += my * my
        h12 += my * dth
        h22 += dth * dth
    if full:
        g[0] = g0
        g[1] = g1
        g[2] = g2
        H[0, 0] = h00
        H[0, 1] = h01
        H[0, 2] = h02
        H[1, 0] = h01
        H[1, 1] = h11
        H[1, 2] = h12
        H[2, 0] = h02
        H[2, 1] = h12
        H[2, 2] = h22
    return cost, summ, n_in


def _blocked_pass(prob, pts, x, y, th, swapped, full, stats=True):
    H = np.full((3, 3), 7.0)
    g = np.full(3, 7.0)
    out = _sums(prob, _xy_rows(pts), x, y, th, swapped, np.bool_(full), np.bool_(stats), H, g)
    return out, H, g


def _one_loop_pass(prob, pts, x, y, th, swapped, full, stats=True):
    """The reference pass; without ``stats`` its Σ M and n_inside as 0 (what ``_sums`` returns then: pass map38)."""
    H = np.full((3, 3), 7.0)
    g = np.full(3, 7.0)
    out = _sums_one_loop(prob, pts, x, y, th, swapped, full, H, g)
    return (out if stats else (out[0], 0.0, 0)), H, g


#: (full, stats) of the passes the matcher makes: the cost, H, g with and without Σ M / n_inside, the cost alone
#: ((False, True) is the free fraction's count mode: tests/test_match_inline_interp.py)
_MODES = ((True, True), (True, False), (False, False))


def _same(a, b) -> None:
    (ca, sa, na), Ha, ga = a
    (cb, sb, nb), Hb, gb = b
    assert np.float64(ca).tobytes() == np.float64(cb).tobytes()
    assert np.float64(sa).tobytes() == np.float64(sb).tobytes()
    assert na == nb
    assert Ha.tobytes() == Hb.tobytes() and ga.tobytes() == gb.tobytes()


@pytest.mark.parametrize("level", [0, 1, 2])
def test_blocked_pass_equals_the_one_loop_pass_on_a_mapped_room(level: int) -> None:
    """``matcher._sums`` (blocked, vectorised; pass front21) against the one-loop pass on a real map: poses that
    put every point inside, some outside and all outside, both gradient forms, with and without the gradient sums
    (and Σ M / n_inside, pass map38), point counts on both sides of the block size."""
    slam, first = mapped(3)
    lv = slam.map.levels[level]
    pts_m = slam.scan_points(scan_at(first.compose(Pose2D(0.12, -0.08, 0.05))))[0]
    n_diff = 0
    for n in (0, 1, 5, 127, 128, 129, 300, pts_m.shape[0]):
        pts = np.ascontiguousarray(pts_m[:n] / lv.resolution)
        for off in ((0.0, 0.0, 0.0), (0.37, -0.21, 0.07), (-3.0, 2.0, -0.4), (40.0, 0.0, 1.0), (0.0, -90.0, 3.1),
                    (1e9, 0.0, 0.0), (math.nan, 0.0, 0.0), (0.0, 0.0, math.nan)):
            mp = lv.pose_to_map(first.as_array())
            x, y, th = mp[0] + off[0], mp[1] + off[1], mp[2] + off[2]
            for swapped in (False, True):
                for full, stats in _MODES:
                    want = _one_loop_pass(decode_probs(lv.prob), pts, x, y, th, swapped, full, stats)
                    _same(_blocked_pass(lv.prob, pts, x, y, th, swapped, full, stats), want)
                    n_diff += full and stats and 0 < want[0][2] < n  # some points inside, some outside
    assert n_diff > 0


def test_blocked_pass_equals_the_one_loop_pass_on_random_and_tiny_maps() -> None:
    """The same on random probability maps with tiny cells (subnormal-free but far from 0.5), maps of one and two
    cells a side (no point can be inside a map narrower than two cells), and points on the cell lines and the
    array's last interpolable row and column."""
    rng = np.random.default_rng(21)
    for shape in ((1, 1), (1, 5), (2, 2), (2, 9), (3, 3), (17, 40), (260, 131)):
        for _ in range(4):
            prob = rng.random(shape).astype(np.float32)
            prob[rng.random(shape) < 0.1] = np.float32(1e-30)
            h, w = shape
            n = int(rng.integers(0, 400))
            pts = np.column_stack([rng.uniform(-2.0, w + 1.0, n), rng.uniform(-2.0, h + 1.0, n)])
            if n > 4:
                pts[:4] = [[0.0, 0.0], [w - 2.0, h - 2.0], [w - 2.0, 0.5], [1.0, h - 2.0]]
            for x, y, th in ((0.0, 0.0, 0.0), (0.3, -0.2, 0.01), (1.5, 0.25, -0.3)):
                for swapped in (False, True):
                    for full, stats in _MODES:
                        _same(_blocked_pass(encode_probs(prob), pts, x, y, th, swapped, full, stats),
                              _one_loop_pass(prob, pts, x, y, th, swapped, full, stats))


@njit(cache=False)
def _xy_rows(pts):  # pragma: no cover - numba
    return _split_xy(pts)
