"""Whole-pipeline CPU time per scan and per stage of two checkouts, in lockstep (not run by pytest).

``bench_tracker_ab.py --pipeline`` swaps only ``detect/tracker.py``; a change anywhere else in the per-scan path
(matcher, map update, evidence ledger, map evidence, filter, pipeline glue) needs both whole checkouts. Two worker
processes, one per checkout (``PYTHONPATH``), each open the input, warm their kernels on its first 60 scans with a
throw-away pipeline, then load every other kernel numba's cache holds and import the modules a run imports late
(``bench_pipeline.warm_up``, ``kernelwarm.preload``: some kernels are first called after scan 60 and the first
optimisation imports ``scipy.sparse``, loads that would count in the measured run; the kernels loaded or compiled
and the modules imported in the measured runs are printed, 0 when the warm-up did its work), then process the scans
one at a time when told to: the parent sends scan ``i`` to one worker, waits, then to the other (which one goes
first alternates with ``i``), so both run on the same core under the same load, scan by scan. Each worker times
``Pipeline.process`` in thread CPU time (``time.thread_time_ns``) and reports its stage timings
(``StepResult.timings``) in thread CPU time too (the pipeline's ``time.perf_counter`` is swapped for
``time.thread_time`` in the worker). Each worker's scan loop runs with its checkout's collector setting of
``pipeline.run``'s loop (``bench_pipeline.scan_loop_gc``: none in a checkout before it), as ``--parts``' loop does.
Printed per input: median CPU ms per scan of each checkout, their ratio, the median of the per-scan ratios, and the
median of every stage (``map_update``, ``loops`` and the whole pipeline also over the scans that updated the map).

    taskset -c 1 python benchmarks/bench_pipeline_ab.py negative_2/right negative_2/left negative_2/rear \
        --other <other checkout>/src [--reps 1]

``--parts`` instead runs this checkout alone (after the same warm-up) with thread-CPU timers around the parts of
the per-scan path and prints, per part, the median and mean µs over the scans that update the map and over the
others: the whole ``Pipeline.process`` and its top-level parts (body filter, the whole match, the tracker's
``update`` and its map view, the exclusions and observed boxes, the evidence ledger's methods, the map update, the
loop closer's ``add``), what ``process`` spends outside them ("unattributed": its own Python, the step record, the
timers), and inside the parts: the matcher's kernels called from Python (``match_pyramid``, which runs every
level with ``_match_core`` inside numba; the per-level ``match_level`` and the evaluation kernels; the scan
gating), the map update's ``MultiResMap.integrate`` (ray kernel and its Python), the vacated-footprint kernel
and the loop closer's place descriptor and searches. The wrapped timers cost ≈ 1 µs each.

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
from bench_pipeline import scan_loop_gc, warm_up  # noqa: E402 - pipeline.run's collector setting; the warm-up
from kernelwarm import kernel_cache_calls  # noqa: E402 - kernels loaded or compiled so far

WARMUP = 60


def load_scans(data: Path, name: str) -> list:
    """The scans of input ``name``: ``ten-movers`` (benchmarks/scenes.py, 30 s, the scene furthest from the per-scan
    target), a ``bench_digest`` input (recorded files under ``data``) or another built-in scene (``sim:NAME``)."""
    from dynslam2d.inputs import open_source

    if name == "ten-movers":
        from scenes import ten_movers

        return list(ten_movers(30.0).scans)
    rel, topic = INPUTS.get(name, (name, None))  # any other built-in scene by its name (sim:paper: README command 1)
    return list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))


def worker(data: Path, name: str, preload: bool = True) -> None:
    """Serve ``go`` lines on stdin: process the next scan, answer one JSON line (CPU ms, stage ms, updated); without
    ``preload`` the warm-up loads nothing it did not reach (the warm-up before pass neg71)."""
    import time
    import types

    import dynslam2d.memtrim as mt
    import dynslam2d.pipeline as pl

    if hasattr(mt, "map_large_blocks"):  # the allocator setting the command line makes (a checkout without it: none)
        mt.map_large_blocks()

    scans = load_scans(data, name)
    warm_up(scans, WARMUP, preload=preload)  # (and every kernel numba's cache holds loaded: none is loaded in the run)
    pl.time = types.SimpleNamespace(perf_counter=time.thread_time)  # stage timings in thread CPU time
    pipe = pl.Pipeline()
    print(json.dumps({"scans": len(scans)}), flush=True)
    looked, modules = kernel_cache_calls(), len(sys.modules)
    with scan_loop_gc():
        for i, line in enumerate(sys.stdin):
            if i >= len(scans) or line.strip() != "go":
                break
            t0 = time.thread_time_ns()
            step = pipe.process(scans[i])
            cpu = (time.thread_time_ns() - t0) / 1e6
            print(json.dumps({"cpu": cpu, "t": step.timings, "u": bool(step.map_updated)}), flush=True)
    # kernels loaded or compiled and modules imported in the measured run
    print(json.dumps({"loads": kernel_cache_calls() - looked, "imports": len(sys.modules) - modules}), flush=True)


def compare(data: Path, name: str, other: Path, reps: int, old_warmup: bool = False) -> None:
    """Run both checkouts over ``name`` ``reps`` times in lockstep and print the comparison (``old_warmup``: the
    other side's warm-up without the preload, see ``--old-warmup``)."""
    cpu: dict[str, list[float]] = {"other": [], "this": []}
    stages: dict[str, dict[str, list[float]]] = {"other": {}, "this": {}}
    upd: dict[str, list[bool]] = {"other": [], "this": []}
    loads = {"other": 0, "this": 0}
    imports = {"other": 0, "this": 0}
    for _ in range(reps):
        procs = {}
        for tag, src in (("other", other.resolve()), ("this", REPO / "src")):
            env = dict(os.environ, PYTHONPATH=str(src))
            late = ["--old-warmup"] if old_warmup and tag == "other" else []
            procs[tag] = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data", str(data), *late],
                env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())
        for i in range(n):
            for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
                p = procs[tag]
                p.stdin.write("go\n")
                p.stdin.flush()
                r = json.loads(p.stdout.readline())
                cpu[tag].append(r["cpu"])
                upd[tag].append(r["u"])
                for k, v in r["t"].items():
                    stages[tag].setdefault(k, []).append(v)
        for tag, p in procs.items():
            p.stdin.close()
            r = json.loads(p.stdout.readline())
            loads[tag] += r["loads"]
            imports[tag] += r["imports"]
            p.wait()
    mo, mt = statistics.median(cpu["other"]), statistics.median(cpu["this"])
    per = statistics.median(t / o for t, o in zip(cpu["this"], cpu["other"]))
    print(f"{name}: {len(cpu['this'])} scans, pipeline CPU ms/scan median: other {mo:.3f}, this {mt:.3f}, "
          f"ratio {mt / mo:.3f} (median per-scan ratio {per:.3f}); inside the measured runs kernels loaded or "
          f"compiled: other {loads['other']}, this {loads['this']}, modules imported: other {imports['other']}, "
          f"this {imports['this']}")
    # the mean and the 95th percentile: work on a few scans (the loop closer's far searches) moves them, not the median
    (ao, at), (po, pt) = ((statistics.fmean(cpu[g]) for g in ("other", "this")),
                          (statistics.quantiles(cpu[g], n=20)[-1] for g in ("other", "this")))
    print(f"  pipeline CPU ms/scan mean: other {ao:.3f}, this {at:.3f}, ratio {at / ao:.3f}; "
          f"p95: other {po:.3f}, this {pt:.3f}, ratio {pt / po:.3f}")
    # per stage the median and (throughput follows it) the mean: a stage's work on a few scans (a map growth, a
    # correlative pre-search) moves its mean only
    for k in stages["this"]:
        a, b = statistics.median(stages["other"][k]), statistics.median(stages["this"][k])
        ma, mb = statistics.fmean(stages["other"][k]), statistics.fmean(stages["this"][k])
        print(f"  {k:<11} other {a:7.3f}  this {b:7.3f}  ratio {b / a if a else float('nan'):.3f}   mean: other "
              f"{ma:7.3f}  this {mb:7.3f}  ratio {mb / ma if ma else float('nan'):.3f}")
    # the scans that update the map (keyframes: the loop closer's place descriptor and searches) decide the median
    for k in ("map_update", "loops", "cpu"):
        for tag in ("other", "this"):
            mu = [v for v, u in zip(cpu[tag] if k == "cpu" else stages[tag].get(k, []), upd[tag]) if u]
            if mu:
                print(f"  {'pipeline CPU' if k == 'cpu' else k} on updated scans ({len(mu)}), {tag}: "
                      f"{statistics.median(mu):.3f} (mean {statistics.fmean(mu):.3f})")
    sys.stdout.flush()


def parts(data: Path, name: str) -> None:
    """Print the per-part CPU µs of this checkout on ``name`` (see the module docstring, ``--parts``)."""
    import collections

    import numpy as np

    import dynslam2d.detect.mapevidence as me
    import dynslam2d.pipeline as pl
    import dynslam2d.slam.matcher as mt
    import dynslam2d.slam.processor as pr
    from dynslam2d.pipeline import Pipeline

    scans = load_scans(data, name)
    warm_up(scans, WARMUP)
    acc: collections.Counter = collections.Counter()

    from cputimers import thread_cpu_wrapper

    wrap = thread_cpu_wrapper(acc)

    wrap(me, "vacated_outlines_kernel", "vacated-footprint kernel")
    try:  # the pipeline's one-call trace (clearing geometry, trace and outlines; dynslam2d/vacated.py, view2 pass)
        import dynslam2d.vacated as va
    except ImportError:  # (a checkout before it)
        va = None
    if va is not None and hasattr(va, "vacated_scan_kernel"):
        wrap(va, "vacated_scan_kernel", "vacated-footprint kernel")
    # the matcher's kernels called from Python (slam/matcher.py): match_pyramid runs every level of the match and
    # the finest level's evaluation in one call (its _match_core / accumulate / fraction_below calls are inside
    # numba and cannot be wrapped); match_level is the per-level path (seeds, other point sets), accumulate /
    # fraction_below alone are evaluate / free_fraction outside match_pyramid
    wrap(mt, "match_pyramid", "match: match_pyramid kernel (all levels, _match_core, evaluation)")
    for k in ("match_level", "accumulate", "fraction_below", "_support_kernel", "_spread_kernel"):
        if hasattr(mt, k):
            wrap(mt, k, "match: other kernels (match_level, accumulate, fraction_below, support, spread)")
    for k in ("gated_points", "close_count"):  # imported by name into slam/processor.py
        if hasattr(pr, k):
            wrap(pr, k, "match: scan gating kernels (gated_points, close_count)")
    pipe = Pipeline()
    # the top-level parts of Pipeline.process (TOP); what process spends outside them is printed as "unattributed"
    wrap(pipe, "process", "process: whole")
    wrap(pipe.slam, "match", "match: whole")
    wrap(pipe.tracker, "update", "tracker: update")
    wrap(pipe, "_evidence_view", "tracker's map view (_evidence_view)")
    wrap(pipe, "_exclude", "exclusion (both calls)")
    wrap(pl, "_observed_rows", "observed boxes (_observed_rows)")
    wrap(pl, "_box_rows", "  box rows (_box_rows, inside _observed_rows)")
    wrap(pipe.slam, "update_map", "map: whole update")
    wrap(pipe.slam, "needs_map_update", "map: needs_map_update")
    # the front end's map only (the loop closer's submaps have their own): every level, its Python and ray kernel
    wrap(pipe.slam.map, "integrate", "map: MultiResMap.integrate")
    wrap(pipe.body, "mask", "body filter")
    wrap(pipe.body, "observe", "body filter")
    if pipe.ledger is not None:
        for k in ("before_update", "after_update", "observe", "erase_entering"):
            wrap(pipe.ledger, k, f"ledger: {k}")
    if pipe.loops is not None:
        wrap(pipe.loops, "add", "loops: add")
        for k, tag in (("_describe", "loops: place descriptor"), ("_search", "loops: searches")):
            if hasattr(pipe.loops, k):
                wrap(pipe.loops, k, tag)
    top = ("match: whole", "tracker: update", "tracker's map view (_evidence_view)", "exclusion (both calls)",
           "observed boxes (_observed_rows)", "map: whole update",
           "map: needs_map_update", "body filter", "loops: add") + tuple(
               f"ledger: {k}" for k in ("before_update", "after_update", "observe", "erase_entering"))
    rows, upd = [], []
    with scan_loop_gc():
        for s in scans:
            acc.clear()
            step = pipe.process(s)
            r = dict(acc)
            r["process: unattributed (whole minus the top-level parts)"] = r["process: whole"] - sum(
                r.get(k, 0) for k in top)
            rows.append(r)
            upd.append(bool(step.map_updated))
    u = np.array(upd)
    print(f"{name}: {len(scans)} scans, {int(u.sum())} update the map; CPU µs per scan (median / mean)")
    tags = sorted({k for r in rows for k in r})
    w = max(len(t) for t in tags)
    print(f"  {'part':<{w}} {'updating scans':>16} {'other scans':>16}")
    for tag in tags:
        v = np.array([r.get(tag, 0) / 1e3 for r in rows])
        cols = [f"{np.median(v[m]):7.0f} / {v[m].mean():6.0f}" if m.any() else "-" for m in (u, ~u)]
        print(f"  {tag:<{w}} {cols[0]:>16} {cols[1]:>16}")
    sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+",
                    help=f"{', '.join(sorted(INPUTS))}, ten-movers or another built-in scene (sim:NAME)")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=1, help="lockstep runs per input (pooled)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--parts", action="store_true", help="instead: per-part CPU of this checkout alone")
    ap.add_argument("--old-warmup", action="store_true",
                    help="the other side warms up as before pass neg71 (the kernels first called after the warm-up "
                         "load inside its measured run): with --other this checkout, what that costs")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    for name in args.inputs:
        if name not in INPUTS and not name.startswith("sim:") and name != "ten-movers":
            ap.error(f"unknown input {name!r}")
    if args.worker:
        worker(args.data, args.inputs[0], preload=not args.old_warmup)
        return
    for name in args.inputs:
        if args.parts:
            parts(args.data, name)
        else:
            compare(args.data, name, args.other, args.reps, args.old_warmup)


if __name__ == "__main__":
    main()
