"""Loop closure on the Kümmerle benchmark logs: relation errors and wall time, on and off (not run by pytest).

For MIT CSAIL, Freiburg 079 (the GMapping-corrected log at full rate, logger time mapped to the
relations' ipc time through ``fr079.flirtlib.log``) and the sub-sampled Intel log
(``intel-lab.flirtlib.log``), laser only, it runs the command line a user would::

    dynslam2d run LOG --odom none --loop-closure on|off --out DIR
    dynslam2d eval relations DIR RELATIONS [--clock LOG] [--tol S] --json

and prints one row per (log, setting): relations scored, translation / rotation error (mean ±
std), loops found / active, whether the optimised poses were kept (map check), the wall time of
the run (``summary.json`` ``wall_time_s``: reading, front end, loop closure, map re-rendering)
the CPU time of the process (user + system: what it takes on one unloaded core) and its peak
memory.

    python benchmarks/bench_loops.py [--only csail fr079 intel] [--data ../shared/data]
        [--out /tmp/dynslam2d-bench-loops] [--cpu 0]

Settings: ``off``, ``on`` (the default) and ``forced`` (on, with ``loop.map_check: false``: the
optimised poses are used even when the map check would keep the front end's); ``recovery`` (on, with
``slam.recovery: true``) and ``far40`` (on, ``loop.far_searches: 40``, ``iterations: 200``, ``map_check:
false``) on request; ``KEY=VALUE[,KEY=VALUE...]`` runs loop closure on with those ``loop:`` settings (e.g.
``far_rank=oldest``: the ablations of docs/slam.md, "Intel: where the error is").

``--cpu N`` pins every command to core N (``taskset -c N``: "one core"). The commands are
printed exactly as they were run (``dynslam2d`` = ``python -m dynslam2d`` with this checkout's
``src`` first on PYTHONPATH).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: name → (log, relations, extra eval options)
LOGS = {
    "csail": ("mit-csail/mit-csail.clf", "mit-csail/mit-csail.relations", []),
    "fr079": ("fr079/freiburg-079-corrected.log.gz", "fr079/fr079.relations",
              ["--clock", "{data}/fr079/fr079.flirtlib.log", "--tol", "0.1"]),
    "intel": ("intel/intel-lab.flirtlib.log", "intel/intel.relations", ["--tol", "0.05"]),
}


def _cmd(args: list[str], cpu: int | None) -> list[str]:
    base = [sys.executable, "-m", "dynslam2d", *args]
    return (["taskset", "-c", str(cpu)] if cpu is not None else []) + base


def _show(args: list[str]) -> str:
    return "dynslam2d " + " ".join(shlex.quote(a) for a in args)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", default=list(LOGS))
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default="/tmp/dynslam2d-bench-loops")
    ap.add_argument("--cpu", type=int, default=None)
    ap.add_argument("--settings", nargs="*", default=["off", "on", "forced"],
                    help="off, on (default settings), forced (on, optimised poses kept whatever the map check says), "
                    "recovery (on, with the front end's large-motion recovery), far40 (on, 40 far searches per "
                    "keyframe, 200 iterations, optimised poses kept), or KEY=VALUE[,KEY=VALUE...] (on, with those "
                    "loop: settings)")
    a = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    rows = []
    for name in a.only:
        log, rel, extra = LOGS[name]
        for setting in a.settings:
            out = Path(a.out) / f"{name}-{setting}"
            run_args = ["run", f"{a.data}/{log}", "--odom", "none", "--loop-closure",
                        "off" if setting == "off" else "on",
                        "--out", str(out), "--force", "-q"]
            if setting == "forced":
                # the optimised poses whatever the map check says (loop.map_check false)
                cfg = Path(a.out) / "forced.yaml"
                cfg.parent.mkdir(parents=True, exist_ok=True)
                cfg.write_text("loop:\n  map_check: false\n")
                run_args += ["--config", str(cfg)]
            if setting == "far40":
                # the far loop search over 40 submaps per keyframe, converged optimisation, optimised poses kept
                # (docs/slam.md, "Intel: where the error is")
                cfg = Path(a.out) / "far40.yaml"
                cfg.parent.mkdir(parents=True, exist_ok=True)
                cfg.write_text("loop:\n  far_searches: 40\n  iterations: 200\n  map_check: false\n")
                run_args += ["--config", str(cfg)]
            if "=" in setting:
                # on, with loop-section settings KEY=VALUE[,KEY=VALUE…] (the ablations of docs/slam.md, "Intel:
                # where the error is"), e.g. far_rank=oldest or weak_robust=false,weak_score=0
                cfg = Path(a.out) / f"{setting.replace('=', '-').replace(',', '_')}.yaml"
                cfg.parent.mkdir(parents=True, exist_ok=True)
                cfg.write_text("loop:\n" + "".join(f"  {kv.split('=', 1)[0]}: {kv.split('=', 1)[1]}\n"
                                                    for kv in setting.split(",")))
                run_args += ["--config", str(cfg)]
            if setting == "recovery":
                # loop closure on plus the front end's large-motion recovery (slam.recovery, docs/slam.md)
                cfg = Path(a.out) / "recovery.yaml"
                cfg.parent.mkdir(parents=True, exist_ok=True)
                cfg.write_text("slam:\n  recovery: true\n")
                run_args += ["--config", str(cfg)]
            print(_show(run_args), flush=True)
            t0 = time.perf_counter()
            proc = subprocess.run(["/usr/bin/time", "-f", "%U %S %M"] + _cmd(run_args, a.cpu), env=env,
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                continue
            user, system, rss = proc.stderr.strip().splitlines()[-1].split()
            cpu_s = float(user) + float(system)  # CPU time: what one unloaded core would take
            peak_mb = int(rss) / 1024
            wall = time.perf_counter() - t0
            ev_args = ["eval", "relations", str(out), f"{a.data}/{rel}"] + [x.format(data=a.data) for x in extra]
            print(_show(ev_args), flush=True)
            ev = json.loads(subprocess.run(_cmd(ev_args + ["--json"], None), env=env, capture_output=True,
                                           text=True, check=True).stdout)
            summ = json.loads((out / "summary.json").read_text())
            lc = summ.get("loop_closure", {})
            rows.append((name, setting, ev["relations_scored"], ev["translation_m"]["mean"], ev["translation_m"]["std"],
                         ev["rotation_deg"]["mean"], ev["rotation_deg"]["std"], lc.get("loops_accepted", "—"),
                         lc.get("loops_active", "—"), "yes" if lc.get("corrected") else "no" if lc else "—",
                         summ["wall_time_s"], wall, cpu_s, peak_mb))
    print()
    print("| log | loop closure | relations | translation [m] | rotation [deg] | loops (active) | optimised kept "
          "| run wall [s] | process wall [s] | process CPU [s] | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.4f} ± {r[4]:.4f} | {r[5]:.2f} ± {r[6]:.2f} | {r[7]} ({r[8]}) "
              f"| {r[9]} | {r[10]:.1f} | {r[11]:.1f} | {r[12]:.1f} | {r[13]:.0f} |")


if __name__ == "__main__":
    main()
