"""Matcher and evidence-ledger CPU time of two checkouts on the same inputs, inside one process (not run by pytest).

Whole runs on a shared machine vary by ±25 % between runs of the same code; this compares the two versions of a
component on identical calls, alternately, in thread CPU time (``time.thread_time_ns``):

  * ``matcher``: ``match_multires`` calls of this checkout's pipeline (its refines through ``match_fit_at`` too;
    scans 50–260, their map levels copied) are replayed through the other checkout's ``slam/matcher.py`` and this
    one's, 5 times each, the versions alternately; prints µs per call (median of the 5 sweeps) and whether every
    result is identical;
  * ``ledger``: the pipeline's ``EvidenceLedger`` (this checkout) and one of the other checkout's
    ``slam/erasure.py`` get the same ``observe`` / ``before_update`` / ``after_update`` calls in lockstep (the
    other ledger's erasure acts on a copy of the map), each method's two versions alternately; prints ms per
    scan per method and checks the two ledgers' summaries are equal;
  * ``map``: the pipeline's ``MultiResMap.integrate`` calls (its map updates) replayed into a fresh map of the
    other checkout's ``slam/grid.py`` with its ``slam/raycast.py`` kernels and of this one's, 5 times each,
    alternately; prints ms per call (median
    of the 5 sweeps) and whether the two maps are identical.

Each part's first run of this checkout's pipeline (the recording, or for ``ledger`` a throw-away lockstep over the
first 60 scans) and a first call of each version warm the kernels; then every kernel numba's cache holds, either
side's, and the modules a run imports late are loaded (``kernelwarm.preload``), and the kernels loaded or compiled
inside the measured runs are printed per part (0 when the warm-up did its work).

    python benchmarks/bench_slam_ab.py "negative_2 /right_scan" mit-csail [--part matcher ledger map]
        [--other ../main/src] [--scans N]

Inputs: the names of ``bench_real_speed.py`` or a built-in scene (``sim:paper``). Pin to one core with
``taskset -c N``.
"""

from __future__ import annotations

import argparse
import collections
import copy
import importlib.util
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from bench_real_speed import INPUTS, load
from kernelwarm import kernel_cache_calls, preload

REPO = Path(__file__).resolve().parents[1]


def other_module(src: Path, rel: str, name: str):
    """The other checkout's module ``rel`` as a module of its own (its imports resolve to this checkout)."""
    spec = importlib.util.spec_from_file_location(name, src / "dynslam2d" / rel)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def matcher_ab(scans: list, other) -> tuple[float, float, bool, int]:
    """(other µs per call, this µs per call, identical results, kernels loaded or compiled while timed) of
    match_multires (module docstring)."""
    import dynslam2d.slam.matcher as this
    import dynslam2d.slam.processor as proc
    from dynslam2d.pipeline import Pipeline

    p = Pipeline()
    calls = []
    f = proc.match_multires

    def keep(levels, a):
        if 50 < p.slam.n_scans <= 260:
            lv_copy = [copy.copy(lv) for lv in levels]
            for lv in lv_copy:
                lv.prob = lv.prob.copy()
            calls.append((lv_copy, a))  # (replayed without the keyword outputs ``fit`` / ``free_thresh``)

    def grab(levels, *a, **k):
        keep(levels, a)
        return f(levels, *a, **k)

    f_at = getattr(proc, "match_fit_at", None)  # (the processor's refine: match_multires from the start's floats)

    def grab_at(levels, pts, sx, sy, sth, *a):
        keep(levels, (pts, np.array([sx, sy, sth]), *a[:8], *a[12:14]))  # (as match_multires' positional call)
        return f_at(levels, pts, sx, sy, sth, *a)

    proc.match_multires = grab
    if f_at is not None:
        proc.match_fit_at = grab_at
    try:
        for s in scans[:261]:
            p.process(s)
    finally:
        proc.match_multires = f
        if f_at is not None:
            proc.match_fit_at = f_at
    same = all(np.array_equal(other.match_multires(lv, *a), this.match_multires(lv, *a), equal_nan=True)
               for lv, a in calls)  # (also the warm-up of both versions)
    preload(extra=(other,))
    looked = kernel_cache_calls(extra=(other,))
    sweeps: dict[str, list[int]] = {"other": [], "this": []}
    for r in range(5):
        for tag, mod in (("other", other), ("this", this)) if r % 2 == 0 else (("this", this), ("other", other)):
            t0 = time.thread_time_ns()
            for lv, a in calls:
                mod.match_multires(lv, *a)
            sweeps[tag].append(time.thread_time_ns() - t0)
    n = max(len(calls), 1)
    return (statistics.median(sweeps["other"]) / n / 1e3, statistics.median(sweeps["this"]) / n / 1e3, same,
            kernel_cache_calls(extra=(other,)) - looked)


def ledger_ab(scans: list, other, warm: int = 60) -> tuple[dict[str, tuple[float, float]], int]:
    """{method: (other ms per scan, this ms per scan)} of the evidence ledger (module docstring), after a throw-away
    lockstep over the first ``warm`` scans (then :func:`kernelwarm.preload`); and the kernels loaded or compiled in
    the measured lockstep."""
    if warm:
        ledger_ab(scans[:warm], other, 0)
        preload(extra=(other, getattr(other, "_lk", other)))
    looked = kernel_cache_calls(extra=(other, getattr(other, "_lk", other)))
    from dynslam2d.pipeline import Pipeline

    p = Pipeline()
    this_l = p.ledger
    other_l = other.EvidenceLedger(this_l.config, this_l.laser_min_dist, this_l.laser_max_dist,
                                   keep_beams=this_l.keep_beams)
    acc: collections.Counter = collections.Counter()
    turn: collections.Counter = collections.Counter()
    pending: dict[str, object] = {}

    def pair(meth: str) -> None:
        f_this, f_other = getattr(this_l, meth), getattr(other_l, meth)

        def call(*a):
            turn[meth] += 1
            a_other = list(a)
            if meth == "erase_entering":
                a_other[-1] = copy.deepcopy(a[-1])
            if meth == "after_update":
                a_other[0] = pending["other"]
            order = [("other", f_other, a_other), ("this", f_this, list(a))]
            if turn[meth] % 2:
                order.reverse()
            res = {}
            for tag, fn, args in order:
                t0 = time.thread_time_ns()
                res[tag] = fn(*args)
                acc[(meth, tag)] += time.thread_time_ns() - t0
            if meth == "before_update":
                pending["other"] = res["other"]
            return res["this"]

        setattr(this_l, meth, call)

    for m in ("observe", "erase_entering", "before_update", "after_update"):
        pair(m)
    for s in scans:
        p.process(s)
    if other_l.summary() != this_l.summary():
        raise SystemExit(f"ledger summaries differ: {other_l.summary()} vs {this_l.summary()}")
    n = len(scans)
    # (erase_entering is left out: the other ledger's copy of the map makes its timing unfair)
    return ({m: (acc[(m, "other")] / n / 1e6, acc[(m, "this")] / n / 1e6)
             for m in ("before_update", "after_update", "observe")},
            kernel_cache_calls(extra=(other, getattr(other, "_lk", other))) - looked)


def map_ab(scans: list, other) -> tuple[float, float, bool, int]:
    """(other, this) ms per ``MultiResMap.integrate`` call of the pipeline's map updates, replayed 5 times into
    a fresh map of each version, the versions alternately (after one untimed replay of each, the warm-up); whether
    every level of the two maps is equal; the kernels loaded or compiled in the timed replays."""
    from dynslam2d.pipeline import Pipeline
    from dynslam2d.slam import grid

    p = Pipeline()
    calls = []
    orig = grid.MultiResMap.integrate

    def grab(self, pose, hits, clear=None):
        if self is p.slam.map:
            calls.append((pose, np.array(hits), None if clear is None else np.array(clear)))
        return orig(self, pose, hits, clear)

    grid.MultiResMap.integrate = grab
    try:
        for s in scans:
            p.process(s)
    finally:
        grid.MultiResMap.integrate = orig
    c = p.slam.config

    def fresh(mod):
        return mod.MultiResMap(c.map_resolution, c.map_levels, c.logodds_free, c.logodds_occupied,
                               c.occupied_logodds_cap, c.map_growth_margin, int(c.max_map_memory_mb * 1e6),
                               c.grazing_stop_cells, c.grazing_min_incidence_deg)

    for mod in (other, grid):  # (the warm-up: each version's kernels compiled or loaded, first calls made)
        m = fresh(mod)
        for pose, hits, clear in calls:
            m.integrate(pose, hits, clear)
    del m
    preload(extra=(other,))
    looked = kernel_cache_calls(extra=(other,))
    sweeps: dict[str, list[float]] = {"other": [], "this": []}
    maps = {}
    for rep in range(5):
        for tag, mod in ((("other", other), ("this", grid)) if rep % 2 == 0 else (("this", grid), ("other", other))):
            m, t = fresh(mod), 0
            for pose, hits, clear in calls:
                t0 = time.thread_time_ns()
                m.integrate(pose, hits, clear)
                t += time.thread_time_ns() - t0
            sweeps[tag].append(t / max(len(calls), 1) / 1e6)
            maps[tag] = m
    same = all(np.array_equal(a.logodds, b.logodds) and np.array_equal(a.prob, b.prob)
               and np.array_equal(a.uidx, b.uidx) for a, b in zip(maps["other"].levels, maps["this"].levels))
    return (statistics.median(sweeps["other"]), statistics.median(sweeps["this"]), same,
            kernel_cache_calls(extra=(other,)) - looked)


def ratio(a: float, b: float) -> str:
    """``×b/a``, or "no calls" where there were none."""
    return f"×{b / a:.2f}" if a else "no calls"


def load_input(data: Path, name: str, limit: int | None) -> list:
    """The first ``limit`` scans (all where None) of a ``bench_real_speed`` input or a built-in scene."""
    if name in INPUTS:
        return load(data, name)[:limit]
    from dynslam2d.inputs import open_source

    return list(open_source(name, None))[:limit]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:paper)")
    ap.add_argument("--part", nargs="+", choices=("matcher", "ledger", "map"),
                    default=["matcher", "ledger", "map"])
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--scans", type=int, default=None, help="only the first N scans of each input")
    args = ap.parse_args()
    bad = [n for n in args.inputs if n not in INPUTS and not n.startswith("sim:")]
    if bad:
        ap.error(f"unknown inputs {bad}; accepted: {', '.join(sorted(INPUTS))} or sim:<scene>")
    for name in args.inputs:
        scans = load_input(args.data, name, args.scans)
        if not scans:
            print(f"{name}: input not found under {args.data}, skipped")
            continue
        if "matcher" in args.part:
            mo, mt, same, loads = matcher_ab(scans, other_module(args.other, "slam/matcher.py", "other_matcher"))
            print(f"{name}: match_multires µs per call, other {mo:.0f}, this {mt:.0f} ({ratio(mo, mt)}); "
                  f"results {'identical' if same else 'DIFFERENT'}; inside the measured runs kernels loaded or "
                  f"compiled: {loads}")
        if "ledger" in args.part:
            other_erasure = other_module(args.other, "slam/erasure.py", "other_erasure")
            if hasattr(other_erasure, "_lk"):  # (its own kernels: the two checkouts' kernels may differ in arguments)
                other_erasure._lk = other_module(args.other, "slam/ledgerkernels.py", "other_ledgerkernels")
            parts, loads = ledger_ab(scans, other_erasure)
            o, t = sum(v[0] for v in parts.values()), sum(v[1] for v in parts.values())
            detail = ", ".join(f"{m} {a:.3f} → {b:.3f}" for m, (a, b) in parts.items())
            print(f"{name}: ledger ms per scan other → this: {o:.3f} → {t:.3f} ({ratio(o, t)}); {detail}; "
                  f"summaries equal; inside the measured runs kernels loaded or compiled: {loads}")
        if "map" in args.part:
            other_grid = other_module(args.other, "slam/grid.py", "other_grid")
            other_rays = other_module(args.other, "slam/raycast.py", "other_raycast")
            for k in ("integrate_levels", "integrate_rays", "integrate_rays_stop"):  # (the other checkout's kernels)
                setattr(other_grid, k, getattr(other_rays, k))
            mo, mt, same, loads = map_ab(scans, other_grid)
            print(f"{name}: MultiResMap.integrate ms per map update, other {mo:.3f}, this {mt:.3f} ({ratio(mo, mt)}); "
                  f"maps {'identical' if same else 'DIFFERENT'}; inside the measured runs kernels loaded or compiled: "
                  f"{loads}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
