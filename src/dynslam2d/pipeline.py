"""The per-scan pipeline and whole-log runs.

Today the pipeline is preprocess → match → map update (Hector-style SLAM, see
:mod:`dynslam2d.slam`); detection, tracking and the dynamic-point filter slot in
between matching and the map update as they land (design.md, "Data flow").

``Pipeline(config).process(scan) -> StepResult`` is the live API for any robot
framework; :func:`run` drives it over a whole :class:`ScanSource`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from dynslam2d.config import Config
from dynslam2d.gridmap import GridMap
from dynslam2d.io.trajectory import Trajectory
from dynslam2d.slam import HectorSlam
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceMeta


@dataclass(slots=True)
class StepResult:
    """What one scan produced.

    Attributes:
        index: 0-based scan index in this pipeline.
        stamp: the scan's stamp, s.
        pose: laser pose in the map frame (m, rad); the map frame is the first scan's laser pose.
        score: match quality, mean occupancy probability at the scan endpoints (0 … 1).
        map_updated: the scan was written into the map.
        rejected: the match was judged bad and kept out of the map (``reason`` says why).
        skipped: the scan held too little to match (``reason`` says why).
        reason: skip / reject reason, or None.
        timings: wall time per stage, ms ("match", "map_update", "total").
    """

    index: int
    stamp: float
    pose: Pose2D
    score: float
    map_updated: bool
    rejected: bool
    skipped: bool
    reason: str | None
    timings: dict[str, float] = field(default_factory=dict)


class Pipeline:
    """Scans in, poses and a map out; one :meth:`process` call per scan, in time order."""

    def __init__(self, config: Config | None = None) -> None:
        self.config = config if config is not None else Config()
        self.slam = HectorSlam(self.config.slam)

    def process(self, scan: Scan) -> StepResult:
        """Run every stage on ``scan`` and return the result."""
        t0 = time.perf_counter()
        step = self.slam.process(scan)
        total = (time.perf_counter() - t0) * 1e3
        return StepResult(
            index=step.index,
            stamp=step.stamp,
            pose=step.pose,
            score=step.score,
            map_updated=step.map_updated,
            rejected=step.rejected,
            skipped=step.skipped,
            reason=step.reason,
            timings={"match": step.match_ms, "map_update": step.update_ms, "total": total},
        )

    def gridmap(self) -> GridMap:
        """The finest map level as occupancy probabilities (NaN = never observed)."""
        return self.slam.gridmap(0)


@dataclass(eq=False)
class RunResult:
    """A whole run: trajectory, map, per-scan flags and timings, counters.

    Attributes:
        source: metadata of the input.
        config: the effective configuration.
        trajectory: one pose per processed scan, stamped with the scan's stamp (map frame).
        scores, map_updated, rejected, skipped: (n,) per-scan match score and flags.
        timings_ms: per-stage (n,) arrays of wall time, ms.
        grid: the final finest-level map.
        logodds: (H, W) raw log-odds of the finest level, same cells as ``grid``.
        wall_time_s: wall time of the whole run, s (includes reading the input).
        reasons: count of each skip / reject reason.
        memory_bytes: memory held by the map levels at the end.
    """

    source: SourceMeta
    config: Config
    trajectory: Trajectory
    scores: np.ndarray
    map_updated: np.ndarray
    rejected: np.ndarray
    skipped: np.ndarray
    timings_ms: dict[str, np.ndarray]
    grid: GridMap
    logodds: np.ndarray
    wall_time_s: float
    reasons: dict[str, int]
    memory_bytes: int

    @property
    def n_scans(self) -> int:
        return len(self.trajectory)

    def summary(self) -> dict[str, object]:
        """Numbers for summary.json and the terminal: scans, time, scans/s, failures, memory."""
        n = self.n_scans
        total = self.timings_ms.get("total", np.zeros(0))
        return {
            "input": self.source.origin,
            "format": self.source.format,
            "scans": n,
            "wall_time_s": round(self.wall_time_s, 3),
            "scans_per_s": round(n / self.wall_time_s, 2) if self.wall_time_s > 0 else None,
            "processing_ms_median": float(np.median(total)) if total.size else None,
            "processing_ms_p95": float(np.percentile(total, 95)) if total.size else None,
            "map_updates": int(self.map_updated.sum()),
            "match_failures": int(self.rejected.sum()),
            "skipped_scans": int(self.skipped.sum()),
            "reasons": dict(self.reasons),
            "memory_bytes": int(self.memory_bytes),
            "map_cells": list(self.grid.shape),
            "map_resolution_m": self.grid.resolution,
            "map_origin_m": list(self.grid.origin),
        }


ProgressFn = Callable[[int, StepResult], None]


def run(source: ScanSource, config: Config | None = None, progress: ProgressFn | None = None) -> RunResult:
    """Run the pipeline over every scan of ``source``.

    ``progress(n_done, step)`` is called after every scan (the CLI draws its progress bar
    from it).
    """
    pipe = Pipeline(config)
    stamps: list[float] = []
    poses: list[Pose2D] = []
    scores: list[float] = []
    flags: list[tuple[bool, bool, bool]] = []
    timings: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    for scan in source:
        step = pipe.process(scan)
        stamps.append(step.stamp)
        poses.append(step.pose)
        scores.append(step.score)
        flags.append((step.map_updated, step.rejected, step.skipped))
        for k, v in step.timings.items():
            timings.setdefault(k, []).append(v)
        if progress is not None:
            progress(len(stamps), step)
    wall = time.perf_counter() - t0
    flag_arr = np.array(flags, dtype=bool).reshape(-1, 3)
    logodds, _ = pipe.slam.logodds(0)
    summary = pipe.slam.summary()
    return RunResult(
        source=source.meta,
        config=pipe.config,
        trajectory=Trajectory.from_poses(np.array(stamps), poses),
        scores=np.array(scores),
        map_updated=flag_arr[:, 0],
        rejected=flag_arr[:, 1],
        skipped=flag_arr[:, 2],
        timings_ms={k: np.array(v) for k, v in timings.items()},
        grid=pipe.gridmap(),
        logodds=logodds,
        wall_time_s=wall,
        reasons=dict(summary.get("reasons", {})),  # type: ignore[arg-type]
        memory_bytes=pipe.slam.memory_bytes,
    )
