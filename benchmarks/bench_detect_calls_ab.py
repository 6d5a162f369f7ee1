"""CPU time of the detection path's per-scan calls of two checkouts on the same arguments (not run by pytest).

The tracker's detection calls cost 5-100 µs each per scan, below ``bench_pipeline_ab.py``'s scan-to-scan noise.
This runs this checkout's pipeline over the first ``--scans`` scans of an input once and records the arguments of

  * ``segment_scan`` (the breakpoint segmentation), ``fit_clusters`` (the shape fits), ``classify_batch``,
    ``admit_long_clusters`` (detect/vehicles.py), ``gate_costs`` and the tracker's ``measure_batch`` calls, as the
    tracker calls them (``dynslam2d.detect.tracker``'s names); since pass trk72 the tracker calls the first ones
    as one kernel, ``detect_scan`` (detect/segment.py), recorded and compared where both checkouts have it,
  * ``FreeSpaceMemory.make_ref`` (the scan's free-space reference),

then calls each recorded call with this checkout's and the other checkout's function (``--other``: its
``segment.py``, ``shapes.py``, ``vehicles.py``, ``freespace.py`` and ``kernels.py`` loaded as modules of their
own), the two alternately first, ``--reps`` times, in thread CPU time, keeping each call's minimum, and compares
the results bit for bit (arrays by their bytes; ``admit_long_clusters`` also the ``keep`` it edits in place).
Printed per call: µs per call of each checkout (mean of the minima), their ratio (sum over sum) and "identical".
These are warm-cache figures (the same call repeated); inside the pipeline each call costs 1.5-4× more.

The other checkout's modules are compiled under other module names; numba's cache would keep them under the
other checkout's source paths with those names, and a later plain import of that checkout would fail on them.
So this points numba at a cache folder of its own (``--cache-dir``, default ``~/.cache/dynslam2d/numba-ab``)
before numba is imported (the first run there compiles every kernel once).

    taskset -c 0 python benchmarks/bench_detect_calls_ab.py negative_2/right negative_2/left negative_2/rear \
        --other <other checkout>/src [--reps 7] [--scans 300]
"""

from __future__ import annotations

import argparse
import collections
import copy
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
_ap.add_argument("inputs", nargs="+")
_ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
_ap.add_argument("--reps", type=int, default=7)
_ap.add_argument("--scans", type=int, default=300)
_ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
_ap.add_argument("--cache-dir", type=Path, default=Path.home() / ".cache" / "dynslam2d" / "numba-ab")

_TRACKER_CALLS = ("segment_scan", "fit_clusters", "classify_batch", "admit_long_clusters", "select_detections",
                  "detect_rows", "gate_costs", "measure_batch", "detect_scan")


def same(a, b) -> bool:
    """Bit-for-bit equality of results (tuples, arrays by dtype / shape / bytes, the reference's fields but its
    pose object, NaN equal to NaN)."""
    import numpy as np

    if isinstance(a, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if hasattr(a, "__slots__") and not isinstance(a, (int, float, bool)):
        return all(same(getattr(a, s), getattr(b, s)) for s in a.__slots__ if s != "pose")
    return bool(a == b or (a != a and b != b))


def record(scans: list) -> dict[str, list]:
    """The recorded (args, kwargs) of each call of :data:`_TRACKER_CALLS` and ``make_ref`` over one pipeline run
    (arguments deep-copied when the call is made)."""
    from dynslam2d.detect import freespace
    from dynslam2d.detect import tracker as T
    from dynslam2d.pipeline import Pipeline

    rec: dict[str, list] = collections.defaultdict(list)
    # (a name this checkout's tracker no longer calls is not recorded: admit_long_clusters runs inside
    # select_detections since the tracker's kernels were fused)
    # (in detect/tracker.py and the step modules it was split into, pass trktable)
    mods = [T] + [m for n in ("trackdetect", "trackupdate", "trackmanage", "trackreport")
                  if (m := sys.modules.get(f"dynslam2d.detect.{n}")) is not None]
    saved = {(m, n): getattr(m, n) for m in mods for n in _TRACKER_CALLS if hasattr(m, n)}
    make0 = freespace.FreeSpaceMemory.make_ref

    def wrap(f, n):
        def g(*a, **k):
            rec[n].append((copy.deepcopy(a), k))
            return f(*a, **k)
        return g

    def make_ref(scan, pose, valid):
        rec["make_ref"].append(((scan, pose, valid.copy()), {}))
        return make0(scan, pose, valid)

    ref_of0 = getattr(freespace.FreeSpaceMemory, "ref_of", None)

    def ref_of(scan, pose, r, par):  # (the tracker's since pass trk60: recorded as the make_ref call it stands for)
        rec["make_ref"].append(((scan, pose, r < float("inf")), {}))  # (the mask: valid ranges finite, others inf)
        return ref_of0(scan, pose, r, par)

    try:
        for (m, n), f in saved.items():
            setattr(m, n, wrap(f, n))
        freespace.FreeSpaceMemory.make_ref = staticmethod(make_ref)
        if ref_of0 is not None:
            freespace.FreeSpaceMemory.ref_of = staticmethod(ref_of)
        p = Pipeline()
        for s in scans:
            p.process(s)
    finally:
        for (m, n), f in saved.items():
            setattr(m, n, f)
        freespace.FreeSpaceMemory.make_ref = staticmethod(make0)
        if ref_of0 is not None:
            freespace.FreeSpaceMemory.ref_of = staticmethod(ref_of0)
    return rec


def ab(f, g, calls: list, reps: int, mutates: bool) -> tuple[float, float, bool]:
    """Per call the minimum thread CPU ns over ``reps`` alternated calls of ``f`` (this) and ``g`` (other): (mean µs
    this, mean µs other, every result identical). ``mutates``: each call gets fresh copies of the arguments (and
    the edited arguments are compared too)."""
    ta, tb, ok = [], [], True
    for a, k in calls:
        best = [1 << 62, 1 << 62]
        res: list = [None, None]
        for r in range(reps):
            for w in ((0, 1) if r % 2 else (1, 0)):
                aa = copy.deepcopy(a) if mutates else a
                fn = f if w == 0 else g
                t0 = time.thread_time_ns()
                out = fn(*aa, **k)
                best[w] = min(best[w], time.thread_time_ns() - t0)
                res[w] = (out, aa) if mutates else out
        ok = ok and same(res[0], res[1])
        ta.append(best[0])
        tb.append(best[1])
    n = max(len(calls), 1)
    return sum(ta) / n / 1e3, sum(tb) / n / 1e3, ok


def main() -> None:
    args = _ap.parse_args()
    os.environ.setdefault("NUMBA_CACHE_DIR", str(args.cache_dir))
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_detect_ab import load_other
    from bench_tracker_ab import load_scans

    from dynslam2d.detect import freespace, kernels, segment, shapes, vehicles

    o_k = load_other(args.other, "detect/kernels.py", "other_kernels")
    o_sh = load_other(args.other, "detect/shapes.py", "other_shapes")
    # (its segmentation with its own kernels and shape fits: detect_scan calls them, pass trk72)
    o_seg = load_other(args.other, "detect/segment.py", "other_segment",
                       {"dynslam2d.detect.kernels": o_k, "dynslam2d.detect.shapes": o_sh})
    o_veh = load_other(args.other, "detect/vehicles.py", "other_vehicles")
    o_free = load_other(args.other, "detect/freespace.py", "other_freespace", {"dynslam2d.detect.kernels": o_k})
    parts = {  # name: (this, other, mutates its arguments)
        "segment_scan": (segment.segment_scan, o_seg.segment_scan, False),
        "fit_clusters": (shapes.fit_clusters, o_sh.fit_clusters, False),
        "classify_batch": (kernels.classify_batch, o_k.classify_batch, False),
        "admit_long_clusters": (vehicles.admit_long_clusters, o_veh.admit_long_clusters, True),
        "gate_costs": (kernels.gate_costs, o_k.gate_costs, False),
        "measure_batch": (kernels.measure_batch, o_k.measure_batch, False),
        "make_ref": (freespace.FreeSpaceMemory.make_ref, o_free.FreeSpaceMemory.make_ref, False),
    }
    if hasattr(kernels, "select_detections") and hasattr(o_k, "select_detections"):
        parts["select_detections"] = (kernels.select_detections, o_k.select_detections, False)
    # (the classification, the selection and the leg merge in one call since pass fus40: compared only against a
    # checkout that has it too; a checkout before it records the three names above instead)
    if hasattr(kernels, "detect_rows") and hasattr(o_k, "detect_rows"):
        parts["detect_rows"] = (kernels.detect_rows, o_k.detect_rows, False)
    # (the segmentation, the shape fits and detect_rows in one call since pass trk72, the tracker's only detection
    # kernel call: compared only against a checkout that has it too)
    if hasattr(segment, "detect_scan") and hasattr(o_seg, "detect_scan"):
        parts["detect_scan"] = (segment.detect_scan, o_seg.detect_scan, False)
    for name in args.inputs:
        scans = load_scans(args.data, name)[:args.scans]
        rec = record(scans)
        print(f"{name}: {len(scans)} scans, µs per call (minimum of {args.reps} alternated calls, mean over calls)")
        tot_a = tot_b = 0.0
        for part, (f, g, mut) in parts.items():
            calls = rec.get(part, [])
            if not calls:  # (not called by this checkout's tracker)
                continue
            a, b, ok = ab(f, g, calls, args.reps, mut)
            per_scan = len(calls) / max(len(scans), 1)
            tot_a += a * per_scan
            tot_b += b * per_scan
            print(f"  {part:<20} this {a:7.2f}  other {b:7.2f}  ratio {a / b if b else float('nan'):.3f}  "
                  f"{'identical' if ok else 'DIFFERENT'}  ({len(calls)} calls)")
        print(f"  {'sum per scan':<20} this {tot_a:7.2f}  other {tot_b:7.2f}  ratio {tot_a / tot_b:.3f}")


if __name__ == "__main__":
    main()
