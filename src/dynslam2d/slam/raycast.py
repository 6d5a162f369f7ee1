"""Scan integration into one log-odds grid level: Bresenham rays (numba).

Implements hector_mapping's ``OccGridMapBase::updateByScan`` / ``bresenham2D`` exactly:

* the integer Bresenham variant of the reference (major axis = larger |Δ|, ties to x,
  error starts at |Δa|/2, the start cell and every intermediate cell are free, the
  endpoint cell is not marked free);
* at most one free and one occupied update per cell per scan, occupied winning
  (a free update made earlier in the same scan is undone), via per-cell update indices;
* a hit is added only while the log-odds is below the cap; the free side is unbounded.

Grid arrays are indexed ``[row, col]`` = ``[y, x]`` in cell units of the level.
The probability cache (``prob``) is refreshed for every touched cell, so the matcher
never needs a full-map recomputation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: placeholders of the inputs :func:`_rays` does not use on a call (its other way of giving the rays)
_NO_ENDS = np.zeros((2, 0))
_NO_CELLS = np.zeros(0, dtype=np.int64)
_NO_STOP = np.zeros(0)


@njit(cache=True)
def _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, ends, r, i0, j0, hit, stop, use_stop,
          l_free, l_occ, cap):  # pragma: no cover - numba
    """Rays from array cell (``sx``, ``sy``) into one level (arrays ``logodds``, ``prob``, ``uidx`` (H, W),
    C-contiguous): to cells (``ex[k]``, ``ey[k]``) or, when ``ends`` has columns, to the cells of the map-frame
    ends ``ends`` (2, n), m (``floor(v / r + 0.5)`` minus the offsets ``i0``, ``j0``: OccGridMapBase::updateByScan's
    rounding). ``hit[k]`` True: the start and intermediate cells free, the endpoint occupied; False: every cell
    free. With ``use_stop`` the last ``stop[k]`` cells of a ray (its endpoint included) get no free update.
    Rays with the start or end cell outside the array, or ending in the start cell, are skipped whole. Returns
    the number of rays integrated.

    Free update (OccGridMapBase::updateSetFree): at most one per cell per scan (update index ``free_idx``);
    occupied (updateSetOccupied): at most one, winning over this scan's free update, which it undoes first; a
    hit adds ``l_occ`` only while the log-odds is below ``cap`` (GridMapLogOdds.h); the probability cache is
    refreshed in every touched cell. The cells are those of the reference's integer Bresenham walk
    (OccGridMapBase::bresenham2D: major axis = larger |Δ|, ties to x, error starting at |Δmajor|/2). The walk
    runs on flat indices with the steps along the major and minor axes as index offsets, and the cell updates
    are written out in the loop (helpers taking the arrays, called per cell, were slower in every trial, several
    times so where numba did not inline them; docs/speed.md)."""
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
    for k in range(n):
        if from_ends:
            x1 = int(math.floor(ends[0, k] / r + 0.5)) - i0
            y1 = int(math.floor(ends[1, k] / r + 0.5)) - j0
        else:
            x1 = ex[k]
            y1 = ey[k]
        if x1 == sx and y1 == sy:
            continue
        if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
            continue
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
        f = f0
        err = major // 2
        for j in range(major - skip):
            if j > 0:
                f += d_major
                err += minor
                if err >= major:
                    f += d_minor
                    err -= major
            if ui[f] < free_idx:
                v = lo[f] + l_free
                lo[f] = v
                pr[f] = 1.0 / (1.0 + math.exp(-v))
                ui[f] = free_idx
        f = y1 * w + x1
        u = ui[f]
        if hit[k]:
            if u < occ_idx:
                v = lo[f]
                if u == free_idx:
                    v -= l_free
                if v < cap:
                    v += l_occ
                lo[f] = v
                pr[f] = 1.0 / (1.0 + math.exp(-v))
                ui[f] = occ_idx
        elif u < free_idx:
            v = lo[f] + l_free
            lo[f] = v
            pr[f] = 1.0 / (1.0 + math.exp(-v))
            ui[f] = free_idx
        n_done += 1
    return n_done


@njit(cache=True)
def integrate_rays(
    logodds: np.ndarray,
    prob: np.ndarray,
    uidx: np.ndarray,
    free_idx: int,
    occ_idx: int,
    sx: int,
    sy: int,
    ex: np.ndarray,
    ey: np.ndarray,
    hit: np.ndarray,
    l_free: float,
    l_occ: float,
    cap: float,
) -> int:  # pragma: no cover - numba
    """Integrate rays from cell (sx, sy) to cells (ex[k], ey[k]) into one level.

    ``hit[k]`` True: a return (start + intermediate cells free, endpoint occupied);
    False: a free-space clearing ray (every cell including the endpoint free).
    Rays whose start or end cell lies outside the array are skipped whole
    (OccGridMapBase::updateByScan); rays ending in the start cell are skipped. Returns the
    number of rays integrated.
    """
    return _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, _NO_STOP,
                 False, l_free, l_occ, cap)


@njit(cache=True)
def bresenham_free_cells(x0: int, y0: int, x1: int, y1: int) -> np.ndarray:  # pragma: no cover - numba
    """(m, 2) int64 (x, y) cells the reference marks free on a ray from (x0, y0) to (x1, y1):
    the start cell and all intermediate cells, not the endpoint (OccGridMapBase::bresenham2D)."""
    dx = x1 - x0
    dy = y1 - y0
    adx = abs(dx)
    ady = abs(dy)
    n = max(adx, ady)
    out = np.empty((max(n, 1), 2), dtype=np.int64)
    if n == 0:
        return out[:0]
    stx = 1 if dx > 0 else -1
    sty = 1 if dy > 0 else -1
    x = x0
    y = y0
    out[0, 0] = x
    out[0, 1] = y
    if adx >= ady:
        err = adx // 2
        for i in range(adx - 1):
            x += stx
            err += ady
            if err >= adx:
                y += sty
                err -= adx
            out[i + 1, 0] = x
            out[i + 1, 1] = y
    else:
        err = ady // 2
        for i in range(ady - 1):
            y += sty
            err += adx
            if err >= ady:
                x += stx
                err -= ady
            out[i + 1, 0] = x
            out[i + 1, 1] = y
    return out


@njit(cache=True)
def integrate_rays_stop(
    logodds: np.ndarray,
    prob: np.ndarray,
    uidx: np.ndarray,
    free_idx: int,
    occ_idx: int,
    sx: int,
    sy: int,
    ex: np.ndarray,
    ey: np.ndarray,
    hit: np.ndarray,
    stop: np.ndarray,
    l_free: float,
    l_occ: float,
    cap: float,
) -> int:  # pragma: no cover - numba
    """:func:`integrate_rays` with a per-ray free-space stop: the intermediate cells of ray ``k`` that lie
    less than ``stop[k] − 1`` cells (along the ray) before its endpoint get no free update — the ray's last
    ``stop[k]`` cells, its endpoint cell included, which the reference never marks free. ``stop[k] ≤ 1``
    gives the reference's update exactly. (Where the stop comes from: ``MultiResMap.integrate``.)"""
    return _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, stop, True,
                 l_free, l_occ, cap)


@njit(cache=True)
def integrate_levels(logodds, prob, uidx, n_levels, res, i0, j0, sx, sy, counter, ends, hit, stop, use_stop,
                     l_free, l_occ, cap):  # pragma: no cover - numba
    """One scan into every level in one call: per level ``k`` < ``n_levels`` (3-tuples ``logodds``, ``prob``,
    ``uidx``, cell side ``res`` m, array offsets ``i0``, ``j0``, ray start cell ``sx``, ``sy`` in array cells,
    update counter ``counter`` before this scan), the end cells of the rays ``ends`` (2, n) (map frame, m) as
    ``MultiResMap.integrate`` computed them level by level (``floor(v / r + 0.5)``, OccGridMapBase::updateByScan's
    rounding, minus the offsets), then :func:`integrate_rays` (or :func:`integrate_rays_stop` with ``use_stop``)
    with the level's update indices ``counter + 1`` (free) and ``counter + 2`` (occupied). The levels must hold
    the rays already (``GridLevel.ensure``). Returns the number of rays integrated on level 0."""
    n0 = 0
    for k in range(n_levels):
        n_done = _rays(logodds[k], prob[k], uidx[k], counter[k] + 1, counter[k] + 2, sx[k], sy[k], _NO_CELLS,
                       _NO_CELLS, ends, res[k], i0[k], j0[k], hit, stop, use_stop, l_free, l_occ, cap)
        if k == 0:
            n0 = n_done
    return n0


@njit(cache=True)
def ray_ends(hits, clear, c, s, x, y):  # pragma: no cover - numba
    """The ends of one scan's rays in the map frame: ((2, n) rows x and y of the ``hits`` (n_hit, 2) then the
    ``clear`` (m, 2) ends, laser frame, m, moved by the pose (``x``, ``y``, cos ``c``, sin ``s``) with the arithmetic
    of ``Pose2D.transform_points`` element by element; (n,) hit flags, True for the hits; [min x, min y, max x,
    max y] of the ends, NaN where a row holds a NaN, as numpy's ``min`` / ``max``)."""
    n_hit = hits.shape[0]
    n = n_hit + clear.shape[0]
    ends = np.empty((2, n))
    hit = np.empty(n, dtype=np.bool_)
    for k in range(n):
        if k < n_hit:
            px = hits[k, 0]
            py = hits[k, 1]
            hit[k] = True
        else:
            px = clear[k - n_hit, 0]
            py = clear[k - n_hit, 1]
            hit[k] = False
        ends[0, k] = c * px - s * py + x
        ends[1, k] = s * px + c * py + y
    box = np.empty(4)
    for r in range(2):
        lo = ends[r, 0]
        hi = lo
        for k in range(1, n):
            v = ends[r, k]
            if v != v:
                lo = v
                hi = v
                break
            if v < lo:
                lo = v
            if v > hi:
                hi = v
        box[r] = lo
        box[2 + r] = hi
    return ends, hit, box
