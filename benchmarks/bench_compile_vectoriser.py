"""LLVM's loop vectoriser per kernel, compile CPU in lockstep (issue 13 item 2; docs/speed.md, pass cmp60).

Runs the README's first command (``dynslam2d run --out DIR``, sim:paper) cold in a fresh interpreter, one process,
background compile off (as ``bench_compile.py``'s profile). When a named kernel's library reaches its one LLVM
optimisation (``jitbox.one_llvm_optimisation``: the linked, unoptimised module), the module is cloned and put
through numba's module pipeline and machine code, and through the same pipeline without the loop vectoriser
(``jitbox._module_pipeline`` as for a kernel in ``LOOPS_NOT_VECTORISED``) and machine code, ``--reps`` times in
alternating order, each timed in thread CPU; then the run goes on as the checkout does it. Prints per kernel the
medians of both and of the per-rep saving, and whether each optimised clone holds a vector loop (``vector.body``).
The split between the kernels' separate runs (``bench_compile_split.py``) is ±10-20 % per kernel on a loaded machine;
in lockstep both sides see the same load.

    PYTHONPATH=src python benchmarks/bench_compile_vectoriser.py detect_rows vacated_scan_kernel [--reps 3]

Kernels by their qualname (a library's name). Not run by pytest; numbers go to docs/speed.md with the load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_compile import RUN_FIRST_COMMAND, cold_probe  # noqa: E402

PROBE = r"""
import json, os, sys, time
import dynslam2d.jitcache as jc
for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile"):
    getattr(jc, name, lambda: None)()
from dynslam2d import jitbox
from numba.core import codegen
KERNELS = set(os.environ["BENCH_KERNELS"].split(","))
REPS = int(os.environ["BENCH_REPS"])
res = {}
def one(library, tuned):
    mod = library._final_module.clone()
    if tuned:  # (the study knob names every kernel for this one call)
        old = os.environ.get(jitbox.STUDY_ENV)
        os.environ[jitbox.STUDY_ENV] = "*"
        try:
            passes, builder = jitbox._module_pipeline(library, "probe.kernel", True)
        finally:
            os.environ.pop(jitbox.STUDY_ENV)
            if old is not None:
                os.environ[jitbox.STUDY_ENV] = old
    else:
        passes, builder = library._codegen._module_pass_manager()
    t0 = time.thread_time()
    passes.run(mod, builder)
    t1 = time.thread_time()
    library._codegen._tm.emit_object(mod)
    return [t1 - t0, time.thread_time() - t1, "vector.body" in str(mod)]
optimise = codegen.CPUCodeLibrary._optimize_final_module
def lockstep(self):
    if self.name in KERNELS and self.name not in res:
        reps = []
        for k in range(REPS):
            order = (False, True) if k % 2 == 0 else (True, False)
            got = {tuned: one(self, tuned) for tuned in order}
            reps.append([got[False], got[True]])
        res[self.name] = reps
    optimise(self)
codegen.CPUCodeLibrary._optimize_final_module = lockstep
""" + RUN_FIRST_COMMAND + r"""
print(json.dumps(res))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kernels", nargs="+", help="kernel qualnames")
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    os.environ["BENCH_KERNELS"] = ",".join(args.kernels)
    os.environ["BENCH_REPS"] = str(args.reps)
    data = cold_probe(args.src, PROBE)
    med = statistics.median
    print(f"load average {os.getloadavg()[0]:.2f}; thread CPU s, median of {args.reps} alternated reps")
    print("| kernel | numba's: opt + code | no loop vectoriser: opt + code | saved per rep | median | vector loops |")
    print("|---|---|---|---|---|---|")
    for name in args.kernels:
        reps = data.get(name)
        if not reps:
            print(f"| `{name}` | not optimised in this run | | | | |")
            continue
        saved = [(a[0] + a[1]) - (b[0] + b[1]) for a, b in reps]
        print(f"| `{name}` | {med(a[0] for a, _ in reps):.3f} + {med(a[1] for a, _ in reps):.3f} | "
              f"{med(b[0] for _, b in reps):.3f} + {med(b[1] for _, b in reps):.3f} | "
              f"{', '.join(f'{s:+.3f}' for s in saved)} | **{med(saved):+.3f}** | "
              f"{'yes' if reps[0][0][2] else 'no'} / {'yes' if reps[0][1][2] else 'no'} |")


if __name__ == "__main__":
    main()
