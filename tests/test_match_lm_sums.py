"""Match pass 10 (issue 13): the matcher's LM pass with its sums in local variables and flat cell reads, and the
cost-only trial passes, give the bits the previous kernels gave. The previous ``accumulate`` (via
``interp_value_grad``, sums into ``H`` / ``g``) and ``_match_core`` (every LM trial a full pass) are copied here
as the reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam
from numba import njit

from dynslam2d.slam.grid import encode_probs
from dynslam2d.slam.interp import interp_value_grad
from dynslam2d.slam.matcher import _match_core, _prior_cost, _round_trips, _solve3, _split_xy, _sums, accumulate
from dynslam2d.types import Pose2D


@njit(cache=False)
def old_accumulate(prob, pts, x, y, th, swapped, H, g):  # pragma: no cover - numba
    c = math.cos(th)
    s = math.sin(th)
    for a in range(3):
        g[a] = 0.0
        for b in range(3):
            H[a, b] = 0.0
    cost = 0.0
    summ = 0.0
    n_in = 0
    for i in range(pts.shape[0]):
        sx = pts[i, 0]
        sy = pts[i, 1]
        qx = c * sx - s * sy + x
        qy = s * sx + c * sy + y
        m, mx, my, inside = interp_value_grad(prob, qx, qy, swapped)
        r = 1.0 - m
        cost += r * r
        if not inside:
            continue
        summ += m
        n_in += 1
        dth = (-s * sx - c * sy) * mx + (c * sx - s * sy) * my
        g[0] += r * mx
        g[1] += r * my
        g[2] += r * dth
        H[0, 0] += mx * mx
        H[0, 1] += mx * my
        H[0, 2] += mx * dth
        H[1, 1] += my * my
        H[1, 2] += my * dth
        H[2, 2] += dth * dth
    H[1, 0] = H[0, 1]
    H[2, 0] = H[0, 2]
    H[2, 1] = H[1, 2]
    return cost, summ, n_in


@njit(cache=False)
def old_match_core(prob, pts, pose, n_iter, swapped, use_lm, lam0, lam_max, max_rot, max_trans, prior, lam_p,
                   H_out):  # pragma: no cover - numba
    """The pass-9 ``_match_core``: every LM trial a full pass."""
    H = np.zeros((3, 3))
    g = np.zeros(3)
    H2 = np.zeros((3, 3))
    g2 = np.zeros(3)
    A = np.zeros((3, 3))
    d = np.zeros(3)
    x = pose[0]
    y = pose[1]
    th = pose[2]
    use_prior = False
    for a in range(3):
        for b in range(3):
            if lam_p[a, b] != 0.0:
                use_prior = True
    gp = np.zeros(3)
    raw, summ, n_in = old_accumulate(prob, pts, x, y, th, swapped, H, g)
    cost = raw
    if use_prior:
        cost += _prior_cost(x, y, th, prior, lam_p)
    lam = lam0
    n_acc = 0
    for _ in range(n_iter):
        if H[0, 0] == 0.0 or H[1, 1] == 0.0:
            break
        for a in range(3):
            gp[a] = g[a]
            for b in range(3):
                A[a, b] = H[a, b]
        if use_prior:
            r0 = prior[0] - x
            r1 = prior[1] - y
            r2 = prior[2] - th
            for a in range(3):
                gp[a] += lam_p[a, 0] * r0 + lam_p[a, 1] * r1 + lam_p[a, 2] * r2
                for b in range(3):
                    A[a, b] += lam_p[a, b]
        if use_lm:
            for a in range(3):
                A[a, a] += lam * A[a, a] + 1e-9
        if not _solve3(A, gp, d):
            if use_lm:
                lam *= 10.0
                if lam > lam_max:
                    break
                continue
            break
        if d[2] > max_rot:
            d[2] = max_rot
        elif d[2] < -max_rot:
            d[2] = -max_rot
        nt = math.sqrt(d[0] * d[0] + d[1] * d[1])
        if nt > max_trans:
            d[0] *= max_trans / nt
            d[1] *= max_trans / nt
        nx = x + d[0]
        ny = y + d[1]
        nth = th + d[2]
        if use_lm:
            new_raw, new_summ, new_in = old_accumulate(prob, pts, nx, ny, nth, swapped, H2, g2)
            new_cost = new_raw
            if use_prior:
                new_cost += _prior_cost(nx, ny, nth, prior, lam_p)
            if new_cost < cost:
                x, y, th = nx, ny, nth
                cost = new_cost
                raw, summ, n_in = new_raw, new_summ, new_in
                H, H2 = H2, H
                g, g2 = g2, g
                lam = max(lam * 0.1, 1e-7)
                n_acc += 1
                if nt < 1e-3 and abs(d[2]) < 1e-5:
                    break
            else:
                lam *= 10.0
                if lam > lam_max:
                    break
        else:
            x, y, th = nx, ny, nth
            raw, summ, n_in = old_accumulate(prob, pts, x, y, th, swapped, H, g)
            cost = raw
            if use_prior:
                cost += _prior_cost(x, y, th, prior, lam_p)
            n_acc += 1
    for a in range(3):
        for b in range(3):
            H_out[a, b] = H[a, b]
    return x, y, th, n_acc, raw, summ, n_in


def test_sums_equal_the_interp_accumulate_bit_for_bit() -> None:
    """Random float32 maps (values in [0, 1] and beyond), points inside, across the edges and NaN, both gradient
    weights: H, g, cost, Σ M and n_inside the same bits; the cost-only pass the same cost."""
    rng = np.random.default_rng(13)
    n_out = 0
    for trial in range(60):
        h, w = rng.integers(3, 60, size=2)
        prob = rng.random((h, w)).astype(np.float32)
        if trial % 5 == 0:
            prob *= np.float32(3.0)
        prob = encode_probs(prob)  # (the cache's words, as a level holds them)
        n = int(rng.integers(0, 400))
        pts = np.column_stack((rng.uniform(-0.3 * w, 1.3 * w, n), rng.uniform(-0.3 * h, 1.3 * h, n)))
        if n > 3 and trial % 4 == 0:
            pts[rng.integers(0, n, 3), rng.integers(0, 2, 3)] = np.nan
        x, y, th = rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0), rng.uniform(-0.4, 0.4)
        for swapped in (False, True):
            H0, g0, H1, g1 = np.full((3, 3), 7.0), np.full(3, 7.0), np.full((3, 3), 5.0), np.full(3, 5.0)
            ref = old_accumulate(prob, pts, x, y, th, swapped, H0, g0)
            got = accumulate(prob, pts, x, y, th, swapped, H1, g1)
            assert ref == got and H0.tobytes() == H1.tobytes() and g0.tobytes() == g1.tobytes()
            H2 = np.full((3, 3), 5.0)
            xy = np.ascontiguousarray(pts.T)  # (rows x, y)
            cost, summ, n_in = _sums(prob, xy, x, y, th, swapped, False, False, H2, g1)
            assert (cost, summ, n_in) == (ref[0], 0.0, 0) and np.all(H2 == 5.0)
            n_out += pts.shape[0] - ref[2]
    assert n_out > 1000  # out-of-bounds points were exercised


@pytest.mark.parametrize("n_levels", [1, 3])
def test_match_core_with_cost_only_trials_equals_the_full_passes(n_levels: int) -> None:
    """On the paper room's map (each level), from starts near and far, with and without the prior, LM and
    Gauss–Newton, both gradient weights, the iteration counts of the pipeline and longer ones: the same pose and
    accepted steps; with ``keep`` and a result that survives the round trip, the same H, cost, Σ M, n_inside."""
    slam, first = paper_room_slam(n_levels)
    pts_m = slam.scan_points(paper_room_scan(first.compose(Pose2D(0.12, -0.08, 0.05))))[0]
    lam_prior = np.array([[30.0, 2.0, 0.5], [2.0, 10.0, 0.1], [0.5, 0.1, 40.0]])
    kept = 0
    for lv in slam.map.levels:
        pts = pts_m / lv.resolution
        for off in ((0.0, 0.0, 0.0), (0.15, -0.1, 0.08), (-0.2, 0.05, -0.12), (0.03, 0.03, 0.3), (0.4, 0.3, 0.2)):
            start = lv.pose_to_map(np.array(off))
            for lam_p in (np.zeros((3, 3)), lam_prior):
                for use_lm in (True, False):
                    for swapped in (False, True):
                        for n_iter in (4, 6, 30):
                            Hr = np.zeros((3, 3))
                            ref = old_match_core(lv.prob, pts, start, n_iter, swapped, use_lm, 0.1, 1e4, 0.2, 2.0,
                                                 start, lam_p, Hr)
                            for keep in (False, True):
                                Hn = np.zeros((3, 3))
                                got = _match_core(lv.prob, _split_xy(pts), start, n_iter, swapped, use_lm, 0.1, 1e4,
                                                  0.2, 2.0, start, lam_p, Hn, keep, lv.resolution, float(lv.i0),
                                                  float(lv.j0))
                                assert np.array(got[:4]).tobytes() == np.array(ref[:4]).tobytes()
                                if keep and _round_trips(got[0], got[1], got[2], lv.resolution, float(lv.i0),
                                                         float(lv.j0)):
                                    kept += 1
                                    assert got[4:] == ref[4:] and Hn.tobytes() == Hr.tobytes()
    assert kept >= 4  # the kept-H comparison ran


def test_gated_points_counts_equal_close_count_and_angular_spread() -> None:
    """The scan gate's counts are ``close_count``'s and ``angular_spread``'s (bins × 2π/72), on scans with NaN,
    inf, out-of-range and too-close returns, narrow and wide views, 0 to 1500 beams; without ``stats`` zeros and
    the same points."""
    from dynslam2d.slam.matcher import BIN_ANGLE, angular_spread, close_count, gated_points

    rng = np.random.default_rng(7)
    narrow = 0
    for _ in range(300):
        n = int(rng.integers(0, 1500))
        fov = rng.choice([0.1, 0.6, 2.0, 2 * math.pi])
        a = rng.uniform(-math.pi, math.pi) + np.linspace(0.0, fov, n)
        r = rng.uniform(0.0, 12.0, n)
        bad = rng.random(n)
        r[bad < 0.05] = np.nan
        r[(bad >= 0.05) & (bad < 0.08)] = np.inf
        r[(bad >= 0.08) & (bad < 0.2)] = rng.uniform(0.0, 0.3, int(((bad >= 0.08) & (bad < 0.2)).sum()))
        lo, hi, min_d, max_d = 0.05, 10.0, float(rng.choice([0.0, 0.2, 0.25])), 9.0
        valid = np.isfinite(r) & (r >= lo) & (r <= hi)
        ca, sa = np.cos(a), np.sin(a)
        pts, clear, nv, nc, bins, ss = gated_points(r, ca, sa, valid, lo, hi, min_d, max_d, 3.0, True)
        p2, c2, z1, z2, z3, z4 = gated_points(r, ca, sa, valid, lo, hi, min_d, max_d, 3.0, False)
        assert (nv, nc) == close_count(r, lo, hi, min_d)
        assert bins * BIN_ANGLE == angular_spread(pts)
        assert (z1, z2, z3, z4) == (0, 0, 0, 0.0) and p2.tobytes() == pts.tobytes() and c2.tobytes() == clear.tobytes()
        narrow += bins * BIN_ANGLE < 0.5
    assert narrow > 10


@pytest.mark.parametrize("limits", [{}, {"relocalise_margin": 0.3}, {"relocalise_min_score": 0.999}])
def test_relocalising_with_the_search_bounds_gives_the_same_steps(monkeypatch: pytest.MonkeyPatch,
                                                                  limits: dict) -> None:
    """Lost after a blackout, then relocalised (default limits), or refused on the margin or on the score: the steps
    (poses, states, reasons) are the same bits whether the relocalising search gets the refusal bounds
    (``min_score`` / ``min_margin``) or not (the previous call)."""
    import dynslam2d.slam.processor as pr
    from dynslam2d.sim import simulate
    from dynslam2d.slam import HectorSlam, SlamConfig

    sim = simulate("static", duration=12.0)
    scans = []
    for i, s in enumerate(sim.scans):
        s = s.with_ranges(s.ranges)  # (no odometry / IMU: the laser alone)
        scans.append(s.with_ranges(np.full(s.ranges.shape, np.inf)) if 120 <= i < 180 else s)

    def run(drop_bounds: bool) -> tuple[list[bytes], int]:
        calls = [0]
        search = pr.correlative_search

        def wrapped(*a, **k):
            if "min_score" in k:
                calls[0] += 1
                if drop_bounds:
                    k.pop("min_score")
                    k.pop("min_margin")
            return search(*a, **k)

        monkeypatch.setattr(pr, "correlative_search", wrapped)
        slam = HectorSlam(SlamConfig(**limits))
        out = []
        for s in scans:
            st = slam.process(s)
            out.append(np.array([st.pose.x, st.pose.y, st.pose.theta, st.score]).tobytes()
                       + f"{st.state}|{st.reason}|{st.pose_source}|{st.map_updated}".encode())
        monkeypatch.setattr(pr, "correlative_search", search)
        return out, calls[0], slam.relocalisations

    with_bounds, n, found = run(False)
    without, n2, found2 = run(True)
    assert n == n2 and found == found2 and with_bounds == without
    assert n >= (1 if not limits else 2) and found <= 1  # with the limits raised, refused at least once
