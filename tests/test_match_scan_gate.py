"""Pass front23 (docs/speed.md): the scan gate's dropped beams and its sum of squares for the degeneracy's ρ."""

from __future__ import annotations

import math
import platform

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam

from dynslam2d.slam.matcher import _EINSUM_BLOCK, degeneracy, gated_points, no_drop
from dynslam2d.types import Pose2D

try:
    from numpy._core._multiarray_umath import c_einsum
except ImportError:  # pragma: no cover - another NumPy layout
    c_einsum = np.einsum

#: NumPy's einsum order (two lanes, four rows a step) is what its x86-64 wheels build (baseline without FMA); another
#: CPU's build (e.g. aarch64 with FMA) may round differently, so there the gate's sum is checked against the plain
#: form of its own order and einsum within 1e-12 only.
_EINSUM_ORDER_KNOWN = platform.machine().lower() in ("x86_64", "amd64")


def _lanes(pts: np.ndarray) -> float:
    """The plain form of the kernel's sum: NumPy 2.x's einsum ``ij,ij->`` order (two lanes, four rows a step with
    the last added first, the rest row by row; blocks of ``_EINSUM_BLOCK`` rows added in order to 0.0)."""
    out = 0.0
    for s in range(0, pts.shape[0], _EINSUM_BLOCK):
        b = pts[s:s + _EINSUM_BLOCK].tolist()
        lane = [0.0, 0.0]
        p = 0
        while len(b) - p >= 4:
            for c in (0, 1):
                t = b[p + 3][c] * b[p + 3][c] + lane[c]
                t = b[p + 2][c] * b[p + 2][c] + t
                t = b[p + 1][c] * b[p + 1][c] + t
                lane[c] = b[p][c] * b[p][c] + t
            p += 4
        for q in range(p, len(b)):
            for c in (0, 1):
                lane[c] = b[q][c] * b[q][c] + lane[c]
        out = out + (lane[0] + lane[1])
    return out


def _scan(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    a = np.linspace(-2.0, 2.0, n)
    r = rng.uniform(0.0, 12.0, n) * rng.choice([1.0, 30.0])
    bad = rng.random(n)
    r[bad < 0.05] = np.nan
    r[(bad >= 0.05) & (bad < 0.08)] = np.inf
    r[(bad >= 0.08) & (bad < 0.2)] = rng.uniform(0.0, 0.3, int(((bad >= 0.08) & (bad < 0.2)).sum()))
    valid = np.isfinite(r) & (r >= 0.05) & (r <= 300.0)
    return r, np.cos(a), np.sin(a), valid


def test_the_gates_sum_of_squares_is_einsums_and_the_plain_forms_bit_for_bit() -> None:
    """The sum the gate returns with ``stats`` equals the plain form of its order and NumPy's einsum (what
    degeneracy summed before) as bits: 0 … 9000 points (two einsum blocks and a part), ranges up to 360 m."""
    rng = np.random.default_rng(23)
    sizes = [0, 1, 2, 3, 4, 5, 7, 8, 9, 600, 1081, _EINSUM_BLOCK - 1, _EINSUM_BLOCK, _EINSUM_BLOCK + 3, 9000]
    for n in sizes + [int(v) for v in rng.integers(0, 1500, 60)]:
        r, ca, sa, valid = _scan(rng, n)
        pts, _, _, _, _, ss = gated_points(r, ca, sa, valid, 0.05, 300.0, 0.2, 290.0, 3.0, True, no_drop(n))
        want = float(c_einsum("ij,ij->", pts, pts))
        assert math.copysign(1.0, ss) == 1.0
        assert np.float64(ss).tobytes() == np.float64(_lanes(pts)).tobytes(), n
        if _EINSUM_ORDER_KNOWN:
            assert np.float64(ss).tobytes() == np.float64(want).tobytes(), n
        assert abs(ss - want) <= 1e-12 * max(ss, 1.0)
        assert abs(ss - float(np.sum(pts.astype(np.float64) ** 2))) <= 1e-12 * max(ss, 1.0)


def test_dropped_beams_give_what_the_scan_without_them_gives() -> None:
    """``drop`` gives the points, clearing-ray ends and counts of the ranges with NaN at the dropped beams and
    ``valid`` False there (``Scan.without``), with and without ``stats``; no drop is the plain call's."""
    rng = np.random.default_rng(5)
    for _ in range(120):
        n = int(rng.integers(0, 1500))
        r, ca, sa, valid = _scan(rng, n)
        drop = rng.random(n) < rng.choice([0.0, 0.05, 0.5, 1.0])
        r2 = r.copy()
        r2[drop] = np.nan
        v2 = valid & ~drop
        for stats in (True, False):
            for clear_dist in (3.0, 0.0):
                got = gated_points(r, ca, sa, valid, 0.05, 300.0, 0.2, 290.0, clear_dist, stats, drop)
                want = gated_points(r2, ca, sa, v2, 0.05, 300.0, 0.2, 290.0, clear_dist, stats, no_drop(n))
                assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
                assert got[2:] == want[2:]
                plain = gated_points(r2, ca, sa, v2, 0.05, 300.0, 0.2, 290.0, clear_dist, stats)  # (no drop given)
                assert plain[0].tobytes() == want[0].tobytes() and plain[2:] == want[2:]


def test_degeneracy_with_the_gates_sum_equals_its_own() -> None:
    """``degeneracy`` given the gate's sum returns what it computes from the points itself."""
    rng = np.random.default_rng(11)
    for _ in range(50):
        n = int(rng.integers(1, 1200))
        r, ca, sa, valid = _scan(rng, n)
        pts, _, _, _, _, ss = gated_points(r, ca, sa, valid, 0.05, 300.0, 0.2, 290.0, 3.0, True, no_drop(n))
        if pts.shape[0] == 0:
            continue
        a = rng.normal(size=(3, 3))
        h = a @ a.T * rng.uniform(1.0, 1e4)
        for thr in (0.01, 0.045, 0.5):
            d1 = degeneracy(h, 0.05, pts, thr)
            d2 = degeneracy(h, 0.05, pts, thr, ss)
            if _EINSUM_ORDER_KNOWN:
                assert (d1.ratio, d1.rotation_ratio, d1.scale, d1.rotation_degenerate) == (
                    d2.ratio, d2.rotation_ratio, d2.scale, d2.rotation_degenerate)
            else:
                assert d1.scale == pytest.approx(d2.scale, rel=1e-12)


@pytest.mark.parametrize("frac", [0.0, 0.1, 0.6])
def test_matching_with_dropped_beams_equals_matching_the_scan_without_them(frac: float) -> None:
    """``HectorSlam.match(scan, drop=m)`` gives the result of ``match(scan.without(m))`` on every scan of a short
    run, and the map update of that scan does not reuse the match's points (they lack the dropped beams)."""
    a, first = paper_room_slam()
    b, _ = paper_room_slam()
    rng = np.random.default_rng(3)
    d = Pose2D()
    for i in range(12):
        d = d.compose(Pose2D(0.03, 0.005 * (i % 3), 0.01))
        scan = paper_room_scan(first.compose(d), stamp=0.1 * (i + 1))
        m = rng.random(scan.ranges.shape[0]) < frac
        ra = a.match(scan.without(m))
        rb = b.match(scan, drop=m)
        assert (ra.pose, ra.score, ra.rejected, ra.reason, ra.degeneracy, ra.support_points, ra.n_points) == (
            rb.pose, rb.score, rb.rejected, rb.reason, rb.degeneracy, rb.support_points, rb.n_points)
        assert b._last_points[0] is None
        if not ra.rejected:
            assert a.update_map(scan.without(m), ra.pose) == b.update_map(scan.without(m), rb.pose)
            assert all(la.logodds.tobytes() == lb.logodds.tobytes() for la, lb in zip(a.map.levels, b.map.levels))
