"""Speed of the full pipeline — detection, tracking, filter, SLAM — per stage (not run by pytest).

Scenes (720 beams, 20 Hz, simulated up front so that only ``Pipeline.process`` is timed):

  * ``sim:paper``  — the paper's room with its three movers,
  * ``sim:crowd``  — the crowd hall,
  * ``ten-movers`` — the crowd hall with 10 movers (six people, four boxes/carts; the scene of
    ``bench_detect.py``).

For each scene it reports

  * warm-up separately: a throw-away pipeline over the first 60 scans, reporting the first
    ``process`` call and the slowest later one (numba compile, or numba cache load when the
    cache is warm; some kernels first run once tracks exist) — excluded from every
    steady-state figure, which come from a fresh pipeline over all scans but the first,
  * ms per stage, median and p95, from ``StepResult.timings`` (match, track, filter,
    map_update, total),
  * scans/s: ``1000 / median(total)`` (the issue-5 target: ≥ 400 on one core) and the
    throughput of the whole steady-state loop (scans / wall time, includes Python overhead
    between calls), and the loop's thread CPU time per scan (``time.thread_time``; on a shared
    machine the wall-time figures include waiting for a core, the CPU time does not).

    python benchmarks/bench_pipeline.py [--duration 30] [--scenes paper crowd ten-movers] [--cold]

``--cold`` points numba at an empty cache directory first, so the first-call line measures a
full compile instead of a cache load. Pin to one core with ``taskset -c 0`` for "one core".
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time

import numpy as np
from scenes import ten_movers
from scratch import scratch_dir

STAGES = ("match", "track", "filter", "map_update", "loops", "total")


def scan_loop_gc() -> contextlib.AbstractContextManager:
    """The collector setting ``pipeline.run`` makes for its scan loop (``dynslam2d.collector.scan_loop_gc``: a
    raised generation-0 threshold), for a benchmark's own loop over ``Pipeline.process``; a checkout without it
    (a base before pass gc27) gets CPython's collector as it is, as its ``run`` does."""
    try:
        from dynslam2d.collector import scan_loop_gc as scope
    except ImportError:
        return contextlib.nullcontext(False)
    return scope()


def _scans(name: str, duration: float) -> list:
    from dynslam2d.sim import simulate

    sim = ten_movers(duration) if name == "ten-movers" else simulate(name, duration=duration)
    return list(sim.scans)


def warm_up(scans: list, n: int = 60, preload: bool = True) -> tuple[float, float]:
    """Run a throw-away ``Pipeline`` over the first ``n`` scans so that the kernels are compiled (or loaded from the
    cache): some are first called only once tracks exist or are confirmed. Then (``preload``) load every other
    kernel numba's cache holds and the modules a run imports late (``kernelwarm.preload``): some kernels are first
    called much later (the loop closer's on its first far search), and the pose graph's first optimisation imports
    ``scipy.sparse``, which would put ≈ 100 + 90 ms of loading on negative_2 inside the measured run. Returns (first
    process() call, slowest later call) in ms."""
    from kernelwarm import preload as load_the_rest

    from dynslam2d.pipeline import Pipeline

    pipe = Pipeline()
    times = []
    for s in scans[:n]:
        t0 = time.perf_counter()
        pipe.process(s)
        times.append((time.perf_counter() - t0) * 1e3)
    del pipe
    if preload:
        load_the_rest()
    return times[0], max(times[1:], default=0.0)


def bench(name: str, scans: list) -> dict[str, object]:
    """Warm up, then run a fresh ``Pipeline`` over ``scans``; return the figures (ms, scans/s).
    The steady-state figures leave out the first scan (it only initialises the map)."""
    from dynslam2d.pipeline import Pipeline

    first_ms, warm_max_ms = warm_up(scans)
    pipe = Pipeline()
    pipe.process(scans[0])
    per_stage: dict[str, list[float]] = {k: [] for k in STAGES}
    n_tracks, n_m, removed = [], [], 0
    t_loop = time.perf_counter()
    c_loop = time.thread_time()
    with scan_loop_gc():
        for s in scans[1:]:
            step = pipe.process(s)
            for k in STAGES:
                per_stage[k].append(step.timings[k])
            n_tracks.append(len(step.tracks))
            n_m.append(sum(t.in_m for t in step.tracks))
            removed += int(step.removed.sum())
    wall = time.perf_counter() - t_loop
    cpu_ms = (time.thread_time() - c_loop) * 1e3 / max(len(scans) - 1, 1)
    stats = {k: (float(np.median(v)), float(np.percentile(v, 95))) for k, v in per_stage.items()}
    return {
        "scene": name, "scans": len(scans), "beams": scans[0].n_beams, "first_ms": first_ms, "warm_max_ms": warm_max_ms,
        "stages": stats,
        "scans_per_s_median": 1e3 / stats["total"][0], "scans_per_s_loop": (len(scans) - 1) / wall, "cpu_ms": cpu_ms,
        "mean_tracks": float(np.mean(n_tracks)), "mean_in_m": float(np.mean(n_m)),
        "removed_per_scan": removed / max(len(scans) - 1, 1),
    }


def report(r: dict[str, object]) -> str:
    lines = [f"\n== {r['scene']}: {r['scans']} scans, {r['beams']} beams; "
             f"{r['mean_tracks']:.1f} live tracks, {r['mean_in_m']:.1f} in M, "
             f"{r['removed_per_scan']:.0f} beams removed per scan ==",
             f"warm-up: first process() call {r['first_ms']:.0f} ms, slowest of the next 59 "
             f"{r['warm_max_ms']:.1f} ms (numba compile or cache load; not in the figures below)",
             f"{'stage':<11} {'median ms':>10} {'p95 ms':>9}"]
    for k, (med, p95) in r["stages"].items():  # type: ignore[union-attr]
        lines.append(f"{k:<11} {med:>10.3f} {p95:>9.3f}")
    lines.append(f"scans/s: {r['scans_per_s_median']:.0f} (1000 / median total), "
                 f"{r['scans_per_s_loop']:.0f} (whole steady-state loop); "
                 f"CPU {r['cpu_ms']:.3f} ms per scan (thread time of the loop, less sensitive to other jobs)")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--scenes", nargs="+", default=["paper", "crowd", "ten-movers"])
    ap.add_argument("--cold", action="store_true")
    args = ap.parse_args()
    if args.cold:
        os.environ["NUMBA_CACHE_DIR"] = scratch_dir("numba-cold-")
    for name in args.scenes:
        t0 = time.perf_counter()
        scans = _scans(name, args.duration)
        print(f"\nsimulated {name}: {len(scans)} scans in {time.perf_counter() - t0:.1f} s")
        print(report(bench(name, scans)))


if __name__ == "__main__":
    main()
