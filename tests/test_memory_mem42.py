"""A zero-filled probability cache (``GridLevel.lazy_prob``, pass mem42): every read of the matcher's kernels gives
the values of the 0.5-filled cache, and the cells never written hold no bytes other than zero."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.grid import MultiResMap
from dynslam2d.slam.interp import _NO_LO, interp_value_grad
from dynslam2d.slam.matcher import accumulate, evaluate, free_fraction, match_multires, support
from dynslam2d.types import Pose2D


def _maps(seed: int, l_free: float) -> tuple[MultiResMap, MultiResMap]:
    """The same random scans into a 0.5-filled and a zero-filled map (small growth margins: several growths)."""
    rng = np.random.default_rng(seed)
    maps = tuple(MultiResMap(0.1, 3, l_free, 0.9, growth_margin=0.5, lazy_prob=lazy) for lazy in (False, True))
    for _ in range(25):
        pose = Pose2D(float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)), float(rng.uniform(-math.pi, math.pi)))
        n = int(rng.integers(5, 60))
        a = rng.uniform(-math.pi, math.pi, n)
        r = rng.uniform(0.3, 4.0, n)
        hits = np.column_stack((r * np.cos(a), r * np.sin(a)))
        for m in maps:
            m.integrate(pose, hits)
    return maps


def _points(rng: np.random.Generator, lv, n: int) -> np.ndarray:
    h, w = lv.shape
    return np.column_stack((rng.uniform(-1.0, w + 0.5, n), rng.uniform(-1.0, h + 0.5, n)))


def _bits(x) -> bytes:
    return np.asarray(x, dtype=np.float64).tobytes()


def test_zero_filled_cache_reads_as_the_half_filled_one() -> None:
    for seed, l_free in ((0, -0.4), (1, -40.0), (2, -0.85)):  # −40: cells freed three times are below −103: p = 0.0
        plain, lazy = _maps(seed, l_free)
        rng = np.random.default_rng(seed + 10)
        n_zero = 0
        for a, b in zip(plain.levels, lazy.levels):
            assert a.shape == b.shape and (a.i0, a.j0) == (b.i0, b.j0)
            np.testing.assert_array_equal(a.logodds.view(np.int32), b.logodds.view(np.int32))
            np.testing.assert_array_equal(a.uidx, b.uidx)
            written = b.prob.view(np.int32) != 0
            np.testing.assert_array_equal(a.prob[written].view(np.int32), b.prob[written].view(np.int32))
            assert np.all(a.prob[~written & (a.logodds == 0)] == 0.5)
            n_zero += int(np.count_nonzero(~written & (a.logodds != 0)))  # written 0.0 (underflow): read as 0.0
            # an erased cell made unknown again (erasure.py: log-odds 0, probability 0.5) and one erased to a value
            for lv in (a, b):
                lv.logodds[0, 0], lv.prob[0, 0] = 0.0, 0.5
            for px, py in _points(rng, b, 400):
                for sw in (False, True):
                    assert _bits(interp_value_grad(a.prob, _NO_LO, px, py, sw)[:3]) == \
                        _bits(interp_value_grad(b.prob, b.prob_lo, px, py, sw)[:3])
            pts = _points(rng, b, 300) - np.array([b.shape[1] / 2, b.shape[0] / 2])
            for _ in range(5):
                x, y, th = rng.uniform(0, b.shape[1]), rng.uniform(0, b.shape[0]), rng.uniform(-3, 3)
                ha, ga, hb, gb = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3)), np.zeros(3)
                ra = accumulate(a.prob, a.prob_lo, pts, x, y, th, False, ha, ga)
                rb = accumulate(b.prob, b.prob_lo, pts, x, y, th, False, hb, gb)
                assert _bits(ra) == _bits(rb) and _bits(ha) == _bits(hb) and _bits(ga) == _bits(gb)
        if l_free == -40.0:
            assert n_zero > 0  # the probability 0.0 a cell's log-odds below −103 gives is exercised
        pts = np.random.default_rng(seed).uniform(-4, 4, (200, 2))
        for _ in range(6):
            start = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-3, 3)])
            fa: list = []
            fb: list = []
            pa = match_multires(plain.levels, pts, start, 4, 6, fit=fa, support_thresh=0.6)
            pb = match_multires(lazy.levels, pts, start, 4, 6, fit=fb, support_thresh=0.6)
            assert _bits(pa) == _bits(pb)
            assert _bits(fa[0].hessian) == _bits(fb[0].hessian) and fa[1:] == fb[1:]
            assert (fa[0].cost, fa[0].score, fa[0].n_inside) == (fb[0].cost, fb[0].score, fb[0].n_inside)
            for k in range(3):
                ea, eb = evaluate(plain.levels[k], pts, start, True), evaluate(lazy.levels[k], pts, start, True)
                assert _bits(ea.hessian) == _bits(eb.hessian) and ea.cost == eb.cost and ea.score == eb.score
                assert free_fraction(plain.levels[k], pts, start, 0.55) == free_fraction(lazy.levels[k], pts, start,
                                                                                         0.55)
                assert support(plain.levels[k], pts, start, 0.45) == support(lazy.levels[k], pts, start, 0.45)


def test_cells_never_written_hold_zero_bytes() -> None:
    """The zero-filled cache's non-zero bytes are those of the cells a scan wrote (the 0.5-filled one's: every
    cell), after growths: the OS maps the pages of the rest to its zero page."""
    plain, lazy = _maps(3, -0.4)
    for a, b in zip(plain.levels, lazy.levels):
        assert b.n_grows >= 2
        written = int(np.count_nonzero(b.uidx >= 0))
        assert 0 < np.count_nonzero(b.prob.view(np.int32)) <= written < b.prob.size
        assert np.count_nonzero(a.prob.view(np.int32)) == a.prob.size
        assert b.prob.nbytes == a.prob.nbytes  # (the same arrays allocated: the memory limit is unchanged)
