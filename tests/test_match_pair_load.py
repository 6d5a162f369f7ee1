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
from dynslam2d.slam.matcher import _scaled_rows, _sums, gated_points, no_drop
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
