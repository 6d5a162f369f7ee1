"""The ``dynslam2d`` command line: parse options, call the library, print results.

This module owns the terminal: library code raises :class:`DynSlamError`; here it
becomes one line on stderr and exit code 2. Nothing else lives here.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from dynslam2d import __version__
from dynslam2d.errors import DynSlamError

app = typer.Typer(
    name="dynslam2d",
    help="2D LiDAR SLAM for scenes that move: simulate, inspect, map and evaluate.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)

TopicOpt = Annotated[Optional[str], typer.Option("--topic", help="LaserScan topic, for bags holding several.")]
SkipBadOpt = Annotated[
    bool, typer.Option("--skip-bad", help="Skip malformed records and non-increasing stamps (counted) instead of stopping.")
]
SeedOpt = Annotated[Optional[int], typer.Option("--seed", help="Simulator seed (sim: inputs); default: the scenario's own.")]
DurationOpt = Annotated[
    Optional[float], typer.Option("--duration", min=0.1, help="Simulated duration in s (sim: inputs); default: the scenario's own.")
]


def _version_callback(value: bool) -> None:
    if value:
        console.print(f"dynslam2d {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version_callback, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """2D LiDAR SLAM for scenes that move.

    INPUT anywhere below is a ROS 1 .bag, a ROS 2 bag folder (sqlite3 or MCAP), an
    .mcap file, a CARMEN log (.clf/.log, optionally .gz) or sim:<scenario>.
    """


def _fmt(value: object, unit: str = "", digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, float):
        return f"{value:.{digits}f}{unit}"
    return f"{value}{unit}"


@app.command()
def info(
    input: Annotated[str, typer.Argument(help="File, bag folder or sim:<scenario> to describe.")],
    topic: TopicOpt = None,
    skip_bad: SkipBadOpt = False,
    seed: SeedOpt = None,
    duration: DurationOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON on stdout.")] = False,
) -> None:
    """Print what a scan source holds: format, topic, scans, beams, FOV, rate, duration, ranges."""
    from dynslam2d.io.sources import open_source
    from dynslam2d.io.summary import summarize_source

    source = open_source(input, topic, seed=seed, duration=duration, skip_bad=skip_bad)
    with console.status(f"reading {input} …", spinner="dots") as status:
        summary = summarize_source(source, progress=lambda n: status.update(f"reading {input} … {n} scans"))
    if as_json:
        sys.stdout.write(json.dumps(summary.as_dict(), indent=2, default=str) + "\n")
        return
    table = Table(title=f"{summary.origin}", show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column()
    beams = str(summary.beams_max) if summary.beams_min == summary.beams_max else f"{summary.beams_min}–{summary.beams_max}"
    rows = [
        ("format", summary.format),
        ("topic / record", summary.topic or "—"),
        ("frame", summary.frame_id or "—"),
        ("scans", str(summary.scans)),
        ("beams", beams),
        ("field of view", f"{math.degrees(summary.fov):.1f}°"),
        ("rate", _fmt(summary.rate_hz, " Hz", 2)),
        ("duration", _fmt(summary.duration, " s", 1)),
        ("stamps", f"{summary.first_stamp:.3f} → {summary.last_stamp:.3f} (largest gap {summary.max_gap:.3f} s)"),
        ("sensor range", f"{_fmt(summary.range_min, ' m', 2)} … {_fmt(summary.range_max, ' m', 2)}"),
        (
            "returns",
            f"min {_fmt(summary.valid_range_min, ' m', 2)}, median {_fmt(summary.valid_range_median, ' m', 2)}, "
            f"max {_fmt(summary.valid_range_max, ' m', 2)}",
        ),
        ("no-return beams", f"{100 * summary.no_return_share:.1f} %"),
    ]
    for key in ("skipped_lines", "skipped_scans", "warnings"):
        if summary.extra.get(key):
            rows.append((key.replace("_", " "), str(summary.extra[key])))
    for k, v in rows:
        table.add_row(k, v)
    console.print(table)


eval_app = typer.Typer(help="Evaluate trajectories: ATE, RPE, and Kümmerle relation errors.", no_args_is_help=True)
app.add_typer(eval_app, name="eval")


def _stats_table(title: str, rows: list[tuple[str, str]]) -> Table:
    table = Table(title=title, show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column(justify="right")
    for k, v in rows:
        table.add_row(k, v)
    return table


def _emit(result: dict[str, object], as_json: bool, table: Table) -> None:
    if as_json:
        sys.stdout.write(json.dumps(result, indent=2) + "\n")
    else:
        console.print(table)


JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")]
MaxDtOpt = Annotated[float, typer.Option("--max-dt", min=0.0, help="Largest stamp difference for associating poses, s.")]


@eval_app.command("ate")
def eval_ate(
    reference: Annotated[Path, typer.Argument(help="Reference trajectory (TUM).")],
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM).")],
    no_align: Annotated[bool, typer.Option("--no-align", help="Do not SE(2)-align the estimate first.")] = False,
    max_dt: MaxDtOpt = 0.01,
    as_json: JsonOpt = False,
) -> None:
    """Absolute trajectory error (translation), after SE(2) alignment, as evo_ape computes it."""
    from dynslam2d.eval.trajectory import ate
    from dynslam2d.io.trajectory import read_tum

    res = ate(read_tum(reference), read_tum(estimate), align=not no_align, max_dt=max_dt)
    a = res.alignment
    out = {"ate": res.trans.as_dict(), "rotation_rad": res.rot.as_dict(), "alignment": [a.x, a.y, a.theta]}
    rows = [(k, f"{getattr(res.trans, k):.4f} m") for k in ("rmse", "mean", "median", "std", "max")]
    rows += [("poses", str(res.n)), ("alignment", f"x {a.x:.3f} m, y {a.y:.3f} m, θ {a.theta:.4f} rad")]
    _emit(out, as_json, _stats_table(f"ATE {estimate} vs {reference}", rows))


@eval_app.command("rpe")
def eval_rpe(
    reference: Annotated[Path, typer.Argument(help="Reference trajectory (TUM).")],
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM).")],
    delta: Annotated[float, typer.Option("--delta", min=0.0, help="Pair distance, in --delta-unit.")] = 1,
    delta_unit: Annotated[str, typer.Option("--delta-unit", help="'frames' or 'm'.")] = "frames",
    all_pairs: Annotated[bool, typer.Option("--all-pairs", help="Use every pair, not consecutive ones.")] = False,
    max_dt: MaxDtOpt = 0.01,
    as_json: JsonOpt = False,
) -> None:
    """Relative pose error (translation and rotation) as evo_rpe computes it."""
    from dynslam2d.eval.trajectory import rpe
    from dynslam2d.io.trajectory import read_tum

    if delta_unit not in ("frames", "m"):
        raise DynSlamError(f"--delta-unit must be 'frames' or 'm', got {delta_unit!r}")
    d: float | int = int(delta) if delta_unit == "frames" else delta
    res = rpe(read_tum(reference), read_tum(estimate), delta=d, delta_unit=delta_unit, all_pairs=all_pairs, max_dt=max_dt)
    out = {"translation_m": res.trans.as_dict(), "rotation_rad": res.rot.as_dict()}
    rows = [
        ("translation rmse", f"{res.trans.rmse:.4f} m"),
        ("translation mean", f"{res.trans.mean:.4f} m"),
        ("rotation rmse", f"{math.degrees(res.rot.rmse):.3f}°"),
        ("rotation mean", f"{math.degrees(res.rot.mean):.3f}°"),
        ("pairs", str(res.n)),
    ]
    _emit(out, as_json, _stats_table(f"RPE (delta {delta:g} {delta_unit}) {estimate} vs {reference}", rows))


@eval_app.command("relations")
def eval_relations(
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM), e.g. a run's trajectory.tum, or a run folder.")],
    relations: Annotated[Path, typer.Argument(help="Kümmerle et al. relations file (t1 t2 x y z roll pitch yaw).")],
    tol: Annotated[float, typer.Option("--tol", min=0.0, help="Largest stamp difference to match a relation to a pose, s.")] = 1e-3,
    as_json: JsonOpt = False,
) -> None:
    """Relative pose error over ground-truth relations (Kümmerle et al. 2009): mean ± std."""
    from dynslam2d.eval.relations import relation_errors_from
    from dynslam2d.io.relations import read_relations
    from dynslam2d.io.trajectory import read_tum

    if estimate.is_dir():
        estimate = estimate / "trajectory.tum"
    res = relation_errors_from(read_tum(estimate), read_relations(relations), tol=tol)
    out = {
        "translation_m": {"mean": res.trans_mean, "std": res.trans_std, "rmse": res.trans_rmse},
        "rotation_deg": {"mean": res.rot_deg_mean, "std": res.rot_deg_std},
        "relations_used": res.n_used,
        "relations_unmatched": res.n_unmatched,
    }
    rows = [
        ("translation", f"{res.trans_mean:.3f} ± {res.trans_std:.3f} m"),
        ("rotation", f"{res.rot_deg_mean:.3f} ± {res.rot_deg_std:.3f}°"),
        ("relations used", f"{res.n_used} ({res.n_unmatched} unmatched)"),
    ]
    _emit(out, as_json, _stats_table(f"relations {relations.name} vs {estimate}", rows))


def main() -> None:
    """Console-script entry point: run the app, turning project errors into one line.

    Usage errors are click's (exit 2 with usage text); :class:`DynSlamError` becomes
    ``error: <message>`` on stderr with exit 2; Ctrl-C exits 130. Every writer is
    atomic, so an interrupted run leaves no half-written file under a final name.
    """
    try:
        app()
    except DynSlamError as exc:
        err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("[yellow]interrupted[/]")
        sys.exit(130)


if __name__ == "__main__":
    main()
