"""How much of the filter stage is the first read of the tracker's reports, and how much its figure depends on what
the track stage did just before it (not run by pytest; pass cln147).

The filter stage read ×1.01–1.16 slower in two releases whose track stage got faster. Three measurements, all in
thread CPU (``time.thread_time``; the pipeline's stage clock replaced by it), in one process:

1. Track objects built: every ``TrackReports._build_many`` call during ``Pipeline.process``, by caller (a lazily built
   report read first by the filter stage would be counted here).
2. First read vs second read: the filter stage's report readers (``moving_index``, ``mover_pack``) and its kernel
   (``mover_exclusions``) each called twice in a row on the same scan, the first result used: "first − second" is
   what their first touch costs above a warm re-read (cold caches and branch predictors, or work done lazily).
3. Neighbour: pipelines in lockstep (scan by scan, the order alternating), identical except for what runs at the end
   of the track stage (inside its timing window): nothing (``plain``); the filter's two report readers (``reports``:
   what "build eagerly what the filter needs" would move into the track stage); a touch of the scan's ranges and
   trig tables (``scan``); a pure-Python spin of ≈ 100 µs (``spin``); a sweep over 8 MiB (``sweep``: the caches
   evicted). The filter stage's own code and data are the same in all of them.

    taskset -c 0 python benchmarks/bench_filter_neighbour.py ten-movers negative_2/right

Inputs: ``scenes.input_scans`` names (``ten-movers``, ``sim:NAME``, the recordings of ``bench_digest.py`` under
``--data``).
"""

from __future__ import annotations

import argparse
import collections
import statistics
import sys
import time
import types
from pathlib import Path

import numpy as np
from bench_pipeline import scan_loop_gc, warm_up
from scenes import input_scans

MODES = ("plain", "reports", "scan", "spin", "sweep")
STAGES = ("track", "filter", "map_update", "total")


def _med(v: list[float]) -> float:
    return statistics.median(v) if v else float("nan")


def install(P: types.ModuleType, TR: types.ModuleType, Tracker: type, state: dict) -> None:
    """Wrap the readers, the kernel and ``Tracker.update`` (each wrapper does its extra work only when ``state``
    asks)."""
    P.time = types.SimpleNamespace(perf_counter=time.thread_time)  # (the stage timings in thread CPU)
    builds = state["builds"]
    twice = state["twice"]
    build_many = TR.TrackReports._build_many

    def counted(self, idx):  # type: ignore[no-untyped-def]
        builds[sys._getframe(1).f_code.co_name] += len(idx)
        return build_many(self, idx)

    TR.TrackReports._build_many = counted

    def read_twice(obj: object, attr: str, tag: str) -> None:
        f = getattr(obj, attr)

        def w(*a, **k):  # type: ignore[no-untyped-def]
            if not state["twice_on"]:
                return f(*a, **k)
            t0 = time.thread_time_ns()
            r = f(*a, **k)
            t1 = time.thread_time_ns()
            f(*a, **k)
            t2 = time.thread_time_ns()
            twice[tag].append((t1 - t0, t2 - t1))
            return r

        setattr(obj, attr, w)

    read_twice(TR.TrackReports, "moving_index", "moving_index (reports)")
    read_twice(TR.TrackReports, "mover_pack", "mover_pack (reports)")
    read_twice(P, "mover_exclusions", "mover_exclusions (kernel)")
    update = Tracker.update
    big = np.ones(1 << 20)

    def tail(self, scan, *a, **k):  # type: ignore[no-untyped-def]
        r = update(self, scan, *a, **k)
        m = state["mode"]
        if m == "reports" and isinstance(r, TR.TrackReports):
            moving = r.moving_index()
            if moving:
                r.mover_pack(moving)
        elif m == "scan":
            with np.errstate(invalid="ignore"):  # (inf ranges: no return)
                scan.ranges.sum()
            c, s = scan.trig()
            c.sum()
            s.sum()
        elif m == "spin":
            x = 0
            for i in range(3000):
                x += i
        elif m == "sweep":
            big.sum()
        return r

    Tracker.update = tail


def measure(name: str, scans: list, P: types.ModuleType, state: dict) -> None:
    warm_up(scans)
    state["builds"].clear()
    state["twice"].clear()
    pipes = {m: P.Pipeline() for m in ("twice", *MODES)}
    got = {m: {k: [] for k in STAGES} for m in MODES}
    order = list(pipes)
    with scan_loop_gc():
        for i, s in enumerate(scans):
            for m in (order if i % 2 == 0 else order[::-1]):
                state["twice_on"] = m == "twice"
                state["mode"] = m
                r = pipes[m].process(s)
                if i and m in got:
                    for k in STAGES:
                        got[m][k].append(r.timings[k] * 1e3)
    state["twice_on"], state["mode"] = False, "plain"
    print(f"\n== {name}: {len(scans)} scans; thread CPU medians, µs")
    built = dict(state["builds"]) or "none"
    print(f"Track objects built during process (all pipelines), by caller: {built}")
    n = len(scans)
    for tag, pairs in state["twice"].items():
        first = [a / 1e3 for a, _ in pairs]
        second = [b / 1e3 for _, b in pairs]
        diff = [a - b for a, b in zip(first, second)]
        print(f"  {tag:27s} calls {len(pairs):4d}  first {_med(first):7.2f}  second {_med(second):7.2f}  "
              f"first − second: median {_med(diff):6.2f}, per scan {sum(diff) / n:6.2f}")
    base = got["plain"]
    for m, d in got.items():
        tf = [a + b for a, b in zip(d["track"], d["filter"])]
        tf0 = [a + b for a, b in zip(base["track"], base["filter"])]
        print(f"  {m:7s} " + "  ".join(f"{k} {_med(v):8.2f}" for k, v in d.items())
              + f"  track+filter {_med(tf):8.2f}   filter ×{_med(d['filter']) / _med(base['filter']):.3f}  "
              f"track+filter ×{_med(tf) / _med(tf0):.3f}  total ×{_med(d['total']) / _med(base['total']):.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--scans", type=int, default=None, help="only the first N scans of each input")
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = ap.parse_args()
    import dynslam2d.detect.trackreport as TR
    import dynslam2d.pipeline as P
    from dynslam2d.detect.tracker import Tracker

    state = {"builds": collections.Counter(), "twice": collections.defaultdict(list), "twice_on": False,
             "mode": "plain"}
    install(P, TR, Tracker, state)
    for name in args.inputs:
        measure(name, input_scans(args.data, name)[:args.scans], P, state)


if __name__ == "__main__":
    main()
