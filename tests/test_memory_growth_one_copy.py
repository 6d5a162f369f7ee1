"""Memory pass mem120 (issue 13 item 3): when the finest map level grows, its old arrays are held by the level
alone (the tracker's map view lets them go and follows the grown level), and each old array's pages are given back
block by block while it is copied: the old and the new array are never both resident (MIT CSAIL's peak was the
growth with the map view still holding the old log-odds)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import dynslam2d.slam.grid as grid_module
from dynslam2d.detect.mapevidence import MapView, map_evidence
from dynslam2d.slam.grid import GridLevel

_LINUX = sys.platform.startswith("linux") and grid_module._MADV_DONTNEED is not None


def _spy(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int, bool, int, bool]]:
    """Per call of ``_copy_written_rows``: (dtype, references to the old array beyond the spy's own, pages given
    back, non-zero cells the old array reads after the copy, the old array was in zeroed memory of its own)."""
    calls: list[tuple[str, int, bool, int, bool]] = []
    orig = grid_module._copy_written_rows

    def spy(dst: np.ndarray, src: np.ndarray, release: object = None) -> None:
        # (references to ``src``: _grow's name, this frame's and getrefcount's argument; more: someone else's)
        refs = sys.getrefcount(src) - 3
        orig(dst, src, release)
        calls.append((src.dtype.name, refs, release is not None, int(np.count_nonzero(src)),
                      src.size * 4 >= grid_module._ZEROED_BYTES))

    monkeypatch.setattr(grid_module, "_copy_written_rows", spy)
    return calls


def _large_level() -> GridLevel:
    """A level past the zeroed-memory size with a band of written cells (every array)."""
    lv = GridLevel(0.05)
    lv.ensure(0, 0, 799, 799)
    rng = np.random.default_rng(3)
    h, w = lv.shape
    band = np.s_[100:700, 50:750]
    lv.logodds[band] = rng.normal(0.0, 4.0, (600, 700)).astype(np.float32)
    lv.prob[band] = rng.integers(1, 1 << 30, (600, 700), dtype=np.uint32)
    lv.uidx[band] = rng.integers(1, 99, (600, 700), dtype=np.int32)
    assert lv.logodds.nbytes >= grid_module._ZEROED_BYTES and (h, w) == lv.shape
    return lv


def test_a_held_view_lets_the_old_arrays_go_and_follows_the_growth(monkeypatch: pytest.MonkeyPatch) -> None:
    lv = _large_level()
    view = MapView.of_level(lv)
    assert view is not None
    before = {n: getattr(lv, n).copy() for n in ("logodds", "prob", "uidx")}
    i0, j0 = lv.i0, lv.j0
    pts = np.random.default_rng(4).uniform(-10.0, 45.0, (4000, 2))
    want = map_evidence(pts, MapView(before["logodds"], i0, j0, 0.05))
    calls = _spy(monkeypatch)
    lv.ensure(i0 - 300, j0 - 20, i0 + 900, j0 + 820)  # (left, bottom and right: every array copied)
    assert [c[0] for c in calls] == ["uint32", "int32", "float32"]
    for dtype, refs, released, nonzero, _ in calls:
        assert refs == 0, dtype  # nothing but the level held the old array while it was copied
        if _LINUX:
            assert released and nonzero == 0, dtype  # its pages given back (a dropped page reads zeros)
    # the view follows: the grown arrays and offsets, the same answers as a view made now and as before
    assert view.logodds is lv.logodds and (view.i0, view.j0) == (lv.i0, lv.j0) and view.occ_bits is lv.occ_bits
    r0, c0 = j0 - lv.j0, i0 - lv.i0
    for name, old in before.items():
        new = getattr(lv, name)
        assert new[r0:r0 + old.shape[0], c0:c0 + old.shape[1]].tobytes() == old.tobytes(), name
        assert np.count_nonzero(new) == np.count_nonzero(old), name
    got = map_evidence(pts, view)
    for a, b in zip(want, got):
        assert np.array_equal(a, b)


def test_an_other_view_of_the_array_keeps_it_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    """An array viewing the log-odds that is not a following view (someone else's slice): the old array is copied
    as before and its pages kept (they are still read)."""
    lv = _large_level()
    held = lv.logodds[100:200]
    kept = held.copy()
    calls = _spy(monkeypatch)
    lv.ensure(lv.i0 - 300, lv.j0, lv.i0 + 799, lv.j0 + 799)
    lo = [c for c in calls if c[0] == "float32"]
    assert len(lo) == 1 and not lo[0][2] and lo[0][3] == np.count_nonzero(lv.logodds) > 0  # (read as before)
    assert held.tobytes() == kept.tobytes()
    other = np.frombuffer(lv._maps["logodds"][0](), dtype=np.float32)  # (another array of the level's memory map)
    calls.clear()
    lv.ensure(lv.i0 - 300, lv.j0, lv.i0 + 799, lv.j0 + 799)
    assert [c[2] for c in calls if c[0] == "float32"] == [False]
    assert np.count_nonzero(other) == np.count_nonzero(lv.logodds) > 0


def test_the_pipelines_map_view_never_holds_the_old_log_odds_at_a_growth(monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole pipeline on a simulated drive (its finest level grows in zeroed memory with the tracker's map view
    held): every large growth copies arrays held by the level alone and gives their pages back,
    and the view the pipeline keeps is the level's (its arrays and offsets) after every scan."""
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    # (levels from 64 KiB an array in zeroed memory: the simulated drive's finest level then grows from such arrays)
    monkeypatch.setattr(grid_module, "_ZEROED_BYTES", 1 << 16)
    calls = _spy(monkeypatch)
    pipe = Pipeline()
    lv = pipe.slam.map.levels[0]
    for scan in open_source("sim:drive", None):
        pipe.process(scan)
        view = pipe._view
        if view is not None:
            assert view.logodds is lv.logodds and (view.i0, view.j0) == (lv.i0, lv.j0)
    big = [c for c in calls if c[0] == "float32" and c[4]]
    assert big  # (the finest level grew from a size past the zeroed-memory one at least once)
    for dtype, refs, released, nonzero, zeroed in calls:
        assert refs == 0, dtype
        if _LINUX and zeroed:  # (a smaller old array came from the heap: freed when it goes)
            assert released and nonzero == 0, dtype


def test_the_copy_writes_only_the_blocks_spans_of_written_cells() -> None:
    """The zeros outside each block's span of non-zero cells are not written (their pages stay untouched): a
    destination of sentinel bytes keeps them there, and every non-zero cell (a −0.0 too) is copied."""
    rng = np.random.default_rng(9)
    src = np.zeros((37, 300), dtype=np.float32)
    src[3:9, 40:60] = rng.normal(0.0, 2.0, (6, 20)).astype(np.float32)
    src[20, 250] = -0.0
    src[33:37, 5:7] = 1.5
    dst = np.full(src.shape, np.nan, dtype=np.float32)
    grid_module._copy_written_rows(dst, src)
    written = ~np.isnan(dst)
    assert np.array_equal(dst[written].view(np.uint32), src[written].view(np.uint32))
    assert (src.view(np.uint32)[~written] == 0).all()  # every non-zero cell copied
    k = grid_module._SPAN_ROWS
    assert k == 8  # (blocks: rows 0-7 and 8-15 hold columns 40-59, 16-23 column 250, 32-36 columns 5-6)
    assert written.sum() == 8 * 20 + 8 * 20 + 8 * 1 + 5 * 2
    assert not written[:, 61:249].any() and not written[k * 3:k * 4].any()
