"""Kernels compiled with the package's one LLVM optimisation against numba's full pipeline, on a run's calls (not run by
pytest).

The kernels of ``dynslam2d.*`` modules get one LLVM optimisation (``jitbox.one_llvm_optimisation``: a compile-time
saving); a module loaded under a name outside the package gets numba's default pipelines. Some loops vectorise only
under the latter (pass neg71: ``correlative._score_pyramid``'s level loops, ×0.77 there). This runs one input with a
fresh pipeline after the warm-up (``bench_pipeline.warm_up``), records up to ``--calls`` calls of each KERNEL (as
looked up in CALLER, the module that calls it by its global name), loads DEFINING (the kernel's module) a second time
under another name, checks the two compilations return the same on the first 50 calls, then times both on every
recorded call, alternated, ``--rounds`` times (thread CPU, µs a call).

    PYTHONPATH=src python benchmarks/bench_one_optimisation.py negative_2/right dynslam2d.slam.correlative \
        dynslam2d.slam.correlative _score_pyramid branch_and_bound

A kernel that writes into its arguments is timed on the recorded arguments as they are after the previous rounds
(the same work for a map update or an output array).
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import warm_up  # noqa: E402


def _deep(args: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple(copy.deepcopy(x) if isinstance(x, (np.ndarray, tuple)) else x for x in args)


def _same(a: Any, b: Any) -> bool:
    a = a if isinstance(a, tuple) else (a,)
    b = b if isinstance(b, tuple) else (b,)
    return len(a) == len(b) and all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input", help=", ".join(sorted(INPUTS)))
    ap.add_argument("defining", help="the kernels' module (dynslam2d.slam.correlative)")
    ap.add_argument("caller", help="the module that calls them by their global names")
    ap.add_argument("kernels", nargs="+")
    ap.add_argument("--calls", type=int, default=400, help="calls recorded per kernel")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()

    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    defining = importlib.import_module(args.defining)
    caller = importlib.import_module(args.caller)
    spec = importlib.util.spec_from_file_location("outside_" + args.defining.replace(".", "_"), defining.__file__)
    full = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = full  # (dataclasses look their module up)
    spec.loader.exec_module(full)
    rel, topic = INPUTS[args.input]
    scans = list(open_source(rel if rel.startswith("sim:") else str(args.data / rel), topic))
    warm_up(scans)
    calls: dict[str, list[tuple[Any, ...]]] = {k: [] for k in args.kernels}
    kept = {k: getattr(caller, k) for k in args.kernels}

    def recorder(k: str) -> Any:
        f = kept[k]

        def rec(*a: Any) -> Any:
            if len(calls[k]) < args.calls:
                calls[k].append(_deep(a))
            return f(*a)
        return rec

    for k in args.kernels:
        setattr(caller, k, recorder(k))
    try:
        pipe = Pipeline()
        for s in scans:
            pipe.process(s)
    finally:
        for k, f in kept.items():
            setattr(caller, k, f)
    for k in args.kernels:
        one, whole = kept[k], getattr(full, k)
        got = calls[k]
        if not got:
            print(f"{args.input} {k}: no calls")
            continue
        same = all(_same(one(*_deep(a)), whole(*_deep(a))) for a in got[:50])
        spent = {"one": 0, "full": 0}
        for r in range(args.rounds):
            for i, a in enumerate(got):
                for tag in (("one", "full") if (r + i) % 2 else ("full", "one")):
                    f = one if tag == "one" else whole
                    t0 = time.thread_time_ns()
                    f(*a)
                    spent[tag] += time.thread_time_ns() - t0
        n = args.rounds * len(got)
        print(f"{args.input} {k}: {len(got)} calls, {'the same results' if same else 'RESULTS DIFFER'}; µs a call: one "
              f"optimisation {spent['one'] / 1e3 / n:.1f}, numba's pipeline {spent['full'] / 1e3 / n:.1f}, ratio "
              f"{spent['full'] / spent['one']:.3f}")


if __name__ == "__main__":
    main()
