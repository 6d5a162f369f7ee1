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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=["negative_2 /left_scan", "negative_2 /rear_scan",
                                                   "negative_2 /right_scan", "mit-csail"])
    ap.add_argument("--data", type=Path, default=brs.REPO.parent / "shared" / "data")
    args = ap.parse_args()
    for name in args.only:
        matches = [k for k in brs.INPUTS if k == name] or [k for k in brs.INPUTS if k.startswith(name)]
        for key in matches:
            scans = brs.load(args.data, key)
            if not scans:
                print(f"\n== {key}: input not found under {args.data}, skipped ==")
                continue
            print(profile(key, scans), flush=True)


if __name__ == "__main__":
    main()
