"""Speed of the SLAM core (not run by pytest).

Measures, at 0.05 m with 3 levels (the defaults):
  * numba compile / cache-load time of the first call (separately),
  * steady-state ms per scan (median, p95) and scans/s for the whole ``process`` call,
    and for matching and map update separately,
on 720-beam simulated scans (``sim:static``) and, if present, the MIT CSAIL log.

    python benchmarks/bench_slam.py [--duration 60] [--no-csail] [--cold]

``--cold`` points numba at an empty cache directory first, so the "first calls" line
measures a full compile instead of a cache load.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

CSAIL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mit-csail" / "mit-csail.clf"


def _stats(ms: list[float]) -> str:
    if not ms:
        return "n=0"
    a = np.asarray(ms)
    return f"median {np.median(a):.3f} ms, p95 {np.percentile(a, 95):.3f} ms, mean {a.mean():.3f} ms (n={a.size})"


def run(name: str, scans: list) -> None:
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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds (20 Hz)")
    ap.add_argument("--no-csail", action="store_true")
    ap.add_argument("--cold", action="store_true", help="compile numba kernels from scratch (empty cache)")
    args = ap.parse_args()
    if args.cold:
        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench_slam_numba_")

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

    sim = simulate("static", seed=0, duration=args.duration, beams=720)
    run("sim:static (20 Hz)", sim.scans)
    if not args.no_csail and CSAIL.exists():
        from dynslam2d.io.carmen import CarmenSource

        run("MIT CSAIL (4.7 Hz, 180°)", list(CarmenSource(CSAIL)))


if __name__ == "__main__":
    main()
