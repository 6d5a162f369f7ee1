"""Speed of the SLAM core (not run by pytest).

Measures, at 0.05 m with 3 levels (the defaults):
  * numba compile / cache-load time of the first call (separately),
  * steady-state ms per scan (median, p95) and scans/s for the whole ``process`` call,
    and for matching and map update separately,
on 720-beam simulated scans (``sim:static``) and, if present, the MIT CSAIL log (laser only: its CARMEN scans
carry no odometry). Times are wall time (``time.perf_counter``) of ``HectorSlam.process``; scans/s is 1 / mean.

    python benchmarks/bench_slam.py [--duration 60] [--no-csail] [--cold] [--markdown]

``--cold`` points numba at an empty cache directory first, so the "first calls" line
measures a full compile instead of a cache load. ``--markdown`` prints, after the runs, the rows of docs/slam.md's
"Speed" table (median / p95 per scan, matching and map-update medians, scans/s) under the command line, the
time and the load average before and after the runs, ready to paste (``benchmarks/release_figures.sh`` writes this
script's output to ``OUT/slam.txt``).
"""

from __future__ import annotations

import argparse
import datetime
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np
from scratch import scratch_dir

CSAIL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mit-csail" / "mit-csail.clf"


def _stats(ms: list[float]) -> str:
    if not ms:
        return "n=0"
    a = np.asarray(ms)
    return f"median {np.median(a):.3f} ms, p95 {np.percentile(a, 95):.3f} ms, mean {a.mean():.3f} ms (n={a.size})"


def run(name: str, scans: list) -> dict[str, object]:
    """One fresh ``HectorSlam`` over ``scans``; prints its figures and returns them (ms lists, first scan left out,
    for :func:`markdown_row`)."""
    from dynslam2d.slam import HectorSlam, SlamConfig

    slam = HectorSlam(SlamConfig())
    total, match, update = [], [], []
    t_all = time.perf_counter()
    for s in scans:
        t0 = time.perf_counter()
        st = slam.process(s)
        total.append((time.perf_counter() - t0) * 1e3)
        match.append(st.match_ms)
        if st.map_updated:
            update.append(st.update_ms)
    wall = time.perf_counter() - t_all
    steady = total[1:]
    print(f"\n== {name}: {len(scans)} scans, {scans[0].n_beams} beams ==")
    print(f"process (all but first): {_stats(steady)}")
    print(f"  scans/s steady (1/mean): {1e3 / np.mean(steady):.0f}; whole run incl. first: {len(scans) / wall:.0f}")
    print(f"  matching:   {_stats(match[1:])}")
    print(f"  map update: {_stats(update[1:])}  ({len(update)} updates)")
    summ = slam.summary()
    print(f"  counters: {summ['reasons']}, memory {summ['memory_bytes'] / 1e6:.1f} MB")
    return {"n": len(scans), "total": steady, "match": match[1:], "update": update[1:], "updates": len(update)}


#: docs/slam.md's "Speed" table header
TABLE_HEAD = ("| input | per scan, median / p95 | matching median | map update median (scans that update the map) "
              "| scans/s |\n|---|---|---|---|---|")


def markdown_row(label: str, fig: dict[str, object]) -> str:
    """One row of docs/slam.md's "Speed" table from :func:`run`'s figures: per-scan median / p95 ms, matching
    median ms, map-update median ms (with the share of scans that update the map), scans/s = 1 / mean (to 10)."""
    total = np.asarray(fig["total"])
    upd = np.asarray(fig["update"])
    n, k = int(fig["n"]), int(fig["updates"])
    share = f"1 scan in {n / k:.1f}" if k else "no updates"
    up = f"{np.median(upd):.2f} ms ({share})" if upd.size else f"— ({share})"
    rate = 10 * round(1e3 / float(total.mean()) / 10)
    return (f"| {label} | {np.median(total):.2f} / {np.percentile(total, 95):.2f} ms | "
            f"{np.median(np.asarray(fig['match'])):.2f} ms | {up} | ≈ {rate} |")


def _load() -> str:
    """The 1-, 5- and 15-minute load averages."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds (20 Hz)")
    ap.add_argument("--no-csail", action="store_true")
    ap.add_argument("--cold", action="store_true", help="compile numba kernels from scratch (empty cache)")
    ap.add_argument("--markdown", action="store_true",
                    help="also print docs/slam.md's Speed table rows, the command line and the load")
    args = ap.parse_args()
    if args.cold:
        os.environ["NUMBA_CACHE_DIR"] = scratch_dir("bench_slam_numba_")

    # first call: numba compile (or cache load) of every kernel
    t0 = time.perf_counter()
    from dynslam2d.sim import simulate
    from dynslam2d.slam import HectorSlam, SlamConfig

    t_import = time.perf_counter() - t0
    warm = simulate("static", seed=5, duration=1.0).scans
    t0 = time.perf_counter()
    slam = HectorSlam(SlamConfig(correlative_mode="always"))
    for s in warm[:3]:
        slam.process(s)
    t_first = time.perf_counter() - t0
    what = "numba compile" if args.cold else "numba cache load (use --cold for compile)"
    print(f"import {t_import:.2f} s; first three process() calls ({what}): {t_first:.2f} s")

    load_before = _load()
    rows = []
    sim = simulate("static", seed=0, duration=args.duration, beams=720)
    fig = run("sim:static (20 Hz)", sim.scans)
    rows.append(markdown_row(f"`sim:static`, {sim.scans[0].n_beams} beams, 20 Hz", fig))
    if not args.no_csail and CSAIL.exists():
        from dynslam2d.io.carmen import CarmenSource

        scans = list(CarmenSource(CSAIL))
        fig = run("MIT CSAIL (4.7 Hz, 180°)", scans)
        rows.append(markdown_row(f"MIT CSAIL, {scans[0].n_beams} beams, laser only", fig))
    if args.markdown:
        cmd = shlex.join(["python", "benchmarks/bench_slam.py", *sys.argv[1:]])
        when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        print(f"\n`{cmd}` ({when}; load average {load_before} before the runs, {_load()} after; wall time, "
              f"scans/s = 1 / mean):\n")
        print(TABLE_HEAD)
        print("\n".join(rows))


if __name__ == "__main__":
    main()
