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
    """The row block, group table and track table of one update, as ``level_rows`` returns them (no group ids)."""
    rows = np.concatenate([g[2] for g in groups], axis=1) if groups else er._EMPTY_I4
    sizes = [g[2].shape[1] for g in groups]
    ga = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64) if groups else er._EMPTY_I
    gb = (ga + np.array(sizes, dtype=np.int64)) if groups else er._EMPTY_I
    glv = np.array([g[1] for g in groups], dtype=np.int64)
    gid = [g[0] for g in groups]
    tids = sorted(set(gid))
    bnd = [gid.index(t) for t in tids] + [len(gid)]
    n_t = [sum(sizes[bnd[i]:bnd[i + 1]]) for i in range(len(tids))]
    return (rows, glv, ga, gb, np.array(tids, dtype=np.int64), np.array(bnd, dtype=np.int64),
            np.array(n_t, dtype=np.int64))


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
    for tid in tracks:
        recs = [_LevelRecord(cap) for _ in range(3)]
        led._ledgers[tid] = _Ledger(tid, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, recs)
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
        for tid in tracks:
            for k, (a, b) in enumerate(zip(led._ledgers[tid].recs, ref[tid])):  # (recs: without settling)
                assert np.array_equal(a.key, b.key), (u, tid, k)
                assert np.array_equal(a.delta.view(np.int64), b.delta.view(np.int64))
                assert np.array_equal(a.pure, b.pure) and np.array_equal(a.last, b.last)
        assert led.stats["cells_recorded"] == ref_added
    assert folds["rows"] >= 3 and folds["updates"] >= 6  # (both reasons to fold were exercised)
    # the entries not yet settled (fewer than one per update: the bounds settled some) fold to the same cells
    assert 0 < sum(len(x.ent) for x in led._ledgers.values()) < 3 * len(ups)
    for tid in tracks:
        for a, b in zip(led._ledgers[tid].levels, ref[tid]):
            assert a.compact() == b.compact()
            assert np.array_equal(a.key, b.key) and np.array_equal(a.delta.view(np.int64), b.delta.view(np.int64))


def test_a_dropped_ledger_counts_its_new_cells_without_settling() -> None:
    """``_Ledger.new_cells`` of a ledger whose rows are still entries (one update, several updates, a record
    holding folded cells and pending rows) equals what folding every record counts, and leaves the entries."""
    rng = np.random.default_rng(5)
    cap = 60
    for n_up in (1, 2, 5):
        ups = _updates(rng, n_up, {4: (50, 90)})
        led = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, [_LevelRecord(cap) for _ in range(3)])
        want = [_LevelRecord(cap) for _ in range(3)]
        for u, groups in enumerate(ups, start=1):
            rows, glv, ga, gb, tid_t, bnd_t, _ = _table(groups)
            led.ent.append(([rows, glv, ga, gb, None, u], 0, int(bnd_t[-1])))
            for _, k, r in groups:
                want[k].refer(r, 0, r.shape[1], u)
            if n_up == 5 and u == 2:  # (a settle and a fold in between: folded cells and pending rows)
                led.settle()
                led.recs[0].compact()
                want[0].compact()
        n = led.new_cells()
        assert n == sum(r.compact() for r in want) and n > 0
        assert led.ent  # (nothing settled)
        assert n == sum(r.compact() for r in led.levels)
