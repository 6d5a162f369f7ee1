"""CPU time of the tracker's detection step of two checkouts on the same inputs (not run by pytest).

``bench_pipeline_ab.py`` times whole pipelines; a change of a few tens of µs per scan in one kernel is below its
scan-to-scan noise. This measures, per input (the first ``--scans`` scans):

  * in lockstep, the detection step inside each checkout's own pipeline: two worker processes (one per checkout,
    ``PYTHONPATH``) warm their kernels on the first 60 scans with a throw-away pipeline, then load every other
    kernel numba's cache holds and the modules a run imports late (``kernelwarm.preload``), then process the scans
    one at a time when told to, the parent sending scan ``i`` to one and then to the other (which one goes first
    alternates with ``i``); each times, in thread CPU time (``time.thread_time_ns``), ``Tracker._detect`` (the
    detection step as a whole: the scan's mask, the fused call, the free-space memory, the detections' objects, a
    leg merge) and inside it ``detect_scan`` (the segmentation, shape fits, classification and ``detect_rows`` as
    one kernel call since pass trk72; a checkout before it has none: "no calls"), and sends a digest of every
    ``detect_scan`` result (arrays by dtype / shape / bytes) and the number of detections;
  * replayed, the free-space fractions read late: ``FreeTest.fraction`` (a detection's own fraction, all
    reference scans) and the vacated part of a track's entry (``FreeSpaceMemory.count_seen_by``; the other
    checkout's ``seen_through_by`` and ``np.count_nonzero`` where it has no ``count_seen_by``), recorded from this
    checkout's pipeline over the input and called with this checkout's and the other checkout's version (the
    other's ``freespace.py`` and ``kernels.py`` loaded as modules of their own), the two alternately first,
    ``--reps`` times, keeping each call's minimum; after one call of each (the warm-up) every kernel numba's cache
    holds is loaded (``kernelwarm.preload``, both sides);
  * ``vacated_outlines`` (the pipeline's vacated footprints) where this checkout's pipeline still calls it itself
    (timed while the pipeline runs; later checkouts run it inside ``vacated.py``'s kernel call: bench_vacate.py).

Printed per part: µs per scan of each checkout (lockstep: the mean over the scans, with the medians; replayed: the
sum of the per-call minima over the scans), their ratio, and whether every result was identical; then the kernels
loaded or compiled inside the measured runs (0 when the warm-up and the preload did their work). A free-space read of
the other checkout gets its own reference scans, made by its ``make_ref`` from the same scan, pose and mask
(untimed: the pipeline makes them once per scan); each read is timed with a fresh test (as the first read of a
scan's test; later reads of the same scan's test reuse its packed references).

    taskset -c 0 python benchmarks/bench_detect_ab.py sim:paper negative_2/right negative_2/left negative_2/rear \
        --other <other checkout>/src [--reps 5] [--scans N]

Inputs: the names of ``bench_digest.py`` (paths under ``--data``) or any built-in scene (``sim:paper``). Both
workers inherit this process's CPU affinity: pin the parent with ``taskset``.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from kernelwarm import kernel_cache_calls, preload  # noqa: E402

WARMUP = 60


def load_scans(data: Path, name: str, limit: int | None) -> list:
    """The first ``limit`` scans (all where None) of input ``name``: a ``bench_digest`` name or a built-in scene."""
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    return scans[:limit] if limit else scans


def digest(values: tuple) -> str:
    """A digest of a kernel call's results: arrays by dtype, shape and bytes, scalars by their repr."""
    h = hashlib.blake2b(digest_size=16)
    for v in values:
        if isinstance(v, np.ndarray):
            h.update(f"{v.dtype}{v.shape}".encode())
            h.update(np.ascontiguousarray(v).tobytes())
        else:
            h.update(repr(v).encode())
    return h.hexdigest()


def forty(out: tuple, a: tuple) -> tuple:
    """A ``detect_scan`` call's results (``a``: its arguments) in the 40 places they had before pass det109, which
    returns 27 (the segmentation's labels and structure left to ``segment.segmentation_of``, the leg merge's arrays
    one tuple or None): the two layouts' digests compare."""
    if len(out) != 27:
        return out
    from dynslam2d.detect.segment import SP_MAX_POINTS, segmentation_of

    beams, offsets, dropped, wrapped, pts, rr, par, *rows7 = out[:14]
    merged, px2, py2 = out[14:17]
    seg = segmentation_of(beams, offsets, a[0].shape[0], int(a[5][SP_MAX_POINTS]), wrapped, dropped)
    if merged is None:  # (no pair: detect_rows' empty arrays and the selected rows again)
        none = np.empty(0, dtype=np.int64)
        starts, npts, kinds, lohi, rel, sfits, mfr = rows7
        merged = (none, none, none, kinds, sfits, lohi, rel, starts, npts, none, np.empty((0, 2)), mfr)
    return (seg.labels, beams, offsets, seg.structure, dropped, wrapped, pts, rr, par, *rows7, *merged[:9], px2, py2,
            *merged[9:], *out[17:])


def worker(data: Path, name: str, limit: int | None) -> None:
    """Serve ``go`` lines on stdin: process the next scan, answer one JSON line (thread CPU ns of
    ``Tracker._detect`` and of ``detect_scan`` inside it, the ``detect_scan`` results' digest, the detections)."""
    from bench_pipeline import warm_up

    import dynslam2d.detect.trackdetect as td
    from dynslam2d.pipeline import Pipeline

    scans = load_scans(data, name, limit)
    warm_up(scans, WARMUP)  # (and every kernel numba's cache holds loaded, the late imports made: kernelwarm.preload)
    owner = next((c for c in vars(td).values() if isinstance(c, type) and "_detect" in vars(c)), None)
    if owner is None:  # (a checkout whose tracker keeps _detect in tracker.py)
        import dynslam2d.detect.tracker as owner_mod
        owner = owner_mod.Tracker
    det0, kern0 = owner._detect, getattr(td, "detect_scan", None)
    cur: dict = {}

    def kern(*a):
        t0 = time.thread_time_ns()
        out = kern0(*a)
        cur["kernel"] = cur.get("kernel", 0) + time.thread_time_ns() - t0
        cur.setdefault("outs", []).append((out, a))  # (in the places of before pass det109 after the scan: forty)
        return out

    def detect(self, *a, **k):
        t0 = time.thread_time_ns()
        out = det0(self, *a, **k)
        cur["detect"] = cur.get("detect", 0) + time.thread_time_ns() - t0
        cur["n"] = cur.get("n", 0) + len(out)
        return out

    owner._detect = detect
    if kern0 is not None:
        td.detect_scan = kern
    pipe = Pipeline()
    print(json.dumps({"scans": len(scans)}), flush=True)
    looked = kernel_cache_calls()
    for i, line in enumerate(sys.stdin):
        if i >= len(scans) or line.strip() != "go":
            break
        cur.clear()
        pipe.process(scans[i])
        outs = cur.get("outs")
        print(json.dumps({"detect": cur.get("detect"), "kernel": cur.get("kernel"), "n": cur.get("n"),
                          "h": None if outs is None else digest(tuple(v for o, a in outs for v in forty(o, a)))}),
              flush=True)
    print(json.dumps({"loads": kernel_cache_calls() - looked}), flush=True)  # (inside the measured run)


def lockstep(data: Path, name: str, other: Path, limit: int | None) -> tuple[int, dict, dict]:
    """Both checkouts' workers over input ``name`` in lockstep: (scans, {tag: per-scan answers}, {tag: loads})."""
    procs = {}
    for tag, src in (("other", other.resolve()), ("this", REPO / "src")):
        env = dict(os.environ, PYTHONPATH=str(src))
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data", str(data)]
        procs[tag] = subprocess.Popen(cmd + (["--scans", str(limit)] if limit else []), env=env,
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())
    got: dict[str, list] = {"other": [], "this": []}
    for i in range(n):
        for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
            p = procs[tag]
            p.stdin.write("go\n")
            p.stdin.flush()
            got[tag].append(json.loads(p.stdout.readline()))
    loads = {}
    for tag, p in procs.items():
        p.stdin.close()
        loads[tag] = json.loads(p.stdout.readline())["loads"]
        if p.wait():
            raise SystemExit(f"{tag} worker failed ({p.returncode})")
    return n, got, loads


def print_lockstep(n: int, got: dict) -> None:
    """The lockstep parts' lines (module docstring)."""
    for part, key in (("detect_scan (fused call)", "kernel"), ("Tracker._detect (the step)", "detect")):
        vals = {tag: [r[key] for r in got[tag] if r[key] is not None] for tag in got}
        if not vals["this"] or not vals["other"]:
            print(f"  {part:26s} no calls ({', '.join(t for t in vals if not vals[t])})")
            continue
        to, tt = (sum(vals[t]) / n / 1e3 for t in ("other", "this"))
        mo, mt = (statistics.median(vals[t]) / 1e3 for t in ("other", "this"))
        same = all(a["h"] == b["h"] and a["n"] == b["n"] for a, b in zip(got["other"], got["this"]))
        print(f"  {part:26s} {len(vals['this']):5d} calls  {to:8.2f} → {tt:8.2f}  (×{tt / to:.2f})  "
              f"{'identical' if same else 'DIFFERENT'}  (lockstep in the run; medians {mo:.2f} → {mt:.2f}, "
              f"×{mt / mo:.2f})")


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
    from dynslam2d.detect import freespace
    from dynslam2d.pipeline import Pipeline

    rec: dict[str, list] = {"free fraction": [], "vacated read": []}
    live: list[tuple[int, int, bool]] = []
    made: dict[int, tuple] = {}  # id(ref) → (scan, pose, valid) it was made from
    # (the pipeline calls vacated_outlines through its own module only in checkouts before the vacated-footprint
    # kernel of vacated.py; later ones run it inside that kernel, timed by bench_vacate.py)
    hook_vac = hasattr(pipeline, "vacated_outlines")
    vac0 = getattr(pipeline, "vacated_outlines", None)
    make0, frac0, count0 = freespace.FreeSpaceMemory.make_ref, freespace.FreeTest.fraction, \
        freespace.FreeSpaceMemory.count_seen_by

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
        if hook_vac:
            pipeline.vacated_outlines = vac0
        freespace.FreeSpaceMemory.make_ref = staticmethod(make0)
        if ref_of0 is not None:
            freespace.FreeSpaceMemory.ref_of = staticmethod(ref_of0)
        freespace.FreeTest.fraction, freespace.FreeSpaceMemory.count_seen_by = frac0, count0
    return rec, live


def callers(other_src: Path) -> tuple[dict, list]:
    """Per part: ((prepare, call) of this checkout, (prepare, call) of the other one): ``prepare`` turns one recorded
    call into the arguments of ``call`` (untimed: e.g. the reference scans of a free-space read, which the pipeline
    makes once per scan), ``call`` returns a comparable result; and the other checkout's modules loaded for them."""
    from dynslam2d.detect import freespace

    o_kernels = load_other(other_src, "detect/kernels.py", "other_kernels")
    o_free = load_other(other_src, "detect/freespace.py", "other_freespace",
                        {"dynslam2d.detect.kernels": o_kernels})

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
        "free fraction": ((refs_of(freespace), fraction), (refs_of(o_free), fraction)),
        "vacated read": ((refs_of(freespace), read), (refs_of(o_free), read)),
    }, [o_kernels, o_free]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:paper)")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=5, help="repetitions of each replayed call")
    ap.add_argument("--scans", type=int, default=None, help="only the first N scans of each input")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    bad = [n for n in args.inputs if n not in INPUTS and not n.startswith("sim:")]
    if bad:
        ap.error(f"unknown inputs {bad}; accepted: {', '.join(sorted(INPUTS))} or sim:<scene>")
    if args.worker:
        worker(args.data, args.inputs[0], args.scans)
        return

    calls, other_mods = callers(args.other)
    o_me = load_other(args.other, "detect/mapevidence.py", "other_mapevidence")
    for name in args.inputs:
        n_lock, got, lock_loads = lockstep(args.data, name, args.other, args.scans)
        scans = load_scans(args.data, name, args.scans)
        rec, live = record(scans, o_me.vacated_outlines, args.reps)
        print(f"{name}: {len(scans)} scans; µs per scan (replayed: sums of per-call minima over {args.reps} "
              "alternated repetitions), other → this")
        print_lockstep(n_lock, got)
        loads = {"other": lock_loads["other"], "this": lock_loads["this"]}
        for part, sides in calls.items():
            got = rec[part]
            if not got:
                print(f"  {part:26s} no calls")
                continue
            prepared = {tag: [prep(a) for a in got] for tag, (prep, _) in zip(("this", "other"), sides)}
            fn = {"this": sides[0][1], "other": sides[1][1]}
            # (also the warm-up of both versions; then every kernel numba's cache holds, either side's, loaded)
            same = all(fn["this"](a) == fn["other"](b) for a, b in zip(prepared["this"], prepared["other"]))
            preload(extra=other_mods)
            looked = {"this": kernel_cache_calls(), "other": kernel_cache_calls("other_", extra=other_mods)}
            best = {"this": [float("inf")] * len(got), "other": [float("inf")] * len(got)}
            for r in range(args.reps):
                for j in range(len(got)):
                    for tag in (("other", "this") if (r + j) % 2 == 0 else ("this", "other")):
                        f, a = fn[tag], prepared[tag][j]
                        t0 = time.thread_time_ns()
                        f(a)
                        best[tag][j] = min(best[tag][j], time.thread_time_ns() - t0)
            loads["this"] += kernel_cache_calls() - looked["this"]
            loads["other"] += kernel_cache_calls("other_", extra=other_mods) - looked["other"]
            to, tt = (sum(best[k]) / len(scans) / 1e3 for k in ("other", "this"))
            print(f"  {part:26s} {len(got):5d} calls  {to:8.2f} → {tt:8.2f}  (×{tt / to:.2f})  "
                  f"{'identical' if same else 'DIFFERENT'}")
        if not live:
            print(f"  {'vacated_outlines':26s} not called by this checkout's pipeline (benchmarks/bench_vacate.py)")
        else:
            tt, to = (sum(x[q] for x in live) / len(scans) / 1e3 for q in (0, 1))
            print(f"  {'vacated_outlines':26s} {len(live):5d} calls  {to:8.2f} → {tt:8.2f}  (×{tt / to:.2f})  "
                  f"{'identical' if all(x[2] for x in live) else 'DIFFERENT'}  (timed during the run)")
        print(f"  inside the measured runs kernels loaded or compiled: other {loads['other']}, this {loads['this']}",
              flush=True)


if __name__ == "__main__":
    main()
