"""Observers that keep what the figures need from a run (bounded memory)."""

from __future__ import annotations

import numpy as np

from dynslam2d.pipeline import Pipeline, RunResult, StepResult
from dynslam2d.types import Scan


class RemovedPointsCollector:
    """A :class:`~dynslam2d.pipeline.RunObserver` that keeps the removed beams' endpoints.

    For every scan it stores the endpoints of the beams the filter removed
    (``StepResult.removed``), transformed into the map frame with the scan's estimated
    pose (m, float32). Memory stays bounded: at most ``per_scan`` points per scan (evenly
    strided), and whenever more than ``max_points`` are held, every stored scan is thinned
    by two (and later scans are strided twice as much).

    Attributes:
        stamps: scan stamps that had removed points, s.
        per_scan: (k, 2) float32 map-frame points, one array per entry of ``stamps``.
        n_removed: total removed beams seen (before any subsampling).
    """

    #: it reads only the scan and its result: :func:`dynslam2d.pipeline.run` feeds it 32 scans at a time
    #: (docs/speed.md, pass wall38)
    scan_batch: int = 32

    def __init__(self, per_scan: int = 200, max_points: int = 300_000) -> None:
        if per_scan < 1 or max_points < 1:
            raise ValueError("per_scan and max_points must be >= 1")
        self.per_scan_limit = int(per_scan)
        self.max_points = int(max_points)
        self.stamps: list[float] = []
        self.per_scan: list[np.ndarray] = []
        self.n_removed = 0
        self._stride = 1
        self._held = 0

    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None:
        removed = np.asarray(step.removed, dtype=bool)
        if removed.shape != scan.ranges.shape or not removed.any():
            return
        mask = removed & scan.valid_mask()
        idx = np.flatnonzero(mask)
        self.n_removed += idx.size
        if idx.size == 0:
            return
        stride = max(self._stride, int(np.ceil(idx.size / self.per_scan_limit)))
        idx = idx[::stride]
        # the kept beams' endpoints in the sensor frame (Scan.points' Paper Eq. 4 at these indices), then in the map
        # frame, rounded to float32 once
        r = scan.ranges[idx]
        cos_a, sin_a = scan.trig()
        pts = step.pose.transform_points(np.column_stack((r * cos_a[idx], r * sin_a[idx])), dtype=np.float32)
        self.stamps.append(float(scan.stamp))
        self.per_scan.append(pts)
        self._held += len(pts)
        while self._held > self.max_points:
            self._thin()

    def _thin(self) -> None:
        """Keep every other point over all scans (by global index), so the total halves even
        when each scan holds a single point; scans left empty are dropped."""
        stamps: list[float] = []
        kept: list[np.ndarray] = []
        start = 0
        for stamp, p in zip(self.stamps, self.per_scan):
            q = p[(start % 2)::2]
            start += len(p)
            if len(q):
                stamps.append(stamp)
                kept.append(q)
        self.stamps, self.per_scan = stamps, kept
        self._held = sum(len(p) for p in kept)
        self._stride *= 2

    def on_finish(self, result: RunResult, pipeline: Pipeline) -> None:
        """Nothing to do: the points are ready after the last scan."""

    def points(self) -> np.ndarray:
        """(n, 2) all kept removed-beam endpoints in the map frame, m (float64)."""
        if not self.per_scan:
            return np.zeros((0, 2))
        return np.concatenate(self.per_scan).astype(np.float64)


__all__ = ["RemovedPointsCollector"]
