"""Retroactive erasure: take out of the online map what a track wrote while it stood still.

A parked car, a box standing in a corridor, a person waiting: while an object is not in
the dynamic set M its points are mapped like structure. When it starts to move and
enters M, :class:`EvidenceLedger` removes the evidence those points added (docs/maps.md,
"Retroactive erasure").

Bookkeeping, per track and map level, at every map update (the pipeline calls
:meth:`EvidenceLedger.before_update` and :meth:`EvidenceLedger.after_update` around
:meth:`HectorSlam.update_map`):

* the hit cells of the track's kept beams in that scan, **only** where no other kept
  beam of the same scan hit the same cell (a cell shared with a wall is the wall's);
* the log-odds the scan added there (after − before; a hit cell gets exactly one
  occupied update per scan, hector_mapping's ``OccGridMapBase::updateByScan``, so the
  change of that cell in that scan is the hit's evidence, including the cap);
* whether the cell was unknown before the track's first hit and nothing but the track's
  hits touched it since (then erasure returns it to *unknown*).

Erasure (:meth:`EvidenceLedger.erase_entering`) subtracts the recorded log-odds from each
recorded cell where they make up at least ``erase_min_share`` of the cell's log-odds (a wall
cell that many scans hit keeps the few hits a false track added) — a cell that was free before the object stood there
is free again, one that only the object made known is unknown again — and refreshes the probability cache
of those cells. No other cell of any level changes. A track's evidence is erased when it
is in the pipeline's removal set, *stood* before it entered it (slower than ``stand_speed``
at one place for ``link_min_stand``: what a walker wrote in the second before it joined M
is left to the clean-up pass) and has moved ``erase_min_travel`` from where it entered it
(a false track that is in M for a moment without going anywhere erases nothing); evidence
of a track that ended while the object stood (the robot drove away) is kept for
``ledger_keep_s`` (only if the track was confirmed: tentative clutter is dropped) and erased
with a track that stood where the ended track last was and then enters M.

Recording is vectorised over all tracks and levels: one sort per update, rows copied into each record's
buffers and folded per cell when they pile up (:class:`_LevelRecord`; no per-update objects are kept).
With ``keep_beams`` (loop closure on) the ledger also keeps each track's (scan index, beams) and lists
those of erased tracks in :attr:`EvidenceLedger.erased_beams`, for the loop closer to mark them removed
in its keyframes so that a map re-rendered from the optimised poses leaves them out too (docs/maps.md).

Frames and units: cells are absolute level indices (cell (i, j) centred at
(i·r_k, j·r_k) in the map frame, :mod:`dynslam2d.slam.grid`), stable when a level grows;
distances in m, stamps in s, log-odds dimensionless.
"""

from __future__ import annotations

import itertools
import math
import zlib
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.detect.trackreport import TrackReports
from dynslam2d.slam.grid import MultiResMap, _zeroed, encode_probs
from dynslam2d.types import Pose2D, Scan, Track

#: (i, j) cell → one int64 key: i·2^32 + j (|i|, |j| < 2^31)
_KEY_SHIFT = 4294967296
_HALF = 2147483648
#: cell keys strictly inside ±2^60 can be shifted two bits (a level, ≤ 4 levels, in the low bits) without overflow
_KEY_LIMIT = 1 << 60
#: A level record folds its appended update rows into one row per cell once it holds this many.
_COMPACT_ROWS = 4096
#: … or this many updates (each update's rows are four small arrays).
_COMPACT_CHUNKS = 64
#: Smallest capacity of a record's pending buffers, rows (most records of clutter tracks hold a few rows).
_PENDING_MIN = 16
#: A record's row references to updates' shared row blocks are copied into its buffer when this many updates old.
_REF_MAX_AGE = 64
#: :meth:`EvidenceLedger._rebase`: an id pinned below the standing boxes' window must save this many rows of it
#: (a pinned layout maps the reports' ids one by one: ≈ 2 µs a scan while a long-lived id is pinned)
_PIN_COST = 64
#: … and lays them out with this many rows more than twice what the live ids need (room for the next ids: a layout
#: costs ≈ 0.1 ms in the pipeline, so one every few hundred new ids)
_ROWS_ROOM = 512
#: … but while every id fits below this many rows they are indexed by the id itself (no shift: a run's first ids —
#: MIT CSAIL's 2675, negative_2's 1033 — cost no per-scan subtraction, ≈ 4 µs in the pipeline), 786 kB at most
_ROWS_FLAT = 1 << 14
#: Ledgers that ended (confirmed: to pack) or were dropped (to count) wait for this many, then are done in one go.
_END_BATCH = 16
#: The ended ledgers' squeezed rows are kept plain until those kept plain pass this many bytes; from then on the
#: ledger deflates every batch (:class:`_Zipped`) and the plain ones kept before it, oldest first, this many bytes
#: more a batch (issue 13 items 1 and 3, pass neg70): deflating cost the map update's mean ×1.03–1.07 on runs whose
#: ended rows stay small (negative_2: ≤ 1.5 MiB, sim:paper 0.4 MiB over the whole run), while MIT CSAIL passes
#: 2 MiB near scan 920 and its ended rows are deflated again by scan ≈ 1080, before its loop's peaks (1285, 1913)
_DEFLATE_FROM = 2 << 20
_DEFLATE_STEP = 256 << 10
#: kept-beam sweep: every this many map updates with kept beams, each live ledger whose kept beams (``_Ledger.kb``)
#: go back before the previous sweep copies its own parts out of the updates' whole kept-beam arrays
#: (:meth:`EvidenceLedger._sweep_beams`, issue 13 item 3): a live ledger then holds at most the last ``2 ·`` this
#: many updates' whole arrays, whatever the track's life; 0 = never (pass led34's layout, the tests' reference)
_KB_SWEEP = 64
_EMPTY_I = np.zeros(0, dtype=np.int64)
_EMPTY_F = np.zeros(0)
_EMPTY_B = np.zeros(0, dtype=bool)
_EMPTY_I4 = np.zeros((4, 0), dtype=np.int64)
_EMPTY_I5 = np.zeros((5, 0), dtype=np.int64)
for _a in (_EMPTY_I, _EMPTY_F, _EMPTY_B, _EMPTY_I4, _EMPTY_I5):
    _a.flags.writeable = False
#: levels the fused kernels read in one call (slam/ledgerkernels.py's FUSED_LEVELS) and their empty padding
_FUSED = 3
_NO_F32 = np.zeros((0, 0), dtype=np.float32)
_NO_I32 = np.zeros((0, 0), dtype=np.int32)
#: empty inputs of ``stand_marks`` (writable: its signature's arrays are; it only reads them)
_NO_X = np.zeros((0, 4))
_NO_B = np.zeros((0, 5))  # (no boxes; no E rows: centre, velocity and half size)
_NO_IDS = np.zeros(0, dtype=np.int64)


#: slam/ledgerkernels.py once imported (at first use, :func:`_kernels`): its explicit signatures compile (or load from
#: numba's cache) on import, which would put ~0.4 s and scipy.linalg on every `import dynslam2d.pipeline` (issue 13's
#: warm start); a ``from … import`` in the per-update methods cost ≈ 3 µs warm, 8–13 µs in the pipeline, per call
_lk = None


def _kernels():
    """The module slam/ledgerkernels.py (imported at the first call)."""
    global _lk
    if _lk is None:
        from dynslam2d.slam import ledgerkernels
        _lk = ledgerkernels
    return _lk


def _decode(keys: np.ndarray) -> np.ndarray:
    """(n,) cell keys → (n, 2) int64 absolute cells (i, j)."""
    j = (keys + _HALF) % _KEY_SHIFT - _HALF
    return np.column_stack(((keys - j) // _KEY_SHIFT, j))


#: :func:`_squeeze_cols`' header, int64: columns N, the integer parts' item size, the inexact log-odds' count M,
#: then the smallest value of each integer part (the key's high and low half, update index before, after, level)
_SQ_HEAD = 8
#: the integer parts' dtypes by item size (their values minus the part's smallest one)
_SQ_INT = {1: np.dtype(np.uint8), 2: np.dtype(np.uint16), 4: np.dtype(np.uint32)}


def _squeeze_cols(blocks: list[np.ndarray], mapped: bool = False) -> np.ndarray | None:
    """Ledger rows — (5, n) int64 blocks: cell key, update index before, after, added log-odds' float64 bits,
    level — side by side as one uint8 array of about 14 bytes a column instead of 40 (issue 13 item 3: MIT CSAIL's
    ended ledgers, kept ``ledger_keep_s`` for linking, held ≈ 14 MB of such rows at the loop's end); None when an
    integer part spans 2^32 or more (then the caller keeps the rows as they are). :func:`_unsqueeze_rows` gives any
    range of the columns back exactly.

    The five integer parts — the key as two halves (``key + 2^31``'s high and low 32 bits: the cell's i and
    j + 2^31; any int64 key comes back), the update indices and the level — are stored minus each part's smallest
    value, in the narrowest unsigned dtype that holds every part's span; the added log-odds as float32, with the
    columns and float64 bits of those float32 does not hold exactly listed apart (≈ 6 % of MIT CSAIL's rows).
    Layout: int64 header (``_SQ_HEAD``), M inexact columns, their M bits, N float32, (5, N) integers. ``mapped``: the
    array in an anonymous memory map of its own (``grid._zeroed``), returned to the system when it goes (pass neg70:
    the batches kept plain, then deflated, left their blocks as holes in the heap, ≈ 0.8 MiB on MIT CSAIL)."""
    cat = blocks[0] if len(blocks) == 1 else np.concatenate(blocks, axis=1)
    n = cat.shape[1]
    t = cat[0] + _HALF  # (wraps around for keys within 2^31 of int64's top: so does the way back)
    low = t & (_KEY_SHIFT - 1)
    t >>= 32
    parts = (t, low, cat[1], cat[2], cat[4])
    lo = [int(x.min()) for x in parts]
    span = max(int(x.max()) - m for x, m in zip(parts, lo))  # (Python ints: no overflow)
    if span >= 1 << 32:
        return None
    size = 1 if span < 1 << 8 else 2 if span < 1 << 16 else 4
    d64 = cat[3].view(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # (values float32 cannot hold are listed apart below)
        d32 = d64.astype(np.float32)
    bad = np.flatnonzero(d32 != d64)  # (equal values are equal bits: the cast keeps a zero's sign; NaN is unequal)
    m = bad.shape[0]
    h = 8 * (_SQ_HEAD + 2 * m)
    nb = h + 4 * n + 5 * size * n
    buf = _zeroed((1, nb), np.uint8).reshape(nb) if mapped else np.empty(nb, dtype=np.uint8)
    head = buf[:h].view(np.int64)
    head[:_SQ_HEAD] = (n, size, m, *lo)
    if m:
        head[_SQ_HEAD:_SQ_HEAD + m] = bad
        head[_SQ_HEAD + m:] = cat[3, bad]
    buf[h:h + 4 * n].view(np.float32)[:] = d32
    ints = buf[h + 4 * n:].view(_SQ_INT[size]).reshape(5, n)
    for r, (x, m0) in enumerate(zip(parts, lo)):
        np.subtract(x, m0, out=ints[r], casting="unsafe")  # (0 … span: the cast keeps it)
    return buf


def _squeeze_rows(cat: np.ndarray) -> np.ndarray:
    """One block of rows as :func:`_squeeze_cols` stores it, or a copy of it when it cannot."""
    buf = _squeeze_cols([cat]) if cat.shape[1] else None
    return cat.copy() if buf is None else buf


class _Zipped:
    """A :func:`_squeeze_cols` buffer deflated (zlib, level 1; issue 13 item 3, pass mem63): MIT CSAIL's ended
    ledgers, kept ``ledger_keep_s`` for linking, held 3.3 MiB of squeezed rows at the scan loop's peak (scan 1285)
    and 5.4 MiB near its end, about a fifth of that deflated. Read (only when a ledger is linked or dropped) through
    :func:`_unsqueeze_rows`, which inflates it: the same bytes, so the same rows. ``ndim`` is 1 as the squeezed
    buffer's (the entries' readers tell a squeezed buffer from plain rows by it)."""

    __slots__ = ("data", "nbytes")
    ndim = 1

    def __init__(self, buf: np.ndarray) -> None:
        self.data = zlib.compress(buf, 1)  # (level 1: ≈ 5× smaller on MIT CSAIL's rows; 6 is 20 % smaller, 3× slower)
        self.nbytes = buf.nbytes  # (the squeezed buffer's, inflated)

    def inflate(self) -> np.ndarray:
        """The squeezed buffer (read-only uint8): the last one inflated is kept, the ledgers of a batch being
        read one after another (they ended together and expire together)."""
        global _INFLATED
        if _INFLATED[0] is not self:
            _INFLATED = (self, np.frombuffer(zlib.decompress(self.data, bufsize=self.nbytes), dtype=np.uint8))
        return _INFLATED[1]


#: the :class:`_Zipped` buffer inflated last and its bytes (≤ one packed batch's squeezed rows, ≈ 0.1 MB)
_INFLATED: tuple[_Zipped | None, np.ndarray] = (None, np.zeros(0, dtype=np.uint8))


def _unsqueeze_rows(buf: np.ndarray | _Zipped, a: int = 0, b: int | None = None) -> np.ndarray:
    """Columns ``a:b`` (all when ``b`` is None) of the (5, N) int64 rows :func:`_squeeze_cols` stored in ``buf``
    (a new array; ``buf`` may also be the rows themselves, kept as they are, or the squeezed buffer deflated)."""
    if buf.ndim == 2:
        return buf[:, a:b].copy()
    if type(buf) is _Zipped:
        buf = buf.inflate()
    n_all, size, m, l0, l1, l2, l3, l4 = buf[:8 * _SQ_HEAD].view(np.int64).tolist()
    if b is None:
        b = n_all
    h = 8 * (_SQ_HEAD + 2 * m)
    ints = buf[h + 4 * n_all:h + (4 + 5 * size) * n_all].view(_SQ_INT[size]).reshape(5, n_all)[:, a:b]
    out = np.empty((5, b - a), dtype=np.int64)
    k = out[0]
    k[:] = ints[0]
    k += l0  # (the key's high half, then the key: high · 2^32 + low − 2^31, wrapping around as the way there)
    k <<= 32
    k += ints[1]
    k += l1 - _HALF
    out[1:3] = ints[2:4]
    out[1] += l2
    out[2] += l3
    out[4] = ints[4]
    out[4] += l4
    np.copyto(out[3].view(np.float64), buf[h:h + 4 * n_all].view(np.float32)[a:b])
    if m:
        cols = buf[8 * _SQ_HEAD:8 * _SQ_HEAD + 8 * m].view(np.int64)
        i, j = np.searchsorted(cols, (a, b)).tolist()
        if j > i:
            out[3, cols[i:j] - a] = buf[8 * _SQ_HEAD + 8 * m:h].view(np.int64)[i:j]
    return out

def _member(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a),) bool: a[i] is in b (int64 keys; a sorted search, ~10× faster than np.isin at these sizes)."""
    if b.shape[0] == 0:
        return np.zeros(a.shape[0], dtype=bool)
    o = np.sort(b)
    i = np.searchsorted(o, a)
    i[i == o.shape[0]] = 0
    return o[i] == a


class _LevelRecord:
    """Evidence of one track on one map level.

    Rows are appended per map update (cell key, added log-odds, update index before, after) and folded into one
    row per cell (added log-odds summed; *pure*: the cell was unknown before the track's first hit there and each
    later hit found the update index the track's previous hit left, i.e. nothing but this track touched it since;
    the last update index) when they pile up and before they are read. At most ``cap`` cells are kept: rows of
    cells first seen after ``cap`` others are dropped.

    Pending rows live in two places, in order: the record's own (4, capacity) int64 buffer (key, update index
    before, update index after, the added log-odds' float64 bits; copied, so no view holds an update's arrays
    alive) and, after it, references ``(rows, a, b)`` to columns ``a:b`` of an update's shared (4, m) row block
    (:meth:`EvidenceLedger.after_update` records every track of a level with one reference each instead of one copy
    each). The references are copied into the buffer (:meth:`materialize`) before the rows are read, when the
    track ends, and when they are older than ``_REF_MAX_AGE`` updates (so a record keeps few update blocks alive)."""

    __slots__ = ("cap", "key", "delta", "pure", "last", "_pk", "_n_rows", "_n_chunks", "_refs", "_n_buf",
                 "_ref0")

    def __init__(self, cap: int) -> None:
        self.cap = cap
        # (empty records share read-only empty arrays: a record's arrays are replaced, never written)
        self.key = _EMPTY_I
        self.delta = _EMPTY_F
        self.pure = _EMPTY_B
        self.last = _EMPTY_I
        self._pk = _EMPTY_I4  # pending rows: key, update index before, update index after, added log-odds' bits
        self._n_rows = 0  # pending rows, in the buffer and referenced
        self._n_chunks = 0
        self._refs: list | None = None  # (rows, a, b) of pending rows after the buffer's, in order
        self._n_buf = 0  # pending rows in the buffer (the others are referenced by _refs)
        self._ref0 = 0  # the ledger's update number of the first reference

    @property
    def _pd(self) -> np.ndarray:
        """The pending buffer's added log-odds (float64 view of its last row)."""
        self.materialize()
        return self._pk[3].view(np.float64)

    def materialize(self) -> None:
        """Copy the referenced rows into the pending buffer, after its rows (one copy into a buffer of exactly the
        pending rows)."""
        refs = self._refs
        if refs is None:
            return
        n = self._n_buf
        parts = [rows[:, a:b] for rows, a, b in refs]
        if n:
            parts.insert(0, self._pk[:, :n])
        self._pk = np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0].copy()
        self._refs = None
        self._n_buf = self._n_rows

    def _room(self, m: int) -> np.ndarray:
        """The pending buffer, grown (doubling) to hold ``m`` rows; the buffers are let go when folded."""
        self.materialize()
        pk = self._pk
        if m > pk.shape[1]:
            grown = np.empty((4, max(_PENDING_MIN, 2 * m)), dtype=np.int64)
            grown[:, :self._n_rows] = pk[:, :self._n_rows]
            self._pk = pk = grown
        return pk

    def refer(self, rows: np.ndarray, a: int, b: int, update: int) -> bool:
        """Add columns ``a:b`` (a < b) of ``rows`` (a (4, n) int64 row block, as in :meth:`push_rows`, that is not
        written afterwards) by reference; ``update`` is the ledger's update number. True when the rows should now
        be folded (:meth:`compact`)."""
        refs = self._refs
        if refs is None:
            self._refs = [(rows, a, b)]
            self._ref0 = update
        else:
            refs.append((rows, a, b))
        m = self._n_rows + b - a
        self._n_rows = m
        c = self._n_chunks + 1
        self._n_chunks = c
        return m >= _COMPACT_ROWS or c >= _COMPACT_CHUNKS

    def push(self, key: np.ndarray, delta: np.ndarray, ub: np.ndarray, ua: np.ndarray) -> bool:
        """Copy the rows of one update (each key at most once, at least one row) into the pending buffer;
        True when they should now be folded (:meth:`compact`)."""
        self.materialize()
        n = self._n_rows
        m = n + key.shape[0]
        pk = self._room(m)
        pk[0, n:m] = key
        pk[1, n:m] = ub
        pk[2, n:m] = ua
        pk[3, n:m] = np.asarray(delta, dtype=np.float64).view(np.int64)
        self._n_rows = self._n_buf = m
        self._n_chunks += 1
        return m >= _COMPACT_ROWS or self._n_chunks >= _COMPACT_CHUNKS

    def push_rows(self, rows: np.ndarray, a: int, b: int) -> bool:
        """:meth:`push` of columns ``a:b`` of ``rows``, a (4, n) int64 array whose rows are the keys, the update
        indices before and after and the added log-odds' float64 bits (one copy instead of four)."""
        self.materialize()
        n = self._n_rows
        m = n + b - a
        pk = self._pk
        if m > pk.shape[1]:  # (_room, inlined: this runs for every track and level at every map update)
            pk = self._room(m)
        pk[:, n:m] = rows[:, a:b]
        self._n_rows = self._n_buf = m
        self._n_chunks += 1
        return m >= _COMPACT_ROWS or self._n_chunks >= _COMPACT_CHUNKS

    def append(self, key: np.ndarray, delta: np.ndarray, ub: np.ndarray, ua: np.ndarray) -> int:
        """Add the rows of one update (each key at most once); returns the number of new cells recorded
        when the rows were folded (else 0)."""
        if key.shape[0] == 0:
            return 0
        return self.compact() if self.push(key, delta, ub, ua) else 0

    def compact(self) -> int:
        """Fold the appended rows into the per-cell arrays; returns the number of new cells."""
        n = self._n_rows
        if not n:
            return 0
        self.materialize()
        nb = self.key.shape[0]
        pk = self._pk
        key = np.concatenate((self.key, pk[0, :n]))
        delta = np.concatenate((self.delta, pk[3, :n].view(np.float64)))
        ub = np.concatenate((self.last, pk[1, :n]))
        ua = np.concatenate((self.last, pk[2, :n]))
        start_pure = np.concatenate((self.pure, pk[1, :n] < 1))  # (update index 0: never updated)
        self._pk = _EMPTY_I4
        self._n_rows = self._n_buf = 0
        self._n_chunks = 0
        order = np.argsort(key, kind="stable")  # per cell: the folded row first, then the updates in order
        k = key[order]
        head = np.ones(k.shape[0], dtype=bool)
        head[1:] = k[1:] != k[:-1]
        starts = np.flatnonzero(head)
        ends = np.append(starts[1:], k.shape[0]) - 1
        ub_s, ua_s = ub[order], ua[order]
        chain = np.ones(k.shape[0], dtype=bool)
        chain[1:] = ub_s[1:] == ua_s[:-1]
        broken = np.add.reduceat((~chain & ~head).astype(np.int64), starts)
        new_key = k[starts]
        new_delta = np.add.reduceat(delta[order], starts)
        new_pure = start_pure[order][starts] & (broken == 0)
        new_last = ua_s[ends]
        first = order[starts]  # the row where each cell first appeared (the folded cells come first)
        if new_key.shape[0] > self.cap:
            rank = np.empty(first.shape[0], dtype=np.int64)
            rank[np.argsort(first, kind="stable")] = np.arange(first.shape[0])
            ok = rank < self.cap
            new_key, new_delta, new_pure, new_last = new_key[ok], new_delta[ok], new_pure[ok], new_last[ok]
        self.key, self.delta, self.pure, self.last = new_key, new_delta, new_pure, new_last
        return int(new_key.shape[0] - nb)

    def shrink(self) -> None:
        """Copy the pending rows into a buffer of their size (the record keeps its rows and what they fold to)."""
        self.materialize()
        n = self._n_rows
        if n < self._pk.shape[1]:
            self._pk = self._pk[:, :n].copy() if n else _EMPTY_I4

    def new_cells(self) -> int:
        """The number of new cells :meth:`compact` would return, without folding (for a record that is
        dropped: counting its distinct cells is much cheaper than folding them)."""
        if not self._n_rows:
            return 0
        if self._n_chunks == 1 and not self.key.shape[0]:  # one update's rows: each key once
            return min(self._n_rows, self.cap)
        keys = [self.key, self._pk[0, :self._n_buf]]
        if self._refs is not None:  # (the referenced rows' keys, without copying the rows first)
            keys += [rows[0, a:b] for rows, a, b in self._refs]
        k = np.concatenate(keys)  # (a new array: sorted in place; its distinct values counted as np.unique would)
        k.sort()
        n = int(np.count_nonzero(k[1:] != k[:-1])) + 1
        return min(n, self.cap) - int(self.key.shape[0])  # compact keeps the first ``cap`` cells

    @property
    def cells(self) -> dict[tuple[int, int], list]:
        """Absolute cell → [added log-odds, pure, last update index] (folds the pending rows first)."""
        self.compact()
        return {(int(i), int(j)): [float(d), bool(p), int(u)]
                for (i, j), d, p, u in zip(_decode(self.key).tolist(), self.delta, self.pure, self.last)}

    def __len__(self) -> int:
        return int(self.key.shape[0]) + self._n_rows

    def clear(self) -> None:
        self.__init__(self.cap)


@dataclass(eq=False, slots=True)
class _Ledger:
    """What one track's points wrote into the map while it was not removed.

    A map update records the track with one *entry* (:meth:`EvidenceLedger.after_update`): the update's shared row
    block, the track's column range in it (its rows of every level, level after level: the block is in (track,
    level) order, pass ledger14) and the levels it has rows on, instead of one reference per (track, level) record
    (pass ledger13: one append per track and update, on fewer cold objects). :meth:`settle` hands the entries'
    rows to the level records, in update order, before any record is read; ``nb_rows`` and ``nb_chunks`` bound
    every record's pending rows and updates from above (their largest exact counts at the last settle plus what
    the entries since could add), so the pipeline settles a ledger, and folds its records, at exactly the update
    where a record reaches ``_COMPACT_ROWS`` or ``_COMPACT_CHUNKS`` (the fold's per-cell sums are not associative
    in float64: folding at another update would change the erased log-odds' bits). The level records are made at
    the first settle (``recs`` is None before: a tentative track's ledger that is dropped never needs them)."""

    id: int
    first_box: tuple[float, float, float]  # centre x, y and half of the longer side where first seen, m
    first_t: float  # stamp when the track was first reported, s
    last_box: tuple[float, float, float]  # the same where last seen, m
    last_seen: float  # stamp, s
    #: per map level (read through :attr:`levels`, which makes them and settles the entries first), or None
    recs: list[_LevelRecord] | None = None
    n_levels: int = 3  # map levels (the records :attr:`levels` makes)
    cap: int = 0  # each record's most cells (MemoryConfig.max_ledger_cells)
    m_start: tuple[float, float] | None = None  # centre when first in the removal set, m
    linked: bool = False  # ended-track evidence already joined to a live track
    confirmed: bool = False  # the track was reported confirmed at least once (not only tentative clutter)
    skip: bool = False  # this stay in the removal set erases nothing (the track did not stand before it)
    #: scan index, the update's kept beams of all tracks, first, end of the track's kept beams at every recorded
    #: map update, four items per update one after the other (only with keep_beams; :attr:`beams` slices them; flat,
    #: not a tuple per update: pass led26, a kept tuple per track and update drove a fifth of the garbage
    #: collector's young-generation passes)
    kb: list = field(default_factory=list)
    #: the older kept beams, copied out of the updates' arrays (:meth:`EvidenceLedger._sweep_beams`): chunks of
    #: ((k, 3) int32 rows (scan index, first, end) into the chunk's beams, the int32 beams), in update order, before
    #: :attr:`kb`'s
    kbc: list | None = None
    #: the track as last seen out of the removal set (None once the track ended): its ``Track``, or its scan's
    #: ``TrackReports`` (its index there :attr:`last_at`) while that report was not built (``TrackReports.sight``,
    #: passes trk90, trk97: two slots, no tuple a ledger and scan). With ``last_seen``, written lazily since pass
    #: glu121: while the track is seen out of the removal set they are the last ``observe`` call's, written only when
    #: the track enters the set or ends (``EvidenceLedger._sync_sights`` writes them for a reader of a live ledger)
    last_track: Track | TrackReports | None = None
    last_at: int = -1  # (last_track's report index when last_track is a TrackReports)
    #: (update's (5, m) row block, first column, end column, levels with rows (bit k: level k)) per map update
    #: since the last :meth:`settle`
    ent: list = field(default_factory=list)
    ent0: int = 0  # the update number of the first entry
    nb_rows: int = 0  # ≥ every record's pending rows once the entries are settled
    nb_chunks: int = 0  # ≥ every record's pending updates once the entries are settled

    @property
    def levels(self) -> list[_LevelRecord]:
        """The level records, with every entry settled into them."""
        if self.ent or self.recs is None:
            self.settle()
        return self.recs

    def _rows(self) -> tuple[np.ndarray, list[int]]:
        """The entries' rows, one after the other ((5, n): the record rows and their level; a view when there is
        one entry of an update's block), and per level the number of updates with rows on it."""
        ent = self.ent
        if len(ent) == 1:
            rows, a, b, lv = ent[0]
            cat = rows[:, a:b] if rows.ndim == 2 else _unsqueeze_rows(rows, a, b)  # (packed: squeezed, _pack_all)
        else:
            cat = np.concatenate([rows[:, a:b] if rows.ndim == 2 else _unsqueeze_rows(rows, a, b)
                                  for rows, a, b, _ in ent], axis=1)
        return cat, self._chunks()

    def _chunks(self) -> list[int]:
        """Per level, the number of updates with rows on it in the entries."""
        lvs = [e[3] for e in self.ent]
        n_lv = self.n_levels
        if lvs.count((1 << n_lv) - 1) == len(lvs):  # (the usual case: rows on every level in every update)
            return [len(lvs)] * n_lv
        chunks = [0] * n_lv
        for x in lvs:
            if type(x) is int:  # (an update's levels as bits)
                for k in range(n_lv):
                    chunks[k] += x >> k & 1
            else:  # (a packed entry's updates per level, :meth:`pack`)
                for k in range(n_lv):
                    chunks[k] += x[k]
        return chunks

    def pack(self) -> None:
        """Copy the entries' rows out of the updates' shared row blocks into one array of exactly their rows (one
        entry, its per-level update counts with it), so that the ledger holds no update's block alive: for a
        ledger that gets no more rows (its track ended; issue 13 item 3), in one copy where :meth:`settle` would
        copy each level's rows apart — the levels are split when the records are read (pass ledger14)."""
        _pack_all([self])

    def settle(self) -> None:
        """Copy every entry's rows into their level records' pending buffers, after the rows they hold (one copy
        into a buffer of exactly the pending rows per level, as :meth:`_LevelRecord.materialize`; the caller
        folds), and make the bounds exact. Makes the records if there are none yet."""
        recs = self.recs
        if recs is None:
            recs = self.recs = [_LevelRecord(self.cap) for _ in range(self.n_levels)]
        if not self.ent:
            return
        cat, chunks = self._rows()
        self.ent = []
        lab = cat[4]
        for k, (rec, c) in enumerate(zip(recs, chunks)):
            if not c:
                continue
            # (a copy: the level's rows in update order, each update's in its order; compress, not
            # cat[:4, lab == k]: the same values in a third to half the time, C- not F-ordered; _pk meets no kernel)
            part = cat[:4].compress(lab == k, axis=1)
            rec.materialize()  # (references given by _LevelRecord.refer, if any, come first)
            n = rec._n_rows
            rec._pk = np.concatenate((rec._pk[:, :n], part), axis=1) if n else part
            rec._n_rows = rec._n_buf = n + part.shape[1]
            rec._n_chunks += c
        self.bound()

    def new_cells(self) -> int:
        """The new cells folding every record would count (:meth:`_LevelRecord.new_cells`), without settling the
        entries (for a ledger that is dropped: no copy of its rows, no records made)."""
        recs = self.recs
        ent = self.ent
        if not ent:
            return sum(rec.new_cells() for rec in recs) if recs is not None else 0
        if recs is None and len(ent) == 1 and type(ent[0][3]) is int and ent[0][2] - ent[0][1] <= self.cap:
            return ent[0][2] - ent[0][1]  # (one update's rows: each key once per level, none over the cap)
        cat, chunks = self._rows()
        lab = cat[4]
        if recs is None and self.n_levels <= 4:  # (the usual case: a tentative track's ledger of a few updates)
            keys = cat[0]
            if -_KEY_LIMIT <= int(keys.min()) and int(keys.max()) < _KEY_LIMIT:
                # the distinct (level, cell) pairs as one int64 each (key · 4 + level: no overflow below the limit)
                kl = (keys << 2) | lab
                kl.sort()
                n = int(np.count_nonzero(kl[1:] != kl[:-1])) + 1
                if n <= self.cap:  # (then no level's count reaches the cap either)
                    return n
        total = 0
        for k, c in enumerate(chunks):
            rec = recs[k] if recs is not None else None
            if not c:
                total += rec.new_cells() if rec is not None else 0
                continue
            mine = cat[0].compress(lab == k)
            cap = self.cap if rec is None else rec.cap
            if c == 1 and (rec is None or (not rec._n_rows and not rec.key.shape[0])):  # one update: each key once
                total += min(mine.shape[0], cap)
                continue
            keys = [mine]
            if rec is not None:
                keys += [rec.key, rec._pk[0, :rec._n_buf]]
                if rec._refs is not None:
                    keys += [rows[0, a:b] for rows, a, b in rec._refs]
            k_all = np.concatenate(keys)
            k_all.sort()
            n = int(np.count_nonzero(k_all[1:] != k_all[:-1])) + 1
            total += min(n, cap) - (int(rec.key.shape[0]) if rec is not None else 0)
        return total

    def bound(self) -> None:
        """Set the bounds to the records' exact largest counts (no entry pending)."""
        r = c = 0
        for rec in self.recs or ():
            r = max(r, rec._n_rows)
            c = max(c, rec._n_chunks)
        self.nb_rows, self.nb_chunks = r, c

    @property
    def beams(self) -> list[tuple[int, np.ndarray]]:
        """(scan index, beams) of the track's kept beams at every recorded map update (only with keep_beams)."""
        kb = self.kb
        out = [(kb[q], kb[q + 1][kb[q + 2]:kb[q + 3]]) for q in range(0, len(kb), 4)]
        if self.kbc is not None:
            old = [(i, cat[a:b]) for m, cat in self.kbc for i, a, b in m.tolist()]
            out = old + out
        return out

    @property
    def n_cells(self) -> int:
        return sum(len(lv) for lv in self.levels)


def _pack_all(leds: list[_Ledger], deflate: bool = False, mapped: bool = False) -> np.ndarray | _Zipped | None:
    """:meth:`_Ledger.pack` of every ledger of ``leds``: all their entries' rows squeezed side by side into one
    array (:func:`_squeeze_cols`; each ledger's entry: its range of columns), the common work done once over the
    batch (the ledgers that end are packed in batches, ``EvidenceLedger._finish_ended``; one at a time, ≈ 25 NumPy
    calls each, this cost the map update ≈ 20 µs a scan on MIT CSAIL). The array goes when the batch's last
    ledger does: they ended together and expire together, ``ledger_keep_s`` after their last sight. ``deflate``:
    the squeezed array kept deflated (:class:`_Zipped`); ``mapped``: kept plain in a memory map of its own
    (:func:`_squeeze_cols`). Returns the squeezed array kept (deflated or not), None
    when there is none (nothing packed, or the rows kept as they are)."""
    todo = []
    blocks = []
    n = 0
    for led in leds:
        ent = led.ent
        if not ent or (len(ent) == 1 and type(ent[0][3]) is not int):  # (nothing, or packed already)
            continue
        a = n
        for rows, i, j, _ in ent:
            blocks.append(rows[:, i:j] if rows.ndim == 2 else _unsqueeze_rows(rows, i, j))
            n += j - i
        todo.append((led, a, n, led._chunks()))
    if not todo:
        return None
    buf = _squeeze_cols(blocks, mapped and not deflate) if n else None
    if buf is None:  # (no rows, or beyond the squeezed form's range: the rows as they are, one array per ledger)
        cat = np.concatenate(blocks, axis=1) if blocks else _EMPTY_I5
        for led, a, b, chunks in todo:
            led.ent = [(cat[:, a:b].copy(), 0, b - a, chunks)]
    else:
        kept = _Zipped(buf) if deflate else buf
        for led, a, b, chunks in todo:
            led.ent = [(kept, a, b, chunks)]
    for led, _, _, _ in todo:
        for rec in led.recs or ():  # (records a previous settle made: their pending buffers are exact already)
            rec.shrink()
    return None if buf is None else kept

class PendingUpdate:
    """Cells and log-odds read before one map update (:meth:`EvidenceLedger.before_update`): per map level
    (track ids, cell keys, cells, log-odds before, update index before), sorted by track id, each (track,
    cell) once.

    Held either per level (:attr:`per_level`) or, from the fused kernels, as
    :func:`~dynslam2d.slam.ledgerkernels.record_cells` returned them (``fused``: the (6, m) block of all levels'
    cells — rows track id, key, i, j, update index before, log-odds before's float64 bits — and ``small``, whose
    first ``n_levels + 1`` values are the levels' column bounds); :attr:`per_level` then gives the levels' slices."""

    __slots__ = ("_per_level", "fused", "n_levels")

    def __init__(self, per_level: list | None = None, fused: tuple | None = None, n_levels: int = 0) -> None:
        self._per_level = per_level
        self.fused = fused
        self.n_levels = n_levels

    @property
    def per_level(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        if self._per_level is None:
            blk, small = self.fused
            bounds = small[:self.n_levels + 1].tolist()
            before = blk[5].view(np.float64)
            self._per_level = [(blk[0, a:b], blk[1, a:b], np.ascontiguousarray(blk[2:4, a:b].T), before[a:b],
                                blk[4, a:b]) for a, b in zip(bounds, bounds[1:])]
        return self._per_level


def _level_arrays(levels: list) -> tuple[tuple, tuple, tuple, tuple]:
    """The first ``FUSED_LEVELS`` levels' log-odds, update indices, i0 and j0 as the fused ledger kernels take
    them (3-tuples, padded with empty arrays and zero offsets)."""
    if len(levels) == _FUSED:  # (the usual three levels: no padding)
        a, b, c = levels
        return (a.logodds, b.logodds, c.logodds), (a.uidx, b.uidx, c.uidx), (a.i0, b.i0, c.i0), (a.j0, b.j0, c.j0)
    lv3 = levels[:_FUSED]
    pad = _FUSED - len(lv3)
    return (tuple([lv.logodds for lv in lv3]) + (_NO_F32,) * pad, tuple([lv.uidx for lv in lv3]) + (_NO_I32,) * pad,
            tuple([lv.i0 for lv in lv3]) + (0,) * pad, tuple([lv.j0 for lv in lv3]) + (0,) * pad)


def _box_key(t: Track) -> tuple[float, float, float]:
    b = t.box
    return (float(b.px), float(b.py), 0.5 * float(max(b.length, b.width)))


def _sight_key(sight: Track | tuple[TrackReports, int]) -> tuple[float, float, float]:
    """:func:`_box_key` of a last sight (``TrackReports.sight``)."""
    return sight[0].box_key(sight[1]) if type(sight) is tuple else _box_key(sight)


def _last_key(led: _Ledger) -> tuple[float, float, float]:
    """:func:`_box_key` of ledger ``led``'s last sight (:attr:`_Ledger.last_track`, not None)."""
    sight = led.last_track
    return sight.box_key(led.last_at) if type(sight) is TrackReports else _box_key(sight)


class EvidenceLedger:
    """Per-track record of map evidence and its erasure (module docstring)."""

    #: map updates with kept beams between two kept-beam sweeps (:meth:`_sweep_beams`); 0 = no sweep (pass led34's
    #: kept beams: references to every update's whole array, the tests' reference)
    kb_sweep: int = _KB_SWEEP

    def __init__(self, config: MemoryConfig, laser_min_dist: float, laser_max_dist: float,
                 keep_beams: bool = False) -> None:
        self.config = config
        self.laser_min_dist = float(laser_min_dist)
        self.laser_max_dist = float(laser_max_dist)
        #: also keep, per track, the scan index and beams of its recorded hits, and list those of every
        #: erased track in :attr:`erased_beams` (for a map re-rendered from the scans, slam/loops.py)
        self.keep_beams = bool(keep_beams)
        #: (scan index, beams) whose evidence was erased since the caller last emptied the list
        self.erased_beams: list[tuple[int, np.ndarray]] = []
        self._ledgers: dict[int, _Ledger] = {}
        self._ended: dict[int, _Ledger] = {}
        self._n_updates = 0  # after_update calls (the age of a record's row references)
        self._oldest_ended = math.inf  # the smallest last_seen among the ended ledgers, s
        #: ended confirmed ledgers not packed yet and dropped ledgers whose new cells are not counted yet (done in
        #: batches by :meth:`_finish_ended`)
        self._to_pack: list[_Ledger] = []
        self._to_count: list[_Ledger] = []
        #: the batches whose squeezed rows are kept plain, oldest first: (their bytes, the batch's track ids), an
        #: upper bound of their bytes (exact after :meth:`_plain_held`), and whether the ledger deflates
        #: (:data:`_DEFLATE_FROM`)
        self._plain: deque[tuple[int, list[int]]] = deque()
        self._plain_bytes = 0
        self._deflating = False
        #: map updates with kept beams since the last kept-beam sweep, and the scan index of that sweep
        #: (:meth:`_sweep_beams`)
        self._kb_n = 0
        self._kb_mark = -1
        #: the standing boxes (pass led32; :meth:`observe`, ``ledgerkernels.stand_marks``): an id's row (below) =
        #: (centre x, y, half size of the box where the track stands (m, map frame), stamp it began standing there,
        #: last stamp it stood there (s)), valid when its ``_mark`` is the number of the last :meth:`observe` call,
        #: ``_obs`` (every track of that call's reports has one; :meth:`_first_of` reads them)
        self._F = np.zeros((0, 5))
        self._mark = np.zeros(0, dtype=np.int64)
        self._obs = 1
        #: the id → row map of ``_F`` / ``_mark`` (pass led34: rows for the live ids only, not one per id ever seen):
        #: an id at or above ``_s + _P`` has row ``id − _s`` (the window); the ``_P`` rows below it belong to the
        #: live ids below the window (``_pins``, sorted: row ``q`` is ``_pins[q]``'s; ``_pin``: id → row). Laid out
        #: again by :meth:`_rebase` from the live ids when an id does not fit
        self._s = 0
        self._s0 = np.zeros((), dtype=np.int64)  # (``_s`` as a 0-d array)
        self._P = 0
        self._pins = _EMPTY_I
        self._pin: dict[int, int] = {}
        self._rs: np.ndarray | None = None  # the levels' cell sides, m (of the levels list ``_rs_of``)
        self._rs_of: list | None = None
        #: absolute finest-level cells whose evidence was erased (for map.png), with the count of events
        self.erased_cells: set[tuple[int, int]] = set()
        self.stats = {"erasures": 0, "tracks_erased": 0, "cells_changed": 0, "cells_to_unknown": 0,
                      "ended_ledgers_linked": 0, "cells_recorded": 0}
        #: :meth:`summary` once :meth:`release` let the records go (nothing is recorded after that)
        self._final: dict[str, int] | None = None
        #: the last :meth:`observe` call's sights (pass glu121): (reports, ids, stamp, set of ids, removal set, lazy);
        #: a live ledger whose id it has out of the removal set, and that existed then, has its last sight there
        #: (written when read, :meth:`_sync_sights`, or when it stops being seen); lazy False: all written already
        self._sc: tuple | None = None
        self._fresh: set[int] = set()  # the ids of the ledgers started since the last observe call
        self._unconf: dict[int, _Ledger] = {}  # the live ledgers not confirmed yet, by id
        self._stays: set[int] = set()  # ids whose stay erase_entering started since the last observe call
        #: the last observe call's ids, their rows, the window start ``_s`` then, its removal set and that set's rows
        self._rows_cache: tuple = ((), _NO_IDS, -1, set(), _NO_IDS)

    # ------------------------------------------------------------------ recording
    def before_update(self, scan: Scan, pose: Pose2D, tracks: Sequence[Track], removed: np.ndarray,
                      hmap: MultiResMap, index: int = -1) -> PendingUpdate | None:
        """Read, before the map update with ``scan`` (beams ``removed`` taken out) at ``pose``, the
        log-odds of the cells each track's kept beams will hit (removed beams, those of the tracks in the
        removal set, are not recorded). ``index`` is the scan's index in the run (kept with the beams when
        ``keep_beams``). Returns None when nothing is to be recorded. ``tracks``: the tracker's reports (read from
        their columns, no ``Track`` built) or any sequence of ``Track``."""
        lk = _lk or _kernels()
        reps = TrackReports.of_tracks(tracks)
        # the indices of the reports with beams, their beams and ids (from the columns; pass trk90)
        mine, blist, tids = reps.with_beams()
        if not mine:
            return None
        idl = np.array(tids + list(map(len, blist)), dtype=np.int64)  # (the ids, then the beam counts: one array)
        allb = np.concatenate(blist).astype(np.int64, copy=False)
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        levels = hmap.levels
        n_lv = len(levels)
        rs = self._rs
        if rs is None or self._rs_of is not levels or rs.shape[0] != n_lv:  # (a map's levels keep their sides)
            rs = self._rs = np.array([lv.resolution for lv in levels], dtype=np.float64)
            self._rs_of = levels
        want_kb = self.keep_beams and index >= 0
        # in one call: each beam's track (a later track's claim wins), the kept beams (valid, inside the laser's
        # ranges, not removed), their map-frame points (the values of pose.transform_points), every point's
        # (level, track, cell) packed and sorted, the distinct ones no unowned point shares decoded and their cells
        # read on (up to) three levels, which tracks keep beams and, for the loop closer, their kept beams
        # (the scan's own valid mask, not a copy: the kernel only reads it)
        status, blk, small, kb_all = lk.record_cells(allb, idl, scan.ranges, *scan.trig(), scan.valid_view(),
                                                     removed, self.laser_min_dist, self.laser_max_dist, c, s,
                                                     float(pose.x), float(pose.y), rs, *_level_arrays(levels), want_kb)
        if status == 0:  # (ledgerkernels.PACKED)
            if n_lv > _FUSED:  # (levels beyond the fused kernel's three)
                bf = blk[5].view(np.float64)
                for k in range(_FUSED, n_lv):
                    lv, a, b = levels[k], int(small[k]), int(small[k + 1])
                    cells = np.ascontiguousarray(blk[2:4, a:b].T)
                    bf[a:b], blk[4, a:b] = lk.read_cells(lv.logodds, lv.uidx, cells, lv.i0, lv.j0)[:2]
            pending = PendingUpdate(fused=(blk, small), n_levels=n_lv)
            sm = small.tolist()
            present = sm[n_lv + 1:n_lv + 1 + len(mine)]
            kb = sm[n_lv + 1 + len(mine):]
        elif status == 1:  # (ledgerkernels.NO_KEPT: no kept beam of any track)
            return None
        else:  # (cells beyond the packed values' range: level by level)
            pending, present, kb_all, kb_b = self._pending_plain(scan, c, s, pose, allb, idl, removed, hmap, want_kb)
            kb = kb_b.tolist() if want_kb else None
        ledgers = self._ledgers
        if want_kb:  # every track's kept beams, split per track
            at = int(index)
            for i, tid, keep, a, b in zip(mine, tids, present, kb, kb[1:]):
                if keep:  # (else every beam of it removed)
                    led = ledgers.get(tid)
                    if led is None:
                        led = ledgers[tid] = self._new_ledger_at(tid, reps.box_key(i), reps.stamp_of(i), n_lv)
                    if b > a:  # (the bounds, not a view: a view costs more per track and holds the same array)
                        led.kb.extend((at, kb_all, a, b))  # (flat: the tuple dies here, not in a young generation)
            self._kb_n += 1
            if self._kb_n == self.kb_sweep:
                self._sweep_beams(at)
        else:
            for i, tid, keep in zip(mine, tids, present):
                if keep and tid not in ledgers:
                    ledgers[tid] = self._new_ledger_at(tid, reps.box_key(i), reps.stamp_of(i), n_lv)
        return pending

    def _sweep_beams(self, at: int) -> None:
        """Every ``_KB_SWEEP`` map updates with kept beams (``at``: this update's scan index): each live ledger
        with kept beams recorded before the previous sweep copies its own parts out (one chunk of
        :attr:`_Ledger.kbc`), so no live ledger refers to an update's whole kept-beam array older than two sweeps
        (an ended one keeps what it holds, ``ledger_keep_s`` at most: copying each of them once cost
        ``before_update`` ≈ 13 µs a map update on negative_2). Ledgers that start between sweeps (mostly
        tentative tracks dropped a few scans later) are not copied until they outlive one."""
        mark = self._kb_mark
        self._kb_mark = at
        self._kb_n = 0
        todo = [led for led in self._ledgers.values() if led.kb and led.kb[0] < mark]
        if not todo:
            return
        # all of them in one gather (not a view and a concatenation per entry: ≈ 0.7 µs each in situ, ≈ 25
        # entries a map update on negative_2): the updates' arrays one after the other, each entry's range in them
        srcs, a, b, at_l = [], [], [], []
        for led in todo:
            kb = led.kb
            srcs += kb[1::4]
            a += kb[2::4]
            b += kb[3::4]
            at_l += kb[0::4]
        uniq = {id(x): x for x in srcs}
        arrs = list(uniq.values())
        g = dict(zip(uniq, itertools.accumulate([x.shape[0] for x in arrs], initial=0)))
        big = np.concatenate(arrs)
        n = len(srcs)
        # (int32 rows: 12 bytes an entry, not 24 — scan indices and offsets into one sweep's kept beams stay far below
        # 2^31; ``beams`` reads them as Python ints, so nothing read changes)
        m = np.empty((n, 3), dtype=np.int32)
        m[:, 0] = at_l
        m[:, 1] = a
        m[:, 2] = b
        ln = m[:, 2] - m[:, 1]
        first = np.fromiter(map(g.__getitem__, map(id, srcs)), dtype=np.int64, count=n) + m[:, 1]
        np.cumsum(ln, out=m[:, 2])
        np.subtract(m[:, 2], ln, out=m[:, 1])
        cat = big[np.arange(int(m[-1, 2]), dtype=np.int64) + np.repeat(first - m[:, 1], ln)]
        q = 0
        for led in todo:  # (each ledger its own copies: a slice would hold the others' beams alive)
            k = len(led.kb) >> 2
            mine = m[q:q + k]
            c0, c1 = int(mine[0, 1]), int(mine[-1, 2])
            mine = mine - np.array((0, c0, c0), dtype=np.int32)
            part = (mine, cat[c0:c1].copy())
            kbc = led.kbc
            if kbc is None:
                led.kbc = [part]
            else:
                kbc.append(part)
                # chunks merged while the one before is at most twice as long (entries): at most log2 of the
                # entries' count chunks (≈ 0.3 kB each), each entry copied O(log) times
                while len(kbc) > 1 and kbc[-2][0].shape[0] <= 2 * kbc[-1][0].shape[0]:
                    (m1, c1), (m2, c2) = kbc[-2], kbc.pop()
                    m2[:, 1:] += c1.shape[0]
                    kbc[-1] = (np.concatenate((m1, m2)), np.concatenate((c1, c2)))
            led.kb = []
            q += k

    def _pending_plain(self, scan: Scan, c: float, s: float, pose: Pose2D, allb: np.ndarray, idl: np.ndarray,
                       removed: np.ndarray, hmap: MultiResMap, want_kb: bool
                       ) -> tuple[PendingUpdate, list, np.ndarray | None, np.ndarray | None]:
        """:meth:`before_update`'s level-by-level path (cells beyond the packed values' range): (the pending
        update, per track of ``idl``'s ids whether it keeps beams, the kept beams and their per-track bounds or
        None). The kept beams as :func:`~dynslam2d.slam.ledgerkernels.record_cells` keeps them."""
        from dynslam2d.slam.ledgerkernels import beam_owners, kept_beams
        n_t = idl.shape[0] // 2
        ids = idl[:n_t]
        ends = np.concatenate(([0], np.cumsum(idl[n_t:]))).astype(np.int64)
        r = scan.ranges
        cos_a, sin_a = scan.trig()
        # (the kernel's test: valid, laser_min_dist < r < laser_max_dist, not removed; NaN compares False)
        valid = scan.valid_view() & (r > self.laser_min_dist) & (r < self.laser_max_dist) & ~removed
        owner = beam_owners(r.shape[0], allb, ends, ids)
        idx = np.flatnonzero(valid)
        own = owner[idx]
        mine_b = own >= 0
        lx, ly = r[idx] * cos_a[idx], r[idx] * sin_a[idx]
        pts = np.column_stack((c * lx - s * ly + pose.x, s * lx + c * ly + pose.y))
        kept = set(own[mine_b].tolist())
        present = [tid in kept for tid in ids.tolist()]
        kb_all, kb_b = kept_beams(valid, allb, ends) if want_kb else (None, None)
        return PendingUpdate(self._level_cells_plain(pts, mine_b, own[mine_b], hmap)), present, kb_all, kb_b

    def _level_cells(self, packed: np.ndarray, params: np.ndarray, uids: np.ndarray, hmap: MultiResMap, flat: list
                     ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """:meth:`_level_cells_plain` for all levels from one sort: ``packed``, every point's (level, owner, cell)
        packed into one integer by :func:`~dynslam2d.slam.ledgerkernels.scan_cells` (``params``; owner 0 = no
        track, else 1 + the rank of the track id in ``uids``), sorted; the distinct values of tracks whose
        (level, cell) no unowned point has are decoded back, in (level, track id, cell key) order, and their
        cells read (one kernel call, then one per level). Appends to ``flat``, per level, (flat array indices
        of the cells, i0, j0, shape) when all lie inside the level's array, else None."""
        from dynslam2d.slam.ledgerkernels import read_cells, unpack_cells  # at first use (see before_update)
        n_lv = len(hmap.levels)
        ids_s, key_s, cells_s, bounds = unpack_cells(packed, params, uids, n_lv)
        bounds = bounds.tolist()
        per_level = []
        for k, lv in enumerate(hmap.levels):
            a, b = bounds[k], bounds[k + 1]
            c = cells_s[a:b]
            before, uidx, f, n_out = read_cells(lv.logodds, lv.uidx, c, lv.i0, lv.j0)
            # the flat indices, for after_update to re-read the same cells if the level does not grow
            flat.append((f, lv.i0, lv.j0, lv.shape) if n_out == 0 else None)
            per_level.append((ids_s[a:b], key_s[a:b], c, before, uidx))
        return per_level

    def _level_cells_plain(self, pts: np.ndarray, mine_b: np.ndarray, ids: np.ndarray, hmap: MultiResMap
                           ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Per map level: (track ids, cell keys, cells, log-odds, update index) of the cells the tracks'
        points ``pts[mine_b]`` (owners ``ids``) hit, sorted by track then cell key, each (track, cell) once,
        leaving out cells the other points hit on that level."""
        per_level = []
        for lv in hmap.levels:
            cells = np.floor(pts / lv.resolution + 0.5).astype(np.int64)
            key = cells[:, 0] * _KEY_SHIFT + cells[:, 1]  # (i, j) as one integer
            mk = key[mine_b]
            order = np.lexsort((mk, ids))  # by track, then cell
            so, sk = ids[order], mk[order]
            first = np.ones(so.shape[0], dtype=bool)
            first[1:] = (so[1:] != so[:-1]) | (sk[1:] != sk[:-1])
            # a cell another (unowned) kept beam of this scan hits is the structure's, not the track's
            first &= ~_member(sk, key[~mine_b])
            sel = order[first]
            c = cells[mine_b][sel]
            before, uidx = self._read(lv, c)
            per_level.append((ids[sel], mk[sel], c, before, uidx))
        return per_level

    def _new_ledger(self, t: Track, stamp: float, n_levels: int) -> _Ledger:
        """An empty ledger of ``t``; its first box is where the track was first reported.

        ``_Ledger(t.id, box, t0, here, stamp, None, n_levels, max_ledger_cells)`` with every other field at its
        default, the slots set directly (pass led28: ≈ 3.5 ledgers start per map update on negative_2, most of them
        tentative tracks' that are dropped a few scans later; the dataclass ``__init__`` with its two default
        factories cost about half as much again; ``tests/test_ledger_observe.py`` compares every field)."""
        return self._new_ledger_at(t.id, _box_key(t), stamp, n_levels)

    def _new_ledger_at(self, tid: int, here: tuple[float, float, float], stamp: float, n_levels: int,
                       _new=object.__new__) -> _Ledger:
        """:meth:`_new_ledger` of the track ``tid`` reported with the box ``here`` (:func:`_box_key`'s centre x, y
        and half longer side, m, map frame) at ``stamp`` (s)."""
        box, t0, _ = self._first_of(tid) or (here, stamp, stamp)
        led = _new(_Ledger)
        led.id = tid
        led.first_box = box
        led.first_t = t0
        led.last_box = here
        led.last_seen = stamp
        led.recs = None
        led.n_levels = n_levels
        led.cap = self.config.max_ledger_cells
        led.m_start = None
        led.linked = False
        led.confirmed = False
        led.skip = False
        led.kb = []
        led.kbc = None
        led.last_track = None
        led.last_at = -1
        led.ent = []
        led.ent0 = 0
        led.nb_rows = 0
        led.nb_chunks = 0
        self._fresh.add(tid)  # (not seen in the last observe call: pass glu121's lazy sights)
        self._unconf[tid] = led
        return led

    @staticmethod
    def _read(lv, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log-odds (float64) and update index of absolute cells (0 and 0 — never updated — outside the level's
        array)."""
        n = cells.shape[0]
        if lv.empty or n == 0:
            return np.zeros(n), np.zeros(n, dtype=np.int64)
        h, w = lv.shape
        col = cells[:, 0] - lv.i0
        row = cells[:, 1] - lv.j0
        if col.min() >= 0 and row.min() >= 0 and col.max() < w and row.max() < h:  # all inside (the usual case)
            return lv.logodds[row, col].astype(np.float64), lv.uidx[row, col].astype(np.int64)
        lo = np.zeros(n)
        ui = np.zeros(n, dtype=np.int64)
        ok = (col >= 0) & (row >= 0) & (col < w) & (row < h)
        lo[ok] = lv.logodds[row[ok], col[ok]]
        ui[ok] = lv.uidx[row[ok], col[ok]]
        return lo, ui

    def after_update(self, pending: PendingUpdate, hmap: MultiResMap) -> None:
        """Record the evidence the map update added in the cells read by :meth:`before_update`."""
        lk = _lk or _kernels()
        ledgers = self._ledgers
        added = 0
        self._n_updates = upd = self._n_updates + 1
        levels = hmap.levels
        if pending.fused is not None and len(levels) <= _FUSED:
            # one block of rows (cell keys, update index before / after, log-odds' bits, level) of the updated cells
            # of every level in (track, level) order, the cells re-read from the levels' current arrays, and per
            # track its column range and levels
            rows, tid_t, bnd_t, lv_t = lk.level_rows(*_level_arrays(levels), len(levels), *pending.fused)
        else:
            rows, tid_t, bnd_t, lv_t = self._level_groups(pending, levels)
        # one entry per track in its ledger: the records get the rows when the ledger settles, which its bounds
        # make happen at the update where a record is due to fold (and before any record is read)
        if tid_t.shape[0]:
            st = bnd_t.tolist()
            for tid, i, j, lv in zip(tid_t.tolist(), st, st[1:], lv_t.tolist()):
                led = ledgers.get(tid)
                if led is None:
                    continue
                ent = led.ent
                if not ent:
                    led.ent0 = upd
                ent.append((rows, i, j, lv))
                m = led.nb_rows + j - i
                led.nb_rows = m
                c = led.nb_chunks + 1
                led.nb_chunks = c
                if m >= _COMPACT_ROWS or c >= _COMPACT_CHUNKS:  # a record may be due: count exactly, fold
                    led.settle()
                    for rec in led.recs:
                        if rec._n_rows >= _COMPACT_ROWS or rec._n_chunks >= _COMPACT_CHUNKS:
                            added += rec.compact()
                    led.bound()
        if upd % _REF_MAX_AGE == 0:  # settle old entries (few update blocks stay alive)
            old = upd - _REF_MAX_AGE
            for led in ledgers.values():
                if led.ent and led.ent0 <= old:
                    led.settle()
                for rec in led.recs or ():  # (references given by _LevelRecord.refer)
                    if rec._refs is not None and rec._ref0 <= old:
                        rec.materialize()
        self.stats["cells_recorded"] += added

    @staticmethod
    def _level_groups(pending: PendingUpdate, levels: list) -> tuple[np.ndarray, ...]:
        """:meth:`after_update`'s row block and tracks level by level (more levels than the fused kernel takes, or
        a level-by-level pending update), as :func:`~dynslam2d.slam.ledgerkernels.level_rows` returns them: the
        (5, m) rows in (track, level) order (the fifth row: the level); per track, in id order, its id, its rows'
        column bounds (T + 1,) and its levels (bit k: level k)."""
        lk = _lk or _kernels()
        blocks, gid, glv, ga, gb = [], [], [], [], []
        off = 0
        for k, (ids, keys, cells, before, ui_before) in enumerate(pending.per_level):
            if ids.shape[0] == 0:
                continue
            lv = levels[k]
            f = lk.read_cells(lv.logodds, lv.uidx, cells, lv.i0, lv.j0)[2]
            rows, tids, starts = lk.update_rows(lv.logodds, lv.uidx, f, ids, keys, before, ui_before)
            blocks.append(np.vstack((rows, np.full((1, rows.shape[1]), k, dtype=np.int64))))
            gid.append(tids)
            glv.append(np.full(tids.shape[0], k, dtype=np.int64))
            ga.append(starts[:-1] + off)
            gb.append(starts[1:] + off)
            off += rows.shape[1]
        if not blocks:
            return _EMPTY_I5, _EMPTY_I, np.zeros(1, dtype=np.int64), _EMPTY_I
        gid, glv = np.concatenate(gid), np.concatenate(glv)
        order = np.lexsort((glv, gid))  # (each (track, level) once: the order of a track's groups is its levels')
        gid, glv, ga, gb = gid[order], glv[order], np.concatenate(ga)[order], np.concatenate(gb)[order]
        n = gb - ga
        # the columns of the groups in that order: each group's first column, then one by one
        col = np.repeat(ga - np.concatenate(([0], np.cumsum(n)[:-1])), n) + np.arange(int(n.sum()))
        head = np.ones(gid.shape[0], dtype=bool)
        head[1:] = gid[1:] != gid[:-1]
        st = np.flatnonzero(head)
        return (np.concatenate(blocks, axis=1)[:, col], gid[st], np.append(np.cumsum(n)[st] - n[st], int(n.sum())),
                np.bitwise_or.reduceat(np.left_shift(1, glv), st))

    def _fold(self, led: _Ledger) -> None:
        """Fold every level's pending rows of ``led`` (counts its new cells)."""
        for rec in led.levels:
            self.stats["cells_recorded"] += rec.compact()

    def _drop(self, led: _Ledger) -> None:
        """Count the new cells of ``led``, a ledger that is dropped, as :meth:`_fold` would."""
        self.stats["cells_recorded"] += led.new_cells()

    def _first_of(self, tid: int) -> tuple[tuple[float, float, float], float, float] | None:
        """Where live track ``tid`` stands as of the last :meth:`observe`: ((centre x, y, half size) m, map frame,
        stamp it began standing there, last stamp it stood there, s); None if it was not in that call's reports."""
        q = tid - self._s
        if q < self._P:  # (below the window: a pinned id's row, or none)
            q = self._pin.get(tid, -1)
        if 0 <= q < self._mark.shape[0] and self._mark[q] == self._obs:
            x, y, h, t0, t1 = self._F[q].tolist()
            return (x, y, h), t0, t1
        return None

    @property
    def _first(self) -> dict[int, list]:
        """The standing boxes as ``{id: [(x, y, half size), t0, t1]}`` in id order (for tests and inspection)."""
        rows = np.flatnonzero(self._mark == self._obs)
        live = sorted(self._ids_of(rows).tolist())
        return {tid: list(self._first_of(tid)) for tid in live}

    def _set_first(self, tid: int, box: tuple[float, float, float], t0: float, t1: float) -> None:
        """Set live track ``tid``'s standing box (as :meth:`observe` would have; for tests)."""
        q = self._row(tid)
        if q < 0 or q >= self._mark.shape[0]:
            if self.compact_ids:
                self._rebase([tid], self._obs)
            else:
                self._room(tid + 1)
            q = self._row(tid)
        self._F[q] = (*box, t0, t1)
        self._mark[q] = self._obs

    #: lay the standing boxes' rows out again by the live ids when an id does not fit (:meth:`_rebase`); False: one
    #: row per id ever seen (pass led32's layout; the reference of tests/test_ledger_observe.py)
    compact_ids = True

    def _row(self, tid: int) -> int:
        """Track ``tid``'s row in ``_F`` / ``_mark`` (−1: below the window and not pinned; may be beyond the
        arrays)."""
        q = tid - self._s
        return self._pin.get(tid, -1) if q < self._P else q

    def _rows_of(self, ids: list[int]) -> np.ndarray | None:
        """(n,) int64: the rows of ``ids`` (an id below the window: a negative row when none is pinned, which
        ``stand_marks`` refuses); None when a pinned layout has no row for one of them."""
        s = self._s
        if self._P:  # (ids pinned below the window, pass led34: one by one)
            lo, get = s + self._P, self._pin.get
            q = [i - s if i >= lo else get(i, -1) for i in ids]
            return None if -1 in q else np.array(q, dtype=np.int64)
        a = np.array(ids, dtype=np.int64)
        if s:
            a -= s
        return a

    def _ids_of(self, rows: np.ndarray) -> np.ndarray:
        """The ids of ``rows`` (rows of ``_F`` / ``_mark``)."""
        ids = rows + self._s
        if self._P:
            low = rows < self._P
            ids[low] = self._pins[rows[low]]
        return ids

    def _rebase(self, ids: list[int], valid: int) -> None:
        """Lay ``_F`` / ``_mark`` out again for the ids of the valid rows (mark ``valid``) and ``ids``: a window
        from one of them to the largest with one row per id, the ids below it pinned, chosen to minimise
        ``_PIN_COST`` · pins + window (so at most ``_PIN_COST`` rows per id), the arrays twice that and
        ``_ROWS_ROOM`` long — or, while every id is below ``_ROWS_FLAT``, row = id in arrays doubled up to it;
        the valid rows keep their values and marks, every other row is zero. (Pass led34: the id-indexed arrays
        grew by 48 bytes for every id a run ever saw, ≈ 11 MB over a 10-hour log.) The boxes a standing test reads
        are only the valid rows', so no result changes."""
        mark = self._mark
        vs = np.flatnonzero(mark == valid)
        vid = self._ids_of(vs)
        u = np.unique(np.concatenate((vid, np.array(ids, dtype=np.int64))))
        n = u.shape[0]
        if n and u[0] < 0:
            raise ValueError("track ids must not be negative")
        top = int(u[-1]) if n else 0
        if top < _ROWS_FLAT:  # (row = id, the arrays doubled up to _ROWS_FLAT)
            k = w0 = 0
            cap = min(max(64, 2 * mark.shape[0], top + 1), _ROWS_FLAT)
        else:
            k = int(np.argmin(_PIN_COST * np.arange(n) + (top + 1 - u)))  # (the first minimum: the fewest pins)
            w0 = int(u[k])
            cap = 2 * (k + top + 1 - w0) + _ROWS_ROOM
        pins = u[:k]
        s = w0 - k
        F = np.zeros((cap, 5))
        mk = np.zeros(cap, dtype=np.int64)
        nq = vid - s
        if k:
            low = vid < w0
            nq[low] = np.searchsorted(pins, vid[low])
        F[nq] = self._F[vs]
        mk[nq] = mark[vs]
        self._F, self._mark, self._s, self._P, self._pins = F, mk, s, k, pins
        self._s0 = np.array(s, dtype=np.int64)
        self._pin = dict(zip(pins.tolist(), range(k)))

    def _room(self, n: int) -> None:
        """Make the id-indexed standing boxes hold ids below ``n`` (at least doubling; without :attr:`compact_ids`)."""
        cap = self._mark.shape[0]
        if n > cap:
            cap = max(n, 2 * cap, 64)
            F = np.zeros((cap, 5))
            F[:self._F.shape[0]] = self._F
            mark = np.zeros(cap, dtype=np.int64)
            mark[:self._mark.shape[0]] = self._mark
            self._F, self._mark = F, mark

    def observe(self, tracks: Sequence[Track], removing: set[int], stamp: float,
                states: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Keep each live track's last box; move ledgers of ended tracks aside; drop old ones.

        ``tracks``: the tracker's reports (read from their columns, no ``Track`` built; a ledger keeps its track's
        report as ``TrackReports.sight``) or any sequence of ``Track``. ``states``: the tracker's state array and
        the rows of its live reports, ``(X, rows)`` (``Tracker.report_states()``; the first ``len(rows)`` of
        ``tracks`` are those reports, in that order, each box centre and velocity the values of its row: x, y (m),
        vx, vy (m/s), map frame); None: read from the reports themselves."""
        lk = _lk or _kernels()
        if type(tracks) is not TrackReports:
            tracks = TrackReports.of_tracks(tracks)
        ids = tracks.ids
        nr = 0
        n_all = len(ids)  # (the reports' count: ``len(tracks)`` without its Python ``__len__``)
        if states is not None:
            X, rows = states
            nr = rows.shape[0]
            if nr > tracks.n_live:  # (not the live reports of these rows)
                nr = 0
        if nr:
            B = tracks.arrays[0]  # (their boxes: the half sizes of new standing boxes, in the kernel, pass obs114)
        else:
            X, rows, B = _NO_X, _NO_IDS, _NO_B
        # the other reports (the tracker's dormant ones, or all without ``states``): centre and velocity as rows
        if n_all > nr:  # (the dormant reports as their list when the rows are the live ones': no slice, pass trk97)
            rest = tracks.dormant if nr == tracks.n_live else tracks[nr:]
            E = np.array([(b.px, b.py, *t.velocity.tolist(), 0.5 * float(max(b.length, b.width)))
                          for t, b in ((t, t.box) for t in rest)], dtype=np.float64)  # (_box_key's half size)
        else:
            E = _NO_B
        self._obs = c = self._obs + 1
        # the reports' and the removal set's rows of the standing boxes (_rows_of, inlined); the kernel compares rows
        s = self._s
        if self._P:  # (ids pinned below the window)
            lo, get = s + self._P, self._pin.get
            q = [i - s if i >= lo else get(i, -1) for i in ids]
            if -1 in q:  # (an id below the window that is not pinned)
                self._rebase(ids, c - 1)
                s, lo, get = self._s, self._s + self._P, self._pin.get
                q = [i - s if i >= lo else get(i, -1) for i in ids]
            ida = np.array(q, dtype=np.int64)
            rm = np.array([i - s if i >= lo else get(i, -1) for i in removing], dtype=np.int64) if removing \
                else _NO_IDS
        else:
            # (the last call's arrays again when its ids, or its removal set, and the window are the same: most
            # scans of the simulated scenes; the kernel only reads them; pass glu121)
            ck = self._rows_cache
            if ck[2] == s and ids == ck[0]:
                ida = ck[1]
            else:
                ida = np.array(ids, dtype=np.int64)
                if s:  # (beyond _ROWS_FLAT; a 0-d array: half the time of a Python int, whose value NumPy inspects)
                    ida -= self._s0
            if not removing:
                rm = _NO_IDS
            elif ck[2] == s and removing == ck[3]:
                rm = ck[4]
            else:
                rm = np.fromiter(removing, np.int64, len(removing))
                if s:
                    rm -= self._s0
            self._rows_cache = (ids, ida, s, removing, rm)
        # (one kernel call where the per-track test cost ≈ 0.45 µs a track in Python, pass led28)
        cfg = self.config
        new = lk.stand_marks(X, rows, B, E, ida, rm, self._F, self._mark, c, stamp, cfg.stand_speed,
                             cfg.link_margin + 0.5)
        if new.shape[0] and new[0] < 0:  # (nothing written: a row below 0 (an id below the window) or beyond)
            if self.compact_ids:
                self._rebase(ids, c - 1)  # (a negative id raises)
                ida = self._rows_of(ids)
                rm = np.array([self._row(i) for i in removing], dtype=np.int64)
            elif new[0] == -1:
                raise ValueError("track ids must not be negative")
            else:
                self._room(int(-1 - new[0]))
            new = lk.stand_marks(X, rows, B, E, ida, rm, self._F, self._mark, c, stamp, cfg.stand_speed,
                                 cfg.link_margin + 0.5)
        ledgers = self._ledgers
        live = set(ids)
        # each ledger's last sight out of the removal set, kept lazily (pass glu121): a ledger seen out of the set in
        # the last call takes that call's report as its last sight when it is read (``_sync_sights``) or when it
        # stops being seen (it enters the set or ends: written below, from the previous call); only the stays'
        # resets and the unconfirmed ledgers' state test are made here, for the few ledgers they concern
        prev = self._sc
        fresh = self._fresh  # (the ledgers started since the previous call: not seen in it)
        stays = self._stays
        if prev is not None:
            p_rm = prev[4]
            if p_rm:  # (a stay is started only for an id of the removal set; one that is still in it goes on)
                stays.update(p_rm - removing if removing else p_rm)
            if not prev[5]:  # (its sights all written already)
                prev = None
            elif removing:  # (the previous call's sights of the ledgers that entered the set since)
                for tid in (removing - p_rm if p_rm else removing):
                    led = ledgers.get(tid)
                    if led is not None:
                        self._close_sight(led, tid, prev, fresh)
        if len(live) != n_all:  # (an id listed twice: every sight written at once, as before pass glu121)
            self._sight_all(tracks, ids, removing, stamp)
            self._sc = (tracks, ids, stamp, live, removing, False)
        else:
            self._sc = (tracks, ids, stamp, live, removing, True)
            if stays:
                for tid in stays:  # out of the removal set (again): the stay ends (skip and linked only with m_start)
                    led = ledgers.get(tid)
                    if led is not None and led.m_start is not None and tid in live and tid not in removing:
                        led.m_start, led.skip, led.linked = None, False, False
                stays.clear()
            unconf = self._unconf
            if unconf:  # (the ledgers not confirmed yet: confirmed when seen out of the set in a state past tentative)
                state_of = tracks.state_of
                for tid in [tid for tid in unconf if tid in live and tid not in removing
                            and state_of(ids.index(tid)) != "tentative"]:
                    unconf.pop(tid).confirmed = True
        for tid in [i for i in ledgers if i not in live]:  # (in the ledgers' order)
            led = ledgers.pop(tid)
            if self._unconf:
                self._unconf.pop(tid, None)
            if prev is not None and tid in prev[3] and tid not in prev[4] and tid not in fresh:
                # (seen out of the set in the previous call: its last box and stamp from that report, as
                # _close_sight then _last_key give them)
                i = prev[1].index(tid)
                r = prev[0].sight(i)
                led.last_box = prev[0].box_key(i) if type(r) is tuple else _box_key(r)
                led.last_seen = prev[2]
                led.last_track = None
            elif led.last_track is not None:
                led.last_box = _last_key(led)
                # (nothing reads an ended ledger's track again: kept, each held its scan's report arrays — the
                # velocity's and covariance's rows, the detections' beams — for ``ledger_keep_s``, ≈ 3 MiB of
                # MIT CSAIL's ended ledgers at the loop's end; pass ldg47)
                led.last_track = None
            if led.confirmed:  # tentative clutter (wall fragments, noise) is never linked
                # an ended ledger gets no more rows: its entries' rows are copied out of the updates' shared row
                # blocks into one array of their size (issue 13 item 3; one copy, where folding them here would
                # sort them in the per-scan path and splitting them per level would copy each level apart) — in
                # the next batch (_finish_ended)
                self._to_pack.append(led)
                self._ended[tid] = led
                self._oldest_ended = min(self._oldest_ended, led.last_seen)
            elif led.recs is None and len(led.ent) < 2:  # (no rows or one update's: counted without sorting)
                self._drop(led)  # (its cells count in cells_recorded)
            else:  # (counted in the next batch)
                self._to_count.append(led)
        if fresh:
            fresh.clear()
        if len(self._to_pack) + len(self._to_count) >= _END_BATCH:
            self._finish_ended()
        keep = self.config.ledger_keep_s
        if self._ended and stamp - self._oldest_ended > keep:  # (a full pass only when one has expired)
            for tid in [i for i, led in self._ended.items() if stamp - led.last_seen > keep]:
                self._drop(self._ended.pop(tid))
            self._oldest_ended = min((led.last_seen for led in self._ended.values()), default=math.inf)

    @staticmethod
    def _close_sight(led: _Ledger, tid: int, prev: tuple, fresh: set[int]) -> None:
        """Write ledger ``led``'s (track ``tid``) last sight from the previous :meth:`observe` call ``prev``
        (:attr:`_sc`) if it was seen out of the removal set there (and already existed): its report kept as
        ``TrackReports.sight`` gives it, and that call's stamp."""
        reps, ids, stamp, live, rm = prev[:5]
        if tid in live and tid not in rm and tid not in fresh:
            i = ids.index(tid)  # (ids unique in a lazy call)
            r = reps.sight(i)
            if type(r) is tuple:
                led.last_track, led.last_at = reps, i
            else:
                led.last_track = r
            led.last_seen = stamp

    def _sync_sights(self) -> None:
        """Write every live ledger's last sight that the last :meth:`observe` call left to be read (for tests and
        inspection: the fields then read as if every sight had been written in the call)."""
        prev = self._sc
        if prev is None or not prev[5]:
            return
        for tid, led in self._ledgers.items():
            self._close_sight(led, tid, prev, self._fresh)

    def _sight_all(self, tracks: TrackReports, ids: Sequence[int], removing: set[int], stamp: float) -> None:
        """Every live ledger's last sight, stay and confirmation written from the reports ``tracks`` (ids ``ids``)
        at ``stamp``, s (:meth:`observe`'s loop before pass glu121; used when an id is listed twice)."""
        ledgers = self._ledgers
        sight, state_of = tracks.sight, tracks.state_of
        built = tracks.live_built
        nb = len(built)
        for i, tid in enumerate(ids):  # (each ledger's last sight)
            if tid in removing:
                continue
            led = ledgers.get(tid)
            if led is not None:
                if led.m_start is not None:  # out of the removal set (again); skip and linked are only set
                    led.m_start, led.skip, led.linked = None, False, False  # (with m_start)
                if i < nb:
                    r = built[i]
                    if r is None:
                        led.last_track, led.last_at = tracks, i
                    else:
                        led.last_track = r
                else:
                    led.last_track = sight(i)
                led.last_seen = stamp
                if not led.confirmed and state_of(i) != "tentative":
                    led.confirmed = True
                    self._unconf.pop(tid, None)
        self._stays.clear()

    def _finish_ended(self) -> None:
        """Pack the ended ledgers and count the new cells of the dropped ones that :meth:`observe` set aside.

        Done for a batch of them at once (pass led26): the same copies and sorts, with the same results, as one at
        a time when each track ends, but back to back: in the pipeline one of them alone, between the tracker's and
        the map's kernels, ran its dozen small NumPy calls about three times slower than in a row. Until then an
        ended ledger holds its entries' update blocks (at most ``_END_BATCH`` ledgers wait) and reads as packed
        (:meth:`_Ledger.settle` and :meth:`_Ledger.new_cells` take both forms); a dropped one is out of every
        table and not changed any more. (Only dropped ledgers with the rows of two or more updates wait: the others
        are counted without a sort at once, and a waiting one lets its track go — ledgers that wait longer outlive
        more of the collector's young generations, and with every dropped ledger waiting the garbage collections
        cost the map update about as much as the batches saved.)"""
        kept = _pack_all(self._to_pack, deflate=self._deflating, mapped=True)
        if kept is not None and not self._deflating:
            self._plain.append((kept.nbytes, [led.id for led in self._to_pack]))
            self._plain_bytes += kept.nbytes
            if self._plain_bytes > _DEFLATE_FROM:
                self._plain_bytes = sum(nb for nb, _ in self._plain_held())
                self._deflating = self._plain_bytes > _DEFLATE_FROM
        if self._deflating and self._plain:
            self._deflate_plain()
        for led in self._to_count:
            self._drop(led)
        self._to_pack = []
        self._to_count = []

    def _held(self, tids: list[int]) -> tuple[np.ndarray | None, list[_Ledger]]:
        """The plain squeezed array of the batch of ``tids`` and its ended ledgers that still hold it ((None, [])
        when none does: linked, dropped or settled since)."""
        buf, leds = None, []
        for tid in tids:
            led = self._ended.get(tid)
            if led is None or len(led.ent) != 1:
                continue
            rows = led.ent[0][0]
            if buf is None and type(rows) is np.ndarray and rows.ndim == 1:
                buf = rows
            if rows is buf:
                leds.append(led)
        return buf, leds

    def _plain_held(self) -> deque[tuple[int, list[int]]]:
        """:attr:`_plain` without the batches no ended ledger holds any more."""
        self._plain = deque(e for e in self._plain if self._held(e[1])[0] is not None)
        return self._plain

    def _deflate_plain(self) -> None:
        """Deflate the oldest batches kept plain, at least :data:`_DEFLATE_STEP` bytes of them (the same bytes
        inflated, so the same rows: :func:`_unsqueeze_rows`)."""
        done = 0
        while self._plain and done < _DEFLATE_STEP:
            nb, tids = self._plain.popleft()
            buf, leds = self._held(tids)
            if buf is None:
                continue
            z = _Zipped(buf)
            for led in leds:
                _, a, b, chunks = led.ent[0]
                led.ent = [(z, a, b, chunks)]
            done += nb

    # ------------------------------------------------------------------ erasure
    def erase_entering(self, tracks: Sequence[Track], removing: set[int], stamp: float, hmap: MultiResMap,
                       movers: tuple[list[int], np.ndarray] | None = None) -> int:
        """Erase the evidence of every live track in the removal set ``removing`` (ids) that has moved
        ``erase_min_travel`` from where it was first removed, with the evidence of ended tracks that stood
        where it was first seen. Returns the number of cells changed on the finest level. ``tracks``: the tracker's
        reports (only the removal set's boxes read from their columns) or any sequence of ``Track``. ``movers``:
        the removal set's ids in their reports' order (``removing`` their set) and their (k, ≥ 5) box rows
        [p_x, p_y, θ, l, w, …] as reported (m, rad, map frame; the pipeline's movers' rows): ``tracks`` is then not
        read (a box only for a track not skipped, all of them as one ``tolist``; docs/speed.md, pass trk97)."""
        if not self.config.erase or not removing:  # (no track in the removal set: nothing to erase or to start)
            return 0
        changed = 0
        # the removal set's ids in their reports' order and their box rows: [p_x, p_y, θ, l, w, …] (``movers``'; as
        # lists when first read) or the box keys (p_x, p_y, half size) read from the reports
        if movers is not None:
            mids, rows = movers[0], None
        else:
            reps = TrackReports.of_tracks(tracks)
            ids = reps.ids
            at = [i for i, tid in enumerate(ids) if tid in removing]
            mids, rows = [ids[i] for i in at], [reps.box_key(i) for i in at]
        ledgers = self._ledgers
        for j, tid in enumerate(mids):
            led = ledgers.get(tid)
            if led is not None and led.skip and led.m_start is not None:  # (skipped below: its box not read, pass
                continue  # trk97 — most walkers are born moving)
            if rows is None:
                rows = movers[1].tolist()
            r = rows[j]
            if led is None:
                here = r if len(r) == 3 else (r[0], r[1], 0.5 * max(r[3], r[4]))  # (_box_key's floats)
                led = self._new_ledger_at(tid, here, stamp, len(hmap.levels))
                self._ledgers[tid] = led
            x, y = r[0], r[1]
            if led.m_start is None:
                led.m_start = (x, y)
                self._stays.add(tid)
                (fx, fy, fh), f_t, last_t = self._first_of(tid) or (led.first_box, led.first_t, led.first_t)
                led.first_box, led.first_t = (fx, fy, fh), f_t
                # only what stood before it moved wrote evidence worth erasing (a person born walking enters
                # M within a second: its few early hits are left to the clean-up pass), and only it may be
                # what ended tracks saw parked where it stood
                stood = (last_t - f_t >= self.config.link_min_stand
                         and math.hypot(x - fx, y - fy) <= self.config.link_margin + 1.0)
                led.skip = not stood
                led.linked = not stood
            if led.skip or math.hypot(x - led.m_start[0], y - led.m_start[1]) < self.config.erase_min_travel:
                continue
            if not led.linked:
                led.linked = True
                for other in self._linked_ended(led):
                    changed += self._erase(other, hmap)
                    self.stats["ended_ledgers_linked"] += 1
                    del self._ended[other.id]
            if led.n_cells:
                changed += self._erase(led, hmap)
        return changed

    def _linked_ended(self, led: _Ledger) -> list[_Ledger]:
        """Ended ledgers whose last box lies where ``led``'s track was first seen."""
        fx, fy, fh = led.first_box
        out = []
        for other in self._ended.values():
            ox, oy, oh = other.last_box
            if math.hypot(ox - fx, oy - fy) <= max(fh, oh) + self.config.link_margin:
                out.append(other)
        return out

    def _erase(self, led: _Ledger, hmap: MultiResMap) -> int:
        """Subtract ``led``'s evidence from every level (only its cells change); clear the ledger."""
        n0 = 0
        self._fold(led)
        for k, rec in enumerate(led.levels):
            if not len(rec):
                continue
            lv = hmap.levels[k]
            keys = _decode(rec.key)
            delta, pure, last = rec.delta, rec.pure, rec.last
            col = keys[:, 0] - lv.i0
            row = keys[:, 1] - lv.j0
            h, w = lv.shape
            ok = (col >= 0) & (row >= 0) & (col < w) & (row < h)
            col, row, delta, pure, last = col[ok], row[ok], delta[ok], pure[ok], last[ok]
            cur = lv.logodds[row, col].astype(np.float64)
            # a cell whose log-odds the track's hits make up only a small part of is the structure's
            mine = delta >= self.config.erase_min_share * cur
            col, row, delta, pure, last, cur = col[mine], row[mine], delta[mine], pure[mine], last[mine], cur[mine]
            keys = keys[ok][mine]
            # unknown again: the track's hits made the cell known and nothing else touched it since
            unknown = pure & (lv.uidx[row, col] == last)
            new = np.where(unknown, 0.0, cur - delta).astype(np.float32)
            lv.logodds[row, col] = new
            lv.mark_long_occupied(row, col)  # (a cell can rise with erase_min_share > 1: the level's bitmap, if kept)
            lv.prob[row, col] = encode_probs(np.where(unknown, 0.5, 1.0 / (1.0 + np.exp(-new.astype(np.float64)))))
            lv.uidx[row, col] = np.where(unknown, 0, lv.uidx[row, col])  # (0: never updated)
            if k == 0:
                n0 = int(col.shape[0])
                self.stats["cells_to_unknown"] += int(unknown.sum())
                self.erased_cells.update(map(tuple, keys.tolist()))
            rec.clear()
        if led.kb or led.kbc is not None:
            self.erased_beams.extend(led.beams)
            led.kb = []
            led.kbc = None
        self.stats["cells_changed"] += n0
        self.stats["erasures"] += 1
        self.stats["tracks_erased"] += 1
        hmap.version += 1
        return n0

    # ------------------------------------------------------------------ output
    def erased_mask(self, origin: tuple[float, float], shape: tuple[int, int], resolution: float) -> np.ndarray:
        """(H, W) bool over a finest-level map whose lower-left cell corner is ``origin`` (m): True where
        evidence was erased."""
        out = np.zeros(shape, dtype=bool)
        if not self.erased_cells:
            return out
        c = np.array(list(self.erased_cells), dtype=np.int64)
        # cell i is centred at i·r: its lower-left corner at (i − 0.5)·r
        col = np.round((c[:, 0] - 0.5) - origin[0] / resolution).astype(np.int64)
        row = np.round((c[:, 1] - 0.5) - origin[1] / resolution).astype(np.int64)
        ok = (col >= 0) & (row >= 0) & (col < shape[1]) & (row < shape[0])
        out[row[ok], col[ok]] = True
        return out

    def summary(self) -> dict[str, int]:
        """Counters for summary.json's ``memory`` block."""
        if self._final is not None:
            return dict(self._final)
        self._finish_ended()
        for led in (*self._ledgers.values(), *self._ended.values()):
            self._fold(led)
        return {**self.stats, "erased_cells_finest": len(self.erased_cells),
                "ledgers_live": len(self._ledgers), "ledgers_ended": len(self._ended)}

    def release(self) -> None:
        """The run is over: keep :meth:`summary` (the records folded first, as it does) and :attr:`erased_cells`,
        and let every track's record go (issue 13 item 3: some 20 MB of buffers and small objects on MIT CSAIL,
        held through the loop closure's re-render and the clean-up pass otherwise). Recording or erasing after
        this starts from empty records; :meth:`summary` keeps returning the counters of the release."""
        self._final = self.summary()
        self._ledgers = {}
        self._sc = None
        self._fresh = set()
        self._unconf = {}
        self._stays = set()
        self._rows_cache = ((), _NO_IDS, -1, set(), _NO_IDS)
        self._ended = {}
        self._to_pack = []
        self._to_count = []
        self._plain = deque()
        self._plain_bytes = 0
        self._deflating = False
        self._F = np.zeros((0, 5))
        self._mark = np.zeros(0, dtype=np.int64)
        self._s = self._P = 0
        self._s0 = np.zeros((), dtype=np.int64)
        self._pins = _EMPTY_I
        self._pin = {}
        self._oldest_ended = math.inf
        self.erased_beams = []


__all__ = ["EvidenceLedger", "PendingUpdate"]
