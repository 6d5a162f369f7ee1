"""Cold compile of single kernels with their callees, this checkout against another (issue 13 item 2).

For each kernel named (``module.qualname`` as in ``src/dynslam2d/jitmanifest.py``), a fresh interpreter with an
empty numba cache imports the kernel's module and compiles the kernel for its manifest signature (a kernel with
explicit signatures compiles while its module is imported), with the command line's compile settings
(``jitcache.lean_numba_compile``, ``lean_compile_gc``, ``jitbox``); the process CPU of the import and compile is
the figure. Runs alternate between ``--src`` and ``--other`` (``--reps`` each) and the medians and ranges are
printed: a steadier comparison of a kernel's compile than a whole cold run on a shared machine (the functions
the kernels share, numba's ``np.empty`` and the like, are compiled in both).

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_compile_alone.py --other <base>/src [--reps 3] KERNEL...

Not run by pytest; numbers go to docs/speed.md with the command and the load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

PROBE = r"""
import sys, time
import dynslam2d.jitcache as jc
for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile", "lean_compile_gc"):
    getattr(jc, name, lambda: None)()
import dynslam2d.jitbox
from dynslam2d.jitmanifest import KERNELS
from dynslam2d.jitwarm import _dispatcher, parse_signature
sig = dict(KERNELS)[sys.argv[1]]
t0 = time.process_time()
kernel = _dispatcher(sys.argv[1])
if kernel._can_compile:
    kernel.compile(parse_signature(sig))
print(time.process_time() - t0)
"""


def compile_alone(src: str, name: str) -> float:
    """Process CPU (s) of importing ``name``'s module and compiling it from an empty cache, in a fresh process."""
    with tempfile.TemporaryDirectory(prefix="numba-alone-") as cache:
        env = dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=cache, DYNSLAM2D_COMPILE_WORKER="0")
        res = subprocess.run([sys.executable, "-c", PROBE, name], env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    return float(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kernels", nargs="+", help="module.qualname of manifest kernels")
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    ap.add_argument("--other", required=True, help="the other checkout's src folder")
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    for name in args.kernels:
        res: dict[str, list[float]] = {"this": [], "other": []}
        for i in range(args.reps):
            for which in (("this", "other") if i % 2 == 0 else ("other", "this")):
                res[which].append(compile_alone(args.src if which == "this" else args.other, name))
        med = {k: statistics.median(v) for k, v in res.items()}
        print(f"{name}: this {med['this']:.2f} s [{min(res['this']):.2f}-{max(res['this']):.2f}], "
              f"other {med['other']:.2f} s [{min(res['other']):.2f}-{max(res['other']):.2f}], "
              f"difference {med['this'] - med['other']:+.2f} s", flush=True)


if __name__ == "__main__":
    main()
