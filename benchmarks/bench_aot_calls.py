"""Per-call cost of a kernel through the AOT module's checking wrapper (dynslam2d.jitaot), its raw export and
numba's dispatcher (warm cache), each in a fresh process, alternated.

    PYTHONPATH=src python benchmarks/bench_aot_calls.py [--rounds 5] [--calls 20000]

Needs a valid AOT module (``dynslam2d kernels build``; ``DYNSLAM2D_KERNELS_DIR`` chooses its folder). Kernels timed:
``detect.freespace._ref_arrays`` (9 arguments: 2 arrays, 7 floats) and ``slam.correlative._score_pyramid`` (a
float32 2-D array, an int). Prints the median ns per call of each way and the wrapper's overhead over the export.
Not run by pytest; numbers go to docs/speed.md (pass aot41).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

PROBE = r"""
import json, sys, time
import numpy as np
mode, calls = sys.argv[1], int(sys.argv[2])
from dynslam2d.detect.freespace import _ref_arrays
from dynslam2d.slam.correlative import _score_pyramid
from dynslam2d import jitbox
r = np.linspace(1.0, 5.0, 360)
ok = np.ones(360, dtype=bool)
prob = (np.random.default_rng(0).random((40, 40)).astype(np.float32).view(np.uint32)
        ^ np.uint32(0x3F000000))  # (a level's probability cache words, slam/grid.py encode_probs)
cases = {"_ref_arrays": (_ref_arrays, (r, ok, -1.5, 0.01, 0.0, 0.0, 0.0, 0.1, 30.0)),
         "_score_pyramid": (_score_pyramid, (prob, 2))}
out = {"aot": jitbox.AOT is not None}
for name, (fn, args) in cases.items():
    ways = {"call": fn}
    if mode == "aot":
        ways["export"] = next(e for e, _t in jitbox.AOT.exports[fn.__module__ + "." + fn.__qualname__])
    for way, f in ways.items():
        f(*args)
        best = []
        for _ in range(5):
            t0 = time.perf_counter_ns()
            for _ in range(calls):
                f(*args)
            best.append((time.perf_counter_ns() - t0) / calls)
        out[f"{name} {way}"] = min(best)
print(json.dumps(out))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--calls", type=int, default=20000)
    args = ap.parse_args()
    rows: dict[str, list[float]] = {}
    for k in range(args.rounds):
        for mode in ("aot", "jit") if k % 2 == 0 else ("jit", "aot"):
            env = dict(os.environ, DYNSLAM2D_KERNELS="jit" if mode == "jit" else "auto")
            res = subprocess.run([sys.executable, "-c", PROBE, mode, str(args.calls)], env=env, capture_output=True,
                                 text=True, check=True)
            out = json.loads(res.stdout.strip().splitlines()[-1])
            if out.pop("aot") != (mode == "aot"):
                raise SystemExit("no valid AOT module: dynslam2d kernels build")
            for key, ns in out.items():
                rows.setdefault(f"{mode} {key}", []).append(ns)
    med = {k: statistics.median(v) for k, v in rows.items()}
    for k in sorted(med):
        print(f"{k:<32} {med[k]:8.0f} ns per call (median of {args.rounds} processes, best of 5 loops each)")
    for name in ("_ref_arrays", "_score_pyramid"):
        print(f"{name}: wrapper - export {med[f'aot {name} call'] - med[f'aot {name} export']:.0f} ns; "
              f"wrapper / numba dispatcher x{med[f'aot {name} call'] / med[f'jit {name} call']:.2f}")


if __name__ == "__main__":
    main()
