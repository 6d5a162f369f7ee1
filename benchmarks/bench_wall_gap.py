"""Why a scan's wall time exceeds its thread CPU, and why the table runs read slower (not run by pytest).

Runs the pipeline over one input and records, around every ``Pipeline.process`` call: the wall time of the
call and its ``StepResult.timings["total"]``, the thread CPU time (``time.thread_time``), the thread's minor
page faults and voluntary / involuntary context switches (``getrusage(RUSAGE_THREAD)``), and the time the cyclic
garbage collector ran inside the call (``gc.callbacks``). Two ways to drive it:

  * ``--mode mem``: the scans in memory, a fresh pipeline in a plain loop (``bench_real_speed.py``'s loop);
  * ``--mode run``: ``pipeline.run`` over the bag read as it goes, as ``dynslam2d run`` does (``Pipeline.process``
    wrapped to take the figures; with ``--cli-malloc`` glibc's thresholds as the command line sets them,
    ``memtrim.map_large_blocks``).

``--tracemalloc`` adds the traced peak per scan above the memory held before it (slow: timings then mean
nothing). Prints medians and means per scan.

    taskset -c 1 python benchmarks/bench_wall_gap.py [--input negative_2 /right_scan] [--mode mem|run]
        [--cli-malloc] [--tracemalloc] [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import gc
import resource
import time
from pathlib import Path

import numpy as np
from bench_pipeline import scan_loop_gc, warm_up

REPO = Path(__file__).resolve().parents[1]
BAG = "dynamic/leg_tracker/negative_2.bag"


class Probe:
    """Per-call figures of a wrapped ``process``."""

    def __init__(self, trace: bool) -> None:
        self.rows: list[tuple[float, ...]] = []
        self.gc_ns = 0
        self._gc0 = 0
        self.trace = trace
        gc.callbacks.append(self._gc)

    def _gc(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._gc0 = time.perf_counter_ns()
        else:
            self.gc_ns += time.perf_counter_ns() - self._gc0

    def wrap(self, process):  # noqa: ANN001, ANN201 - a bound method
        import tracemalloc

        def timed(scan):  # noqa: ANN001, ANN202
            if self.trace:
                tracemalloc.reset_peak()
                m0 = tracemalloc.get_traced_memory()[0]
            g0 = self.gc_ns
            r0 = resource.getrusage(resource.RUSAGE_THREAD)
            c0 = time.thread_time_ns()
            w0 = time.perf_counter_ns()
            step = process(scan)
            w1 = time.perf_counter_ns()
            c1 = time.thread_time_ns()
            r1 = resource.getrusage(resource.RUSAGE_THREAD)
            peak = (tracemalloc.get_traced_memory()[1] - m0) / 1024 if self.trace else 0.0
            self.rows.append((step.timings["total"], (w1 - w0) / 1e6, (c1 - c0) / 1e6, r1.ru_minflt - r0.ru_minflt,
                              r1.ru_nvcsw - r0.ru_nvcsw, r1.ru_nivcsw - r0.ru_nivcsw, (self.gc_ns - g0) / 1e6, peak))
            return step

        return timed

    def report(self, skip: int = 1) -> str:
        a = np.array(self.rows[skip:])
        names = ("total ms", "call ms", "cpu ms", "minflt", "vcsw", "ivcsw", "gc ms", "peak KiB")
        out = [f"{len(a)} scans; {'':>8}" + "".join(f"{n:>10}" for n in names)]
        out.append(f"{'median':>18}" + "".join(f"{v:>10.3f}" for v in np.median(a, axis=0)))
        out.append(f"{'mean':>18}" + "".join(f"{v:>10.3f}" for v in a.mean(axis=0)))
        out.append(f"{'p95':>18}" + "".join(f"{v:>10.3f}" for v in np.percentile(a, 95, axis=0)))
        tot = a[:, 0]
        flt = a[:, 3] > 0
        out.append(f"scans/s {1e3 / np.median(tot):.0f}; scans with faults {int(flt.sum())}, their median total "
                   f"{np.median(tot[flt]) if flt.any() else float('nan'):.3f} ms against "
                   f"{np.median(tot[~flt]) if (~flt).any() else float('nan'):.3f}; scans with an involuntary switch "
                   f"{int((a[:, 5] > 0).sum())}; gc collections in scans {int((a[:, 6] > 0).sum())}")
        quiet = (a[:, 5] == 0) & (a[:, 4] == 0) & (a[:, 6] == 0)
        out.append(f"scans not switched out and without a collection: {int(quiet.sum())}; their median total "
                   f"{np.median(tot[quiet]):.3f} ms, cpu {np.median(a[quiet, 2]):.3f} ms, call - cpu "
                   f"{np.median(a[quiet, 1] - a[quiet, 2]):.3f} ms; call - total {np.median(a[:, 1] - tot):.4f} ms")
        out.append(f"median cpu of every scan {np.median(a[:, 2]):.3f} ms, of scans 1-60 {np.median(a[:60, 2]):.3f}, "
                   f"of the later ones {np.median(a[60:, 2]):.3f}")
        return "\n".join(out)


def cli_once(probe: Probe, path: str, topic: str) -> None:
    """``dynslam2d run`` on ``topic`` of ``path`` in this process, every ``process`` call through ``probe``."""
    import sys
    import tempfile

    from dynslam2d.cli import main as cli_main
    from dynslam2d.pipeline import Pipeline

    orig = Pipeline.process

    def patched(self, scan):  # noqa: ANN001, ANN202
        return probe.wrap(lambda s: orig(self, s))(scan)

    Pipeline.process = patched  # type: ignore[method-assign]
    argv = sys.argv
    with tempfile.TemporaryDirectory() as tmp:
        sys.argv = ["dynslam2d", "run", path, "--topic", topic, "--out", f"{tmp}/out", "--quiet", "--force"]
        try:
            cli_main()
        except SystemExit:
            pass
        finally:
            Pipeline.process = orig  # type: ignore[method-assign]
            sys.argv = argv


def cli_ab(probe: Probe, path: str, topic: str, batch: int, reps: int) -> None:
    """Command-line runs alternated in this process: the clean-up recorder and the removed-points collector fed
    after every scan (as today) and in batches of ``batch`` scans (``scan_batch``, ``pipeline.run``); per run the
    median thread CPU of every ``process`` call and the median total of the scans not switched out."""
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    out: dict[int, list[tuple[float, float]]] = {1: [], batch: []}
    for r in range(reps):
        for b in ((1, batch) if r % 2 == 0 else (batch, 1)):
            CleanupRecorder.scan_batch = b  # type: ignore[attr-defined]
            RemovedPointsCollector.scan_batch = b  # type: ignore[attr-defined]
            probe.rows = []
            cli_once(probe, path, topic)
            a = np.array(probe.rows[1:])
            quiet = (a[:, 5] == 0) & (a[:, 4] == 0) & (a[:, 6] == 0)
            out[b].append((float(np.median(a[:, 2])), float(np.median(a[quiet, 0]))))
    for b, rows in out.items():
        print(f"observers every {b:>3} scans: median cpu ms {[round(x[0], 3) for x in rows]}, "
              f"median total of the scans not switched out {[round(x[1], 3) for x in rows]}")
    print("ratio batched / every scan, cpu:", [round(x[0] / y[0], 3) for x, y in zip(out[batch], out[1])],
          "quiet total:", [round(x[1] / y[1], 3) for x, y in zip(out[batch], out[1])])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--topic", default="/right_scan")
    ap.add_argument("--mode", choices=("mem", "run", "cli"), default="mem")
    ap.add_argument("--cli-malloc", action="store_true")
    ap.add_argument("--preload", action="store_true", help="--mode run: the scans read into memory first")
    ap.add_argument("--tracemalloc", action="store_true")
    ap.add_argument("--cli-ab", type=int, default=0, metavar="K",
                    help="--mode cli: runs alternated, the observers fed after every scan against in batches of K")
    ap.add_argument("--reps", type=int, default=4, help="--cli-ab: pairs")
    ap.add_argument("--no-warm", action="store_true",
                    help="no throw-away pipeline over the first 60 scans first (the command line's first scans)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    if args.cli_malloc:
        from dynslam2d.memtrim import map_large_blocks

        map_large_blocks()
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline, run

    path = str(args.data / BAG)
    scans = list(open_source(path, args.topic))
    if not args.no_warm:
        warm_up(scans)
    if args.tracemalloc:
        import tracemalloc

        tracemalloc.start()
    probe = Probe(args.tracemalloc)
    orig = Pipeline.process
    if args.mode == "cli":  # the command line's run in this process (its observers, allocator and collector settings)
        del scans
        if args.cli_ab:
            cli_ab(probe, path, args.topic, args.cli_ab, args.reps)
            return
        cli_once(probe, path, args.topic)
    elif args.mode == "mem":
        pipe = Pipeline()
        proc = probe.wrap(pipe.process)
        with scan_loop_gc():
            for s in scans:
                proc(s)
    else:
        source = open_source(path, args.topic)
        if args.preload:
            from dynslam2d.types import SourceWrapper

            class Listed(SourceWrapper):
                def __iter__(self):  # noqa: ANN204
                    return iter(scans)

            source = Listed(source)
        else:
            del scans

        def patched(self, scan):  # noqa: ANN001, ANN202
            return probe.wrap(lambda s: orig(self, s))(scan)

        Pipeline.process = patched  # type: ignore[method-assign]
        try:
            run(source)
        finally:
            Pipeline.process = orig  # type: ignore[method-assign]
    print(f"{args.mode}{' cli-malloc' if args.cli_malloc else ''} {args.topic}")
    print(probe.report())


if __name__ == "__main__":
    main()
