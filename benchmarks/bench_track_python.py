"""Where the track stage's Python (``Tracker.update`` outside its kernels) spends its time, per scan (not run by
pytest).

After a 60-scan warm-up, three pipelines run over the input (``pipeline.run``'s collector setting):

* ``clean``: ``Tracker.update`` timed as a whole and each kernel call timed (thread CPU) through a thin wrapper: the
  Python outside the kernels is the update's time less its kernels' (as ``bench_kernel_context.py``);
* ``profile``: ``cProfile`` enabled only inside ``Tracker.update`` (each kernel behind a wrapper named for it, so its
  calls show as their own rows): per function its calls a scan and its own time. The profiler's hooks inflate the
  Python (≈ 0.1–0.3 µs a call event), so the own times are also shown *scaled* so that their non-kernel sum equals
  the clean pipeline's Python a scan (an attribution by share, not a measurement of each row alone);
* ``lines``: ``sys.settrace`` on the frames of ``dynslam2d.detect`` only (the first ``--line-scans`` scans), counting
  line events (statements) per function and per line (loop bodies show as lines executed many times a scan) and
  timing each line (to the next event, less the kernels' time; untraced callees, C and numpy, are the calling
  line's); the tracer's per-event cost is calibrated so that the lines' sum equals the clean pipeline's Python, and
  each line's estimate is its time less its events × that cost (an estimate: a line's own cost is not constant).

Rows are grouped into categories: the kernels (dispatch included), numpy's C entry points (``np.empty``,
``np.array``, ``astype``, ``concatenate``, ``tolist`` …), numpy's Python wrappers, object creations (``__init__`` /
``__new__`` / dataclass constructors), the stage's own Python functions (``dynslam2d.detect``), other built-ins.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_track_python.py sim:paper sim:crowd negative_2/right
        [--data <data>] [--top 25] [--line-scans 300]

Inputs: the names of ``bench_digest.py`` or a built-in scene (``sim:NAME``).
"""

from __future__ import annotations

import argparse
import cProfile
import importlib
import linecache
import pstats
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import scan_loop_gc  # noqa: E402
from bench_track_kernels import TARGETS, warmed_scans  # noqa: E402

clock = time.thread_time_ns


class Kernels:
    """The tracker's kernels replaced, where its modules look them up, by wrappers named for them (a cProfile row
    each); ``timing`` on: each call's thread CPU time is added to ``self.ns``."""

    def __init__(self) -> None:
        self.undo: list = []
        self.timing = False
        self.ns = 0
        self.calls = 0
        for modname, n in TARGETS:
            mod = importlib.import_module(modname)
            f = getattr(mod, n)
            self.undo.append((mod, n, f))
            ns = {"f": f, "box": self, "clock": clock}
            exec(f"def {n}(*a):\n"  # noqa: S102 (the benchmark's own wrapper, named for its kernel)
                 f"    if not box.timing:\n        return f(*a)\n"
                 f"    t0 = clock()\n    r = f(*a)\n    box.ns += clock() - t0\n    box.calls += 1\n    return r\n",
                 ns)
            setattr(mod, n, ns[n])

    def restore(self) -> None:
        for mod, n, f in self.undo:
            setattr(mod, n, f)


KERNELS = {n for _, n in TARGETS}
ALLOC = ("empty", "zeros", "ones", "full", "array", "asarray", "ascontiguousarray", "concatenate", "copy", "astype",
         "arange", "stack", "vstack", "hstack", "tolist", "tobytes", "nonzero", "flatnonzero", "frombuffer",
         "empty_like", "zeros_like", "full_like", "reshape", "view", "any", "all", "sum", "max", "min", "argsort")


def category(key: tuple) -> str:
    """The category of a pstats key (file, line, name)."""
    fn, _, name = key
    if name in KERNELS:  # (the wrapper's row, and the kernel's own: numba's dispatcher reports it to the profiler)
        return "kernel (incl. dispatch)"
    if name in ("__init__", "__new__", "__post_init__") or (fn == "<string>" and name == "__init__"):
        return "object creation"
    if fn == "~":
        if "numpy" in name or "ndarray" in name:
            return "numpy C entry"
        return "other built-in"
    if "/numpy/" in fn:
        return "numpy Python wrapper"
    if "/dynslam2d/detect/" in fn:
        return "detect/ Python"
    if "/dynslam2d/" in fn:
        return "other dynslam2d Python"
    return "other Python"


def label(key: tuple) -> str:
    fn, line, name = key
    if fn == "~":
        return name
    if fn == "<string>":
        return f"<{name}> wrapper"
    return f"{Path(fn).name}:{line}({name})"


def _pipeline(scans: list, wrap_update) -> None:
    from dynslam2d.detect import tracker as tracker_mod
    from dynslam2d.pipeline import Pipeline

    update = tracker_mod.Tracker.update
    tracker_mod.Tracker.update = wrap_update(update)
    try:
        pipe = Pipeline()
        with scan_loop_gc():
            for s in scans:
                pipe.process(s)
    finally:
        tracker_mod.Tracker.update = update


def clean(scans: list, kern: Kernels) -> tuple[list, list]:
    """Per scan: ``Tracker.update``'s ns and its kernels' ns."""
    upd, ker = [], []

    def wrap(update):
        def timed(self, *a, **k):
            kern.ns = 0
            kern.timing = True
            t0 = clock()
            r = update(self, *a, **k)
            upd.append(clock() - t0)
            kern.timing = False
            ker.append(kern.ns)
            return r
        return timed

    _pipeline(scans, wrap)
    return upd, ker


def profiled(scans: list) -> pstats.Stats:
    prof = cProfile.Profile()

    def wrap(update):
        def timed(self, *a, **k):
            prof.enable()
            try:
                return update(self, *a, **k)
            finally:
                prof.disable()
        return timed

    _pipeline(scans, wrap)
    return pstats.Stats(prof)


def lines(scans: list, kern: Kernels) -> tuple[Counter, Counter, Counter]:
    """Line events of ``dynslam2d.detect``'s frames inside ``Tracker.update``: per (file, line) their count and their
    time (``perf_counter`` ns from the line's event to the next event — the next line, a call of a traced function or
    the frame's return — less the kernels' time inside it: callees that are not traced, C functions and numpy, are the
    calling line's), and per function the count."""
    per_line: Counter = Counter()
    per_ns: Counter = Counter()
    per_fn: Counter = Counter()
    detect_dir = str(REPO / "src" / "dynslam2d" / "detect")
    now = time.perf_counter_ns
    state = [None, 0, 0]  # (the line the time runs for, its start, the kernels' ns then)

    def charge() -> None:
        key = state[0]
        if key is not None:
            per_ns[key] += now() - state[1] - (kern.ns - state[2])

    def local(frame, event, arg):
        if event == "line":
            charge()
            code = frame.f_code
            key = (code.co_filename, frame.f_lineno, code.co_name)
            per_line[key] += 1
            per_fn[(code.co_filename, code.co_firstlineno, code.co_name)] += 1
            state[0] = key
            state[2] = kern.ns
            state[1] = now()
        elif event == "return":
            charge()
            state[0] = None
        return local

    def glob(frame, event, arg):
        fn = frame.f_code.co_filename
        if fn.startswith(detect_dir) or "/dynslam2d/detect/" in fn:
            charge()
            state[0] = None
            return local
        return None

    def wrap(update):
        def timed(self, *a, **k):
            kern.timing = True
            state[0] = None
            sys.settrace(glob)
            try:
                return update(self, *a, **k)
            finally:
                sys.settrace(None)
                kern.timing = False
        return timed

    _pipeline(scans, wrap)
    return per_line, per_ns, per_fn


def run(name: str, data: Path, top: int, line_scans: int) -> None:

    scans = warmed_scans(name, data)
    kern = Kernels()
    try:
        n = len(scans)
        upd, ker = clean(scans, kern)
        upd_a, ker_a = np.array(upd) / 1e3, np.array(ker) / 1e3
        py = upd_a - ker_a
        st = profiled(scans)
        per_line, per_ns, per_fn = lines(scans[:line_scans], kern)
        n_lines = min(n, line_scans)
    finally:
        kern.restore()
    print(f"\n{name}: {n} scans; clean pipeline, µs a scan (median / mean): Tracker.update "
          f"{np.median(upd_a):.1f} / {upd_a.mean():.1f}, its kernels {np.median(ker_a):.1f} / {ker_a.mean():.1f}, "
          f"the Python outside them {np.median(py):.1f} / {py.mean():.1f}")
    rows = []
    for key, (_cc, nc, tt, _ct, _callers) in st.stats.items():
        rows.append((key, category(key), nc / n, tt * 1e6 / n))
    prof_py = sum(r[3] for r in rows if r[1] != "kernel (incl. dispatch)")
    scale = py.mean() / prof_py if prof_py > 0 else 1.0
    calls_py = sum(r[2] for r in rows)
    print(f"  profiled: {calls_py:.0f} call events a scan; own time outside the kernels {prof_py:.1f} µs a scan "
          f"(profiler included) -> scale {scale:.3f} to the clean Python's mean")
    cats: dict = {}
    for _, c, calls, tt in rows:
        a = cats.setdefault(c, [0.0, 0.0])
        a[0] += calls
        a[1] += tt
    print(f"  {'category':<26} {'calls/scan':>10} {'own µs/scan (prof.)':>20} {'scaled µs':>10}")
    for c, (calls, tt) in sorted(cats.items(), key=lambda x: -x[1][1]):
        sc = tt * (scale if c != "kernel (incl. dispatch)" else 1.0)
        print(f"  {c:<26} {calls:>10.1f} {tt:>20.1f} {sc:>10.1f}")
    print(f"  top {top} rows by own time outside the kernels (µs a scan; scaled = attribution by share):")
    print(f"  {'function':<58} {'category':<22} {'calls/scan':>10} {'prof µs':>8} {'scaled':>7} {'ns/call':>8}")
    for key, c, calls, tt in sorted((r for r in rows if r[1] != "kernel (incl. dispatch)"), key=lambda r: -r[3])[:top]:
        print(f"  {label(key)[:58]:<58} {c[:22]:<22} {calls:>10.2f} {tt:>8.2f} {tt * scale:>7.2f} "
              f"{1e3 * tt * scale / calls if calls else 0:>8.0f}")
    print("  kernel rows (calls a scan, µs a scan incl. the profiler's wrapper):")
    for key, _c, calls, tt in sorted((r for r in rows if r[1] == "kernel (incl. dispatch)"), key=lambda r: -r[3]):
        print(f"    {label(key):<28} {calls:>6.2f} {tt:>7.1f}")
    allocs = [(label(k), calls, tt * scale) for k, c, calls, tt in rows
              if c == "numpy C entry" and any(a in k[2] for a in ALLOC)]
    print(f"  numpy C entries (allocations, conversions, reductions): {sum(a[1] for a in allocs):.1f} calls, "
          f"{sum(a[2] for a in allocs):.1f} µs (scaled) a scan; by calls: "
          + ", ".join(f"{lab.replace('numpy.ndarray', 'ndarray')} {c:.1f} ({u:.1f} µs)"
                      for lab, c, u in sorted(allocs, key=lambda a: -a[1])[:10]))
    news = [(label(k), calls) for k, c, calls, tt in rows if k[2].startswith("<built-in method __new__")]
    print("  object.__new__ calls a scan (in-place report / detection objects): " + ", ".join(
        f"{c:.1f}" for _, c in news))
    inits = [(label(k), calls) for k, c, calls, tt in rows if c == "object creation"]
    print("  object creations a scan: " + ", ".join(f"{lab} {c:.1f}" for lab, c in sorted(inits, key=lambda x: -x[1])
                                                    [:8]))
    tot_lines = sum(per_fn.values()) / n_lines
    print(f"  statements (line events, dynslam2d.detect frames) over {n_lines} scans: {tot_lines:.0f} a scan; "
          f"top functions:")
    for key, c in per_fn.most_common(top // 2):
        print(f"    {Path(key[0]).name}:{key[1]}({key[2]}) {c / n_lines:.1f}")
    # the per-event cost of the tracer, calibrated: the traced lines' time less n events × o equals the clean
    # pipeline's Python a scan (its mean over the same scans); the estimate of a line is its time less its events × o
    traced = sum(per_ns.values()) / n_lines / 1e3
    events = sum(per_line.values()) / n_lines
    py_same = py[:n_lines].mean()
    o = max(traced - py_same, 0.0) / events if events else 0.0
    print(f"  line timing: traced {traced:.1f} µs a scan outside the kernels over {events:.0f} line events; "
          f"per-event cost o = {1e3 * o:.0f} ns (so that the sum is the clean mean {py_same:.1f} µs)")
    est = {k: per_ns[k] / n_lines / 1e3 - o * per_line[k] / n_lines for k in per_line}
    fn_est: Counter = Counter()
    for k, v in est.items():
        fn_est[(Path(k[0]).name, k[2])] += v
    print("  per function (estimate, µs a scan): " + ", ".join(f"{f}:{nm} {v:.1f}" for (f, nm), v in
                                                             fn_est.most_common(12)))
    print(f"  top {top} lines by estimated µs a scan (executions a scan: a loop body's count is its iterations):")
    for k, v in sorted(est.items(), key=lambda x: -x[1])[:top]:
        src = linecache.getline(k[0], k[1]).strip()
        print(f"    {Path(k[0]).name}:{k[1]:<4} {per_line[k] / n_lines:>6.1f} {v:>6.2f}  {src[:70]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--line-scans", type=int, default=300)
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data, args.top, args.line_scans)


if __name__ == "__main__":
    main()
