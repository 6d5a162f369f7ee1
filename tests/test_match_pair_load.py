"""Pass stg119 (docs/speed.md): the matcher's cells read two at a time (``cell_prob_pair``: one 8-byte load of a
cell and its right neighbour), the cost-only pass computing only the cost's terms, and ``gated_points`` classifying
each beam once — each the values of the forms they replace, bit for bit."""

from __future__ import annotations

import math

import numpy as np
from conftest import paper_room_scan, paper_room_slam
from numba import njit

from dynslam2d.slam.grid import encode_probs
from dynslam2d.slam.interp import cell_prob, cell_prob_pair
from dynslam2d.slam.matcher import _degeneracy_kernel, _scaled_rows, _sums, gated_points, no_drop
from dynslam2d.types import Pose2D


@njit(cache=False)
def _pairs(flat):  # pragma: no cover - numba
    """Every k's pair (k = 0 … n − 2: odd k reads 8 bytes across an 8-byte boundary) and its two single reads."""
    n = flat.shape[0] - 1
    out = np.empty((n, 4), dtype=np.float32)
    for k in range(n):
        a, b = cell_prob_pair(flat, k)
        out[k, 0] = a
        out[k, 1] = b
        out[k, 2] = cell_prob(flat[k])
        out[k, 3] = cell_prob(flat[k + 1])
    return out


def test_a_pair_read_is_the_two_cells_read_one_by_one() -> None:
    rng = np.random.default_rng(3)
    probs = rng.uniform(0.0, 1.0, 257).astype(np.float32)
    probs[:4] = (0.0, 1.0, 0.5, np.float32(0.5) + np.float32(1e-7))
    flat = encode_probs(probs)
    got = _pairs(flat)
    assert got[:, 0].tobytes() == got[:, 2].tobytes()
    assert got[:, 1].tobytes() == got[:, 3].tobytes()
    assert got[:, 0].tobytes() == probs[:-1].tobytes()  # (the encoding's round trip: every bit kept)
    assert got[-1, 1] == probs[-1]  # (the last pair ends on the array's last word)


def test_the_cost_only_pass_gives_the_full_passs_cost_bit_for_bit() -> None:
    slam, pose = paper_room_slam()
    pts = slam.scan_points(paper_room_scan(Pose2D(pose.x + 0.05, pose.y - 0.03, pose.theta + 0.02)))[0]
    rng = np.random.default_rng(7)
    n_out = 0
    for lv in slam.map.levels:
        xy = _scaled_rows(pts, lv.resolution)
        h, w = lv.prob.shape
        for _ in range(40):
            # around the map's middle, some poses far enough off that points fall outside (cost 1 each)
            x = rng.uniform(-0.3, 1.3) * w
            y = rng.uniform(-0.3, 1.3) * h
            th = rng.uniform(-math.pi, math.pi)
            H = np.zeros((3, 3))
            g = np.zeros(3)
            full = _sums(lv.prob, xy, x, y, th, np.bool_(False), np.bool_(True), np.bool_(False), H, g)
            cost = _sums(lv.prob, xy, x, y, th, np.bool_(False), np.bool_(False), np.bool_(False), H, g)
            assert math.copysign(1.0, cost[0]) == math.copysign(1.0, full[0])
            assert cost[0] == full[0]
            n_out += int(full[0] >= 1.0)
    assert n_out > 0


def _gated_reference(r, cos_a, sin_a, valid, lo, hi, dmin, dmax, clear, drop):
    """``gated_points``' outputs by NumPy masks (its docstring's definitions)."""
    r = np.where(drop, np.nan, r)
    valid = valid & ~drop
    keep = valid & (r > dmin) & (r < dmax)
    fin = np.isfinite(r)
    ray = ~keep & (clear > 0.0) & (~fin | (r > hi) | (r >= dmax))
    pts = np.stack([r[keep] * cos_a[keep], r[keep] * sin_a[keep]], axis=1)
    ends = np.stack([clear * cos_a[ray], clear * sin_a[ray]], axis=1)
    with np.errstate(invalid="ignore"):
        ok = fin & (r >= lo) & (r <= hi)
    return pts, ends, int(ok.sum()), int((ok & (r <= dmin)).sum())


def test_gated_points_equal_the_mask_reference_with_drops_and_bad_ranges() -> None:
    rng = np.random.default_rng(11)
    for trial in range(30):
        n = int(rng.integers(1, 900))
        a = np.linspace(-math.pi, math.pi, n, endpoint=False)
        r = rng.uniform(0.0, 35.0, n)
        bad = rng.random(n)
        r[bad < 0.05] = np.nan
        r[(bad >= 0.05) & (bad < 0.1)] = np.inf
        r[(bad >= 0.1) & (bad < 0.15)] = -np.inf
        r[(bad >= 0.15) & (bad < 0.25)] = rng.uniform(0.0, 0.3, int(((bad >= 0.15) & (bad < 0.25)).sum()))
        lo, hi = 0.05, 30.0
        valid = np.isfinite(r) & (r >= lo) & (r <= hi)
        cos_a, sin_a = np.cos(a), np.sin(a)
        drop = rng.random(n) < 0.1 if trial % 2 else no_drop(n)
        clear = 0.0 if trial % 3 == 0 else 3.0
        pts, ends, n_valid, n_close, _, _ = gated_points(r, cos_a, sin_a, valid, lo, hi, 0.2, 25.0, clear, True,
                                                         drop)
        want = _gated_reference(r, cos_a, sin_a, valid, lo, hi, 0.2, 25.0, clear, drop)
        assert pts.tobytes() == want[0].tobytes() and pts.shape == want[0].shape
        assert ends.tobytes() == want[1].tobytes() and ends.shape == want[1].shape
        assert (n_valid, n_close) == want[2:]


def test_the_matchers_degeneracy_values_are_the_processors_bit_for_bit() -> None:
    """``match_multires(..., degeneracy_threshold=t)``'s fit holds :func:`degeneracy_values` of its Hessian (the axis
    normalised by ``unit_axis``): every value's bits, on the paper room at poses around its first one, with the gate's
    Σ x² + y² (and none without it)."""
    from dynslam2d.slam.matcher import degeneracy_values, match_multires, unit_axis

    slam, pose = paper_room_slam()
    rng = np.random.default_rng(5)
    n_deg = 0
    for i in range(40):
        start = Pose2D(pose.x + rng.normal(0.0, 0.1), pose.y + rng.normal(0.0, 0.1), pose.theta + rng.normal(0, 0.05))
        pts, _, _, _, _, sumsq = gated_points(*_gate_args(slam, paper_room_scan(start)))
        if i % 3 == 0:  # a few points only: a weak, often degenerate Hessian
            pts = np.ascontiguousarray(pts[rng.integers(0, pts.shape[0], 12)])
            sumsq = float(np.einsum("ij,ij->", pts, pts))
        for t in (0.05, 0.5):
            fit: list = []
            match_multires(slam.map.levels, pts, start.as_array(), 4, 6, fit=fit, free_thresh=0.45,
                           degeneracy_threshold=t, sumsq=sumsq)
            got = list(fit[0].degeneracy)
            got[3], got[4] = unit_axis(got[3], got[4])
            want = degeneracy_values(fit[0].hessian, slam.map.levels[0].resolution, pts, t, sumsq)
            assert np.array(got[:7]).tobytes() == np.array(want[:7]).tobytes()
            assert tuple(got[7:]) == tuple(want[7:])
            n_deg += int(want[7] or want[8])
    assert n_deg > 0
    fit = []
    match_multires(slam.map.levels, pts, start.as_array(), 4, 6, fit=fit, degeneracy_threshold=0.1)
    assert fit[0].degeneracy is None  # (without the gate's Σ x² + y²: the processor computes it)


def _gate_args(slam, scan):  # type: ignore[no-untyped-def]
    c = slam.config
    cos_a, sin_a = scan.trig()
    return (scan.ranges, cos_a, sin_a, scan.valid_view(), float(scan.range_min), float(scan.range_max),
            float(c.laser_min_dist), float(c.laser_max_dist), float(c.clear_no_return_dist), True,
            no_drop(scan.ranges.shape[0]))


@njit(cache=False)
def _kernel_values(Hs, res, n, sumsq, t):  # pragma: no cover - numba
    out = np.empty((Hs.shape[0], 9))
    two = 2.0 + 0.0 * t  # (a run-time 2.0, as match_multires passes it)
    for i in range(Hs.shape[0]):
        r0, r1, r2, ax, ay, rho, lam, t_deg, r_deg = _degeneracy_kernel(Hs[i], res, n, sumsq, t, two)
        out[i, 0] = r0
        out[i, 1] = r1
        out[i, 2] = r2
        out[i, 3] = ax
        out[i, 4] = ay
        out[i, 5] = rho
        out[i, 6] = lam
        out[i, 7] = 1.0 if t_deg else 0.0
        out[i, 8] = 1.0 if r_deg else 0.0
    return out


def test_the_degeneracy_kernel_equals_degeneracy_values_on_many_hessians() -> None:
    """Random symmetric and asymmetric Hessians (thousands: ``x ** 2`` of CPython — the C library's ``pow`` — and
    ``x * x`` differ for about one value in a thousand, so a kernel squaring by multiplication fails here)."""
    from dynslam2d.slam.matcher import degeneracy_values, unit_axis

    rng = np.random.default_rng(9)
    Hs = rng.normal(0.0, 1.0, (6000, 3, 3)) * rng.choice([1e-3, 1.0, 1e3, 1e5], (6000, 1, 1))
    Hs[: 3000] = Hs[: 3000] @ Hs[: 3000].transpose(0, 2, 1)  # (positive semi-definite ones)
    Hs[5990:, 2, 2] = 0.0
    pts = rng.normal(0.0, 4.0, (300, 2))
    sumsq = float(np.einsum("ij,ij->", pts, pts))
    got = _kernel_values(Hs, 0.05, pts.shape[0], sumsq, 0.1)
    for i in range(Hs.shape[0]):
        want = degeneracy_values(Hs[i], 0.05, pts, 0.1, sumsq)
        ax, ay = unit_axis(got[i, 3], got[i, 4])
        row = (got[i, 0], got[i, 1], got[i, 2], ax, ay, got[i, 5], got[i, 6])
        assert np.array(row).tobytes() == np.array(want[:7]).tobytes(), i
        assert (got[i, 7] != 0.0, got[i, 8] != 0.0) == tuple(want[7:])
