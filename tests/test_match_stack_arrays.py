"""Pass match30 (issue 13 item 1): the matcher's work arrays in the kernel's stack frame (``_stack_array``) instead
of ``np.empty`` — every result bit for bit what the heap-allocated form gives.

The reference is ``_match_core`` as it was before the pass (its small arrays from ``np.empty``), compiled here from
the current source with those allocations put back, so the two differ only in where the arrays live; ``_sums``'
blocked pass is compared with its one-loop reference in ``tests/test_slam_match_kernels.py``."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam
from numba import njit

import dynslam2d.slam.matcher as mt
from dynslam2d.slam.matcher import _split_xy, _stack_array, match_level
from dynslam2d.types import Pose2D


@njit(cache=False)
def _fill_two(n):  # pragma: no cover - numba
    """Two stack arrays of each dtype the matcher uses, written with distinct values; returns heap copies."""
    a = _stack_array(np.float64, 5, 128)
    b = _stack_array(np.float64, 11, 128)
    q = _stack_array(np.float32, 4, 128)
    k = _stack_array(np.uint64, 1, 128)[0]
    for i in range(5):
        for j in range(128):
            a[i, j] = i * 1000.0 + j
    for i in range(11):
        for j in range(128):
            b[i, j] = -(i * 1000.0 + j)
    for i in range(4):
        for j in range(128):
            q[i, j] = np.float32(i + 0.5 * j)
    for j in range(128):
        k[j] = np.uint64(j * n)
    return a.copy(), b.copy(), q.copy(), k.copy()


def test_stack_arrays_have_their_shape_and_type_and_do_not_overlap() -> None:
    a, b, q, k = _fill_two(3)
    assert a.shape == (5, 128) and b.shape == (11, 128) and q.shape == (4, 128) and k.shape == (128,)
    assert (a.dtype, b.dtype, q.dtype, k.dtype) == (np.float64, np.float64, np.float32, np.uint64)
    i, j = np.meshgrid(np.arange(5), np.arange(128), indexing="ij")
    np.testing.assert_array_equal(a, i * 1000.0 + j)
    i, j = np.meshgrid(np.arange(11), np.arange(128), indexing="ij")
    np.testing.assert_array_equal(b, -(i * 1000.0 + j))
    i, j = np.meshgrid(np.arange(4), np.arange(128), indexing="ij")
    np.testing.assert_array_equal(q, (i + 0.5 * j).astype(np.float32))
    np.testing.assert_array_equal(k, np.arange(128, dtype=np.uint64) * 3)


def _heap_match_core():
    """``_match_core`` with its work arrays from ``np.empty`` again (the form before this pass), compiled."""
    src = inspect.getsource(mt._match_core.py_func)
    src = src.replace("@njit(cache=True)\n", "")
    n_mat = src.count("_stack_array(np.float64, 3, 3)")
    n_vec = src.count("_stack_array(np.float64, 1, 3)[0]")
    assert (n_mat, n_vec) == (3, 4)  # H, H2, A; g, g2, d, gp
    src = src.replace("_stack_array(np.float64, 3, 3)", "np.empty((3, 3))")
    src = src.replace("_stack_array(np.float64, 1, 3)[0]", "np.empty(3)")
    ns = dict(vars(mt))
    exec(compile(src, "<heap _match_core>", "exec"), ns)
    return njit(cache=False)(ns["_match_core"])


_HEAP_CORE = None


def _heap_level(prob, pts, pose, n_iter, swapped, use_lm, prior, lam_p, keep, res, i0, j0):
    global _HEAP_CORE
    if _HEAP_CORE is None:
        _HEAP_CORE = _heap_match_core()
    H = np.zeros((3, 3))
    out = _HEAP_CORE(prob, _split_xy(pts), pose, n_iter, swapped, use_lm, 0.1, 1e4, 0.2, 2.0, prior, lam_p, H, keep,
                     res, i0, j0)
    return out, H


def _stack_level(prob, pts, pose, n_iter, swapped, use_lm, prior, lam_p, keep, res, i0, j0):
    H = np.zeros((3, 3))
    out = mt._match_core(prob, _split_xy(pts), pose, n_iter, swapped, use_lm, 0.1, 1e4, 0.2, 2.0, prior, lam_p, H,
                         keep, res, i0, j0)
    return out, H


def _bits(x) -> bytes:
    return np.asarray(x, dtype=np.float64).tobytes()


@pytest.mark.parametrize("level", [0, 1, 2])
def test_match_core_with_stack_arrays_equals_the_heap_form(level: int) -> None:
    slam, first = paper_room_slam()
    lv = slam.map.levels[level]
    prior_info = np.array([[30.0, 2.0, 0.5], [2.0, 10.0, 0.1], [0.5, 0.1, 40.0]])
    S = np.diag([lv.resolution, lv.resolution, 1.0])
    n_runs = 0
    for d in (Pose2D(0.0, 0.0, 0.0), Pose2D(0.12, -0.08, 0.05), Pose2D(-0.2, 0.1, -0.15), Pose2D(0.05, 0.3, 0.4)):
        pts_m = slam.scan_points(paper_room_scan(first.compose(d)))[0]
        pts = np.ascontiguousarray(pts_m / lv.resolution)
        for off in ((0.0, 0.0, 0.0), (0.1, -0.05, 0.03), (-0.15, 0.2, -0.1)):
            mp = lv.pose_to_map(np.array(off))
            for swapped in (False, True):
                for use_lm in (True, False):
                    for prior in (False, True):
                        if prior:
                            pp = lv.pose_to_map(np.array(off) + np.array([0.02, -0.01, 0.03]))
                            pp[2] = mp[2] + (pp[2] - mp[2] + math.pi) % (2.0 * math.pi) - math.pi
                            lam = S @ prior_info @ S
                        else:
                            pp, lam = mp.copy(), np.zeros((3, 3))
                        for keep in (False, True):
                            args = (lv.prob, pts, mp, 6, swapped, use_lm, pp, lam, keep, lv.resolution,
                                    float(lv.i0), float(lv.j0))
                            (xs, ys, ts, ns, rs, ss, ins), hs = _stack_level(*args)
                            (xh, yh, th, nh, rh, sh, inh), hh = _heap_level(*args)
                            assert _bits([xs, ys, ts, rs, ss]) == _bits([xh, yh, th, rh, sh])
                            assert (ns, ins) == (nh, inh)
                            assert hs.tobytes() == hh.tobytes()
                            n_runs += 1
        # the public per-level kernel (the same _match_core) on the same points
        out, n_acc = match_level(lv.prob, pts, lv.pose_to_map(np.zeros(3)), 4, False, True, 0.1, 1e4, 0.2, 2.0,
                                 lv.pose_to_map(np.zeros(3)), np.zeros((3, 3)))
        (xh, yh, th, nh, _, _, _), _ = _heap_level(lv.prob, pts, lv.pose_to_map(np.zeros(3)), 4, False, True,
                                                   lv.pose_to_map(np.zeros(3)), np.zeros((3, 3)), False, 1.0, 0.0,
                                                   0.0)
        assert out.tobytes() == _bits([xh, yh, th]) and n_acc == nh
    assert n_runs == 4 * 3 * 2 * 2 * 2 * 2
