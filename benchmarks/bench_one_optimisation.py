"""Kernels compiled with the package's one LLVM optimisation against numba's full pipeline, on a run's calls (not run by
pytest).

The kernels of ``dynslam2d.*`` modules get one LLVM optimisation (``jitbox.one_llvm_optimisation``: a compile-time
saving); a module loaded under a name outside the package gets numba's default pipelines. Some loops vectorise only
under the latter (pass neg71: ``correlative._score_pyramid``'s level loops, ×0.77 there). This runs one input with a
fresh pipeline after the warm-up (``bench_pipeline.warm_up``), records up to ``--calls`` calls of each KERNEL (as
looked up in CALLER, the module that calls it by its global name), loads the kernel's module a second time under
another name with numba's cache off for its kernels (numba names a cache file after the source file, not the module:
with the cache on, the second copy loaded the package's compilation, pass opt72), checks the two compilations return
the same and leave their arguments the same on the first 50 calls, then times both on every
recorded call, alternated, ``--rounds`` times (thread CPU, µs a call).

    PYTHONPATH=src python benchmarks/bench_one_optimisation.py negative_2/right dynslam2d.slam.correlative \
        dynslam2d.slam.correlative _score_pyramid branch_and_bound

A kernel that writes into its arguments is timed on the recorded arguments as they are after the previous rounds
(the same work for a map update or an output array). A KERNEL written ``CALLER:NAME`` is looked up in that module
instead (the tracker's kernels are called from several modules); each kernel's outside copy is loaded from the module
that defines it (its ``py_func.__module__``). The per-scan figure is the mean per call times the run's calls of the
kernel (all of them counted, ``--calls`` recorded) over its scans.

    PYTHONPATH=src python benchmarks/bench_one_optimisation.py sim:paper dynslam2d.detect.kernels_update \
        dynslam2d.detect.tracker association_gates dynslam2d.detect.trackreport:report_rows
"""

from __future__ import annotations

import argparse
import copy
import importlib
import importlib.util
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numba.core.caching import NullCache
from numba.core.dispatcher import Dispatcher

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import warm_up  # noqa: E402


def _deep(args: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple(copy.deepcopy(x) if isinstance(x, (np.ndarray, tuple)) else x for x in args)


def _equal(x: Any, y: Any) -> bool:
    if isinstance(x, tuple) or isinstance(y, tuple):
        return _same(x, y)
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        nan = np.asarray(x).dtype.kind in "fc"
        return np.array_equal(x, y, equal_nan=nan)
    return x == y or (x != x and y != y)


def _same(a: Any, b: Any) -> bool:
    a = a if isinstance(a, tuple) else (a,)
    b = b if isinstance(b, tuple) else (b,)
    return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))


def _same_call(one: Any, whole: Any, a: tuple[Any, ...]) -> bool:
    """Whether both compilations return the same and leave the arguments they write into the same."""
    ea, eb = _deep(a), _deep(a)
    return _same(one(*ea), whole(*eb)) and _same(ea, eb)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input", help=", ".join(sorted(INPUTS)) + " or any sim: scene")
    ap.add_argument("defining", help="the kernels' module (dynslam2d.slam.correlative)")
    ap.add_argument("caller", help="the module that calls them by their global names")
    ap.add_argument("kernels", nargs="+", help="NAME (looked up in CALLER) or MODULE:NAME (looked up in MODULE)")
    ap.add_argument("--calls", type=int, default=400, help="calls recorded per kernel")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()

    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    importlib.import_module(args.defining)
    where = {k.rpartition(":")[2]: importlib.import_module(k.rpartition(":")[0] or args.caller) for k in args.kernels}
    outside: dict[str, Any] = {}

    def outside_copy(name: str) -> Any:
        if name not in outside:
            defining = importlib.import_module(name)
            spec = importlib.util.spec_from_file_location("outside_" + name.replace(".", "_"), defining.__file__)
            full = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = full  # (dataclasses look their module up)
            spec.loader.exec_module(full)
            for value in vars(full).values():  # (numba's cache file is named after the source file, not the module:
                if isinstance(value, Dispatcher):  # a cached copy would load the package's compilation)
                    value._cache = NullCache()
            outside[name] = full
        return outside[name]

    rel, topic = INPUTS[args.input] if args.input in INPUTS else (args.input, None)  # (any sim: scene)
    scans = list(open_source(rel if rel.startswith("sim:") else str(args.data / rel), topic))
    warm_up(scans)
    calls: dict[str, list[tuple[Any, ...]]] = {k: [] for k in where}
    counted = dict.fromkeys(where, 0)
    kept = {k: getattr(m, k) for k, m in where.items()}

    def recorder(k: str) -> Any:
        f = kept[k]

        def rec(*a: Any) -> Any:
            counted[k] += 1
            if len(calls[k]) < args.calls:
                calls[k].append(_deep(a))
            return f(*a)
        return rec

    for k, m in where.items():
        setattr(m, k, recorder(k))
    try:
        pipe = Pipeline()
        for s in scans:
            pipe.process(s)
    finally:
        for k, f in kept.items():
            setattr(where[k], k, f)
    for k in where:
        one = kept[k]
        whole = getattr(outside_copy(one.py_func.__module__), k)
        got = calls[k]
        if not got:
            print(f"{args.input} {k}: no calls")
            continue
        same = all(_same_call(one, whole, a) for a in got[:50])
        spent = {"one": 0, "full": 0}
        for r in range(args.rounds):
            for i, a in enumerate(got):
                for tag in (("one", "full") if (r + i) % 2 else ("full", "one")):
                    f = one if tag == "one" else whole
                    t0 = time.thread_time_ns()
                    f(*a)
                    spent[tag] += time.thread_time_ns() - t0
        n = args.rounds * len(got)
        per_scan = counted[k] / len(scans) / 1e3 / n  # µs a scan per ns spent on the recorded calls
        print(f"{args.input} {k}: {len(got)} of {counted[k]} calls in {len(scans)} scans, "
              f"{'the same results' if same else 'RESULTS DIFFER'}; µs a call: one optimisation "
              f"{spent['one'] / 1e3 / n:.1f}, numba's pipeline {spent['full'] / 1e3 / n:.1f}; µs a scan: "
              f"{spent['one'] * per_scan:.2f}, {spent['full'] * per_scan:.2f}; ratio "
              f"{spent['full'] / spent['one']:.3f}")


if __name__ == "__main__":
    main()
