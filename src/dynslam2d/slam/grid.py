"""Growable multi-resolution log-odds occupancy grids (Kohlbrecher et al.,
SSRR 2011 §IV-A; hector_mapping map/).

Geometry. Level k has resolution ``r_k = r0·2^k``. Integer map coordinates are cell
centres (as hector_mapping's GridMapBase.h): the cell with absolute index ``(i, j)`` is centred at world
``(i·r_k, j·r_k)``, so the map-frame origin is a cell centre on every level. Each level
stores a dense block of cells ``[i0, i0+W) × [j0, j0+H)`` as ``array[row=j−j0, col=i−i0]``
(row 0 at the bottom, like :class:`~dynslam2d.gridmap.GridMap`). When a scan reaches past
the block, the block is reallocated larger (:meth:`GridLevel.ensure`) and its content is
copied: the map grows as the robot explores and the user never chooses a map size.

"Array map coordinates" (what the numba kernels use) are ``(x, y) = (world/r_k − i0,
world/r_k − j0)``: continuous, in cells, with array cell (col, row) centred at (col, row).
"""

from __future__ import annotations

import math
import mmap
import sys
import weakref
from functools import cache
from itertools import count
from typing import Protocol

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.slam.raycast import integrate_levels, integrate_rays, integrate_rays_stop, ray_ends
from dynslam2d.types import Pose2D

#: Bytes per cell: float32 log-odds + 32-bit probability cache + int32 update index.
_BYTES_PER_CELL = 12
#: The most levels :meth:`MultiResMap.integrate` updates in one kernel call (the default map has 3, the loop closer's
#: submaps 4 — pass rest18: they took the per-level loop before; the level tuples are padded to this length with empty
#: arrays: one kernel specialisation).
_FUSED_LEVELS = 4
_NO_F32 = np.zeros((0, 0), dtype=np.float32)
_NO_I32 = np.zeros((0, 0), dtype=np.int32)
_NO_U32 = np.zeros((0, 0), dtype=np.uint32)
_NO_STOP = np.zeros(0)
_NO_CLEAR = np.zeros((0, 2))
_NO_ROWS = np.zeros((0, 0), dtype=np.float32)
#: a level without a long-occupied bitmap (:meth:`GridLevel.keep_long_occupied`)
_NO_BITS = np.zeros((0, 0), dtype=np.uint64)
#: float64's dtype (an array's ``dtype is _F64``: the cheap form of ``== np.float64`` for the arrays NumPy makes)
_F64 = np.dtype(np.float64)


class LevelFollower(Protocol):
    """A view of a :class:`GridLevel`'s arrays that follows the level's growth (:meth:`GridLevel.follow`)."""

    def detach(self) -> None:
        """Let go of the level's arrays (the level is about to replace them)."""

    def follow(self, level: GridLevel) -> None:
        """Take the level's current arrays and offsets."""


class MapTooLargeError(RuntimeError):
    """Integrating a scan would grow the map beyond its memory limit (the scan is not integrated)."""


#: Bytes from which a level's grown log-odds and update-index arrays are made zeroed (:func:`_zeroed`), with only the
#: old array's rows that hold a non-zero cell copied (:meth:`GridLevel._grow`; smaller arrays, e.g. the loop closer's
#: submaps, which grow often, are filled and copied whole).
_ZEROED_BYTES = 1 << 20
#: A level's per-cell arrays: (attribute, value of a cell never updated, dtype), in the order :meth:`GridLevel.ensure`
#: grows them (the log-odds last: the tracker's view of the last scan's map keeps the old ones until the next scan).
_LEVEL_ARRAYS = (("prob", 0, np.uint32), ("uidx", 0, np.int32), ("logodds", 0.0, np.float32))
#: The bits of float32 0.5: a level's probability cache holds each cell's float32 probability's bits XOR these
#: (:func:`encode_probs`), so a cell never updated (0.5) is a zero word — a large level's cache lives in zeroed
#: memory like its log-odds, and only its pages holding an updated cell take memory (docs/speed.md pass mem52).
#: Decoding is the same XOR and a bit cast: no rounding, every value's bits kept.
PROB_HALF_BITS = 0x3F000000


def encode_probs(p: np.ndarray) -> np.ndarray:
    """The probability cache's words (uint32) of probabilities ``p`` (rounded to float32 first): bits XOR
    :data:`PROB_HALF_BITS`."""
    return np.asarray(p, dtype=np.float32).view(np.uint32) ^ np.uint32(PROB_HALF_BITS)


def decode_probs(words: np.ndarray) -> np.ndarray:
    """The float32 probabilities of probability cache words ``words`` (uint32; a new array, same shape)."""
    return (np.asarray(words, dtype=np.uint32) ^ np.uint32(PROB_HALF_BITS)).view(np.float32)


#: the source of :attr:`GridLevel.geometry_stamp`: every value is taken once, by one level's geometry
_GEOMETRY_STAMPS = count(1)


def _zeroed(shape: tuple[int, int], dtype: type) -> np.ndarray:
    """A C-contiguous zero array in its own anonymous memory map: its pages take no memory until written, whatever
    the allocator's state (``np.zeros``' calloc clears a block the heap reuses, touching every page: glibc serves
    blocks below its adaptive mmap threshold, up to 32 MiB, from the heap); unmapped when the array goes."""
    return _zeroed_map(shape, dtype)[0]


def _zeroed_map(shape: tuple[int, int], dtype: type) -> tuple[np.ndarray, mmap.mmap]:
    """:func:`_zeroed`'s array and its memory map, private (``MAP_PRIVATE``: a map that :meth:`GridLevel._grow` can
    extend in place with ``mremap``; a shared anonymous map's new pages would be past the end of its shared memory
    object)."""
    dt = np.dtype(dtype)
    n = shape[0] * shape[1]
    flags = getattr(mmap, "MAP_PRIVATE", 0) | getattr(mmap, "MAP_ANONYMOUS", 0)
    mm = mmap.mmap(-1, max(n * dt.itemsize, 1), flags=flags) if flags else mmap.mmap(-1, max(n * dt.itemsize, 1))
    return np.frombuffer(mm, dtype=dt, count=n).reshape(shape), mm


#: Bytes of the old array :func:`_copy_written_rows` copies before it gives their pages back (a page multiple): the
#: growth's transient above the old level is about this, not a whole new array (docs/speed.md, pass mem120).
_RELEASE_BLOCK = 1 << 18
#: Rows per block whose span of written columns :func:`_copy_written_rows` copies as one slice.
_SPAN_ROWS = 8
#: ``madvise``'s "drop these pages" (a private anonymous map's pages read as zeros afterwards); None without it.
_MADV_DONTNEED = getattr(mmap, "MADV_DONTNEED", None)


def _holder_counts(arr: np.ndarray, entry: tuple[weakref.ref, int] | None) -> tuple[int, int, int, int] | None:
    """The reference counts of ``arr`` (a level's array), of the array and memoryview that hold its memory and of its
    memory map (``entry``: a ``GridLevel._maps`` entry), as seen from a call with ``arr`` in one name of the caller;
    None when ``arr`` is not that map's whole array as :func:`_zeroed_map` made it. A view of ``arr`` (a slice: its
    base is the 1-D array) or another array of the map (a memoryview of it) raises a count."""
    mm = None if entry is None else entry[0]()
    if mm is None or arr.__array_interface__["data"][0] != entry[1]:
        return None
    base = arr.base
    buf = getattr(base, "base", None)
    if not isinstance(base, np.ndarray) or not isinstance(buf, memoryview) or buf.obj is not mm:
        return None
    return sys.getrefcount(arr), sys.getrefcount(base), sys.getrefcount(buf), sys.getrefcount(mm)


@cache
def _sole_counts() -> tuple[int, int, int, int] | None:
    """:func:`_holder_counts` of an array of :func:`_zeroed_map` that nothing views, held by one name (this
    interpreter's counts: measured, not assumed)."""
    arr, mm = _zeroed_map((1, 1), np.float32)
    entry = (weakref.ref(mm), arr.__array_interface__["data"][0])
    del mm
    return _holder_counts(arr, entry)


def _copy_written_rows(dst: np.ndarray, src: np.ndarray, release: mmap.mmap | None = None) -> None:
    """``dst[...] = src`` (2-D, same shape; ``dst`` zeroed) for the cells of ``src`` whose bits are not all zero:
    per block of :data:`_SPAN_ROWS` rows, the columns from the block's first to its last such cell, as one slice copy
    (blocks without one are skipped). The zeros left out are not written, so the pages of ``dst`` that would hold only
    zeros are never touched and take no memory: whole rows copied touched ≈ 4 % more pages on MIT CSAIL's finest
    level than its non-zero cells need (docs/speed.md, pass mem120). A plain copy's speed where
    ``np.copyto(..., where=mask)`` took 24 times as long (a per-cell mask).

    ``release``: the memory map whose first bytes are ``src`` (C-contiguous), which nothing reads after this call:
    each block of about :data:`_RELEASE_BLOCK` bytes of ``src`` copied, its whole pages are given back to the system
    (``MADV_DONTNEED``), so the old and the new array are never both resident (``src`` reads as zeros after)."""
    h, w = src.shape
    if h == 0 or w == 0:
        return
    k = _SPAN_ROWS
    nb = -(-h // k)
    words = src.view(np.int32)
    occ = np.empty((nb, w), dtype=bool)  # (a block's columns holding a non-zero cell)
    np.any(words[:h // k * k].reshape(-1, k, w), axis=1, out=occ[:h // k])
    if h % k:
        np.any(words[h // k * k:], axis=0, out=occ[-1])
    first = occ.argmax(axis=1).tolist()
    stop = (w - occ[:, ::-1].argmax(axis=1)).tolist()
    blocks = np.flatnonzero(occ.any(axis=1)).tolist()
    del occ
    if release is None or _MADV_DONTNEED is None or not src.flags.c_contiguous:
        for b in blocks:
            a, e, c, d = b * k, min(b * k + k, h), first[b], stop[b]
            dst[a:e, c:d] = src[a:e, c:d]
        return
    row_bytes = src.strides[0]
    done = 0  # bytes of ``src`` given back so far (a page multiple)
    for b in blocks:
        a, e, c, d = b * k, min(b * k + k, h), first[b], stop[b]
        dst[a:e, c:d] = src[a:e, c:d]
        if (e * row_bytes - done) >= _RELEASE_BLOCK:
            done = _give_back(release, done, e * row_bytes)
    _give_back(release, done, h * row_bytes)


def _give_back(mm: mmap.mmap, start: int, end: int) -> int:
    """Give the whole pages of ``mm``'s bytes [``start``, ``end``) back to the system (``start`` a page multiple);
    returns the end of what was given back (``start`` when less than a page)."""
    stop = end - end % mmap.PAGESIZE
    if stop > start:
        try:
            mm.madvise(_MADV_DONTNEED, start, stop - start)
        except (OSError, ValueError):  # (a system that refuses: the pages go when the array does)
            return start
        return stop
    return start


class GridLevel:
    """One log-odds grid level.

    Attributes:
        resolution: cell side, m.
        logodds: (H, W) float32 log-odds, 0 = unknown (hector_mapping GridMapLogOdds.h).
        prob: (H, W) uint32 occupancy probability cache, kept in step with ``logodds``: each cell's float32
            probability's bits XOR :data:`PROB_HALF_BITS` (0 = 0.5, never updated; :func:`decode_probs`).
        uidx: (H, W) int32 per-cell update index, as OccGridMapBase's updateIndex, 0 = never updated (the reference's
            −1: a scan's indices are ≥ 1, so every comparison with them reads the same; 0 lets a large level's
            array be zeroed memory whose pages no ray reached are never touched, docs/speed.md pass mem43).
        i0, j0: absolute cell index of array column 0 / row 0.
        geometry_stamp: a number, unique among all levels and all their states, taken anew whenever ``resolution``,
            ``i0``, ``j0`` or the emptiness of ``logodds`` may have changed (made, released, grown; these are written
            only here): two equal stamps mean the same level with the same (resolution, i0, j0, empty), so a
            matcher can key what it derives from them on the stamps alone (``matcher._level_geometry``).
        occ_bits: (H, ⌈W / 64⌉) uint64 bitmap of the long-occupied cells (bit ``col & 63`` of word ``[row, col >> 6]``)
            for the threshold ``occ_bits_thr`` (NaN and a (0, 0) array: not kept; :meth:`keep_long_occupied`).
            Invariant: every cell whose stored float32 log-odds, compared as float64, is ≥ ``occ_bits_thr`` has its
            bit set; a set bit may be stale (its cell lowered since). Kept by every writer of the level: the
            occupied updates (``raycast._rays``), growth, :meth:`mark_long_occupied` (the erasure).
    """

    def __init__(self, resolution: float, growth_margin_cells: int = 100) -> None:
        self.resolution = float(resolution)
        self.growth_margin_cells = max(int(growth_margin_cells), 1)
        self.logodds: np.ndarray
        self.prob: np.ndarray
        self.uidx: np.ndarray
        #: the memory maps of the arrays made by :func:`_zeroed_map` (name → (weak reference to the map, address of
        #: the array's data); weak: an array replaced from outside lets its map go): :meth:`_grow` extends them in
        #: place when the level grows by rows at its top
        self._maps: dict[str, tuple[weakref.ref, int]] = {}
        #: the views that follow the level's growth (:meth:`follow`)
        self._followers: weakref.WeakSet[LevelFollower] = weakref.WeakSet()
        self.occ_bits = _NO_BITS
        self.occ_bits_thr = math.nan
        self.release()
        self.i0 = 0
        self.j0 = 0
        self.update_counter = 0  # hector's currUpdateIndex (grows by 3 per scan)
        self.n_grows = 0
        self.geometry_stamp = next(_GEOMETRY_STAMPS)

    # ---- geometry -------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return self.logodds.shape  # type: ignore[return-value]

    @property
    def empty(self) -> bool:
        return self.logodds.size == 0

    def world_to_map(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) world points, m → (n, 2) array map coordinates, cells (cell centres at integers)."""
        xy = np.asarray(xy, dtype=np.float64)
        out = xy / self.resolution
        out[..., 0] -= self.i0
        out[..., 1] -= self.j0
        return out

    def map_to_world(self, m: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`world_to_map`."""
        m = np.asarray(m, dtype=np.float64).copy()
        m[..., 0] += self.i0
        m[..., 1] += self.j0
        return m * self.resolution

    def pose_to_map(self, pose: np.ndarray) -> np.ndarray:
        """World pose (x m, y m, θ rad) → array map pose (x cells, y cells, θ rad)."""
        return np.array(
            [pose[0] / self.resolution - self.i0, pose[1] / self.resolution - self.j0, pose[2]],
            dtype=np.float64,
        )

    def pose_to_world(self, mpose: np.ndarray) -> np.ndarray:
        """Array map pose → world pose (inverse of :meth:`pose_to_map`)."""
        return np.array(
            [(mpose[0] + self.i0) * self.resolution, (mpose[1] + self.j0) * self.resolution, mpose[2]],
            dtype=np.float64,
        )

    @property
    def nbytes(self) -> int:
        return int(self.logodds.nbytes + self.prob.nbytes + self.uidx.nbytes)

    def release(self, *names: str) -> None:
        """Replace the arrays ``names`` ("logodds", "prob", "uidx"; all when none are given) by empty (0, 0) ones,
        freeing their memory (the level's offsets are kept)."""
        for name, fill, dtype in _LEVEL_ARRAYS:
            if not names or name in names:
                setattr(self, name, np.full((0, 0), fill, dtype=dtype))
                self._maps.pop(name, None)
        if not names or "logodds" in names:
            self.occ_bits = _NO_BITS if self.occ_bits_thr != self.occ_bits_thr else self._bits_of(None)
            self.geometry_stamp = next(_GEOMETRY_STAMPS)  # (now empty)

    # ---- long-occupied bitmap ------------------------------------------------------------
    def keep_long_occupied(self, thr: float) -> None:
        """Keep :attr:`occ_bits` for log-odds ≥ ``thr`` (> 0: a never-updated cell, 0, is below it) from now on,
        built from the level as it is (NaN: keep none)."""
        thr = float(thr)
        if not thr > 0.0:
            self.occ_bits_thr = math.nan
            self.occ_bits = _NO_BITS
            return
        self.occ_bits_thr = thr
        self.occ_bits = self._bits_of(None)

    def _bits_of(self, rows: np.ndarray | None) -> np.ndarray:
        """A new bitmap of the level for :attr:`occ_bits_thr`, exact (no stale bit) on ``rows`` (array rows; None:
        all) and 0 elsewhere."""
        h, w = self.logodds.shape
        nw = (w + 63) >> 6
        out = np.zeros((h, nw), dtype=np.uint64)
        if h == 0 or w == 0:
            return out
        lo = self.logodds if rows is None else self.logodds[rows]
        occ = np.zeros((lo.shape[0], nw * 64), dtype=bool)
        np.greater_equal(lo, np.float64(self.occ_bits_thr), out=occ[:, :w])  # (as float64: not NumPy's weak float)
        words = np.packbits(occ, axis=1, bitorder="little").view("<u8")  # (bit c & 63 of word c >> 6)
        if rows is None:
            out[:] = words
        else:
            out[rows] = words
        return out

    def mark_long_occupied(self, row: np.ndarray, col: np.ndarray) -> None:
        """After a write of the cells (``row``, ``col``) (array indices, int64) outside the ray kernel: set the bits
        of those now ≥ :attr:`occ_bits_thr` (nothing when no bitmap is kept)."""
        if self.occ_bits_thr != self.occ_bits_thr or row.shape[0] == 0:
            return
        up = self.logodds[row, col].astype(np.float64) >= self.occ_bits_thr
        if up.any():
            r, c = row[up], col[up]
            np.bitwise_or.at(self.occ_bits, (r, c >> 6), np.left_shift(np.uint64(1), (c & 63).astype(np.uint64)))

    # ---- growth -----------------------------------------------------------------------
    def _grown_bounds(self, imin: int, jmin: int, imax: int, jmax: int) -> tuple[int, int, int, int] | None:
        """(i0, j0, i1, j1) of the array after growing to hold [imin, imax] × [jmin, jmax], or None
        if it already does."""
        h, w = self.shape
        if w > 0 and imin >= self.i0 and jmin >= self.j0 and imax < self.i0 + w and jmax < self.j0 + h:
            return None
        if w == 0:
            m = self.growth_margin_cells
            return imin - m, jmin - m, imax + m + 1, jmax + m + 1
        mx = max(self.growth_margin_cells, w // 4)
        my = max(self.growth_margin_cells, h // 4)
        ni0 = min(self.i0, imin - mx) if imin < self.i0 else self.i0
        nj0 = min(self.j0, jmin - my) if jmin < self.j0 else self.j0
        ni1 = max(self.i0 + w, imax + 1 + mx) if imax >= self.i0 + w else self.i0 + w
        nj1 = max(self.j0 + h, jmax + 1 + my) if jmax >= self.j0 + h else self.j0 + h
        return ni0, nj0, ni1, nj1

    def bytes_after_growth(self, imin: int, jmin: int, imax: int, jmax: int) -> int:
        """Bytes this level would hold after :meth:`ensure` with these bounds."""
        b = self._grown_bounds(imin, jmin, imax, jmax)
        if b is None:
            return self.nbytes
        return (b[2] - b[0]) * (b[3] - b[1]) * _BYTES_PER_CELL

    def ensure(self, imin: int, jmin: int, imax: int, jmax: int) -> bool:
        """Make absolute cells [imin, imax] × [jmin, jmax] part of the array (content kept).

        Grows only the sides that need it, by at least ``growth_margin_cells`` and 25 % of the
        current size, so repeated growth is amortised. Returns True if the array was reallocated.
        """
        b = self._grown_bounds(imin, jmin, imax, jmax)
        if b is None:
            return False
        self._grow(b)
        return True

    def _grow(self, b: tuple[int, int, int, int]) -> None:
        """Reallocate the arrays to absolute cells [b[0], b[2]) × [b[1], b[3]) (bounds of :meth:`_grown_bounds`),
        content kept."""
        h, w = self.shape
        ni0, nj0, ni1, nj1 = b
        nw, nh = ni1 - ni0, nj1 - nj0
        c0, r0 = self.i0 - ni0, self.j0 - nj0
        # the views of the level (the tracker's map evidence) let the old arrays go first: only the level holds them
        # while they are copied, so their pages can be given back block by block (pass mem120)
        followers = list(self._followers) if self._followers else ()
        for v in followers:
            v.detach()
        # one array at a time, each old one let go before the next new one is made: the transient is the old
        # level plus one new array, not old and new levels side by side (MIT CSAIL's last growth of the finest
        # level: 47 instead of 67 MiB; docs/speed.md "Memory, eighth pass").
        # Each cell of the new array is written once (pass rest18): the old array into its place, the fill value
        # into the strips around it — not the whole array filled and then the old part written over (the loop
        # closer's submaps grow on most keyframes they take in; ≈ 40 % less time per growth).
        for name, fill, dtype in _LEVEL_ARRAYS:
            if nh * nw * 4 >= _ZEROED_BYTES:
                # a large level's log-odds (0 = unknown), probability cache (0 = 0.5) and update indices (0 = never)
                # in zeroed memory, only the old array's rows that hold a non-zero cell copied (a −0.0 does: its
                # bits are not zero): pages no ray reached are never touched and take no memory (12.5 % of MIT
                # CSAIL's finest level was ever updated; docs/speed.md passes mem39, mem43 and mem52)
                if w == nw and r0 == 0 and self._extend_rows(name, dtype, h, nh):
                    continue
                new, mm = _zeroed_map((nh, nw), dtype)
                if w > 0:
                    old = getattr(self, name)
                    setattr(self, name, new)  # (the level lets the old array go before it is copied)
                    # (its pages given back while it is copied only when nothing else views it: the counts of the
                    # references to it and to what holds its memory are those of an array held by one name)
                    sole = _holder_counts(old, self._maps.get(name)) == _sole_counts()
                    old_map = self._maps[name][0]() if sole else None
                    _copy_written_rows(new[r0:r0 + h, c0:c0 + w], old, old_map)
                    del old, old_map
                setattr(self, name, new)
                self._maps[name] = (weakref.ref(mm), new.__array_interface__["data"][0])
                continue
            self._maps.pop(name, None)
            new = np.empty((nh, nw), dtype=dtype)
            if w > 0:
                new[r0:r0 + h, c0:c0 + w] = getattr(self, name)
                new[:r0] = fill  # (rows below, then above the old array; then its rows' left and right parts)
                new[r0 + h:] = fill
                new[r0:r0 + h, :c0] = fill
                new[r0:r0 + h, c0 + w:] = fill
            else:
                new.fill(fill)
            setattr(self, name, new)
        if self.occ_bits_thr == self.occ_bits_thr:
            # the bitmap of the grown level: the new cells are 0 (never updated), below the threshold; every old cell
            # at or above it is on a row with a set bit (the invariant), so only those rows are re-read
            old = self.occ_bits
            rows = np.flatnonzero(old.any(axis=1)) + r0 if old.size else np.zeros(0, dtype=np.int64)
            self.occ_bits = self._bits_of(rows)
        self.i0, self.j0 = ni0, nj0
        self.n_grows += 1
        self.geometry_stamp = next(_GEOMETRY_STAMPS)
        for v in followers:
            v.follow(self)

    def follow(self, view: LevelFollower) -> None:
        """Keep ``view`` (which holds this level's arrays) in step with the level: when the level grows, ``view``
        lets the old arrays go before they are copied (:meth:`LevelFollower.detach`) and is pointed at the grown
        ones after (:meth:`LevelFollower.follow`), as a view made after the growth would be. Held weakly."""
        self._followers.add(view)

    def _extend_rows(self, name: str, dtype: type, h: int, nh: int) -> bool:
        """Grow array ``name`` ((``h``, W), made by :func:`_zeroed_map`) to ``nh`` rows at its top in place: its memory
        map extended (``mremap``: the old pages are kept where they are, nothing is copied or read, the new rows are
        zero pages not yet touched), the same content as a new zeroed array with the old one copied into its first
        rows. False, with the array unchanged, when it is not its map's array any more, when another array still
        views it (a map cannot be resized then) or the system has no ``mremap``: :meth:`_grow` copies instead."""
        entry = self._maps.get(name)
        mm = None if entry is None else entry[0]()
        cur = getattr(self, name)
        if mm is None or cur.__array_interface__["data"][0] != entry[1] or cur.shape[0] != h:
            return False
        w = cur.shape[1]
        setattr(self, name, _NO_ROWS)
        del cur  # (the map's only views must go before it can be resized)
        dt = np.dtype(dtype)
        try:
            mm.resize(max(nh * w * dt.itemsize, 1))
        except (BufferError, OSError, SystemError, ValueError, TypeError):
            setattr(self, name, np.frombuffer(mm, dtype=dt, count=h * w).reshape(h, w))
            return False
        new = np.frombuffer(mm, dtype=dt, count=nh * w).reshape(nh, w)
        setattr(self, name, new)
        self._maps[name] = (weakref.ref(mm), new.__array_interface__["data"][0])
        return True

    def cell_bounds(self, origin_xy: np.ndarray, ends_xy: np.ndarray) -> tuple[int, int, int, int]:
        """(imin, jmin, imax, jmax) absolute cells covering a ray origin and its ends (world, m)."""
        r = self.resolution
        s_abs = np.floor(np.asarray(origin_xy, dtype=np.float64) / r + 0.5)
        e = np.asarray(ends_xy, dtype=np.float64)
        # v ↦ floor(v / r + 0.5) is monotonic: the cells of the extreme ends are the extreme cells
        e_lo = np.floor(e.min(axis=0) / r + 0.5)
        e_hi = np.floor(e.max(axis=0) / r + 0.5)
        return (
            int(min(s_abs[0], e_lo[0])), int(min(s_abs[1], e_lo[1])),
            int(max(s_abs[0], e_hi[0])), int(max(s_abs[1], e_hi[1])),
        )

    # ---- update -----------------------------------------------------------------------
    def integrate(
        self,
        origin_xy: np.ndarray,
        ends_xy: np.ndarray,
        hit: np.ndarray,
        l_free: float,
        l_occ: float,
        cap: float,
        stop: np.ndarray | None = None,
    ) -> int:
        """Integrate one scan: rays from world point ``origin_xy`` (2,) to ``ends_xy`` (n, 2), m.

        ``hit`` (n,) bool: True = return (endpoint occupied), False = clearing ray (all free).
        Cells are the reference's rounding of map coordinates (``floor(v + 0.5)``,
        OccGridMapBase::updateByScan). Grows the level first so that no ray is dropped. Returns the number
        of rays integrated. ``stop`` (n,) optional: per ray, its last ``stop`` cells (endpoint included) get
        no free update (:func:`~dynslam2d.slam.raycast.integrate_rays_stop`; None = the reference's update).
        """
        r = self.resolution
        s_abs = np.floor(np.asarray(origin_xy, dtype=np.float64) / r + 0.5).astype(np.int64)
        e_abs = np.floor(np.asarray(ends_xy, dtype=np.float64) / r + 0.5).astype(np.int64)
        if e_abs.shape[0] == 0:
            return 0
        imin = int(min(s_abs[0], e_abs[:, 0].min()))
        imax = int(max(s_abs[0], e_abs[:, 0].max()))
        jmin = int(min(s_abs[1], e_abs[:, 1].min()))
        jmax = int(max(s_abs[1], e_abs[:, 1].max()))
        self.ensure(imin, jmin, imax, jmax)
        ex = np.ascontiguousarray(e_abs[:, 0] - self.i0)
        ey = np.ascontiguousarray(e_abs[:, 1] - self.j0)
        return self.integrate_cells(int(s_abs[0] - self.i0), int(s_abs[1] - self.j0), ex, ey, hit,
                                    l_free, l_occ, cap, stop)

    def integrate_cells(self, sx: int, sy: int, ex: np.ndarray, ey: np.ndarray, hit: np.ndarray,
                        l_free: float, l_occ: float, cap: float, stop: np.ndarray | None = None) -> int:
        """:meth:`integrate` with the rays already in array cells: from (``sx``, ``sy``) to (``ex[k]``,
        ``ey[k]``) (int64, the level already grown to hold them; cells outside are skipped). One scan's
        update: takes the next update indices. Returns the number of rays integrated."""
        free_idx = self.update_counter + 1
        occ_idx = self.update_counter + 2
        self.update_counter += 3
        if self.occ_bits_thr == self.occ_bits_thr:  # (a kept bitmap on this rare way: rebuilt whole after the rays)
            n = self._integrate_cells(sx, sy, ex, ey, hit, l_free, l_occ, cap, stop, free_idx, occ_idx)
            self.occ_bits = self._bits_of(None)
            return n
        return self._integrate_cells(sx, sy, ex, ey, hit, l_free, l_occ, cap, stop, free_idx, occ_idx)

    def _integrate_cells(self, sx: int, sy: int, ex: np.ndarray, ey: np.ndarray, hit: np.ndarray, l_free: float,
                         l_occ: float, cap: float, stop: np.ndarray | None, free_idx: int, occ_idx: int) -> int:
        """:meth:`integrate_cells`' kernel call with the scan's update indices."""
        if stop is not None:
            return int(integrate_rays_stop(
                self.logodds, self.prob, self.uidx, free_idx, occ_idx, int(sx), int(sy), ex, ey,
                np.ascontiguousarray(hit, dtype=np.bool_), np.ascontiguousarray(stop, dtype=np.float64),
                float(l_free), float(l_occ), float(cap)))
        return int(
            integrate_rays(
                self.logodds, self.prob, self.uidx, free_idx, occ_idx, int(sx), int(sy), ex, ey,
                np.ascontiguousarray(hit, dtype=np.bool_), float(l_free), float(l_occ), float(cap),
            )
        )

    # ---- export -----------------------------------------------------------------------
    def known_bounds(self) -> tuple[int, int, int, int] | None:
        """(row0, row1, col0, col1) half-open array bounds of the observed cells, or None."""
        if self.empty:
            return None
        seen = self.uidx > 0
        rows = np.flatnonzero(seen.any(axis=1))
        if rows.size == 0:
            return None
        cols = np.flatnonzero(seen.any(axis=0))
        return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1

    def corner_origin(self, row0: int = 0, col0: int = 0) -> tuple[float, float]:
        """World (x, y) of the lower-left corner of array cell (row0, col0), m."""
        r = self.resolution
        return ((self.i0 + col0 - 0.5) * r, (self.j0 + row0 - 0.5) * r)


class MultiResMap:
    """The level pyramid: level k at ``map_resolution·2^k``, each updated from the full scan
    at the same pose (Kohlbrecher et al., SSRR 2011 §IV-C, MapRepMultiMap; no downsampling of maps
    or scans)."""

    def __init__(
        self,
        resolution: float,
        levels: int,
        l_free: float,
        l_occ: float,
        cap: float = 50.0,
        growth_margin: float = 5.0,
        max_bytes: int | None = None,
        grazing_cells: float = 0.0,
        min_incidence_deg: float = 5.0,
    ) -> None:
        self.grazing_cells = float(grazing_cells)  # 0 = the reference's free update (see grazing_stop)
        self.min_sin = math.sin(math.radians(min_incidence_deg))
        self.levels = [
            GridLevel(resolution * 2**k, growth_margin_cells=math.ceil(growth_margin / (resolution * 2**k)))
            for k in range(levels)
        ]
        self.l_free = float(l_free)
        self.l_occ = float(l_occ)
        self.cap = float(cap)
        self.version = 0  # incremented by every integration
        self.max_bytes = max_bytes

    @property
    def resolution(self) -> float:
        return self.levels[0].resolution

    def keep_long_occupied(self, thr: float) -> None:
        """Keep the finest level's bitmap of cells with log-odds ≥ ``thr`` (:meth:`GridLevel.keep_long_occupied`;
        the vacated-footprint trace reads it). Not kept when a free update could raise a cell (``l_free`` > 0)."""
        self.levels[0].keep_long_occupied(thr if self.l_free <= 0.0 else math.nan)

    @property
    def empty(self) -> bool:
        return self.levels[0].logodds.size == 0  # (the finest level's GridLevel.empty, read directly: every scan)

    @property
    def memory_bytes(self) -> int:
        """Bytes held by all levels (log-odds, probability cache, update indices)."""
        return sum(lv.nbytes for lv in self.levels)

    def _integrate_fused(self, hits: np.ndarray, clear: np.ndarray, c: float, s: float, ox: float, oy: float,
                         stop: np.ndarray | None) -> int:
        """One scan into every level (at most ``_FUSED_LEVELS``) by one call of ``raycast.integrate_levels``
        (``hits`` (n, 2), ``clear`` (m, 2) laser frame, m; laser pose ``ox``, ``oy`` m, cos ``c``, sin ``s``;
        ``stop`` as :func:`grazing_stop`, or None). Returns the rays integrated on level 0, or −1 with nothing
        written (and the update counters unchanged) when a level must grow first, an end is not finite or the
        map is over its limit. The cells are written in ``raycast._rays``."""
        levels = self.levels
        n_lv = len(levels)
        if n_lv == 3:  # (the default map: the arguments written out, padded to four levels)
            la, lb, lc = levels
            n0 = integrate_levels(
                hits, clear, c, s, ox, oy, (la.logodds, lb.logodds, lc.logodds, _NO_F32),
                (la.prob, lb.prob, lc.prob, _NO_U32), (la.uidx, lb.uidx, lc.uidx, _NO_I32), 3,
                (la.resolution, lb.resolution, lc.resolution, 1.0), (la.i0, lb.i0, lc.i0, 0), (la.j0, lb.j0, lc.j0, 0),
                (la.update_counter, lb.update_counter, lc.update_counter, 0),
                stop if stop is not None else _NO_STOP, stop is not None,
                -1 if self.max_bytes is None else self.max_bytes, self.l_free, self.l_occ, self.cap,
                la.occ_bits, la.occ_bits_thr)
        else:  # (other counts: the tuples padded to four, one kernel specialisation)
            pad = _FUSED_LEVELS - n_lv
            n0 = integrate_levels(
                hits, clear, c, s, ox, oy, tuple(lv.logodds for lv in levels) + (_NO_F32,) * pad,
                tuple(lv.prob for lv in levels) + (_NO_U32,) * pad,
                tuple(lv.uidx for lv in levels) + (_NO_I32,) * pad, n_lv,
                tuple(lv.resolution for lv in levels) + (1.0,) * pad,
                tuple(lv.i0 for lv in levels) + (0,) * pad, tuple(lv.j0 for lv in levels) + (0,) * pad,
                tuple(lv.update_counter for lv in levels) + (0,) * pad,
                stop if stop is not None else _NO_STOP, stop is not None,
                -1 if self.max_bytes is None else self.max_bytes, self.l_free, self.l_occ, self.cap,
                levels[0].occ_bits, levels[0].occ_bits_thr)
        if n0 < 0:
            return -1
        for lv in levels:
            lv.update_counter += 3  # (GridLevel.integrate_cells: a scan takes the next three update indices)
        self.version += 1
        return int(n0)

    def integrate(self, pose: Pose2D, hits_laser: np.ndarray, clear_laser: np.ndarray | None = None) -> int:
        """Integrate a scan taken at laser pose ``pose`` (map frame) into every level.

        ``hits_laser``: (n, 2) returns in the laser frame, m. ``clear_laser``: (m, 2) ends of
        free-space clearing rays in the laser frame (optional). Returns the rays integrated on
        level 0. The caller must have checked the pose is finite.
        """
        # (the processor's points: (n, 2) float64 arrays, taken as they are — np.asarray(…).reshape(-1, 2) of such an
        # array is a view of the same values)
        hits = hits_laser if type(hits_laser) is np.ndarray and hits_laser.dtype is _F64 and hits_laser.ndim == 2 \
            and hits_laser.shape[1] == 2 else np.asarray(hits_laser, dtype=np.float64).reshape(-1, 2)
        n_hit = hits.shape[0]
        clear = _NO_CLEAR if clear_laser is None else np.asarray(clear_laser, dtype=np.float64).reshape(-1, 2)
        n = n_hit + clear.shape[0]
        if n == 0:
            return 0
        stop = None
        if self.grazing_cells > 0.0:
            stop = np.zeros(n)
            stop[:n_hit] = grazing_stop(hits, self.grazing_cells, self.min_sin)
        th = pose.theta
        c, s = math.cos(th), math.sin(th)
        ox, oy = float(pose.x), float(pose.y)
        levels = self.levels
        n_lv = len(levels)
        if n_lv == 3 and stop is None:
            # (:meth:`_integrate_fused` of the default map without grazing stops, inline: one call less on every
            # map update; the same kernel call and bookkeeping)
            la, lb, lc = levels
            mb = self.max_bytes
            n0 = integrate_levels(
                hits, clear, c, s, ox, oy, (la.logodds, lb.logodds, lc.logodds, _NO_F32),
                (la.prob, lb.prob, lc.prob, _NO_U32), (la.uidx, lb.uidx, lc.uidx, _NO_I32), 3,
                (la.resolution, lb.resolution, lc.resolution, 1.0), (la.i0, lb.i0, lc.i0, 0), (la.j0, lb.j0, lc.j0, 0),
                (la.update_counter, lb.update_counter, lc.update_counter, 0), _NO_STOP, False,
                -1 if mb is None else mb, self.l_free, self.l_occ, self.cap, la.occ_bits, la.occ_bits_thr)
            if n0 >= 0:
                la.update_counter += 3
                lb.update_counter += 3
                lc.update_counter += 3
                self.version += 1
                return int(n0)
        elif n_lv <= _FUSED_LEVELS:
            # every level in one kernel call, which writes nothing and returns −1 when a level must grow first
            # (or an end is not finite, or the map is over its limit): the way below
            n0 = self._integrate_fused(hits, clear, c, s, ox, oy, stop)
            if n0 >= 0:
                return n0
        # the rays' ends in the map frame as two contiguous rows (the arithmetic of Pose2D.transform_points,
        # element by element, so the same values), the hit flags and the ends' extremes, in one kernel call
        ends_t, hit, box = ray_ends(hits, clear, c, s, ox, oy)
        # every level's cell bounds from the extreme ends: v ↦ floor(v / r + 0.5) is monotonic, so the
        # extreme ends give the extreme cells (as GridLevel.cell_bounds), with a few scalar operations
        box = box.tolist()
        lo, hi = box[:2], box[2:]
        bounds = []
        for lv in levels:
            r = lv.resolution
            sx, sy = math.floor(ox / r + 0.5), math.floor(oy / r + 0.5)
            bounds.append((sx, sy, min(sx, math.floor(lo[0] / r + 0.5)), min(sy, math.floor(lo[1] / r + 0.5)),
                           max(sx, math.floor(hi[0] / r + 0.5)), max(sy, math.floor(hi[1] / r + 0.5))))
        # each level's bounds after growth (None: it holds the scan already), computed once for the limit and the growth
        grown = [lv._grown_bounds(*b[2:]) for lv, b in zip(levels, bounds)]
        if self.max_bytes is not None:
            need = sum(lv.nbytes if g is None else (g[2] - g[0]) * (g[3] - g[1]) * _BYTES_PER_CELL
                       for lv, g in zip(levels, grown))  # (GridLevel.bytes_after_growth)
            if need > self.max_bytes:
                raise MapTooLargeError(
                    f"integrating this scan would grow the map to {need / 1e6:.0f} MB "
                    f"(limit {self.max_bytes / 1e6:.0f} MB)"
                )
        for lv, g in zip(levels, grown):
            if g is not None:
                lv._grow(g)  # (GridLevel.ensure)
        if n_lv <= _FUSED_LEVELS:  # every level holds the scan now: the fused call again
            n0 = self._integrate_fused(hits, clear, c, s, ox, oy, stop)
            if n0 < 0:
                raise ValueError("a level's arrays differ in shape (released?): the scan cannot be integrated")
            return n0
        # the rays' end cells of a level, computed as GridLevel.integrate does (floor(v / r + 0.5), array
        # coordinates), into buffers shared by the levels: (2, n) rows are the contiguous x and y arrays
        buf = np.empty_like(ends_t)
        n0 = 0
        for k, (lv, (sx, sy, *_)) in enumerate(zip(self.levels, bounds)):
            np.divide(ends_t, lv.resolution, out=buf)
            buf += 0.5
            np.floor(buf, out=buf)
            cells = buf.astype(np.int64)
            cells[0] -= lv.i0
            cells[1] -= lv.j0
            n = lv.integrate_cells(sx - lv.i0, sy - lv.j0, cells[0], cells[1], hit,
                                   self.l_free, self.l_occ, self.cap, stop)
            if k == 0:
                n0 = n
        self.version += 1
        return n0

    def to_gridmap(self, level: int = 0, crop: bool = True) -> GridMap:
        """Level ``level`` as a :class:`GridMap` of probabilities (NaN = never updated).

        ``crop`` trims the array to the bounding box of observed cells.
        """
        lv = self.levels[level]
        if lv.empty:
            return GridMap(np.full((1, 1), np.nan), lv.resolution, lv.corner_origin())
        b = lv.known_bounds() if crop else None
        r0, r1, c0, c1 = b if b is not None else (0, lv.shape[0], 0, lv.shape[1])
        prob = logistic_map(lv.logodds[r0:r1, c0:c1], lv.uidx[r0:r1, c0:c1] < 1)
        return GridMap(prob, lv.resolution, lv.corner_origin(r0, c0))

    def export_logodds(self, level: int = 0, crop: bool = True) -> tuple[np.ndarray, tuple[float, float]]:
        """(log-odds (H, W) float32 copy, row 0 at the bottom; (x, y) world corner of cell (0, 0), m)."""
        lv = self.levels[level]
        if lv.empty:
            return np.zeros((1, 1), dtype=np.float32), lv.corner_origin()
        b = lv.known_bounds() if crop else None
        r0, r1, c0, c1 = b if b is not None else (0, lv.shape[0], 0, lv.shape[1])
        return lv.logodds[r0:r1, c0:c1].copy(), lv.corner_origin(r0, c0)


def logistic_map(logodds: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """(H, W) float64 occupancy probabilities 1 / (1 + exp(−l)) of float32 log-odds ``logodds``, NaN where
    ``unknown`` (bool, same shape): :meth:`MultiResMap.to_gridmap`'s values. Computed in place in one float64
    array, without three map-sized temporaries (the export is the end of the run loop's memory peak;
    docs/speed.md)."""
    prob = logodds.astype(np.float64)
    np.negative(prob, out=prob)
    np.exp(prob, out=prob)
    prob += 1.0
    np.divide(1.0, prob, out=prob)
    prob[unknown] = np.nan
    return prob


def grazing_stop(pts: np.ndarray, grazing_cells: float, min_sin: float) -> np.ndarray:
    """Per return of a scan (``pts`` (n, 2) laser frame, m, in beam order), how many cells before its
    endpoint the free-space update stops, in cells of any level: ``grazing_cells / max(sin α, min_sin)``.

    α is the incidence between the beam and the surface it hit, estimated from the neighbouring returns
    (``p[i+1] − p[i−1]``, one-sided at the ends; a depth jump reads as grazing, which only stops earlier).
    A ray meeting a surface at α runs within one cell of it for ``1 / sin α`` cells before the endpoint,
    so with the reference's update (every cell before the endpoint free) rays that graze a wall clear the
    wall cells other rays hit. Free space is therefore not written within the surface's extent along the
    ray: the inverse range sensor model of Thrun, Burgard & Fox, *Probabilistic Robotics* (2005), Table 9.2,
    gives no free update within the obstacle depth before the measured range; at incidence α a surface of
    thickness ``grazing_cells`` cells has depth ``grazing_cells / sin α`` along the ray (the same margin the
    Peopleremover's ray shortening and our clean-up pass use, docs/maps.md). At normal incidence the stop is
    ``grazing_cells`` (≤ 1.5 by default: nothing changes beyond the endpoint cell the reference skips)."""
    n = pts.shape[0]
    if n < 2:
        return np.full(n, float(grazing_cells))
    prev = np.vstack((pts[:1], pts[:-1]))
    nxt = np.vstack((pts[1:], pts[-1:]))
    t = nxt - prev
    tn = np.hypot(t[:, 0], t[:, 1])
    r = np.hypot(pts[:, 0], pts[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        sn = np.abs(pts[:, 0] * t[:, 1] - pts[:, 1] * t[:, 0]) / (tn * r)
    sn = np.where((tn > 0.0) & (r > 0.0) & np.isfinite(sn), sn, 1.0)
    return grazing_cells / np.maximum(sn, min_sin)
