"""How much the command line's per-scan work between two scans slows the next ``Pipeline.process`` (not run by pytest).

``dynslam2d run`` (the runs of ``bench_real.py``'s tables) does more per scan than ``bench_real_speed.py``'s loop
over scans in memory: it decodes the next scan from the bag, and its observers count the scan's beams into the
clean-up pass's grid (``slam.cleanup.CleanupRecorder``) and keep the removed points
(``viz.collect.RemovedPointsCollector``). That work is outside ``StepResult.timings``, but it evicts the pipeline's
own arrays from the CPU caches, and the next ``process`` call pays for the misses.

Measured in one process, in thread CPU time (``time.thread_time_ns``; a switch to another job does not count): a
fresh pipeline over the scans in memory, with the command line's per-scan work (one scan decoded from a second
reader of the bag, the two observers) done for every scan, but deferred in pairs so that only every other
``process`` call follows it directly (scans 2k, 2k+1: process, process, work of 2k and 2k+1). A second pipeline
does the same with the other phase (the work before the odd scans). Every scan is so timed once after the work
and once after only the other scan's ``process``; the observers see every scan in order as in a run. Repeated
``--reps`` times with the phases alternated; prints the median over scans of the paired difference (after the
work − without), µs, and the median CPU of each.

    taskset -c 1 python benchmarks/bench_run_context.py [--topic /right_scan] [--reps 2] [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from bench_pipeline import scan_loop_gc, warm_up

REPO = Path(__file__).resolve().parents[1]
BAG = "dynamic/leg_tracker/negative_2.bag"


def one(scans: list, path: str, topic: str, phase: int, work: tuple[str, ...], batch: int = 2) -> np.ndarray:
    """Thread CPU (ns) of every ``process`` call of a fresh pipeline; the command line's work deferred so that it
    directly precedes the scans of parity ``phase`` (``work``: which of "decode", "collect", "clean"). ``batch`` other
    than 2: the work of the last ``batch`` scans done together before every ``batch``-th scan (1: after every scan,
    as ``pipeline.run`` does; ``phase`` then unused)."""
    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    cfg = Config()
    pipe = Pipeline(cfg)
    observers = ([RemovedPointsCollector()] if "collect" in work else []) + (
        [CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)] if "clean" in work else [])
    reader = iter(open_source(path, topic))
    cpu = np.zeros(len(scans), dtype=np.int64)
    pending: list = []

    def flush() -> None:
        for s, step in pending:
            if "decode" in work:
                next(reader, None)
            for obs in observers:
                obs.on_scan(s, step, pipe)
        pending.clear()

    with scan_loop_gc():
        for i, s in enumerate(scans):
            if (i % 2 == phase) if batch == 2 else (i % batch == 0):
                flush()
            c0 = time.thread_time_ns()
            step = pipe.process(s)
            cpu[i] = time.thread_time_ns() - c0
            pending.append((s, step))
    return cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--topic", default="/right_scan")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--work", default="decode,collect,clean",
                    help="the per-scan work between scans, comma-separated among decode, collect, clean")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--batch", type=int, default=0,
                    help="instead: the work after every scan (as run does) against the work of every BATCH scans "
                         "done together, runs alternated; median CPU of every process() call of each")
    args = ap.parse_args()
    from dynslam2d.inputs import open_source

    path = str(args.data / BAG)
    scans = list(open_source(path, args.topic))
    warm_up(scans)
    if args.batch:
        work = tuple(args.work.split(","))
        meds: dict[int, list[float]] = {1: [], args.batch: []}
        for r in range(args.reps):
            for b in ((1, args.batch) if r % 2 == 0 else (args.batch, 1)):
                meds[b].append(float(np.median(one(scans, path, args.topic, 0, work, b)[1:])) / 1e3)
        ratio = [x / y for x, y in zip(meds[args.batch], meds[1])]
        print(f"negative_2 {args.topic}, work {args.work}: median thread CPU of process(), µs, work after every scan "
              f"{[round(x) for x in meds[1]]}, in batches of {args.batch} {[round(x) for x in meds[args.batch]]}; "
              f"ratio batch / every scan {[round(x, 3) for x in ratio]}")
        return
    after: list[np.ndarray] = []
    clean: list[np.ndarray] = []
    idx = np.arange(len(scans))
    for r in range(args.reps):
        order = (0, 1) if r % 2 == 0 else (1, 0)
        cpu = {phase: one(scans, path, args.topic, phase, tuple(args.work.split(","))) for phase in order}
        even = idx % 2 == 0
        # phase 0 puts the work before the even scans: their "after" timing; the odd ones' comes from phase 1
        after.append(np.where(even, cpu[0], cpu[1])[2:])
        clean.append(np.where(even, cpu[1], cpu[0])[2:])
    a = np.concatenate(after)
    b = np.concatenate(clean)
    d = (a - b) / 1e3
    ok = np.ones(len(a), dtype=bool)
    print(f"negative_2 {args.topic}, work {args.work}: {int(ok.sum())} scans, {args.reps} reps (both phases each); "
          f"thread CPU of process() median after the run's per-scan work {np.median(a[ok]) / 1e3:.1f} µs, after only"
          f" the other scan's process() {np.median(b[ok]) / 1e3:.1f} µs; paired difference median {np.median(d):.1f} "
          f"µs (25-75 %: {np.percentile(d, 25):.1f} … {np.percentile(d, 75):.1f})")


if __name__ == "__main__":
    main()
