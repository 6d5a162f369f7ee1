"""The clean-up counter's one-call ``add`` (kernel ``_add_scan``) against its call-by-call form ``add_steps``, and the
removed-points collector's kernel against the former NumPy steps, value for value (docs/speed.md, pass cln102)."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

import dynslam2d.slam.cleanup as cl
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.config import SlamConfig
from dynslam2d.types import Pose2D, Scan
from dynslam2d.viz.collect import RemovedPointsCollector


def _scan(rng: np.random.Generator, stamp: float, n: int, far: float) -> Scan:
    """A fan of ``n`` beams with returns up to ``far`` m, some missing (NaN, inf, out of the sensor's limits) and
    some inside / beyond the SLAM's range gates."""
    r = rng.uniform(0.1, far, n)
    r[rng.random(n) < 0.08] = np.nan
    r[rng.random(n) < 0.04] = np.inf
    r[rng.random(n) < 0.04] = 0.3  # (below laser_min_dist)
    return Scan(stamp=stamp, angle_min=-2.0, angle_increment=4.0 / max(n - 1, 1), ranges=r, range_min=0.05,
                range_max=40.0)


def _removed(rng: np.random.Generator, n: int, k: int) -> np.ndarray | None:
    """The filter's mask in its shapes: none, bool, another dtype, the wrong length."""
    if k % 4 == 0:
        return None
    m = rng.random(n) < 0.3
    if k % 4 == 1:
        return m
    if k % 4 == 2:
        return m.astype(np.uint8) * 3
    return m[:-1]


def _state(c: cl.VisibilityCounter) -> tuple:
    return (c.hits, c.through, c.switches, c.last_touch(), c.i0, c.j0, c.shape, c._n_tiles, c.scans, c.too_large,
            c._id_base)


def _small_reserve(self: cl.VisibilityCounter, free: int) -> None:
    """``_reserve_tiles`` with just the rows asked for (not a row for every tile of the extent): the passes then run
    the pool full often (the counts do not depend on the pool's size)."""
    n = self._n_tiles
    free = min(free, self._table.size - n)
    if self._pool.shape[0] - n >= free:
        return
    pool = np.zeros((n + free, cl._TILE * cl._TILE, 4), dtype=np.uint16)
    pool[:n] = self._pool[:n]
    self._pool = pool


@pytest.mark.parametrize(("span", "small"), [(cl._ID_SPAN, False), (5, False), (cl._ID_SPAN, True)])
def test_add_is_add_steps(monkeypatch: pytest.MonkeyPatch, span: int, small: bool) -> None:
    """Scan after scan the same counts, extent, tiles and numbers, through extent growth (scans far apart), scans
    without returns, scans too large for the memory limit, (``span`` 5) the renumbering of the scan numbers and
    (``small``) the pool running full while the passes are counted."""
    monkeypatch.setattr(cl, "_ID_SPAN", span)
    if small:
        monkeypatch.setattr(cl.VisibilityCounter, "_reserve_tiles", _small_reserve)
    full = []
    count = cl.VisibilityCounter._count

    def spy(self, *a, **k):  # type: ignore[no-untyped-def]
        full.append(bool(k.get("resume", False)))
        return count(self, *a, **k)

    monkeypatch.setattr(cl.VisibilityCounter, "_count", spy)
    rng = np.random.default_rng(11)
    slam = SlamConfig(map_resolution=0.05, max_map_memory_mb=100.0)
    one = cl.VisibilityCounter(0.05, CleanConfig(), slam)
    steps = cl.VisibilityCounter(0.05, CleanConfig(), slam)
    for k in range(40):
        few = k % 5 == 3
        n = 3 if few else int(rng.integers(40, 400))
        scan = _scan(rng, 0.1 * k, n, 35.0 if few else 12.0)
        if k == 7:
            scan = Scan(stamp=0.7, angle_min=0.0, angle_increment=0.01, ranges=np.full(n, np.nan), range_min=0.05,
                        range_max=40.0)
        x = 20.0 * (k // 10) * (1 if k % 2 else -1) + rng.normal(0, 1)
        if k == 25:
            x = 5000.0  # (too large: the extent would pass max_map_memory_mb)
        pose = Pose2D(x, 15.0 * (k % 3) + rng.normal(0, 1), float(rng.uniform(-math.pi, math.pi)))
        removed = _removed(rng, n, k)
        one.add(scan, pose, removed)
        steps.add_steps(scan, pose, removed)
        for a, b in zip(_state(one), _state(steps)):
            assert np.array_equal(a, b), f"scan {k}"
    assert one.too_large >= 1 and one._id_base > (0 if span == 5 else -1)
    assert any(full) == small, "the pool ran full inside _add_scan (the resume path) only with the small pool"


def _former(col: RemovedPointsCollector, scan: Scan, step: object) -> None:
    """``RemovedPointsCollector.on_scan`` before pass cln102 (NumPy steps)."""
    removed = np.asarray(step.removed, dtype=bool)  # type: ignore[attr-defined]
    if removed.shape != scan.ranges.shape or not removed.any():
        return
    idx = np.flatnonzero(removed & scan.valid_mask())
    col.n_removed += idx.size
    if idx.size == 0:
        return
    stride = max(col._stride, int(np.ceil(idx.size / col.per_scan_limit)))
    idx = idx[::stride]
    r = scan.ranges[idx]
    cos_a, sin_a = scan.trig()
    pts = step.pose.transform_points(np.column_stack((r * cos_a[idx], r * sin_a[idx])),  # type: ignore[attr-defined]
                                     dtype=np.float32)
    col.stamps.append(float(scan.stamp))
    col.per_scan.append(pts)
    col._held += len(pts)
    while col._held > col.max_points:
        col._thin()


def test_collector_kernel_is_the_numpy_steps() -> None:
    """The same points (bytes), stamps, counts and thinning over 300 scans whose removed beams exceed the per-scan
    limit or not, with masks of the wrong length and scans without a removed return."""
    rng = np.random.default_rng(5)
    new, old = RemovedPointsCollector(per_scan=40, max_points=3000), RemovedPointsCollector(per_scan=40,
                                                                                           max_points=3000)
    for k in range(300):
        n = int(rng.integers(50, 720))
        scan = _scan(rng, 0.05 * k, n, 20.0)
        m = rng.random(n) < rng.choice([0.0, 0.02, 0.3])
        if k % 17 == 0:
            m = m[:-1]
        step = types.SimpleNamespace(removed=m, pose=Pose2D(*rng.normal(0, 30, 2), float(rng.uniform(-3, 3))))
        new.on_scan(scan, step, None)  # type: ignore[arg-type]
        _former(old, scan, step)
    assert new.n_removed == old.n_removed and new.stamps == old.stamps and new._stride == old._stride > 1
    assert len(new.per_scan) == len(old.per_scan)
    for a, b in zip(new.per_scan, old.per_scan):
        assert a.dtype == b.dtype == np.float32 and a.tobytes() == b.tobytes()


def test_pool_running_full_counts_as_a_large_pool(monkeypatch: pytest.MonkeyPatch) -> None:
    """The passes stopped by a full pool and resumed (the rest of the scan's marked cells, put back into the mask's
    word the walk had cleared: pass cln113) give the counts of a pool that never runs full."""
    rng = np.random.default_rng(5)
    slam = SlamConfig(map_resolution=0.05, max_map_memory_mb=100.0)
    scans = []
    for k in range(12):
        n = int(rng.integers(100, 400))
        pose = Pose2D(25.0 * k, 10.0 * (k % 3), float(rng.uniform(-math.pi, math.pi)))
        scans.append((_scan(rng, 0.2 * k, n, 30.0), pose, _removed(rng, n, k)))
    large = cl.VisibilityCounter(0.05, CleanConfig(), slam)
    for scan, pose, removed in scans:
        large.add(scan, pose, removed)
    resumed = []
    count = cl.VisibilityCounter._count

    def spy(self, *a, **k):  # type: ignore[no-untyped-def]
        resumed.append(bool(k.get("resume", False)))
        return count(self, *a, **k)

    monkeypatch.setattr(cl.VisibilityCounter, "_reserve_tiles", _small_reserve)
    monkeypatch.setattr(cl.VisibilityCounter, "_count", spy)
    small = cl.VisibilityCounter(0.05, CleanConfig(), slam)
    for scan, pose, removed in scans:
        small.add(scan, pose, removed)
    assert sum(resumed) >= 4, "the small pool ran full while the passes were counted"
    assert int(large.through.astype(np.int64).sum()) > 10_000
    for a, b in zip(_state(small), _state(large)):
        assert np.array_equal(a, b)
