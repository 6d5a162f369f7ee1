"""Memory pass mem39 (issue 13 item 3): a level's log-odds grown into zeroed memory with only the old array's
non-zero cells copied (the untouched pages take no memory), and the clean-up pass's cleaned map written over the
online map once the online map's files are written (no cleaned copies) — both with the values of before."""

from __future__ import annotations

import numpy as np
from conftest import ScanList
from test_memory_mem38 import _loop_run

import dynslam2d.slam.grid as grid_module
from dynslam2d.config import Config
from dynslam2d.gridmap import GridMap
from dynslam2d.pipeline import run
from dynslam2d.slam.cleanup import (
    ERASED_PROBABILITY,
    RESTORED_PROBABILITY,
    CleanResult,
    CleanupRecorder,
    CountWindows,
    clean_windows,
)
from dynslam2d.slam.grid import GridLevel


def _filled_grow(level: GridLevel, b: tuple[int, int, int, int]) -> dict[str, np.ndarray]:
    """The arrays a growth to bounds ``b`` must give: each old array in its place, its fill value around it."""
    h, w = level.shape
    out = {}
    for name, fill, dtype in (("prob", 0.5, np.float32), ("uidx", -1, np.int32), ("logodds", 0.0, np.float32)):
        new = np.full((b[3] - b[1], b[2] - b[0]), fill, dtype=dtype)
        r0, c0 = level.j0 - b[1], level.i0 - b[0]
        new[r0:r0 + h, c0:c0 + w] = getattr(level, name)
        out[name] = new
    return out


def test_grown_level_keeps_every_log_odds_bit_and_fills_zeros() -> None:
    rng = np.random.default_rng(5)
    lv = GridLevel(0.05, growth_margin_cells=7)
    lv.ensure(0, 0, 40, 30)
    h, w = lv.shape
    seen = rng.random((h, w)) < 0.3
    lv.logodds[seen] = rng.normal(0.0, 3.0, int(seen.sum())).astype(np.float32)
    lv.logodds[3, 4] = -0.0  # (a cell whose bits are not zero although it compares equal to 0.0)
    lv.uidx[seen] = rng.integers(0, 99, int(seen.sum()))
    lv.prob[seen] = rng.random(int(seen.sum())).astype(np.float32)
    for bounds in ((-30, -5, 45, 30), (0, 0, 400, 33), (-200, -300, 900, 700)):  # (the last one past _ZEROED_BYTES)
        b = lv._grown_bounds(*bounds)
        assert b is not None
        want = _filled_grow(lv, b)
        lv.ensure(*bounds)
        for name, arr in want.items():
            got = getattr(lv, name)
            assert got.dtype == arr.dtype and got.shape == arr.shape
            assert np.array_equal(got.view(np.uint8), arr.view(np.uint8)), name  # bit for bit
        assert np.signbit(lv.logodds).sum() == np.signbit(want["logodds"]).sum() > 0
    assert lv.logodds.nbytes >= grid_module._ZEROED_BYTES


def _pending_run():
    scans, meta = _loop_run()
    cfg = Config()
    rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    res = run(ScanList(scans, meta), cfg, observers=[rec])
    assert rec.result is not None
    return res, rec.result


def test_cleaned_map_in_place_and_lazy_copies_equal_the_copies() -> None:
    rng = np.random.default_rng(1)
    prob = rng.random((60, 50))
    prob[rng.random((60, 50)) < 0.2] = np.nan
    online = GridMap(prob, 0.05, (1.0, -2.0))
    lo = np.nan_to_num(np.log(prob / (1.0 - prob)), nan=0.0).astype(np.float32)  # (0: never observed)
    counts = CountWindows(rng.integers(0, 9, (60, 50)).astype(np.uint16),
                          rng.integers(0, 30, (60, 50)).astype(np.uint16),
                          rng.integers(0, 3, (60, 50)).astype(np.uint16), None, CleanupRecorder().config, 10, 0,
                          0.0, 0)
    ref = clean_windows(online, counts, lo)
    assert ref.erased.any() and ref.restored is not None and ref.restored.any()
    assert np.nanmax(np.abs(ref.grid.prob - prob)) > 0  # (the pass changed cells)
    lazy = clean_windows(online, counts, lo, defer=True)
    assert lazy.pending and lazy.cleans(online, lo)
    assert np.array_equal(lazy.grid.prob, ref.grid.prob, equal_nan=True)
    assert np.array_equal(lazy.logodds, ref.logodds) and lazy.logodds.dtype == np.float32
    assert not lazy.pending and np.array_equal(online.prob, prob, equal_nan=True)  # (copies: online untouched)
    prob0, lo0 = online.prob, lo
    inplace = clean_windows(online, counts, lo, defer=True)
    inplace.apply_in_place()
    assert inplace.grid.prob is prob0 and inplace.logodds is lo0  # written over the online arrays
    assert np.array_equal(prob0, ref.grid.prob, equal_nan=True) and np.array_equal(lo0, ref.logodds)
    assert (prob0[ref.erased] == ERASED_PROBABILITY).all() and (prob0[ref.restored] == RESTORED_PROBABILITY).all()


def test_released_outputs_clean_the_online_map_in_place_with_the_same_files(tmp_path, monkeypatch) -> None:
    import dynslam2d.results as R

    res, cleaned = _pending_run()
    assert cleaned.pending and cleaned.cleans(res.grid, res.logodds)
    # the reference: the same run and clean-up, the cleaned map made as copies, written without release
    twin = CleanResult.deferred(res.grid, res.logodds, cleaned.erased, cleaned.hits, cleaned.through,
                                cleaned.switches, dict(cleaned.stats), cleaned.restored)
    assert twin.grid is not None and not twin.pending
    assert (twin.grid.prob != res.grid.prob).sum() > 0
    ref_paths = R.write_outputs(res, tmp_path / "ref", cleaned=twin).paths
    online_prob = res.grid.prob
    written: dict[str, object] = {}
    write_map = R.write_map

    def spy(path, grid, *a, **k):  # type: ignore[no-untyped-def]
        written[path.name] = grid.prob
        return write_map(path, grid, *a, **k)

    monkeypatch.setattr(R, "write_map", spy)
    paths = R.write_outputs(res, tmp_path / "new", cleaned=cleaned, release=True).paths
    assert written["map.yaml"] is online_prob  # the cleaned map is the online map's array, cleaned in place
    assert list(paths) == list(ref_paths)
    for name, p in paths.items():
        if name in ("run.json", "summary.json"):
            continue
        assert p.read_bytes() == ref_paths[name].read_bytes(), name


def test_released_outputs_let_map_png_indices_go_before_tracks_png(tmp_path, monkeypatch) -> None:
    """``write_outputs`` hands the figures' grey indices over: the map drawn in map.png is not alive while
    tracks.png is drawn."""
    import gc
    import weakref

    import dynslam2d.results as R
    import dynslam2d.viz.figures as F

    res, cleaned = _pending_run()
    refs: dict[str, weakref.ref] = {}
    make, tracks_fn = R.FigureMaps, F.plot_tracks

    def made(drawn, background):  # type: ignore[no-untyped-def]
        refs["drawn"] = weakref.ref(drawn.indices)
        return make(drawn, background)

    alive: dict[str, bool] = {}

    def tracks_spy(*a, **k):  # type: ignore[no-untyped-def]
        gc.collect()
        alive["drawn"] = refs["drawn"]() is not None
        return tracks_fn(*a, **k)

    monkeypatch.setattr(R, "FigureMaps", made)
    monkeypatch.setattr(F, "plot_tracks", tracks_spy)
    R.write_outputs(res, tmp_path, cleaned=cleaned, release=True)
    assert alive == {"drawn": False}
