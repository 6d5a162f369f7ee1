"""Start-up of the README's first command, ``dynslam2d run --out DIR`` (sim:paper): cold and warm (issue 13 item 2).

Each measurement runs in a fresh interpreter (a subprocess importing dynslam2d from ``--src``):

  * ``warm``: numba's cache holds every kernel. Reports the import of the pipeline and the time from
    the script's first line (the interpreter's own start, ~0.1 s, not included) to the end of the
    first ``Pipeline.process`` call — wall and process CPU
    (CPU is what a shared machine does not inflate), and the whole run's wall / CPU;
  * ``cold`` (``--cold``): numba's cache is an empty temporary folder, so every kernel a run uses is
    compiled. Reports ``kernel_compile_s`` of summary.json (wall time inside numba's compiler during the
    run loop), the process CPU time of the whole run (cold CPU − warm CPU is the compile work) and the
    compile wall time of every kernel (including those compiled after the loop: clean-up pass). The run is
    the command line's, so with a second CPU its background compile (dynslam2d.jitwarm) takes the late
    kernels and they count neither here nor in the process CPU; ``bench_compile.py --wait`` reports both.

    python benchmarks/bench_startup.py [--reps 3] [--cold] [--src src]

Not run by pytest. Numbers go to docs/speed.md with the command that produced them.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

from scratch import scratch_dir

PROBE = r"""
import json, sys, time, resource
t_wall0 = time.perf_counter(); c0 = time.process_time()
import dynslam2d.pipeline as P
imp = (time.perf_counter() - t_wall0, time.process_time() - c0)
from numba.core import event
per_kernel = {}
class _PerKernel(event.Listener):  # outermost compile time per kernel (nested compiles inside it)
    depth = 0
    def on_start(self, ev):
        if self.depth == 0:
            self.t0 = time.perf_counter()
            d = ev.data or {}
            f = getattr(d.get("dispatcher"), "py_func", None)
            self.name = f"{f.__module__}.{f.__qualname__}" if f else "?"
        self.depth += 1
    def on_end(self, ev):
        self.depth -= 1
        if self.depth == 0:
            per_kernel[self.name] = per_kernel.get(self.name, 0.0) + time.perf_counter() - self.t0
event.register("numba:compile", _PerKernel())
orig = P.Pipeline.process
first = []
def process(self, scan):
    out = orig(self, scan)
    if not first:
        first.append((time.perf_counter() - t_wall0, time.process_time() - c0))
    return out
P.Pipeline.process = process
from dynslam2d.cli import main
out_dir = sys.argv[1]
sys.argv = ["dynslam2d", "run", "--out", out_dir, "--force", "-q"]
try:
    main()
except SystemExit:
    pass
end = (time.perf_counter() - t_wall0, time.process_time() - c0)
summary = json.load(open(out_dir + "/summary.json"))
print(json.dumps({"import": imp, "first_scan": first[0], "end": end,
                  "kernel_compile_s": summary.get("kernel_compile_s"), "per_kernel": per_kernel}))
"""


def one(src: str, cold: bool) -> dict[str, object]:
    env = dict(os.environ, PYTHONPATH=src)
    if cold:
        env["NUMBA_CACHE_DIR"] = scratch_dir("numba-cold-")
    out = scratch_dir("startup-out-")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run([sys.executable, "-c", PROBE, out + "/run"], env=env, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise SystemExit(res.stderr)
    r = json.loads(res.stdout.strip().splitlines()[-1])
    r["process_cpu_s"] = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="also measure one run from an empty numba cache")
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    args = ap.parse_args()
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("note: PYTHONDONTWRITEBYTECODE is set: every interpreter compiles the sources it imports (no .pyc), "
              "which a pip-installed package does not (measure with `env -u PYTHONDONTWRITEBYTECODE` for that)")
    one(args.src, cold=False)  # fills the default cache if needed
    warm = [one(args.src, cold=False) for _ in range(args.reps)]

    def med(key: str, i: int) -> float:
        return statistics.median(float(w[key][i]) for w in warm)  # type: ignore[index]

    print(f"warm (median of {args.reps}): import of the pipeline {med('import', 0):.2f} s wall / "
          f"{med('import', 1):.2f} s CPU; first scan done {med('first_scan', 0):.2f} s wall / "
          f"{med('first_scan', 1):.2f} s CPU after start; whole run {med('end', 0):.1f} s wall, "
          f"process CPU {statistics.median(w['process_cpu_s'] for w in warm):.1f} s")  # type: ignore[type-var]
    if args.cold:
        c = one(args.src, cold=True)
        print(f"cold (empty numba cache): kernel_compile_s {c['kernel_compile_s']} s wall in numba's compiler; "
              f"first scan done {c['first_scan'][0]:.1f} s wall; process CPU {c['process_cpu_s']:.1f} s "  # type: ignore[index]
              f"(warm: {statistics.median(w['process_cpu_s'] for w in warm):.1f} s)")  # type: ignore[type-var]
        kernels = sorted(c["per_kernel"].items(), key=lambda kv: -kv[1])  # type: ignore[union-attr]
        total = sum(t for _, t in kernels)
        print(f"compile wall per kernel ({len(kernels)} compiled, {total:.1f} s in all, incl. outside the run loop):")
        for name, t in kernels:
            print(f"  {t:7.2f} s  {100 * t / total:5.1f} %  {name}")


if __name__ == "__main__":
    main()
