"""Compact per-scan records of a run: memory that grows by bytes, not kilobytes, per scan.

A long run keeps, for every scan, its pose, flags, timings, removed-beam mask and
track rows. Kept as Python objects that cost ~8 KB per scan (1.5 GB at 200 000
scans); here they live in growable numpy buffers:

* :class:`GrowArray` — an (n, k) array with amortised O(1) append;
* :class:`PackedGrowArray` — a :class:`GrowArray` whose rows can also be given as their bytes (one C call a row in
  the run loop, where a NumPy row assignment converts a tuple field by field);
* :class:`BitRows` — one bool row per scan (any length), stored as packed bits;
* :class:`TrackRows` — the rows of :data:`dynslam2d.pipeline.TRACK_COLUMNS` in a
  structured array, read back as tuples.

Both row containers behave like read-only sequences (``len``, iteration, indexing),
so code written for the former lists keeps working.
"""

from __future__ import annotations

import struct
from array import array
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

try:  # np.count_nonzero(a) without axis is this C function behind a Python wrapper and its dispatch (every scan)
    from numpy._core.multiarray import count_nonzero as _count_nonzero
except ImportError:  # pragma: no cover - another NumPy layout
    _count_nonzero = np.count_nonzero

_BOOL = np.dtype(np.bool_)


class GrowArray:
    """An append-only array of rows of dtype ``dtype`` and shape ``shape`` (doubling growth)."""

    def __init__(self, dtype: object, shape: tuple[int, ...] = (), capacity: int = 256) -> None:
        self._buf = np.empty((max(1, capacity), *shape), dtype=dtype)
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def _reserve(self, k: int) -> None:
        need = self._n + k
        if need > self._buf.shape[0]:
            cap = max(need, 2 * self._buf.shape[0])
            new = np.empty((cap, *self._buf.shape[1:]), dtype=self._buf.dtype)
            new[: self._n] = self._buf[: self._n]
            self._buf = new

    def append(self, row: object) -> None:
        self._reserve(1)
        self._buf[self._n] = row
        self._n += 1

    def extend(self, rows: np.ndarray) -> None:
        k = len(rows)
        if k == 0:
            return
        self._reserve(k)
        self._buf[self._n : self._n + k] = rows
        self._n += k

    def view(self) -> np.ndarray:
        """The rows so far (a view; copy it if the array keeps growing)."""
        return self._buf[: self._n]

    def __getitem__(self, i):  # type: ignore[no-untyped-def]
        return self.view()[i]

    def __iter__(self) -> Iterator[object]:
        return iter(self.view())

    def __array__(self, dtype: object = None, copy: object = None) -> np.ndarray:
        """``np.array(grow)`` / ``np.asarray(grow)``: a copy of the rows so far."""
        out = self.view().copy()
        return out if dtype is None else out.astype(dtype)

    @property
    def nbytes(self) -> int:
        return int(self._buf.nbytes)


class PackedGrowArray(GrowArray):
    """A :class:`GrowArray` whose rows may also be added as their bytes (:meth:`add_raw`): the fields of each row
    packed in the dtype's order without padding, native byte order (``struct.Struct("=…").pack``, the layout of a
    NumPy structured dtype without ``align``). The bytes wait in a ``bytearray`` (one C append per row) and move into
    the array's buffer in one copy when the rows are read (any method of :class:`GrowArray`) or when more than
    ``chunk`` bytes wait (the waiting bytes stay below that: a long run's memory is the buffer's)."""

    def __init__(self, dtype: object, shape: tuple[int, ...] = (), capacity: int = 256, chunk: int = 1 << 20) -> None:
        super().__init__(dtype, shape, capacity)
        self._raw = bytearray()
        self._chunk = int(chunk)

    def add_raw(self, raw: bytes | bytearray | memoryview) -> None:
        """Add whole rows given as their packed bytes (a multiple of the row size)."""
        waiting = self._raw
        waiting += raw
        if len(waiting) >= self._chunk:
            self.settle()

    def settle(self) -> None:
        """Move the waiting bytes into the buffer (a no-op when none wait)."""
        raw = self._raw
        if raw:
            self._raw = bytearray()  # (first: GrowArray.extend below reserves through _reserve, which settles)
            buf = self._buf
            GrowArray.extend(self, np.frombuffer(raw, dtype=buf.dtype).reshape(-1, *buf.shape[1:]))

    def _reserve(self, k: int) -> None:
        if self._raw:
            self.settle()
        GrowArray._reserve(self, k)

    def __len__(self) -> int:
        if self._raw:
            self.settle()
        return self._n

    def view(self) -> np.ndarray:
        if self._raw:
            self.settle()
        return self._buf[: self._n]

    @property
    def nbytes(self) -> int:
        return int(self._buf.nbytes) + len(self._raw)


class BitRows(Sequence[np.ndarray]):
    """Bool rows of any length, packed 8 per byte (a row without a set bit keeps no bytes); ``rows[i]`` is a fresh
    (len_i,) bool array."""

    def __init__(self) -> None:
        # (the packed rows appended as bytes: one C call a row; ``_used`` counts them, the next row's first byte)
        self._bits = PackedGrowArray(np.uint8, capacity=4096)
        self._used = 0
        # (each row's first byte and length as C int64 arrays of the standard library: an append is one C call, where
        # a GrowArray's costs a Python method and a NumPy item assignment — on every scan of a run)
        self._start = array("q")
        self._len = array("q")
        self.total_bits = 0
        self.total_set = 0
        self._widths: set[int] = set()

    def append(self, row: np.ndarray) -> None:
        # (a 1-D bool array, what the pipeline gives on every scan, as it is: np.asarray(…, bool).ravel() of it is
        # the same values; its width tested against the set before adding it)
        r = row if type(row) is np.ndarray and row.dtype is _BOOL and row.ndim == 1 else np.asarray(
            row, dtype=bool).ravel()
        size = r.size
        n_set = int(_count_nonzero(r))  # (np.count_nonzero(r) without its Python wrapper)
        if n_set:
            packed = np.packbits(r)
            self._start.append(self._used)
            self._used += packed.shape[0]
            self._bits.add_raw(packed.data)
        else:  # a row without a set bit (nearly every scan's removed beams) keeps no bytes: start −1
            self._start.append(-1)
        self._len.append(size)
        self.total_bits += size
        self.total_set += n_set
        if size not in self._widths:
            self._widths.add(size)

    def __len__(self) -> int:
        return len(self._start)

    def __getitem__(self, i):  # type: ignore[no-untyped-def, override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        n = len(self)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(i)
        s, k = self._start[i], self._len[i]
        if s < 0:
            return np.zeros(k, dtype=bool)
        return np.unpackbits(self._bits.view()[s : s + (k + 7) // 8], count=k).astype(bool)

    def __iter__(self) -> Iterator[np.ndarray]:
        for i in range(len(self)):
            yield self[i]

    @property
    def uniform(self) -> bool:
        """All rows have the same length."""
        return len(self._widths) <= 1

    def stack(self) -> np.ndarray:
        """(n, width) bool when every row has the same width (see :attr:`uniform`)."""
        n = len(self)
        if n == 0:
            return np.zeros((0, 0), dtype=bool)
        if not self.uniform:
            raise ValueError("rows differ in length")
        width = self._len[0]
        per = (width + 7) // 8
        kept = np.flatnonzero(np.array(self._start, dtype=np.int64) >= 0)  # (rows with bytes, stored in their order)
        out = np.zeros((n, width), dtype=bool)
        if kept.size:
            packed = self._bits.view()[: kept.size * per].reshape(kept.size, per)
            out[kept] = np.unpackbits(packed, axis=1, count=width).astype(bool)
        return out

    @property
    def nbytes(self) -> int:
        return self._bits.nbytes + self._start.itemsize * len(self._start) + self._len.itemsize * len(self._len)


#: Track states, stored as small integers in :class:`TrackRows`.
TRACK_STATES = ("tentative", "confirmed", "coasting", "deleted")

_TRACK_DTYPE = np.dtype([
    ("stamp", np.float64), ("id", np.int64), ("state", np.int8), ("x", np.float64), ("y", np.float64),
    ("heading", np.float64), ("length", np.float64), ("width", np.float64), ("vx", np.float64),
    ("vy", np.float64), ("in_M", np.bool_), ("remembered", np.bool_),
])

#: Rows waiting in :class:`TrackRows`' columns before they move into its buffer (≈ 75 bytes each).
_COLUMN_CHUNK = 1 << 13


def _new_wait() -> tuple[array | bytearray, ...]:
    """Empty waiting columns of :class:`TrackRows`: the scans' stamps (s) and row counts, then per row its id, state
    code (a byte), box (5 float64's bytes), state [x, y, v_x, v_y] (4 float64's bytes), in M and remembered (a byte
    each)."""
    return array("d"), array("q"), array("q"), bytearray(), bytearray(), bytearray(), bytearray(), bytearray()


_F64 = np.dtype(np.float64)


#: One :data:`_TRACK_DTYPE` row's bytes from its fields (native order, no padding: the dtype's layout).
_PACK_TRACK = struct.Struct("=dqb7d??").pack
assert struct.calcsize("=dqb7d??") == _TRACK_DTYPE.itemsize


class TrackRows(Sequence[tuple]):
    """Rows ``(stamp, id, state, x, y, heading, length, width, vx, vy, in_M)`` in a structured array.

    Every number is kept as float64 (tracks.csv is identical to the one a list of tuples
    gives), the state as a small integer: 75 bytes per row instead of ~500. Rows read back as tuples of Python values.
    Beside each row a flag ``remembered`` (the track is in M only by track memory, docs/maps.md):
    :meth:`remembered`, tracks.csv's last column.
    """

    def __init__(self) -> None:
        self._rows = PackedGrowArray(_TRACK_DTYPE, capacity=1024)
        self._state_codes: dict[str, int] = {s: i for i, s in enumerate(TRACK_STATES)}
        self._states: list[str] = list(TRACK_STATES)
        # :meth:`add_columns`' rows waiting column by column (C arrays of the standard library, one C call per
        # column and scan), moved into the structured buffer when read or when _COLUMN_CHUNK rows wait
        self._wait: tuple[array | bytearray, ...] = _new_wait()

    def _settle(self) -> None:
        """Move the rows waiting in columns (:meth:`add_columns`) into the structured buffer, after its rows."""
        stamps, counts, ids, states, boxes, xv, in_m, rem = self._wait
        k = len(ids)
        if not k:
            return
        self._wait = _new_wait()
        rows = self._rows
        rows._reserve(k)  # (settles the waiting bytes first: they are older)
        n = rows._n
        seg = rows._buf[n:n + k]
        seg["stamp"] = np.repeat(np.frombuffer(stamps, np.float64), np.frombuffer(counts, np.int64))
        seg["id"] = np.frombuffer(ids, np.int64)
        seg["state"] = np.frombuffer(states, np.int8)
        b = np.frombuffer(boxes, np.float64).reshape(k, 5)
        for j, name in enumerate(("x", "y", "heading", "length", "width")):
            seg[name] = b[:, j]
        v = np.frombuffer(xv, np.float64).reshape(k, 4)
        seg["vx"] = v[:, 2]
        seg["vy"] = v[:, 3]
        m = np.frombuffer(in_m, np.uint8)
        # (a flag's truth, as struct's "?" stores it; remembered: the truth of ``remembered & in_M``, operator.and_)
        seg["in_M"] = m != 0
        seg["remembered"] = (np.frombuffer(rem, np.uint8) & m) != 0
        rows._n = n + k

    def add_columns(self, stamp: float, ids: Sequence[int], states: Sequence[int], boxes: np.ndarray,
                    xv: np.ndarray, in_m: Sequence[int], remembered: Sequence[int]) -> bool:
        """Append one scan's ``k = len(ids)`` rows given as columns — state codes (from :meth:`code`), ``boxes``
        (k, 5) float64 C-ordered [x, y, heading, length, width] (m, rad, map frame), ``xv`` (k, 4) float64 C-ordered
        states [x, y, v_x, v_y] (m, m/s; the velocities kept), the in-M and remembered flags (bools, or ints
        0..255) — the tracker's reports' columns (``TrackReports.add_rows``): each column added to the rows waiting
        column by column in one C call, without a tuple per row. The bytes :meth:`extend_records` stores for the
        rows ``zip(repeat(stamp), ids, states, *boxes.T, *xv[:, 2:].T, in_m, map(operator.and_, remembered,
        in_m))``. Returns False, with nothing added, when a value is one the C calls do not take (a ``None``, an
        id beyond int64, a negative code) or the shapes differ: the caller then adds the rows another way."""
        k = len(ids)
        if (boxes.shape != (k, 5) or xv.shape != (k, 4) or boxes.dtype != _F64 or xv.dtype != _F64
                or len(self._states) > 128):  # (codes beyond int8: struct refuses them)
            return False
        if self._rows._raw:
            self._rows.settle()  # (the rows waiting as bytes are older: into the buffer first)
        stamps, counts, wid, wst, wbox, wxv, win, wrem = self._wait
        n0 = len(wid)
        try:
            st, fm, fr = bytes(states), bytes(in_m), bytes(remembered)
            if not len(st) == len(fm) == len(fr) == k:
                return False
            wid.extend(ids)
            if len(wid) != n0 + k:
                raise ValueError
            stamps.append(stamp)
            wbox += memoryview(boxes)  # (an array's bytes, C order; a memoryview: not NumPy's ``+``)
            wxv += memoryview(xv)
        except (TypeError, ValueError, OverflowError, BufferError):  # (no float / int; not C-ordered)
            del wid[n0:], wbox[n0 * 40:], wxv[n0 * 32:]
            if len(stamps) > len(counts):
                stamps.pop()
            return False
        counts.append(k)
        wst += st
        win += fm
        wrem += fr
        if n0 + k >= _COLUMN_CHUNK:
            self._settle()
        return True

    def _code(self, state: str) -> int:
        code = self._state_codes.get(state)
        if code is None:
            code = len(self._states)
            self._states.append(state)
            self._state_codes[state] = code
        return code

    def append(self, row: Sequence[object], remembered: bool = False) -> None:
        if self._wait[2]:
            self._settle()
        stamp, tid, state, x, y, th, ln, wd, vx, vy, in_m = row
        self._rows.append((stamp, tid, self._code(str(state)), x, y, th, ln, wd, vx, vy, bool(in_m),
                           bool(remembered)))

    def code(self, state: object) -> int:
        """The small integer ``state`` is stored as (a new state name gets the next code)."""
        return self._code(str(state))

    @property
    def state_codes(self) -> dict[str, int]:
        """State name → code of the states seen so far (read only; :meth:`code` adds new ones)."""
        return self._state_codes

    def add_tracks(self, stamp: float, tracks: Iterable[object]) -> bool:
        """Append one scan's live tracks (:class:`dynslam2d.types.Track`, map frame; what :meth:`extend_records`
        stores of ``dynslam2d.pipeline._track_records``' rows, the same values): each row packed into its 75 bytes by
        one ``struct`` call and added to the rows' waiting bytes (:class:`PackedGrowArray`) — the run loop's
        per-scan record of its tracks, without a tuple per track converted field by field by NumPy. Returns False,
        with nothing added, when a track has a state not coded yet or a value ``struct`` does not take (a ``None``
        where NumPy stores NaN): the caller then adds the rows the NumPy way."""
        if self._wait[2]:
            self._settle()
        rows = self._rows
        raw = rows._raw
        n0 = len(raw)
        codes = self._state_codes
        pack = _PACK_TRACK
        try:
            for t in tracks:
                b = t.box  # type: ignore[attr-defined]
                vx, vy = t.velocity.tolist()  # type: ignore[attr-defined]
                raw += pack(stamp, t.id, codes[t.state], b.px, b.py, b.theta, b.length, b.width,  # type: ignore
                            vx, vy, t.in_m, t.remembered)  # type: ignore[attr-defined]
        except (KeyError, TypeError, ValueError, OverflowError, struct.error):  # (a new state name, or no float)
            del raw[n0:]
            return False
        if len(raw) >= rows._chunk:
            rows.settle()
        return True

    def extend_records(self, records: Sequence[tuple]) -> None:
        """Append rows given in storage order ``(stamp, id, state code, x, y, heading, length, width, vx, vy,
        in_M, remembered)`` (codes from :meth:`code`) in one array write: the values :meth:`append` stores (one
        scan's live tracks at once in :func:`dynslam2d.pipeline.run`)."""
        k = len(records)
        if k:
            if self._wait[2]:
                self._settle()
            rows = self._rows
            rows._reserve(k)
            n = rows._n
            # (the tuples converted straight into the buffer's rows: np.array(records, dtype=_TRACK_DTYPE)'s values
            # without that array and its copy)
            rows._buf[n:n + k] = records
            rows._n = n + k

    def __len__(self) -> int:
        return len(self._rows) + len(self._wait[2])

    def _tuple(self, r: np.void) -> tuple:
        return (float(r["stamp"]), int(r["id"]), self._states[int(r["state"])], float(r["x"]), float(r["y"]),
                float(r["heading"]), float(r["length"]), float(r["width"]), float(r["vx"]), float(r["vy"]),
                bool(r["in_M"]))

    def __getitem__(self, i):  # type: ignore[no-untyped-def, override]
        if isinstance(i, slice):
            return [self._tuple(r) for r in self.array()[i]]
        return self._tuple(self.array()[i])

    def __iter__(self) -> Iterator[tuple]:
        for r in self.array():
            yield self._tuple(r)

    def array(self) -> np.ndarray:
        """The rows as a structured array (fields as in :data:`TRACK_COLUMNS`; ``state`` coded)."""
        if self._wait[2]:
            self._settle()
        return self._rows.view()

    def remembered(self) -> np.ndarray:
        """(n,) bool: the row's track is in M only because it moved before and stopped (track memory)."""
        return self.array()["remembered"]

    def state_names(self) -> list[str]:
        """State name of each code in :meth:`array`'s ``state`` field."""
        return list(self._states)

    @property
    def nbytes(self) -> int:
        return self._rows.nbytes + sum(a.itemsize * len(a) if isinstance(a, array) else len(a) for a in self._wait)


__all__ = ["BitRows", "GrowArray", "PackedGrowArray", "TRACK_STATES", "TrackRows"]
