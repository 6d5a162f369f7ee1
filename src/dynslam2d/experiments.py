"""The paper's experiment (§3, Table 1, Figure 2) reproduced on the built-in simulator.

Three trials (``paper-1``, ``paper-2``, ``paper-3``: the paper's three tests) are
each mapped in four filter configurations:

- ``none``: raw scans (the paper's configuration 1, "unfiltered");
- ``fixed``: d = d_ref·λ/2 = 1.5 m, only when exactly 3 objects are in M (configuration 2);
- ``adaptive``: d_j = max(w_j, l_j)·λ/2 with λ = 1 (configuration 3);
- ``box``: our recommended setting, each object's own box plus a margin (docs/experiment.md;
  formerly named ``default``, which is still accepted).

Every run is scored against the simulator's ground truth with the metrics of
:mod:`dynslam2d.results` (paper Eq. 9 IoU, Eq. 10 weighted RMSE, and ours).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dynslam2d.config import Config, with_overrides
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import write_text_atomic
from dynslam2d.pipeline import run
from dynslam2d.results import evaluate, ground_truth_for
from dynslam2d.viz.figure import new_figure, save_png

TRIALS = ("paper-1", "paper-2", "paper-3")
CONFIGURATIONS = ("none", "fixed", "adaptive", "box")

#: The paper's Table 1 (IoU and weighted RMSE, unfiltered vs filtered), for comparison.
PAPER_TABLE1 = {
    "paper-1": {"iou_unfiltered": 0.2234, "rmse_unfiltered": 0.0362, "iou_filtered": 0.1503, "rmse_filtered": 0.0115},
    "paper-2": {"iou_unfiltered": 0.1133, "rmse_unfiltered": 0.1763, "iou_filtered": 0.1044, "rmse_filtered": 0.1675},
    "paper-3": {"iou_unfiltered": 0.1787, "rmse_unfiltered": 0.0303, "iou_filtered": 0.1223, "rmse_filtered": 0.0205},
}

#: Columns of table.csv / table.json rows, in order.
COLUMNS = (
    "trial", "config", "iou", "weighted_rmse", "iou_tolerant", "f1_tolerant", "ghost_area_m2", "ate_rmse_m",
    "removal_precision", "removal_recall", "static_removed_share", "scans", "scans_per_s",
)


@dataclass(eq=False)
class ExperimentResult:
    """Rows of the table (one per trial × configuration) and the maps for the figure."""

    rows: list[dict[str, object]] = field(default_factory=list)
    maps: dict[tuple[str, str], GridMap] = field(default_factory=dict)
    truth: dict[str, GridMap] = field(default_factory=dict)


@dataclass(eq=False)
class ExperimentJob:
    """One cell of the table: a trial mapped in one filter configuration (a batch engine job)."""

    name: str
    trial: str
    mode: str
    duration: float | None
    base: Config


#: Trials simulated in this process: (trial, duration) → (source, simulation, ground truth), at most
#: one per trial of the paper, so a worker simulates each trial once (about 1 s) and reuses its scans.
_SIMULATED: dict[tuple[str, float | None], tuple[object, object, object]] = {}


def _simulated(trial: str, duration: float | None, resolution: float) -> tuple[object, object, object]:
    from dynslam2d.sim import SimSource

    key = (trial, duration)
    if key not in _SIMULATED:
        while len(_SIMULATED) >= len(TRIALS):
            _SIMULATED.pop(next(iter(_SIMULATED)))
        source = SimSource(trial, duration=duration)
        sim = source.simulation  # simulate once, reuse the scans for every configuration
        gt = ground_truth_for(source, None, resolution)
        assert gt is not None
        _SIMULATED[key] = (source, sim, gt)
    return _SIMULATED[key]


def run_cell(job: ExperimentJob) -> tuple[dict[str, object], GridMap, GridMap]:
    """Map ``job.trial`` with filter ``job.mode`` and score it: (table row, map, ground-truth map)."""
    _, sim, gt = _simulated(job.trial, job.duration, job.base.slam.map_resolution)
    cfg = with_overrides(job.base, {"filter": {"mode": job.mode}})
    result = run(sim.source(), cfg)  # type: ignore[attr-defined]
    removed = result.removed
    metrics = evaluate(result.trajectory, result.grid, gt, removed, result.trajectory.stamps)  # type: ignore[arg-type]
    m, r = metrics["map"], metrics.get("removal", {})
    row = {
        "trial": job.trial,
        "config": job.mode,
        "iou": m["iou"],
        "weighted_rmse": m["weighted_rmse"],
        "iou_tolerant": m["iou_tolerant"],
        "f1_tolerant": m["f1"],
        "ghost_area_m2": m["ghost_area_m2"],
        "ate_rmse_m": metrics["ate_rmse_m"],
        "removal_precision": r.get("precision", float("nan")),
        "removal_recall": r.get("recall", float("nan")),
        "static_removed_share": r.get("static_removed_share", float("nan")),
        "scans": result.n_scans,
        "scans_per_s": result.n_scans / result.wall_time_s if result.wall_time_s > 0 else float("nan"),
    }
    return row, result.grid, gt.static_map  # type: ignore[attr-defined]


def run_experiment(
    trials: tuple[str, ...] = TRIALS,
    configurations: tuple[str, ...] = CONFIGURATIONS,
    duration: float | None = None,
    base: Config | None = None,
    progress: Callable[[str], None] | None = None,
    workers: int = 1,
    ray: str | None = None,
) -> ExperimentResult:
    """Map every trial in every configuration and score it against ground truth.

    The cells run through the batch engine (:func:`dynslam2d.batch.engine.map_jobs`):
    one after the other in this process by default, on ``workers`` processes, or on Ray;
    the table's rows are in the same order and hold the same values either way (only
    scans/s depends on the machine's load).

    Args:
        duration: shorten each trial to this many seconds (None = the scenario's own 60 s).
        base: configuration the filter modes are applied to (defaults otherwise).
        progress: called with "trial / mode" as each cell finishes.
        workers, ray: where the cells run (see :func:`dynslam2d.batch.engine.map_jobs`).
    """
    from dynslam2d.batch.engine import map_jobs
    from dynslam2d.errors import DynSlamError

    base = base or Config()
    jobs = [ExperimentJob(f"{t} / {m}", t, m, duration, base) for t in trials for m in configurations]
    outcomes = map_jobs(run_cell, jobs, workers=workers, ray=ray,
                        on_outcome=(lambda o: progress(o.name)) if progress is not None else None)
    _SIMULATED.clear()  # the simulated scans are not needed any more
    out = ExperimentResult()
    for job, o in zip(jobs, outcomes):
        if o.status != "done":
            raise DynSlamError(f"experiment {job.name}: {o.error}")
        row, grid, truth = o.value
        out.truth.setdefault(job.trial, truth)
        out.rows.append(row)
        out.maps[(job.trial, job.mode)] = grid
    return out


def _fmt(v: object, digits: int = 4) -> str:
    if isinstance(v, float):
        return "—" if not np.isfinite(v) else f"{v:.{digits}f}"
    return str(v)


def table_markdown(rows: list[dict[str, object]]) -> str:
    """The results table as Markdown, with the paper's Table 1 values beside ours."""
    head = ("| trial | config | IoU | wRMSE | IoU@0.10 m | F1@0.10 m | ghost m² | ATE m | "
            "removal P | removal R | static removed | scans/s |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:
        lines.append(
            f"| {r['trial']} | {r['config']} | {_fmt(r['iou'])} | {_fmt(r['weighted_rmse'])} | "
            f"{_fmt(r['iou_tolerant'])} | {_fmt(r['f1_tolerant'])} | {_fmt(r['ghost_area_m2'], 3)} | "
            f"{_fmt(r['ate_rmse_m'])} | {_fmt(r['removal_precision'], 3)} | {_fmt(r['removal_recall'], 3)} | "
            f"{_fmt(100 * float(r['static_removed_share']), 2)} % | {_fmt(r['scans_per_s'], 0)} |"
        )
    lines += ["", "The paper's Table 1 (Gazebo, its own maps):", "",
              "| trial | IoU unfiltered | wRMSE unfiltered | IoU filtered | wRMSE filtered |", "|---|---|---|---|---|"]
    for trial, p in PAPER_TABLE1.items():
        lines.append(f"| {trial} | {p['iou_unfiltered']} | {p['rmse_unfiltered']} | {p['iou_filtered']} | "
                     f"{p['rmse_filtered']} |")
    return "\n".join(lines) + "\n"


def table_csv(rows: list[dict[str, object]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def plot_figure2(result: ExperimentResult, path: str | os.PathLike[str], dpi: int = 110) -> Path:
    """The paper's Figure 2: ground-truth outline and each configuration's map, per trial.

    Rows are trials; columns are the ground truth and the configurations. Every panel shows
    the same window (the ground-truth extent, map frame of the first scan); maps are drawn
    as occupancy (black occupied, white free, grey unknown) with the ground-truth outline
    in red on top, so ghosts (black off the red) and gaps (red without black) show.
    """
    from dynslam2d.viz.mapplot import occupancy_image

    trials = list(result.truth)
    modes = sorted({m for _, m in result.maps}, key=lambda m: CONFIGURATIONS.index(m) if m in CONFIGURATIONS else 99)
    ncol = 1 + len(modes)
    fig = new_figure((3.2 * ncol, 3.3 * len(trials) + 0.4))
    axes = fig.subplots(len(trials), ncol, squeeze=False)
    by_key = {(r["trial"], r["config"]): r for r in result.rows}
    for i, trial in enumerate(trials):
        truth = result.truth[trial]
        x0, x1, y0, y1 = truth.extent
        occ = truth.occupied(0.5)
        for j in range(ncol):
            ax = axes[i, j]
            if j == 0:
                ax.imshow(np.where(occ, 0.0, 1.0), cmap="gray", vmin=0, vmax=1, origin="lower",
                          extent=truth.extent, interpolation="nearest")
                ax.set_title(f"{trial}: ground truth", fontsize=9)
            else:
                mode = modes[j - 1]
                grid = result.maps[(trial, mode)]
                ax.imshow(occupancy_image(grid), cmap="gray", vmin=0, vmax=1, origin="lower",
                          extent=grid.extent, interpolation="nearest")
                ys, xs = np.nonzero(occ)
                ax.scatter(truth.origin[0] + (xs + 0.5) * truth.resolution,
                           truth.origin[1] + (ys + 0.5) * truth.resolution, s=0.15, c="tab:red", linewidths=0)
                r = by_key.get((trial, mode), {})
                ax.set_title(f"{mode}: ghost {float(r.get('ghost_area_m2', np.nan)):.2f} m², "
                             f"wRMSE {float(r.get('weighted_rmse', np.nan)):.3f}", fontsize=8)
            ax.set_xlim(x0, x1)
            ax.set_ylim(y0, y1)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=6)
    fig.suptitle("Maps per trial and filter configuration (red: ground-truth structure)", fontsize=11)
    fig.tight_layout()
    return save_png(fig, path, dpi)


def write_experiment(result: ExperimentResult, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Write table.md, table.csv, table.json and figure2.png into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "table.md": write_text_atomic(out / "table.md", table_markdown(result.rows)),
        "table.csv": write_text_atomic(out / "table.csv", table_csv(result.rows)),
        "table.json": write_text_atomic(
            out / "table.json",
            json.dumps({"rows": result.rows, "paper_table1": PAPER_TABLE1}, indent=2, default=float) + "\n",
        ),
    }
    paths["figure2.png"] = plot_figure2(result, out / "figure2.png")
    return paths
