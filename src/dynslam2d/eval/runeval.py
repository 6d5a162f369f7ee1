"""A run scored against ground truth, once: what metrics.json holds and what the figures draw.

:func:`evaluate_run` computes the ATE (with its association and SE(2) alignment), the map cell
sets and metrics of the final map (and of the online map when a clean-up pass replaced it), the
removal metrics and the time walking movers take to enter M. The :class:`RunEvaluation` it
returns is passed on as it is: :func:`dynslam2d.results.write_outputs` writes its
:meth:`~RunEvaluation.as_dict` as metrics.json, :func:`dynslam2d.viz.figures.write_figures`
draws its ATE and cell sets (map.png, errors.png), and the CLI prints its numbers. Nothing
downstream computes any of it again. Formulas: docs/metrics.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # the scoring modules are imported on use: a run without ground truth never needs them
    from dynslam2d.eval.maps import CellSets, MapMetrics
    from dynslam2d.eval.motionclass import MotionRemoval, TimeToM
    from dynslam2d.eval.removal import RemovalMetrics
    from dynslam2d.eval.trajectory import AteResult
    from dynslam2d.gridmap import GridMap
    from dynslam2d.io.groundtruth import GroundTruthFiles
    from dynslam2d.trajectory import Trajectory


@dataclass(frozen=True, eq=False)
class MapScore:
    """One estimated map against the ground-truth map: the cell sets (ground-truth frame, what
    errors.png draws) and the metrics counted from them (metrics.json's ``map``)."""

    sets: CellSets
    metrics: MapMetrics


@dataclass(frozen=True, eq=False)
class RunEvaluation:
    """Every score of a run against ground truth, each computed once (docs/metrics.md).

    Attributes:
        reference: the ground-truth trajectory (ground-truth frame, s and m).
        ate: the SE(2)-aligned ATE against ``reference``; ``ate.alignment`` is the pose of the
            run's map frame in the ground-truth frame and maps every estimate below.
        map: the final map (the cleaned one after a clean-up pass) against the ground-truth map.
        map_online: the online map when ``map`` is the cleaned one, else None.
        removal: removed beams against the per-beam labels (None without a removal mask or
            when the beam counts differ).
        removal_by_motion: the removal split by walking / standing / stopped movers (None
            without mover rows).
        time_to_m: how fast walking movers entered M (None without tracks or mover hits).
        cleanup: the clean-up pass's counters, as summary.json's ``cleanup`` (None without one).
    """

    reference: Trajectory
    ate: AteResult
    map: MapScore
    map_online: MapScore | None
    removal: RemovalMetrics | None
    removal_by_motion: MotionRemoval | None
    time_to_m: TimeToM | None
    cleanup: dict[str, Any] | None

    def as_dict(self) -> dict[str, Any]:
        """metrics.json: plain Python values, in the file's key order."""
        res, a = self.ate, self.ate.alignment
        out: dict[str, Any] = {
            "ate_rmse_m": res.trans.rmse,
            "ate_m": res.trans.as_dict(),
            "ate_rotation_rad": res.rot.as_dict(),
            "alignment": {"x": a.x, "y": a.y, "theta": a.theta},
            "poses_compared": res.n,
            "map": self.map.metrics.as_dict(),
        }
        if self.removal is not None:
            out["removal"] = self.removal.as_dict()
        if self.removal_by_motion is not None:
            out["removal_by_motion"] = self.removal_by_motion.as_dict()
        if self.time_to_m is not None:
            out["time_to_m"] = self.time_to_m.as_dict()
        if self.map_online is not None:
            out["map_online"] = self.map_online.metrics.as_dict()
        if self.cleanup is not None:
            out["cleanup"] = dict(self.cleanup)
        return out


def association_max_dt(reference: Trajectory) -> float:
    """The stamp tolerance a run is associated with its ground truth by: half the reference's median
    period (at least 1 ms; 0.01 s for a single pose), s."""
    dt = float(np.median(np.diff(reference.stamps))) / 2 if len(reference) > 1 else 0.01
    return max(dt, 1e-3)


def score_map(grid: GridMap, gt: GroundTruthFiles, ate_result: AteResult) -> MapScore:
    """``grid`` (the run's map frame) against the ground-truth map, through the ATE alignment."""
    from dynslam2d.eval.maps import cell_sets, map_metrics_of

    sets = cell_sets(grid, gt.static_map, transform=ate_result.alignment)
    return MapScore(sets, map_metrics_of(sets))


def evaluate_run(
    trajectory: Trajectory,
    grid: GridMap,
    gt: GroundTruthFiles,
    removed: np.ndarray | None = None,
    removed_stamps: np.ndarray | None = None,
    tracks: np.ndarray | None = None,
    *,
    cleaned: GridMap | None = None,
    cleanup: dict[str, Any] | None = None,
) -> RunEvaluation:
    """Score a run against ground truth (formulas in docs/metrics.md).

    - ATE (SE(2)-aligned, evo's definition) of ``trajectory`` against the GT trajectory;
    - map metrics (paper Eq. 9 IoU, Eq. 10 weighted RMSE, tolerant precision / recall /
      F1, ghost area) of ``grid`` against the GT static map, with the ATE alignment
      mapping the run's map frame into the ground-truth frame; with ``cleaned`` (the
      clean-up pass's map) the cleaned map is ``map`` and ``grid`` is ``map_online``;
    - with ``removed`` ((n, beams) bool, True = beam removed by the filter) and its stamps:
      precision / recall of removed beams against the per-beam labels;
    - with ``tracks`` (tracks.csv rows, :data:`dynslam2d.io.runfolder.TRACK_DTYPE`): how fast
      walking movers enter M (:func:`dynslam2d.eval.motionclass.time_to_m`).
    """
    from dynslam2d.eval.motionclass import removal_by_motion, time_to_m
    from dynslam2d.eval.removal import match_scans, removal_metrics
    from dynslam2d.eval.trajectory import ate

    max_dt = association_max_dt(gt.trajectory)
    res = ate(gt.trajectory, trajectory, align=True, max_dt=max_dt)
    a = res.alignment
    online = score_map(grid, gt, res)
    removal = by_motion = None
    if removed is not None and removed_stamps is not None and removed.size:
        i_run, i_gt = match_scans(removed_stamps, gt.stamps, max_dt=max_dt)
        lab = gt.labels[i_gt]
        rem = removed[i_run]
        if rem.shape[1] == lab.shape[1]:
            removal = removal_metrics(rem, lab)
            if gt.movers is not None and gt.movers.shape[0]:
                # walking / standing / stopped movers apart (dynslam2d.eval.motionclass)
                by_motion = removal_by_motion(rem, lab, gt.stamps[i_gt], gt.movers)
    caught = None
    if tracks is not None and gt.movers is not None and gt.movers.shape[0] and "hits" in (gt.movers.dtype.names or ()):
        caught = time_to_m(gt.movers, tracks, transform=a)
    if cleaned is None:
        return RunEvaluation(gt.trajectory, res, online, None, removal, by_motion, caught, cleanup)
    return RunEvaluation(gt.trajectory, res, score_map(cleaned, gt, res), online, removal, by_motion, caught, cleanup)


__all__ = ["MapScore", "RunEvaluation", "association_max_dt", "evaluate_run", "score_map"]
