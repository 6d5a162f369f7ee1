"""The ray walk's cells already updated in the same scan (slam/raycast.py, pass upd48): the branch-free free walk
writes such a cell's own log-odds and update index back and drops its listing, so an occupied cell crossed by a
later ray stays occupied (and is not occupied twice by a later return to it), and only the cells the scan changed
get a probability — bit for bit the reference update, scan after scan."""

from __future__ import annotations

import math

import numpy as np
from test_raycast_walk import L_FREE, L_OCC, _check

from dynslam2d.slam.grid import decode_probs
from dynslam2d.slam.raycast import integrate_rays


def _sig(v: float) -> np.float32:
    return np.float32(1.0 / (1.0 + math.exp(-v)))


def test_cells_seen_earlier_in_the_scan_keep_their_update() -> None:
    """Start (10, 10): a return at X = (20, 10); a clearing ray through X to (30, 10); a return at X again (not the
    ray before it: walked, changes nothing); a return at (25, 10), a cell the clearing ray made free (undone, then
    occupied). After the scan X is occupied once, the row's other cells free once, every other cell untouched —
    values, probabilities and indices."""
    h, w, sx, sy = 21, 40, 10, 10
    lo = np.zeros((h, w), np.float32)
    pr = np.zeros((h, w), np.uint32)  # (the cache's words: 0.5 everywhere)
    ui = np.zeros((h, w), np.int32)
    ex = np.array([20, 30, 20, 25], np.int64)
    ey = np.array([10, 10, 10, 10], np.int64)
    hit = np.array([True, False, True, True])
    assert integrate_rays(lo, pr, ui, 1, 2, sx, sy, ex, ey, hit, L_FREE, L_OCC, 6.0) == 4
    v_occ = 0.0 + L_OCC
    v_undo = (float(np.float32(L_FREE)) - L_FREE) + L_OCC
    want_lo = np.zeros((h, w), np.float32)
    want_pr = np.full((h, w), 0.5, np.float32)
    want_ui = np.zeros((h, w), np.int32)
    want_lo[10, 10:31] = np.float32(L_FREE)
    want_pr[10, 10:31] = _sig(L_FREE)
    want_ui[10, 10:31] = 1
    for x, v in ((20, v_occ), (25, v_undo)):
        want_lo[10, x] = np.float32(v)
        want_pr[10, x] = _sig(v)
        want_ui[10, x] = 2
    assert np.array_equal(lo, want_lo)
    assert np.array_equal(decode_probs(pr), want_pr)
    assert np.array_equal(ui, want_ui)


def test_crossing_fans_over_many_scans_equal_the_reference() -> None:
    """Two interleaved fans (returns, then clearing rays over the same cells, then returns again at the first fan's
    cells), at the cap over several scans: every array bit for bit the cell-by-cell reference after each scan."""
    rng = np.random.default_rng(48)
    h, w, sx, sy = 70, 80, 35, 33
    a = np.sort(rng.uniform(-math.pi, math.pi, 300))
    r = rng.uniform(5.0, 30.0, a.size)
    ex = np.floor(sx + r * np.cos(a) + 0.5).astype(np.int64)
    ey = np.floor(sy + r * np.sin(a) + 0.5).astype(np.int64)
    far = 1.0 + rng.uniform(0.2, 0.6, a.size)
    cx = np.floor(sx + far * r * np.cos(a) + 0.5).astype(np.int64)
    cy = np.floor(sy + far * r * np.sin(a) + 0.5).astype(np.int64)
    ex_all = np.concatenate((ex, cx, ex[::3]))
    ey_all = np.concatenate((ey, cy, ey[::3]))
    hit = np.concatenate((np.ones(a.size, bool), np.zeros(a.size, bool), np.ones(ex[::3].size, bool)))
    _check(h, w, sx, sy, ex_all, ey_all, hit, None, scans=6, cap=3.0)
