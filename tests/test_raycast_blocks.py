"""The ray kernel's set-up in loops before the walks (pass map22, slam/raycast.py ``_rays``): the rays' end cells,
which rays count and which repeat the previous one, and each walked ray's lengths, steps and multiplier are computed
for all rays first, the walks after in the rays' order; the probabilities of the updated cells in batches after the
walks (pass map30). Compared bit for bit (the three level arrays, the returned count) with the one-loop form it
replaced, kept below with each cell's probability computed in the plain form as it is updated, compiled here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.jitbox import njit
from dynslam2d.slam.grid import decode_probs, encode_probs
from dynslam2d.slam.raycast import (
    _MAGIC_MAX,
    _MAGIC_SHIFT,
    _NO_CELLS,
    _NO_ENDS,
    _NO_STOP,
    _PREFETCH,
    _prefetch,
    _rays,
)

L_FREE = -0.4054651081081643
L_OCC = 2.1972245773362196


@njit(cache=True)
def _rays_one_loop(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, ends, r, i0, j0, hit, stop, use_stop,
          l_free, l_occ, cap):  # pragma: no cover - numba
    """The one-loop form of ``raycast._rays`` before pass map22 (each ray's end cell, repeat test and set-up
    computed just before its walk), kept as the reference; each updated cell's probability is the plain
    float32(1 / (1 + exp(−v))) of its float64 log-odds, written as the cell is updated (before pass map30 a memo
    gave those bits)."""
    h, w = logodds.shape
    if sx < 0 or sy < 0 or sx >= w or sy >= h:
        return 0
    lo = logodds.reshape(h * w)  # (views: the arrays are C-contiguous)
    pr = prob.reshape(h * w)
    ui = uidx.reshape(h * w)
    from_ends = ends.shape[1] > 0
    n = ends.shape[1] if from_ends else ex.shape[0]
    f0 = sy * w + sx
    n_done = 0
    px = -1  # the previous ray: end cell, hit flag, stop and whether it was integrated (1) or skipped (0)
    py = -1
    ph = False
    ps = 0.0
    pd = 0
    for k in range(n):
        if from_ends:
            x1 = int(math.floor(ends[0, k] / r + 0.5)) - i0
            y1 = int(math.floor(ends[1, k] / r + 0.5)) - j0
        else:
            x1 = ex[k]
            y1 = ey[k]
        hk = hit[k]
        sk = stop[k] if use_stop else 0.0
        if k > 0 and x1 == px and y1 == py and hk == ph and sk == ps:
            # the previous ray again (same start, end cell, kind and stop: the same cells): its cells hold this
            # scan's update indices now (free_idx or occ_idx; they only grow within a scan), so walking it again
            # would change nothing — counted as the previous one was
            n_done += pd
            continue
        px = x1
        py = y1
        ph = hk
        ps = sk
        pd = 0
        if x1 == sx and y1 == sy:
            continue
        if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
            continue
        pd = 1
        dx = x1 - sx
        dy = y1 - sy
        adx = abs(dx)
        ady = abs(dy)
        stx = 1 if dx > 0 else -1
        sty = w if dy > 0 else -w  # (a step along y in flat indices)
        if adx >= ady:
            major, minor, d_major, d_minor = adx, ady, stx, sty
        else:
            major, minor, d_major, d_minor = ady, adx, sty, stx
        skip = 0  # intermediate cell j major steps before the end lies j·L/major cells from it
        if use_stop and stop[k] > 1.0:
            skip = int((stop[k] - 1.0) * major / math.sqrt(float(dx * dx + dy * dy)))
            if skip > major - 1:
                skip = major - 1
        # the start cell (j = 0), then the first major − 1 − skip intermediate cells of the walk: free
        n_free = major - skip
        c = major // 2
        if major < _MAGIC_MAX:
            magic = ((1 << _MAGIC_SHIFT) + major - 1) // major  # ceil(2^42 / major)
            t = c
            fb = f0
            for _ in range(n_free):
                f = np.uint64(fb + ((t * magic) >> _MAGIC_SHIFT) * d_minor)  # (unsigned: no negative-index test)
                if ui[f] < free_idx:
                    # a cell seen for the first time this scan: the cells _PREFETCH steps on are likely new too
                    g = np.uint64(fb + _PREFETCH * d_major + (((t + _PREFETCH * minor) * magic) >> _MAGIC_SHIFT)
                                  * d_minor)
                    _prefetch(ui, g)
                    _prefetch(lo, g)
                    _prefetch(pr, g)
                    v = lo[f] + l_free
                    lo[f] = v
                    ui[f] = free_idx
                    pr[f] = np.float32(1.0 / (1.0 + math.exp(-v)))
                t += minor
                fb += d_major
        else:
            t = c
            fb = f0
            for _ in range(n_free):
                f = fb + (t // major) * d_minor
                if ui[f] < free_idx:
                    v = lo[f] + l_free
                    lo[f] = v
                    pr[f] = np.float32(1.0 / (1.0 + math.exp(-v)))
                    ui[f] = free_idx
                t += minor
                fb += d_major
        f = np.uint64(y1 * w + x1)
        u = ui[f]
        v = 0.0
        updated = False
        if hk:
            if u < occ_idx:
                v = lo[f]
                if u == free_idx:
                    v -= l_free
                if v < cap:
                    v += l_occ
                lo[f] = v
                ui[f] = occ_idx
                updated = True
        elif u < free_idx:
            v = lo[f] + l_free
            lo[f] = v
            ui[f] = free_idx
            updated = True
        if updated:
            pr[f] = np.float32(1.0 / (1.0 + math.exp(-v)))
        n_done += 1
    return n_done



def _state(h: int, w: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A level with earlier scans in it: random log-odds on a few values, their probabilities, update indices
    below, at and above this scan's (free 31, occupied 32)."""
    lo = rng.choice(np.array([0.0, L_FREE, 2 * L_FREE, L_OCC, L_OCC + L_FREE, 6.5], np.float32), size=(h, w))
    pr = (1.0 / (1.0 + np.exp(-lo.astype(np.float64)))).astype(np.float32)
    ui = rng.choice(np.array([-1, 4, 28, 30], np.int32), size=(h, w))
    return lo, pr, ui


def _both(lo, pr, ui, sx, sy, ex, ey, ends, r, i0, j0, hit, stop, use_stop, cap=6.0) -> None:
    """One call of each form on copies of the same level; every output bit for bit equal."""
    out = []
    for fn in (_rays, _rays_one_loop):  # (the kernel's cache of words, decoded; the reference's float32 one)
        a, b, c = lo.copy(), encode_probs(pr) if fn is _rays else pr.copy(), ui.copy()
        n = fn(a, b, c, 31, 32, sx, sy, ex, ey, ends, r, i0, j0, hit, stop, use_stop, L_FREE, L_OCC, cap)
        out.append((n, a, decode_probs(b) if fn is _rays else b, c))
    (n1, *arrs1), (n2, *arrs2) = out
    assert n1 == n2
    for x, y in zip(arrs1, arrs2):
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _rays_with_repeats(rng: np.random.Generator, n: int, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """End cells in runs of repeats (as a dense scan's neighbouring beams give), some outside the array."""
    ex = np.empty(n, np.int64)
    ey = np.empty(n, np.int64)
    k = 0
    while k < n:
        run = int(rng.integers(1, 5))
        ex[k:k + run] = rng.integers(-5, w + 5)
        ey[k:k + run] = rng.integers(-5, h + 5)
        k += run
    return ex, ey


@pytest.mark.parametrize("seed", range(6))
def test_set_up_loops_equal_the_one_loop_form_on_cells(seed: int) -> None:
    """Rays given as cells (``integrate_rays`` / ``integrate_rays_stop``'s way): runs of equal ends, ends outside the
    array and at the start cell, returns and clearing rays mixed within runs, stops equal, different, ±0 and NaN."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(3, 90, 2))
    lo, pr, ui = _state(h, w, rng)
    sx, sy = int(rng.integers(0, w)), int(rng.integers(0, h))
    n = int(rng.integers(0, 400))
    ex, ey = _rays_with_repeats(rng, n, h, w)
    if n > 3:
        ex[1], ey[1] = sx, sy  # (a ray ending in the start cell)
    hit = rng.random(n) < 0.7
    stop = rng.choice(np.array([0.0, -0.0, 1.0, 2.5, 9.0, np.nan]), size=n)
    for k in range(1, n, 2):
        stop[k] = stop[k - 1]  # (equal stops within runs)
    _both(lo, pr, ui, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, _NO_STOP, False)
    _both(lo, pr, ui, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, stop, True)
    # a start cell outside the array: nothing written, nothing counted
    _both(lo, pr, ui, w, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, _NO_STOP, False)


@pytest.mark.parametrize("seed", range(6))
def test_set_up_loops_equal_the_one_loop_form_on_map_frame_ends(seed: int) -> None:
    """Rays given as map-frame ends (``integrate_levels``' way), rounded to cells in the vectorised loop: ends on and
    next to the rounding's half-cell edges, negative coordinates, level offsets, three cell sizes, with a long ray
    (major length past the multiply-shift limit) in some calls."""
    rng = np.random.default_rng(100 + seed)
    for r in (0.05, 0.1, 0.2):
        h, w = (int(v) for v in rng.integers(20, 120, 2))
        lo, pr, ui = _state(h, w, rng)
        i0, j0 = int(rng.integers(-60, 10)), int(rng.integers(-60, 10))
        sx, sy = int(rng.integers(0, w)), int(rng.integers(0, h))
        n = int(rng.integers(1, 700))
        cx, cy = _rays_with_repeats(rng, n, h, w)
        ends = np.empty((2, n))
        ends[0] = (cx + i0 + rng.choice(np.array([-0.5, -0.49999999, 0.0, 0.3, 0.49999999, 0.5]), n)) * r
        ends[1] = (cy + j0 + rng.uniform(-0.5, 0.5, n)) * r
        ends[:, 1::3] = ends[:, 0:-1:3][:, : len(range(1, n, 3))]  # (exact repeats of the ray before)
        hit = rng.random(n) < 0.8
        stop = rng.choice(np.array([0.0, 1.0, 3.0, 7.5]), size=n)
        _both(lo, pr, ui, sx, sy, _NO_CELLS, _NO_CELLS, ends, r, i0, j0, hit, _NO_STOP, False)
        _both(lo, pr, ui, sx, sy, _NO_CELLS, _NO_CELLS, ends, r, i0, j0, hit, stop, True)
    # rays at and past the multiply-shift limit (the division walk) next to short ones
    h, w = 4, _MAGIC_MAX + 40
    lo, pr, ui = _state(h, w, rng)
    ex = np.array([_MAGIC_MAX + 30, _MAGIC_MAX + 30, 12, _MAGIC_MAX + 1, 3, 3], np.int64)
    ey = np.array([3, 3, 2, 0, 1, 1], np.int64)
    hit = np.array([True, True, False, True, True, False])
    _both(lo, pr, ui, 1, 1, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, _NO_STOP, False)
