"""Peak memory of ``dynslam2d run`` on a long CARMEN log vs a short one (issue 14, item 7).

Generates synthetic FLASER logs (a robot driving back and forth in a 10 m × 6 m room,
180 beams, 10 Hz) of N scans under /tmp (never in the repository), runs
``dynslam2d run LOG --out DIR -q`` in a subprocess for each N and reports the child's
peak resident memory (``ru_maxrss``) and wall time.

    PYTHONPATH=src python benchmarks/bench_memory.py --scans 2000 200000

``--inputs`` measures recordings instead (issue 13 item 3, the baseline: imports, kernels, map,
clean-up pass and figures), e.g. MIT CSAIL, the leg_tracker and datmo bags, the README's scene:

    PYTHONPATH=src python benchmarks/bench_memory.py --inputs ../shared/data/mit-csail/mit-csail.clf sim:paper

Numbers go to docs/reliability.md with the command that produced them.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scratch import scratch_dir

ROOM = (-5.0, 5.0, -3.0, 3.0)  # x0, x1, y0, y1 of the walls, m
BEAMS = 180
RATE_HZ = 10.0


def room_ranges(x: float, y: float, th: float, angles: np.ndarray) -> np.ndarray:
    """Range from (x, y, heading th) to the walls of :data:`ROOM` along each beam angle, m."""
    a = th + angles
    c, s = np.cos(a), np.sin(a)
    x0, x1, y0, y1 = ROOM
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (x1 - x) / c, np.where(c < 0, (x0 - x) / c, np.inf))
        ty = np.where(s > 0, (y1 - y) / s, np.where(s < 0, (y0 - y) / s, np.inf))
    return np.minimum(tx, ty)


def write_log(path: Path, n: int, seed: int = 0) -> None:
    """A FLASER log of ``n`` scans: the robot drives ±2 m along x at 0.3 m/s, turning gently."""
    rng = np.random.default_rng(seed)
    angles = -math.pi / 2 + math.pi * np.arange(BEAMS) / (BEAMS - 1)
    with path.open("w") as fh:
        for i in range(n):
            t = 1_000_000.0 + i / RATE_HZ
            x = 2.0 * math.sin(0.15 * t / 2.0)
            y = 0.3 * math.sin(0.05 * t)
            th = 0.2 * math.sin(0.07 * t)
            r = room_ranges(x, y, th, angles) + rng.normal(0.0, 0.01, BEAMS)
            rr = " ".join(f"{v:.3f}" for v in r)
            fh.write(f"FLASER {BEAMS} {rr} {x:.4f} {y:.4f} {th:.4f} {x:.4f} {y:.4f} {th:.4f} {t:.6f} bench {t:.6f}\n")


def measure(log: Path, out: Path, extra: list[str], src: str) -> tuple[float, float]:
    """(peak RSS MiB, wall s) of one ``dynslam2d run`` subprocess importing dynslam2d from ``src``."""
    env = dict(os.environ)
    env["PYTHONPATH"] = src
    code = ("import resource, subprocess, sys; "
            "r = subprocess.run(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); sys.exit(r.returncode)")
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "dynslam2d", "run", str(log), "--out",
                          str(out),
                          "-q", *extra], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"run failed: {res.stderr}")
    kib = int(res.stderr.strip().splitlines()[-1])
    return kib / 1024.0, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scans", type=int, nargs="+", default=[2000, 200000])
    ap.add_argument("--keep", action="store_true", help="keep the generated logs and results")
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"),
                    help="the dynslam2d source folder to measure (default: this checkout's src/)")
    ap.add_argument("--inputs", nargs="+", default=None,
                    help="recordings (or sim:<scenario>) to measure instead of generated logs")
    ap.add_argument("extra", nargs="*", help="extra options for 'dynslam2d run' (after --)")
    args = ap.parse_args()
    work = Path(scratch_dir("dynslam2d-bench-memory-", keep=args.keep))  # removed at exit unless --keep
    rows = []
    try:
        if args.inputs:
            for i, inp in enumerate(args.inputs):
                mib, wall = measure(Path(inp), work / f"in-{i}", args.extra, args.src)  # str(Path("sim:x")) == "sim:x"
                print(f"{inp:<60} peak RSS {mib:8.1f} MiB  wall {wall:8.1f} s", flush=True)
            return
        for n in args.scans:
            log = work / f"room-{n}.clf"
            write_log(log, n)
            mib, wall = measure(log, work / f"out-{n}", args.extra, args.src)
            rows.append((n, log.stat().st_size / 2**20, mib, wall))
            print(f"{n:>8} scans  log {rows[-1][1]:8.1f} MiB  peak RSS {mib:8.1f} MiB  wall {wall:8.1f} s "
                  f"({n / wall:.0f} scans/s)", flush=True)
            log.unlink()
        if len(rows) >= 2:
            print(f"peak RSS ratio {rows[-1][0]} / {rows[0][0]} scans: {rows[-1][2] / rows[0][2]:.2f}")
    finally:
        if args.keep:
            print(f"logs and results kept in {work}")


if __name__ == "__main__":
    main()
