"""Observers that keep what the figures need from a run (bounded memory)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.jitbox import njit
from dynslam2d.pipeline import Pipeline, RunResult, StepResult
from dynslam2d.types import Scan


@njit(cache=True)
def _removed_points(removed, valid, ranges, cos_a, sin_a, stride_min, limit, c, s, x, y):  # pragma: no cover - numba
    """The removed beams with a return (``removed`` and ``valid``, (n,) bool) and the map-frame endpoints of every
    ``stride``-th of them, ``stride`` = max(``stride_min``, ⌈count / ``limit``⌉): (count, (k, 2) float32 m). The
    endpoints are :meth:`Scan.points`' (Paper Eq. 4: ``r·cos a``, ``r·sin a`` with the scan's (``cos_a``,
    ``sin_a``)) moved by the pose (``c``, ``s`` = cos, sin of its heading; ``x``, ``y``) as
    :meth:`Pose2D.transform_points` does — the same float64 operations in the same order — each rounded to float32
    once (:meth:`RemovedPointsCollector.on_scan` in one call: no index, point or transformed arrays of NumPy)."""
    n = removed.shape[0]
    idx = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if removed[i] and valid[i]:
            idx[m] = i
            m += 1
    if m == 0:
        return 0, np.empty((0, 2), dtype=np.float32)
    stride = max(stride_min, int(math.ceil(m / limit)))
    k = (m + stride - 1) // stride
    out = np.empty((k, 2), dtype=np.float32)
    for j in range(k):
        i = idx[j * stride]
        r = ranges[i]
        px = r * cos_a[i]
        py = r * sin_a[i]
        out[j, 0] = np.float32(c * px - s * py + x)
        out[j, 1] = np.float32(s * px + c * py + y)
    return m, out


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
        # the removed beams with a return, every stride-th of them in the map frame, float32 (one kernel call)
        cos_a, sin_a = scan.trig()
        pose = step.pose
        count, pts = _removed_points(removed, scan.valid_view(), scan.ranges, cos_a, sin_a, self._stride,
                                     self.per_scan_limit, math.cos(pose.theta), math.sin(pose.theta), float(pose.x),
                                     float(pose.y))
        self.n_removed += count
        if count == 0:
            return
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
