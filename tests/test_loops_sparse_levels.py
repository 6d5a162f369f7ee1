"""The loop closer's memory (docs/speed.md, pass lcm47): what it keeps is smaller, every result the same bit for bit.

* a cached submap keeps its levels below the search level (read only by a match's refinement) sparse: the cells of
  the probability cache that are not 0.5, given back dense as the same float32 bits;
* the place index stores its spectra in blocks of places allocated once (no growth slack, no copies), with the
  distances of one array of them all.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_loops import _block_loop_world, _drifted, _loop_path, _scans

import dynslam2d.slam.loops as lp
import dynslam2d.slam.placedesc as pd
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.loops import LoopCloser
from dynslam2d.types import Pose2D


def _run(scans: list, front: np.ndarray, sparse: bool, monkeypatch: pytest.MonkeyPatch) -> tuple:
    with monkeypatch.context() as m:
        if not sparse:
            m.setattr(lp, "_make_sparse", lambda grid, k: None)
        lc = LoopCloser(LoopConfig(), SlamConfig())
        for k, (s, p) in enumerate(zip(scans, front)):
            lc.add(s.stamp, Pose2D(*p), s, np.zeros(s.ranges.shape, bool), keyframe=k % 2 == 0)
        res = lc.finish()
        grids = {}  # every submap's grid as the searches hold it
        for s in range(len(lc.keyframes) // lc.config.submap_keyframes):
            lc._cache.clear()
            lc._dense_forget()
            grids[s] = lc._submap_grid(s)
            lp._sparsify_late(grids[s])  # (as when it leaves the recent set of dense levels, pass lcm50)
        lc._dense_forget()
    return lc, res, grids


@pytest.fixture(scope="module")
def runs() -> tuple:
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.006)  # the far search closes this loop (test_loops.py)
    scans = _scans(world, gt)
    mp = pytest.MonkeyPatch()
    try:
        return _run(scans, front, True, mp), _run(scans, front, False, mp)
    finally:
        mp.undo()


def test_sparse_levels_give_the_dense_levels_bit_for_bit(runs: tuple) -> None:
    (lc, _res, grids), (_lc0, _res0, dense) = runs
    assert len(grids) >= 5
    n_sparse = 0
    for s, grid in grids.items():
        ref = dense[s]
        assert not ref.sparse
        for k, (lv, lv0) in enumerate(zip(grid.levels, ref.levels)):
            got = grid.dense_level(k)
            assert got.shape == lv0.shape and (got.i0, got.j0) == (lv0.i0, lv0.j0) and got.resolution == lv0.resolution
            assert got.prob.dtype == np.uint32 and got.prob.tobytes() == lv0.prob.tobytes(), (s, k)  # (words)
            if k in grid.sparse:
                n_sparse += 1
                assert k < lc.config.search_level  # the searched levels and the far level stay dense
                assert np.isnan(lv.prob).all() and lv.prob.strides == (0, 0)  # the cache itself is not held
                idx, vals = grid.sparse[k]
                assert idx.nbytes + vals.nbytes < lv0.prob.nbytes / 2
            else:
                assert lv.prob is got.prob
        whole = lc._submap(s)  # for callers outside the searches: every level dense
        assert all(a.prob.tobytes() == b.prob.tobytes() for a, b in zip(whole.levels, ref.levels))
    assert n_sparse >= len(grids)  # (the finest level at least of every submap)


def test_sparse_levels_give_the_same_loops_and_poses(runs: tuple) -> None:
    (lc, res, _g), (lc0, res0, _g0) = runs
    assert lc.stats["far_loops"] >= 3 and lc.stats["loops_accepted"] >= 5 and res.corrected
    assert np.array_equal(res.poses, res0.poses) and np.array_equal(res.node_poses, res0.node_poses)
    assert res.loops == res0.loops
    assert {k: v for k, v in res.stats.items() if not k.endswith("_ms")} == {
        k: v for k, v in res0.stats.items() if not k.endswith("_ms")}


def test_place_spectra_in_blocks_give_the_distances_of_one_array() -> None:
    rng = np.random.default_rng(47)
    idx = pd.PlaceIndex(20, 60, 15.0)
    clouds = [rng.normal(0.0, 4.0, (int(rng.integers(5, 200)), 2)) for _ in range(2 * pd._BLOCK + 37)]
    keys = [5 * i + 2 for i in range(len(clouds))]
    a = 0
    for b in (1, 17, pd._BLOCK - 3, pd._BLOCK + 9, 30, 1000):  # batches across the blocks' edges
        idx.add_many(keys[a:a + b], idx.describe_many(clouds[a:a + b]))
        a += b
    n = len(clouds)
    assert len(idx) == n and len(idx._col_blocks) == -(-n // pd._BLOCK)  # no block beyond the last place's
    cols, occ, count = pd._spectra_many(idx.describe_many(clouds))
    assert idx._cols.tobytes() == cols.astype(np.complex64).tobytes()
    assert idx._occ.tobytes() == occ.astype(np.complex64).tobytes()
    all_cols = cols.astype(np.complex64)
    for q in (clouds[3], clouds[pd._BLOCK], rng.normal(0.0, 3.0, (80, 2))):
        qc, qo, qn = pd._spectra(idx.describe(q))
        # the former path: one kernel call over one array of every stored place
        corr = np.fft.irfft(pd._ring_correlation(qc, all_cols, n), n=60, axis=1)
        overlap = np.fft.irfft(qo[None, :] * np.conj(occ.astype(np.complex64)), n=60, axis=1)
        d = 1.0 - corr / np.maximum(qn + count[:, None].astype(np.float64) - np.rint(overlap), 1.0)
        best = np.argmin(d, axis=1)
        k2, d2, s2 = idx.distances(idx.describe(q))
        assert k2.tolist() == keys and s2.tolist() == best.tolist()
        assert d2.tobytes() == np.clip(d[np.arange(n), best], 0.0, 1.0).tobytes()
        for upto in (1, pd._BLOCK, pd._BLOCK + 1, n - 1):
            assert idx.distances(idx.describe(q), upto)[1].tobytes() == d2[:upto].tobytes()
    key = keys[pd._BLOCK + 5]
    assert idx.distances_of(key)[1].tobytes() == idx._distances(
        all_cols[pd._BLOCK + 5].astype(np.complex128), occ[pd._BLOCK + 5].astype(np.complex64).astype(np.complex128),
        int(count[pd._BLOCK + 5]), n)[1].tobytes()


def test_dense_level_cache_follows_the_grid(runs: tuple) -> None:
    """The one-entry cache of rebuilt dense levels (docs/speed.md, pass lcm48): a repeat is the cached level, a
    level of another grid — or of the same submap rebuilt after ``drop_beams`` — the bits of its own rebuild, in
    the reused buffer (no 0.5 left out, no cells of the grid before)."""
    (lc, _res, grids), _dense = runs
    ks = sorted({k for g in grids.values() for k in g.sparse})
    assert ks
    order = [0, 0, 1, 0, 2, 2, 1, len(grids) - 1, 0]
    for s in order:
        lc._cache[s] = grids[s]  # (the grids the searches hold)
        for k in ks:
            if k not in grids[s].sparse:
                continue
            got = lc._dense(grids[s], k)
            assert got.prob.tobytes() == grids[s].dense_level(k).prob.tobytes(), (s, k)
            assert lc._dense(grids[s], k) is got  # the repeat: no rebuild
    assert len(lc._dense_entries) == 1  # outside a far verification: one grid's levels
    assert all(buf.base is None for ent in lc._dense_entries.values() for buf in ent[2].values())  # reused buffers
    # submap 0 changes: its keyframes' beams dropped, the grid rebuilt (another object)
    k0 = ks[0]
    before = lc._dense(grids[0], k0).prob.copy()
    kfs = lc.keyframes[:lc.config.submap_keyframes]
    n = lc.drop_beams([(kf.scan_index, np.arange(0, kf.n_beams, 2)) for kf in kfs])
    assert n > 0 and 0 not in lc._cache
    new = lc._submap_grid(0)
    got = lc._dense(new, k0)
    ref = new.dense_level(k0).prob
    assert got.prob.tobytes() == ref.tobytes() and ref.tobytes() != before.tobytes()
    lc._cache.clear()
    lc._dense_forget()


def test_dense_level_cache_holds_three_grids_while_verifying(runs: tuple) -> None:
    """While a far candidate is verified (pass lcm49) the cache keeps the dense levels of three grids (its partners
    go to submaps s − 1, s, s + 1 in turn): a return to any of them is the cached level, a fourth grid evicts the
    least recently used one and is rebuilt bit for bit in its buffers; after the verification one entry is kept."""
    (lc, _res, grids), _dense = runs
    ks = sorted({k for g in grids.values() for k in g.sparse})
    subs = [s for s in sorted(grids) if ks[0] in grids[s].sparse]
    assert len(subs) >= 4
    lc._dense_forget()
    lc._verifying += 1
    try:
        got = {}
        for s in subs[:3]:
            lc._cache[s] = grids[s]
            got[s] = lc._dense(grids[s], ks[0])
        for s in subs[:3]:  # returns to each of the three: no rebuild
            assert lc._dense(grids[s], ks[0]) is got[s]
            assert got[s].prob.tobytes() == grids[s].dense_level(ks[0]).prob.tobytes(), s
        bufs = lc._dense_entries[id(grids[subs[0]])][2]
        fourth = lc._dense(grids[subs[3]], ks[0])  # evicts subs[0], the least recently used, into its buffers
        assert id(grids[subs[0]]) not in lc._dense_entries and len(lc._dense_entries) == 3
        assert lc._dense_entries[id(grids[subs[3]])][2] is bufs
        assert fourth.prob.tobytes() == grids[subs[3]].dense_level(ks[0]).prob.tobytes()
        for s in subs[1:3]:  # the two others untouched by the fourth's rebuild
            assert lc._dense(grids[s], ks[0]) is got[s]
            assert got[s].prob.tobytes() == grids[s].dense_level(ks[0]).prob.tobytes(), s
    finally:
        lc._verifying -= 1
    lc._dense_trim()
    assert list(lc._dense_entries) == [id(grids[subs[2]])]
    again = lc._dense(grids[subs[0]], ks[0])  # one entry again: the next grid takes the kept entry's buffers
    assert len(lc._dense_entries) == 1
    assert again.prob.tobytes() == grids[subs[0]].dense_level(ks[0]).prob.tobytes()
    lc._cache.clear()
    lc._dense_forget()


def test_built_grid_is_its_own_dense_entry_until_it_leaves(runs: tuple) -> None:
    """A grid just built keeps its levels due to be sparse dense as the most recent entry of the dense-level cache
    (pass lcm50): a refinement right after the build reads them with no rebuild; the next grid's entry evicts it,
    makes it sparse then (the same bits back), and its former caches become the buffers a later rebuild fills."""
    (lc, _res, grids), (_lc0, _res0, dense) = runs
    a, b = 1, 2  # (not submap 0, whose keyframes' beams test_dense_level_cache_follows_the_grid drops)
    lc._cache.clear()
    lc._dense_forget()
    g0 = lc._submap_grid(a)
    ks = list(g0.late)
    assert ks and not g0.sparse and list(lc._dense_entries) == [id(g0)]
    for k in ks:
        assert lc._dense(g0, k) is g0.levels[k]  # its own cache: no rebuild
        assert g0.levels[k].prob.tobytes() == dense[a].levels[k].prob.tobytes(), k
    whole = lc._submap(a)  # for callers outside the searches: copies, not the caches reused later
    assert all(whole.levels[k].prob is not g0.levels[k].prob for k in ks)
    g1 = lc._submap_grid(b)  # the next grid's entry evicts g0's: g0 made sparse now
    own1 = {k: g1.levels[k].prob for k in g1.late}
    assert list(lc._dense_entries) == [id(g1)] and not g0.late
    assert set(g0.sparse) == set(grids[a].sparse) and set(g1.late) == set(grids[b].sparse)
    for k in g0.sparse:
        assert np.isnan(g0.levels[k].prob).all() and g0.levels[k].prob.strides == (0, 0)
    back = {k: lc._dense(g0, k) for k in ks}  # g0 rebuilt: g1 evicted and made sparse, its caches g0's buffers
    assert list(lc._dense_entries) == [id(g0)] and set(g1.sparse) == set(own1)
    for k in ks:
        assert back[k].prob.tobytes() == dense[a].levels[k].prob.tobytes(), k
        assert g1.dense_level(k).prob.tobytes() == dense[b].levels[k].prob.tobytes(), k
        assert whole.levels[k].prob.tobytes() == dense[a].levels[k].prob.tobytes(), k
        if back[k].prob.size <= own1[k].size:
            assert np.shares_memory(back[k].prob, own1[k])
    lc._cache.clear()
    lc._dense_forget()
