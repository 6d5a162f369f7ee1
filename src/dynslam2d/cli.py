"""The ``dynslam2d`` command line: parse options, call the library, print results.

This module owns the terminal: library code raises :class:`DynSlamError`; here it
becomes one line on stderr and exit code 2. Nothing else lives here.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.cells import cell_len
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from rich.text import Text
from typer.core import TyperArgument, TyperCommand, TyperGroup

from dynslam2d import __version__
from dynslam2d.errors import DynSlamError

if TYPE_CHECKING:  # annotations only: the commands import what they use when they run
    from dynslam2d.config import Config
    from dynslam2d.io.groundtruth import GroundTruthFiles
    from dynslam2d.io.outputs import ResultsFolder
    from dynslam2d.pipeline import RunResult
    from dynslam2d.results import RunOutputs
    from dynslam2d.slam.cleanup import CleanResult, CleanupRecorder
    from dynslam2d.types import Pose2D, ScanSource
    from dynslam2d.viz.collect import RemovedPointsCollector


class _Console(Console):
    """A rich Console that never wraps lines when its output is not a terminal: a pipe or a
    file gets each line at full width (a terminal keeps rich's wrapping to its width)."""

    @property  # type: ignore[override]
    def soft_wrap(self) -> bool:
        return not self.is_terminal

    @soft_wrap.setter
    def soft_wrap(self, value: bool) -> None:  # Console.__init__ assigns it; the output decides
        pass


class _Command(TyperCommand):
    """A command whose arguments read as ``INPUT`` (not ``{input}``) in the usage line and help."""

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        pieces = [self.options_metavar] if self.options_metavar else []
        for p in self.get_params(ctx):
            if isinstance(p, TyperArgument):
                name = p.metavar or (p.name or "").upper()
                name = name if p.required else f"[{name}]"
                pieces.append(name + ("..." if p.nargs != 1 else ""))
            else:
                pieces.extend(p.get_usage_pieces(ctx))
        return pieces


class _Group(TyperGroup):
    """A command group that prints its help on stdout with exit 0 when called bare, and lists
    its commands with their whole first sentence (click cuts it to the terminal width)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for cmd in self.commands.values():
            if type(cmd) is TyperCommand:
                cmd.__class__ = _Command  # typer builds plain TyperCommands; ours only changes the help
                for p in cmd.params:
                    if isinstance(p, TyperArgument) and p.metavar is None and p.name:
                        p.metavar = p.name.upper()

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        if not args and not ctx.resilient_parsing:
            typer.echo(ctx.get_help())
            ctx.exit(0)
        return super().parse_args(ctx, args)

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        rows = []
        for name in self.list_commands(ctx):
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                rows.append((name, cmd.get_short_help_str(limit=10_000)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


#: ``-h`` is help everywhere; help text up to 100 columns (click's default caps it at 80).
CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}

app = typer.Typer(
    name="dynslam2d",
    cls=_Group,
    help="2D LiDAR SLAM for scenes that move: simulate, inspect, map and evaluate.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts hold literal brackets: [0.05], "dynslam2d[viewer]"
    context_settings=CONTEXT,
)
console = _Console()
err_console = _Console(stderr=True)


def _plain(con: Console, cell: object) -> str:
    if isinstance(cell, Text):
        return cell.plain
    return con.render_str(str(cell)).plain if cell is not None else ""


def _show(table: Table, con: Console | None = None) -> None:
    """Print a table: boxed by rich on a terminal; to a pipe or file as plain text at full
    width (title on its own line, columns separated by two spaces, nothing cut)."""
    con = con or console
    if con.is_terminal:
        if table.title is not None:  # on a line of its own: rich would wrap it to the table's width
            con.print(Text(_plain(con, table.title), style="table.title"))
            table.title = None
        con.print(table)
        return
    cols = table.columns
    cells = [[_plain(con, c) for c in col.cells] for col in cols]
    grid = [[_plain(con, col.header) for col in cols]] if table.show_header else []
    grid += [list(row) for row in zip(*cells)]
    widths = [max((cell_len(r[i]) for r in grid), default=0) for i in range(len(cols))]
    lines = [_plain(con, table.title)] if table.title else []
    for r in grid:
        # right-aligned columns stay so while short (numbers); a long text column reads better left-aligned
        parts = [(" " * (w - cell_len(c)) + c) if col.justify == "right" and w <= 24 else c + " " * (w - cell_len(c))
                 for c, w, col in zip(r, widths, cols)]
        lines.append("  ".join(parts).rstrip())
    con.file.write("\n".join(lines) + "\n")

TopicOpt = Annotated[str | None, typer.Option("--topic", help="LaserScan topic, for bags holding several.")]
SkipBadOpt = Annotated[
    bool, typer.Option(
        "--skip-bad", help="Skip malformed records and non-increasing stamps (counted) instead of stopping.")
]
SeedOpt = Annotated[int | None, typer.Option(
    "--seed", help="Simulator seed (sim: inputs); default: the scenario's own.")]
SetOpt = Annotated[list[str] | None, typer.Option(
    "--set", metavar="KEY=VALUE", help="Set one config key (dotted as in 'dynslam2d config dump'; the value is read "
                                       "as YAML), after --config and before the named options; repeat for more, "
                                       "e.g. --set detect.tracker.m_exit_time=2 --set loop.far_searches=8.")]
DurationOpt = Annotated[
    float | None, typer.Option(
        "--duration", min=0.1, help="Simulated duration in s (sim: inputs); default: the scenario's own.")
]


OdomOpt = Annotated[
    str,
    typer.Option("--odom", help="Odometry prior: auto (what the recording has: nav_msgs/Odometry, TF odom→base_link, "
                 "wheel speeds + IMU, CARMEN pose fields / ODOM records, the simulator's), none (laser only), "
                 "or a topic, 'tf', or a CARMEN record type (FLASER, ODOM)."),
]
ImuOpt = Annotated[
    str, typer.Option("--imu", help="IMU yaw rate: auto (the recording's sensor_msgs/Imu), none, or a topic.")
]
LaserOffsetOpt = Annotated[
    str | None,
    typer.Option("--laser-offset", help="base_link → laser transform x,y,yaw (m, m, rad) when the recording has no "
                 "TF for it, e.g. -0.12,0,0 (overrides TF)."),
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
    odom: OdomOpt = "auto",
    imu: ImuOpt = "auto",
    laser_offset: LaserOffsetOpt = None,
    body_scans: Annotated[int, typer.Option("--body-scans", min=0, help="Look for the robot's own body (returns "
                                            "fixed in the laser frame while it drives) in the first N scans and "
                                            "suggest a footprint; 0 = skip.")] = 600,
) -> None:
    """Print what a scan source holds: format, topic, scans, beams, FOV, rate, duration, ranges, robot body.

    A bag with several LaserScan topics and no --topic: every scan topic (one row each), the other topics
    (odometry, TF, IMU, poses) and what 'run' needs (--topic)."""
    from dynslam2d.inputs import open_source
    from dynslam2d.io.odometry import parse_laser_offset
    from dynslam2d.io.summary import summarize_source

    _check_sim_only(input, seed, duration)
    if topic is not None and not topic.strip():
        raise DynSlamError(f"--topic is empty; give the LaserScan topic name (see 'dynslam2d info {input}')")
    offset = parse_laser_offset(laser_offset) if laser_offset else None
    if topic is None and _several_scan_topics(input):
        _info_bag_overview(input, skip_bad=skip_bad, odom=odom, imu=imu, body_scans=body_scans, as_json=as_json)
        return
    source = open_source(input, topic, seed=seed, duration=duration, skip_bad=skip_bad, odom=odom, imu=imu,
                         laser_offset=offset)
    first: list = []  # the first body_scans scans, kept while the summary reads the source once

    class _KeepFirst:
        meta = source.meta

        def __iter__(self) -> Iterator:
            for scan in source:
                if len(first) < body_scans:
                    first.append(scan)
                yield scan

    with console.status(Text(f"reading {input} …"), spinner="dots") as status:
        summary = summarize_source(_KeepFirst(), progress=lambda n: status.update(Text(f"reading {input} … {n} scans")))
        body = None
        if body_scans > 0 and first:
            from dynslam2d.pipeline import find_body

            status.update(Text(f"looking for the robot's body in the first {len(first)} scans …"))
            body = find_body(first, max_scans=body_scans)
    if as_json:
        out = summary.as_dict()
        if body is not None:
            out["body"] = body
        sys.stdout.write(json.dumps(out, indent=2, default=str) + "\n")
        return
    table = Table(title=Text(f"{summary.origin}"), show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column()
    beams = (str(summary.beams_max) if summary.beams_min == summary.beams_max
             else f"{summary.beams_min}–{summary.beams_max}")
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
    odo = source.meta.extra.get("odometry")
    if isinstance(odo, dict):
        rows.append(("odometry", f"{source.meta.odometry or '—'} ({odo.get('with_odom', '?')} of "
                                 f"{odo.get('scans', '?')} scans; laser mount {odo.get('mount')} from "
                                 f"{odo.get('mount_source')})"))
    for key in ("skipped_lines", "skipped_scans", "warnings"):
        if summary.extra.get(key):
            rows.append((key.replace("_", " "), str(summary.extra[key])))
    if body is not None:
        rows.append(("robot body", _body_line(body)))
    for k, v in rows:
        table.add_row(k, Text(str(v)))
    _show(table)


#: The order in which ``info``'s bag overview lists the other topics, by role (io/baginfo.py ``topic_role``).
_ROLE_ORDER = ("odometry", "TF", "static TF", "IMU", "wheel speeds", "poses", "other")


def _several_scan_topics(input: str) -> bool:
    """Whether ``input`` is a bag file or folder (not a pipe) holding more than one LaserScan topic."""
    from dynslam2d.io.baginfo import laserscan_topics
    from dynslam2d.io.sources import SIM_PREFIX, is_stream, sniff_format

    if input.startswith(SIM_PREFIX) or is_stream(input):
        return False
    if sniff_format(input) not in ("ros1-bag", "ros2-bag", "mcap", "zip"):
        return False
    return len(laserscan_topics(input)) > 1


def _info_bag_overview(input: str, *, skip_bad: bool, odom: str, imu: str, body_scans: int, as_json: bool) -> None:
    """``info`` on a bag with several LaserScan topics: one row per scan topic (read in one pass), the robot
    body each laser sees in its first ``body_scans`` scans, the other topics, and the ``--topic`` choice."""
    from dynslam2d.io.baginfo import describe_bag, topic_role

    with console.status(Text(f"reading {input} …"), spinner="dots") as status:
        bag = describe_bag(input, keep_first=body_scans, skip_bad=skip_bad, odom=odom, imu=imu,
                           progress=lambda n: status.update(Text(f"reading {input} … {n} scans")))
        bodies: dict[str, dict] = {}
        if body_scans > 0:
            from dynslam2d.pipeline import find_body

            for name, first in bag.first_scans.items():
                if first:
                    status.update(Text(f"looking for the robot's body in the first {len(first)} scans of {name} …"))
                    bodies[name] = find_body(first, max_scans=body_scans)
    names = list(bag.scans)
    if as_json:
        out = bag.as_dict()
        for name, body in bodies.items():
            out["scans"][name]["body"] = body  # type: ignore[index]
        out["run_needs_topic"] = names
        sys.stdout.write(json.dumps(out, indent=2, default=str) + "\n")
        return
    table = Table(title=Text(f"{input}: {bag.format}, {len(names)} LaserScan topics"), title_justify="left")
    for head in ("topic", "messages", "rate", "duration", "beams", "field of view", "sensor range", "median return",
                 "no return", "frame", "robot body"):
        table.add_column(head, justify="left" if head in ("topic", "frame", "robot body") else "right")
    for name, s in bag.scans.items():
        beams = str(s.beams_max) if s.beams_min == s.beams_max else f"{s.beams_min}–{s.beams_max}"
        table.add_row(
            Text(name), str(bag.topics[name][1]),
            _fmt(s.rate_hz, " Hz", 2), _fmt(s.duration, " s", 1), beams, f"{math.degrees(s.fov):.1f}°",
            f"{_fmt(s.range_min, '', 2)}–{_fmt(s.range_max, ' m', 2)}", _fmt(s.valid_range_median, " m", 2),
            f"{100 * s.no_return_share:.1f} %", Text(s.frame_id or "—"), Text(_body_cell(bodies.get(name))))
    _show(table)
    lines = []
    for name, s in bag.scans.items():
        if s.extra.get("skipped_scans"):
            lines.append(f"{name}: {s.extra['skipped_scans']} of {bag.topics[name][1]} stamps do not increase "
                         "(left out above; 'run' needs --skip-bad)")
        if s.extra.get("skipped_messages"):
            lines.append(f"{name}: {s.extra['skipped_messages']} malformed messages skipped")
    others: dict[str, list[str]] = {role: [] for role in _ROLE_ORDER}
    for name, (msgtype, count) in bag.topics.items():
        if name not in bag.scans:
            role = topic_role(name, msgtype) or "other"
            others.setdefault(role, []).append(f"{name} ({msgtype.replace('/msg/', '/')}, {count})")
    lines += [f"{role}: {', '.join(items)}" for role, items in others.items() if items] or ["other topics: none"]
    tried = bag.odometry["odometry"]
    lines.append(f"--odom {odom}: " + (" else ".join(tried) if tried else "none (laser only)")  # type: ignore[arg-type]
                 + f"; --imu {imu}: {bag.odometry['imu'] or 'none'}")
    lines += [str(n) for n in bag.odometry["notes"]]  # type: ignore[attr-defined]
    for name, body in bodies.items():
        if body.get("auto_body_beams"):
            lines.append(f"{name} body footprint (laser frame {bag.scans[name].frame_id or '?'}, "
                         f"detect.footprint.polygon): {body['suggested_footprint']}")
    lines.append(f"'dynslam2d run' maps one of them: --topic {' | '.join(names)}; "
                 f"'dynslam2d info {input} --topic T' describes one in full")
    for line in lines:
        console.print(Text(line), soft_wrap=True)


def _body_cell(body: dict | None) -> str:
    """The robot-body cell of ``info``'s bag overview (the full line is ``info --topic``'s)."""
    if body is None:
        return "—"
    if body.get("auto_body_beams"):
        lo, hi = body["body_range_m"]
        return f"{body['auto_body_beams']} beams at {lo:.2f}–{hi:.2f} m"
    return "none" if body.get("enough_motion") else f"unknown (laser moved {body['travel_m']:.1f} m)"


def _body_line(body: dict) -> str:
    """One line for ``info``: the body beams found in the first scans and the footprint to configure."""
    seen = (f"the first {body['scans_used']} scans (laser moved {body['travel_m']:.1f} m, turned "
            f"{body['turn_rad']:.1f} rad)")
    if body.get("auto_body_beams"):
        lo, hi = body["body_range_m"]
        return (f"{body['auto_body_beams']} beams return a fixed range {lo:.2f}–{hi:.2f} m while the laser moves, in "
                f"{seen}: the robot itself; suggested detect.footprint.polygon: {body['suggested_footprint']}")
    if not body.get("enough_motion"):
        return (f"not found in {seen}: a laser that hardly moves cannot tell its body from a wall; "
                "'dynslam2d run' keeps looking over the whole recording (summary.json 'body')")
    return f"none found in {seen}"


@app.command()
def simulate(
    scenario: Annotated[str, typer.Argument(
        help="Scenario name (see --list), e.g. paper, paper-1, static, crowd.")] = "paper",
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output folder (default: results/sim-<scenario>-<time>).")] = None,
    seed: SeedOpt = None,
    duration: DurationOpt = None,
    resolution: Annotated[float, typer.Option(
        "--map-resolution", min=0.005, help="Ground-truth map cell size, m.")] = 0.05,
    storage: Annotated[str, typer.Option(
        "--storage", help="Scan bag: mcap (bare .mcap), sqlite3 (ROS 2 folder) or ros1 (.bag).")] = "mcap",
    beams: Annotated[int | None, typer.Option("--beams", min=1, help="Beams per scan [720].")] = None,
    fov_deg: Annotated[float | None, typer.Option(
        "--fov-deg", min=1.0, max=360.0, help="Field of view, degrees [360].")] = None,
    rate: Annotated[float | None, typer.Option("--rate", min=0.1, help="Scan rate, Hz [20].")] = None,
    noise: Annotated[float | None, typer.Option("--noise", min=0.0, help="Gaussian range noise σ, m [0.01].")] = None,
    dropout: Annotated[float | None, typer.Option(
        "--dropout", min=0.0, max=1.0, help="Probability a beam returns nothing [0].")] = None,
    range_max: Annotated[float | None, typer.Option("--range-max", min=0.1, help="Sensor max range, m [20].")] = None,
    list_scenarios: Annotated[bool, typer.Option("--list", help="List the scenarios and exit.")] = False,
    force: Annotated[bool, typer.Option(
        "--force", help="Replace an earlier output folder of dynslam2d at --out (never anything else).")] = False,
    odom_noise: Annotated[float, typer.Option(
        "--odom-noise", min=0.0, help="Multiplies every odometry/IMU noise, bias and scale error of the default model "
                                      "(0 = perfect odometry) [1].")] = 1.0,
    laser_mount: Annotated[str | None, typer.Option(
        "--laser-mount", help="The laser's pose on the robot base, x,y,yaw (m, m, rad) [0.15,0,0].")] = None,
    as_json: Annotated[bool, typer.Option(
        "--json", help="Print the scenario list (--list) or the written files as JSON on stdout.")] = False,
) -> None:
    """Simulate a scene: scans as a bag, ground truth (map, trajectory, labels, movers), an overview PNG.

    The folder can be mapped with `dynslam2d run DIR/scans.mcap` and used as `--gt DIR`.
    """
    from dynslam2d.sim import SCENARIOS
    from dynslam2d.sim import simulate as run_simulation
    from dynslam2d.sim.export import write_simulation

    if list_scenarios and as_json:
        sys.stdout.write(json.dumps([{"name": name, "duration_s": spec.duration, "seed": spec.seed,
                                      "description": spec.description} for name, spec in SCENARIOS.items()],
                                    indent=2) + "\n")
        return
    if list_scenarios:
        table = Table(title="scenarios", title_justify="left")
        table.add_column("name", style="bold")
        table.add_column("duration", justify="right")
        table.add_column("seed", justify="right")
        table.add_column("description")
        for name, spec in SCENARIOS.items():
            table.add_row(name, f"{spec.duration:g} s", str(spec.seed), spec.description)
        _show(table)
        return
    from dynslam2d.io.outputs import plan_results_folder, write_marker

    out = out or _default_out(f"sim-{scenario}")
    folder = plan_results_folder(out, force=force)  # before simulating: a bad --out fails at once
    with console.status(Text(f"simulating {scenario} …"), spinner="dots"):
        sensor = {"beams": beams, "fov": math.radians(fov_deg) if fov_deg else None, "rate_hz": rate,
                  "noise_sigma": noise, "dropout": dropout, "range_max": range_max}
        from dynslam2d.io.odometry import parse_laser_offset
        from dynslam2d.sim.odometry import OdometryModel

        model = OdometryModel().scaled(odom_noise)
        if laser_mount is not None:
            import dataclasses as _dc

            model = _dc.replace(model, mount=parse_laser_offset(laser_mount, "--laser-mount"))
        sim = run_simulation(scenario, seed=seed, duration=duration, odometry_model=model,
                             **{k: v for k, v in sensor.items() if v is not None})
    with console.status(Text(f"writing {out} …"), spinner="dots"):
        try:
            folder.start(input=f"sim:{scenario}")
            work = folder.work
            paths = write_simulation(sim, work, map_resolution=resolution, storage=storage)
            write_marker(work, "complete", input=f"sim:{scenario}", kind="simulation")
            folder.finish()
        except BaseException:
            folder.discard()
            raise
        paths = {k: out / Path(v).relative_to(work) for k, v in paths.items()}
    sc = sim.scenario
    if as_json:
        sys.stdout.write(json.dumps({"scenario": sc.name, "seed": sc.seed, "scans": len(sim.scans),
                                     "duration_s": sc.duration, "movers": len(sc.movers), "out": str(out),
                                     "files": {k: str(v) for k, v in paths.items()}}, indent=2) + "\n")
        return
    console.print(Text.assemble(
        "simulated ", (sc.name, "bold"), f" (seed {sc.seed}): {len(sim.scans)} scans over {sc.duration:g} s, "
        f"{len(sc.movers)} movers"
    ))
    for path in paths.values():
        console.print(Text(f"  {path}"))
    console.print(Text(f"map it with: dynslam2d run {paths['scans']} --gt {out}"))


def _laser_mount(meta: Any) -> Any:
    """The base_link → laser Pose2D of a source (for --frame base_link), or a DynSlamError."""
    from dynslam2d.types import Pose2D

    odo = meta.extra.get("odometry")
    if not isinstance(odo, dict) or odo.get("mount") is None:
        raise DynSlamError(f"{meta.origin}: --frame base_link needs the base_link → laser transform, and the input "
                           f"gives none (no odometry/TF used); give --laser-offset x,y,yaw")
    return Pose2D(*map(float, odo["mount"]))


def _default_out(prefix: str) -> Path:
    import datetime as _dt

    return Path("results") / f"{prefix}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}"


config_app = typer.Typer(cls=_Group, help="Show the configuration.", no_args_is_help=True)
app.add_typer(config_app, name="config")


@config_app.command("dump")
def config_dump(
    config: Annotated[Path | None, typer.Option(
        "--config", help="Start from this YAML file instead of the defaults.")] = None,
    as_json: Annotated[bool, typer.Option(
        "--json", help="Print the values as JSON instead of commented YAML.")] = False,
) -> None:
    """Print the full configuration as YAML (defaults, or a file completed with defaults)."""
    from dynslam2d.config import Config, dump_config, load_config

    cfg = load_config(config) if config else Config()
    if as_json:
        sys.stdout.write(json.dumps(cfg.model_dump(mode="json"), indent=2) + "\n")
        return
    sys.stdout.write(dump_config(cfg))


@app.command()
def run(
    input: Annotated[str, typer.Argument(help="Bag, bag folder, .mcap, CARMEN log or sim:<scenario>.")] = "sim:paper",
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Results folder (default: results/run-<time>).")] = None,
    topic: TopicOpt = None,
    gt: Annotated[Path | None, typer.Option(
        "--gt", help="Ground-truth folder written by 'dynslam2d simulate' (for metrics).")] = None,
    config: Annotated[Path | None, typer.Option(
        "--config", help="YAML configuration (see 'dynslam2d config dump').")] = None,
    sets: SetOpt = None,
    map_resolution: Annotated[float | None, typer.Option(
        "--map-resolution", help="Finest map cell size, m [0.05].")] = None,
    map_levels: Annotated[int | None, typer.Option("--map-levels", help="Map levels [3].")] = None,
    update_distance: Annotated[float | None, typer.Option(
        "--map-update-distance-thresh", "--update-distance", help="Map update after this translation, m "
                                                                  "(slam.map_update_distance_thresh) [0.4].")] = None,
    update_angle: Annotated[float | None, typer.Option(
        "--map-update-angle-thresh", "--update-angle", help="Map update after this rotation, rad "
                                                            "(slam.map_update_angle_thresh) [0.06].")] = None,
    laser_min_dist: Annotated[float | None, typer.Option(
        "--laser-min-dist", help="Ignore returns closer than this, m [0.4].")] = None,
    laser_max_dist: Annotated[float | None, typer.Option(
        "--laser-max-dist", help="Ignore returns farther than this, m [30].")] = None,
    filter_mode: Annotated[str | None, typer.Option(
        "--filter-mode", "--filter", help="Dynamic-point filter (filter.mode): none, fixed, adaptive (the paper's "
                                          "configurations 1-3) or box (ours: each moving object's box plus a margin; "
                                          "'default' is its old name) [box].")] = None,
    constant_velocity: Annotated[bool | None, typer.Option(
        "--constant-velocity/--no-constant-velocity", help="Predict with constant velocity instead of the previous "
                                                           "pose.")] = None,
    correlative: Annotated[str | None, typer.Option(
        "--correlative-mode", "--correlative", help="Correlative search seed: auto, always or never "
                                                    "(slam.correlative_mode) [auto].")] = None,
    hector_compat: Annotated[bool, typer.Option(
        "--hector-compat", help="Behave like the reference hector_mapping: raw Gauss-Newton step, its swapped "
                                "gradient, no correlative search.")] = False,
    animate: Annotated[bool, typer.Option(
        "--animate", help="Also write run.gif: scan points (kept / removed), tracked boxes, the growing map.")] = False,
    frame_step: Annotated[int, typer.Option(
        "--frame-step", min=1, help="With --animate: one frame every N scans.")] = 5,
    write_bag: Annotated[Path | None, typer.Option(
        "--write-bag", help="Also write a bag for RViz / Foxglove: .mcap (default), .db3, .bag (ROS 1) or a folder "
                            "(ROS 2).")] = None,
    bag_storage: Annotated[str | None, typer.Option(
        "--bag-storage", help="ROS 2 storage for a bag folder: mcap or sqlite3.")] = None,
    map_period: Annotated[float, typer.Option(
        "--map-period", min=0.0, help="Seconds of scan time between /map messages (bag, viewer); 0 = every "
                                      "scan.")] = 1.0,
    viewer: Annotated[str, typer.Option(
        "--viewer", help="Live viewer: none or rerun (pip install \"dynslam2d[viewer]\").")] = "none",
    rerun_save: Annotated[Path | None, typer.Option(
        "--rerun-save", help="With --viewer rerun: save a .rrd recording instead of opening the viewer.")] = None,
    seed: SeedOpt = None,
    duration: DurationOpt = None,
    skip_bad: SkipBadOpt = False,
    force: Annotated[bool, typer.Option(
        "--force", help="Replace an earlier results folder (one with run.json) at --out and a bag dynslam2d wrote at "
                        "--write-bag; never anything else.")] = False,
    checkpoint_period: Annotated[float, typer.Option(
        "--checkpoint-period", min=0.0, help="Write the trajectory and map so far into OUT every this many seconds (0 "
                                             "= never).")] = 60.0,
    checkpoint_scans: Annotated[int, typer.Option(
        "--checkpoint-scans", min=0, help="Also checkpoint every this many scans (0 = only by time).")] = 0,
    odom: OdomOpt = "auto",
    imu: ImuOpt = "auto",
    laser_offset: LaserOffsetOpt = None,
    range_scale: Annotated[str | None, typer.Option(
        "--laser-range-scale", "--range-scale", help="Multiply every range by this (a lidar that reads short: > 1), or "
                                                     "'auto': estimate it from the recording's odometry "
                                                     "(laser.range_scale) [1].")] = None,
    frame: Annotated[str, typer.Option("--frame", help="Poses in trajectory.tum: laser (default) or base_link "
                                       "(laser pose ⊕ (base_link→laser)⁻¹; needs TF, CARMEN pose fields or "
                                       "--laser-offset).")] = "laser",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or table.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON on stdout.")] = False,
    loop_closure: Annotated[str | None, typer.Option(
        "--loop-closure", help="Loop closure and pose-graph optimisation behind the front end: on (trajectory.tum and "
                               "the map from the optimised poses; trajectory_frontend.tum and graph.g2o too) or off "
                               "(the front end alone) [on] (loop.enabled).")] = None,
    clean: Annotated[str | None, typer.Option("--clean", help="Clean-up pass after the run: on (map.pgm = cleaned "
                                                 "static map, map_online.pgm = online map) or off [on] "
                                                 "(docs/maps.md).")] = None,
) -> None:
    """Detect and remove moving objects, map the rest with Hector-style SLAM.

    Writes into OUT: map.pgm + map.yaml (map_server; the cleaned static map, docs/maps.md),
    map_online.pgm + map_online.yaml (the online map; not with --clean off), map_logodds.npy, trajectory.tum,
    tracks.csv, kept_mask.npz, config.yaml, summary.json, map.png, tracks.png and, with
    ground truth (sim: inputs or --gt), metrics.json and errors.png; run.gif with --animate.
    """
    _check_run_options(input, topic, viewer, {
        "--map-resolution": map_resolution, "--update-distance": update_distance, "--update-angle": update_angle,
        "--laser-min-dist": laser_min_dist, "--laser-max-dist": laser_max_dist, "--map-period": map_period})
    early = _early_background_compile()  # an empty cache: the second CPU compiles while this process imports
    cfg = _run_config(config, {
        "map_resolution": map_resolution, "map_levels": map_levels,
        "map_update_distance_thresh": update_distance, "map_update_angle_thresh": update_angle,
        "laser_min_dist": laser_min_dist, "laser_max_dist": laser_max_dist,
        "constant_velocity": constant_velocity, "correlative_mode": correlative,
    }, filter_mode=filter_mode, range_scale=range_scale, clean=clean, loop_closure=loop_closure,
        hector_compat=hector_compat, sets=sets or [])
    _check_sim_only(input, seed, duration)
    inputs = _input_paths(input, gt, config)
    truth_files = _read_gt(gt)  # before the first scan: a bad --gt fails now
    from dynslam2d.inputs import open_source
    from dynslam2d.io.odometry import parse_laser_offset

    if frame not in ("laser", "base_link"):
        raise DynSlamError(f"--frame must be 'laser' or 'base_link', got {frame!r}")
    offset = parse_laser_offset(laser_offset) if laser_offset else None
    out = out or _default_out("run")
    folder = _plan_run_folder(out, force, inputs, write_bag)  # outputs first: reading a log can take long
    compiling, background = _cold_start(early)  # before the input's first scan, which may need kernels already
    source = open_source(input, topic, seed=seed, duration=duration, skip_bad=skip_bad, odom=odom, imu=imu,
                         laser_offset=offset)
    mount = _laser_mount(source.meta) if frame == "base_link" else None
    _check_source(source, cfg, write_bag)
    show = not (quiet or as_json)
    _announce_run(source, show, compiling)
    from dynslam2d.io.checkpoint import Checkpointer
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    collector = RemovedPointsCollector()
    cleaner = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)  # (only its map, erased cells and stats)
    folder.start(input=source.meta.origin)
    checkpointer = Checkpointer(folder.work, every_s=checkpoint_period, every_scans=checkpoint_scans,
                                info={"input": source.meta.origin})
    old_term = _sigterm_as_interrupt()
    pause = _compile_collector_pause(compiling)  # no cyclic collector while the kernels compile (jitcache.py)
    try:
        with contextlib.ExitStack() as stack:
            observers: list[Any] = [collector, checkpointer, *([pause] if pause is not None else [])]
            observers += _run_observers(stack, cfg, folder.work, cleaner, animate=animate, frame_step=frame_step,
                                        write_bag=write_bag, bag_storage=bag_storage, map_period=map_period,
                                        viewer=viewer, rerun_save=rerun_save)
            result = _map_with_progress(source, cfg, observers, show)
        _check_run_usable(result, input)
        from dynslam2d.results import ground_truth_for

        truth = ground_truth_for(source, truth_files, cfg.slam.map_resolution)
        outputs = _write_run_outputs(result, folder.work, out, truth, collector, cleaner.result, mount)
        folder.finish()
    except KeyboardInterrupt:
        _interrupted(folder, checkpointer)
    except BaseException:
        folder.discard()
        raise
    finally:
        _restore_sigterm(old_term)
        if pause is not None:
            pause.resume()
        if background is not None:
            background.stop()
    if as_json:
        sys.stdout.write(json.dumps({**outputs.summary, "out": str(out)}, indent=2) + "\n")
        return
    if quiet:
        return
    _warn_odometry_gaps(source.meta.extra.get("odometry"))
    _print_run(input, outputs, source.meta.extra.get("odometry"), compiling)
    console.print(Text.assemble("results in ", (str(out), "bold")))
    if write_bag is not None:
        console.print(Text.assemble("bag for RViz / Foxglove: ", (str(write_bag), "bold"), " (docs/ros.md)"))
    _suggest_kernel_build(compiling, input)


def _check_run_options(input: str, topic: str | None, viewer: str, numbers: dict[str, float | None]) -> None:
    """``run``'s options that need no file: the viewer's name, finite numbers, a non-empty topic."""
    if viewer not in ("none", "rerun"):
        raise DynSlamError(f"--viewer must be 'none' or 'rerun', got {viewer!r}")
    for name, value in numbers.items():
        if value is not None and not math.isfinite(value):
            raise DynSlamError(f"{name} must be a finite number, got {value}")
    if topic is not None and not topic.strip():
        raise DynSlamError(f"--topic is empty; give the LaserScan topic name (see 'dynslam2d info {input}')")


def _on_off(name: str, value: str) -> bool:
    """An on/off option's value as a bool."""
    if value not in ("on", "off"):
        raise DynSlamError(f"{name} must be 'on' or 'off', got {value!r}")
    return value == "on"


def _run_config(config: Path | None, slam: dict[str, Any], *, filter_mode: str | None, range_scale: str | None,
                clean: str | None, loop_closure: str | None, hector_compat: bool, sets: list[str]) -> Config:
    """``run``'s configuration: the --config file (or the defaults), then the --set KEY=VALUE assignments, then
    every named option given on the command line (``slam``: slam.* keys, None = not given)."""
    from dynslam2d.config import Config, load_config, with_assignments, with_overrides

    cfg = with_assignments(load_config(config) if config else Config(), sets)
    cfg = with_overrides(cfg, {"slam": slam})
    if filter_mode is not None:
        cfg = with_overrides(cfg, {"filter": {"mode": filter_mode}})
    if range_scale is not None:
        cfg = with_overrides(cfg, {"laser": {"range_scale": _parse_range_scale(range_scale)}})
    if clean is not None:
        cfg = with_overrides(cfg, {"clean": {"enabled": _on_off("--clean", clean)}})
    if loop_closure is not None:
        cfg = with_overrides(cfg, {"loop": {"enabled": _on_off("--loop-closure", loop_closure)}})
    if hector_compat:
        cfg = with_overrides(cfg, {"slam": {"hector_gradient_bug": True, "step_mode": "gauss_newton",
                                            "correlative_mode": "never"}})
    return cfg


def _read_gt(gt: Path | None) -> GroundTruthFiles | None:
    """The --gt folder's ground truth, or None."""
    if gt is None:
        return None
    from dynslam2d.io.groundtruth import read_ground_truth_folder

    return read_ground_truth_folder(gt)


def _plan_run_folder(out: Path, force: bool, inputs: list[Path], write_bag: Path | None) -> ResultsFolder:
    """The results folder to write (and the --write-bag target checked against it), before any work."""
    from dynslam2d.io.outputs import check_bag_target, plan_results_folder, same_or_inside

    folder = plan_results_folder(out, force=force, inputs=inputs)
    if write_bag is not None:
        check_bag_target(write_bag, force=force, inputs=inputs, out=out)
        if folder.replace and same_or_inside(write_bag, out):
            raise DynSlamError(f"--write-bag {write_bag}: lies inside --out {out}, which is replaced; put the bag "
                               f"elsewhere")
    return folder


def _check_source(source: ScanSource, cfg: Config, write_bag: Path | None) -> None:
    """What the opened input must allow before the run: odometry for --range-scale auto, a map that fits; then
    the parts an interrupted --write-bag left are cleared."""
    odo_info = source.meta.extra.get("odometry") or {}
    if cfg.laser.range_scale == "auto" and not odo_info.get("has_odometry", bool(odo_info.get("source"))):
        raise DynSlamError(f"{source.meta.origin}: --range-scale auto needs odometry, and the input has none "
                           "(see --odom; or give the scale as a number)")
    _check_map_size(source, cfg)
    if write_bag is not None:
        from dynslam2d.io.outputs import clean_stale_parts

        clean_stale_parts(write_bag)


def _announce_run(source: ScanSource, show: bool, cold: bool) -> None:
    """Before a run, on stderr: the odometry used, the input's warnings, and whether kernels compile."""
    if show:
        err_console.print(f"odometry: {escape(source.meta.odometry or 'none (laser only)')}")
        for w in source.meta.extra.get("warnings", []) or []:
            err_console.print(f"[yellow]warning:[/] {escape(str(w))}")
    _say_if_compiling(show, cold)


def _run_observers(stack: contextlib.ExitStack, cfg: Config, work: Path, cleaner: CleanupRecorder, *, animate: bool,
                   frame_step: int, write_bag: Path | None, bag_storage: str | None, map_period: float, viewer: str,
                   rerun_save: Path | None) -> list[Any]:
    """The optional observers of a run, in order: the clean-up recorder, the animation, the bag, the live viewer
    (those that hold files or windows are entered on ``stack``)."""
    observers: list[Any] = []
    if cfg.clean.enabled:
        observers.append(cleaner)
    if animate:
        from dynslam2d.viz.animate import Animator

        observers.append(Animator(work / "run.gif", frame_step=frame_step))
    if write_bag is not None:
        from dynslam2d.io.rosout import BagRecorder

        observers.append(stack.enter_context(BagRecorder(write_bag, storage=bag_storage, map_period=map_period)))
    if viewer == "rerun":
        from dynslam2d.viz.live import RerunViewer

        observers.append(stack.enter_context(RerunViewer(save=rerun_save, map_period=map_period)))
    return observers


def _map_with_progress(source: ScanSource, cfg: Config, observers: list[Any], show: bool) -> RunResult:
    """Run the pipeline over ``source`` with a progress bar on stderr (scans/s after the first scan)."""
    import time

    from dynslam2d.pipeline import run as run_pipeline

    total = source.meta.count
    progress = _progress_bar("mapping", "rate", show)
    with progress:
        task = progress.add_task("map", total=total, rate="")
        state = {"t0": None}

        def tick(n: int, step: object) -> None:
            now = time.perf_counter()
            if state["t0"] is None:
                state["t0"] = now
            if n % 10 == 0 or n == total:
                el = now - state["t0"]
                progress.update(task, completed=n, rate=f"{(n - 1) / el:.0f} scans/s" if el > 0 else "")

        # (a hidden bar draws nothing: no callback then, ≈ 2 µs a scan less; docs/speed.md, pass rec110)
        result = run_pipeline(source, cfg, progress=tick if show else None, observers=observers)
        progress.update(task, completed=result.n_scans)
    return result


def _write_run_outputs(result: RunResult, work: Path, out: Path, truth: GroundTruthFiles | None,
                       collector: RemovedPointsCollector, cleaned: CleanResult | None,
                       mount: Pose2D | None) -> RunOutputs:
    """Write the results folder (evaluated once against ``truth`` when there is one); with --frame base_link
    turn its trajectories into base_link poses. Returns what was written (:class:`dynslam2d.results.RunOutputs`)."""
    from dynslam2d.results import write_outputs

    try:
        outputs = write_outputs(result, work, truth, collector, cleaned=cleaned, release=True)
        if mount is not None:
            _rewrite_frame(work, mount)
            from dynslam2d.io.odometry import base_frame_fields

            outputs.summary.update(base_frame_fields(mount))  # as rewritten into summary.json
    except OSError as exc:  # disk full, folder removed under our feet, …
        raise DynSlamError(f"--out {out}: cannot write the results ({exc.strerror or exc}); nothing was "
                           f"kept") from None
    return outputs


def _rewrite_frame(work: Path, mount: Pose2D) -> None:
    """--frame base_link: trajectory.tum (and the front end's, with loop closure) as base_link poses."""
    from dynslam2d.io.odometry import rewrite_trajectory_frame

    rewrite_trajectory_frame(work, mount)
    if (work / "trajectory_frontend.tum").exists():  # loop closure: the front end's too
        from dynslam2d.io.odometry import compose_mount
        from dynslam2d.io.trajectory import Trajectory, read_tum, write_tum

        ft = read_tum(work / "trajectory_frontend.tum")
        write_tum(work / "trajectory_frontend.tum",
                  Trajectory(ft.stamps, compose_mount(ft.poses, mount.inverse()), ft.frame),
                  comment="base_link pose in the map frame, front end before loop closure")


def _warn_odometry_gaps(odo: Any) -> None:
    """After a run, on stderr: scans that had no odometry or no IMU yaw rate."""
    if isinstance(odo, dict) and (odo.get("without_odom") or 0) > 0:
        err_console.print(f"[yellow]warning:[/] odometry: {odo['without_odom']} of {odo['scans']} scans had no "
                          f"odometry (outside its time span or in a gap): matched laser only")
    if isinstance(odo, dict) and odo.get("imu") and odo.get("scans") and odo.get("with_yaw_rate", 0) < odo["scans"]:
        err_console.print(f"[yellow]warning:[/] IMU: {odo['scans'] - odo['with_yaw_rate']} of {odo['scans']} scans had "
                          f"no yaw rate (outside the IMU's time span or in a gap): no rotation prior there")


def _print_run(input: str, outputs: RunOutputs, odo: Any, compiling: bool) -> None:
    """The table of a run: summary.json's numbers and, with ground truth, metrics.json's (as written)."""
    summary = outputs.summary
    rows = _summary_rows(summary, odo, compiling)
    if outputs.metrics is not None:
        rows += _metric_rows(outputs.metrics)
    _show(_stats_table(f"dynslam2d run {input}", rows))
    pc = summary.get("pose_confidence")
    if pc and pc.get("warning"):
        console.print(Text.assemble(("warning: ", "bold red"), f"{pc['warning']} — the map and trajectory are not "
                                    "reliable there (map.png marks the poses)"))


def _summary_rows(summary: dict[str, Any], odo: Any, compiling: bool) -> list[tuple[str, str]]:
    """The run table's rows from summary.json: speed, map updates, odometry, tracks, removal, map, clean-up, …"""
    skipped = summary.get("input_skipped", {})
    rows = [
        ("scans", str(summary["scans"])),
        ("wall time", f"{summary['wall_time_s']:.1f} s ({summary['scans_per_s']} scans/s"
                      + (f", including {summary['kernel_compile_s']:.1f} s compiling the kernels)"
                         if summary.get("kernel_compile_s", 0.0) >= 0.05
                         else ", including compiling the kernels)" if compiling else ")")),
        *_steady_rows(summary, compiling),
        ("map updates", str(summary["map_updates"])),
        *_range_scale_row(summary),
        ("odometry", (f"{summary.get('odometry') or 'none (laser only)'}"
                      + (f", {odo['with_odom']}/{odo['scans']} "
                         f"scans" if isinstance(odo, dict) and odo.get('scans') else ""))),
        ("rejected matches", str(summary["match_failures"])),
        ("skipped scans", str(summary["skipped_scans"])),
        ("input dropped (--skip-bad)", ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in skipped.items() if v)
         if summary.get("input_skipped_total") else "none"),
        ("tracks (in M)", f"{summary['tracks']} ({summary['tracks_in_M']})"),
        ("beams removed", f"{100 * summary['removed_beam_share']:.2f} % (filter {summary['filter']})"),
        ("map", f"{summary['map_cells'][1]}×{summary['map_cells'][0]} cells at {summary['map_resolution_m']} m, "
                f"{summary['memory_bytes'] / 2**20:.1f} MiB"),
    ]
    cl = summary.get("cleanup")
    if isinstance(cl, dict):
        rows.append(("clean-up", f"erased {cl['erased_cells']} of {cl['occupied_cells_online']} occupied cells "
                                 f"({cl['erased_area_m2']:.2f} m²), restored {cl.get('restored_cells', 0)} in "
                                 f"{cl['pass_time_s']:.2f} s; online map in map_online.pgm"))
    repairs = summary.get("stamp_repairs") or {}
    if repairs.get("backward_steps") or repairs.get("nudged_stamps") or repairs.get("time_source") not in (None, "ipc"):
        rows.append(("stamp repairs", "; ".join(summary.get("input_warnings", [])) or str(repairs)))
    pc = summary.get("pose_confidence")
    if pc:
        from dynslam2d.slam.confidence import jump_text

        rows.append(("pose confidence",
                     f"{100 * pc['low_support_share']:.1f} % low support (longest {pc['longest_low_support_s']:.1f} "
                     f"s), "
                     f"{100 * pc['degenerate_share']:.1f} % degenerate (longest {pc['longest_degenerate_s']:.1f} s), "
                     f"lost {pc['lost_events']}× ({pc['lost_time_s']:.1f} s)"
                     + (f", {pc['jumps']} front-end jump(s) (largest {jump_text(pc)})" if pc.get("jumps") else "")))
    body = summary.get("body") or {}
    if body.get("footprint_dropped_returns") or body.get("auto_body_beams"):
        rows.append(("robot's own returns dropped",
                     f"{body.get('footprint_dropped_returns', 0) + body.get('auto_dropped_returns', 0)} "
                     f"({body.get('auto_body_beams', 0)} body beams found; suggested footprint in summary.json)"))
    return rows


def _parse_range_scale(text: str) -> float | str:
    """``--range-scale``: 'auto' or a number."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise DynSlamError(f"--range-scale must be 'auto' or a number such as 1.05, got {text!r}") from None


def _range_scale_row(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """The range scale used, with the evidence of an automatic estimate."""
    rs = summary.get("range_scale")
    if not isinstance(rs, dict) or (rs.get("mode") == "fixed" and rs.get("used") == 1.0):
        return []
    if rs.get("mode") != "auto":
        return [("range scale", f"{rs['used']:g} (given)")]
    if not math.isfinite(rs.get("scale") or math.nan):
        return [("range scale", f"1 (auto: too little odometry motion, {rs['odom_distance']:.2f} m)")]
    return [("range scale", f"{rs['used']:.4f} (auto: odometry {rs['odom_distance']:.2f} m / laser "
                            f"{rs['slam_distance']:.2f} m over {rs['windows']} windows of the first {rs['scans']} "
                            f"scans)")]


def _early_background_compile() -> Any:
    """The background compile (:mod:`dynslam2d.jitwarm`) started at once when numba's cache folder holds no index
    file at all (:func:`dynslam2d.jitcache.cache_holds_no_index`: a first run), before this process imports the
    configuration, numba and the kernel modules (≈ 0.7–1 s at the start of ``run``): the second CPU starts its
    first kernel that much earlier. None otherwise (not started: the AOT-compiled kernels, a cache holding
    something, or :func:`dynslam2d.jitwarm.worker_wanted` says no); :func:`_cold_start` then decides as before."""
    from dynslam2d.jitaot import table
    from dynslam2d.jitcache import cache_holds_no_index

    if table() is not None or not cache_holds_no_index():
        return None
    from dynslam2d.jitwarm import start_background_compile

    return start_background_compile()


def _cold_start(background: Any = None) -> tuple[bool, Any]:
    """Whether numba must compile the kernels (a first run, or the first after an update), and then the
    background compile of the late kernels on a second CPU (:mod:`dynslam2d.jitwarm`; None when not
    started; ``background``: the one :func:`_early_background_compile` started, which makes the cache cold).
    Loads the pipeline's kernel modules to tell, after making numba's compiles leaner
    (:func:`dynslam2d.jitcache.lean_numba_compile`: about a tenth less cold compile, the same kernels); on a cold
    cache also Python's garbage collector (:func:`dynslam2d.jitcache.lean_compile_gc`)."""
    from dynslam2d.jitbox import AOT

    if AOT is not None:  # the AOT-compiled kernels (dynslam2d kernels build): nothing to compile, numba not imported
        return False, None
    from dynslam2d.jitcache import lean_numba_compile

    lean_numba_compile()
    import dynslam2d.pipeline  # noqa: F401 - its kernel modules, for the cache check
    from dynslam2d.jitcache import kernel_cache_state
    from dynslam2d.jitwarm import start_background_compile

    cold = background is not None or kernel_cache_state().cold
    if cold:
        from dynslam2d.jitcache import lean_compile_gc

        lean_compile_gc()  # fewer collections while numba compiles (about a sixth of the compile CPU)
    return cold, (background or start_background_compile()) if cold else None


def _compile_collector_pause(cold: bool) -> Any:
    """On a cold cache, Python's cyclic garbage collector switched off until the run's scans compile nothing any
    more (:class:`dynslam2d.jitcache.CompileCollectorPause`, a run observer; ≈ 1 s less CPU in the run's compile);
    None on a warm cache (or with the AOT-compiled kernels), where nothing changes."""
    if not cold:
        return None
    from dynslam2d.jitcache import CompileCollectorPause

    pause = CompileCollectorPause()
    return pause if pause.pause() else None


def _say_if_compiling(show: bool, cold: bool) -> None:
    """Before a run: one line on stderr when numba must compile the kernels, whose speed would otherwise
    look like the program's."""
    if cold and show:
        err_console.print(Text("compiling kernels (first run only; later runs start at once) …", style="yellow"))


def _suggest_kernel_build(compiled: bool, input: str = "RECORDING") -> None:
    """After a run, one dim line on stderr on the kernels built ahead of time (docs/kernels.md): why a built module
    was not used (stale after an upgrade, naming the part of its key that differs; a call of types it lacks, naming
    the kernel; :func:`dynslam2d.jitaot.unused_reason`), else, after a run that compiled numba's kernels, that
    ``dynslam2d kernels build`` exists. Nothing after a run that used the module throughout."""
    from dynslam2d.jitaot import unused_reason

    why = unused_reason(input)
    if why is not None:
        err_console.print(Text(f"{why} (docs/kernels.md)", style="dim"))
    elif compiled:
        err_console.print(Text("the kernels are cached for later runs; `dynslam2d kernels build` compiles them ahead "
                               "of time for this machine: runs then start without numba and use about half the memory "
                               "(docs/kernels.md)", style="dim"))


def _steady_rows(summary: dict[str, Any], compiling: bool) -> list[tuple[str, str]]:
    """Steady-state speed (median per-scan processing after the first scans) beside the wall time."""
    if summary.get("steady_scans_per_s") is None:
        return []
    first = summary.get("first_scan_ms") or 0.0
    first_txt = f"{first / 1e3:.1f} s" if first >= 1e3 else f"{first:.0f} ms"
    return [("steady speed", f"{summary['steady_scans_per_s']} scans/s (median {summary['steady_ms_median']:.1f} ms "
                             f"per scan, processing only); first scan {first_txt}"
                             + (" (compiling kernels)" if compiling else ""))]


def _check_sim_only(input: str, seed: int | None, duration: float | None) -> None:
    """--seed and --duration drive the simulator; for a recording they would be silently ignored."""
    if not input.startswith("sim:"):
        given = [name for name, v in (("--seed", seed), ("--duration", duration)) if v is not None]
        if given:
            verb = "applies" if len(given) == 1 else "apply"
            raise DynSlamError(f"{' and '.join(given)} {verb} to sim:<scenario> inputs only, not to {input}; drop the "
                               f"option")


def _input_paths(input: str, *more: Path | None) -> list[Path]:
    """Every file the command reads (never written over)."""
    paths = [] if input.startswith("sim:") else [Path(input)]
    return paths + [Path(p) for p in more if p is not None]


def _check_map_size(source: Any, cfg: Any) -> None:
    """Refuse a map that cannot be built, before the work: a non-finite cell size, or one at
    which the area the first scan covers already exceeds the map memory budget
    (``slam.max_map_memory_mb``; the estimate is a lower bound: bounding box of the first
    scan's returns, every level, no growth margin)."""
    import numpy as np

    from dynslam2d.slam import grid as slam_grid

    res = cfg.slam.map_resolution
    if not (isinstance(res, float) and math.isfinite(res) and res > 0):
        raise DynSlamError(f"--map-resolution / slam.map_resolution must be a positive finite number of m, got {res}")
    budget = float(getattr(cfg.slam, "max_map_memory_mb", 0.0) or 0.0) * 1e6
    if budget <= 0:
        return
    first = next(iter(source), None)  # peek: sources can be iterated again from the start
    if first is None:
        return
    valid = first.valid_mask() & (first.ranges <= cfg.slam.laser_max_dist)
    pts = np.vstack((first.points(valid), np.zeros((1, 2))))
    w, h = (pts.max(axis=0) - pts.min(axis=0)) / res + 1.0
    levels = sum(4.0 ** -k for k in range(int(cfg.slam.map_levels)))
    need = float(w * h) * levels * float(getattr(slam_grid, "_BYTES_PER_CELL", 4))
    if need > budget:
        raise DynSlamError(
            f"--map-resolution {res:g} m: the area the first scan sees ({w * res:.1f} m × {h * res:.1f} m) alone "
            f"needs {need / 1e6:.3g} MB of map, over the budget of {budget / 1e6:.0f} MB (slam.max_map_memory_mb); "
            f"use a coarser resolution such as 0.05"
        )


def _check_run_usable(result: Any, input: str) -> None:
    """A run that could not map anything is an error, not an empty map with exit 0."""
    n = result.n_scans
    if n and not result.map_updated.any():
        reasons = ", ".join(f"{k} ×{v}" for k, v in sorted(result.reasons.items())) or "no reason recorded"
        if result.reasons.get("map_too_large"):
            raise DynSlamError(f"{input}: no scan could enter the map ({reasons}); the map is too large at "
                               f"--map-resolution {result.config.slam.map_resolution:g} m, use a coarser one")
        raise DynSlamError(f"{input}: none of the {n} scans has enough usable returns to map ({reasons}); "
                           f"check the topic and the sensor's range limits")


def _sigterm_as_interrupt() -> Any:
    """SIGTERM behaves like Ctrl-C during a run (checkpoint, one line); returns the old handler."""
    import signal

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. some test runners)
        return None


def _restore_sigterm(old: Any) -> None:
    import signal

    if old is not None:
        with contextlib.suppress(ValueError):
            signal.signal(signal.SIGTERM, old)


def _interrupted(folder: Any, checkpointer: Any) -> None:
    """Ctrl-C / SIGTERM during a run: write a last checkpoint, say where it is, exit 130."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the checkpoint
    try:
        checkpointer.write()
        where = folder.keep_partial()
    except Exception as exc:  # the checkpoint itself failed: say so, keep what is on disk
        err_console.print(Text(f"interrupted after {checkpointer.n_scans} scans; the last checkpoint could not be "
                               f"written ({exc}); earlier checkpoints in {folder.work}"), soft_wrap=True)
        raise SystemExit(130) from None
    err_console.print(Text(f"interrupted after {checkpointer.n_scans} scans, partial results in "
                           f"{where}"), soft_wrap=True)
    raise SystemExit(130)


def _default_workers() -> int:
    """The CPUs this process may use (the pool's default size)."""
    import os

    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


WorkersOpt = Annotated[int | None, typer.Option(
    "--workers", "-j", min=1, help="Local worker processes [the CPUs available; 1 = one run after the other in this "
                                   "process].")]
RayOpt = Annotated[str | None, typer.Option(
    "--ray", metavar="ADDRESS", help="Run the jobs on Ray instead: a cluster address (ray://host:10001, host:6379), "
                                     "'auto' (the cluster this machine belongs to) or 'local' (start Ray here); pip "
                                     "install \"dynslam2d[cluster]\" (docs/batch.md).")]


def _progress_bar(label: str, field: str, show: bool) -> Any:
    """A progress bar on stderr: ``label``, bar, done/total, the task's ``field``, elapsed time, eta."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(TextColumn(f"[bold]{label}[/]"), BarColumn(), MofNCompleteColumn(),
                    TextColumn(f"{{task.fields[{field}]}}"), TimeElapsedColumn(), TextColumn("eta"),
                    TimeRemainingColumn(), console=err_console, disable=not show)


def _batch_progress(total: int, show: bool) -> Any:
    return _progress_bar("runs", "info", show)


@app.command()
def batch(
    inputs: Annotated[list[str], typer.Argument(
        metavar="INPUT", help="Bags, bag folders, .mcap files, CARMEN logs or sim:<scenario> inputs.")],
    out: Annotated[Path, typer.Option(
        "--out", "-o", help="Batch folder: one results folder per (input, setting), batch.csv, batch.md, batch.json.")],
    sets: Annotated[list[str] | None, typer.Option(
        "--set", metavar="KEY=V1,V2", help="A config key (as in 'dynslam2d config dump') and the values to try; repeat "
                                           "for a grid, e.g. --set filter.mode=none,box --set "
                                           "slam.map_resolution=0.05,0.025.")] = None,
    workers: WorkersOpt = None,
    ray: RayOpt = None,
    config: Annotated[Path | None, typer.Option("--config", help="YAML configuration every run starts from.")] = None,
    topic: TopicOpt = None,
    seed: SeedOpt = None,
    duration: DurationOpt = None,
    skip_bad: SkipBadOpt = False,
    odom: OdomOpt = "auto",
    imu: ImuOpt = "auto",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or table.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print batch.json on stdout.")] = False,
) -> None:
    """Run many inputs × parameter settings: one results folder each, batch.csv / batch.md with every summary and
    metric.

    Resumable: runs whose folder is complete (run.json) are skipped; a failed run is recorded
    with its error and does not stop the others (exit 1 at the end if any failed). --seed and
    --duration apply to the sim: inputs. docs/batch.md.
    """
    from dynslam2d.batch import make_jobs, parse_setting, run_batch
    from dynslam2d.batch.engine import ray_module
    from dynslam2d.config import Config, load_config

    if ray is not None:
        ray_module()  # the install hint before any work
    base = load_config(config) if config else Config()
    settings = [parse_setting(s) for s in sets or []]
    options = {"topic": topic, "seed": seed, "duration": duration, "skip_bad": skip_bad, "odom": odom, "imu": imu}
    jobs = make_jobs(list(inputs), settings, base, options)
    show = not (quiet or as_json)
    n_workers = workers or _default_workers()
    counts = {"done": 0, "skipped": 0, "failed": 0}
    progress = _batch_progress(len(jobs), show)
    if show:
        where = f"Ray ({ray})" if ray else (f"{n_workers} worker "
                                            f"processes" if n_workers > 1 and len(jobs) > 1 else "this process")
        err_console.print(f"{len(jobs)} runs ({len(inputs)} inputs × {len(jobs) // len(inputs)} settings) on {where}")
    with progress:
        task = progress.add_task("runs", total=len(jobs), info="")

        def tick(outcome: Any) -> None:
            counts[outcome.status] += 1
            progress.update(task, advance=1, info=f"{counts['skipped']} skipped, {counts['failed']} failed · "
                                                  f"{outcome.name}")
            if show and outcome.status == "failed":
                progress.console.print(Text.assemble(("failed: ", "bold "
                                                                  "red"), f"{outcome.name}: "
                                                                          f"{outcome.error}"), soft_wrap=True)

        result = run_batch(jobs, out, workers=n_workers, ray=ray, on_outcome=tick)
    if as_json:
        sys.stdout.write(result.paths["batch.json"].read_text())
    elif show:
        table = Table(title=f"dynslam2d batch: {len(jobs)} runs in {out}")
        for col in ("run", "status", "scans/s", "ATE m", "error"):
            table.add_column(col, justify="right" if col in ("scans/s", "ATE m") else "left")
        for o in result.outcomes:
            v = o.value or {}
            s, m = v.get("summary") or {}, v.get("metrics") or {}
            table.add_row(o.name, o.status, _fmt(s.get("scans_per_s"), digits=0), _fmt(m.get("ate_rmse_m"), digits=4),
                          o.error or "")
        _show(table)
        console.print(Text.assemble("results in ", (str(out), "bold"), " (batch.csv, batch.md, batch.json)"))
    if result.failed:
        raise typer.Exit(1)


experiment_app = typer.Typer(cls=_Group, help="Reproduce experiments.", no_args_is_help=True)
app.add_typer(experiment_app, name="experiment")


@experiment_app.command("paper")
def experiment_paper(
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output folder (default: results/experiment-<time>).")] = None,
    duration: DurationOpt = None,
    trials: Annotated[list[str] | None, typer.Option(
        "--trial", help="Trial(s) to run [paper-1 paper-2 paper-3].")] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="Replace an earlier output folder of dynslam2d at --out (never anything else).")] = False,
    as_json: Annotated[bool, typer.Option(
        "--json", help="Print the table (table.json) on stdout instead of table.md.")] = False,
    workers: Annotated[int, typer.Option(
        "--workers", "-j", min=1, help="Worker processes for the 12 runs [1: one after the other, so that the scans/s "
                                       "column is the speed of an unloaded core]; the other columns do not depend on "
                                       "it.")] = 1,
    ray: RayOpt = None,
    config: Annotated[Path | None, typer.Option(
        "--config", help="YAML configuration every cell starts from (its filter.mode is the cell's).")] = None,
    sets: SetOpt = None,
) -> None:
    """The paper's experiment: 3 trials × 4 filter configurations → table.md/csv/json and figure2.png.

    With --config or --set the cells start from that configuration (written to config.yaml
    beside the table); each cell then sets its own filter.mode.
    """
    from dynslam2d.config import Config, dump_config, load_config, with_assignments
    from dynslam2d.experiments import CONFIGURATIONS, TRIALS, run_experiment, write_experiment
    from dynslam2d.io.atomic import write_text_atomic
    from dynslam2d.io.outputs import plan_results_folder, write_marker

    if any(s.partition("=")[0].strip() == "filter.mode" for s in sets or []):
        raise DynSlamError("--set filter.mode: the experiment runs every filter mode itself; set other keys")
    base = with_assignments(load_config(config) if config else Config(), sets or [])
    out = out or _default_out("experiment")
    folder = plan_results_folder(out, force=force)  # before the work: a bad --out fails at once
    chosen = tuple(trials) if trials else TRIALS
    if ray is not None:
        from dynslam2d.batch.engine import ray_module

        ray_module()  # the install hint before any work
    n_done = [0]

    def cell_done(text: str) -> None:
        n_done[0] += 1
        status.update(Text(f"running … {n_done[0]}/{len(CONFIGURATIONS) * len(chosen)} done (last: {text})"))

    with console.status("running …", spinner="dots") as status:
        result = run_experiment(chosen, duration=duration, base=base, progress=cell_done, workers=workers, ray=ray)
        try:
            folder.start(input="experiment paper")
            paths = write_experiment(result, folder.work)
            paths["config.yaml"] = write_text_atomic(folder.work / "config.yaml", dump_config(base, comments=False))
            write_marker(folder.work, "complete", input="experiment paper", files=sorted(paths))
            work = folder.work
            folder.finish()
        except BaseException:
            folder.discard()
            raise
        paths = {k: out / Path(v).relative_to(work) for k, v in paths.items()}
    if as_json:
        sys.stdout.write(paths["table.json"].read_text())
        return
    sys.stdout.write(paths["table.md"].read_text())
    console.print(Text.assemble("results in ", (str(out), "bold"), f" ({', '.join(paths)})"))


class _EvalGroup(_Group):
    """``dynslam2d eval RUN_DIR --gt GT_DIR`` is short for ``dynslam2d eval run RUN_DIR --gt GT_DIR``
    (shown in the usage line and the help of ``dynslam2d eval``)."""

    def parse_args(self, ctx, args):  # type: ignore[no-untyped-def]
        if args and args[0] not in self.commands and not args[0].startswith("-"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


eval_app = typer.Typer(
    cls=_EvalGroup,
    help="Evaluate: a run against ground truth, trajectories (ATE, RPE), relations, tracking, people.\n\n"
    "'dynslam2d eval RUN_DIR --gt GT_DIR' is short for 'dynslam2d eval run RUN_DIR --gt GT_DIR'.",
    short_help="Evaluate: a run against ground truth (eval RUN_DIR --gt GT_DIR), trajectories (ATE, RPE), relations.",
    subcommand_metavar="RUN_DIR --gt GT_DIR | COMMAND [ARGS]...",
    no_args_is_help=True,
)
app.add_typer(eval_app, name="eval")


def _stats_table(title: str, rows: list[tuple[str, str]]) -> Table:
    table = Table(title=Text(title), show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column(justify="right")
    for k, v in rows:
        table.add_row(Text(str(k)), Text(str(v)))
    return table


def _emit(result: dict[str, object], as_json: bool, table: Table) -> None:
    if as_json:
        sys.stdout.write(json.dumps(result, indent=2) + "\n")
    else:
        _show(table)


JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")]
MaxDtOpt = Annotated[float, typer.Option(
    "--max-dt", min=0.0, help="Largest stamp difference for associating poses, s (evo's --t_max_diff).")]


RefTopicOpt = Annotated[
    str | None, typer.Option("--ref-topic", help="Pose topic when REFERENCE is a bag (e.g. /ego_pose).")
]
SensorOffsetOpt = Annotated[
    tuple[float, float, float],
    typer.Option("--sensor-offset", help="Laser pose in the reference body frame: x y yaw (m, m, rad)."),
]


_BAG_SUFFIXES = (".bag", ".mcap", ".db3")


def _check_not_swapped(command: str, reference: Path, estimate: Path) -> None:
    """REFERENCE comes first: a run folder given as REFERENCE, or a bag given as ESTIMATE,
    means the two arguments were swapped; say so instead of a message about --ref-topic."""
    ref_is_run = reference.is_dir() and (reference / "trajectory.tum").is_file()
    est_is_bag = estimate.suffix in _BAG_SUFFIXES or (estimate.is_dir() and (estimate / "metadata.yaml").is_file())
    if ref_is_run or (est_is_bag and not (estimate.is_dir() and (estimate / "trajectory.tum").is_file())):
        what = f"{reference} is a run folder" if ref_is_run else f"{estimate} is a bag"
        raise DynSlamError(f"eval {command}: the arguments look swapped ({what}); the reference comes first: "
                           f"dynslam2d eval {command} {estimate} {reference}")


def _estimate_path(estimate: Path) -> Path:
    return estimate / "trajectory.tum" if estimate.is_dir() else estimate


@eval_app.command("run")
def eval_run(
    run_dir: Annotated[Path, typer.Argument(help="Results folder written by 'dynslam2d run'.")],
    gt: Annotated[Path, typer.Option("--gt", help="Ground-truth folder written by 'dynslam2d simulate'.")],
    as_json: JsonOpt = False,
) -> None:
    """Score a results folder against ground truth: ATE, map IoU / weighted RMSE / F1 / ghost area, removal.

    Writes RUN_DIR/metrics.json. Formulas: docs/metrics.md.
    """
    from dynslam2d.io.atomic import write_text_atomic
    from dynslam2d.results import evaluate_folder, metrics_json

    metrics = evaluate_folder(run_dir, gt)
    write_text_atomic(run_dir / "metrics.json", metrics_json(metrics))
    _emit(metrics, as_json, _stats_table(f"{run_dir} vs {gt}", _metric_rows(metrics)))


def _pct(value: float) -> str:
    """A share as a percentage; NaN (an empty class) as —."""
    return "—" if value != value else f"{100 * value:.2f} %"


def _metric_rows(metrics: dict[str, Any]) -> list[tuple[str, str]]:
    rows = [("ATE RMSE", f"{metrics['ate_rmse_m']:.4f} m ({metrics['poses_compared']} poses)")]
    m = metrics.get("map")
    if m:
        rows += [
            ("IoU (strict / 0.10 m)", f"{m['iou']:.3f} / {m['iou_tolerant']:.3f}"),
            ("weighted RMSE", f"{m['weighted_rmse']:.4f}"),
            ("precision / recall / F1", f"{m['precision']:.3f} / {m['recall']:.3f} / {m['f1']:.3f}"),
            ("ghost area", f"{m['ghost_area_m2']:.3f} m²"),
        ]
    r = metrics.get("removal")
    if r:
        rows += [
            ("removed beams: precision / recall", f"{r['precision']:.3f} / {r['recall']:.3f}"),
            ("static beams removed", f"{100 * r['static_removed_share']:.2f} %"),
        ]
    mc = metrics.get("removal_by_motion")
    if mc and mc["n_standing"] + mc["n_stopped"] > 0:
        rows += [
            ("walking-mover beams removed", _pct(mc["walking_recall"])),
            ("standing-mover beams removed", _pct(mc["standing_removed_share"])),
            ("stopped-mover beams removed", _pct(mc["stopped_removed_share"])),
        ]
    tm = metrics.get("time_to_m")
    if tm and tm["seen_walking"]:
        delay = "—" if tm["median_delay"] != tm["median_delay"] else f"{tm['median_delay']:.2f} s"
        rows.append(("walking movers caught by M (median delay)",
                     f"{tm['reached']} of {tm['seen_walking']} ({delay}; {_pct(tm['within_half_second'])} within 0.5 "
                     f"s)"))
    return rows


@eval_app.command("people")
def eval_people(
    bag: Annotated[Path, typer.Argument(help="Annotated leg_tracker bag (or a .zip holding it).")],
    run_dir: Annotated[Path, typer.Argument(help="Results folder of 'dynslam2d run' on that bag.")],
    topic: TopicOpt = None,
    people_topic: Annotated[str, typer.Option(
        "--people-topic", help="Topic of the leg_tracker/Person annotations.")] = "/ground_truth_people_tracks",
    radius: Annotated[float, typer.Option(
        "--radius", help="Beams ending this close to an annotation are person beams, m.")] = 0.35,
    walk_speed: Annotated[float, typer.Option(
        "--walk-speed", help="A person moving at least this fast is walking, m/s.")] = 0.3,
    window: Annotated[float, typer.Option("--window", help="Window of the walking speed, s.")] = 1.0,
    m_radius: Annotated[float, typer.Option(
        "--m-radius", help="A track in M this close to a person has caught it, m.")] = 0.5,
    motion_frame: Annotated[str, typer.Option(
        "--motion-frame", help="Judge walking in the 'map' frame (the run's trajectory) or the 'scan' frame "
                               "(motionless sensor).")] = "map",
    as_json: JsonOpt = False,
) -> None:
    """Score a run against hand-annotated people: removal recall on person beams (walking / standing),
    non-person beams removed, and the time from a person's first motion to the dynamic set M.

    Definitions: docs/real.md.
    """
    from dynslam2d.eval.people import PeopleParams, evaluate_people

    params = PeopleParams(radius=radius, walk_speed=walk_speed, window=window, m_radius=m_radius,
                          motion_frame=motion_frame)
    m = evaluate_people(bag, run_dir, scan_topic=topic, people_topic=people_topic, params=params)
    rows = [
        ("scans (annotated)", f"{m.scans} ({m.scans_annotated})"),
        ("people (walking)", f"{m.people} ({m.walking_people})"),
        ("person beams removed", f"{_pct(m.recall)} of {m.person_beams}"),
        ("walking-person beams removed", f"{_pct(m.walking_recall)} of {m.walking_beams}"),
        ("standing-person beams removed", f"{_pct(m.standing_recall)} of {m.standing_beams}"),
        ("non-person beams removed", f"{_pct(m.non_person_removed_share)} of {m.non_person_beams}"),
        ("all beams removed (every scan)", _pct(m.removed_share_all)),
        ("people reaching M", f"{m.people_reached_m} of {m.walking_people} walking"),
        ("time from first motion to M (median)", _fmt(m.median_time_to_m, " s", 2)),
    ]
    for r in m.per_person:
        delay = "never in M" if r.time_to_m is None else f"{r.time_to_m:.2f} s to M"
        rows.append((f"  person {r.id}", f"{r.annotations} annotations, {_pct(r.recall)} removed, {delay}"))
    _emit(m.as_dict(), as_json, _stats_table(f"{run_dir} vs people in {bag}", rows))


@eval_app.command("foreground")
def eval_foreground(
    input: Annotated[str, typer.Argument(help="The recording of a motionless sensor (bag, log).")],
    run_dir: Annotated[Path, typer.Argument(help="Results folder of 'dynslam2d run' on that recording.")],
    topic: TopicOpt = None,
    margin: Annotated[float, typer.Option(
        "--margin", help="A return this far in front of the per-beam median background is foreground, m.")] = 0.3,
    as_json: JsonOpt = False,
) -> None:
    """Removed foreground and background beams of a run of a motionless sensor.

    Foreground: returns at least --margin in front of the per-beam median range (docs/real.md).
    """
    from dynslam2d.eval.foreground import evaluate_foreground

    r = evaluate_foreground(input, run_dir, topic=topic, margin=margin)
    rows = [
        ("scans (with ≥5 foreground beams)", f"{r.scans} ({r.scans_with_foreground})"),
        ("foreground beams removed", f"{_pct(r.foreground_removed_share)} of {r.foreground_beams}"),
        ("background beams removed", f"{_pct(r.background_removed_share)} of {r.background_beams}"),
        ("returns of rarely-returning beams removed", f"{_pct(r.rare_removed_share)} of {r.rare_beams}"),
    ]
    _emit(r.as_dict(), as_json, _stats_table(f"{run_dir} (foreground ≥ {margin:g} m in front of the background)", rows))


@eval_app.command("tracking")
def eval_tracking(
    scenes: Annotated[list[str] | None, typer.Option(
        "--scene", help="Simulated scene(s) [paper crowd corridor static].")] = None,
    datmo: Annotated[Path | None, typer.Option(
        "--datmo", help="Folder of datmo bags (motion-capture ground truth) to score too.")] = None,
    duration: Annotated[float, typer.Option("--duration", min=1.0, help="Simulated duration per scene, s.")] = 20.0,
    seed: SeedOpt = None,
    poses: Annotated[str, typer.Option(
        "--poses", help="Laser poses for the tracker: truth (simulator) or slam.")] = "truth",
    config: Annotated[Path | None, typer.Option(
        "--config", help="YAML configuration (its 'detect' section is used).")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Score detection and tracking: dynamic-beam recall/precision, centre and speed errors, identity switches.

    Definitions: dynslam2d.eval.tracking (module docstring) and docs/tracking.md.
    """
    from dynslam2d.config import Config, load_config
    from dynslam2d.eval.tracking import evaluate_datmo_folder, evaluate_sim

    if poses not in ("truth", "slam"):
        raise DynSlamError(f"--poses must be 'truth' or 'slam', got {poses!r}")
    detect_cfg = (load_config(config) if config else Config()).detect
    chosen = scenes or ["paper", "crowd", "corridor", "static"]
    sim_rows: list[dict[str, object]] = []
    bag_rows: list[dict[str, object]] = []
    with console.status("tracking …", spinner="dots") as status:
        for scene in chosen:
            status.update(f"tracking sim:{scene} …")
            sim_rows.append(evaluate_sim(scene, seed=seed, duration=duration, config=detect_cfg,
                                         pose_source=poses).row())
        if datmo is not None:
            status.update(f"tracking the bags in {datmo} …")
            bag_rows = [r.row() for r in evaluate_datmo_folder(datmo)]
    if as_json:
        sys.stdout.write(json.dumps({"simulated": sim_rows, "datmo": bag_rows}, indent=2, default=float) + "\n")
        return
    t = Table(title=f"simulated scenes ({duration:g} s, {poses} poses)", title_justify="left")
    for col in ("scene", "recall", "precision", "FP "
                                                "beams", "centre err "
                                                         "(med)", "speed err "
                                                                  "(med)", "ID switches", "static tracks in M"):
        t.add_column(col, justify="right")
    for r in sim_rows:
        t.add_row(str(r["scene"]), _fmt(r["recall"]), _fmt(r["precision"]), f"{100 * float(r['fp_beam_rate']):.3f} %",
                  _fmt(r["median_center_error"], " m"), _fmt(r["median_speed_error"], " m/s"), str(r["id_switches"]),
                  str(r["static_tracks_in_m"]))
    _show(t)
    if bag_rows:
        b = Table(title="datmo bags (motion capture)", title_justify="left")
        for col in ("bag", "target", "matched", "centre RMSE", "DATMO RMSE", "speed err (med)", "ID switches"):
            b.add_column(col, justify="right")
        for r in bag_rows:
            b.add_row(str(r["bag"]), str(r["target"]), f"{r['n_matched']}/{r['n_with_truth']}", _fmt(r["rmse_center"],
                                                                                                     " m"),
                      _fmt(r["datmo_rmse"], " m"), _fmt(r["median_speed_error"], " m/s"), str(r["id_switches"]))
        _show(b)


@eval_app.command("stationary")
def eval_stationary(
    input: Annotated[str, typer.Argument(help="The recording of a sensor that never moved (bag, log).")],
    run_dir: Annotated[Path, typer.Argument(help="Results folder of 'dynslam2d run' on that recording.")],
    topic: TopicOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Score a run of a motionless sensor: pose drift, and the occupied area that moving people left in the map.

    The residue is measured against a map of the per-beam median scan (the background).
    """
    from dynslam2d.config import load_config
    from dynslam2d.eval.maps import load_run_map
    from dynslam2d.eval.stationary import background_map, median_background_scan, stationary_score
    from dynslam2d.inputs import open_source
    from dynslam2d.io.trajectory import read_tum

    cfg = load_config(run_dir / "config.yaml") if (run_dir / "config.yaml").exists() else None
    bg = background_map(median_background_scan(open_source(input, topic)), cfg.slam if cfg else None)
    score = stationary_score(read_tum(_estimate_path(run_dir)), load_run_map(run_dir), bg)
    rows = [
        ("drift, largest", f"{score.drift_max_m:.4f} m"),
        ("drift, final", f"{score.drift_final_m:.4f} m"),
        ("rotation, largest", f"{math.degrees(score.rotation_max_rad):.3f}°"),
        ("residue of movers in the map", f"{score.residue_area_m2:.4f} m²"),
    ]
    _emit(score.as_dict(), as_json, _stats_table(f"{run_dir} (stationary sensor)", rows))


#: Fewest associated poses an ATE is computed from (two points fit any SE(2) alignment exactly).
MIN_ATE_POSES = 3


@eval_app.command("ate")
def eval_ate(
    reference: Annotated[Path, typer.Argument(help="Reference: TUM file, or a bag with --ref-topic.")],
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM) or a run folder.")],
    ref_topic: RefTopicOpt = None,
    sensor_offset: SensorOffsetOpt = (0.0, 0.0, 0.0),
    no_align: Annotated[bool, typer.Option(
        "--no-align", help="Do not SE(2)-align the estimate first (like evo_ape without -a; the default aligns like "
                           "evo_ape -a).")] = False,
    max_dt: MaxDtOpt = 0.01,
    as_json: JsonOpt = False,
) -> None:
    """Absolute trajectory error (translation) as evo_ape computes it; aligns by default.

    By default the estimate is first SE(2)-aligned to the reference, as 'evo_ape tum REF EST -a'
    does (evo without -a does not align; here that is --no-align). No scale is ever corrected
    (evo's -s / --correct_scale); --max-dt is evo's --t_max_diff. docs/metrics.md has the table.

    Example (datmo bags, laser 0.12 m behind the motion-capture body):
    dynslam2d eval ate parallel.bag RUN_DIR --ref-topic /ego_pose --sensor-offset -0.12 0 0
    """
    from dynslam2d.eval.reference import load_reference
    from dynslam2d.eval.trajectory import ate
    from dynslam2d.io.trajectory import read_tum
    from dynslam2d.types import Pose2D

    _check_not_swapped("ate", reference, estimate)
    ref = load_reference(reference, ref_topic, Pose2D(*sensor_offset))
    res = ate(ref, read_tum(_estimate_path(estimate)), align=not no_align, max_dt=max_dt)
    if res.n < MIN_ATE_POSES:
        raise DynSlamError(
            f"{estimate}: only {res.n} pose(s) associate with {reference} within --max-dt {max_dt:g} s; an ATE needs "
            f"at least {MIN_ATE_POSES} (check the stamps' clock, or raise --max-dt)"
        )
    a = res.alignment
    out = {"ate": res.trans.as_dict(), "rotation_rad": res.rot.as_dict(), "alignment": [a.x, a.y, a.theta],
           "aligned": not no_align}
    rows = [(k, f"{getattr(res.trans, k):.4f} m") for k in ("rmse", "mean", "median", "std", "max")]
    rows += [("poses", str(res.n))]
    if no_align:
        rows.append(("alignment", "none (--no-align; as evo_ape without -a)"))
    else:
        rows.append(("alignment", f"SE(2), as evo_ape -a: x {a.x:.3f} m, y {a.y:.3f} m, θ {a.theta:.4f} rad"))
    _emit(out, as_json, _stats_table(f"ATE {estimate} vs {reference}", rows))


@eval_app.command("rpe")
def eval_rpe(
    reference: Annotated[Path, typer.Argument(help="Reference: TUM file, or a bag with --ref-topic.")],
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM) or a run folder.")],
    ref_topic: RefTopicOpt = None,
    sensor_offset: SensorOffsetOpt = (0.0, 0.0, 0.0),
    delta: Annotated[float, typer.Option(
        "--delta", min=0.0, help="Pair distance, in --delta-unit (evo's --delta).")] = 1,
    delta_unit: Annotated[str, typer.Option(
        "--delta-unit", help="'frames' or 'm' (evo's --delta_unit f / m).")] = "frames",
    all_pairs: Annotated[bool, typer.Option(
        "--all-pairs", help="Use every pair, not consecutive ones (evo's --all_pairs).")] = False,
    max_dt: MaxDtOpt = 0.01,
    as_json: JsonOpt = False,
) -> None:
    """Relative pose error (translation and rotation) as evo_rpe computes it; no alignment needed.

    A rigid alignment does not change relative errors, so none is applied (evo_rpe's -a has no
    effect on them either). --max-dt is evo's --t_max_diff. docs/metrics.md has the table.
    """
    from dynslam2d.eval.reference import load_reference
    from dynslam2d.eval.trajectory import rpe
    from dynslam2d.io.trajectory import read_tum
    from dynslam2d.types import Pose2D

    if delta_unit not in ("frames", "m"):
        raise DynSlamError(f"--delta-unit must be 'frames' or 'm', got {delta_unit!r}")
    _check_not_swapped("rpe", reference, estimate)
    d: float | int = int(delta) if delta_unit == "frames" else delta
    ref = load_reference(reference, ref_topic, Pose2D(*sensor_offset))
    res = rpe(ref, read_tum(_estimate_path(estimate)), delta=d, delta_unit=delta_unit, all_pairs=all_pairs,
              max_dt=max_dt)
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
    estimate: Annotated[Path, typer.Argument(
        help="Estimated trajectory (TUM), e.g. a run's trajectory.tum, or a run folder.")],
    relations: Annotated[Path, typer.Argument(help="Kümmerle et al. relations file (t1 t2 x y z roll pitch yaw).")],
    tol: Annotated[float, typer.Option(
        "--tol", min=0.0, help="Largest stamp difference to match a relation to a pose, s.")] = 1e-3,
    clock: Annotated[Path | None, typer.Option(
        "--clock", help="CARMEN log with both clocks (ipc and logger) on its laser records, e.g. fr079.flirtlib.log: "
                        "the estimate's logger stamps are mapped to the relations' ipc clock through it.")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Relative pose error over ground-truth relations, mean ± std (Kümmerle et al., 2009)."""
    from dynslam2d.eval.relations import relation_errors_from
    from dynslam2d.io.relations import read_relations
    from dynslam2d.io.trajectory import Trajectory, read_tum

    estimate = _estimate_path(estimate)
    traj = read_tum(estimate)
    if clock is not None:
        from dynslam2d.io.relclock import read_clock_pairs

        traj = Trajectory(read_clock_pairs(clock).to_ipc(traj.stamps), traj.poses)
    res = relation_errors_from(traj, read_relations(relations), tol=tol)
    out = {
        "translation_m": {"mean": res.trans_mean, "std": res.trans_std, "rmse": res.trans_rmse},
        "rotation_deg": {"mean": res.rot_deg_mean, "std": res.rot_deg_std},
        "relations_used": res.n_used,
        "relations_unmatched": res.n_unmatched,
        "relations_scored": res.n_used,
    }
    rows = [
        ("translation", f"{res.trans_mean:.3f} ± {res.trans_std:.3f} m"),
        ("rotation", f"{res.rot_deg_mean:.3f} ± {res.rot_deg_std:.3f}°"),
        ("relations scored", f"{res.n_used} of {res.n_used + res.n_unmatched} ({res.n_unmatched} unmatched)"),
    ]
    _emit(out, as_json, _stats_table(f"relations {relations.name} vs {estimate}", rows))


kernels_app = typer.Typer(cls=_Group, help="The kernels compiled ahead of time for this machine (docs/kernels.md).",
                          no_args_is_help=True)
app.add_typer(kernels_app, name="kernels")


def _kernel_build_child(argv: list[str]) -> int:
    """The child process of ``dynslam2d kernels build``: ``python -c "...; _kernel_build_child(sys.argv)" FOLDER CPU
    DURATION [INPUT ...]`` runs :func:`dynslam2d.kernelbuild.build` with its progress as JSON lines on stdout (what
    the parent shows) and a last line ``{"stage": "done", "info": sidecar}`` or
    ``{"stage": "error", "message": ...}``."""
    from dynslam2d.kernelbuild import build

    def note(stage: str, data: dict[str, Any]) -> None:
        sys.stdout.write(json.dumps({"stage": stage, **data}) + "\n")
        sys.stdout.flush()

    folder, cpu, duration, *inputs = argv[1:]
    try:
        info = build(Path(folder), inputs=inputs, cpu=cpu, progress=note, duration=float(duration))
    except DynSlamError as exc:
        note("error", {"message": str(exc)})
        return 2
    note("done", {"info": info})
    return 0


@kernels_app.command("build")
def kernels_build(
    inputs: Annotated[list[str] | None, typer.Option(
        "--input", help="Also run this recording (bag, CARMEN log, sim:<scenario>) to collect the kernel types it "
                        "uses; repeat for more. Simulated scenes, a bag and a CARMEN log are always run.")] = None,
    cpu: Annotated[str, typer.Option("--cpu", help="LLVM CPU name the code is compiled for [host: this CPU].")] =
        "host",
    duration: Annotated[float, typer.Option("--duration", min=1.0, help="Simulated seconds per scene run [12].")] =
        12.0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress display.")] = False,
) -> None:
    """Compile every kernel a run uses into one extension module for this machine (about a minute of one CPU; needs
    a C compiler and setuptools). Later runs load it instead of numba: no compile, less memory."""
    import subprocess

    from dynslam2d.jitaot import MODE_ENV, aot_dir, build_lock, build_requirements

    why = build_requirements()
    if why:
        raise DynSlamError(why)
    folder = aot_dir()
    with build_lock(folder):  # at once: a folder that cannot be written, another build running (the child locks)
        pass
    env = dict(os.environ, **{MODE_ENV: "jit", "DYNSLAM2D_COMPILE_WORKER": "0"})
    child = "import sys; from dynslam2d.cli import _kernel_build_child; sys.exit(_kernel_build_child(sys.argv))"
    cmd = [sys.executable, "-c", child, str(folder), cpu, f"{duration:g}", *(inputs or [])]
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    done: dict[str, Any] = {}
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(), console=err_console,
                  disable=quiet) as bar:
        task = bar.add_task("building kernels", total=None)
        with subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc, \
                _note_interrupt("kernels build stopped: the previous kernel module (if any) is still in use"):
            assert proc.stdout is not None
            compiled = total = 0
            for line in proc.stdout:
                try:
                    msg = json.loads(line)
                except ValueError:
                    continue
                stage = msg.get("stage")
                if stage == "run":
                    bar.update(task, description=f"collecting kernel types: run {msg['k'] + 1}/{msg['n']} "
                                                 f"{msg['input']}")
                elif stage == "compile":
                    bar.update(task, description=f"compiling {msg['signatures']} kernel signatures")
                    total = msg["signatures"]
                elif stage == "kernel":
                    compiled += 1
                    bar.update(task, description=f"compiling kernels {compiled}/{total}: {msg['name']}")
                elif stage in ("done", "error"):
                    done = msg
            err = proc.stderr.read() if proc.stderr is not None else ""
    if done.get("stage") == "error":
        raise DynSlamError(f"kernels build: {done['message']}")
    if done.get("stage") != "done":
        last = [ln for ln in err.splitlines() if ln.strip()][-1:] or ["no output"]
        raise DynSlamError(f"kernels build failed (exit {proc.returncode}): {last[0]}")
    info = done["info"]
    n_sig = sum(len(v) for v in info["exports"].values())
    console.print(f"built {len(info['exports'])} kernels ({n_sig} signatures, {info['bytes'] / 2**20:.1f} MiB) for "
                  f"CPU {info['cpu_target']} in {info['build_s']:.0f} s: {folder}")


@contextlib.contextmanager
def _note_interrupt(message: str) -> Iterator[None]:
    """Print ``message`` on stderr when Ctrl-C interrupts the block (then interrupted as before)."""
    try:
        yield
    except KeyboardInterrupt:
        err_console.print(Text(message, style="yellow"))
        raise


@kernels_app.command("status")
def kernels_status(
    as_json: Annotated[bool, typer.Option("--json", help="Print the status as JSON.")] = False,
) -> None:
    """Whether an AOT kernel module is present and valid for this machine, and where."""
    from dynslam2d.jitaot import MODE_ENV, status

    st = status()
    used = st.valid and st.mode != "jit"
    row = {"folder": str(st.folder), "present": st.present, "valid": st.valid, "reason": st.reason,
           "used": used, "mode": st.mode, "kernels": len(st.info.get("exports", {})),
           "signatures": sum(len(v) for v in st.info.get("exports", {}).values()), "built": st.info.get("built"),
           "cpu_target": st.info.get("cpu_target"), "bytes": st.info.get("bytes"), "file": st.info.get("file"),
           "numba": st.info.get("numba_imported"), "cpu": st.info.get("cpu_name"), "sha256": st.info.get("sha256"),
           "stale": list(st.stale)}
    if as_json:
        console.print_json(json.dumps(row))
        return
    table = Table(show_header=False, box=None)
    table.add_row("folder", str(st.folder))
    table.add_row("module", "present" if st.present else "none")
    table.add_row("status", st.reason)
    if st.present and st.info:
        table.add_row("file", f"{row['file']} ({(row['bytes'] or 0) / 2**20:.1f} MiB)")
        table.add_row("kernels", f"{row['kernels']} ({row['signatures']} signatures), built {row['built']} with "
                                 f"numba {row['numba']} for CPU {row['cpu_target']} ({row['cpu'] or 'unknown'})")
    table.add_row("runs use", "the AOT kernels" if used else
                  f"numba's JIT kernels ({MODE_ENV}=jit)" if st.valid else "numba's JIT kernels")
    _show(table)


@kernels_app.command("clear")
def kernels_clear() -> None:
    """Delete the AOT kernel module (every file a build made in its folder, nothing else): runs use numba's JIT
    kernels again."""
    from dynslam2d.jitaot import aot_dir, clear

    gone = clear()
    console.print(f"removed {len(gone)} file(s) from {aot_dir()}" if gone else f"no AOT kernel module in {aot_dir()}")


def _one_line(text: str) -> str:
    """An error message on one line (YAML and library messages may span several), with control
    characters escaped so that binary junk quoted in a message cannot garble the terminal."""
    line = " ".join(part.strip() for part in text.splitlines() if part.strip())
    return "".join(ch if ch.isprintable() else ascii(ch)[1:-1] for ch in line)


def main() -> None:
    """Console-script entry point: run the app, turning project errors into one line.

    Usage errors are click's (exit 2 with usage text); :class:`DynSlamError` becomes
    ``error: <message>`` on stderr with exit 2; Ctrl-C exits 130. Every writer is
    atomic, so an interrupted run leaves no half-written file under a final name.
    """
    from dynslam2d.jitcache import load_blas_alone, plain_numba_errors
    from dynslam2d.lazynumpy import defer_numpy_submodules
    from dynslam2d.lazyscipy import defer_scipy_submodules
    from dynslam2d.memtrim import map_large_blocks

    defer_numpy_submodules()  # SciPy's copy of NumPy's namespace imports none of f2py, testing, ... (lazynumpy.py)
    defer_scipy_submodules()  # scipy.ndimage's import leaves scipy.special unexecuted (lazyscipy.py)
    map_large_blocks()  # freed map-sized arrays go back to the OS, not into a fragmented heap (memtrim.py)
    plain_numba_errors()  # no colorama round trip per numba typing attempt: a shorter cold compile (docs/speed.md)
    from dynslam2d.jitaot import table

    if table() is None:  # (with the AOT-compiled kernels numba is not imported and checks no BLAS)
        load_blas_alone()  # numba's BLAS check without the whole of scipy.linalg (about 17 MiB, docs/speed.md)
    try:
        app()
    except DynSlamError as exc:
        err_console.print(Text.assemble(("error:", "bold "
                                                   "red"), " ", _one_line(str(exc))), highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print(Text("interrupted", style="yellow"))
        sys.exit(130)


if __name__ == "__main__":
    main()
