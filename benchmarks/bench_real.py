"""Every real recording in ../shared/data/dynamic, plus the simulated drive, in one table (not run by pytest).

For each recording it runs the command line a user would (``dynslam2d run``), then the
evaluation that fits what the recording can tell:

  * ``negative_2.bag`` (a robot driving through an empty room), each of its three scan
    topics: every removed beam and every track in M is false;
  * ``positive_1.bag``, ``positive_7.bag``, ``demo_stationary_simple_environment.bag``
    (motionless sensor, people walking): ``dynslam2d eval foreground`` — removed
    foreground beams (≥ 0.3 m in front of the per-beam median) and background beams;
  * ``person_following_outdoor_1.bag.zip`` (hand-annotated person): ``dynslam2d eval people``;
  * the six datmo bags (RC cars, moving sensor): removed share, tracks, speed;
  * ``sim:drive`` (simulated robot driving through corridors, people walking and standing),
    seeds 11–13 (the range noise): ``metrics.json`` of the run (ground truth from the simulator).

Columns: scans; removed = removed beams / beams with a return (every scan); fg / bg =
foreground / background removals (stationary bags); tracks (born) and tracks in M;
M near robot = tracks in M whose centre stays within 0.5 m of the laser
(:mod:`dynslam2d.eval.following`); people: removal recall on walking (and standing)
person beams; non-person = removed share of beams that are not people (static
structure for the simulation); to M = median time from a person's first motion to M
(simulation: from the first scan a mover is seen walking, ``metrics.json`` ``time_to_m``);
ms/scan = median processing time per scan (summary.json ``processing_ms_median``; p95
beside it) and scans/s = 1000 / that median.

    python benchmarks/bench_real.py [--filter default] [--config FILE] [--only negative_2 drive ...]
        [--data ../shared/data] [--out DIR] [--table real.md] [--cpu 0]

``--cpu N`` pins every command to core N (``taskset -c N``: "one core"). The commands are
printed, and written under the table, exactly as they were run (``dynslam2d`` = ``python -m
dynslam2d`` with this checkout's ``src`` first on PYTHONPATH).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from scratch import scratch_dir

REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Recording:
    """One row of the table: an input, its topic and the evaluation that fits it."""

    name: str
    input: str  # path relative to the data folder, or sim:<scenario>
    kind: str  # "negative" | "stationary" | "people" | "datmo" | "sim"
    topic: str | None = None
    note: str = ""
    seed: int | None = None  # simulator seed (sim: inputs)


LEG = "dynamic/leg_tracker"
DATMO = "dynamic/datmo"
RECORDINGS = [
    *(Recording("negative_2", f"{LEG}/negative_2.bag", "negative", t, "empty room, robot driving")
      for t in ("/left_scan", "/rear_scan", "/right_scan")),
    Recording("positive_1", f"{LEG}/positive_1.bag", "stationary", None, "motionless sensor, people"),
    Recording("positive_7", f"{LEG}/positive_7.bag", "stationary", None, "people near the robot"),
    Recording("demo_stationary", f"{LEG}/demo_stationary_simple_environment.bag", "stationary", None,
              "motionless sensor, people"),
    Recording("person_following_outdoor_1", f"{LEG}/person_following_outdoor_1.bag.zip", "people", None,
              "robot following a person outdoors"),
    *(Recording(f"datmo {n}", f"{DATMO}/{n}.bag", "datmo", None, "RC cars, moving sensor")
      for n in ("intersection", "overtake_ego", "overtake_red", "overtakes", "parallel", "two_robots")),
    # three noise draws: one seed moves the static share by ~0.5 point
    *(Recording("sim:drive", "sim:drive", "sim", None, "simulated drive, people walking and standing", seed)
      for seed in (11, 12, 13)),
]


@dataclass
class Row:
    rec: Recording
    commands: list[str] = field(default_factory=list)
    values: dict[str, object] = field(default_factory=dict)
    error: str | None = None


def _display(argv: list[str], prefix: list[str]) -> str:
    """The command as a user types it: ``dynslam2d …`` (plus ``taskset`` when pinned)."""
    return shlex.join(prefix + ["dynslam2d", *argv])


def _call(argv: list[str], prefix: list[str], env: dict[str, str], row: Row) -> str:
    row.commands.append(_display(argv, prefix))
    print(f"$ {row.commands[-1]}", flush=True)
    proc = subprocess.run([*prefix, sys.executable, "-m", "dynslam2d", *argv], cwd=REPO, env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError((proc.stderr or proc.stdout).strip().splitlines()[-1] if (proc.stderr or proc.stdout)
                           else f"exit code {proc.returncode}")
    return proc.stdout


def _relative(path: Path) -> str:
    """``path`` relative to the repository when it lies beside it (``../shared/data/…``,
    as the docs write it); absolute otherwise."""
    try:
        rel = os.path.relpath(path, REPO)
    except ValueError:
        return str(path)
    return str(path) if rel.startswith(os.path.join("..", "..")) else rel


def measure(rec: Recording, args: argparse.Namespace, env: dict[str, str], prefix: list[str]) -> Row:
    """Run and evaluate one recording; fill the row's values."""
    from dynslam2d.eval.following import tracks_following_sensor
    from dynslam2d.io.runfolder import read_run_trajectory, read_tracks

    row = Row(rec)
    if rec.kind == "sim":
        source = rec.input
    else:
        path = args.data / rec.input
        if not path.exists():
            row.error = f"{path} not found"
            return row
        source = _relative(path)
    label = rec.name + (rec.topic or "") + ("" if rec.seed is None else f"-seed{rec.seed}")
    out = args.out / label.replace("/", "_").replace(":", "_").replace(" ", "_")
    topic = ["--topic", rec.topic] if rec.topic else []
    seed = [] if rec.seed is None else ["--seed", str(rec.seed)]
    # --force: a run folder left by an earlier benchmark at --out is replaced (only a dynslam2d results folder is)
    run = ["run", source, *topic, *seed, "--out", _relative(out), "--filter", args.filter, "--quiet", "--force"]
    if args.config:
        run += ["--config", _relative(args.config)]
    try:
        _call(run, prefix, env, row)
        summary = json.loads((out / "summary.json").read_text())
        v = row.values
        v["scans"] = summary["scans"]
        v["removed"] = summary["removed_beam_share"]
        v["tracks"] = summary["tracks"]
        v["in_m"] = summary["tracks_in_M"]
        v["ms"] = summary["processing_ms_median"]
        v["p95"] = summary.get("processing_ms_p95")
        traj = read_run_trajectory(out)
        v["near_robot"] = len(tracks_following_sensor(read_tracks(out), traj.stamps, traj.poses))
        if rec.kind == "stationary":
            fg = json.loads(_call(["eval", "foreground", source, *topic, _relative(out), "--json"], prefix, env, row))
            v["fg"], v["bg"] = fg["foreground_removed_share"], fg["background_removed_share"]
        elif rec.kind == "people":
            p = json.loads(_call(["eval", "people", source, _relative(out), *topic, "--json"], prefix, env, row))
            v["walking"], v["standing"] = p["walking_recall"], p["standing_recall"]
            v["non_person"], v["to_m"] = p["non_person_removed_share"], p["median_time_to_m"]
        elif rec.kind == "sim":
            m = json.loads((out / "metrics.json").read_text())
            mc = m.get("removal_by_motion", {})
            v["walking"], v["standing"] = mc.get("walking_recall"), mc.get("standing_removed_share")
            v["non_person"] = mc.get("static_removed_share", m["removal"]["static_removed_share"])
            v["to_m"] = m.get("time_to_m", {}).get("median_delay")
    except (RuntimeError, OSError, KeyError, ValueError) as err:
        row.error = str(err)
    return row


def _pct(x: object, digits: int = 2) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{100 * float(x):.{digits}f} %"


HEADER = ("recording", "topic / seed", "scans", "removed", "fg removed", "bg removed", "tracks", "in M", "M near robot",
          "people: walking (standing) removed", "non-person removed", "to M", "ms/scan", "p95 ms", "scans/s")


def _topic(rec: Recording) -> str:
    """The topic column: the scan topic, or the simulator seed."""
    return rec.topic or ("" if rec.seed is None else f"seed {rec.seed}")


def table(rows: list[Row]) -> str:
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    for r in rows:
        v = r.values
        if r.error:
            lines.append(f"| {r.rec.name} | {_topic(r.rec)} | error: {r.error} |" + " |" * (len(HEADER) - 3))
            continue
        people = "—"
        if v.get("walking") is not None:
            people = f"{_pct(v['walking'], 1)} ({_pct(v.get('standing'), 1)})"
        ms = v.get("ms")
        cells = [
            r.rec.name, _topic(r.rec), str(v.get("scans", "—")), _pct(v.get("removed")), _pct(v.get("fg"), 1),
            _pct(v.get("bg")), str(v.get("tracks", "—")), str(v.get("in_m", "—")), str(v.get("near_robot", "—")),
            people, _pct(v.get("non_person")),
            "—" if v.get("to_m") is None or not math.isfinite(float(v["to_m"])) else f"{float(v['to_m']):.2f} s",
            "—" if ms is None else f"{float(ms):.2f}", "—" if v.get("p95") is None else f"{float(v['p95']):.1f}",
            "—" if not ms else f"{1000.0 / float(ms):.0f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data", help="the shared data folder")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for the run folders (default: a new temporary one, removed at exit; earlier runs in "
                         "a given one are replaced)")
    ap.add_argument("--table", type=Path, default=None, help="also write the markdown table + commands here")
    ap.add_argument("--filter", default="box", choices=("none", "fixed", "adaptive", "box", "default"))
    ap.add_argument("--config", type=Path, default=None, help="YAML configuration passed to every run")
    ap.add_argument("--only", nargs="+", default=None, help="recordings whose name contains any of these words")
    ap.add_argument("--cpu", type=int, default=None, help="pin every command to this core (taskset -c)")
    args = ap.parse_args()
    if args.out is None:
        args.out = Path(scratch_dir("dynslam2d-bench-real-"))
    args.data, args.out = args.data.resolve(), args.out.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(REPO / "src"))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO / "src"), os.environ.get("PYTHONPATH", "")]))
    prefix = ["taskset", "-c", str(args.cpu)] if args.cpu is not None else []
    chosen = [r for r in RECORDINGS if not args.only or any(w in r.name for w in args.only)]
    t0 = time.perf_counter()
    rows = []
    for rec in chosen:
        rows.append(measure(rec, args, env, prefix))
        if rows[-1].error:
            print(f"  {rec.name}: {rows[-1].error}", flush=True)
    elapsed = time.perf_counter() - t0
    text = table(rows)
    pinned = f", pinned with taskset -c {args.cpu}" if args.cpu is not None else ""
    cmd = shlex.join(["python", "benchmarks/bench_real.py", *sys.argv[1:]])
    report = (f"{text}\n{len(rows)} recordings in {elapsed:.0f} s (filter {args.filter}{pinned}); "
              f"table by `{cmd}`\n\nCommands:\n\n```bash\n"
              + "\n".join(c for r in rows for c in r.commands) + "\n```\n")
    print()
    print(report)
    if args.table:
        args.table.parent.mkdir(parents=True, exist_ok=True)
        args.table.write_text(report)


if __name__ == "__main__":
    main()
