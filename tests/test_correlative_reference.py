"""The correlative search against a copy of the branch and bound it replaced (point by point sums with range
checks, no cell lists, no acceptance bounds): the same poses, scores and runner-ups, bit for bit, on maps whose
searches run off the map's edges too (slam/correlative.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import paper_room_slam_points
from numba import njit

from dynslam2d.slam import HectorSlam
from dynslam2d.slam.correlative import (
    _NO_EXCL,
    CorrelativeResult,
    _percentile95,
    _rotated_cells,
    _score_pyramid,
    _wrapped_rows,
    correlative_search,
)
from dynslam2d.slam.grid import GridLevel, decode_probs, encode_probs

# ---- the code before (slam/correlative.py at the previous release), kept to compare against -------------------


@njit(cache=False)
def _ref_block_score(table, qx, qy, dx, dy):
    hh, ww = table.shape
    n = qx.shape[0]
    s = 0.0
    for i in range(n):
        x = qx[i] + dx
        y = qy[i] + dy
        if x >= 0 and y >= 0 and x < ww and y < hh:
            s += table[y, x]
    return s / n


@njit(cache=False)
def _ref_min_abs(lo, hi):
    if lo <= 0 <= hi:
        return 0
    return min(abs(lo), abs(hi))


@njit(cache=False)
def _reference_bnb(pyr, qx, qy, w, dth, wt_cell2, wr, excl):
    """Exact best (rotation index, dx, dy, score) over rotations (qx/qy rows) and offsets in [−w, w]².

    ``pyr`` (Hmax+1, H, W); ``qx, qy`` (nrot, n) int64 point cells at zero offset; ``dth`` (nrot,)
    rotation offsets, rad; penalties ``wt_cell2`` per cell², ``wr`` per rad². ``excl`` (6,) int64
    (k0, k1, dx0, dx1, dy0, dy1): candidates with k0 ≤ k ≤ k1, dx0 ≤ dx ≤ dx1 and dy0 ≤ dy ≤ dy1
    are left out (the runner-up search); k0 > k1 leaves nothing out.
    """
    hmax = pyr.shape[0] - 1
    nrot = qx.shape[0]
    step = 1 << hmax
    na = (2 * w + 1 + step - 1) // step
    ntop = nrot * na * na
    top_k = np.empty(ntop, dtype=np.int64)
    top_dx = np.empty(ntop, dtype=np.int64)
    top_dy = np.empty(ntop, dtype=np.int64)
    top_s = np.empty(ntop)
    c = 0
    for k in range(nrot):
        pr = wr * dth[k] * dth[k]
        for a in range(na):
            dx = -w + a * step
            ex = min(dx + step - 1, w)
            mx = _ref_min_abs(dx, ex)
            for b in range(na):
                dy = -w + b * step
                ey = min(dy + step - 1, w)
                my = _ref_min_abs(dy, ey)
                top_k[c] = k
                top_dx[c] = dx
                top_dy[c] = dy
                top_s[c] = _ref_block_score(pyr[hmax], qx[k], qy[k], dx, dy) - pr - wt_cell2 * (mx * mx + my * my)
                c += 1
    # best bound first: a stable merge sort by descending bound (ties in block order), written out here
    # because numba's np.argsort compiles its quicksort machinery, about 1.5 s of a first run's compile
    # (docs/speed.md). Only equal bounds are ordered differently from numba's quicksort; the results of
    # all 2514 searches of a MIT CSAIL run are the same either way
    order = np.arange(ntop)
    buf = np.empty(ntop, dtype=np.int64)
    width = 1
    while width < ntop:
        for lo in range(0, ntop, 2 * width):
            mid = min(lo + width, ntop)
            hi = min(lo + 2 * width, ntop)
            i = lo
            j = mid
            for o in range(lo, hi):
                if j < hi and (i >= mid or top_s[order[j]] > top_s[order[i]]):
                    buf[o] = order[j]
                    j += 1
                else:
                    buf[o] = order[i]
                    i += 1
        order, buf = buf, order
        width *= 2
    best = -1e300
    bk = 0
    bdx = 0
    bdy = 0
    cap = 4 * (hmax + 2) + 8
    sk = np.empty(cap, dtype=np.int64)
    sdx = np.empty(cap, dtype=np.int64)
    sdy = np.empty(cap, dtype=np.int64)
    sh = np.empty(cap, dtype=np.int64)
    ss = np.empty(cap)
    cs = np.empty(4)
    cx = np.empty(4, dtype=np.int64)
    cy = np.empty(4, dtype=np.int64)
    for oi in range(ntop):
        t = order[oi]
        if top_s[t] <= best:
            break
        sp = 0
        sk[0] = top_k[t]
        sdx[0] = top_dx[t]
        sdy[0] = top_dy[t]
        sh[0] = hmax
        ss[0] = top_s[t]
        sp = 1
        while sp > 0:
            sp -= 1
            k = sk[sp]
            dx = sdx[sp]
            dy = sdy[sp]
            h = sh[sp]
            sc = ss[sp]
            if sc <= best:
                continue
            if h == 0:
                if (excl[0] <= k <= excl[1] and excl[2] <= dx <= excl[3] and excl[4] <= dy <= excl[5]):
                    continue
                best = sc
                bk = k
                bdx = dx
                bdy = dy
                continue
            half = 1 << (h - 1)
            pr = wr * dth[k] * dth[k]
            nc = 0
            for ix in range(2):
                cdx = dx + ix * half
                if cdx > w:
                    continue
                ex = min(cdx + half - 1, w)
                mx = _ref_min_abs(cdx, ex)
                for iy in range(2):
                    cdy = dy + iy * half
                    if cdy > w:
                        continue
                    ey = min(cdy + half - 1, w)
                    my = _ref_min_abs(cdy, ey)
                    cs[nc] = _ref_block_score(pyr[h - 1], qx[k], qy[k], cdx, cdy) - pr - wt_cell2 * (mx * mx + my * my)
                    cx[nc] = cdx
                    cy[nc] = cdy
                    nc += 1
            # push children in ascending score so the best is explored first
            for _ in range(nc):
                j = 0
                for q in range(1, nc):
                    if cs[q] < cs[j]:
                        j = q
                if cs[j] > best:
                    sk[sp] = k
                    sdx[sp] = cx[j]
                    sdy[sp] = cy[j]
                    sh[sp] = h - 1
                    ss[sp] = cs[j]
                    sp += 1
                cs[j] = 1e300
    return bk, bdx, bdy, best




def reference_search(
    level: GridLevel,
    pts_m: np.ndarray,
    start_world: np.ndarray,
    linear_window: float,
    angular_window: float,
    angular_step: float | None = None,
    max_points: int = 240,
    max_height: int = 4,
    translation_weight: float = 0.05,
    rotation_weight: float = 0.05,
    runner_up_distance: float | None = None,
    runner_up_angle: float = 0.3,
    runner_up_wrap: bool = False,
) -> CorrelativeResult | None:
    """The search as it was before the cell lists and the acceptance bounds."""
    if level.empty or pts_m.shape[0] == 0:
        return None
    r = level.resolution
    n = pts_m.shape[0]
    if n > max_points:
        pts_m = pts_m[np.linspace(0, n - 1, max_points).astype(np.int64)]
    pc = pts_m / r
    ranges = np.hypot(pc[:, 0], pc[:, 1])
    if angular_step is None:
        d = max(float(np.percentile(ranges, 95)), 1.0)
        # Olson's rule: farthest point moves at most one cell
        angular_step = math.acos(max(-1.0, 1.0 - 1.0 / (2.0 * d * d)))
    n_half = int(math.ceil(angular_window / angular_step)) if angular_window > 0 else 0
    dth = np.arange(-n_half, n_half + 1, dtype=np.float64) * (angular_window / max(n_half, 1))
    th = start_world[2] + dth
    mp = level.pose_to_map(np.asarray(start_world, dtype=np.float64))
    qx, qy, qx_min, qx_max, qy_min, qy_max = _rotated_cells(pc, np.cos(th), np.sin(th), float(mp[0]), float(mp[1]))
    w = int(math.ceil(linear_window / r))
    hmax = max(0, min(max_height, int(math.floor(math.log2(2 * w + 1))) if w > 0 else 0))
    H, W = level.shape
    c0 = max(qx_min - w - 1, 0)
    c1 = min(qx_max + w + 2, W)
    r0 = max(qy_min - w - 1, 0)
    r1 = min(qy_max + w + 2, H)
    if c1 <= c0 or r1 <= r0:
        return None
    crop = level.prob[r0:r1, c0:c1]
    pyr = _score_pyramid(crop, hmax)  # = _pyramid(
    # _score_table(crop), hmax): one pass per level in a kernel instead of a dozen array temporaries
    qx -= c0  # (fresh contiguous arrays from the kernel: shifted in place)
    qy -= r0
    qx0, qy0 = qx, qy
    k, dx, dy, best = _reference_bnb(pyr, qx0, qy0, w, dth, translation_weight * r * r, rotation_weight, _NO_EXCL)
    pose_map = np.array([mp[0] + dx, mp[1] + dy, th[k]])
    out = CorrelativeResult(level.pose_to_world(pose_map), float(best), int(th.shape[0]))
    if runner_up_distance is not None:
        # the best pose outside a neighbourhood of the best: how clearly the best one wins
        ec = int(math.ceil(runner_up_distance / r))
        step = angular_window / max(n_half, 1)
        ek = int(math.ceil(runner_up_angle / step)) if step > 0 else 0
        excl = np.array([k - ek, k + ek, dx - ec, dx + ec, dy - ec, dy + ec], dtype=np.int64)
        near = _wrapped_rows(dth, k, ek, step) if runner_up_wrap else None
        if near is not None:
            # the rows within ±ek of the best one around the circle go first, so that one contiguous
            # exclusion box covers all of them
            rows = np.arange(th.shape[0])
            perm = np.concatenate((rows[near], rows[~near]))
            excl[0], excl[1] = 0, int(near.sum()) - 1
            k2, dx2, dy2, s2 = _reference_bnb(pyr, np.ascontiguousarray(qx0[perm]), np.ascontiguousarray(qy0[perm]),
                                                w, dth[perm], translation_weight * r * r, rotation_weight, excl)
            k2 = int(perm[k2])
        else:
            k2, dx2, dy2, s2 = _reference_bnb(pyr, qx0, qy0, w, dth, translation_weight * r * r, rotation_weight,
                                                excl)
        out.runner_up = float(s2) if s2 > -1e299 else 0.0
        out.runner_up_pose = level.pose_to_world(np.array([mp[0] + dx2, mp[1] + dy2, th[k2]]))
    return out


# ---- the comparison ---------------------------------------------------------------------------------------------

def _level_and_points() -> tuple[HectorSlam, np.ndarray]:
    return paper_room_slam_points()


def _same(a: CorrelativeResult | None, b: CorrelativeResult | None) -> None:
    assert (a is None) == (b is None)
    if a is None:
        return
    assert a.score == b.score and a.n_rotations == b.n_rotations
    np.testing.assert_array_equal(a.pose, b.pose)
    assert a.runner_up == b.runner_up
    if a.runner_up_pose is None:
        assert b.runner_up_pose is None
    else:
        np.testing.assert_array_equal(a.runner_up_pose, b.runner_up_pose)


@pytest.mark.parametrize("level", [0, 1, 2])
def test_search_equals_the_point_by_point_search(level: int) -> None:
    slam, pts = _level_and_points()
    lv = slam.map.levels[level]
    lo = lv.pose_to_world(np.array([1.0, 1.0, 0.0]))  # near the map's lower-left corner: crops clamped, padding
    hi = lv.pose_to_world(np.array([lv.shape[1] - 2.0, lv.shape[0] - 2.0, 0.0]))  # near the upper-right one
    rng = np.random.default_rng(11 + level)
    starts = [np.array([rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi)])
              for _ in range(8)]
    starts += [np.array([lo[0], lo[1], 0.4]), np.array([hi[0], hi[1], -2.0])]
    n = 0
    for start in starts:
        for lin, ang, weights in ((0.5, 0.2, (0.05, 0.05)), (1.2, math.pi, (0.0, 0.0)), (0.8, 3.0, (0.0, 0.0))):
            for wrap in (False, True):
                kw = dict(translation_weight=weights[0], rotation_weight=weights[1], runner_up_distance=0.5,
                          runner_up_angle=0.3, runner_up_wrap=wrap)
                ref = reference_search(lv, pts, start, lin, ang, None, 150, 4, **kw)
                _same(correlative_search(lv, pts, start, lin, ang, None, 150, 4, **kw), ref)
                plain = dict(translation_weight=weights[0], rotation_weight=weights[1])
                _same(correlative_search(lv, pts, start, lin, ang, None, 150, 3, **plain),
                      reference_search(lv, pts, start, lin, ang, None, 150, 3, **plain))
                n += 1
    assert n == 60


def test_search_equals_it_on_a_probability_above_one() -> None:
    """A table value above 1 (not a probability): the points are not merged per cell and the sums stay those of
    the point-by-point search."""
    slam, pts = _level_and_points()
    lv = slam.map.levels[1]
    saved = lv.prob
    prob = decode_probs(saved)  # (the cache holds words: slam/grid.py encode_probs)
    prob[prob > 0.9] = 1e9  # table values 2e9: float64 sums of them and of multiples of 2^−24 round
    try:
        lv.prob = encode_probs(prob)
        for th in (0.0, 1.0, -2.5):
            start = np.array([0.1, -0.2, th])
            _same(correlative_search(lv, pts, start, 0.8, 0.5, None, 150, 4),
                  reference_search(lv, pts, start, 0.8, 0.5, None, 150, 4))
    finally:
        lv.prob = saved


def test_percentile95_equals_numpys() -> None:
    """The angular step's 95th percentile of the point ranges, bit for bit numpy's (ties, one point, scales)."""
    rng = np.random.default_rng(7)
    for it in range(4000):
        n = int(rng.integers(1, 400))
        kind = it % 4
        if kind == 0:
            v = rng.uniform(0.0, 400.0, n)
        elif kind == 1:
            v = np.round(rng.uniform(0.0, 50.0, n), 1)  # many equal values
        elif kind == 2:
            v = np.hypot(rng.normal(0.0, 100.0, n), rng.normal(0.0, 100.0, n))
        else:
            v = rng.exponential(30.0, n) * rng.choice([1e-3, 1.0, 1e3])
        assert _percentile95(v) == float(np.percentile(v, 95))
