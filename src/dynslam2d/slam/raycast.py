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


@njit(cache=True)
def _mark_free(logodds, prob, uidx, x, y, free_idx, l_free):  # pragma: no cover - numba
    # OccGridMapBase::updateSetFree: at most one free update per cell per scan
    if uidx[y, x] < free_idx:
        v = logodds[y, x] + l_free
        logodds[y, x] = v
        prob[y, x] = 1.0 / (1.0 + math.exp(-v))
        uidx[y, x] = free_idx


@njit(cache=True)
def _mark_occupied(logodds, prob, uidx, x, y, free_idx, occ_idx, l_free, l_occ, cap):  # pragma: no cover
    # OccGridMapBase::updateSetOccupied: occupied wins; undo this scan's free update first
    u = uidx[y, x]
    if u < occ_idx:
        v = logodds[y, x]
        if u == free_idx:
            v -= l_free
        if v < cap:  # GridMapLogOdds.h: soft cap on the occupied side only
            v += l_occ
        logodds[y, x] = v
        prob[y, x] = 1.0 / (1.0 + math.exp(-v))
        uidx[y, x] = occ_idx


@njit(cache=True)
def _integrate_ray(logodds, prob, uidx, free_idx, occ_idx, sx, sy, x1, y1, is_hit, skip,
                   l_free, l_occ, cap):  # pragma: no cover - numba
    """One ray from cell (sx, sy) to (x1, y1), both inside the array and distinct: the start cell and the
    intermediate cells free except the last ``skip`` intermediate ones, the endpoint occupied if
    ``is_hit`` else free (Bresenham as OccGridMapBase::bresenham2D; ties of the major axis go to x)."""
    dx = x1 - sx
    dy = y1 - sy
    adx = abs(dx)
    ady = abs(dy)
    stx = 1 if dx > 0 else -1
    sty = 1 if dy > 0 else -1
    major = adx if adx >= ady else ady
    n_free = major - 1 - skip
    x = sx
    y = sy
    _mark_free(logodds, prob, uidx, x, y, free_idx, l_free)
    if adx >= ady:
        err = adx // 2
        for i in range(adx - 1):
            x += stx
            err += ady
            if err >= adx:
                y += sty
                err -= adx
            if i < n_free:
                _mark_free(logodds, prob, uidx, x, y, free_idx, l_free)
    else:
        err = ady // 2
        for i in range(ady - 1):
            y += sty
            err += adx
            if err >= ady:
                x += stx
                err -= ady
            if i < n_free:
                _mark_free(logodds, prob, uidx, x, y, free_idx, l_free)
    if is_hit:
        _mark_occupied(logodds, prob, uidx, x1, y1, free_idx, occ_idx, l_free, l_occ, cap)
    else:
        _mark_free(logodds, prob, uidx, x1, y1, free_idx, l_free)


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
    h, w = logodds.shape
    if sx < 0 or sy < 0 or sx >= w or sy >= h:
        return 0
    n_done = 0
    for k in range(ex.shape[0]):
        x1 = ex[k]
        y1 = ey[k]
        if x1 == sx and y1 == sy:
            continue
        if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
            continue
        _integrate_ray(logodds, prob, uidx, free_idx, occ_idx, sx, sy, x1, y1, hit[k], 0, l_free, l_occ, cap)
        n_done += 1
    return n_done


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
    h, w = logodds.shape
    if sx < 0 or sy < 0 or sx >= w or sy >= h:
        return 0
    n_done = 0
    for k in range(ex.shape[0]):
        x1 = ex[k]
        y1 = ey[k]
        if x1 == sx and y1 == sy:
            continue
        if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
            continue
        dx = x1 - sx
        dy = y1 - sy
        major = abs(dx) if abs(dx) >= abs(dy) else abs(dy)
        skip = 0
        if stop[k] > 1.0:  # intermediate cell j major steps before the end lies j·L/major cells from it
            skip = int((stop[k] - 1.0) * major / math.sqrt(float(dx * dx + dy * dy)))
            if skip > major - 1:
                skip = major - 1
        _integrate_ray(logodds, prob, uidx, free_idx, occ_idx, sx, sy, x1, y1, hit[k], skip, l_free, l_occ, cap)
        n_done += 1
    return n_done


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
    n = ends.shape[1]
    for k in range(n_levels):
        lo = logodds[k]
        pr = prob[k]
        ui = uidx[k]
        h, w = lo.shape
        r = res[k]
        free_idx = counter[k] + 1
        occ_idx = counter[k] + 2
        s_x = sx[k]
        s_y = sy[k]
        if s_x < 0 or s_y < 0 or s_x >= w or s_y >= h:
            continue
        n_done = 0
        for i in range(n):
            x1 = int(math.floor(ends[0, i] / r + 0.5)) - i0[k]
            y1 = int(math.floor(ends[1, i] / r + 0.5)) - j0[k]
            if x1 == s_x and y1 == s_y:
                continue
            if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
                continue
            skip = 0
            if use_stop:
                dx = x1 - s_x
                dy = y1 - s_y
                major = abs(dx) if abs(dx) >= abs(dy) else abs(dy)
                if stop[i] > 1.0:  # (as integrate_rays_stop)
                    skip = int((stop[i] - 1.0) * major / math.sqrt(float(dx * dx + dy * dy)))
                    if skip > major - 1:
                        skip = major - 1
            _integrate_ray(lo, pr, ui, free_idx, occ_idx, s_x, s_y, x1, y1, hit[i], skip, l_free, l_occ, cap)
            n_done += 1
        if k == 0:
            n0 = n_done
    return n0
