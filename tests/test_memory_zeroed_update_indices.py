"""Memory pass mem43 (issue 13 item 3): a SLAM level's update indices use 0 for "never updated" (the reference's
−1; a scan's indices are >= 1), so that a large level's index array is zeroed memory whose untouched pages take
no memory, as its log-odds; every reader takes 0 as "never"."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.grid import GridLevel, MultiResMap, decode_probs
from dynslam2d.types import Pose2D


def _rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096


def test_a_large_grown_level_touches_none_of_its_new_cells() -> None:
    """Growing a level with a few updated cells to 3000 × 3000 cells (34 MiB an array): the log-odds, the update
    indices and (since pass mem52: its words, 0 = 0.5) the probability cache stay untouched zeroed memory outside
    the old array, and keep their values."""
    lv = GridLevel(0.05)
    lv.ensure(0, 0, 99, 99)
    n_rays = lv.integrate(np.array([2.0, 2.0]), np.array([[4.0, 3.0], [1.0, 4.5], [3.0, 0.5]]),
                          np.array([True, True, False]), -0.4, 0.85, 50.0)
    assert n_rays == 3
    lo, ui, i0, j0 = lv.logodds.copy(), lv.uidx.copy(), lv.i0, lv.j0
    assert ui.max() == 2 and ui.min() == 0  # (one scan: 1 on its free cells, 2 on its hits, 0 elsewhere)
    before = _rss_bytes()
    lv.ensure(-1400, -1400, 1499, 1499)
    grown = _rss_bytes() - before
    per_array = lv.prob.nbytes
    assert per_array >= 30 * 2**20
    # a few pages of the copied cells; a filled array (the cache before pass mem52: 0.5 in every cell) adds per_array
    assert grown < per_array // 2, (grown / 2**20, per_array / 2**20)
    r0, c0 = j0 - lv.j0, i0 - lv.i0
    h, w = ui.shape
    assert np.array_equal(lv.uidx[r0:r0 + h, c0:c0 + w], ui)
    assert np.array_equal(lv.logodds[r0:r0 + h, c0:c0 + w].view(np.int32), lo.view(np.int32))
    assert int(np.count_nonzero(lv.uidx)) == int(np.count_nonzero(ui))
    assert (decode_probs(lv.prob[:r0]) == np.float32(0.5)).all() and not lv.prob[:r0].any()


def test_cells_with_update_index_zero_read_as_never_updated() -> None:
    """A map made by scans: a cell is never updated exactly where its update index is 0 (log-odds 0, cache 0.5);
    the observed box, the exported probabilities' NaN and the pipeline's map export's unknown mask are those
    cells."""
    from dynslam2d.pipeline import _MapExport

    rng = np.random.default_rng(43)
    m = MultiResMap(0.05, 3, -0.4, 0.85)
    ang = np.linspace(-math.pi / 2, math.pi / 2, 181)
    for k in range(6):
        r = rng.uniform(1.0, 4.0, ang.shape[0])
        pts = np.column_stack((r * np.cos(ang), r * np.sin(ang)))
        m.integrate(Pose2D(0.3 * k, 0.1 * k, 0.2 * k), pts)
    for lv in m.levels:
        assert lv.uidx.min() == 0 and lv.uidx.max() == lv.update_counter - 1
        never = lv.uidx == 0
        assert (lv.logodds[never] == 0).all() and (decode_probs(lv.prob[never]) == np.float32(0.5)).all()
        rows = np.flatnonzero((~never).any(axis=1))
        cols = np.flatnonzero((~never).any(axis=0))
        assert lv.known_bounds() == (rows[0], rows[-1] + 1, cols[0], cols[-1] + 1)
    lv = m.levels[0]
    r0, r1, c0, c1 = lv.known_bounds()
    crop = lv.uidx[r0:r1, c0:c1] == 0
    assert crop.any() and not crop.all()
    assert np.array_equal(np.isnan(m.to_gridmap(0).prob), crop)
    export = _MapExport.of(m)
    assert np.array_equal(export.unknown, crop)
    np.testing.assert_array_equal(export.gridmap().prob, m.to_gridmap(0).prob)


def _resident_pages(a: np.ndarray) -> int:
    """Pages of ``a``'s memory that are resident (mincore(2); the arrays tested are page-aligned)."""
    import ctypes
    import mmap

    libc = ctypes.CDLL(None, use_errno=True)
    page = mmap.PAGESIZE
    addr = a.__array_interface__["data"][0]
    start = addr - addr % page
    n = (addr + a.nbytes - start + page - 1) // page
    vec = (ctypes.c_ubyte * n)()
    assert libc.mincore(ctypes.c_void_p(start), ctypes.c_size_t(n * page), vec) == 0, ctypes.get_errno()
    return sum(v & 1 for v in vec)


def _copied_pages(a: np.ndarray, r0: int, c0: int, h: int, w: int) -> int:
    """Pages of ``a`` (page-aligned, C-contiguous) spanned by the parts ``[c0, c0 + w)`` of its rows ``r0 … r0 + h``
    that hold a non-zero cell: what a growth copies of the old array (its written rows, whole)."""
    nw, item, page = a.shape[1], a.itemsize, 4096
    pages: set[int] = set()
    for r in range(r0, r0 + h):
        if a[r, c0:c0 + w].view(np.int32).any():
            lo, hi = (r * nw + c0) * item, (r * nw + c0 + w) * item - 1
            pages.update(range(lo // page, hi // page + 1))
    return len(pages)


def test_grown_zeroed_arrays_hold_only_their_written_pages_after_heap_reuse() -> None:
    """The grown log-odds, update indices and probability cache words are resident only on the pages of the old
    array's written rows, also when the allocator has a large freed heap block at hand (which ``np.zeros``' calloc
    would clear, touching every page): the arrays have their own memory maps."""
    big = np.ones(24 * 2**20, dtype=np.uint8)  # (freed: glibc's mmap threshold rises to its size)
    del big
    heap = np.ones(12 * 2**20, dtype=np.uint8)  # (now from the heap, its pages resident; freed for reuse)
    del heap
    lv = GridLevel(0.05)
    lv.ensure(0, 0, 99, 99)
    lv.integrate(np.array([2.0, 2.0]), np.array([[4.0, 3.0], [1.0, 4.5]]), np.array([True, True]), -0.4, 0.85, 50.0)
    i0, j0, (h, w) = lv.i0, lv.j0, lv.shape
    lv.ensure(-600, -600, 799, 799)  # 1600 × 1600 cells with the margins, 9.8 MiB an array
    assert lv.uidx.nbytes > 4 * 2**20
    for name in ("uidx", "logodds", "prob"):
        a = getattr(lv, name)
        assert _resident_pages(a) <= _copied_pages(a, j0 - lv.j0, i0 - lv.i0, h, w) <= 200, name  # (of 2500 pages)
