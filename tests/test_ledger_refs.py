"""The evidence ledger's row references (slam/erasure.py ``_LevelRecord.refer``, the map10 pass): a record given
its rows as references to an update's shared row block, copied into its buffer only when read, when its track
ends or when they are old, must fold to exactly what copying each update's rows (``push_rows``) gives, and count
the same new cells when dropped."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import _LevelRecord


def _blocks(seed: int, n: int) -> list[tuple[np.ndarray, int, int]]:
    """``n`` updates' (4, m) row blocks (key, update index before, after, log-odds' bits) with this record's
    columns ``a:b`` among other tracks' columns."""
    rng = np.random.default_rng(seed)
    out = []
    for step in range(n):
        keys = np.unique(rng.integers(step // 2, step // 2 + 120, rng.integers(1, 60))).astype(np.int64)
        k = keys.shape[0]
        delta = rng.normal(0.4, 0.3, k)
        ub = np.where(rng.random(k) < 0.8, step - 1, -1).astype(np.int64)
        a = int(rng.integers(0, 5))
        rows = np.full((4, a + k + int(rng.integers(0, 5))), -9, dtype=np.int64)
        rows[:, a:a + k] = np.stack((keys, ub, np.full(k, step, dtype=np.int64), delta.view(np.int64)))
        out.append((rows, a, a + k))
    return out


@pytest.mark.parametrize("cap", [10_000, 40])
@pytest.mark.parametrize("mode", ["plain", "materialize", "copy", "shrink"])
def test_referenced_rows_fold_as_copied_rows(cap: int, mode: str) -> None:
    blocks = _blocks(5 if cap > 100 else 6, 150)
    copied, referred = _LevelRecord(cap), _LevelRecord(cap)
    added_c = added_r = 0
    for u, (rows, a, b) in enumerate(blocks):
        if copied.push_rows(rows, a, b):
            added_c += copied.compact()
        if mode == "copy" and u % 5 == 2:  # copied rows after referenced ones (the buffer takes them first)
            if referred.push_rows(rows, a, b):
                added_r += referred.compact()
        elif referred.refer(rows, a, b, u):
            added_r += referred.compact()
        assert len(referred) == len(copied)
        if u % 7 == 3:  # copy the references at random times (the age sweep, a track's end)
            if mode == "materialize":
                referred.materialize()
                assert referred._pk.shape[1] == referred._n_rows and referred._refs is None
            elif mode == "shrink":
                referred.shrink()
                assert referred._pk.shape[1] == referred._n_rows
    # copied rows are the record's: the blocks may be overwritten once the references are copied
    referred.materialize()
    for rows, _, _ in blocks:
        rows[:] = -3
    assert added_c == added_r and added_c > 0  # the chunk limit folded both at the same updates
    assert copied.new_cells() == referred.new_cells()
    assert copied.compact() == referred.compact()
    for f in ("key", "delta", "pure", "last"):
        assert np.array_equal(getattr(copied, f), getattr(referred, f))
    assert not referred.pure.all() and referred.pure.any()


def test_dropped_record_with_references_counts_the_cells_folding_would() -> None:
    blocks = _blocks(9, 20)
    for cap in (10_000, 25):
        a, b = _LevelRecord(cap), _LevelRecord(cap)
        for u, (rows, lo, hi) in enumerate(blocks):
            a.refer(rows, lo, hi, u)
            b.refer(rows, lo, hi, u)
        n = a.new_cells()
        assert n == b.compact() and (n == cap if cap < 100 else n > 100)


def test_refer_asks_for_a_fold_at_the_row_and_chunk_limits(monkeypatch) -> None:
    monkeypatch.setattr(er, "_COMPACT_ROWS", 50)
    monkeypatch.setattr(er, "_COMPACT_CHUNKS", 4)
    rows = np.zeros((4, 70), dtype=np.int64)
    rows[0] = np.arange(70)
    rows[1] = -1
    rec = _LevelRecord(1000)
    assert [rec.refer(rows, 0, 3, u) for u in range(4)] == [False, False, False, True]
    assert rec.compact() == 3 and len(rec) == 3 and rec._refs is None
    assert rec.refer(rows, 0, 60, 4)  # 60 rows >= 50
    assert len(rec) == 63 and rec.compact() == 57
