"""The evidence ledger's numba kernels (slam/ledgerkernels.py) against the numpy code they replaced in
slam/erasure.py (kept here as the reference): on random points with ties (duplicate points, points on cell
boundaries where ``v / r + 0.5`` is an integer, negative coordinates, tracks and unowned points sharing cells,
cells outside the level's array) the kernels must pick exactly the same cells, keys, values and rows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.slam import ledgerkernels as lk

_KEY_SHIFT = 4294967296


def _reference_cells(xs, ys, ids, mine_b, rs):
    """The numpy path of ``EvidenceLedger._level_cells`` before the kernels: (ids, keys, cells) per level,
    or None when the packed values would not fit in an int64."""
    n_lv = len(rs)
    x0, x1, y0, y1 = float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())
    lox = [math.floor(x0 / r + 0.5) for r in rs]
    loy = [math.floor(y0 / r + 0.5) for r in rs]
    hix = [math.floor(x1 / r + 0.5) for r in rs]
    hiy = [math.floor(y1 / r + 0.5) for r in rs]
    wi = max(b - a for a, b in zip(lox, hix)) + 1
    wj = max(b - a for a, b in zip(loy, hiy)) + 1
    uids = np.unique(ids)
    block = (uids.shape[0] + 1) * wi * wj
    if n_lv * block >= 1 << 62:
        return None
    owner = np.zeros(xs.shape[0], dtype=np.int64)
    owner[mine_b] = np.searchsorted(uids, ids) + 1
    res = np.array(rs)[:, None]
    cx = np.floor(xs / res + 0.5).astype(np.int64) - np.array(lox, dtype=np.int64)[:, None]
    cy = np.floor(ys / res + 0.5).astype(np.int64) - np.array(loy, dtype=np.int64)[:, None]
    packed = cx * wj + cy + owner * (wi * wj) + np.arange(0, n_lv * block, block, dtype=np.int64)[:, None]
    u = np.sort(packed.ravel())
    keep = np.ones(u.shape[0], dtype=bool)
    keep[1:] = u[1:] != u[:-1]
    u = u[keep]
    lvl, rest = np.divmod(u, block)
    own, cell = np.divmod(rest, wi * wj)
    q = u - own * (wi * wj)
    i = np.searchsorted(u, q)
    i[i == u.shape[0]] = 0
    mine = (own > 0) & (u[i] != q)
    lvl, own, cell = lvl[mine], own[mine], cell[mine]
    ci, cj = np.divmod(cell, wj)
    ci += np.array(lox, dtype=np.int64)[lvl]
    cj += np.array(loy, dtype=np.int64)[lvl]
    bounds = np.searchsorted(lvl, np.arange(n_lv + 1))
    return uids[own - 1], ci * _KEY_SHIFT + cj, np.column_stack((ci, cj)), bounds


def _points(rng, n, r):
    """Points with ties: a third on cell boundaries of the coarsest level ((k − 0.5)·r, also boundaries of the
    finer levels), duplicates, and the rest uniform over negative and positive coordinates."""
    xs = rng.uniform(-3.0, 2.0, n)
    ys = rng.uniform(-1.0, 4.0, n)
    b = rng.random(n) < 0.35
    xs[b] = (rng.integers(-40, 40, int(b.sum())) - 0.5) * r
    b = rng.random(n) < 0.35
    ys[b] = (rng.integers(-40, 40, int(b.sum())) - 0.5) * r
    d = rng.integers(0, n, n // 5)
    xs[d[1:]], ys[d[1:]] = xs[d[:-1]], ys[d[:-1]]
    return xs, ys


def _scan(rng, n, r_coarse):
    """Ranges and read-only cos / sin (as Scan.trig's) whose points ``r·cos``, ``r·sin`` (the identity pose's
    map-frame points) have ties: a third on cell boundaries of the coarsest level ((k − 0.5)·r, also boundaries
    of the finer levels), duplicates, negative and positive coordinates."""
    xs, ys = _points(rng, n, r_coarse)
    rr = np.hypot(xs, ys)
    rr[rr == 0.0] = 1.0
    cos_a, sin_a = xs / rr, ys / rr
    on = rng.random(n) < 0.5  # half the beams exactly on the boundaries: cos = x, sin = y at range 1
    rr[on], cos_a[on], sin_a[on] = 1.0, xs[on], ys[on]
    cos_a.flags.writeable = sin_a.flags.writeable = False
    return rr, cos_a, sin_a


def _scan_cells(rr, cos_a, sin_a, owner, uids, rs):
    """scan_cells at the identity pose (every beam kept), sorted: (packed, params, the points x and y)."""
    n = rr.shape[0]
    packed, params, valid, counts = lk.scan_cells(rr, cos_a, sin_a, np.ones(n, dtype=bool), np.zeros(n, dtype=bool),
                                                  owner, uids, 0.0, np.inf, 1.0, 0.0, 0.0, 0.0, np.array(rs))
    assert valid.all()
    packed.sort()
    return packed, params, rr * cos_a, rr * sin_a


@pytest.mark.parametrize("seed", range(12))
def test_scan_cells_and_unpack_pick_the_cells_of_the_numpy_path(seed: int) -> None:
    rng = np.random.default_rng(seed)
    rs = [0.05, 0.1, 0.2] if seed % 3 else [0.025, 0.05, 0.1, 0.2]
    n = int(rng.integers(1, 400))
    rr, cos_a, sin_a = _scan(rng, n, rs[-1])
    mine_b = rng.random(n) < (0.5 if seed % 2 else 0.95)
    if not mine_b.any():
        mine_b[0] = True
    ids = rng.choice([2, 7, 8, 31, 1000], int(mine_b.sum()))
    owner = np.full(n, -1, dtype=np.int64)
    owner[mine_b] = ids
    uids = np.unique(ids)
    packed, params, xs, ys = _scan_cells(rr, cos_a, sin_a, owner, uids, rs)
    ref = _reference_cells(xs, ys, ids, mine_b, rs)
    got = lk.unpack_cells(packed, params, uids, len(rs))
    for u, v in zip(got, ref):
        assert u.dtype == v.dtype and np.array_equal(u, v)
    assert got[0].shape[0] > 0


def test_scan_cells_refuse_values_beyond_int64_and_far_cells() -> None:
    """A scan spread so wide that the packed values would overflow, and a point whose cell does not fit in a
    key, give empty packed values (the caller then takes the per-level path), as the numpy path returned None."""
    cos_a = np.array([1.0, -1.0, 0.0, 0.0])
    sin_a = np.array([0.0, 0.0, 1.0, -1.0])
    cos_a.flags.writeable = sin_a.flags.writeable = False
    rr = np.full(4, 6.0e7)
    owner = np.array([-1, 5, 9, 5], dtype=np.int64)
    uids = np.array([5, 9])
    ones, zeros = np.ones(4, dtype=bool), np.zeros(4, dtype=bool)
    rs = np.array([0.05, 0.1, 0.2])
    xs, ys = rr * cos_a, rr * sin_a
    assert _reference_cells(xs, ys, owner[owner >= 0], owner >= 0, list(rs)) is None
    out = lk.scan_cells(rr, cos_a, sin_a, ones, zeros, owner, uids, 0.0, np.inf, 1.0, 0.0, 0.0, 0.0, rs)
    assert out[0].shape[0] == 0 and out[1].shape[0] == 0 and out[3].tolist() == [2, 1]
    far = lk.scan_cells(rr / 1e4, cos_a, sin_a, ones, zeros, owner, uids, 0.0, np.inf, 1.0, 0.0, 1.0e9, 0.0, rs)
    assert far[1].shape[0] == 0
    near = lk.scan_cells(rr / 1e4, cos_a, sin_a, ones, zeros, owner, uids, 0.0, np.inf, 1.0, 0.0, 0.0, 0.0, rs)
    assert near[1].shape[0] == 9 and near[0].shape[0] == 12


def _read_reference(logodds, uidx, cells, i0, j0):
    """``EvidenceLedger._read``: log-odds and update index of absolute cells, 0 and 0 (never) outside the array."""
    n = cells.shape[0]
    h, w = logodds.shape
    col, row = cells[:, 0] - i0, cells[:, 1] - j0
    lo, ui = np.zeros(n), np.zeros(n, dtype=np.int64)
    ok = (col >= 0) & (row >= 0) & (col < w) & (row < h)
    lo[ok] = logodds[row[ok], col[ok]]
    ui[ok] = uidx[row[ok], col[ok]]
    return lo, ui, ok


@pytest.mark.parametrize("seed", range(6))
def test_read_and_update_rows_equal_the_numpy_after_update(seed: int) -> None:
    """read_cells / update_rows against the gathers and masks of the former after_update: every cell read the
    same, rows only where the update index changed (outside cells and skipped rays give none), groups per
    track in order, the added log-odds' bits exact."""
    rng = np.random.default_rng(100 + seed)
    h, w = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    logodds = rng.normal(0.0, 2.0, (h, w)).astype(np.float32)
    uidx = rng.integers(0, 5, (h, w)).astype(np.int32)
    i0, j0 = int(rng.integers(-10, 10)), int(rng.integers(-10, 10))
    m = int(rng.integers(0, 200))
    cells = np.column_stack((rng.integers(i0 - 5, i0 + w + 5, m), rng.integers(j0 - 5, j0 + h + 5, m)))
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    ids = np.sort(rng.choice([1, 4, 9, 12], m)).astype(np.int64)
    keys = cells[:, 0] * _KEY_SHIFT + cells[:, 1]
    lo, ui, f, n_out = lk.read_cells(logodds, uidx, cells, i0, j0)
    rlo, rui, ok = _read_reference(logodds, uidx, cells, i0, j0)
    assert np.array_equal(lo, rlo) and np.array_equal(ui, rui) and n_out == int((~ok).sum())
    assert np.array_equal(f[ok], (cells[ok, 1] - j0) * w + cells[ok, 0] - i0) and np.all(f[~ok] == -1)
    # the map update: some cells change (new value, new update index), some change value only (a skipped ray
    # leaves the index: no row), the rest stay
    logodds2, uidx2 = logodds.copy(), uidx.copy()
    hit = rng.random((h, w)) < 0.5
    logodds2[hit] += rng.normal(0.5, 0.3, int(hit.sum())).astype(np.float32)
    uidx2[hit & (rng.random((h, w)) < 0.8)] = 7
    rows, tids, starts = lk.update_rows(logodds2, uidx2, f, ids, keys, lo, ui)
    after, ua, _ = _read_reference(logodds2, uidx2, cells, i0, j0)
    upd = ua != ui
    want = np.empty((4, int(upd.sum())), dtype=np.int64)
    want[0], want[1], want[2] = keys[upd], ui[upd], ua[upd]
    want[3] = (after[upd] - lo[upd]).view(np.int64)
    assert np.array_equal(rows, want)
    kept = ids[upd]
    cut = np.flatnonzero(kept[1:] != kept[:-1]) + 1
    assert np.array_equal(starts, np.concatenate(([0], cut, [kept.shape[0]])) if kept.shape[0] else [0])
    assert np.array_equal(tids, kept[np.concatenate(([0], cut))] if kept.shape[0] else kept)
    if seed == 0:
        assert 0 < want.shape[1] < m and n_out > 0


@pytest.mark.parametrize("seed", range(6))
def test_scan_cells_keep_the_beams_and_cells_of_the_numpy_path(seed: int) -> None:
    """scan_cells against the numpy code of the former before_update: the kept beams (valid, inside the laser's
    open range interval, not removed; NaN, inf and ranges exactly at the limits among them), the map-frame
    points of Pose2D.transform_points, and, decoded, the same cells per level (a track whose beams are all
    dropped has a count of 0 and no cell)."""
    from dynslam2d.types import Pose2D

    rng = np.random.default_rng(200 + seed)
    n = 720
    r = rng.uniform(0.0, 12.0, n)
    r[rng.integers(0, n, 30)] = np.nan
    r[rng.integers(0, n, 10)] = np.inf
    r[rng.integers(0, n, 10)] = 0.1  # == laser_min_dist: not kept
    r[rng.integers(0, n, 10)] = 10.0  # == laser_max_dist: not kept
    r[100:140] = r[40]  # ties: equal ranges
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    cos_a.flags.writeable = sin_a.flags.writeable = False  # as Scan.trig's shared arrays
    vm = np.isfinite(r) & (r >= 0.05) & (r <= 11.0)
    removed = rng.random(n) < 0.1
    owner = np.full(n, -1, dtype=np.int64)
    for tid, (a, b) in zip((12, 3, 40, 7), ((0, 60), (200, 260), (400, 405), (600, 700))):
        owner[a:b] = tid
    removed[400:405] = True  # track 40: every beam removed
    uids = np.array([3, 7, 12, 40])
    pose = Pose2D(float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)), float(rng.uniform(-np.pi, np.pi)))
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    rs = np.array([0.05, 0.1, 0.2])
    packed, params, valid, counts = lk.scan_cells(r, cos_a, sin_a, vm, removed, owner, uids, 0.1, 10.0, c, s,
                                                  pose.x, pose.y, rs)
    with np.errstate(invalid="ignore"):
        want_valid = vm & (r > 0.1) & (r < 10.0) & ~removed
    assert np.array_equal(valid, want_valid)
    idx = np.flatnonzero(want_valid)
    own = owner[idx]
    mine_b = own >= 0
    assert np.array_equal(counts, [int((own == t).sum()) for t in uids]) and counts[3] == 0 and counts[:3].all()
    pts = pose.transform_points(np.column_stack((r[idx] * cos_a[idx], r[idx] * sin_a[idx])))
    ref = _reference_cells(pts[:, 0].copy(), pts[:, 1].copy(), own[mine_b], mine_b, list(rs))
    packed.sort()
    got = lk.unpack_cells(packed, params, uids, 3)
    for u, v in zip(got, ref):
        assert u.dtype == v.dtype and np.array_equal(u, v)
    none = lk.scan_cells(r, cos_a, sin_a, vm, np.ones(n, dtype=bool), owner, uids, 0.1, 10.0, c, s, 0.0, 0.0, rs)
    assert none[0].shape[0] == 0 and not none[3].any()


@pytest.mark.parametrize("seed", range(6))
def test_beam_owners_give_each_beam_to_the_last_track_listing_it(seed: int) -> None:
    """beam_owners against numpy's assignment track after track (beams shared by tracks, repeated within a
    track, negative indices, tracks without beams)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    ids = rng.choice(np.arange(1, 60), int(rng.integers(1, 12)), replace=False).astype(np.int64)
    beams = [rng.integers(-n, n, int(rng.integers(0, 40))) for _ in ids]
    beams.append(np.concatenate([b[:2] for b in beams]))  # a last track sharing beams with every other
    ids = np.append(ids, 99)
    want = np.full(n, -1, dtype=np.int64)
    for tid, b in zip(ids, beams):
        want[b] = tid
    ends = np.cumsum([0] + [b.shape[0] for b in beams]).astype(np.int64)
    got = lk.beam_owners(n, np.concatenate(beams).astype(np.int64), ends, ids)
    assert got.dtype == np.int64 and np.array_equal(got, want)
    assert (got[beams[-1]] == 99).all()
    with pytest.raises(IndexError):
        lk.beam_owners(3, np.array([3], dtype=np.int64), np.array([0, 1], dtype=np.int64), ids[:1])


def test_stand_marks_writes_the_half_size_of_each_new_box_as_box_key_does() -> None:
    """Pass obs114: ``stand_marks`` writes a new standing box's half size (``F[id, 2]``) itself — from the live
    reports' boxes ``B`` (``0.5 * max(l, w)``, Python's ``max``: l unless w > l, NaN in either place included) and
    from ``E[…, 4]`` for the others — bit for bit ``erasure._box_key``'s; a standing report's stays unchanged."""
    nan = math.nan
    lw = [(2.0, 1.0), (1.0, 2.0), (1.5, 1.5), (1.0, nan), (nan, 1.0), (-0.0, 0.0), (0.3, 0.1 + 0.2)]
    n_live = len(lw)
    B = np.array([(0.1 * i, -0.2 * i, 0.3, ln, wd) for i, (ln, wd) in enumerate(lw)], dtype=np.float64)
    X = np.array([(0.1 * i, -0.2 * i, 0.0, 0.0) for i in range(n_live)], dtype=np.float64)
    rows = np.arange(n_live, dtype=np.int64)
    E = np.array([(5.0, 6.0, 0.0, 0.0, 0.75), (7.0, 8.0, 0.0, 0.0, nan)], dtype=np.float64)
    ids = np.arange(n_live + 2, dtype=np.int64)[::-1].copy()
    F = np.full((16, 5), -9.0)
    mark = np.full(16, -5, dtype=np.int64)
    none = np.zeros(0, dtype=np.int64)
    new = lk.stand_marks(X, rows, B, E, ids, none, F, mark, 1, 10.0, 0.1, 0.5)
    assert new.tolist() == list(range(n_live + 2))
    want = [0.5 * max(ln, wd) for ln, wd in lw] + [0.75, nan]
    got = [F[t, 2] for t in ids.tolist()]
    assert [math.copysign(1, g) if g == 0 else g for g in got if g == g] == \
        [math.copysign(1, g) if g == 0 else g for g in want if g == g]
    assert [g != g for g in got] == [g != g for g in want]
    # (the next scan, nobody moved: every box stands; a changed size does not rewrite it)
    B2 = B.copy()
    B2[:, 3:5] = 4.0
    E2 = E.copy()
    E2[:, 4] = 4.0
    assert lk.stand_marks(X, rows, B2, E2, ids, none, F, mark, 2, 11.0, 0.1, 0.5).shape[0] == 0
    assert [F[t, 2] != F[t, 2] or F[t, 2] == g for t, g in zip(ids.tolist(), got)] == [True] * len(got)
