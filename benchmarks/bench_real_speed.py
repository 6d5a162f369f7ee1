"""Speed of the whole pipeline on the real recordings, per stage (not run by pytest).

Issue 9's speed target: ≥ 500 scans/s median for the whole pipeline on one core on the real bags
(``1000 / median total ms`` ≥ 500, i.e. a median of ≤ 2 ms per scan). Inputs (paths relative to
``--data``):

  * ``negative_2``  — ``leg_tracker/negative_2.bag``, each of ``/left_scan``, ``/rear_scan``,
    ``/right_scan`` (robot driving through an empty room: about a thousand clutter tracks per topic),
  * ``positive_7``  — ``leg_tracker/positive_7.bag`` (people walking near a motionless robot),
  * ``demo``        — ``leg_tracker/demo_stationary_simple_environment.bag``,
  * ``overtakes``   — ``datmo/overtakes.bag`` (RC cars, moving sensor),
  * ``sim:drive``   — the simulated corridor drive,
  * ``mit-csail``   — ``mit-csail/mit-csail.clf`` (a robot driving through an office building, laser only).

The scans are read into memory first, so only ``Pipeline.process`` is timed (no bag decoding), in a loop with
the collector setting of ``pipeline.run``'s (``bench_pipeline.scan_loop_gc``; none in a checkout before it). For
each input it reports

  * the first-call cost apart: the first ``process`` call of a throw-away pipeline in this process
    (numba compile, or numba cache load when the cache is warm; ``--cold`` points numba at an empty
    cache so that it is a full compile) and the slowest of its next 59 calls (kernels first run
    once tracks exist), excluded from every figure below;
  * per stage (match, track, filter, map_update, total; ``StepResult.timings``): the median and
    the 95th percentile of the per-scan wall time, ms, over ``--reps`` fresh pipelines (the median
    over the repetitions of each figure; the first scan, which only starts the map, left out);
  * scans/s = 1000 / median total;
  * cpu ms = thread CPU time of the whole loop per scan (less sensitive than wall time to other
    jobs on a shared machine; ``time.thread_time``); with ``--thread-time`` the per-stage figures
    are thread CPU time too.

    python benchmarks/bench_real_speed.py [--only negative_2 positive_7 ...] [--reps 3] [--cold]
        [--data ../shared/data] [--json out.json] [--thread-time] [--loop-parts]

``--loop-parts`` instead times the loop closer's parts (``LoopCloser.add`` and the searches, submap builds,
optimisation, place descriptors and graph distances inside it, and ``correlative_search``) in thread CPU time over
one fresh pipeline: calls, ms per call, mean µs per scan (MIT CSAIL: its spikes).

Pin to one core with ``taskset -c N`` for "one core". To compare two checkouts, run the script
alternately with ``PYTHONPATH=<checkout>/src`` and compare the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from bench_pipeline import scan_loop_gc, warm_up  # the same throw-away pipeline over the first scans; run's collector
from scratch import scratch_dir

STAGES = ("match", "track", "filter", "map_update", "loops", "total")
REPO = Path(__file__).resolve().parents[1]

#: name → (input relative to the data folder or sim:…, topic)
INPUTS: dict[str, tuple[str, str | None]] = {
    "negative_2 /left_scan": ("dynamic/leg_tracker/negative_2.bag", "/left_scan"),
    "negative_2 /rear_scan": ("dynamic/leg_tracker/negative_2.bag", "/rear_scan"),
    "negative_2 /right_scan": ("dynamic/leg_tracker/negative_2.bag", "/right_scan"),
    "positive_7": ("dynamic/leg_tracker/positive_7.bag", None),
    "positive_1": ("dynamic/leg_tracker/positive_1.bag", None),
    "demo_stationary": ("dynamic/leg_tracker/demo_stationary_simple_environment.bag", None),
    "overtakes": ("dynamic/datmo/overtakes.bag", None),
    "two_robots": ("dynamic/datmo/two_robots.bag", None),
    "sim:drive": ("sim:drive", None),
    "mit-csail": ("mit-csail/mit-csail.clf", None),
}


def load(data: Path, name: str) -> list:
    """The scans of input ``name`` in memory (None when the file is absent)."""
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS[name]
    path = rel if rel.startswith("sim:") else str(data / rel)
    if not rel.startswith("sim:") and not Path(path).exists():
        return []
    return list(open_source(path, topic))


def one_run(scans: list) -> dict[str, float]:
    """One fresh pipeline over ``scans``: median / p95 per stage (ms, first scan left out), CPU ms per scan."""
    from dynslam2d.pipeline import Pipeline

    pipe = Pipeline()
    per: dict[str, list[float]] = {k: [] for k in STAGES}
    c0 = time.thread_time()
    with scan_loop_gc():  # the collector setting of pipeline.run's loop (a checkout without it: none)
        for i, s in enumerate(scans):
            step = pipe.process(s)
            if i:
                for k in STAGES:
                    per[k].append(step.timings[k])
    cpu = (time.thread_time() - c0) * 1e3 / len(scans)
    out = {"cpu_ms": cpu, "tracks_born": float(pipe.tracker.stats.tracks_born)}
    for k, v in per.items():
        out[f"{k}_median"] = float(np.median(v))
        out[f"{k}_p95"] = float(np.percentile(v, 95))
    return out


def bench(name: str, scans: list, reps: int) -> dict[str, object]:
    first_ms, warm_max_ms = warm_up(scans)
    runs = [one_run(scans) for _ in range(reps)]
    fig = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
    return {"input": name, "scans": len(scans), "beams": scans[0].n_beams, "first_ms": first_ms,
            "warm_max_ms": warm_max_ms, "reps": reps, **fig, "scans_per_s": 1e3 / fig["total_median"]}


def report(r: dict[str, object]) -> str:
    lines = [f"\n== {r['input']}: {r['scans']} scans, {r['beams']} beams, {r['tracks_born']:.0f} tracks born; "
             f"median of {r['reps']} runs ==",
             f"first process() call {r['first_ms']:.0f} ms, slowest of the next 59 {r['warm_max_ms']:.1f} ms "
             "(numba compile or cache load; not in the figures below)",
             f"{'stage':<11} {'median ms':>10} {'p95 ms':>9}"]
    for k in STAGES:
        lines.append(f"{k:<11} {r[f'{k}_median']:>10.3f} {r[f'{k}_p95']:>9.3f}")
    lines.append(f"scans/s: {r['scans_per_s']:.0f} (1000 / median total); CPU {r['cpu_ms']:.3f} ms per scan")
    return "\n".join(lines)


#: the loop closer's methods (and module function) timed by ``--loop-parts``
LOOP_PARTS = ("add", "_search", "_far_search", "_match_at", "_submap", "_optimise", "_place_ranks", "_describe",
              "_uncertainty")


def loop_parts(name: str, scans: list) -> str:
    """One fresh pipeline over ``scans`` after the warm-up with thread-CPU timers around the loop closer's parts:
    calls, ms per call and mean µs per scan of each (nested parts are inside their callers' figures)."""
    import collections

    import dynslam2d.slam.loops as loops_module
    from dynslam2d.pipeline import Pipeline

    warm_up(scans)
    acc: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()

    def wrap(obj: object, attr: str) -> None:
        f = getattr(obj, attr)

        def timed(*a, **k):
            t0 = time.thread_time_ns()
            try:
                return f(*a, **k)
            finally:
                acc[attr] += time.thread_time_ns() - t0
                calls[attr] += 1

        setattr(obj, attr, timed)

    saved = loops_module.correlative_search
    wrap(loops_module, "correlative_search")
    try:
        pipe = Pipeline()
        if pipe.loops is None:
            return f"\n== {name}: loop closure off =="
        for k in LOOP_PARTS:
            if hasattr(pipe.loops, k):
                wrap(pipe.loops, k)
        per = []
        for s in scans:
            a0 = acc["add"]
            pipe.process(s)
            per.append((acc["add"] - a0) / 1e6)
    finally:
        loops_module.correlative_search = saved
    v = np.array(per)
    lines = [f"\n== {name}: loop closer, thread CPU; add ms/scan mean {v.mean():.3f} median {np.median(v):.3f} "
             f"p95 {np.percentile(v, 95):.3f} max {v.max():.1f}; scans over 2 ms: {int((v > 2).sum())} ==",
             f"{'part':<20} {'calls':>6} {'ms/call':>8} {'µs/scan':>8}"]
    for k, t in sorted(acc.items(), key=lambda kv: -kv[1]):
        lines.append(f"{k:<20} {calls[k]:>6} {t / 1e6 / calls[k]:>8.3f} {t / 1e3 / len(scans):>8.1f}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="+", default=None,
                    help="inputs whose name contains one of these (default: all)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="empty numba cache: the first call is a full compile")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    ap.add_argument("--thread-time", action="store_true",
                    help="per-stage figures in thread CPU time instead of wall time (the pipeline's stage clock "
                         "becomes time.thread_time: less sensitive to other jobs on a shared machine)")
    ap.add_argument("--loop-parts", action="store_true",
                    help="instead: thread CPU of the loop closer's parts (searches, submaps, optimisation, place "
                         "descriptors) per call and per scan")
    args = ap.parse_args()
    if args.thread_time:
        import types

        import dynslam2d.pipeline as pipeline_module

        pipeline_module.time = types.SimpleNamespace(perf_counter=time.thread_time)
    if args.cold:
        os.environ["NUMBA_CACHE_DIR"] = scratch_dir("numba-cold-")
    names = [n for n in INPUTS if args.only is None or any(o in n for o in args.only)]
    results = []
    for name in names:
        scans = load(args.data, name)
        if not scans:
            print(f"\n== {name}: input not found under {args.data}, skipped ==")
            continue
        if args.loop_parts:
            print(loop_parts(name, scans))
            continue
        r = bench(name, scans, args.reps)
        results.append(r)
        print(report(r))
        sys.stdout.flush()
    if results:
        print(f"\n{'input':<24} {'total ms':>9} {'p95':>7} {'track':>7} {'match':>7} {'map':>7} {'cpu ms':>7} "
              f"{'scans/s':>8}")
        for r in results:
            print(f"{r['input']:<24} {r['total_median']:>9.3f} {r['total_p95']:>7.3f} {r['track_median']:>7.3f} "
                  f"{r['match_median']:>7.3f} {r['map_update_median']:>7.3f} {r['cpu_ms']:>7.3f} "
                  f"{r['scans_per_s']:>8.0f}")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
