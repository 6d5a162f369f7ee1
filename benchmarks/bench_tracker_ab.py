"""Tracker CPU time of two checkouts on the same scans, and where a pipeline step's CPU time goes (not run by pytest).

On a shared machine the wall time of a whole run varies by a factor of 2-5 between runs of the same code; this
compares ``Tracker.update`` of this checkout with that of another one (``--other``, e.g. the main worktree)
inside one process, on the same tracker states:

  * both pipelines (one with each checkout's ``detect/tracker.py``; the rest of the code is this checkout's) run
    over the first ``--end`` scans of an input in lockstep; before each scan from ``--start`` on, each tracker is
    snapshotted (deep copy) with that scan's arguments (scan, pose, map view, body beams);
  * each snapshot's ``update`` is timed ``--reps`` times on a fresh copy, the two checkouts alternately, in
    thread CPU time (``time.thread_time_ns``); the per-scan minimum over the repetitions is kept;
  * printed: the mean over the scans of those minima for each checkout (µs per scan), their ratio, and the
    median of the per-scan ratios.

``--stages`` instead prints the thread CPU time of one plain run per pipeline component (tracker, SLAM
match, map update, evidence ledger, body filter, exclusion), ms per scan and share of the step.

``--split`` prints how much of ``Tracker.update``'s CPU time is spent in functions of other modules that it
calls (segmentation, shape fits, classification, map evidence, free-space memory, the association / Kalman
kernels) and how much in ``detect/tracker.py``'s own Python, µs per scan.

``--pipeline`` runs two whole pipelines (one with each checkout's tracker) over every scan in lockstep, timing each
``Pipeline.process`` call in thread CPU time, the two alternately first: the median CPU ms per scan of each and their
ratio — the figure bench_real.py's ms/scan (a wall-time median) gives on a quiet machine, robust to other load.

``--phases`` runs the two whole pipelines in lockstep as ``--pipeline`` does and splits each ``Tracker.update`` into
its steps (prediction, detection, association, vacated space, Kalman / shape updates, management and the test of M,
fragments, the clutter test of unused detections, births, reports; the rest of ``update`` apart; :data:`_PHASES`):
for each checkout the median over the scans of the thread CPU µs of each step, inclusive (the timers add about 1 µs
per timed call); the methods called inside those steps (:data:`_NESTED`: the leg merge, the merged-detection veto,
the Kalman bookkeeping, the acceleration bound, the dynamic test, the riding test, the free-space entries read late)
as their mean over the scans (several run on few scans), each inside the step that calls it.

``--check`` runs both checkouts' trackers over every scan of an input in lockstep and compares their reports
exactly (every field of every track, floats and arrays bit for bit, the stats and the removed beams): a
speed change of the tracker must print "reports identical".

    python benchmarks/bench_tracker_ab.py negative_2/right positive_7 [--other ../main/src] [--reps 5]
        [--start 150 --end 210] [--stages | --split | --check | --pipeline | --phases]

Pin to one core with ``taskset -c N``. Inputs: every name of ``bench_digest.INPUTS`` (``negative_2/left|rear|right``,
``positive_7``, ``positive_1``, ``demo``, ``overtakes``, ``mit-csail``, ``sim:drive|crowd|stop-and-go|corridor``;
recorded files under ``--data``); an unknown name stops with the list of accepted ones.
"""

from __future__ import annotations

import argparse
import collections
import copy
import importlib
import importlib.abc
import importlib.util
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS as _ALL_INPUTS  # noqa: E402  (the inputs the digest checks)
from bench_pipeline import warm_up  # noqa: E402
from kernelwarm import preload  # noqa: E402

#: name → (input relative to the data folder or sim:…, topic): every input the digest knows
INPUTS: dict[str, tuple[str, str | None]] = dict(_ALL_INPUTS)


def check_inputs(ap: argparse.ArgumentParser, names: list[str]) -> None:
    """Stop (``ap.error``, exit status 2) if a name is not in :data:`INPUTS`, listing the accepted names."""
    bad = [n for n in names if n not in INPUTS and n != "ten-movers"]
    if bad:
        ap.error(f"unknown input{'s' if len(bad) > 1 else ''} {', '.join(map(repr, bad))}; "
                 f"accepted: {', '.join(INPUTS)}")


def load_scans(data: Path, name: str) -> list:
    """The scans of input ``name`` (:data:`INPUTS`, or ``ten-movers``: scenes.input_scans)."""
    from scenes import input_scans

    return input_scans(data, name)


#: the tracker's modules: ``detect/tracker.py`` and the step modules it was split into (pass trktable); a name a
#: checkout lacks is skipped
TRACKER_MODULES = ("tracker", "trackdetect", "trackupdate", "trackmanage", "trackreport", "tracktable")


def tracker_modules() -> list:
    """This checkout's tracker modules (:data:`TRACKER_MODULES` that exist), imported."""
    out = []
    for n in TRACKER_MODULES:
        try:
            out.append(importlib.import_module(f"dynslam2d.detect.{n}"))
        except ModuleNotFoundError:
            pass
    return out


#: the tracker's kernel modules, loaded from the other checkout with its tracker (a kernel's signature may differ
#: between the checkouts: pass trk26 folded the windows' push into ``kernels.shape_update``)
TRACKER_KERNEL_MODULES = ("kernels", "kernels_update", "kernels_assign")


class _OtherParts(importlib.abc.MetaPathFinder):
    """Finds ``dynslam2d.detect.track*`` (other than ``tracker``) and the tracker's kernel modules in the other
    checkout while its tracker loads."""

    def __init__(self, folder: Path, names: set[str]) -> None:
        self.folder, self.names = folder, names

    def find_spec(self, name, path=None, target=None):
        pkg, _, stem = name.rpartition(".")
        if pkg == "dynslam2d.detect" and stem in self.names:
            return importlib.util.spec_from_file_location(name, self.folder / f"{stem}.py")
        return None


def other_tracker_module(src: Path):
    """The other checkout's ``dynslam2d/detect/tracker.py`` as a module of its own, with the other checkout's step
    modules ``detect/track*.py`` if it has them (pass trktable split the tracker) and its tracker kernel modules
    (:data:`TRACKER_KERNEL_MODULES`, as the tracker's modules import them); every other import resolves to this
    checkout. This checkout's modules stay what ``dynslam2d.detect.*`` names afterwards."""
    import dynslam2d.detect as pkg

    folder = src / "dynslam2d" / "detect"
    parts = ({p.stem for p in folder.glob("track*.py")} - {"tracker"}) | {
        n for n in TRACKER_KERNEL_MODULES if (folder / f"{n}.py").exists()}
    full = [f"dynslam2d.detect.{n}" for n in parts]
    saved = {n: sys.modules.pop(n) for n in full if n in sys.modules}
    attrs = {n: getattr(pkg, n) for n in parts if hasattr(pkg, n)}
    finder = _OtherParts(folder, parts)
    sys.meta_path.insert(0, finder)
    try:
        spec = importlib.util.spec_from_file_location("other_tracker", folder / "tracker.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules["other_tracker"] = mod
        spec.loader.exec_module(mod)
    finally:
        sys.meta_path.remove(finder)
        for n in full:
            sys.modules.pop(n, None)
        sys.modules.update(saved)
        for n in parts:
            if n in attrs:
                setattr(pkg, n, attrs[n])
            elif hasattr(pkg, n):
                delattr(pkg, n)
    return mod


def ab(scans: list, other, reps: int, start: int, end: int) -> tuple[float, float, float]:
    """(other µs/scan, this µs/scan, median per-scan ratio this / other) of Tracker.update (see the docstring)."""
    from dynslam2d.detect import tracker as this
    from dynslam2d.pipeline import Pipeline

    pipes, states = {}, {"other": [], "this": []}
    for tag, mod in (("other", other), ("this", this)):
        p = Pipeline()
        p.tracker = mod.Tracker(p.config.detect)
        pipes[tag] = p
    got: dict = {}
    for i, s in enumerate(scans[:end]):
        for tag, p in pipes.items():
            if i < start:
                p.process(s)
                continue
            snap = copy.deepcopy(p.tracker)
            orig = p.tracker.update

            def grab(*a, _o=orig):
                got["args"] = (a[0], a[1], copy.deepcopy(a[2]), None if a[3] is None else a[3].copy())
                return _o(*a)

            p.tracker.update = grab
            p.process(s)
            del p.tracker.update
            states[tag].append((snap, got["args"]))
    n = len(states["this"])
    best = {"other": [float("inf")] * n, "this": [float("inf")] * n}
    for r in range(reps):
        for j in range(n):
            for tag in (("other", "this") if (r + j) % 2 == 0 else ("this", "other")):
                tr, args = states[tag][j]
                fresh = copy.deepcopy(tr)
                t0 = time.thread_time_ns()
                fresh.update(*args)
                best[tag][j] = min(best[tag][j], time.thread_time_ns() - t0)
    mo, mt = (sum(best[k]) / n / 1e3 for k in ("other", "this"))
    return mo, mt, statistics.median(t / o for t, o in zip(best["this"], best["other"]))


def _same_tracks(a: list, b: list) -> bool:
    """The two ``Tracker.update`` reports are equal field by field (floats and arrays bit for bit)."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        for f in ("id", "state", "stamp", "age", "hits", "misses", "kind", "in_m", "m_reason", "n_points",
                  "remembered"):
            if getattr(x, f) != getattr(y, f):
                return False
        bx, by = x.box, y.box
        if (bx.px, bx.py, bx.theta, bx.length, bx.width) != (by.px, by.py, by.theta, by.length, by.width):
            return False
        for f in ("velocity", "covariance", "beams"):
            u, v = getattr(x, f), getattr(y, f)
            if u.dtype != v.dtype or u.shape != v.shape or u.tobytes() != v.tobytes():
                return False
    return True


def check(scans: list, other) -> tuple[int, int | None]:
    """Both checkouts' trackers in lockstep over every scan (each in a pipeline of its own): (scans compared,
    index of the first scan whose reports or stats differ, None if none). Identical reports keep the two
    pipelines identical, so this checks the whole run's output of the tracker."""
    from dynslam2d.detect import tracker as this
    from dynslam2d.pipeline import Pipeline

    pipes = []
    for mod in (other, this):
        p = Pipeline()
        p.tracker = mod.Tracker(p.config.detect)
        pipes.append(p)
    for i, s in enumerate(scans):
        ra, rb = (p.process(s) for p in pipes)
        if not _same_tracks(ra.tracks, rb.tracks) or pipes[0].tracker.stats.as_dict() != \
                pipes[1].tracker.stats.as_dict() or ra.removed.tobytes() != rb.removed.tobytes():
            return i + 1, i
    return len(scans), None


def pipeline_ab(scans: list, other) -> tuple[float, float, float]:
    """(other, this) median CPU ms of ``Pipeline.process`` per scan over every scan, two pipelines (one with each
    checkout's tracker) in lockstep, and the median of the per-scan ratios this / other."""
    from dynslam2d.detect import tracker as this
    from dynslam2d.pipeline import Pipeline

    for mod in (other, this):  # (each checkout's tracker kernels: TRACKER_KERNEL_MODULES)
        warm = Pipeline()
        warm.tracker = mod.Tracker(warm.config.detect)
        for s in scans[:60]:
            warm.process(s)
    preload(extra=(other,))  # (kernels first called after the warm-up, either side's tracker's)
    pipes = {}
    for tag, mod in (("other", other), ("this", this)):
        p = Pipeline()
        p.tracker = mod.Tracker(p.config.detect)
        pipes[tag] = p
    cpu: dict[str, list[float]] = {"other": [], "this": []}
    for i, s in enumerate(scans):
        for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
            t0 = time.thread_time_ns()
            pipes[tag].process(s)
            cpu[tag].append((time.thread_time_ns() - t0) / 1e6)
    return (statistics.median(cpu["other"]), statistics.median(cpu["this"]),
            statistics.median(t / o for t, o in zip(cpu["this"], cpu["other"])))


#: the steps of Tracker.update that --phases times (methods of the tracker, each called from update; a name the
#: checkout lacks counts 0; _associate_update: _associate and _update_pairs in one step since pass trk108)
_PHASES = ("_predict", "_detect", "_associate", "_vacated", "_update_pairs", "_associate_update", "_manage",
           "_clutter_detections", "_hosts_of_fragments", "_birth", "_births", "_report")


#: methods called inside those steps that --phases times too (not subtracted from the rest of update): the leg merge
#: (in _detect), the merged-detection veto (_associate), the Kalman bookkeeping and the acceleration bound
#: (_update_pairs), the dynamic test, the free-space entries read late and the riding test (_manage)
_NESTED = ("_free_values", "_update_tracks", "_bound_acceleration", "_merge_legs", "_veto_merged", "_dynamic",
           "_rides_with_laser")


def phases_ab(scans: list, other) -> dict[str, dict[str, float]]:
    """Per checkout ("other", "this"): the median over the scans of the thread CPU µs that each step of
    ``Tracker.update`` (:data:`_PHASES`, inclusive) took in the scan, of the rest of ``update`` ("update (rest)") and
    of the whole ``update`` ("total"), two pipelines in lockstep over every scan after a warm-up over every scan
    (medians: a one-off pause of the shared machine or a late first call does not count)."""
    from dynslam2d.detect import tracker as this
    from dynslam2d.pipeline import Pipeline

    for mod in (other, this):  # (each checkout's tracker kernels: TRACKER_KERNEL_MODULES)
        warm = Pipeline()
        warm.tracker = mod.Tracker(warm.config.detect)
        for s in scans:  # (every scan: a kernel first called late, e.g. on scan 339, would load in a timed run)
            warm.process(s)
    acc: dict[str, collections.Counter] = {"other": collections.Counter(), "this": collections.Counter()}
    per: dict[str, dict[str, list[float]]] = {"other": collections.defaultdict(list),
                                              "this": collections.defaultdict(list)}
    pipes = {}
    for tag, mod in (("other", other), ("this", this)):
        p = Pipeline()
        p.tracker = mod.Tracker(p.config.detect)
        for name in _PHASES + _NESTED + ("update",):
            f = getattr(p.tracker, name, None)
            if f is None:
                continue

            def timed(*a, _f=f, _c=acc[tag], _n=name, **k):
                t0 = time.thread_time_ns()
                r = _f(*a, **k)
                _c[_n] += time.thread_time_ns() - t0
                return r

            setattr(p.tracker, name, timed)  # (an instance attribute: update's self._x(...) calls find it)
        pipes[tag] = p
    for i, s in enumerate(scans):
        for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
            c = acc[tag]
            c.clear()
            pipes[tag].process(s)
            total = c["update"]
            per[tag]["total"].append(total / 1e3)
            per[tag]["update (rest)"].append((total - sum(c[n] for n in _PHASES)) / 1e3)
            for n in _PHASES:
                per[tag][n].append(c[n] / 1e3)
            for n in _NESTED:
                per[tag][n].append(c[n] / 1e3)
    # (a nested method runs on few scans: its mean over the scans; the step it runs in includes it)
    return {tag: {(f"{k} (mean)" if k in _NESTED else k):
                  (statistics.fmean(v) if k in _NESTED else statistics.median(v)) for k, v in d.items()}
            for tag, d in per.items()}


#: functions of other modules that Tracker.update calls (module attributes of detect/tracker.py and its step modules)
_SPLIT = ("segment_scan", "fit_clusters", "classify_batch", "admit_long_clusters", "map_evidence",
          "map_evidence_kernel", "gate_costs", "measure_batch", "kalman_update_batch", "fragment_hosts",
          "segment_means", "linear_sum_assignment", "assign_groups", "select_detections", "cv_predict",
          "association_rows", "size_jump_gate", "pair_priors", "shape_update", "accel_candidates", "accel_bound",
          "manage_speed_rows", "manage_rows", "report_boxes", "world_points", "merge_legs", "association_gates",
          "fragment_hosts_rows", "report_rows", "manage_counters", "associate_scan",
          "kalman_pairs")


def split(scans: list) -> tuple[float, dict[str, tuple[float, float]]]:
    """Tracker.update CPU µs per scan of one run after a warm-up, and the part of it (µs per scan) spent in each
    function of another module (:data:`_SPLIT` and the free-space memory's methods) with its calls per scan."""
    from dynslam2d.pipeline import Pipeline

    warm_up(scans, 60)  # (and every kernel numba's cache holds loaded: none is loaded in the measured run)
    p = Pipeline()
    acc: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()
    # (in every tracker module that calls it: detect/tracker.py and its step modules; names a later version no longer
    # uses skipped)
    saved = {(m, n): getattr(m, n) for m in tracker_modules() for n in _SPLIT if hasattr(m, n)}

    def timed(f, tag: str):
        def g(*a, **k):
            t0 = time.thread_time_ns()
            r = f(*a, **k)
            acc[tag] += time.thread_time_ns() - t0
            calls[tag] += 1
            return r
        return g

    try:
        for (m, n), f in saved.items():
            setattr(m, n, timed(f, n))
        if p.tracker._free is not None:
            for n in ("seen_through", "seen_through_by", "count_seen_by", "make_ref", "ref_of", "add"):
                if hasattr(p.tracker._free, n):  # (names of either checkout's memory)
                    setattr(p.tracker._free, n, timed(getattr(p.tracker._free, n), f"free-space memory ({n})"))
        p.tracker.update = timed(p.tracker.update, "update")
        for s in scans:
            p.process(s)
    finally:
        for (m, n), f in saved.items():
            setattr(m, n, f)
    n = len(scans)
    total = acc.pop("update") / 1e3 / n
    return total, {k: (v / 1e3 / n, calls[k] / n) for k, v in acc.items()}


def stages(scans: list) -> tuple[float, dict[str, float]]:
    """CPU ms per scan of one run after a warm-up, and per component (ms per scan)."""
    from dynslam2d.pipeline import Pipeline

    warm_up(scans, 60)  # (and every kernel numba's cache holds loaded: none is loaded in the measured run)
    p = Pipeline()
    acc: collections.Counter = collections.Counter()

    from cputimers import thread_cpu_wrapper

    wrap = thread_cpu_wrapper(acc)

    wrap(p.tracker, "update", "tracker")
    wrap(p.slam, "match", "SLAM match")
    wrap(p.slam, "update_map", "SLAM map update")
    if p.ledger is not None:
        for n in ("before_update", "after_update", "observe", "erase_entering"):
            wrap(p.ledger, n, "evidence ledger (slam/erasure.py)")
    wrap(p.body, "mask", "body filter")
    wrap(p.body, "observe", "body filter")
    wrap(p, "_exclude", "exclusion")
    t0 = time.thread_time_ns()
    for s in scans:
        p.process(s)
    n = len(scans)
    return (time.thread_time_ns() - t0) / 1e6 / n, {k: v / 1e6 / n for k, v in acc.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", metavar="INPUT", help=f"input names: {', '.join(INPUTS)}")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--start", type=int, default=150)
    ap.add_argument("--end", type=int, default=210)
    ap.add_argument("--stages", action="store_true", help="per-component CPU of this checkout instead")
    ap.add_argument("--split", action="store_true",
                    help="instead: Tracker.update's CPU in other modules' functions vs tracker.py's own code")
    ap.add_argument("--check", action="store_true",
                    help="instead: run both checkouts' trackers over every scan and compare their reports exactly")
    ap.add_argument("--pipeline", action="store_true",
                    help="instead: median CPU ms per scan of the whole pipeline with each checkout's tracker")
    ap.add_argument("--phases", action="store_true",
                    help="instead: CPU µs per scan of each step of Tracker.update, both checkouts in lockstep")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    check_inputs(ap, args.inputs)
    other = None if args.stages or args.split else other_tracker_module(args.other)
    for name in args.inputs:
        scans = load_scans(args.data, name)
        if args.split:
            total, parts = split(scans)
            elsewhere = sum(v for v, _ in parts.values())
            print(f"{name}: Tracker.update {total:.0f} µs CPU per scan; in other modules' functions {elsewhere:.0f} "
                  f"({100 * elsewhere / total:.0f} %), detect/tracker.py's own code {total - elsewhere:.0f}")
            for k, (v, c) in sorted(parts.items(), key=lambda kv: -kv[1][0]):
                print(f"  {k:<36} {v:6.1f} µs  {c:5.2f} calls ({v / c if c else 0.0:5.1f} µs each)")
        elif args.check:
            n, bad = check(scans, other)
            print(f"{name:<18} {n} scans: " + ("reports identical" if bad is None else f"DIFFERENT at scan {bad}"))
        elif args.pipeline:
            mo, mt, med = pipeline_ab(scans, other)
            print(f"{name:<18} pipeline CPU ms/scan, median over {len(scans)} scans: other {mo:.3f}, this {mt:.3f}, "
                  f"ratio {mt / mo:.3f} (median per scan {med:.3f})")
        elif args.phases:
            ph = phases_ab(scans, other)
            to, tt = ph["other"].pop("total"), ph["this"].pop("total")
            print(f"{name}: Tracker.update CPU µs per scan, medians over the scans, other → this (ratio): "
                  f"{to:.0f} → {tt:.0f} ({tt / to:.3f}); by step:")
            for k in sorted(ph["this"], key=lambda q: -ph["other"].get(q, 0.0)):
                o, t = ph["other"].get(k, 0.0), ph["this"][k]
                print(f"  {k:<22} {o:7.1f} → {t:7.1f}" + (f"  ({t / o:.2f})" if o > 0 else ""))
        elif args.stages:
            total, parts = stages(scans)
            print(f"{name}: {total:.2f} ms CPU per scan")
            for k, v in sorted(parts.items(), key=lambda kv: -kv[1]):
                print(f"  {k:<36} {v:6.3f} ms ({100 * v / total:3.0f} %)")
        else:
            mo, mt, med = ab(scans, other, args.reps, args.start, args.end)
            print(f"{name:<18} Tracker.update CPU µs/scan, scans {args.start}-{args.end}, min of {args.reps}: "
                  f"other {mo:.0f}, this {mt:.0f}, ratio {mt / mo:.3f} (median per scan {med:.3f})")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
