"""The evidence ledger's fused kernels (slam/ledgerkernels.py: ``record_cells`` before a map update, ``level_rows``
after it, ``_radix_sort`` inside ``record_cells``) against the sequence of single-step kernels they replaced in
``EvidenceLedger.before_update`` / ``after_update`` (beam_owners, scan_cells, np.sort, unpack_cells, read_cells per
level, kept_beams; read_cells and update_rows per level): the same cells, values, rows and groups, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.slam import ledgerkernels as lk

_KEY_SHIFT = 4294967296


def _levels(rng, rs, pts):
    """Per level a random (log-odds, update index, i0, j0) covering the points' cells right of their median."""
    out = []
    for r in rs:
        ci = np.floor(pts / r + 0.5).astype(np.int64)
        i0, j0 = int(np.median(ci[:, 0])), int(ci[:, 1].min()) - 1  # (cells left of the median are outside)
        w, h = int(ci[:, 0].max()) - i0 + 1, int(ci[:, 1].max()) - j0 + 1
        lo = rng.normal(0.0, 2.0, (max(h, 1), max(w, 1))).astype(np.float32)
        ui = rng.integers(-1, 9, lo.shape).astype(np.int32)
        out.append((lo, ui, i0, j0))
    return out


def _scan(rng, n=360):
    r = rng.uniform(0.2, 8.0, n)
    r[rng.integers(0, n, 20)] = np.nan
    r[rng.integers(0, n, 10)] = 0.1  # == laser_min_dist: not kept
    r[60:90] = r[59]  # ties
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    cos_a.flags.writeable = sin_a.flags.writeable = False  # as Scan.trig's shared arrays
    vm = np.isfinite(r)
    removed = rng.random(n) < 0.05
    return r, cos_a, sin_a, vm, removed


def _tracks(rng, n):
    """Track ids (unsorted, one repeated) and their beams (shared between tracks, negative indices)."""
    ids = [int(v) for v in rng.choice(np.arange(1, 90), 7, replace=False)]
    ids.append(ids[2])  # an id listed twice
    beams = []
    for _ in ids:
        a = int(rng.integers(0, n - 40))
        beams.append(np.arange(a, a + int(rng.integers(1, 40))))
    beams[3] = np.concatenate((beams[3], beams[1][:5], [-1, -2]))  # shared with track 1; negative indices
    return np.array(ids, dtype=np.int64), beams


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("n_lv", [1, 2, 3])
def test_record_cells_equals_the_single_step_kernels(seed: int, n_lv: int) -> None:
    """record_cells against beam_owners → scan_cells → np.sort → unpack_cells → read_cells per level and
    kept_beams: every output equal (cells outside a level's array read as 0 / −1; fewer levels than three)."""
    rng = np.random.default_rng(seed)
    r, cos_a, sin_a, vm, removed = _scan(rng)
    n = r.shape[0]
    ids, beams = _tracks(rng, n)
    allb = np.concatenate(beams).astype(np.int64)
    lens = np.array([b.shape[0] for b in beams], dtype=np.int64)
    ends = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
    rs = np.array([0.05, 0.1, 0.2][:n_lv])
    c, s, px, py = math.cos(0.3), math.sin(0.3), float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3))
    pts = np.column_stack((c * r * cos_a - s * r * sin_a + px, s * r * cos_a + c * r * sin_a + py))
    levels = _levels(rng, rs, pts[np.isfinite(pts[:, 0])])
    pad = 3 - n_lv
    lo_t = tuple(lv[0] for lv in levels) + (np.zeros((0, 0), np.float32),) * pad
    ui_t = tuple(lv[1] for lv in levels) + (np.zeros((0, 0), np.int32),) * pad
    i0_t = tuple(lv[2] for lv in levels) + (0,) * pad
    j0_t = tuple(lv[3] for lv in levels) + (0,) * pad
    removed[beams[5]] = True  # (track 5 keeps no beam)
    idl = np.concatenate((ids, lens))
    status, blk, small, g_kb = lk.record_cells(allb, idl, r, cos_a, sin_a, vm, removed, 0.1, 10.0, c, s, px, py, rs,
                                               lo_t, ui_t, i0_t, j0_t, True)
    m = blk.shape[1]
    g_ids, g_keys, g_cells, g_ui = blk[0], blk[1], np.ascontiguousarray(blk[2:4].T), blk[4]
    g_lo = blk[5].view(np.float64)
    n_t = ids.shape[0]
    g_bounds, g_present, g_kbb = small[:n_lv + 1], small[n_lv + 1:n_lv + 1 + n_t], small[n_lv + 1 + n_t:]
    assert small.shape[0] == n_lv + 1 + n_t + n_t + 1
    # the single steps
    owner = lk.beam_owners(n, allb, ends, ids)
    uids = np.array(sorted(set(ids.tolist())), dtype=np.int64)
    packed, params, valid, counts = lk.scan_cells(r, cos_a, sin_a, vm, removed, owner, uids, 0.1, 10.0, c, s, px,
                                                  py, rs)
    assert status == lk.PACKED and params.shape[0] > 0
    packed.sort()
    w_ids, w_keys, w_cells, w_bounds = lk.unpack_cells(packed, params, uids, n_lv)
    for u, v in ((g_ids, w_ids), (g_keys, w_keys), (g_cells, w_cells), (g_bounds, w_bounds)):
        assert u.dtype == v.dtype and np.array_equal(u, v)
    n_out = 0
    for k, (lo, ui, i0, j0) in enumerate(levels):
        a, b = int(w_bounds[k]), int(w_bounds[k + 1])
        w_lo, w_ui, _, out = lk.read_cells(lo, ui, w_cells[a:b], i0, j0)
        assert np.array_equal(g_lo[a:b].view(np.int64), w_lo.view(np.int64)) and np.array_equal(g_ui[a:b], w_ui)
        n_out += out
    assert n_out > 0 and m > 20  # (cells outside the arrays were read)
    kept = set(uids[counts > 0].tolist())
    assert g_present.tolist() == [int(t in kept) for t in ids.tolist()]
    assert 0 < g_present.sum() < n_t  # (a track whose kept beams are all removed or invalid is left out)
    w_kb, w_kbb = lk.kept_beams(valid, allb, ends)
    assert np.array_equal(g_kb, w_kb) and g_kb.dtype == np.int32 and np.array_equal(g_kbb, w_kbb)
    # without the kept beams: no kept-beam bounds; and with every beam removed: nothing to record
    st2, blk2, small2, kb2 = lk.record_cells(allb, idl, r, cos_a, sin_a, vm, removed, 0.1, 10.0, c, s, px, py, rs,
                                             lo_t, ui_t, i0_t, j0_t, False)
    assert st2 == lk.PACKED and kb2.shape[0] == 0 and np.array_equal(small2, small[:n_lv + 1 + n_t])
    assert np.array_equal(blk2, blk)
    none = lk.record_cells(allb, idl, r, cos_a, sin_a, vm, np.ones(n, dtype=bool), 0.1, 10.0, c, s, px, py,
                           rs, lo_t, ui_t, i0_t, j0_t, True)
    assert none[0] == lk.NO_KEPT and none[1].shape == (6, 0) and none[2].shape[0] == none[3].shape[0] == 0


@pytest.mark.parametrize("first", [0, 1, 2])
def test_record_cells_keeps_every_distinct_value_around_runs_of_repeats(first: int) -> None:
    """Every kept beam a track's, each beam's cell its own except runs of equal ranges (repeated packed values) at
    the start (after ``first`` single values), in the middle and at the end: record_cells' repeat removal before
    the sort keeps each distinct value once — the cells equal those of the single steps (np.sort, unpack_cells),
    the first values of the scan included."""
    n = 40
    r = 1.0 + 0.3 * np.arange(n)
    r[first:first + 4] = r[first]
    r[20:25] = r[20]
    r[n - 3:] = r[n - 3]
    cos_a = np.ones(n)
    sin_a = np.zeros(n)  # every beam along x: a range is a cell
    cos_a.flags.writeable = sin_a.flags.writeable = False
    vm = np.ones(n, dtype=bool)
    removed = np.zeros(n, dtype=bool)
    ids = np.array([7, 3], dtype=np.int64)
    allb = np.arange(n, dtype=np.int64)
    lens = np.array([25, n - 25], dtype=np.int64)
    rs = np.array([0.05, 0.1, 0.2])
    lv = (np.zeros((1, 1), np.float32), np.zeros((1, 1), np.int32), 0, 0)
    status, blk, small, _ = lk.record_cells(allb, np.concatenate((ids, lens)), r, cos_a, sin_a, vm, removed, 0.1,
                                            100.0, 1.0, 0.0, 0.0, 0.0, rs, (lv[0],) * 3, (lv[1],) * 3, (0,) * 3,
                                            (0,) * 3, False)
    owner = lk.beam_owners(n, allb, np.array([0, 25, n], dtype=np.int64), ids)
    uids = np.array([3, 7], dtype=np.int64)
    packed, params, _, _ = lk.scan_cells(r, cos_a, sin_a, vm, removed, owner, uids, 0.1, 100.0, 1.0, 0.0, 0.0, 0.0,
                                         rs)
    packed.sort()
    w_ids, w_keys, w_cells, w_bounds = lk.unpack_cells(packed, params, uids, 3)
    assert status == lk.PACKED
    assert np.array_equal(blk[0], w_ids) and np.array_equal(blk[1], w_keys) and np.array_equal(small[:4], w_bounds)
    assert np.array_equal(blk[2:4].T, w_cells)
    assert w_bounds[1] == n - 3 - 4 - 2  # (level 0: one cell a distinct range)


def test_record_cells_leaves_values_beyond_an_int64_to_the_level_by_level_path() -> None:
    """A point far away (cells beyond the packed values' range): not packed, but the kept beams, track ids and
    counts are returned for the level-by-level path."""
    rng = np.random.default_rng(3)
    r, cos_a, sin_a, vm, removed = _scan(rng)
    r[5] = 1e12
    ids, beams = _tracks(rng, r.shape[0])
    beams[0] = np.append(beams[0], 5)
    allb = np.concatenate(beams).astype(np.int64)
    lens = np.array([b.shape[0] for b in beams], dtype=np.int64)
    rs = np.array([0.05, 0.1, 0.2])
    lo = np.zeros((4, 4), np.float32)
    ui = np.zeros((4, 4), np.int32)
    got = lk.record_cells(allb, np.concatenate((ids, lens)), r, cos_a, sin_a, vm, np.zeros(r.shape[0], dtype=bool),
                          0.0, 1e13, 1.0, 0.0, 0.0, 0.0, rs, (lo,) * 3, (ui,) * 3, (0,) * 3, (0,) * 3, True)
    assert got[0] == lk.PLAIN and got[1].shape == (6, 0)


@pytest.mark.parametrize("bits", [0, 1, 7, 11, 12, 23, 33, 45, 62])
def test_radix_sort_equals_numpy_sort(bits: int) -> None:
    """_radix_sort orders non-negative int64 values as np.sort does, whatever the digits' number (an even and an
    odd number of passes, one value, duplicates)."""
    rng = np.random.default_rng(bits)
    for n in (0, 1, 2, 17, 1800):
        a = rng.integers(0, 1 << bits, n, dtype=np.int64) if bits else np.zeros(n, dtype=np.int64)
        if n > 2:
            a[: n // 3] = a[n // 3: 2 * (n // 3)]  # duplicates
        want = np.sort(a)
        lk._radix_sort(a)
        assert np.array_equal(a, want)


@pytest.mark.parametrize("seed", range(6))
def test_level_rows_equal_update_rows_per_level(seed: int) -> None:
    """level_rows against read_cells + update_rows level by level after a map update that changed some cells
    (and on one level grew the array: other offsets and shape): the same row block, level after level, the same
    groups (a track's rows on one level) with their levels, in (track id, level) order."""
    rng = np.random.default_rng(50 + seed)
    n_lv = 3
    levels_before, levels_after, per = [], [], []
    for k in range(n_lv):
        h, w = int(rng.integers(2, 30)), int(rng.integers(2, 30))
        lo = rng.normal(0.0, 2.0, (h, w)).astype(np.float32)
        ui = rng.integers(-1, 5, (h, w)).astype(np.int32)
        i0, j0 = int(rng.integers(-10, 10)), int(rng.integers(-10, 10))
        m = int(rng.integers(0, 80))
        cells = np.ascontiguousarray(np.column_stack((rng.integers(i0 - 3, i0 + w + 3, m),
                                                      rng.integers(j0 - 3, j0 + h + 3, m))), dtype=np.int64)
        # (even seeds: one track, id 0, on every level: a level's first group has the id of the one before it)
        ids = np.sort(rng.choice([2, 5, 8, 13] if seed % 2 else [0], m)).astype(np.int64)
        keys = cells[:, 0] * _KEY_SHIFT + cells[:, 1]
        before, ub, _, _ = lk.read_cells(lo, ui, cells, i0, j0)
        lo2, ui2 = lo.copy(), ui.copy()
        hit = rng.random((h, w)) < 0.5
        lo2[hit] += rng.normal(0.5, 0.3, int(hit.sum())).astype(np.float32)
        ui2[hit & (rng.random((h, w)) < 0.8)] = 7
        if k == 1:  # the level grew: two columns on the left, one row on top
            g_lo = np.zeros((h + 1, w + 2), np.float32)
            g_ui = np.full((h + 1, w + 2), -1, np.int32)
            g_lo[:h, 2:], g_ui[:h, 2:] = lo2, ui2
            lo2, ui2, i0 = g_lo, g_ui, i0 - 2
        levels_after.append((lo2, ui2, i0, j0))
        per.append((ids, keys, cells, before, ub))
        levels_before.append((lo, ui))
    cat = [np.concatenate([p[q] for p in per]) for q in range(5)]
    bounds = np.concatenate(([0], np.cumsum([p[0].shape[0] for p in per]))).astype(np.int64)
    # record_cells' block (id, key, i, j, update index before, log-odds before's bits) and its small outputs (the
    # level bounds, then values level_rows must not read)
    blk = np.ascontiguousarray(np.vstack((cat[0], cat[1], cat[2].T, cat[4], cat[3].view(np.int64))))
    small = np.concatenate((bounds, [1, 0, 1, 5, 9]))
    blk_before = blk.copy()
    rows, t_id, t_bnd, t_lv = lk.level_rows(
        tuple(lv[0] for lv in levels_after), tuple(lv[1] for lv in levels_after), tuple(lv[2] for lv in levels_after),
        tuple(lv[3] for lv in levels_after), n_lv, blk, small)
    assert np.array_equal(blk, blk_before)  # (it reads the log-odds before through a view of the block: not written)
    groups = []  # (track id, level, its rows) from update_rows, level by level
    for k, ((lo2, ui2, i0, j0), (ids, keys, cells, before, ub)) in enumerate(zip(levels_after, per)):
        f = lk.read_cells(lo2, ui2, cells, i0, j0)[2]
        r_k, g_k, s_k = lk.update_rows(lo2, ui2, f, ids, keys, before, ub)
        groups += [(t, k, r_k[:, a:b]) for t, a, b in zip(g_k.tolist(), s_k.tolist(), s_k[1:].tolist())]
    groups.sort(key=lambda g: (g[0], g[1]))  # (track id, level): each track's groups one after the other
    assert len({g[1] for g in groups}) > 1
    # the rows in (track id, level) order, each group's rows as update_rows gives them, the fifth row its level
    want = np.concatenate([np.vstack((r, np.full((1, r.shape[1]), k))) for _, k, r in groups], axis=1)
    assert rows.shape[1] > 0 and np.array_equal(rows, want)
    # the tracks: each id once, ascending, its rows one column range (all its levels), its levels as bits
    w_ids = sorted({g[0] for g in groups})
    assert t_id.tolist() == w_ids and t_bnd[0] == 0 and t_bnd[-1] == rows.shape[1]
    for t, tid in enumerate(w_ids):
        mine = [g for g in groups if g[0] == tid]
        assert t_bnd[t + 1] - t_bnd[t] == sum(g[2].shape[1] for g in mine) > 0
        assert np.array_equal(rows[:4, t_bnd[t]:t_bnd[t + 1]], np.concatenate([g[2] for g in mine], axis=1))
        assert t_lv[t] == sum(1 << g[1] for g in mine)


@pytest.mark.parametrize("levels", [2, 3, 4])
def test_ledger_records_the_same_rows_through_the_fused_and_the_level_by_level_path(levels: int) -> None:
    """Map updates recorded by EvidenceLedger with the fused kernels (and, with four levels, the fourth level read
    and recorded level by level) and, for a second ledger, from the same reads handed over level by level (the
    per-level path of after_update): every track's records fold to the same cells, log-odds, purity and update
    indices, and the counters agree."""
    from conftest import paper_room_scan, paper_room_slam

    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam.erasure import EvidenceLedger, PendingUpdate
    from dynslam2d.types import Box, Pose2D, Track

    slam, first = paper_room_slam(levels)
    a = EvidenceLedger(MemoryConfig(), slam.config.laser_min_dist, slam.config.laser_max_dist)
    b = EvidenceLedger(MemoryConfig(), slam.config.laser_min_dist, slam.config.laser_max_dist)
    for step in range(6):
        pose = first.compose(Pose2D(0.05 * step, 0.02 * step, 0.01 * step))
        scan = paper_room_scan(pose, 0.1 * step)
        n = scan.ranges.shape[0]
        tracks = [Track(id=tid, state="confirmed", stamp=0.1 * step, box=Box(1.0, 0.5, 0.0, 0.4, 0.4),
                        velocity=np.zeros(2), covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect",
                        in_m=False, m_reason="", beams=beams, n_points=int(beams.shape[0]))
                  for tid, beams in ((7, np.arange(100 + step, 160)), (2, np.arange(400, 430 + step)),
                                     (11, np.arange(600, 640)))]
        removed = np.zeros(n, dtype=bool)
        pa = a.before_update(scan, pose, tracks, removed, slam.map)
        pb = b.before_update(scan, pose, tracks, removed, slam.map)
        assert pa.fused is not None
        pb = PendingUpdate(per_level=pb.per_level)  # (the level-by-level form of the same reads)
        assert slam.update_map(scan, pose, force=True)
        a.after_update(pa, slam.map)
        b.after_update(pb, slam.map)
    assert set(a._ledgers) == set(b._ledgers) == {2, 7, 11}
    cells = 0
    for tid, la in a._ledgers.items():
        lb = b._ledgers[tid]
        # one entry per update in which the track had rows (not yet handed to the records: nothing folded)
        n_ent = len(la.ent)
        assert 1 <= n_ent <= 6 and len(lb.ent) == n_ent and la.nb_chunks == n_ent
        assert la.recs is None and lb.recs is None  # (made at the first settle)
        for ra, rb in zip(la.levels, lb.levels):  # (levels settles the entries into the records)
            assert not la.ent and ra._refs is None and len(ra) == len(rb) and ra._n_chunks == rb._n_chunks
            assert max(r._n_chunks for r in la.recs) == n_ent
            n = ra.compact()
            assert n == rb.compact() and n > 0
            cells += n
            for x, y in ((ra.key, rb.key), (ra.delta, rb.delta), (ra.pure, rb.pure), (ra.last, rb.last)):
                assert np.array_equal(x, y)
    assert cells > 100 and a.summary() == b.summary()


def _room_tracks(stamp: float) -> list:
    from dynslam2d.types import Box, Track

    return [Track(id=tid, state="confirmed", stamp=stamp, box=Box(1.0, 0.5, 0.0, 0.4, 0.4), velocity=np.zeros(2),
                  covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect", in_m=False, m_reason="", beams=beams,
                  n_points=int(beams.shape[0]))
            for tid, beams in ((7, np.arange(100, 160)), (2, np.arange(400, 430)))]


def test_before_update_reads_each_maps_own_cell_sides() -> None:
    """One ledger used with two maps of other resolutions (pass ledger15 keeps the levels' cell sides per map): the
    second map's cells are those a fresh ledger reads on it; the scan's cached valid mask (handed to the kernel
    without a copy) is left as it was."""
    from conftest import paper_room_scan

    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.slam.erasure import EvidenceLedger
    from dynslam2d.types import Pose2D

    maps = [HectorSlam(SlamConfig(map_resolution=r)) for r in (0.05, 0.07)]
    pose = Pose2D(0.3, -0.4, 0.2)
    scan = paper_room_scan(pose)
    for slam in maps:
        slam.update_map(scan, Pose2D(), force=True)
    mask = scan.valid_view().copy()
    removed = np.zeros(scan.ranges.shape[0], dtype=bool)
    cfg = MemoryConfig()
    reused = EvidenceLedger(cfg, 0.1, 30.0)
    reused.before_update(scan, pose, _room_tracks(0.0), removed, maps[0].map)
    got = reused.before_update(scan, pose, _room_tracks(0.0), removed, maps[1].map).fused
    want = EvidenceLedger(cfg, 0.1, 30.0).before_update(scan, pose, _room_tracks(0.0), removed, maps[1].map).fused
    first = EvidenceLedger(cfg, 0.1, 30.0).before_update(scan, pose, _room_tracks(0.0), removed, maps[0].map).fused
    assert got[0].shape[1] > 50 and np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    assert not np.array_equal(got[0][2:4], first[0][2:4])  # (other cells on the other map)
    assert np.array_equal(scan.valid_view(), mask)


def test_erase_entering_without_a_track_in_the_removal_set_does_nothing() -> None:
    """An empty removal set returns at once (pass ledger15): nothing erased, no ledger started or changed; the
    same track in the set starts its stay (``m_start``)."""
    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.slam.erasure import EvidenceLedger

    slam = HectorSlam(SlamConfig())
    led = EvidenceLedger(MemoryConfig(), 0.1, 30.0)
    tracks = _room_tracks(0.0)
    led.observe(tracks, set(), 0.0)
    assert led.erase_entering(tracks, set(), 0.0, slam.map) == 0 and not led._ledgers
    assert led.erase_entering(tracks, {7}, 0.1, slam.map) == 0
    assert set(led._ledgers) == {7} and led._ledgers[7].m_start == (1.0, 0.5)
