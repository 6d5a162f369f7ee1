"""Instructions per scan of ``Pipeline.process`` under valgrind's callgrind (not run by pytest).

Wall time and even thread CPU time on a shared, busy machine cannot resolve a 2-5 % per-scan change between two
checkouts; the number of instructions executed can (it does not depend on what else runs). For each checkout this
script

  1. reads the input's first ``--warm + --scans`` scans into memory here and pickles them (no bag decoding under
     valgrind);
  2. runs the child (this file, ``--child``) once under valgrind with 0 scans, so that the numba cache is warm:
     valgrind presents a different CPU (no AVX-512) to LLVM, so numba's cache entries written by a native run do
     not match and the first run under valgrind compiles every kernel (~10 min under valgrind);
  3. runs the child under ``valgrind --tool=callgrind --instr-atstart=no``: it loads the scans, warms a throw-away
     pipeline over the first ``--warm`` scans (``bench_pipeline.warm_up``, the numba cache load; not instrumented),
     builds a fresh ``Pipeline``, switches instrumentation on (``callgrind_control -i on <pid>``), runs
     ``Pipeline.process`` over the first ``--scans`` scans in ``bench_pipeline.scan_loop_gc``, switches it off;
  4. runs the same child with 0 scans and subtracts its count (the cost of the two switches);

and reports instructions (callgrind ``Ir``) per scan, and with ``--other`` the ratio this / other. Numba's
machine code is counted (valgrind runs it like any code; the default ``--smc-check=all-non-file`` covers code
written to anonymous memory). ``PYTHONHASHSEED=0`` in the children for repeatable dict/set order.

    python benchmarks/bench_instructions.py [--src src] [--other <base>/src] [--scans 150] [--reps 1]
        [--input "negative_2 /left_scan"] [--data ../shared/data]

Runtime: about 1 min per child once that cache is warm (20 scans; valgrind runs instrumented code ~50x slower),
plus ~10 min per checkout the first time.
"""

from __future__ import annotations

import argparse
import os
import pickle
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def _toggle(on: bool) -> None:
    """Callgrind instrumentation of this process on or off (no-op outside valgrind)."""
    if os.environ.get("INS_UNDER_VALGRIND") != "1":
        return
    subprocess.run(["callgrind_control", "-i", "on" if on else "off", str(os.getpid())],
                   check=True, capture_output=True)


def child(scans_file: Path, n: int, warm: int) -> None:
    """Warm up a throw-away pipeline, then run a fresh one over the first ``n`` scans with instrumentation on."""
    from bench_pipeline import scan_loop_gc, warm_up

    from dynslam2d.pipeline import Pipeline

    scans = pickle.loads(scans_file.read_bytes())
    warm_up(scans, warm)
    pipe = Pipeline()
    run = scans[:n]
    with scan_loop_gc():
        _toggle(True)
        for s in run:
            pipe.process(s)
        _toggle(False)


def _env(src: Path) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=f"{src}{os.pathsep}{HERE}", PYTHONHASHSEED="0")
    return env


def _child_cmd(scans_file: Path, n: int, warm: int) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--child", str(scans_file), "--scans", str(n),
            "--warm", str(warm)]


def count(src: Path, scans_file: Path, n: int, warm: int, out: Path) -> int:
    """Instructions (Ir) counted while the child's loop over ``n`` scans ran under callgrind."""
    cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}", *_child_cmd(
        scans_file, n, warm)]
    r = subprocess.run(cmd, env=dict(_env(src), INS_UNDER_VALGRIND="1"), capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError(f"valgrind child failed ({r.returncode}):\n{r.stderr[-3000:]}")
    m = re.search(r"^totals:\s*(\d+)", out.read_text(), re.M)
    if m is None:
        raise RuntimeError(f"no totals line in {out}")
    return int(m.group(1))


def per_scan(src: Path, scans_file: Path, n: int, warm: int, tmp: Path) -> float:
    """Instructions per scan of one repetition (the 0-scan child's count subtracted)."""
    full = count(src, scans_file, n, warm, tmp / "cg.n.out")
    base = count(src, scans_file, 0, warm, tmp / "cg.0.out")
    print(f"  {src}: {full} - {base} Ir -> {(full - base) / n:,.0f} Ir/scan", flush=True)
    return (full - base) / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--src", type=Path, default=REPO / "src", help="checkout's src folder")
    ap.add_argument("--other", type=Path, default=None, help="a second checkout's src folder to compare with")
    ap.add_argument("--input", default="negative_2 /left_scan", help="a name of bench_real_speed.INPUTS")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--scans", type=int, default=150, help="scans in the instrumented loop")
    ap.add_argument("--warm", type=int, default=60, help="scans of the throw-away warm-up pipeline")
    ap.add_argument("--reps", type=int, default=1, help="repetitions per checkout (alternated)")
    ap.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child, args.scans, args.warm)
        return
    from bench_real_speed import load

    scans = load(args.data, args.input)
    if not scans:
        sys.exit(f"no scans for {args.input} under {args.data}")
    n = min(args.scans, len(scans))
    srcs = [args.src.resolve()] + ([args.other.resolve()] if args.other else [])
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_instr_") as d:
        tmp = Path(d)
        scans_file = tmp / "scans.pkl"
        scans_file.write_bytes(pickle.dumps(scans[:max(n, args.warm)]))
        figs: dict[Path, list[float]] = {s: [] for s in srcs}
        for s in srcs:
            count(s, scans_file, 0, args.warm, tmp / "cg.warm.out")  # numba cache warm for valgrind's CPU
        for _ in range(args.reps):  # alternated checkouts
            for s in srcs:
                figs[s].append(per_scan(s, scans_file, n, args.warm, tmp))
    print(f"\n== {args.input}: {n} scans instrumented after a {args.warm}-scan warm-up; "
          f"{time.perf_counter() - t0:.0f} s ==")
    for s, v in figs.items():
        spread = (max(v) - min(v)) / min(v) * 100
        print(f"{str(s):<50} Ir/scan {min(v):>14,.0f} .. {max(v):>14,.0f} (spread {spread:.3f} %)")
    if args.other:
        a, b = (sorted(figs[s])[len(figs[s]) // 2] for s in srcs)
        print(f"ratio this / other: {a / b:.4f}")


if __name__ == "__main__":
    main()
