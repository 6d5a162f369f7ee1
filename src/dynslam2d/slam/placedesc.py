"""Place descriptors: which older places look like the current one, cheaply (docs/slam.md, "Far search").

A place is described by the points a robot saw around a keyframe — the scans of the last few keyframes,
placed with the front end's relative poses in the keyframe's laser frame — as a polar occupancy image after
Scan Context (Kim & Kim, "Scan Context: Egocentric Spatial Descriptor for Place Recognition within 3D Point
Cloud Map", IROS 2018): ``rings`` range bins of ``max_range / rings`` m × ``sectors`` bearing bins, a cell
being 1 where any point falls (the 2D counterpart of Scan Context's maximum height). Comparing two places,
the column (sector) vectors are compared by cosine similarity at every circular shift of the sectors — a
rotation of the robot shifts the image's columns — and the distance is

    d(a, b) = min_shift 1 − Σ_j cos(a_j, b_(j − shift)) / |{j : a_j ≠ 0 or b_(j − shift) ≠ 0}|

(Kim & Kim, Eq. 5–6; here divided by the columns occupied in either image, so a place that sees much more
or much less than the other scores worse, not better). All shifts of all stored places are evaluated at
once as circular cross-correlations with the FFT along the sectors (the products of the spectra summed over
the rings in one kernel, :func:`_ring_correlation`). 0 = identical (up to rotation), 1 = nothing in common.

What it is for: ranking every older place by ``d`` and running the expensive correlative verification only
on the best few (:mod:`dynslam2d.slam.loops`, far search). It is no proof of a loop.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle


def polar_descriptor(points: np.ndarray, rings: int, sectors: int, max_range: float) -> np.ndarray:
    """(rings, sectors) float32 0/1 polar occupancy image of ``points`` ((n, 2), m, in the place's frame):
    ring k holds ranges [k, k+1)·max_range/rings, sector j bearings [j, j+1)·2π/sectors − π (rad)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros((rings, sectors), dtype=np.float32)
    if pts.shape[0] == 0:
        return out
    r = np.hypot(pts[:, 0], pts[:, 1])
    m = np.isfinite(r) & (r < max_range)
    if not m.any():
        return out
    ri = np.minimum((r[m] * (rings / max_range)).astype(np.int64), rings - 1)
    a = np.arctan2(pts[:, 1][m], pts[:, 0][m])  # (the kept points' columns: the values of pts[m, 1], faster)
    si = np.floor((a + math.pi) * (sectors / (2.0 * math.pi))).astype(np.int64) % sectors
    out[ri, si] = 1.0
    return out


def _spectra(desc: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(rfft of the column-normalised image (rings, sectors//2+1), rfft of its occupied-column indicator,
    number of occupied columns) of one descriptor."""
    d = np.asarray(desc, dtype=np.float64)
    norm = np.linalg.norm(d, axis=0)
    occ = norm > 0.0
    unit = d / np.where(occ, norm, 1.0)
    return np.fft.rfft(unit, axis=1), np.fft.rfft(occ.astype(np.float64)), int(occ.sum())


def polar_descriptors(points: list[np.ndarray], rings: int, sectors: int, max_range: float) -> np.ndarray:
    """(k, rings, sectors) float32: :func:`polar_descriptor` of each of the ``k`` point sets (``(n_i, 2)``, m) in
    one pass over all their points. Each element goes through the same NumPy operations (``hypot``, ``arctan2``,
    ``floor`` on contiguous float64 arrays) as in :func:`polar_descriptor`, so every image is the same bit for bit;
    the batch saves the per-call overhead of the ≈ 15 NumPy calls per place."""
    k = len(points)
    out = np.zeros((k, rings, sectors), dtype=np.float32)
    if k == 0:
        return out
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in points]
    counts = np.fromiter((p.shape[0] for p in pts), dtype=np.int64, count=k)
    allp = np.concatenate(pts) if k > 1 else pts[0]
    if allp.shape[0] == 0:
        return out
    r = np.hypot(allp[:, 0], allp[:, 1])
    m = np.isfinite(r) & (r < max_range)
    if not m.any():
        return out
    place = np.repeat(np.arange(k, dtype=np.int64), counts)[m]
    ri = np.minimum((r[m] * (rings / max_range)).astype(np.int64), rings - 1)
    # the kept points' y and x: a column's view masked is the same contiguous float64 array as ``allp[m, 1]`` (the
    # same elements in the same order) at about a seventh of the time (≈ 0.35 ms a batch of 16 places)
    a = np.arctan2(allp[:, 1][m], allp[:, 0][m])
    si = np.floor((a + math.pi) * (sectors / (2.0 * math.pi))).astype(np.int64) % sectors
    out[place, ri, si] = 1.0
    return out


def _spectra_many(descs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_spectra` of each of the descriptors ``descs`` ((k, rings, sectors)): (k, rings, sectors//2+1),
    (k, sectors//2+1) and (k,) int. The column norms are square roots of exact integer sums (0/1 images), the
    division is elementwise and NumPy's pocketfft transforms each row on its own: the same values as one call per
    descriptor."""
    d = np.asarray(descs, dtype=np.float64)
    norm = np.linalg.norm(d, axis=1)
    occ = norm > 0.0
    unit = d / np.where(occ, norm, 1.0)[:, None, :]
    return (np.fft.rfft(unit, axis=2), np.fft.rfft(occ.astype(np.float64), axis=1),
            occ.sum(axis=1).astype(np.int64))


@njit(cache=True)
def _ring_correlation(q_cols: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:  # pragma: no cover - numba
    """(n, f) complex128 ``Σ_r q_cols[r, f] · conj(cols[i, r, f])`` for the first ``n`` stored places: the product
    of the spectra of Scan Context's column correlation (Kim & Kim 2018, Eq. 5) summed over the rings.

    ``q_cols``: (rings, f) complex128, the query's spectra; ``cols``: (capacity, rings, f) complex64, the stored
    ones. Bit-identical to ``np.einsum("rf,nrf->nf", q_cols, np.conj(cols[:n]))``: the complex64 values widened
    exactly, the product's real and imaginary parts as NumPy's einsum forms them (``a.re·b.re − a.im·b.im``,
    ``a.re·b.im + a.im·b.re``) and summed over the rings in ring order from +0."""
    rings = q_cols.shape[0]
    nf = q_cols.shape[1]
    out = np.empty((n, nf), dtype=np.complex128)
    qr = np.empty((rings, nf))
    qi = np.empty((rings, nf))
    for r in range(rings):
        for f in range(nf):
            qr[r, f] = q_cols[r, f].real
            qi[r, f] = q_cols[r, f].imag
    re = np.empty(nf)
    im = np.empty(nf)
    for i in range(n):
        for f in range(nf):
            re[f] = 0.0
            im[f] = 0.0
        for r in range(rings):  # ring by ring, each frequency's sums in ring order (the stored rows read in order)
            for f in range(nf):
                b = cols[i, r, f]
                br = np.float64(b.real)
                bi = -np.float64(b.imag)
                re[f] += qr[r, f] * br - qi[r, f] * bi
                im[f] += qr[r, f] * bi + qi[r, f] * br
        for f in range(nf):
            out[i, f] = complex(re[f], im[f])
    return out


#: Places per block of the stored spectra (≈ 0.3 MB of column spectra a block at 20 rings × 60 sectors).
_BLOCK = 64


def _rows(blocks: list[np.ndarray], n: int, tail: tuple[int, ...]) -> np.ndarray:
    """The first ``n`` rows of the row blocks ``blocks`` (each (_BLOCK, *tail)) as one array."""
    if n == 0 or not blocks:
        return np.zeros((0, *tail), dtype=np.complex64)
    nb = -(-n // _BLOCK)
    if nb == 1:
        return blocks[0][:n]
    return np.concatenate([*blocks[:nb - 1], blocks[nb - 1][:n - (nb - 1) * _BLOCK]])


class PlaceIndex:
    """Descriptors of stored places (integer keys, e.g. pose-graph nodes) and their distance to a query.

    >>> idx = PlaceIndex(20, 60, 15.0)
    >>> pts = np.array([[2.0, 0.0], [0.0, 3.0], [-4.0, -1.0]])
    >>> idx.add(7, polar_descriptor(pts, 20, 60, 15.0))
    >>> keys, d, shift = idx.distances(polar_descriptor(pts, 20, 60, 15.0))
    >>> int(keys[0]), round(float(d[0]), 6), int(shift[0])
    (7, 0.0, 0)
    """

    def __init__(self, rings: int, sectors: int, max_range: float) -> None:
        self.rings = int(rings)
        self.sectors = int(sectors)
        self.max_range = float(max_range)
        nf = self.sectors // 2 + 1
        # the stored spectra in blocks of _BLOCK places, each allocated once and never copied (issue 13 item 3: a
        # single array grown by a quarter held up to 25 % of zeroed slack, ≈ 0.5 MB on MIT CSAIL, and old and new
        # side by side at each growth); the counts and keys (12 bytes a place) in arrays grown by a quarter
        self._nf = nf
        self._col_blocks: list[np.ndarray] = []  # (_BLOCK, rings, nf) complex64 each
        self._occ_blocks: list[np.ndarray] = []  # (_BLOCK, nf) complex64 each
        self._count = np.zeros(16, dtype=np.int32)
        self._keys = np.zeros(16, dtype=np.int64)
        self._n = 0
        self._row: dict[int, int] = {}  # key → row of the arrays

    @property
    def _cols(self) -> np.ndarray:
        """(n, rings, nf) complex64 stored column spectra (a new array: the blocks concatenated)."""
        return _rows(self._col_blocks, self._n, (self.rings, self._nf))

    @property
    def _occ(self) -> np.ndarray:
        """(n, nf) complex64 stored occupied-column spectra (a new array: the blocks concatenated)."""
        return _rows(self._occ_blocks, self._n, (self._nf,))

    def __len__(self) -> int:
        return self._n

    @property
    def keys(self) -> np.ndarray:
        """(n,) keys of the stored places, in the order added."""
        return self._keys[: self._n]

    @property
    def nbytes(self) -> int:
        """Memory of the stored spectra, bytes."""
        return int(sum(b.nbytes for b in self._col_blocks) + sum(b.nbytes for b in self._occ_blocks)
                   + self._count.nbytes + self._keys.nbytes)

    def describe(self, points: np.ndarray) -> np.ndarray:
        """:func:`polar_descriptor` with this index's rings, sectors and range."""
        return polar_descriptor(points, self.rings, self.sectors, self.max_range)

    def add(self, key: int, desc: np.ndarray) -> None:
        """Store place ``key`` with descriptor ``desc`` ((rings, sectors), from :meth:`describe`)."""
        if desc.shape != (self.rings, self.sectors):
            raise ValueError(f"PlaceIndex.add: descriptor shape {desc.shape}, expected {(self.rings, self.sectors)}")
        cols, occ, count = _spectra(desc)
        self._store([int(key)], cols[None], occ[None], np.array([count], dtype=np.int64))

    def describe_many(self, points: list[np.ndarray]) -> np.ndarray:
        """(k, rings, sectors): :meth:`describe` of each point set in ``points`` (:func:`polar_descriptors`)."""
        return polar_descriptors(points, self.rings, self.sectors, self.max_range)

    def add_many(self, keys: list[int], descs: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
        """Store places ``keys`` with descriptors ``descs`` ((k, rings, sectors)), in order: the same index as
        :meth:`add` of each in turn. Returns the last descriptor's spectra as :func:`_spectra` gives them (the
        same values: :func:`_spectra_many`), to be its query's (:meth:`distances`' ``spectra``), or None if
        ``keys`` is empty."""
        if descs.shape != (len(keys), self.rings, self.sectors):
            raise ValueError(f"PlaceIndex.add_many: descriptors shape {descs.shape}, "
                             f"expected {(len(keys), self.rings, self.sectors)}")
        if not keys:
            return None
        cols, occ, count = _spectra_many(descs)
        self._store([int(k) for k in keys], cols, occ, count)
        return cols[-1], occ[-1], int(count[-1])

    def _store(self, keys: list[int], cols: np.ndarray, occ: np.ndarray, count: np.ndarray) -> None:
        """Append the spectra of places ``keys`` (rows of ``cols``, ``occ``, ``count``): the spectra into their blocks
        (a new block when the last is full), the counts and keys into arrays grown by a quarter."""
        need = self._n + len(keys)
        cap = self._keys.shape[0]
        if need > cap:
            while need > cap:  # by a quarter (the stored rows only are read): ≤ 25 % slack, a small copy a time
                cap += max(16, cap // 4)
            k = self._n
            for name in ("_count", "_keys"):
                old = getattr(self, name)
                new = np.zeros((cap,) + old.shape[1:], dtype=old.dtype)
                new[:k] = old[:k]
                setattr(self, name, new)
                del old, new
        k = self._n
        i = 0
        while k + i < need:
            b, r = divmod(k + i, _BLOCK)
            if b == len(self._col_blocks):
                self._col_blocks.append(np.zeros((_BLOCK, self.rings, self._nf), dtype=np.complex64))
                self._occ_blocks.append(np.zeros((_BLOCK, self._nf), dtype=np.complex64))
            m = min(_BLOCK - r, need - k - i)
            self._col_blocks[b][r:r + m] = cols[i:i + m]
            self._occ_blocks[b][r:r + m] = occ[i:i + m]
            i += m
        self._count[k:need] = count
        self._keys[k:need] = keys
        for i, key in enumerate(keys):
            self._row[key] = k + i
        self._n = need

    def distances(self, desc: np.ndarray, upto: int | None = None, rows: np.ndarray | None = None,
                  spectra: tuple[np.ndarray, np.ndarray, int] | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance of the query ``desc`` to every stored place (the first ``upto`` if given; only the rows ``rows``
        of those if given: ascending (m,) int indices into the stored places, in the order added). ``spectra``:
        ``desc``'s spectra if the caller has them (:meth:`add_many` returned them; pass neg70: not computed again).

        Returns (keys (n,), d (n,) in [0, 1], shift (n,) sectors): at the best shift, query sector j faces the
        stored place's sector j − shift, i.e. the query's frame is the stored one turned by
        −shift·2π/sectors rad (for places seen from the same position). Each place's row is computed on its own,
        so a row's values are the same whichever rows are asked for.
        """
        n = self._n if upto is None else min(int(upto), self._n)
        if n == 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        return self._distances(*(_spectra(desc) if spectra is None else spectra), n, rows)

    def __contains__(self, key: object) -> bool:
        return isinstance(key, (int, np.integer)) and int(key) in self._row

    def distances_of(self, key: int, upto: int | None = None,
                     rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`distances` with the stored place ``key`` as the query (its descriptor is not kept, its spectra
        are; KeyError if it was not stored)."""
        k = self._row[int(key)]
        n = self._n if upto is None else min(int(upto), self._n)
        b, r = divmod(k, _BLOCK)
        return self._distances(self._col_blocks[b][r].astype(np.complex128),
                               self._occ_blocks[b][r].astype(np.complex128), int(self._count[k]), n, rows)

    def _distances(self, q_cols: np.ndarray, q_occ: np.ndarray, q_count: int, n: int,
                   rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(keys, d, shift) of the first ``n`` stored places (only the rows ``rows`` of them if given: ascending
        indices below ``n``) against a query given by its spectra (_spectra)."""
        if rows is not None:
            rows = np.asarray(rows, dtype=np.int64)
            rows = rows[rows < n]
            if rows.shape[0] == n:  # (every row: the whole blocks, no gather)
                rows = None
        if rows is None:
            if n == 0:
                return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
            nb = -(-n // _BLOCK)
            # block by block: each place's row is computed on its own, so the rows are those of one call over them all
            parts = [_ring_correlation(q_cols, self._col_blocks[b], min(_BLOCK, n - b * _BLOCK)) for b in range(nb)]
            occ = _rows(self._occ_blocks, n, (self._nf,))
            count = self._count[:n]
            keys = self._keys[:n].copy()
        else:
            m = rows.shape[0]
            if m == 0:
                return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
            # the asked rows gathered block by block (each row's values as in the whole blocks: see above)
            blk = rows // _BLOCK
            cuts = np.flatnonzero(np.diff(blk)) + 1
            parts = []
            occs = []
            for seg in np.split(rows, cuts) if cuts.size else [rows]:
                b = int(seg[0]) // _BLOCK
                r = seg - b * _BLOCK
                parts.append(_ring_correlation(q_cols, self._col_blocks[b][r], r.shape[0]))
                occs.append(self._occ_blocks[b][r])
            occ = occs[0] if len(occs) == 1 else np.concatenate(occs)
            count = self._count[rows]
            keys = self._keys[rows]
            n = m
        s = self.sectors
        # Σ_j Σ_r a[r, j] b[r, j − shift] for every shift: circular cross-correlation, summed over the rings
        corr = np.fft.irfft(parts[0] if len(parts) == 1 else np.concatenate(parts), n=s, axis=1)
        overlap = np.fft.irfft(q_occ[None, :] * np.conj(occ), n=s, axis=1)
        union = q_count + count[:, None].astype(np.float64) - np.rint(overlap)
        d = 1.0 - corr / np.maximum(union, 1.0)
        best = np.argmin(d, axis=1)
        return keys, np.clip(d[np.arange(n), best], 0.0, 1.0), best.astype(np.int64)


__all__ = ["PlaceIndex", "polar_descriptor", "polar_descriptors"]
