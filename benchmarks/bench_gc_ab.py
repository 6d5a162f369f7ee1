"""CPU time per scan and garbage-collector time per scan of ``pipeline.run`` in two checkouts, in lockstep.

``bench_pipeline_ab.py`` calls ``Pipeline.process`` itself, so a change in :func:`dynslam2d.pipeline.run`
(the loop ``dynslam2d run``, ``batch`` workers and ``experiment`` share) is not in it. Here two worker
processes, one per checkout (``PYTHONPATH``), each warm their kernels on the input's first 60 scans with a
throw-away pipeline, then call ``run`` over the input read from the file as the CLI reads it (a bag is
decoded scan by scan, not held in memory), with the observers a ``batch`` job has (removed-points collector,
clean-up recorder). The source hands ``run`` its next scan when the parent says ``go``: the parent alternates
which worker goes first, scan by scan, so both run on the same core under the same load. Each worker reports
per scan the thread CPU time from handing over the scan to being asked for the next one (``process``, the
run loop's records, the observers; the bag decoding is outside) and the time spent in Python's cyclic
garbage collector (``gc.callbacks``, thread CPU time) over the same interval, plus collections per generation.

    taskset -c 0 python benchmarks/bench_gc_ab.py negative_2/right [--other /tmp/base/src] [--reps 3] \
        [--freeze [--threshold 10000]]

``--other`` defaults to this checkout, so ``--freeze`` alone measures ``gc.freeze()`` after the first scan
(``gc.collect(1)`` first) against the unchanged collector, ``--threshold N`` also a raised generation-0
threshold, without changing the library.

Inputs: the names of ``bench_digest.py`` (paths under ``--data``). Both workers inherit this process's CPU
affinity: pin the parent with ``taskset``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from kernelwarm import preload  # noqa: E402

WARMUP = 60


def worker(data: Path, name: str, freeze: bool, threshold: int | None) -> None:
    """Serve ``go`` lines on stdin: hand ``run`` its next scan; answer one JSON line per scan (module docstring)."""
    import gc
    import time

    import dynslam2d.pipeline as pl
    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    rel, topic = INPUTS[name]
    path = rel if rel.startswith("sim:") else str(data / rel)
    warm = pl.Pipeline()
    for i, s in enumerate(open_source(path, topic)):
        if i == WARMUP:
            break
        warm.process(s)
    del warm
    preload()  # (kernels first called after the warm-up: not loaded inside the run)
    gc_ns = [0]
    started = [0]
    per_gen = [0, 0, 0]
    gen_ns = [0, 0, 0]
    where = ["start"]  # where the run is: "scan" (between handing a scan over and the next request), "read", "end"
    by_phase: dict[str, list[float]] = {}

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            started[0] = time.thread_time_ns()
        else:
            dt = time.thread_time_ns() - started[0]
            gc_ns[0] += dt
            per_gen[info["generation"]] += 1
            gen_ns[info["generation"]] += dt
            if info["generation"] == 2:
                by_phase.setdefault(where[0], []).append(round(dt / 1e6, 1))

    gc.callbacks.append(on_gc)
    totals = {"cpu_ms": 0.0, "gc_ms": 0.0}
    inner = open_source(path, topic)

    class Lockstep:
        """``inner`` handed out one scan per ``go`` line; times the caller's work between two scans."""

        meta = inner.meta

        def __len__(self) -> int:
            return len(inner)

        def __iter__(self):  # type: ignore[no-untyped-def]
            t0 = g0 = None
            for k, scan in enumerate(inner):
                where[0] = "read"
                if freeze and k == 1:  # the first scan is done: start-up's objects out of later collections
                    gc.collect(1)
                    gc.freeze()
                    if threshold is not None:
                        gc.set_threshold(threshold, 10, 10)
                if t0 is not None:
                    cpu = (time.thread_time_ns() - t0) / 1e6
                    totals["cpu_ms"] += cpu
                    totals["gc_ms"] += (gc_ns[0] - g0) / 1e6
                    print(json.dumps({"cpu": cpu, "gc": (gc_ns[0] - g0) / 1e6}), flush=True)
                if sys.stdin.readline().strip() != "go":
                    return
                g0 = gc_ns[0]
                t0 = time.thread_time_ns()
                where[0] = "scan"
                yield scan
            where[0] = "end"
            if t0 is not None:
                print(json.dumps({"cpu": (time.thread_time_ns() - t0) / 1e6, "gc": (gc_ns[0] - g0) / 1e6}),
                      flush=True)

    cfg = Config()
    observers = [RemovedPointsCollector(), CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)]
    print(json.dumps({"ready": True}), flush=True)
    result = pl.run(Lockstep(), cfg, observers=observers)
    print(json.dumps({"end": True, "n": result.n_scans, "per_gen": per_gen,
                      "gen_ms": [v / 1e6 for v in gen_ns],
                      "gen2_ms_by_phase": by_phase, "tracked": len(gc.get_objects()),
                      "loop_totals": totals, "gc_after": gc.get_threshold(),
                      "frozen_after": gc.get_freeze_count()}), flush=True)


def compare(data: Path, name: str, other: Path, reps: int, freeze: bool, threshold: int | None) -> None:
    """Run both checkouts over ``name`` ``reps`` times in lockstep and print the comparison."""
    cpu: dict[str, list[float]] = {"other": [], "this": []}
    gct: dict[str, list[float]] = {"other": [], "this": []}
    ends: dict[str, list[dict]] = {"other": [], "this": []}
    for _ in range(reps):
        procs = {}
        for tag, src in (("other", other.resolve()), ("this", REPO / "src")):
            env = dict(os.environ, PYTHONPATH=str(src))
            procs[tag] = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data", str(data)]
                + (["--freeze"] if freeze and tag == "this" else [])
                + (["--threshold", str(threshold)] if threshold is not None and tag == "this" else []),
                env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        for p in procs.values():
            assert json.loads(p.stdout.readline())["ready"]
        done = False
        i = 0
        while not done:
            for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
                p = procs[tag]
                try:
                    p.stdin.write("go\n")
                    p.stdin.flush()
                except BrokenPipeError:  # its run has ended and printed its last line: read that
                    pass
                line = p.stdout.readline()
                if os.environ.get("GCAB_DEBUG"):
                    print(tag, i, repr(line), flush=True)
                r = json.loads(line)
                if "end" in r:
                    ends[tag].append(r)
                    done = True
                    continue
                cpu[tag].append(r["cpu"])
                gct[tag].append(r["gc"])
            i += 1
        for tag, p in procs.items():
            try:
                p.stdin.close()
            except BrokenPipeError:
                pass
            for line in p.stdout:
                r = json.loads(line)
                if "end" in r:
                    ends[tag].append(r)
                elif "cpu" in r:  # the last scan of the worker that had not ended yet
                    cpu[tag].append(r["cpu"])
                    gct[tag].append(r["gc"])
            p.wait()
    n = min(len(cpu["other"]), len(cpu["this"]))
    for tag in cpu:
        cpu[tag], gct[tag] = cpu[tag][:n], gct[tag][:n]
    mo, mt = statistics.median(cpu["other"]), statistics.median(cpu["this"])
    ao, at = statistics.fmean(cpu["other"]), statistics.fmean(cpu["this"])
    go, gt = statistics.fmean(gct["other"]), statistics.fmean(gct["this"])
    print(f"{name}: {n} scans ({reps} runs), run-loop CPU ms/scan median: other {mo:.3f}, this {mt:.3f}, "
          f"ratio {mt / mo:.3f}; mean: other {ao:.3f}, this {at:.3f}, ratio {at / ao:.3f}")
    print(f"  GC ms/scan (mean): other {go:.4f}, this {gt:.4f}; collections per generation (run 1): "
          f"other {ends['other'][0]['per_gen'] if ends['other'] else '?'}, "
          f"this {ends['this'][0]['per_gen'] if ends['this'] else '?'}")
    print(f"  GC ms per generation (run 1): other {[round(v, 1) for v in ends['other'][0]['gen_ms']]}, "
          f"this {[round(v, 1) for v in ends['this'][0]['gen_ms']]}; slowest scan: other {max(cpu['other']):.1f}, "
          f"this {max(cpu['this']):.1f} ms")
    for tag in ("other", "this"):
        if ends[tag]:
            print(f"  {tag}: full collections (ms) by where they ran: {ends[tag][0]['gen2_ms_by_phase']}; "
                  f"{ends[tag][0]['tracked']} tracked objects at the end")
    print(f"  GC state after run(): other threshold {ends['other'][0]['gc_after']}, frozen "
          f"{ends['other'][0]['frozen_after']}; this threshold {ends['this'][0]['gc_after']}, frozen "
          f"{ends['this'][0]['frozen_after']}")
    sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", choices=sorted(INPUTS))
    ap.add_argument("--other", type=Path, default=REPO / "src", help="the other checkout's src/ (default: this one)")
    ap.add_argument("--reps", type=int, default=1, help="lockstep runs per input (pooled)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--freeze", action="store_true",
                    help="this checkout's worker calls gc.collect(1); gc.freeze() after the first scan")
    ap.add_argument("--threshold", type=int, default=None,
                    help="with --freeze: also gc.set_threshold(N, 10, 10) (CPython's default: 700)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.data, args.inputs[0], args.freeze, args.threshold)
        return
    for name in args.inputs:
        compare(args.data, name, args.other, args.reps, args.freeze, args.threshold)


if __name__ == "__main__":
    main()
