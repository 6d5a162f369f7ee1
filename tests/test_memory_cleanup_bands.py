"""The command line's clean-up pass (``keep_counts=False``) applies its rules to count windows read from the
counter's tiles a band of rows at a time, lets the counter go once they are applied, and leaves the cleaned
log-odds unmade until they are read or written (issue 13 item 3): the same masks, stats, log-odds and file bytes
as the dense windows and the eager copy."""

from __future__ import annotations

import gc
import io
import math
import weakref

import numpy as np
import pytest

from dynslam2d.slam import HectorSlam, SlamConfig, cleanup
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.types import Pose2D, Scan

N_BEAMS = 360
ANGLES = -math.pi + np.arange(N_BEAMS) * (2 * math.pi / N_BEAMS)
OBJECT = (ANGLES > 0.2) & (ANGLES < 0.9)
HIDDEN = (ANGLES > -2.0) & (ANGLES < -1.5)  # an object at 3 m the counter sees and the map was never written with


def _counted(config: CleanConfig):
    """A sensor inside a 4 m ring wall; an object at 2 m there, gone, back, gone (erased); another at 3 m
    counted but not in the map (restored); two poses. The online map, its log-odds and the counter."""
    slam = HectorSlam(SlamConfig(map_levels=1))
    counter = cleanup.VisibilityCounter(0.05, config, slam.config)
    present = [True] * 8 + [False] * 10 + [True] * 8 + [False] * 6
    for k, p in enumerate(present):
        r = np.full(N_BEAMS, 4.0)
        r[OBJECT & p] = 2.0 + 0.03 * (k % 3)
        scan = Scan(stamp=0.1 * k, angle_min=-math.pi, angle_increment=2 * math.pi / N_BEAMS, ranges=r,
                    range_min=0.1, range_max=20.0)
        pose = Pose2D(0.013 * (k % 2), -0.021 * (k % 2), 0.0)
        slam.update_map(scan, pose, force=True)
        counter.add(scan.with_ranges(np.where(HIDDEN, 3.0, r)), pose, np.zeros(N_BEAMS, dtype=bool))
    return slam.gridmap(0), slam.logodds(0)[0], counter


@pytest.mark.parametrize("rows", [7, 16, 256])
@pytest.mark.parametrize("config", [CleanConfig(rehit_min_hits=6, restore_min_hits=2, restore_through_ratio=0.5),
                                    CleanConfig(rehit_min_hits=0)])
def test_banded_windows_give_the_dense_windows_result(monkeypatch, rows: int, config: CleanConfig) -> None:
    online, lo, counter = _counted(config)
    dense = cleanup.clean_windows(online, cleanup.CountWindows.of(online, counter), lo, keep_counts=True)
    assert dense.erased.any()
    monkeypatch.setattr(cleanup, "_RULE_ROWS", rows)  # bands cutting the counter's 16-row tiles, or one band
    pool = weakref.ref(counter._pool)
    counts = cleanup.CountWindows.banded(counter)
    assert counts.hits.size == 0 and counts.latest_hit is None  # no dense window
    del counter
    lean = cleanup.clean_windows(online, counts, lo, keep_counts=False)
    gc.collect()
    assert counts.counter is None and pool() is None  # the counter's tiles are let go by the pass
    assert np.array_equal(lean.erased, dense.erased)
    assert np.array_equal(lean.restored, dense.restored)
    assert {k: v for k, v in lean.stats.items() if k != "pass_time_s"} == \
        {k: v for k, v in dense.stats.items() if k != "pass_time_s"}
    assert np.array_equal(np.asarray(lean.logodds), dense.logodds)
    if config.restore_min_hits:
        assert dense.restored.any()


def test_banded_windows_are_not_kept() -> None:
    online, lo, counter = _counted(CleanConfig())
    with pytest.raises(ValueError):
        cleanup.clean_windows(online, cleanup.CountWindows.banded(counter), lo, keep_counts=True)


@pytest.mark.parametrize("rows", [5, 256])
def test_cleaned_logodds_made_on_read_write_np_save_bytes(monkeypatch, rows: int) -> None:
    monkeypatch.setattr(cleanup, "_RULE_ROWS", rows)
    online, lo, counter = _counted(CleanConfig(restore_min_hits=2, restore_through_ratio=0.5))
    before = lo.copy()
    dense = cleanup.clean_windows(online, cleanup.CountWindows.of(online, counter), lo, keep_counts=True)
    lean = cleanup.clean_windows(online, cleanup.CountWindows.banded(counter), lo, keep_counts=False)
    assert isinstance(lean.logodds, cleanup.CleanedLogodds) and lean.logodds.shape == lo.shape
    assert dense.erased.any() and dense.restored.any()
    want = io.BytesIO()
    np.save(want, np.asarray(dense.logodds, dtype=np.float32))
    got = io.BytesIO()
    lean.logodds.write_npy(got, np.float32)
    assert got.getvalue() == want.getvalue()
    made = np.asarray(lean.logodds)
    assert made.dtype == dense.logodds.dtype and np.array_equal(made, dense.logodds)
    assert np.asarray(lean.logodds, dtype=np.float64).dtype == np.float64
    assert np.array_equal(lo, before)  # the online log-odds untouched


def test_recorder_without_counts_cleans_as_with_them() -> None:
    from types import SimpleNamespace

    config = CleanConfig(rehit_min_hits=6, restore_min_hits=2, restore_through_ratio=0.5)
    online, lo, counter = _counted(config)
    results = []
    for keep in (True, False):
        rec = cleanup.CleanupRecorder(config, SlamConfig(map_levels=1), keep_counts=keep)
        rec.counter = counter
        rec.on_finish(SimpleNamespace(grid=online, logodds=lo, loop=None), None)
        assert (rec.counter is None) is not keep
        results.append(rec.result)
    full, lean = results
    assert np.array_equal(full.erased, lean.erased) and np.array_equal(full.restored, lean.restored)
    assert np.array_equal(full.logodds, np.asarray(lean.logodds))
    assert np.array_equal(full.grid.prob, lean.grid.prob, equal_nan=True)
