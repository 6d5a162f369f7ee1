"""Pass mem63 (issue 13 item 3): the ended ledgers' squeezed rows kept deflated (slam/erasure.py ``_Zipped``).

The pipeline packs the ledgers of tracks that ended in batches (``EvidenceLedger._finish_ended``): their rows,
squeezed (``_squeeze_cols``, pass mem41), are kept zlib-deflated until a ledger is linked or dropped and its rows
read (``_unsqueeze_rows`` inflates them). Reading must give every row's exact int64 values — the key, the update
indices, the level and the added log-odds' float64 bits — at the extremes each part may take, from any range of
columns, with several deflated buffers read in turn (the last one inflated is kept). Pass neg70: the batches stay
plain until the plain rows the ended ledgers hold pass ``_DEFLATE_FROM``, then they and every later batch are
deflated (oldest first)."""

from __future__ import annotations

import mmap

import numpy as np

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import EvidenceLedger, _Ledger, _squeeze_cols, _unsqueeze_rows, _Zipped

I64 = np.iinfo(np.int64)


def _extreme_rows(rng: np.random.Generator, n: int, top: bool) -> np.ndarray:
    """(5, n) rows whose every part spans as far as the squeezed form allows (just under 2^32): keys at int64's
    top or bottom, update indices from −1 and from int64's top, the level's too, and log-odds bits that float32
    cannot hold (NaN payloads, infinities, −0.0, the smallest subnormal, float64's largest, float32's overflow)."""
    span = (1 << 32) - 1
    base = I64.max - span if top else I64.min
    rows = np.empty((5, n), dtype=np.int64)
    # (the key's halves: key + 2^31 is stored as its high and low 32 bits, each part within its own span)
    rows[0] = base + rng.integers(0, span, n, endpoint=True)
    rows[0, 0], rows[0, -1] = base, base + span
    lo = -1 if not top else I64.max - span
    rows[1] = lo + rng.integers(0, span, n, endpoint=True)
    rows[1, 0], rows[1, -1] = lo, lo + span
    rows[2] = rows[1]
    rows[2, 1:-1] += rng.integers(0, 2, n - 2) * (rows[2, 1:-1] < lo + span)
    rows[4] = rng.integers(0, span, n, endpoint=True) + (I64.max - span if top else 0)
    special = np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308, 3.5e38, 0.85, -0.4],
                       dtype=np.float64).view(np.int64)
    bits = rng.choice(special, n)
    bits[::7] = rng.integers(I64.min, I64.max, bits[::7].shape[0], endpoint=True)  # (any bits, NaNs with payloads)
    bits[0] = np.int64(0x7FF0_0000_DEAD_BEEF)  # (a signalling NaN's payload)
    rows[3] = bits
    return rows


def test_deflated_rows_read_back_exactly_at_the_extremes() -> None:
    """Squeezed then deflated, rows at every part's extremes read back bit for bit, whole and by ranges (empty,
    one column, the last), with several deflated buffers read in turn."""
    rng = np.random.default_rng(63)
    cats = [_extreme_rows(rng, n, top) for n, top in ((3000, True), (2500, False), (2, True))]
    zs = []
    for cat in cats:
        buf = _squeeze_cols([cat])
        assert buf is not None and buf.ndim == 1  # (4 bytes a part: the squeezed form, not the plain rows)
        zs.append(_Zipped(buf))
        assert np.array_equal(np.frombuffer(zlib_inflate(zs[-1]), np.uint8), buf)
    for _ in range(3):  # (in turn: the kept inflated buffer must be the one asked for)
        for cat, z in zip(cats, zs):
            n = cat.shape[1]
            for a, b in ((0, None), (0, 0), (n - 1, n), (n // 3, n - n // 4), (1, 2)):
                back = _unsqueeze_rows(z, a, b)
                assert back.dtype == np.int64 and np.array_equal(back, cat[:, a:b])


def zlib_inflate(z: _Zipped) -> bytes:
    """The deflated bytes inflated with zlib alone (what ``_Zipped.inflate`` must give)."""
    import zlib

    return zlib.decompress(z.data)


def _ledgers(rng: np.random.Generator, id0: int = 0) -> tuple[list[_Ledger], list[_Ledger], list[np.ndarray]]:
    """Two copies of a batch of ledgers (ids ``id0`` on) with random entries of rows at the extremes (three
    levels), and their rows."""
    leds, twins, refs = [], [], []
    for k in range(id0, id0 + 12):
        led = _Ledger(k, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, 100000)
        twin = _Ledger(k, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0, None, 3, 100000)
        blocks = []
        for _ in range(int(rng.integers(1, 5))):
            n = int(rng.integers(2, 300))
            c = _extreme_rows(rng, n, True)  # (all near int64's top: the batch's parts span < 2^32)
            c[4] = rng.integers(0, 3, n)  # (the ledger's levels)
            for x in (led, twin):
                x.ent.append((c, 0, n, 7))
                x.nb_rows += n
                x.nb_chunks += 1
            blocks.append(c)
        leds.append(led)
        twins.append(twin)
        refs.append(np.concatenate(blocks, axis=1))
    return leds, twins, refs


def test_the_pipeline_batches_are_deflated_and_read_as_the_plain_ones(monkeypatch) -> None:  # noqa: ANN001
    """``EvidenceLedger._finish_ended`` keeps a batch's squeezed rows deflated (past its threshold), one buffer for
    the batch: each ledger reads its own rows, counts the new cells and settles to the records of its twin packed
    squeezed alone."""
    monkeypatch.setattr(er, "_DEFLATE_FROM", 0)
    rng = np.random.default_rng(11)
    leds, twins, refs = _ledgers(rng)
    el = EvidenceLedger(MemoryConfig(), 0.1, 30.0)
    el._ended.update((led.id, led) for led in leds)
    el._to_pack = list(leds)
    el._finish_ended()
    er._pack_all(twins)
    assert len({id(led.ent[0][0]) for led in leds}) == 1
    for led, twin, ref in zip(leds, twins, refs):
        (z, a, b, _), = led.ent
        assert type(z) is _Zipped and b - a == ref.shape[1]
        assert np.array_equal(led._rows()[0], ref)
        assert led.new_cells() == twin.new_cells()
        led.settle()
        twin.settle()
        for ra, rb in zip(led.recs, twin.recs):
            assert ra._n_rows == rb._n_rows and ra._n_chunks == rb._n_chunks
            assert np.array_equal(ra._pk, rb._pk)


def test_ended_rows_stay_plain_until_the_held_ones_pass_the_threshold_then_oldest_first(monkeypatch) -> None:  # noqa: ANN001
    """Pass neg70: the batches stay plain while the plain rows the ended ledgers still hold stay within
    ``_DEFLATE_FROM`` (a batch no ledger holds any more does not count); past it, every new batch is deflated and
    the plain ones kept before, oldest first, at least ``_DEFLATE_STEP`` bytes a batch; a plain batch lives in a
    memory map of its own; every ledger reads its rows the same throughout."""
    rng = np.random.default_rng(5)
    el = EvidenceLedger(MemoryConfig(), 0.1, 30.0)
    monkeypatch.setattr(er, "_DEFLATE_STEP", 1)
    batches = []

    made = [_ledgers(rng, 100 * k) for k in range(6)]
    nb = [_squeeze_cols(refs).nbytes for _, _, refs in made]

    def pack(k: int) -> None:
        leds, _, refs = made[k]
        batches.append((leds, refs))
        el._ended.update((led.id, led) for led in leds)
        el._to_pack = list(leds)
        el._finish_ended()

    def kinds() -> list[str]:
        out = []
        for leds, refs in batches:
            held = [led for led in leds if el._ended.get(led.id) is led]
            if not held:
                out.append("gone")
                continue
            assert len({id(led.ent[0][0]) for led in held}) == 1
            for led, ref in zip(leds, refs):
                if led in held:
                    assert np.array_equal(led._rows()[0], ref)
            buf = held[0].ent[0][0]
            if type(buf) is not _Zipped:  # (kept plain in a memory map of its own: unmapped when it goes)
                while isinstance(buf, np.ndarray):
                    buf = buf.base
                assert isinstance(buf.obj if isinstance(buf, memoryview) else buf, mmap.mmap)
            out.append("zip" if type(held[0].ent[0][0]) is _Zipped else "plain")
        return out

    monkeypatch.setattr(er, "_DEFLATE_FROM", 1 << 40)
    pack(0)
    pack(1)
    assert kinds() == ["plain", "plain"] and not el._deflating
    for led in batches[0][0]:  # (batch 0 dropped: its bytes no longer count)
        del el._ended[led.id]
    monkeypatch.setattr(er, "_DEFLATE_FROM", nb[1] + nb[2])
    pack(2)
    assert kinds() == ["gone", "plain", "plain"] and not el._deflating
    pack(3)  # (batches 1–3 pass it: batch 3 packed plain, the oldest held one deflated)
    assert el._deflating and kinds() == ["gone", "zip", "plain", "plain"]
    pack(4)
    assert kinds() == ["gone", "zip", "zip", "plain", "zip"]
    pack(5)
    assert kinds() == ["gone", "zip", "zip", "zip", "zip", "zip"] and not el._plain
