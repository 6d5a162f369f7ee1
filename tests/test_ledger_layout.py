"""The evidence ledger's per-record pending buffers (slam/erasure.py ``_LevelRecord``, issue 13 item 3): rows are
copied into two growing arrays per record instead of kept as views of each update's arrays. The folded record must
be what the rows say, whatever the buffer growth, fold schedule and cap, and must not depend on the caller's arrays
after :meth:`push` returned."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import _LevelRecord


def _reference(updates: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], cap: int) -> dict:
    """Cell key → [summed log-odds, pure, last update index] from the rows in order, plainly: the first ``cap``
    distinct keys in order of first appearance are kept (later ones dropped entirely)."""
    out: dict[int, list] = {}
    for key, delta, ub, ua in updates:
        for k, d, b, a in zip(key.tolist(), delta.tolist(), ub.tolist(), ua.tolist()):
            if k not in out:
                if len(out) >= cap:
                    continue
                out[k] = [d, b < 0, a]
                continue
            rec = out[k]
            rec[0] += d
            rec[1] = rec[1] and b == rec[2]  # each hit found the update index the previous one left
            rec[2] = a
    return out


def _updates(seed: int, n: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """``n`` updates of an object whose cells drift: keys from a window that moves, each key once per update;
    update indices chain for most cells and break for some (another beam touched the cell in between)."""
    rng = np.random.default_rng(seed)
    last: dict[int, int] = {}
    ups = []
    for u in range(n):
        lo = u // 3
        key = np.unique(rng.integers(lo, lo + 40, rng.integers(1, 35))).astype(np.int64)
        ub = np.array([last.get(k, -1) if rng.random() > 0.1 else 10_000 + u for k in key.tolist()], dtype=np.int64)
        ua = np.full(key.shape[0], u, dtype=np.int64)
        for k in key.tolist():
            last[k] = u
        ups.append((key, rng.normal(0.4, 0.2, key.shape[0]), ub, ua))
    return ups


@pytest.mark.parametrize("cap, fold_every", [(10_000, 0), (10_000, 7), (25, 0), (25, 5)])
def test_pending_buffers_fold_to_the_rows_record(cap: int, fold_every: int) -> None:
    ups = _updates(3, 60)
    rec = _LevelRecord(cap)
    for i, (key, delta, ub, ua) in enumerate(ups):
        # the caller's arrays are overwritten after each push: the record must have copied the rows
        k2, d2, b2, a2 = key.copy(), delta.copy(), ub.copy(), ua.copy()
        if rec.push(k2, d2, b2, a2):
            rec.compact()
        for arr in (k2, b2, a2):
            arr[:] = -7
        d2[:] = np.nan
        if fold_every and i % fold_every == fold_every - 1:
            rec.compact()
    n_pending = len(rec) - rec.key.shape[0]
    rec.compact()
    got = rec.cells
    ref = _reference(ups, cap)
    assert n_pending >= 0 and len(rec) == len(ref)
    if cap == 10_000 and not fold_every:
        # the rows outgrew the smallest buffer several times before the chunk count folded them
        assert sum(u[0].shape[0] for u in ups) > 4 * er._PENDING_MIN
    if cap < 10_000 and not fold_every:
        assert len(got) == cap
    assert set(got) == {(0, k) for k in ref}  # keys < 2^31 decode to cell (0, key)
    for k, (d, pure, last) in ref.items():
        gd, gp, gl = got[(0, k)]
        assert gd == pytest.approx(d, rel=1e-12, abs=1e-12)
        assert (gp, gl) == (pure, last)
    assert any(v[1] for v in ref.values()) and not all(v[1] for v in ref.values())


def test_push_asks_for_a_fold_at_the_row_and_chunk_limits(monkeypatch) -> None:
    monkeypatch.setattr(er, "_COMPACT_ROWS", 50)
    monkeypatch.setattr(er, "_COMPACT_CHUNKS", 4)
    rec = _LevelRecord(1000)
    one = (np.arange(3, dtype=np.int64), np.ones(3), np.full(3, -1), np.zeros(3, dtype=np.int64))
    assert [rec.push(*one) for _ in range(4)] == [False, False, False, True]  # 4 chunks
    assert rec.compact() == 3 and len(rec) == 3
    big = (np.arange(60, dtype=np.int64), np.ones(60), np.full(60, -1), np.zeros(60, dtype=np.int64))
    assert rec.push(*big)  # 60 rows >= 50
    assert len(rec) == 63 and rec.compact() == 57
    assert rec._pd.shape[0] == 0  # a folded record lets its buffers go
