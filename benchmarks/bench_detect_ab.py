"""CPU time of the detection path's kernels of two checkouts on the same inputs (not run by pytest).

``bench_pipeline_ab.py`` times whole pipelines; a change of a few tens of µs per scan in one kernel is below its
scan-to-scan noise. This runs this checkout's pipeline over an input once and records the arguments of

  * ``fit_clusters`` (the tracker's shape fits, one call per scan),
  * ``vacated_outlines`` (the pipeline's vacated footprints, one call per scan with a map; timed while the
    pipeline runs, both versions on the call's arguments, as the map is too large to keep a copy per scan; only
    in checkouts whose pipeline still calls it itself: later ones run it inside ``vacated.py``'s kernel call),
  * the free-space fractions read late: ``FreeTest.fraction`` (a detection's own fraction, all reference scans)
    and the vacated part of a track's entry (``FreeSpaceMemory.count_seen_by``; the other checkout's
    ``seen_through_by`` and ``np.count_nonzero`` where it has no ``count_seen_by``),

then calls each recorded call with this checkout's and the other checkout's version (the other's ``shapes.py``,
``mapevidence.py``, ``freespace.py`` and ``kernels.py`` loaded as modules of their own), the two alternately
first, ``--reps`` times, in thread CPU time (``time.thread_time_ns``), keeping each call's minimum. Printed per
part: µs per scan (the sum of the minima over the scans of the input) of each checkout, their ratio, and whether
every result was identical. A free-space read of the other checkout gets its own reference scans, made by its
``make_ref`` from the same scan, pose and mask (untimed: the pipeline makes them once per scan); each read is
timed with a fresh test (as the first read of a scan's test; later reads of the same scan's test reuse its packed
references).

    taskset -c 0 python benchmarks/bench_detect_ab.py negative_2/right negative_2/left negative_2/rear \
        --other /work/main/src [--reps 5]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402


def load_other(src: Path, rel: str, name: str, deps: dict | None = None):
    """The other checkout's ``src/dynslam2d/<rel>`` as module ``name``; ``deps``: modules its imports resolve to
    instead of this checkout's (module name → module), only while it loads."""
    spec = importlib.util.spec_from_file_location(name, src / "dynslam2d" / rel)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    saved = {k: sys.modules.get(k) for k in deps or {}}
    sys.modules.update(deps or {})
    try:
        spec.loader.exec_module(mod)
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    return mod


def record(scans: list, other_vacated, reps: int) -> tuple[dict, list]:
    """This checkout's pipeline over ``scans``: the recorded calls of the parts timed afterwards (module docstring),
    and per call of ``vacated_outlines`` (timed as it happens, against ``other_vacated``: its map is too large to
    keep a copy per scan) the minima over ``reps`` alternated calls (this ns, other ns) and whether the results
    were equal."""
    from dynslam2d import pipeline
    from dynslam2d.detect import freespace, trackdetect
    from dynslam2d.pipeline import Pipeline

    rec: dict[str, list] = {"fit_clusters": [], "free fraction": [], "vacated read": []}
    live: list[tuple[int, int, bool]] = []
    made: dict[int, tuple] = {}  # id(ref) → (scan, pose, valid) it was made from
    # (the pipeline calls vacated_outlines through its own module only in checkouts before the vacated-footprint
    # kernel of vacated.py; later ones run it inside that kernel, timed by bench_vacate.py)
    hook_vac = hasattr(pipeline, "vacated_outlines")
    fit0, vac0 = trackdetect.fit_clusters, getattr(pipeline, "vacated_outlines", None)
    make0, frac0, count0 = freespace.FreeSpaceMemory.make_ref, freespace.FreeTest.fraction, \
        freespace.FreeSpaceMemory.count_seen_by

    def copies(args: tuple) -> list:
        return [a.copy() if isinstance(a, np.ndarray) else a for a in args]

    def fit(*a):
        rec["fit_clusters"].append(copies(a))
        return fit0(*a)

    def vac(*a, **k):
        fn = {"this": vac0, "other": other_vacated}
        best, out = {"this": 1 << 62, "other": 1 << 62}, {}
        for r in range(reps):
            for tag in (("other", "this") if (r + len(live)) % 2 == 0 else ("this", "other")):
                t0 = time.thread_time_ns()
                out[tag] = fn[tag](*a, **k)
                best[tag] = min(best[tag], time.thread_time_ns() - t0)
        a_, b_ = out["this"], out["other"]
        same = (a_.rows.tobytes(), a_.cols.tobytes(), a_.seen_through, a_.outlines, a_.sizes) == \
            (b_.rows.tobytes(), b_.cols.tobytes(), b_.seen_through, b_.outlines, b_.sizes)
        live.append((best["this"], best["other"], same))
        return out["this"]

    def make_ref(scan, pose, valid):
        ref = make0(scan, pose, valid)
        made[id(ref)] = (ref, scan, pose, valid.copy())  # (the ref kept: its id stays its own)
        return ref

    ref_of0 = getattr(freespace.FreeSpaceMemory, "ref_of", None)

    def ref_of(scan, pose, r, par):  # (the tracker's since pass trk60: the arrays made by the segmentation's kernel)
        ref = ref_of0(scan, pose, r, par)
        made[id(ref)] = (ref, scan, pose, r < np.inf)  # (its mask: the valid beams' ranges are finite, the others inf)
        return ref

    def fraction(self, points):
        rec["free fraction"].append(([made[id(r)][1:] for r in self.refs], self.margin, points.copy()))
        return frac0(self, points)

    def count_seen_by(self, ref, points):
        rec["vacated read"].append(([made[id(ref)][1:]], self.margin, points.copy()))
        return count0(self, ref, points)

    trackdetect.fit_clusters = fit
    if hook_vac:
        pipeline.vacated_outlines = vac
    freespace.FreeSpaceMemory.make_ref = staticmethod(make_ref)
    if ref_of0 is not None:
        freespace.FreeSpaceMemory.ref_of = staticmethod(ref_of)
    freespace.FreeTest.fraction, freespace.FreeSpaceMemory.count_seen_by = fraction, count_seen_by
    try:
        p = Pipeline()
        for s in scans:
            p.process(s)
    finally:
        trackdetect.fit_clusters = fit0
        if hook_vac:
            pipeline.vacated_outlines = vac0
        freespace.FreeSpaceMemory.make_ref = staticmethod(make0)
        if ref_of0 is not None:
            freespace.FreeSpaceMemory.ref_of = staticmethod(ref_of0)
        freespace.FreeTest.fraction, freespace.FreeSpaceMemory.count_seen_by = frac0, count0
    return rec, live


def callers(other_src: Path) -> dict:
    """Per part: ((prepare, call) of this checkout, (prepare, call) of the other one): ``prepare`` turns one recorded
    call into the arguments of ``call`` (untimed: e.g. the reference scans of a free-space read, which the pipeline
    makes once per scan), ``call`` returns a comparable result."""
    from dynslam2d.detect import freespace, shapes

    o_kernels = load_other(other_src, "detect/kernels.py", "other_kernels")
    o_shapes = load_other(other_src, "detect/shapes.py", "other_shapes")
    o_free = load_other(other_src, "detect/freespace.py", "other_freespace",
                        {"dynslam2d.detect.kernels": o_kernels})

    def same(a):
        return a

    def refs_of(mod):
        def prep(rec):
            made, margin, points = rec
            return mod, tuple(mod.FreeSpaceMemory.make_ref(*m) for m in made), margin, points
        return prep

    def fraction(a):
        mod, refs, margin, points = a
        return mod.FreeTest(refs, margin).fraction(points)  # (a fresh test: the first read of a scan's test)

    def read(a):
        mod, refs, margin, points = a
        mem = mod.FreeSpaceMemory(margin=margin)
        if hasattr(mem, "count_seen_by"):
            return mem.count_seen_by(refs[0], points)
        return int(np.count_nonzero(mem.seen_through_by(refs[0], points)))

    return {
        "fit_clusters": ((same, lambda a: shapes.fit_clusters(*a).tobytes()),
                         (same, lambda a: o_shapes.fit_clusters(*a).tobytes())),
        "free fraction": ((refs_of(freespace), fraction), (refs_of(o_free), fraction)),
        "vacated read": ((refs_of(freespace), read), (refs_of(o_free), read)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="+", choices=sorted(INPUTS))
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    from dynslam2d.inputs import open_source

    calls = callers(args.other)
    o_me = load_other(args.other, "detect/mapevidence.py", "other_mapevidence")
    for name in args.inputs:
        rel, topic = INPUTS[name]
        scans = list(open_source(rel if rel.startswith("sim:") else str(args.data / rel), topic))
        rec, live = record(scans, o_me.vacated_outlines, args.reps)
        print(f"{name}: {len(scans)} scans; µs per scan (sums of per-call minima over {args.reps} alternated "
              "repetitions), other → this")
        for part, sides in calls.items():
            got = rec[part]
            if not got:
                print(f"  {part:26s} no calls")
                continue
            prepared = {tag: [prep(a) for a in got] for tag, (prep, _) in zip(("this", "other"), sides)}
            fn = {"this": sides[0][1], "other": sides[1][1]}
            # (also the warm-up of both versions)
            same = all(fn["this"](a) == fn["other"](b) for a, b in zip(prepared["this"], prepared["other"]))
            best = {"this": [float("inf")] * len(got), "other": [float("inf")] * len(got)}
            for r in range(args.reps):
                for j in range(len(got)):
                    for tag in (("other", "this") if (r + j) % 2 == 0 else ("this", "other")):
                        f, a = fn[tag], prepared[tag][j]
                        t0 = time.thread_time_ns()
                        f(a)
                        best[tag][j] = min(best[tag][j], time.thread_time_ns() - t0)
            to, tt = (sum(best[k]) / len(scans) / 1e3 for k in ("other", "this"))
            print(f"  {part:26s} {len(got):5d} calls  {to:8.2f} → {tt:8.2f}  (×{tt / to:.2f})  "
                  f"{'identical' if same else 'DIFFERENT'}")
        if not live:
            print(f"  {'vacated_outlines':26s} not called by this checkout's pipeline (benchmarks/bench_vacate.py)")
            continue
        tt, to = (sum(x[q] for x in live) / len(scans) / 1e3 for q in (0, 1))
        print(f"  {'vacated_outlines':26s} {len(live):5d} calls  {to:8.2f} → {tt:8.2f}  (×{tt / to:.2f})  "
              f"{'identical' if all(x[2] for x in live) else 'DIFFERENT'}  (timed during the run)")


if __name__ == "__main__":
    main()
