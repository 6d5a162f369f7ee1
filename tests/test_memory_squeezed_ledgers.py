"""Pass mem41 (issue 13 item 3): an ended track's ledger rows squeezed (slam/erasure.py ``_squeeze_rows``).

A packed ledger (``_Ledger.pack``: its track ended, its rows kept ``ledger_keep_s`` for linking) stores its (5, n)
int64 rows — cell key, update index before, after, the added log-odds' float64 bits, level — as one uint8 array:
each integer part minus its smallest value in the narrowest unsigned dtype, the log-odds as float32 when their
float64 bits come back from it. Reading them back must give every row's exact values (the fold's sums and the
erasure read them), and the squeezed array must be the size that encoding gives (array bytes, not RSS)."""

from __future__ import annotations

import numpy as np

from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import _Ledger, _squeeze_rows, _unsqueeze_rows


def _rows(rng: np.random.Generator, n: int, cell_span: int, upd_span: int, exact: bool) -> np.ndarray:
    """(5, n) ledger rows: cells within ``cell_span`` of a random cell, update indices within ``upd_span`` (−1
    among them), log-odds float32 differences (``exact``: representable in float32) or arbitrary float64."""
    i = int(rng.integers(-5000, 5000)) + rng.integers(0, cell_span, n)
    j = int(rng.integers(-5000, 5000)) + rng.integers(0, cell_span, n)
    ub = rng.integers(-1, upd_span, n)
    ua = ub + rng.integers(0, 3, n)
    if exact:  # (what the map's float32 log-odds give: one occupied or free update, capped, −0.0 among them)
        d = rng.choice(np.array([0.85, -0.4, 0.45, -0.0, 0.0, 2.5], dtype=np.float32), n).astype(np.float64)
    else:  # (after − before of float32 values that float32 cannot hold)
        a = rng.normal(0, 3, n).astype(np.float32).astype(np.float64)
        b = (rng.normal(0, 1e-6, n)).astype(np.float32).astype(np.float64)
        d = a - b
    return np.stack((i * er._KEY_SHIFT + j, ub, ua, d.view(np.int64), rng.integers(0, 3, n)))


def test_squeezed_rows_read_back_exactly() -> None:
    """Random rows of every kind read back bit for bit: narrow and wide cell spans (up to beyond 32 bits), update
    indices, float32-exact and inexact log-odds (−0.0 kept), keys beyond the documented range (stored whole)."""
    rng = np.random.default_rng(41)
    for t in range(400):
        n = int(rng.integers(1, 400))
        cat = _rows(rng, n, [1, 200, 70000, 1 << 20][t % 4], [3, 300, 70000, 1 << 30][t % 4], bool(t % 3))
        if t % 5 == 0:
            cat[4] += 1 << 40  # (a part that needs 64 bits)
        if t % 7 == 0:
            cat[0, 0] = np.iinfo(np.int64).max - int(rng.integers(0, 1 << 20))  # (no (i, j) gives it back)
        cat[3, 0] = np.float64(-0.0).view(np.int64) if t % 2 else cat[3, 0]
        buf = _squeeze_rows(cat)
        assert buf.dtype == np.uint8 and buf.ndim == 1
        back = _unsqueeze_rows(buf)
        assert back.dtype == np.int64 and back.shape == cat.shape
        assert np.array_equal(back, cat), t


def test_squeezed_rows_take_the_bytes_of_their_narrow_parts() -> None:
    """A track's rows as a run has them (cells within 300, update indices within 65536, float32 log-odds, three
    levels) take 5 · 2 + 4 = 14 bytes a row and a 64-byte header; each log-odds float32 does not hold 16 more
    (its column and bits); every part within 256 one byte each; a part beyond 32 bits keeps the plain rows."""
    rng = np.random.default_rng(7)
    n = 5000
    head = 8 * er._SQ_HEAD
    cat = _rows(rng, n, 300, 60000, True)
    assert _squeeze_rows(cat).nbytes == 14 * n + head
    inexact = _rows(rng, n, 300, 60000, False)
    cat[3, 100:150] = inexact[3, 100:150]
    assert _squeeze_rows(cat).nbytes == 14 * n + 16 * 50 + head
    cat = _rows(rng, n, 200, 200, True)
    assert _squeeze_rows(cat).nbytes == 9 * n + head
    cat[1, 0] = 1 << 33
    assert _squeeze_rows(cat).shape == (5, n)


def test_a_packed_ledger_holds_its_rows_squeezed_and_settles_to_them() -> None:
    """``_Ledger.pack`` keeps one squeezed entry (14 bytes a row here, not 40) and settles to the same pending
    rows as the ledger that was not packed."""
    rng = np.random.default_rng(3)
    a = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, 100000)
    b = _Ledger(4, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, 100000)
    n_rows = 0
    for _ in range(9):
        rows = _rows(rng, 600, 200, 6000, True)
        rows = rows[:, np.argsort(rows[4], kind="stable")]  # (a block's rows in level order)
        for x in (a, b):
            x.ent.append((rows, 100, 500, 7))
            x.nb_rows += 400
            x.nb_chunks += 1
        n_rows += 400
    a.pack()
    (buf, lo, hi, chunks), = a.ent
    assert (lo, hi) == (0, n_rows) and buf.dtype == np.uint8
    assert buf.nbytes == 14 * n_rows + 8 * er._SQ_HEAD  # (the plain rows: 40 bytes each)
    assert np.array_equal(_unsqueeze_rows(buf), np.concatenate([r[:, i:j] for r, i, j, _ in b.ent], axis=1))
    for ra, rb in zip(a.levels, b.levels):
        assert ra._n_rows == rb._n_rows and ra._n_chunks == rb._n_chunks
        assert np.array_equal(ra._pk, rb._pk)
        assert ra.compact() == rb.compact()
        assert np.array_equal(ra.key, rb.key) and np.array_equal(ra.delta.view(np.int64), rb.delta.view(np.int64))


def test_ledgers_packed_together_read_back_their_own_rows() -> None:
    """``_pack_all`` (the ended ledgers of a batch) squeezes every ledger's entries into one array, each ledger's
    entry its range of columns: each settles to the rows of its own entries, whatever the others hold (a ledger
    packed before among them, inexact log-odds); with a part beyond 32 bits every ledger keeps its plain rows."""
    rng = np.random.default_rng(5)
    for t in range(30):
        leds, refs = [], []
        for k in range(int(rng.integers(1, 17))):
            led = _Ledger(k, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, 100000)
            blocks = []
            for _ in range(int(rng.integers(1, 5))):
                n = int(rng.integers(1, 200))
                c = _rows(rng, n, [1, 200, 70000][k % 3], [3, 300, 70000][(k + t) % 3], bool((k + t) % 4))
                led.ent.append((c, 0, n, 7))
                blocks.append(c)
            if k == 1:
                led.pack()  # (a packed entry, then more update entries)
                c = _rows(rng, 30, 50, 50, True)
                led.ent.append((c, 0, 30, 7))
                blocks.append(c)
            leds.append(led)
            refs.append(np.concatenate(blocks, axis=1))
        if t % 10 == 9:
            refs[0][2, 0] = leds[0].ent[0][0][2, 0] = 1 << 40
        er._pack_all(leds)
        bufs = {id(led.ent[0][0]) for led in leds}
        for led, ref in zip(leds, refs):
            (buf, a, b, _), = led.ent
            assert b - a == ref.shape[1] and np.array_equal(led._rows()[0], ref)
            assert (buf.ndim == 2) == (t % 10 == 9)
        assert len(bufs) == (len(leds) if t % 10 == 9 else 1)
