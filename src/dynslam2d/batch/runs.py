"""``dynslam2d batch``: every job is one ``dynslam2d run`` into its own results folder.

Layout of a batch folder ``DIR`` (docs/batch.md)::

    DIR/batch.json               marker (written first) and, at the end, every run's summary and metrics
    DIR/batch.csv, DIR/batch.md  one row per run, in the jobs' order: settings, status, error,
                                 every summary.json and metrics.json value
    DIR/<run name>/              a results folder exactly as ``dynslam2d run`` writes it

Resumable: a run whose folder's ``run.json`` says ``"complete"`` (docs/reliability.md) and
whose ``batch_job.json`` names the same input, configuration and options is not run again;
its summary and metrics are read from the folder (a folder of a changed job is run again
and replaced). A run that fails is
recorded with its one-line error (its partial folder is removed) and is tried again by the
next invocation; it never stops the others.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dynslam2d.batch.engine import Outcome, map_jobs
from dynslam2d.batch.jobs import Job
from dynslam2d.errors import DynSlamError
from dynslam2d.io.atomic import write_text_atomic
from dynslam2d.io.outputs import check_writable_location, read_marker

#: The batch folder's marker and full record.
BATCH_MARKER = "batch.json"


@dataclass
class BatchResult:
    """Outcomes of a batch, in the jobs' order, and the files written."""

    jobs: list[Job]
    outcomes: list[Outcome]
    paths: dict[str, Path] = field(default_factory=dict)

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if o.status == "failed"]


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


#: Written into each run's folder before its results (so before run.json): what the run was asked
#: to do. A complete folder is skipped on resume only if this matches the job.
JOB_FILE = "batch_job.json"


def _job_record(job: Job) -> dict[str, Any]:
    return {"input": job.input, "config": job.config,
            "options": {k: v for k, v in job.options.items() if k != "folder"}}


def finished_value(folder: Path, job: Job | None = None) -> dict[str, Any] | None:
    """``{"summary", "metrics"}`` of a complete results folder (run.json says complete), else None.

    With ``job``: None also when the folder was made for another input, configuration or
    options (a changed ``--config``), so that resuming never keeps a stale run.
    """
    marker = read_marker(folder)
    if marker is None or marker.get("status") != "complete":
        return None
    if job is not None:
        record = _read_json(folder / JOB_FILE)
        if record is None or record != json.loads(json.dumps(_job_record(job), default=str)):
            return None
    summary = _read_json(folder / "summary.json")
    if summary is None:
        return None
    return {"summary": summary, "metrics": _read_json(folder / "metrics.json")}


def run_job(job: Job) -> dict[str, Any]:
    """Worker: run ``job`` like ``dynslam2d run`` into ``job.options["folder"]``; return its summary and metrics,
    and ``kernels``: which kernels this worker process ran (:func:`dynslam2d.jitaot.in_use`).

    The folder is planned as ``run --force`` would (an earlier incomplete attempt is
    replaced; a foreign non-empty folder is refused). On any error the folder is discarded.
    """
    from dynslam2d.config import config_from_dict
    from dynslam2d.inputs import open_source
    from dynslam2d.io.outputs import plan_results_folder
    from dynslam2d.pipeline import run as run_pipeline
    from dynslam2d.results import ground_truth_for, write_results
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    opts = dict(job.options)
    target = Path(opts.pop("folder"))
    cfg = config_from_dict(job.config, origin=f"batch job {job.name}")
    inputs = [] if job.input.startswith("sim:") else [Path(job.input)]
    folder = plan_results_folder(target, force=True, inputs=inputs)
    sim = job.input.startswith("sim:")  # --seed and --duration drive the simulator only
    source = open_source(job.input, opts.get("topic"), seed=opts.get("seed") if sim else None,
                         duration=opts.get("duration") if sim else None,
                         skip_bad=bool(opts.get("skip_bad", False)), odom=opts.get("odom", "auto"),
                         imu=opts.get("imu", "auto"))
    collector = RemovedPointsCollector()
    cleaner = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)  # (only its map, erased cells, stats)
    folder.start(input=source.meta.origin, batch_job=job.name)
    try:
        write_text_atomic(folder.work / JOB_FILE, json.dumps(_job_record(job), indent=2, default=str) + "\n")
        observers: list[Any] = [collector] + ([cleaner] if cfg.clean.enabled else [])
        result = run_pipeline(source, cfg, observers=observers)
        if result.n_scans and not result.map_updated.any():
            reasons = ", ".join(f"{k} ×{v}" for k, v in sorted(result.reasons.items())) or "no reason recorded"
            raise DynSlamError(f"{job.input}: none of the {result.n_scans} scans could enter the map ({reasons})")
        if result.n_scans == 0:
            raise DynSlamError(f"{job.input}: no scans")
        truth = ground_truth_for(source, None, cfg.slam.map_resolution)
        write_results(result, folder.work, truth, collector, cleaned=cleaner.result)
        folder.finish()
    except BaseException:
        folder.discard()
        raise
    value = finished_value(target)
    if value is None:
        raise DynSlamError(f"{target}: the results folder is not complete after the run")
    from dynslam2d.jitaot import in_use

    value["kernels"] = in_use()  # which kernels this worker ran (batch.json; docs/kernels.md)
    return value


def check_batch_folder(out: str | os.PathLike[str]) -> Path:
    """Raise DynSlamError unless ``out`` is new, empty, or an earlier batch folder (holds batch.json)."""
    p = Path(out)
    if p.exists():
        if not p.is_dir():
            raise DynSlamError(f"--out {out}: exists and is not a folder; give a new, empty or earlier batch folder")
        if any(p.iterdir()):
            marker = _read_json(p / BATCH_MARKER)
            if marker is None or marker.get("tool") != "dynslam2d" or marker.get("kind") != "batch":
                raise DynSlamError(f"--out {out}: folder is not empty and is not a dynslam2d batch folder "
                                   f"(no {BATCH_MARKER}); nothing was written, choose a new or empty folder")
        check_writable_location(p / "x", "--out")
    else:
        check_writable_location(p, "--out")
    return p


def run_batch(
    jobs: list[Job],
    out: str | os.PathLike[str],
    workers: int = 1,
    ray: str | None = None,
    on_outcome: Callable[[Outcome], None] | None = None,
) -> BatchResult:
    """Run every job into ``out/<job.name>/``, skip finished ones, then write batch.csv/md/json.

    ``on_outcome`` is called once per job (skipped ones first, then in completion order).
    """
    root = check_batch_folder(out)
    root.mkdir(parents=True, exist_ok=True)
    _write_record(root, jobs, None, status="running")
    outcomes: dict[str, Outcome] = {}
    todo: list[Job] = []
    for job in jobs:
        value = finished_value(root / job.name, job)
        if value is not None:
            outcomes[job.name] = Outcome(job.name, "skipped", value=value)
            if on_outcome is not None:
                on_outcome(outcomes[job.name])
        else:
            todo.append(Job(job.name, job.input, job.settings, job.config,
                            {**job.options, "folder": str(root / job.name)}))
    for o in map_jobs(run_job, todo, workers=workers, ray=ray, on_outcome=on_outcome):
        outcomes[o.name] = o
    ordered = [outcomes[j.name] for j in jobs]
    paths = {
        "batch.csv": write_text_atomic(root / "batch.csv", batch_csv(jobs, ordered)),
        "batch.md": write_text_atomic(root / "batch.md", batch_markdown(jobs, ordered)),
    }
    paths[BATCH_MARKER] = _write_record(root, jobs, ordered, status="complete")
    return BatchResult(jobs, ordered, paths)


def _write_record(root: Path, jobs: list[Job], outcomes: list[Outcome] | None, status: str) -> Path:
    runs = []
    for i, job in enumerate(jobs):
        entry: dict[str, Any] = {"name": job.name, "input": job.input, "settings": job.settings}
        if outcomes is not None:
            o = outcomes[i]
            entry.update(status=o.status, error=o.error, seconds=o.seconds, **(o.value or {}))
        runs.append(entry)
    data = {"tool": "dynslam2d", "kind": "batch", "status": status, "runs": runs}
    return write_text_atomic(root / BATCH_MARKER, json.dumps(data, indent=2, default=str) + "\n")


def flatten(data: Any, prefix: str) -> dict[str, Any]:
    """Nested dicts as ``prefix.a.b`` → scalar; lists as compact JSON text."""
    flat: dict[str, Any] = {}
    if isinstance(data, dict):
        for k, v in data.items():
            flat.update(flatten(v, f"{prefix}.{k}"))
    elif isinstance(data, (list, tuple)):
        flat[prefix] = json.dumps(data, separators=(",", ":"), default=str)
    else:
        flat[prefix] = data
    return flat


#: batch.csv columns that measure the machine (wall time, speed), not the result: they differ
#: between two runs of the same job; every other column is reproducible.
_TIMING = re.compile(r"(^seconds$|wall_time_s$|pass_time_s$|kernel_compile_s$|_ms$|_ms_median$|_ms_p95$|scans_per_s$|"
                     r"\.stage_ms_median\.)")


def is_timing_column(column: str) -> bool:
    """True for a batch.csv column that depends on the machine's speed and load (see :data:`_TIMING`)."""
    return bool(_TIMING.search(column))


def batch_rows(jobs: list[Job], outcomes: list[Outcome]) -> tuple[list[str], list[dict[str, Any]]]:
    """Columns and rows of batch.csv: run, input, the settings, status, error, seconds, then
    every ``summary.*`` and ``metrics.*`` value (sorted by name), one row per job in order."""
    keys: list[str] = []
    for job in jobs:
        keys += [k for k in job.settings if k not in keys]
    rows, values = [], set()
    for job, o in zip(jobs, outcomes):
        row: dict[str, Any] = {"run": job.name, "input": job.input, **job.settings,
                               "status": o.status, "error": o.error or "",
                               "seconds": round(o.seconds, 3) if o.status == "done" else ""}
        v = o.value or {}
        extra = {**flatten(v.get("summary") or {}, "summary"), **flatten(v.get("metrics") or {}, "metrics")}
        values.update(extra)
        row.update(extra)
        rows.append(row)
    columns = ["run", "input", *keys, "status", "error", "seconds"]
    columns += sorted(k for k in values if k.startswith("summary."))
    columns += sorted(k for k in values if k.startswith("metrics."))
    return columns, rows


def batch_csv(jobs: list[Job], outcomes: list[Outcome]) -> str:
    """batch.csv: every run's settings, status, error, summary and metrics (floats as repr)."""
    columns, rows = batch_rows(jobs, outcomes)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n", restval="")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else ("" if v is None else v)) for k, v in r.items()})
    return buf.getvalue()


def _num(row: dict[str, Any], key: str, digits: int, scale: float = 1.0) -> str:
    v = row.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "—"
    return f"{scale * v:.{digits}f}"


def batch_markdown(jobs: list[Job], outcomes: list[Outcome]) -> str:
    """batch.md: a headline table per run, then every value of every run (as in batch.csv)."""
    columns, rows = batch_rows(jobs, outcomes)
    keys = [c for c in columns[2:]
            if c not in ("status", "error", "seconds") and not c.startswith(("summary.", "metrics."))]
    head = ["run", *keys, "status", "scans", "scans/s", "removed %", "ATE m", "IoU", "error"]
    lines = ["# dynslam2d batch", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [str(r["run"]), *[str(r.get(k, "")) for k in keys], str(r["status"]),
                 _num(r, "summary.scans", 0), _num(r, "summary.scans_per_s", 0),
                 _num(r, "summary.removed_beam_share", 2, 100.0), _num(r, "metrics.ate_rmse_m", 4),
                 _num(r, "metrics.map.iou", 4), str(r["error"]).replace("|", "\\|")]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Every value of every run (the columns of batch.csv):", ""]
    for r in rows:
        lines += [f"<details><summary>{r['run']} ({r['status']})</summary>", "", "| key | value |", "|---|---|"]
        lines += [f"| {c} | {str(r[c]).replace('|', chr(92) + '|')} "
                  f"|" for c in columns if c in r and r[c] not in ("", None)]
        lines += ["", "</details>", ""]
    return "\n".join(lines)


__all__ = ["BATCH_MARKER", "BatchResult", "batch_csv", "batch_markdown", "batch_rows", "check_batch_folder",
           "finished_value", "flatten", "is_timing_column", "run_batch", "run_job"]
