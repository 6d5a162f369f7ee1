"""The evidence ledger's per-update entries (slam/erasure.py ``_Ledger.ent``, pass ledger13): a map update records
each track with one entry in its ledger, and the ledger hands the rows to its level records (``settle``) when its
bounds say a record may be due to fold. Every record must fold at exactly the update where it folded when each
(track, level) group was handed to its record at once (``_LevelRecord.refer``): the fold's per-cell sums are not
associative in float64, so folding at another update would change the erased log-odds' bits."""

from __future__ import annotations

import types

import numpy as np

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import EvidenceLedger, PendingUpdate, _Ledger, _LevelRecord


def _updates(rng: np.random.Generator, n_updates: int, tracks: dict[int, tuple[int, int]]) -> list[list]:
    """Per update, per (track, level) in (track, level) order: (track, level, (4, m) rows), m > 0. ``tracks``:
    id → (most rows per level per update, cells it draws its keys from)."""
    out = []
    for u in range(n_updates):
        groups = []
        for tid in sorted(tracks):
            most, n_cells = tracks[tid]
            for k in range(3):
                if rng.random() < 0.15:  # (no rows of this track on this level in this update)
                    continue
                m = int(rng.integers(1, most + 1))
                keys = np.sort(rng.choice(n_cells, size=min(m, n_cells), replace=False)).astype(np.int64)
                m = keys.shape[0]
                ub = rng.integers(-1, u + 1, m).astype(np.int64)
                ua = ub + rng.integers(0, 2, m)
                delta = rng.normal(0.4, 0.3, m)
                groups.append((tid, k, np.stack((keys * 7 + tid, ub, ua, delta.view(np.int64)))))
        out.append(groups)
    return out


def _table(groups: list) -> tuple:
    """The row block and track table of one update, as ``level_rows`` returns them: (5, m) rows in (track, level)
    order (the fifth row: the level), per track its id, its column bounds (T + 1,) and its levels (bit k)."""
    if not groups:
        return er._EMPTY_I5, er._EMPTY_I, np.zeros(1, dtype=np.int64), er._EMPTY_I
    rows = np.concatenate([np.vstack((g[2], np.full((1, g[2].shape[1]), g[1], dtype=np.int64))) for g in groups],
                          axis=1)
    tids = sorted({g[0] for g in groups})
    bnd, lv, off = [], [], 0
    for t in tids:
        bnd.append(off)
        off += sum(g[2].shape[1] for g in groups if g[0] == t)
        lv.append(sum(1 << g[1] for g in groups if g[0] == t))
    return (rows, np.array(tids, dtype=np.int64), np.array(bnd + [off], dtype=np.int64),
            np.array(lv, dtype=np.int64))


def test_records_fold_at_the_same_updates_as_with_one_reference_per_group(monkeypatch) -> None:
    """200 updates of three tracks (one with many rows a level: it folds on rows, ≥ 4096; two with few: they fold
    on updates, 64, one of them capped): after every update each record's folded cells (key, log-odds bits,
    purity, last index) equal those of a record given each group with ``refer`` and folded when it says so, and
    the ledger's cells_recorded equals the folds' count; at the end the settled pending rows fold to the same."""
    rng = np.random.default_rng(13)
    cfg = MemoryConfig()
    cap = cfg.max_ledger_cells
    tracks = {3: (12, 40), 5: (160, 3000), 9: (30, cap + 300)}
    ups = _updates(rng, 200, tracks)
    monkeypatch.setattr(EvidenceLedger, "_level_groups", staticmethod(lambda pending, levels: pending.per_level))
    led = EvidenceLedger(cfg, 0.1, 30.0)
    hmap = types.SimpleNamespace(levels=[None, None, None])
    for tid in tracks:  # (the ledgers as the pipeline makes them: no records before the first settle)
        led._ledgers[tid] = led._new_ledger(types.SimpleNamespace(id=tid, box=types.SimpleNamespace(
            px=0.0, py=0.0, length=1.0, width=1.0)), 0.0, 3)
        assert led._ledgers[tid].recs is None and led._ledgers[tid].cap == cap
    empty = _LevelRecord(cap)
    ref = {tid: [_LevelRecord(cap) for _ in range(3)] for tid in tracks}
    ref_added = 0
    folds = {"rows": 0, "updates": 0}
    for u, groups in enumerate(ups, start=1):
        for tid, k, rows in groups:
            rec = ref[tid][k]
            if rec.refer(rows, 0, rows.shape[1], u):
                folds["rows" if rec._n_rows >= er._COMPACT_ROWS else "updates"] += 1
                ref_added += rec.compact()
        led.after_update(PendingUpdate(per_level=_table(groups)), hmap)
        if u % 10 == 0:  # (track 3's entries packed now and then: a packed entry followed by update entries)
            led._ledgers[3].pack()
            assert len(led._ledgers[3].ent) <= 1
        for tid in tracks:
            x = led._ledgers[tid]
            # (recs: without settling; none yet: nothing folded)
            for k, (a, b) in enumerate(zip(x.recs if x.recs is not None else [empty] * 3, ref[tid])):
                assert np.array_equal(a.key, b.key), (u, tid, k)
                assert np.array_equal(a.delta.view(np.int64), b.delta.view(np.int64))
                assert np.array_equal(a.pure, b.pure) and np.array_equal(a.last, b.last)
        assert led.stats["cells_recorded"] == ref_added
    assert folds["rows"] >= 3 and folds["updates"] >= 6  # (both reasons to fold were exercised)
    assert all(x.recs is not None for x in led._ledgers.values())  # (made at each ledger's first settle)
    # the entries not yet settled (fewer than one per update: the bounds settled some) fold to the same cells
    assert 0 < sum(len(x.ent) for x in led._ledgers.values()) < 3 * len(ups)
    for tid in tracks:
        for a, b in zip(led._ledgers[tid].levels, ref[tid]):
            b.materialize()  # (the pending rows, in order, exactly as the records given each group hold them)
            assert a._n_rows == b._n_rows > 0 and a._n_chunks == b._n_chunks
            assert np.array_equal(a._pk[:, :a._n_rows], b._pk[:, :b._n_rows])
            assert a.compact() == b.compact()
            assert np.array_equal(a.key, b.key) and np.array_equal(a.delta.view(np.int64), b.delta.view(np.int64))


def test_a_dropped_ledger_counts_its_new_cells_without_settling() -> None:
    """``_Ledger.new_cells`` of a ledger whose rows are still entries (one update, several updates, a record
    holding folded cells and pending rows) equals what folding every record counts, and leaves the entries."""
    rng = np.random.default_rng(5)
    # (cap 60: some levels capped; 4000: none, a lazy ledger counts its (level, cell) pairs in one sort; huge keys:
    # the counts level by level, as the pairs would not fit one int64)
    for n_up, lazy, cap, big in ((1, True, 60, 0), (2, True, 60, 0), (1, False, 60, 0), (2, False, 60, 0),
                                 (5, True, 60, 0), (5, False, 60, 0), (2, True, 4000, 0), (3, True, 4000, 1 << 62),
                                 (1, True, 4000, 0), (5, True, 4000, 0)):
        ups = _updates(rng, n_up, {4: (50, 90), 6: (20, 30)})
        for g in ups[-1]:  # (the last update's keys 2^62 above the others: shifted by two bits they would wrap)
            g[2][0] += big
        recs = None if lazy else [_LevelRecord(cap) for _ in range(3)]
        led = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, recs, 3, cap)
        want = [_LevelRecord(cap) for _ in range(3)]
        for u, groups in enumerate(ups, start=1):
            rows, tid_t, bnd_t, lv_t = _table(groups)
            if 4 in tid_t.tolist():  # (track 4's column range in a block that also holds track 6's rows)
                t = tid_t.tolist().index(4)
                led.ent.append((rows, int(bnd_t[t]), int(bnd_t[t + 1]), int(lv_t[t])))
            groups = [g for g in groups if g[0] == 4]
            for _, k, r in groups:
                want[k].refer(r, 0, r.shape[1], u)
            if n_up == 5 and u == 2:  # (a settle and a fold in between: folded cells and pending rows)
                led.settle()
                assert led.recs is not None
                led.recs[0].compact()
                want[0].compact()
        n = led.new_cells()
        assert n == sum(r.compact() for r in want) and n > 0
        assert led.ent and (led.recs is None) == (lazy and n_up < 5)  # (nothing settled, no records made)
        assert n == sum(r.compact() for r in led.levels)


def test_a_packed_ledger_settles_to_the_same_records() -> None:
    """``_Ledger.pack`` (an ended track's ledger: its entries' rows copied out of the shared update blocks in one
    array) holds no update block, keeps the bounds, and settles to the same pending rows, update counts and folded
    cells as settling the entries directly; ``new_cells`` of the packed ledger counts the same."""
    rng = np.random.default_rng(21)
    cap = 4000
    for n_up, settle_at in ((1, 0), (7, 0), (7, 3)):
        ups = _updates(rng, n_up, {4: (50, 90), 6: (20, 30)})
        a = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, cap)
        b = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, cap)
        blocks = []
        for u, groups in enumerate(ups, start=1):
            rows, tid_t, bnd_t, lv_t = _table(groups)
            blocks.append(rows)
            t = tid_t.tolist().index(4)
            for x in (a, b):
                x.ent.append((rows, int(bnd_t[t]), int(bnd_t[t + 1]), int(lv_t[t])))
                x.nb_rows += int(bnd_t[t + 1] - bnd_t[t])
                x.nb_chunks += 1
            if u == settle_at:  # (records with pending rows before the pack)
                a.settle()
                b.settle()
        bound = (a.nb_rows, a.nb_chunks)
        a.pack()
        assert len(a.ent) == 1 and all(a.ent[0][0] is not r and a.ent[0][0].base is None for r in blocks)
        assert (a.nb_rows, a.nb_chunks) == bound and a.new_cells() == b.new_cells() > 0
        for ra, rb in zip(a.levels, b.levels):
            assert ra._n_rows == rb._n_rows and ra._n_chunks == rb._n_chunks and ra._pk.shape == rb._pk.shape
            assert np.array_equal(ra._pk, rb._pk)
            assert ra.compact() == rb.compact()
            assert np.array_equal(ra.delta.view(np.int64), rb.delta.view(np.int64))
