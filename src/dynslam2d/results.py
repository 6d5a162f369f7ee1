"""A results folder: everything a run writes, each file atomically.

``write_results(run, out_dir, gt)`` writes map.pgm + map.yaml (map_server,
thresholds 0.65 / 0.196), map_logodds.npy, trajectory.tum, config.yaml,
summary.json, map.png and, with ground truth, metrics.json.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.config import dump_config
from dynslam2d.eval.trajectory import ate
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.io.groundtruth import GroundTruthFiles, read_ground_truth_folder
from dynslam2d.io.mapfile import write_map
from dynslam2d.io.trajectory import Trajectory, write_tum
from dynslam2d.pipeline import RunResult
from dynslam2d.types import ScanSource
from dynslam2d.viz.mapplot import plot_map


def ground_truth_for(source: ScanSource, gt_dir: str | os.PathLike[str] | None, resolution: float) -> GroundTruthFiles | None:
    """Ground truth for a run: from ``gt_dir`` if given, else from a simulated source, else None.

    Simulated ground truth is expressed in the first-scan frame (the SLAM map frame), like
    the files ``dynslam2d simulate`` writes.
    """
    if gt_dir is not None:
        return read_ground_truth_folder(gt_dir)
    inner = getattr(source, "inner", source)
    gt = getattr(inner, "ground_truth", None)
    if gt is None:
        return None
    return GroundTruthFiles(
        trajectory=Trajectory(stamps=gt.stamps.copy(), poses=gt.poses_in("first")),
        static_map=gt.static_map(resolution, frame="first"),
        stamps=gt.stamps.copy(),
        labels=gt.labels,
        movers=gt.mover_rows(frame="first"),
        info={"scenario": gt.scenario.name, "seed": gt.scenario.seed},
    )


def compute_metrics(run: RunResult, gt: GroundTruthFiles) -> dict[str, Any]:
    """Metrics of a run against ground truth: ATE (SE(2)-aligned, evo's definition)."""
    dt = float(np.median(np.diff(gt.trajectory.stamps))) / 2 if len(gt.trajectory) > 1 else 0.01
    res = ate(gt.trajectory, run.trajectory, align=True, max_dt=max(dt, 1e-3))
    a = res.alignment
    return {
        "ate_rmse_m": res.trans.rmse,
        "ate_m": res.trans.as_dict(),
        "ate_rotation_rad": res.rot.as_dict(),
        "alignment": {"x": a.x, "y": a.y, "theta": a.theta},
        "poses_compared": res.n,
    }


def _json(data: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        return str(o)

    return json.dumps(data, indent=2, default=default) + "\n"


def write_results(run: RunResult, out_dir: str | os.PathLike[str], gt: GroundTruthFiles | None = None) -> dict[str, Path]:
    """Write the results of ``run`` into ``out_dir``; return the written paths by name."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    ypath, ppath = write_map(out / "map.yaml", run.grid)
    paths["map.yaml"], paths["map.pgm"] = ypath, ppath
    with atomic_path(out / "map_logodds.npy") as tmp:
        with tmp.open("wb") as fh:
            np.save(fh, run.logodds.astype(np.float32))
    paths["map_logodds.npy"] = out / "map_logodds.npy"
    paths["trajectory.tum"] = write_tum(out / "trajectory.tum", run.trajectory, comment="laser pose in the map frame")
    paths["config.yaml"] = write_text_atomic(out / "config.yaml", dump_config(run.config))
    summary = run.summary()
    metrics = compute_metrics(run, gt) if gt is not None else None
    if metrics is not None:
        summary["ate_rmse_m"] = metrics["ate_rmse_m"]
        paths["metrics.json"] = write_text_atomic(out / "metrics.json", _json(metrics))
    paths["summary.json"] = write_text_atomic(out / "summary.json", _json(summary))
    ref_xy = None
    if gt is not None:
        # Draw the ground truth in the map frame of the run (inverse of the ATE alignment).
        al = metrics["alignment"] if metrics else None
        if al is not None:
            from dynslam2d.types import Pose2D

            inv = Pose2D(al["x"], al["y"], al["theta"]).inverse()
            ref_xy = inv.transform_points(gt.trajectory.xy)
    title = f"{run.source.origin} — {run.n_scans} scans"
    if metrics is not None:
        title += f", ATE RMSE {metrics['ate_rmse_m']:.3f} m"
    paths["map.png"] = plot_map(out / "map.png", run.grid, run.trajectory.xy, reference_xy=ref_xy, title=title)
    return paths


__all__ = ["compute_metrics", "ground_truth_for", "read_ground_truth_folder", "write_results"]
