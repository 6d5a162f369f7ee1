"""The clean-up pass of the command line (``clean_windows(keep_counts=False)``) makes its cleaned float64 map when
the results first read it, not beside the online map at the pass's end (issue 13 item 3): the same map, the same
file, nothing made before the read."""

from __future__ import annotations

import pickle

import numpy as np


def _inputs():
    from dynslam2d.gridmap import GridMap
    from dynslam2d.slam import cleanup
    from dynslam2d.slam.cleanconfig import CleanConfig

    rng = np.random.default_rng(5)
    shape = (60, 70)
    online = GridMap(np.where(rng.random(shape) < 0.2, np.nan, rng.random(shape)), 0.05, (1.5, -2.0))

    def counts() -> cleanup.CountWindows:
        r = np.random.default_rng(6)
        win = [r.integers(0, 30, shape).astype(np.uint16) for _ in range(3)]
        return cleanup.CountWindows(*win, r.random(shape) < 0.5, CleanConfig(restore_min_hits=5), 10, 0, 0.0, 0)

    return online, counts


def test_cleaned_map_made_on_read_is_the_eager_one(tmp_path) -> None:
    from dynslam2d.io.mapfile import write_map
    from dynslam2d.slam import cleanup

    online, counts = _inputs()
    before = online.prob.copy()
    full = cleanup.clean_windows(online, counts(), keep_counts=True)
    lean = cleanup.clean_windows(online, counts(), keep_counts=False)
    assert full.erased.any() and full.restored.any()  # (both masks change cells)
    assert lean.grid._parts is not None  # not made by the pass
    assert lean.grid.shape == online.shape and lean.grid._parts is not None  # (its shape does not make it)
    assert lean.grid.resolution == full.grid.resolution and lean.grid.origin == full.grid.origin
    write_map(tmp_path / "lean.yaml", lean.grid)
    write_map(tmp_path / "full.yaml", full.grid)
    assert lean.grid._parts is None  # made by the first read, once
    assert lean.grid.prob is lean.grid.prob
    assert (tmp_path / "lean.pgm").read_bytes() == (tmp_path / "full.pgm").read_bytes()
    assert np.array_equal(lean.grid.prob, full.grid.prob, equal_nan=True)
    assert lean.grid.prob.dtype == np.float64
    assert np.array_equal(online.prob, before, equal_nan=True)  # (the online map untouched)
    assert np.array_equal(lean.logodds is None, full.logodds is None)


def test_cleaned_map_set_and_pickled() -> None:
    from dynslam2d.slam import cleanup

    online, counts = _inputs()
    full = cleanup.clean_windows(online, counts(), keep_counts=True)
    lean = cleanup.clean_windows(online, counts(), keep_counts=False)
    copy = pickle.loads(pickle.dumps(lean.grid))
    assert np.array_equal(copy.prob, full.grid.prob, equal_nan=True)
    other = cleanup.clean_windows(online, counts(), keep_counts=False).grid
    other.prob = np.zeros(online.shape)
    assert other._parts is None and not other.prob.any()  # a value set is kept, never replaced by the made map
