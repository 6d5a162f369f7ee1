"""Where the loop closer's per-scan time goes on the real recordings, search by search (not run by pytest).

``bench_real_speed.py --loop-parts`` times the loop closer's methods; this script goes one step further, into
what a search is made of, over one fresh pipeline per input (after the throw-away warm-up, so that no numba
compile or cache load is timed), in thread CPU time:

  * the closer's methods (``add``, ``_search``, ``_far_search``, ``_match_at``, ``_submap``, ``_place_ranks``,
    ``_place_flush``, ``_optimise``, ``_uncertainty``, ``_verify_far``, ``_build_far_level``) and the kernels and
    helpers inside a search (``branch_and_bound``, ``_turn_first``, ``_score_pyramid``, ``_rotated_cells``,
    ``_percentile95``, ``_admissible``, ``refine_supported``, the place index's ``describe_many`` / ``add_many`` /
    ``distances``): calls, ms per call, µs per scan (nested parts are inside their callers' figures);
  * the correlative searches split into local and far ones (count, mean / median / max ms, how many returned a
    pose), the submap grids built (cache misses) against those found built, the far searches' outcome in
    ``_turn_first`` (status: 1 = refused, 2 = decided on the turn block, 0 = whole search; and the number of
    branch-and-bound passes) and how often ``_admissible`` let the search prune below ``min_score``.

    python benchmarks/bench_loop_searches.py [--only "negative_2 /right_scan" mit-csail ...] [--data ../shared/data]

``--trace N`` instead runs N whole ``pipeline.run`` calls in one process (after the same warm-up) and records every
scan: the thread CPU of ``Pipeline.process``, its stages (``StepResult.timings`` in thread CPU), the loop closer's
events inside it (far and local correlative searches, submap grids built, the place descriptors and ranks, the
optimisation, ...) and the collector's pauses (``gc.callbacks``); and after the scan loop the loop closure's finish
(final optimisation, re-match, second search), the renders and the map export. It prints where the gap between the
mean and the median scan goes: the map-updating scans against the others, each stage's mean, median and top 5 %,
each event's µs a scan, and which event or stage owns the top 5 % scans. The first run of the process also pays
what the 60 warm-up scans never reach (the first optimisation's import of ``scipy.sparse.linalg``, the graph
distances' and far search's kernels loaded from numba's cache), as ``bench_pipeline_ab.py`` and a command-line run
do; the second does not.

    taskset -c 1 python benchmarks/bench_loop_searches.py --trace 2 --only "negative_2 /right_scan"

The inputs are ``bench_real_speed.py``'s. Pin with ``taskset -c N``. The wrappers add ≈ 1 µs a call.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_real_speed as brs  # noqa: E402
from bench_pipeline import warm_up  # noqa: E402

#: the loop closer's methods timed (bound on the instance)
METHODS = ("add", "_search", "_far_search", "_match_at", "_submap", "_place_ranks", "_place_flush", "_optimise",
           "_uncertainty", "_verify_far", "_build_far_level")


def profile(name: str, scans: list) -> str:
    """One fresh pipeline over ``scans`` with thread-CPU timers around the loop closer's parts; the report."""
    import dynslam2d.slam.correlative as cm
    import dynslam2d.slam.loops as lm
    import dynslam2d.slam.placedesc as pm
    from dynslam2d.pipeline import Pipeline

    warm_up(scans)
    acc: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()
    saved: list[tuple[object, str, object]] = []

    def timed(f, key, after=None):  # noqa: ANN001, ANN202
        def g(*a, **k):  # noqa: ANN002, ANN003, ANN202
            t0 = time.thread_time_ns()
            r = f(*a, **k)
            dt = time.thread_time_ns() - t0
            acc[key] += dt
            calls[key] += 1
            if after is not None:
                after(dt, r, a, k)
            return r
        return g

    def wrap(obj: object, attr: str, after=None) -> None:  # noqa: ANN001
        saved.append((obj, attr, getattr(obj, attr)))
        setattr(obj, attr, timed(getattr(obj, attr), attr, after))

    searches: list[tuple[bool, float, bool]] = []  # (far, ms, pose returned)
    status: collections.Counter = collections.Counter()
    admissible: collections.Counter = collections.Counter()
    bb_calls = [0]
    wrap(lm, "correlative_search",
         lambda dt, r, a, k: searches.append((k.get("accept_turn") is not None, dt / 1e6, r is not None)))
    for f in ("_score_pyramid", "_rotated_cells", "_percentile95"):
        wrap(cm, f)
    wrap(cm, "branch_and_bound", lambda dt, r, a, k: bb_calls.__setitem__(0, bb_calls[0] + 1))
    wrap(cm, "_admissible", lambda dt, r, a, k: admissible.update([bool(r)]))
    tf = cm._turn_first
    saved.append((cm, "_turn_first", tf))

    def turn_first(*a):  # noqa: ANN002, ANN202
        n0 = bb_calls[0]
        t0 = time.thread_time_ns()
        r = tf(*a)
        acc["_turn_first"] += time.thread_time_ns() - t0
        calls["_turn_first"] += 1
        status[(int(r[0]), bb_calls[0] - n0)] += 1
        return r

    cm._turn_first = turn_first
    wrap(lm, "refine_supported")
    for f in ("describe_many", "add_many", "distances"):
        wrap(pm.PlaceIndex, f)
    built = collections.Counter()
    try:
        pipe = Pipeline()
        if pipe.loops is None:
            return f"\n== {name}: loop closure off =="
        lc = pipe.loops
        sub = lc._submap

        def submap(s: int):  # noqa: ANN202
            t0 = time.thread_time_ns()
            hit = s in lc._cache
            r = sub(s)
            built["found" if hit else "built"] += 1
            built["ms found" if hit else "ms built"] += (time.thread_time_ns() - t0) / 1e6
            return r

        lc._submap = submap
        for m in METHODS:
            if m != "_submap" and hasattr(lc, m):
                setattr(lc, m, timed(getattr(lc, m), m))
        per = []
        for s in scans:
            a0 = acc["add"]
            pipe.process(s)
            per.append((acc["add"] - a0) / 1e6)
    finally:
        for obj, attr, f in reversed(saved):
            setattr(obj, attr, f)
    v = np.array(per)
    n = len(scans)
    lines = [f"\n== {name}: loop closer, thread CPU; add ms/scan mean {v.mean():.3f} median {np.median(v):.3f} ==",
             f"{'part':<20} {'calls':>6} {'ms/call':>8} {'µs/scan':>8}"]
    for k, t in sorted(acc.items(), key=lambda kv: -kv[1]):
        lines.append(f"{k:<20} {calls[k]:>6} {t / 1e6 / calls[k]:>8.3f} {t / 1e3 / n:>8.1f}")
    for far in (False, True):
        sel = np.array([ms for f, ms, _ok in searches if f == far])
        if sel.size:
            ok = sum(1 for f, _ms, o in searches if f == far and o)
            lines.append(f"{'far' if far else 'local'} correlative searches: {sel.size}, ms mean {sel.mean():.3f} "
                         f"median {np.median(sel):.3f} max {sel.max():.2f}, µs/scan {sel.sum() * 1e3 / n:.1f}, "
                         f"pose returned {ok}")
    if built:
        lines.append(f"submap grids: built {built['built']} ({built['ms built']:.1f} ms), found built "
                     f"{built['found']} ({built['ms found']:.1f} ms)")
    if status:
        lines.append("far searches' _turn_first (status, branch-and-bound passes): count "
                     + ", ".join(f"{k}: {c}" for k, c in sorted(status.items())))
    if admissible:
        lines.append(f"_admissible (pruning below min_score allowed): {admissible[True]} yes, {admissible[False]} no")
    lines.append("closer stats (counts): " + ", ".join(f"{k} {val}"
                                              for k, val in lc.stats.items() if val and not k.endswith("_ms")))
    return "\n".join(lines)


#: the per-scan events ``trace`` times inside a scan (inclusive times; nested ones are inside their callers)
TRACE_METHODS = ("_far_search", "_search", "_place_ranks", "_place_flush", "_describe_many", "_optimise",
                 "_uncertainty", "_verify_far", "_build_far_level", "_pack_keyframes", "_chunk_poses", "_confirm")


def trace(name: str, data: Path) -> str:
    """One whole ``pipeline.run`` over input ``name`` (after the warm-up) with a per-scan record: thread CPU of
    ``Pipeline.process``, its stages, the loop closer's events in that scan, the collector's pauses; and the
    run's CPU outside ``process`` (reading the input, records, the loop closure's finish, the renders). The
    report splits the gap between the mean and the median scan by what owns it."""
    import gc
    import types

    import dynslam2d.pipeline as pl
    import dynslam2d.slam.loops as lm
    from dynslam2d.inputs import open_source

    rel, topic = brs.INPUTS[name]
    scans = brs.load(data, name)
    warm_up(scans)
    del scans
    ev: list[collections.Counter] = [collections.Counter()]  # the current scan's events (ns and counts)
    post: collections.Counter = collections.Counter()  # after the scan loop
    state = {"in_scan": False}
    saved: list[tuple[object, str, object]] = []

    def sink() -> collections.Counter:
        return ev[-1] if state["in_scan"] else post

    def wrap(obj: object, attr: str, key: str, before=None) -> None:  # noqa: ANN001
        f = getattr(obj, attr)
        saved.append((obj, attr, f))

        def g(*a, **k):  # noqa: ANN002, ANN003, ANN202
            t0 = time.thread_time_ns()
            try:
                return f(*a, **k)
            finally:
                c = sink()
                tag = key if before is None else before(a, k)
                c[tag] += time.thread_time_ns() - t0
                c["n " + tag] += 1
        setattr(obj, attr, g)

    # the correlative searches, far (an accept_turn) or local; the submap grids built (cache misses)
    wrap(lm, "correlative_search", "", lambda a, k: "far corr" if k.get("accept_turn") is not None else "local corr")
    wrap(lm, "rematch_keyframes", "rematch")
    wrap(lm, "run_second_search", "second search")
    for m in TRACE_METHODS:
        wrap(lm.LoopCloser, m, m)
    sub = lm.LoopCloser._submap
    saved.append((lm.LoopCloser, "_submap", sub))

    def submap(self, s):  # noqa: ANN001, ANN202
        hit = s in self._cache
        t0 = time.thread_time_ns()
        r = sub(self, s)
        if not hit:
            c = sink()
            c["grid build"] += time.thread_time_ns() - t0
            c["n grid build"] += 1
        return r
    lm.LoopCloser._submap = submap
    wrap(lm.LoopCloser, "finish", "finish")
    wrap(pl, "render_map", "render_map")
    wrap(pl, "render_written_map", "render_written_map")
    wrap(pl, "keep_optimised", "keep_optimised")
    wrap(pl._MapExport, "of", "map export")
    wrap(pl, "release_free_memory", "release_free_memory")
    per: list[tuple[float, dict, bool]] = []
    proc = pl.Pipeline.process
    saved.append((pl.Pipeline, "process", proc))

    def process(self, scan):  # noqa: ANN001, ANN202
        ev.append(collections.Counter())
        state["in_scan"] = True
        t0 = time.thread_time_ns()
        try:
            step = proc(self, scan)
        finally:
            state["in_scan"] = False
        per.append(((time.thread_time_ns() - t0) / 1e6, dict(step.timings), bool(step.map_updated)))
        return step
    pl.Pipeline.process = process
    gcs: list = [0, 0]

    def on_gc(phase: str, info: dict) -> None:
        if phase == "start":
            gcs[0] = time.thread_time_ns()
        else:
            c = sink()
            c[f"gc{info['generation']}"] += time.thread_time_ns() - gcs[0]
            c[f"n gc{info['generation']}"] += 1
    gc.callbacks.append(on_gc)
    saved_time = pl.time
    pl.time = types.SimpleNamespace(perf_counter=time.thread_time)  # stage timings in thread CPU
    try:
        c0 = time.thread_time_ns()
        res = pl.run(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
        run_cpu = (time.thread_time_ns() - c0) / 1e6
    finally:
        pl.time = saved_time
        gc.callbacks.remove(on_gc)
        for obj, attr, f in reversed(saved):
            setattr(obj, attr, f)
    evs = ev[1:]
    n = len(per)
    cpu = np.array([p[0] for p in per])
    med = float(np.median(cpu))
    gap = cpu.mean() - med
    lines = [f"\n== {name}: {n} scans; process CPU ms mean {cpu.mean():.3f} median {med:.3f} (gap {gap:.3f}) "
             f"p95 {np.percentile(cpu, 95):.3f} max {cpu.max():.2f}; whole run CPU {run_cpu:.0f} ms = "
             f"{run_cpu / n:.3f} ms/scan ({1e3 * n / run_cpu:.0f} scans/s of CPU), outside process "
             f"{(run_cpu - cpu.sum()) / n:.3f} ms/scan; wall {res.wall_time_s:.3f} s =="]
    upd = np.array([p[2] for p in per])
    lines.append(f"map-updating scans {int(upd.sum())}: median {np.median(cpu[upd]):.3f} mean {cpu[upd].mean():.3f};"
                 f" others {int((~upd).sum())}: median {np.median(cpu[~upd]):.3f} mean {cpu[~upd].mean():.3f}")
    lines.append(f"{'stage':<12}{'median':>8}{'mean':>8}{'mean-med':>9}  (ms/scan over all scans)")
    lines[-1] += "; median on map-updating / other scans; what the stage's top 5 % carry over its median"
    for k in per[0][1]:
        v = np.array([p[1].get(k, 0.0) for p in per])
        m = float(np.median(v))
        tail = np.sort(v)[::-1][: max(1, n // 20)]
        lines.append(f"{k:<12}{m:8.3f}{v.mean():8.3f}{v.mean() - m:9.3f}  {np.median(v[upd]):.3f} / "
                     f"{np.median(v[~upd]):.3f}; top 5 % {(tail - m).sum() / n:.3f} (≥ {tail[-1]:.2f} ms)")
    keys = sorted({k for e in evs for k in e if not k.startswith("n ")})
    lines.append(f"{'event in a scan':<22}{'scans':>6}{'calls':>7}{'ms/call':>9}{'µs/scan':>9}{'max ms':>8}")
    tot = {}
    for k in keys:
        v = np.array([e.get(k, 0) for e in evs]) / 1e6
        c = sum(e.get("n " + k, 0) for e in evs)
        tot[k] = v.sum() / n
        lines.append(f"{k:<22}{int((v > 0).sum()):>6}{c:>7}{v.sum() / max(c, 1):9.3f}{1e3 * v.sum() / n:9.1f}"
                     f"{v.max():8.2f}")
    lines.append("after the loop (ms; µs/scan): " + ", ".join(
        f"{k} {post[k] / 1e6:.1f} ({post[k] / 1e3 / n:.1f}, {post.get('n ' + k, 0)} calls)"
        for k in sorted(post) if not k.startswith("n ")))
    # the top 5 % scans by CPU: which owner (the largest of the loop closer's top events, the collector, or the
    # stage whose excess over its own median is the largest) and how much of the gap they carry
    top = np.argsort(cpu)[::-1][: max(1, n // 20)]
    owners: collections.Counter = collections.Counter()
    share: collections.Counter = collections.Counter()
    stage_med = {k: float(np.median([p[1].get(k, 0.0) for p in per])) for k in per[0][1] if k != "total"}
    outer = ("far corr", "local corr", "grid build", "_build_far_level", "_optimise", "_place_ranks",
             "_place_flush", "_describe_many", "_uncertainty", "gc0", "gc1", "gc2")
    for i in top:
        cand = {k: evs[i].get(k, 0) / 1e6 for k in outer}
        cand.update({"stage " + k: per[i][1].get(k, 0.0) - m for k, m in stage_med.items() if k != "loops"})
        own = max(cand, key=cand.get)
        owners[own] += 1
        share[own] += cpu[i] - med
    lines.append(f"top {len(top)} scans (≥ {cpu[top[-1]]:.2f} ms) carry {(cpu[top] - med).sum() / n:.3f} ms/scan of "
                 f"the gap; owners: " + ", ".join(f"{k} {c} ({share[k] / n:.3f})" for k, c in owners.most_common()))
    # what the mean would be without each event (its time taken out of the scans it ran in)
    lines.append("mean without: " + ", ".join(f"{k} −{tot[k]:.3f}" for k in sorted(tot, key=lambda x: -tot[x])[:10]))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=["negative_2 /left_scan", "negative_2 /rear_scan",
                                                   "negative_2 /right_scan", "mit-csail"])
    ap.add_argument("--data", type=Path, default=brs.REPO.parent / "shared" / "data")
    ap.add_argument("--trace", type=int, default=0, metavar="N",
                    help="N whole runs in one process with a per-scan trace each instead (trace(); the first run "
                         "loads the kernels the warm-up's scans do not reach)")
    args = ap.parse_args()
    for name in args.only:
        matches = [k for k in brs.INPUTS if k == name] or [k for k in brs.INPUTS if k.startswith(name)]
        for key in matches:
            scans = brs.load(args.data, key)
            if not scans:
                print(f"\n== {key}: input not found under {args.data}, skipped ==")
                continue
            if not args.trace:
                print(profile(key, scans), flush=True)
            for r in range(args.trace):
                print(f"\n-- run {r + 1} of {args.trace} in this process --" + trace(key, args.data), flush=True)


if __name__ == "__main__":
    main()
