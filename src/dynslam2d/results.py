"""A results folder: everything a run writes, each file atomically.

``write_results(run, out_dir, gt)`` writes map.pgm + map.yaml (map_server,
thresholds 0.65 / 0.196), map_logodds.npy, trajectory.tum, tracks.csv,
kept_mask.npz (``stamps`` (n,), ``removed`` (n, beams) bool), config.yaml,
summary.json, map.png, tracks.png and, with ground truth, metrics.json and errors.png;
then, last, run.json (``"status": "complete"``) that marks the folder as complete.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.config import dump_config
from dynslam2d.errors import DynSlamError
from dynslam2d.eval.maps import map_metrics
from dynslam2d.eval.motionclass import removal_by_motion, time_to_m
from dynslam2d.eval.removal import match_scans, removal_metrics
from dynslam2d.eval.trajectory import ate
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.io.groundtruth import GroundTruthFiles, read_ground_truth_folder
from dynslam2d.io.mapfile import write_map
from dynslam2d.io.outputs import read_marker, write_marker
from dynslam2d.io.summary import input_report
from dynslam2d.io.trajectory import Trajectory, write_tum
from dynslam2d.memtrim import release_free_memory
from dynslam2d.pipeline import TRACK_CSV_COLUMNS, RunResult
from dynslam2d.slam.cleanup import CleanResult
from dynslam2d.types import ScanSource
from dynslam2d.viz.collect import RemovedPointsCollector
from dynslam2d.viz.figures import write_figures


def ground_truth_for(source: ScanSource, gt_dir: str | os.PathLike[str] | GroundTruthFiles | None,
                     resolution: float) -> GroundTruthFiles | None:
    """Ground truth for a run: from ``gt_dir`` if given, else from a simulated source, else None.

    Simulated ground truth is expressed in the first-scan frame (the SLAM map frame), like
    the files ``dynslam2d simulate`` writes.
    """
    if isinstance(gt_dir, GroundTruthFiles):  # read already (the CLI checks --gt before the run)
        return gt_dir
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


def evaluate(
    trajectory: Trajectory,
    grid: GridMap,
    gt: GroundTruthFiles,
    removed: np.ndarray | None = None,
    removed_stamps: np.ndarray | None = None,
    tracks: np.ndarray | None = None,
) -> dict[str, Any]:
    """Every metric of a run against ground truth (formulas in docs/metrics.md).

    - ATE (SE(2)-aligned, evo's definition) of ``trajectory`` against the GT trajectory;
    - map metrics (paper Eq. 9 IoU, Eq. 10 weighted RMSE, tolerant precision / recall /
      F1, ghost area) of ``grid`` against the GT static map, with the ATE alignment
      mapping the run's map frame into the ground-truth frame;
    - with ``removed`` ((n, beams) bool, True = beam removed by the filter) and its stamps:
      precision / recall of removed beams against the per-beam labels;
    - with ``tracks`` (tracks.csv rows, :data:`dynslam2d.io.runfolder.TRACK_DTYPE`): how fast
      walking movers enter M (:func:`dynslam2d.eval.motionclass.time_to_m`).
    """
    dt = float(np.median(np.diff(gt.trajectory.stamps))) / 2 if len(gt.trajectory) > 1 else 0.01
    res = ate(gt.trajectory, trajectory, align=True, max_dt=max(dt, 1e-3))
    a = res.alignment
    out: dict[str, Any] = {
        "ate_rmse_m": res.trans.rmse,
        "ate_m": res.trans.as_dict(),
        "ate_rotation_rad": res.rot.as_dict(),
        "alignment": {"x": a.x, "y": a.y, "theta": a.theta},
        "poses_compared": res.n,
        "map": map_metrics(grid, gt.static_map, transform=a).as_dict(),
    }
    if removed is not None and removed_stamps is not None and removed.size:
        i_run, i_gt = match_scans(removed_stamps, gt.stamps, max_dt=max(dt, 1e-3))
        lab = gt.labels[i_gt]
        rem = removed[i_run]
        if rem.shape[1] == lab.shape[1]:
            out["removal"] = removal_metrics(rem, lab).as_dict()
            if gt.movers is not None and gt.movers.shape[0]:
                # walking / standing / stopped movers apart (dynslam2d.eval.motionclass)
                out["removal_by_motion"] = removal_by_motion(rem, lab, gt.stamps[i_gt], gt.movers).as_dict()
    if tracks is not None and gt.movers is not None and gt.movers.shape[0] and "hits" in (gt.movers.dtype.names or ()):
        out["time_to_m"] = time_to_m(gt.movers, tracks, transform=a).as_dict()
    return out


def compute_metrics(run: RunResult, gt: GroundTruthFiles) -> dict[str, Any]:
    """:func:`evaluate` on an in-memory run."""
    from dynslam2d.io.runfolder import TRACK_DTYPE

    removed = run.removed
    tracks = np.array([tuple(r) for r in run.track_rows], dtype=TRACK_DTYPE)
    return evaluate(run.trajectory, run.grid, gt, removed if removed.size else None, run.trajectory.stamps, tracks)


def tracks_csv(run: RunResult) -> str:
    """tracks.csv text: one row per (scan, live track), columns :data:`TRACK_CSV_COLUMNS` (map frame)."""
    from dynslam2d.records import TrackRows

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TRACK_CSV_COLUMNS)
    rows = run.track_rows
    mem = rows.remembered().tolist() if isinstance(rows, TrackRows) else [False] * len(rows)
    for row, rem in zip(rows, mem):
        stamp, tid, state, x, y, th, ln, wd, vx, vy, in_m = row
        w.writerow([repr(stamp), tid, state, f"{x:.4f}", f"{y:.4f}", f"{th:.4f}", f"{ln:.3f}", f"{wd:.3f}",
                    f"{vx:.4f}", f"{vy:.4f}", int(in_m), int(rem)])
    return buf.getvalue()


def evaluate_folder(run_dir: str | os.PathLike[str], gt_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """:func:`evaluate` on a results folder (``dynslam2d eval RUN_DIR --gt GT_DIR``)."""
    from dynslam2d.eval.maps import load_run_map
    from dynslam2d.io.runfolder import read_tracks
    from dynslam2d.io.trajectory import read_tum

    d = Path(run_dir)
    if not (d / "trajectory.tum").exists():
        raise DynSlamError(f"{d}: not a results folder (no trajectory.tum; write one with 'dynslam2d run')")
    marker = read_marker(d)
    if marker is not None and marker.get("status") != "complete":
        raise DynSlamError(
            f"{d}: results of an interrupted run ({marker.get('scans', '?')} scans, run.json status "
            f"{marker.get('status')!r}); run it again to score it"
        )
    removed = stamps = None
    mask_path = d / "kept_mask.npz"
    if mask_path.exists():
        with np.load(mask_path) as npz:
            removed, stamps = np.asarray(npz["removed"], dtype=bool), np.asarray(npz["stamps"], dtype=np.float64)
    tracks = read_tracks(d) if (d / "tracks.csv").exists() else None
    return evaluate(read_tum(d / "trajectory.tum"), load_run_map(d), read_ground_truth_folder(gt_dir), removed, stamps,
                    tracks)


def metrics_json(data: Any) -> str:
    """JSON text of a metrics / summary mapping (numpy values converted)."""
    def default(o: Any) -> Any:
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        return str(o)

    return json.dumps(data, indent=2, default=default) + "\n"


def write_results(
    run: RunResult,
    out_dir: str | os.PathLike[str],
    gt: GroundTruthFiles | None = None,
    collector: RemovedPointsCollector | None = None,
    cleaned: CleanResult | None = None,
) -> dict[str, Path]:
    """Write the results of ``run`` into ``out_dir``; return the written paths by name.

    ``collector``: the :class:`~dynslam2d.viz.collect.RemovedPointsCollector` that watched
    the run (``run(..., observers=[collector])``), to draw the removed points in map.png.
    ``cleaned``: the clean-up pass's result (docs/maps.md); map.pgm/map.yaml and
    map_logodds.npy then hold the cleaned map and map_online.pgm/.yaml and
    map_logodds_online.npy the online one; metrics.json's ``map`` scores the cleaned map
    and ``map_online`` the online one.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    final_grid = cleaned.grid if cleaned is not None else run.grid
    final_lo = cleaned.logodds if cleaned is not None and cleaned.logodds is not None else run.logodds
    ypath, ppath = write_map(out / "map.yaml", final_grid)
    paths["map.yaml"], paths["map.pgm"] = ypath, ppath
    with atomic_path(out / "map_logodds.npy") as tmp:
        with tmp.open("wb") as fh:
            np.save(fh, final_lo.astype(np.float32))
    paths["map_logodds.npy"] = out / "map_logodds.npy"
    if cleaned is not None:
        ypath, ppath = write_map(out / "map_online.yaml", run.grid)
        paths["map_online.yaml"], paths["map_online.pgm"] = ypath, ppath
        with atomic_path(out / "map_logodds_online.npy") as tmp:
            with tmp.open("wb") as fh:
                np.save(fh, run.logodds.astype(np.float32))
        paths["map_logodds_online.npy"] = out / "map_logodds_online.npy"
    paths["trajectory.tum"] = write_tum(out / "trajectory.tum", run.trajectory, comment="laser pose in the map frame")
    if run.loop is not None:
        # loop closure (docs/slam.md): trajectory.tum is optimised, the front end's trajectory and the graph kept
        from dynslam2d.io.g2o import write_g2o

        front = run.frontend_trajectory if run.frontend_trajectory is not None else run.trajectory
        paths["trajectory_frontend.tum"] = write_tum(out / "trajectory_frontend.tum", front,
                                                     comment="laser pose in the map frame, front end before loop "
                                                             "closure")
        paths["graph.g2o"] = write_g2o(out / "graph.g2o", run.loop.graph)
    paths["config.yaml"] = write_text_atomic(out / "config.yaml", dump_config(run.config))
    paths["tracks.csv"] = write_text_atomic(out / "tracks.csv", tracks_csv(run))
    removed = run.removed
    with atomic_path(out / "kept_mask.npz") as tmp:
        with tmp.open("wb") as fh:
            # removed[i, b] is True where the filter removed beam b of scan i (stamps[i]).
            np.savez_compressed(fh, stamps=run.trajectory.stamps, removed=removed)
    paths["kept_mask.npz"] = out / "kept_mask.npz"
    summary = run.summary()
    metrics = compute_metrics(run, gt) if gt is not None else None
    if cleaned is not None:
        summary["cleanup"] = dict(cleaned.stats)
        if metrics is not None:
            from dynslam2d.types import Pose2D

            a = metrics["alignment"]
            metrics["map_online"] = metrics["map"]
            metrics["map"] = map_metrics(cleaned.grid, gt.static_map,  # type: ignore[union-attr]
                                         transform=Pose2D(a["x"], a["y"], a["theta"])).as_dict()
            metrics["cleanup"] = dict(cleaned.stats)
    if metrics is not None:
        summary["ate_rmse_m"] = metrics["ate_rmse_m"]
        paths["metrics.json"] = write_text_atomic(out / "metrics.json", metrics_json(metrics))
    summary.update(input_report(run.source))
    summary["status"] = "complete"
    paths["summary.json"] = write_text_atomic(out / "summary.json", metrics_json(summary))
    # Figures: map.png, tracks.png and, with ground truth, errors.png (dynslam2d.viz.figures).
    release_free_memory()  # figures allocate much; start them from a trimmed heap (memtrim.py)
    paths.update(write_figures(run, out, gt, collector, cleaned=cleaned))
    # run.json LAST: a folder whose run.json does not say "complete" lacks files (docs/reliability.md).
    paths["run.json"] = write_marker(out, "complete", scans=run.n_scans, input=run.source.origin,
                                     files=sorted(paths))
    return paths


__all__ = ["compute_metrics", "evaluate", "evaluate_folder", "ground_truth_for", "write_results"]
