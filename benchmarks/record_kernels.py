"""Write ``src/dynslam2d/jitmanifest.py``: the kernels the README's first command compiles, in order of first use,
with their signatures and compile times (what the background compile of a cold first run compiles, docs/speed.md).

    PYTHONPATH=src python benchmarks/record_kernels.py [--out src/dynslam2d/jitmanifest.py]

Runs ``dynslam2d run`` (sim:paper) in a fresh interpreter with an empty numba cache and the background compile
off, and records every dynslam2d kernel numba compiles (``numba:compile`` events) with the moment its compile
started and its compile's CPU time (the kernels it compiles in turn included); then runs it again on the filled
cache and keeps the kernels that run holds: those the code calls from Python (a kernel only called by other kernels
is compiled, and cached, with its caller). Re-run it after adding a kernel or changing a kernel's argument types;
tests/test_jitwarm.py fails while the manifest and a real run disagree. The compile times order the background
compile (``jitwarm.compile_balanced``); only their ratios matter.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from bench_compile import RUN_FIRST_COMMAND  # (benchmarks/ is on sys.path when this script runs)
from scratch import scratch_dir

PROBE = r"""
import json, sys, time
import dynslam2d.jitcache as jc
jc.plain_numba_errors(); jc.load_blas_alone()
from numba.core import event
from dynslam2d.jitwarm import signature_text
seen, took, stack = {}, {}, []
class FirstUse(event.Listener):
    def on_start(self, ev):
        d = ev.data or {}
        f = getattr(d.get("dispatcher"), "py_func", None)
        key = None
        if f is not None and f.__module__.startswith("dynslam2d"):
            key = (f"{f.__module__}.{f.__qualname__}", signature_text(d["args"]))
            seen.setdefault(key, time.perf_counter())
        stack.append((key, time.process_time()))
    def on_end(self, ev):
        key, t0 = stack.pop()
        if key is not None:
            took.setdefault(key, time.process_time() - t0)
event.register("numba:compile", FirstUse())
""" + RUN_FIRST_COMMAND + r"""
print(json.dumps([[*k, took.get(k, 0.0)] for k in sorted(seen, key=seen.get)]))
"""

WARM = r"""
import json, sys
from numba.core.registry import CPUDispatcher
from dynslam2d.jitwarm import signature_text
""" + RUN_FIRST_COMMAND + r"""
held = [[f"{name}.{attr}", signature_text(sig)] for name, mod in list(sys.modules.items())
        if mod is not None and name.startswith("dynslam2d") for attr, obj in vars(mod).items()
        if isinstance(obj, CPUDispatcher) and obj.__module__ == name for sig in obj.signatures]
print(json.dumps(held))
"""

HEADER = '''"""The kernels a first run of ``dynslam2d run`` (sim:paper, default configuration) compiles, in order of
first use, with the argument types of each (numba type names) and its compile time: what :mod:`dynslam2d.jitwarm`
compiles in a second process while a cold run compiles in its own order.

Written by ``benchmarks/record_kernels.py`` (do not edit by hand); tests/test_jitwarm.py checks it against the
signatures the kernels hold after a real run. A kernel missing here is compiled by the run itself, as before.
"""

#: (module.qualname, argument types) in order of first use; one signature per kernel.
KERNELS: tuple[tuple[str, str], ...] = (
'''

COSTS = '''
#: CPU time of each kernel's compile (s, the kernels it compiles in turn included) in a one-core cold run when
#: recorded: the background compile's estimate of how far ahead of the run a kernel is (its order, docs/speed.md).
COMPILE_S: dict[str, float] = {
'''


def _last_json(code: str, out: str, env: dict[str, str]) -> list:
    res = subprocess.run([sys.executable, "-c", code, out], env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def _chunks(text: str, width: int = 100) -> list[str]:
    """``text`` cut after ", " into pieces of at most about ``width`` characters (adjacent string literals)."""
    parts, line = [], ""
    for piece in text.split(", "):
        piece = piece + ", "
        if line and len(line) + len(piece) > width:
            parts.append(line)
            line = ""
        line += piece
    parts.append(line[:-2])
    return parts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = Path(__file__).resolve().parents[1] / "src"
    ap.add_argument("--out", type=Path, default=src / "dynslam2d" / "jitmanifest.py")
    args = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=scratch_dir("numba-record-"),
               DYNSLAM2D_COMPILE_WORKER="0")
    out = scratch_dir("record-kernels-") + "/run"
    timed, held = (_last_json(code, out, env) for code in (PROBE, WARM))
    took = {(name, sig): s for name, sig, s in timed}
    kernels = [k for k in took if k in {tuple(h) for h in held}]
    names = [name for name, _ in kernels]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise SystemExit(f"a kernel compiled for two signatures in one run: {twice}")
    body = "".join(f"    ({name!r},\n     " + "\n     ".join(repr(part) for part in _chunks(sig)) + "),\n"
                   for name, sig in kernels)
    costs = "".join(f"    {name!r}: {took[name, sig]:.2f},\n" for name, sig in kernels)
    args.out.write_text(HEADER + body + ")\n" + COSTS + costs + "}\n")
    print(f"{len(kernels)} kernels -> {args.out}")


if __name__ == "__main__":
    main()
