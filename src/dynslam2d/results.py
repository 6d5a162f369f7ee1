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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.config import dump_config
from dynslam2d.errors import DynSlamError
from dynslam2d.eval.runeval import RunEvaluation, evaluate_run
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.io.groundtruth import GroundTruthFiles, read_ground_truth_folder
from dynslam2d.io.mapfile import write_map
from dynslam2d.io.outputs import read_marker, write_marker
from dynslam2d.io.summary import input_report
from dynslam2d.io.trajectory import Trajectory, write_tum
from dynslam2d.memtrim import release_free_memory
from dynslam2d.pipeline import TRACK_CSV_COLUMNS, RunResult
from dynslam2d.slam.cleanup import CleanedLogodds, CleanResult
from dynslam2d.types import ScanSource
from dynslam2d.viz.collect import RemovedPointsCollector
from dynslam2d.viz.figures import figure_maps, write_figures
from dynslam2d.viz.mapplot import GreyMap
from dynslam2d.viz.tracksplot import tracks_background


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


def evaluate(trajectory: Trajectory, grid: GridMap, gt: GroundTruthFiles, removed: np.ndarray | None = None,
             removed_stamps: np.ndarray | None = None, tracks: np.ndarray | None = None) -> dict[str, Any]:
    """Every metric of a run against ground truth, as metrics.json holds them: the
    :meth:`~dynslam2d.eval.runeval.RunEvaluation.as_dict` of
    :func:`~dynslam2d.eval.runeval.evaluate_run` (formulas in docs/metrics.md)."""
    return evaluate_run(trajectory, grid, gt, removed, removed_stamps, tracks).as_dict()


def evaluate_result(run: RunResult, gt: GroundTruthFiles, cleaned: CleanResult | None = None) -> RunEvaluation:
    """:func:`~dynslam2d.eval.runeval.evaluate_run` on an in-memory run; with ``cleaned`` (the clean-up
    pass, docs/maps.md) its map is scored as ``map`` and the online map as ``map_online``."""
    from dynslam2d.io.runfolder import TRACK_DTYPE

    removed = run.removed
    tracks = np.array([tuple(r) for r in run.track_rows], dtype=TRACK_DTYPE)
    return evaluate_run(run.trajectory, run.grid, gt, removed if removed.size else None, run.trajectory.stamps, tracks,
                        cleaned=cleaned.grid if cleaned is not None else None,
                        cleanup=dict(cleaned.stats) if cleaned is not None else None)


def compute_metrics(run: RunResult, gt: GroundTruthFiles) -> dict[str, Any]:
    """:func:`evaluate` on an in-memory run (its online map)."""
    return evaluate_result(run, gt).as_dict()


def tracks_csv(run: RunResult) -> str:
    """tracks.csv text: one row per (scan, live track), columns :data:`TRACK_CSV_COLUMNS` (map frame)."""
    from dynslam2d.records import TrackRows

    rows = run.track_rows
    if isinstance(rows, TrackRows) and not any(set(n) & set(',"\r\n') for n in rows.state_names()):
        return _track_rows_csv(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TRACK_CSV_COLUMNS)
    mem = rows.remembered().tolist() if isinstance(rows, TrackRows) else [False] * len(rows)
    for row, rem in zip(rows, mem):
        stamp, tid, state, x, y, th, ln, wd, vx, vy, in_m = row
        w.writerow([repr(stamp), tid, state, f"{x:.4f}", f"{y:.4f}", f"{th:.4f}", f"{ln:.3f}", f"{wd:.3f}",
                    f"{vx:.4f}", f"{vy:.4f}", int(in_m), int(rem)])
    return buf.getvalue()


def _track_rows_csv(rows: Any) -> str:
    """:func:`tracks_csv` of a :class:`~dynslam2d.records.TrackRows` whose state names need no CSV quoting: the
    same text, formatted column-wise from the structured array's Python values instead of one tuple and one
    ``csv.writer`` call per row (tens of thousands of rows on a long run)."""
    a = rows.array()
    names = rows.state_names()
    states = [names[c] for c in a["state"].tolist()]
    cols = zip(a["stamp"].tolist(), a["id"].tolist(), states, a["x"].tolist(), a["y"].tolist(),
               a["heading"].tolist(), a["length"].tolist(), a["width"].tolist(), a["vx"].tolist(),
               a["vy"].tolist(), a["in_M"].tolist(), a["remembered"].tolist())
    lines = [",".join(TRACK_CSV_COLUMNS)]
    lines += [f"{t!r},{i},{st},{x:.4f},{y:.4f},{th:.4f},{ln:.3f},{wd:.3f},{vx:.4f},{vy:.4f},{int(m)},{int(r)}"
              for t, i, st, x, y, th, ln, wd, vx, vy, m, r in cols]
    lines.append("")
    return "\n".join(lines)


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


@dataclass(frozen=True, eq=False)
class RunOutputs:
    """What :func:`write_outputs` wrote, for a caller that reports on it without reading the files back.

    Attributes:
        paths: every written file by name (``"summary.json"``, ``"map.png"``, …).
        summary: summary.json's content as written (plain JSON values: lists, str keys, …).
        metrics: metrics.json's content as written, or None without ground truth.
        evaluation: the typed evaluation metrics.json and the figures came from, or None.
    """

    paths: dict[str, Path]
    summary: dict[str, Any]
    metrics: dict[str, Any] | None = None
    evaluation: RunEvaluation | None = None


def write_results(run: RunResult, out_dir: str | os.PathLike[str], gt: GroundTruthFiles | None = None,
                  collector: RemovedPointsCollector | None = None,
                  cleaned: CleanResult | None = None) -> dict[str, Path]:
    """Write the results of ``run`` into ``out_dir``; return the written paths by name
    (:func:`write_outputs`, whose other results the caller does not need)."""
    return write_outputs(run, out_dir, gt, collector, cleaned=cleaned).paths


def write_outputs(
    run: RunResult,
    out_dir: str | os.PathLike[str],
    gt: GroundTruthFiles | None = None,
    collector: RemovedPointsCollector | None = None,
    cleaned: CleanResult | None = None,
    release: bool = False,
) -> RunOutputs:
    """Write the results of ``run`` into ``out_dir``; return the paths, summary and metrics written.

    ``collector``: the :class:`~dynslam2d.viz.collect.RemovedPointsCollector` that watched
    the run (``run(..., observers=[collector])``), to draw the removed points in map.png.
    ``cleaned``: the clean-up pass's result (docs/maps.md); map.pgm/map.yaml and
    map_logodds.npy then hold the cleaned map and map_online.pgm/.yaml and
    map_logodds_online.npy the online one; metrics.json's ``map`` scores the cleaned map
    and ``map_online`` the online one.

    With ``gt`` the run is evaluated once (:func:`evaluate_result`): metrics.json, the
    summary's ``ate_rmse_m`` and the figures all come from that one :class:`RunEvaluation`.

    ``release``: the caller does not use ``run`` and ``cleaned`` afterwards (the command line): their log-odds
    and the loop closure's keyframes are let go once written, before the figures are drawn, and the maps as the
    figures are done with them (issue 13 item 3; ``run.logodds`` becomes a 0 × 0 array, ``cleaned.logodds``,
    ``run.grid`` and ``cleaned.grid`` None, ``run.loop.keyframes`` empty; :func:`write_figures`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    summary: dict[str, Any] | None = None
    evaluation: RunEvaluation | None = None
    if release:  # read before the maps go one by one below (the summary reads the online map's shape only)
        summary = run.summary()
        evaluation = evaluate_result(run, gt, cleaned) if gt is not None else None
    # the log-odds files first, each let go once written, then the maps (map.png's grey indices made from the
    # cleaned one, which goes before the online map's files): at most the two float64 maps and no log-odds live
    # at once (issue 13 item 3, pass mem48; the files are the same, only their order of writing differs)
    final_lo = cleaned.logodds if cleaned is not None and cleaned.logodds is not None else run.logodds
    with atomic_path(out / "map_logodds.npy") as tmp:
        with tmp.open("wb") as fh:
            if isinstance(final_lo, CleanedLogodds):  # (written a band of rows at a time: no copy of the map)
                final_lo.write_npy(fh, np.float32)
            else:
                np.save(fh, np.asarray(final_lo, dtype=np.float32))  # (no copy of a float32 map)
    paths["map_logodds.npy"] = out / "map_logodds.npy"
    del final_lo
    if release and cleaned is not None:
        cleaned.logodds = None
    if cleaned is not None:
        with atomic_path(out / "map_logodds_online.npy") as tmp:
            with tmp.open("wb") as fh:
                np.save(fh, np.asarray(run.logodds, dtype=np.float32))
        paths["map_logodds_online.npy"] = out / "map_logodds_online.npy"
    if release:  # nothing below reads them (the figures draw the maps' probabilities)
        run.logodds = np.zeros((0, 0), dtype=np.float32)
        # a map made when read (the run's online map, pipeline.ExportGridMap) holds its log-odds packed now: its
        # float64 map is made below without them beside it (MIT CSAIL: 9.1 MiB; issue 13 item 3, pass mem61)
        if hasattr(run.grid, "pack"):
            run.grid.pack()  # (no bound method kept here: it would keep the map through the figures)
    cleaned_grey = background = None
    if release and cleaned is not None and hasattr(cleaned.grid, "make_over"):  # (the pass's map, not made yet)
        # the online map's files and tracks.png's faint map first, then the cleaned map made over the online map's
        # own array (the same values): one float64 map lives here instead of two (issue 13 item 3, pass mem53)
        paths["map.yaml"] = paths["map.pgm"] = out / "map.yaml"  # (the keys in their usual order; set below)
        ypath, ppath = write_map(out / "map_online.yaml", run.grid)
        paths["map_online.yaml"], paths["map_online.pgm"] = ypath, ppath
        background = tracks_background(run.grid)
        online, run.grid = run.grid, None  # type: ignore[assignment]
        if not cleaned.grid.make_over(online):
            run.grid = online  # (not made from this online map: made in a copy below, as before)
        del online
    final_grid = cleaned.grid if cleaned is not None else run.grid
    ypath, ppath = write_map(out / "map.yaml", final_grid)
    paths["map.yaml"], paths["map.pgm"] = ypath, ppath
    del final_grid  # (a reference here kept the drawn map through the figures, which let it go when done)
    if release and cleaned is not None:  # map.png's grey indices now; the cleaned float64 map goes
        cleaned_grey = GreyMap.of(cleaned.grid)
        cleaned.grid = None  # type: ignore[assignment]
    if cleaned is not None and "map_online.yaml" not in paths:
        ypath, ppath = write_map(out / "map_online.yaml", run.grid)
        paths["map_online.yaml"], paths["map_online.pgm"] = ypath, ppath
    paths["trajectory.tum"] = write_tum(out / "trajectory.tum", run.trajectory, comment="laser pose in the map frame")
    if run.loop is not None:
        # loop closure (docs/slam.md): trajectory.tum is optimised, the front end's trajectory and the graph kept
        from dynslam2d.io.g2o import write_g2o

        front = run.frontend_trajectory if run.frontend_trajectory is not None else run.trajectory
        paths["trajectory_frontend.tum"] = write_tum(out / "trajectory_frontend.tum", front,
                                                     comment="laser pose in the map frame, front end before loop "
                                                             "closure")
        paths["graph.g2o"] = write_g2o(out / "graph.g2o", run.loop.graph)
    if release and run.loop is not None:
        run.loop.keyframes = []
    if summary is None:
        summary = run.summary()
        evaluation = evaluate_result(run, gt, cleaned) if gt is not None else None
    drawn = None
    if release:  # the maps as the figures' grey indices now: no float64 map lives through the files below
        drawn = figure_maps(run, cleaned, drawn=cleaned_grey, background=background)
        del cleaned_grey, background
    paths["config.yaml"] = write_text_atomic(out / "config.yaml", dump_config(run.config))
    paths["tracks.csv"] = write_text_atomic(out / "tracks.csv", tracks_csv(run))
    removed = run.removed
    with atomic_path(out / "kept_mask.npz") as tmp:
        with tmp.open("wb") as fh:
            # removed[i, b] is True where the filter removed beam b of scan i (stamps[i]).
            np.savez_compressed(fh, stamps=run.trajectory.stamps, removed=removed)
    paths["kept_mask.npz"] = out / "kept_mask.npz"
    del removed
    if cleaned is not None:
        summary["cleanup"] = dict(cleaned.stats)
    metrics = None
    if evaluation is not None:
        summary["ate_rmse_m"] = evaluation.ate.rmse
        text = metrics_json(evaluation.as_dict())
        paths["metrics.json"] = write_text_atomic(out / "metrics.json", text)
        metrics = json.loads(text)  # the values as written (JSON types), not the file read back
    summary.update(input_report(run.source))
    summary["status"] = "complete"
    summary_text = metrics_json(summary)
    paths["summary.json"] = write_text_atomic(out / "summary.json", summary_text)
    # Figures: map.png, tracks.png and, with ground truth, errors.png (dynslam2d.viz.figures).
    release_free_memory()  # figures allocate much; start them from a trimmed heap (memtrim.py)
    paths.update(write_figures(run, out, evaluation, collector, cleaned=cleaned, release=release, drawn=drawn))
    # run.json LAST: a folder whose run.json does not say "complete" lacks files (docs/reliability.md).
    paths["run.json"] = write_marker(out, "complete", scans=run.n_scans, input=run.source.origin,
                                     files=sorted(paths))
    return RunOutputs(paths, json.loads(summary_text), metrics, evaluation)


__all__ = ["RunOutputs", "compute_metrics", "evaluate", "evaluate_folder", "evaluate_result", "ground_truth_for",
           "write_outputs", "write_results"]
