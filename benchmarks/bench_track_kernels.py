"""The tracker's kernels one by one: thread CPU in situ (first-called in the pipeline) against replayed warm (not run
by pytest).

Every kernel call of the ``track`` stage (inside ``Tracker.update``) is wrapped where the tracker's modules call it
(:func:`track_targets` finds them in the modules, so a renamed or moved kernel is followed, not missed): after a
60-scan warm-up (a throw-away pipeline) one pipeline runs over the input with ``pipeline.run``'s collector setting,
each call is timed in thread CPU time and its arguments are copied (arrays below 200 000 elements; larger ones, the
map, are kept by reference). Then each kernel's recorded calls are replayed back to back, ``--reps`` times (fresh
copies of the array arguments before each call, outside the timing); the least of the repetitions' medians is the
warm figure. Printed per kernel: the in-situ median, the warm median, their ratio, the calls a scan and the
arguments a call. A no-op kernel called at the start of every ``Tracker.update`` gives the fixed cost of a first
call in situ against its warm dispatch; the same kernel called again right after it, the part of that cost a second
call of the same kernel does not pay; then a no- op with 33 arguments (16 arrays of 700 floats, 17 floats: as many
as ``detect_rows``') on even scans and one with its 16 arrays alone on odd ones, the in-situ price of the arguments.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_track_kernels.py negative_2/right sim:paper [--reps 3]
        [--data <data>]

Inputs: the names of ``bench_digest.py`` or a built-in scene (``sim:NAME``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import named_scans, scan_loop_gc  # noqa: E402

WARMUP = 60
BIG = 200_000  # arrays with more elements are not copied (the map view's log-odds)
#: The modules whose Python the ``track`` stage runs: the kernels are wrapped where these look them up.
TRACK_MODULES = ("tracker", "trackdetect", "trackupdate", "trackmanage", "trackreport", "tracktable", "freespace",
                 "segment", "mapevidence", "measure", "shapes", "vehicles", "body")


def _is_kernel(obj: object) -> bool:
    """A numba dispatcher (JIT) or an AOT kernel (both keep the Python function as ``py_func``)."""
    return callable(obj) and hasattr(obj, "py_func")


def track_targets() -> list[tuple[str, str]]:
    """(module, name) of every kernel the track stage's modules (:data:`TRACK_MODULES`) call from Python, derived
    from the modules themselves so that a renamed or moved kernel cannot leave a stale name here: each module's
    attributes that are kernels, less those another kernel of the same module names (numba binds a kernel's callees
    when it compiles: a wrapper there would not be called, and would break a compile)."""
    import importlib

    out = []
    for short in TRACK_MODULES:
        modname = f"dynslam2d.detect.{short}"
        mod = importlib.import_module(modname)
        kern = {n: v for n, v in vars(mod).items() if _is_kernel(v)}
        callees = {c for v in kern.values() for c in v.py_func.__code__.co_names}
        out += [(modname, n) for n in sorted(kern) if n not in callees]
    seen: dict[str, object] = {}
    for modname, n in out:  # (a name is a key of the tables below: one kernel per name)
        f = getattr(importlib.import_module(modname), n)
        if seen.setdefault(n, f) is not f:
            raise RuntimeError(f"two different kernels named {n} (the last in {modname}): give them distinct keys")
    if not out:
        raise RuntimeError(f"no kernel found in {TRACK_MODULES}: the track stage's modules were renamed or moved")
    return out


def check_targets(targets: list[tuple[str, str]]) -> None:
    """Raise with the stale names if a (module, name) of ``targets`` is no longer a kernel of its module."""
    import importlib

    stale = [f"{m}.{n}" for m, n in targets if not _is_kernel(getattr(importlib.import_module(m), n, None))]
    if stale:
        raise RuntimeError(f"not kernels of their modules (renamed or moved?): {', '.join(stale)}")


#: (module, name): where the track stage's modules look its kernels up (derived: :func:`track_targets`).
TARGETS = track_targets()


def warmed_scans(name: str, data: Path) -> list:
    """The scans of input ``name`` (a key of bench_digest's ``INPUTS``, ``sim:NAME`` or ``ten-movers``, bench_pipeline's
    scene; recordings under ``data``), after a throw-away pipeline ran their first :data:`WARMUP` scans (kernels
    loaded, caches warm)."""
    from dynslam2d.pipeline import Pipeline

    scans = named_scans(name, data, INPUTS)
    warm = Pipeline()
    for s in scans[:WARMUP]:
        warm.process(s)
    return scans

def _copy(args: tuple) -> tuple:
    return tuple(a.copy() if isinstance(a, np.ndarray) and a.size < BIG else a for a in args)


def run(name: str, data: Path, reps: int) -> None:
    import importlib

    from dynslam2d.detect import tracker as tracker_mod
    from dynslam2d.jitbox import njit
    from dynslam2d.pipeline import Pipeline

    @njit(cache=False)  # (a probe of the benchmark's own, a few ms to compile)
    def _noop(a: np.ndarray) -> int:
        return a.shape[0]

    @njit(cache=False)  # (… and one with 33 arguments, as many as detect_rows': 16 arrays, 17 floats)
    def _noop33(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15,  # noqa: ANN001
                f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12, f13, f14, f15, f16) -> int:  # noqa: ANN001
        return a0.shape[0]

    @njit(cache=False)  # (… and one with its 16 arrays alone: the 17 floats' price is the difference)
    def _noop16(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15) -> int:  # noqa: ANN001
        return a0.shape[0]

    clock = time.thread_time_ns
    calls: dict[str, list] = {n: [] for _, n in TARGETS}
    situ: dict[str, list] = {n: [] for _, n in TARGETS}
    noop: list[int] = []
    noop2: list[int] = []  # (the same no-op called again right after the first)
    noop33: list[int] = []  # (the 33-argument no-op, called after them)
    noop16: list[int] = []  # (the 16-array no-op, on every other scan in its place)
    on = [False]  # (inside Tracker.update)
    active = [False]  # (the measured pipeline, not the warm-up)
    undo = []

    def wrap(n: str, f):
        def timed(*a):
            if not on[0]:
                return f(*a)
            calls[n].append(_copy(a))
            t0 = clock()
            r = f(*a)
            situ[n].append(clock() - t0)
            return r
        return timed

    kernels = {}
    for modname, n in TARGETS:
        mod = importlib.import_module(modname)
        kernels[n] = getattr(mod, n)
        undo.append((mod, n, kernels[n]))
        setattr(mod, n, wrap(n, kernels[n]))
    probe = np.zeros(4)
    _noop(probe)
    arrs = [np.zeros(700) for _ in range(16)]
    args33 = (*arrs, *[float(i) for i in range(17)])
    _noop33(*args33)
    _noop16(*arrs)
    update = tracker_mod.Tracker.update

    def probed(self, *a, **k):
        if active[0]:
            t0 = clock()
            _noop(probe)
            t1 = clock()
            _noop(probe)
            t2 = clock()
            if len(noop) % 2:
                _noop16(*arrs)
            else:
                _noop33(*args33)
            t3 = clock()
            (noop16 if len(noop) % 2 else noop33).append(t3 - t2)
            noop.append(t1 - t0)
            noop2.append(t2 - t1)
        on[0] = active[0]  # (only the track stage's calls: some kernels are also called by other stages)
        try:
            return update(self, *a, **k)
        finally:
            on[0] = False

    tracker_mod.Tracker.update = probed
    try:
        scans = warmed_scans(name, data)
        pipe = Pipeline()
        active[0] = True
        with scan_loop_gc():
            for s in scans:
                pipe.process(s)
        active[0] = False
    finally:
        tracker_mod.Tracker.update = update
        for mod, n, f in undo:
            setattr(mod, n, f)
    print(f"{name}: {len(scans)} scans; thread CPU µs a call, medians: in situ / replayed warm (ratio), calls a scan, "
          "arguments a call")
    tot_s = tot_w = n_args = 0.0
    for n in dict.fromkeys(n for _, n in TARGETS):  # (a kernel looked up in two modules: one row)
        if not calls[n]:
            continue
        f = kernels[n]
        best = np.inf
        for _ in range(reps):
            ts = []
            for a in calls[n]:
                a2 = _copy(a)
                t0 = clock()
                f(*a2)
                ts.append(clock() - t0)
            best = min(best, float(np.median(ts)))
        si = float(np.median(situ[n]))
        per = len(calls[n]) / len(scans)
        tot_s += si * per
        tot_w += best * per
        na = len(calls[n][0])
        n_args += na * per
        print(f"  {n:22s} {si / 1e3:7.1f} / {best / 1e3:6.1f} (×{si / best:.2f})  {per:.2f}  {na}")
    print(f"  {'all, a scan':22s} {tot_s / 1e3:7.1f} / {tot_w / 1e3:6.1f} (×{tot_s / tot_w:.2f})  "
          f"{n_args:.0f} arguments")
    t0 = clock()
    for _ in range(10_000):
        _noop(probe)
    w1 = (clock() - t0) / 1e7
    t0 = clock()
    for _ in range(10_000):
        _noop33(*args33)
    w33 = (clock() - t0) / 1e7
    t0 = clock()
    for _ in range(10_000):
        _noop16(*arrs)
    print(f"  no-op kernel: in situ {np.median(noop) / 1e3:.2f} (called again: {np.median(noop2) / 1e3:.2f}), "
          f"warm {w1:.2f}; after it, 33 arguments: in situ {np.median(noop33) / 1e3:.2f}, warm {w33:.2f}; "
          f"16 arrays: in situ {np.median(noop16) / 1e3:.2f}, warm {(clock() - t0) / 1e7:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data, args.reps)


if __name__ == "__main__":
    main()
