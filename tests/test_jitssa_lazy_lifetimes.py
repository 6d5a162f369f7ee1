"""numba's variable lifetimes left to its lazy ``VariableLifetime`` after each ``PostProcessor.run`` give the same
LLVM IR and results, and the command line's kernels are of the kinds that never read them (dynslam2d.jitssa
``lazy_lifetimes``, issue 13 item 2, docs/speed.md pass cmp70)."""

from __future__ import annotations

import inspect
import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")

#: argv[1] "lazy": dynslam2d.jitssa installed; "eager": installed with the lifetimes computed in every run (numba's
#: way). Compiles, in fresh dispatchers, the matcher's ``gated_points``, a loop left by ``break``, a function with
#: ``literal_unroll`` over a heterogeneous tuple and one inlining an ``inline="always"`` callee (numba's inlining
#: runs ``PostProcessor.run(emit_dels=True)``); prints their LLVM IR, results and how many runs left the lifetimes
#: lazy.
CODE = r"""
import json, math, sys
import numpy as np
import numba
from numba import literal_unroll
from numba.core import postproc
from dynslam2d import jitssa
assert jitssa.install()
if sys.argv[1] == "eager":
    jitssa._LIFETIMES_LAZY[0] = False
lazy = [0, 0]
run = postproc.PostProcessor.run
def counted(self, emit_dels=False, extend_lifetimes=False):
    run(self, emit_dels=emit_dels, extend_lifetimes=extend_lifetimes)
    lazy["deadmaps" not in self.func_ir.variable_lifetime.__dict__] += 1
postproc.PostProcessor.run = counted
from dynslam2d.slam import matcher
def early_exit(n):
    k, acc = 0, 1.0
    while k < n:
        acc = acc * 1.5 - k
        if acc < 0.0:
            break
        k += 1
    return acc + k
def unrolled(n):
    t = (1, 2.5, n, 4j)
    s = 0.0
    for v in literal_unroll(t):
        s += abs(v) * n
    return s
@numba.njit(inline="always")
def hyp(a, b):
    return math.sqrt(a * a + b * b)
def inlines(x):
    s = 0.0
    for i in range(x.size):
        s += hyp(x[i], i)
    return s
rng = np.random.default_rng(7)
n = 721
ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
r = rng.uniform(0.05, 32.0, n)
r[rng.random(n) < 0.1] = np.nan
kernels = [numba.njit(matcher.gated_points.py_func), numba.njit(early_exit), numba.njit(unrolled),
           numba.njit(inlines)]
outs = [kernels[0](r, np.cos(ang), np.sin(ang), np.isfinite(r), 0.1, 30.0, 0.2, 25.0, 10.0, True),
        kernels[1](10), kernels[2](3), kernels[3](r[:50].copy())]
llvm = ["\n".join(k.inspect_llvm().values()) for k in kernels]
print(json.dumps({"llvm": llvm, "out": [np.asarray(o).tolist() for o in outs[0]] + [float(o) for o in outs[1:]],
                  "lazy": lazy[1], "eager": lazy[0]}))
"""


def _run(script: str, args: list[str], tmp_path: Path, tag: str) -> dict:
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path / f"numba-{tag}"))
    res = subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _masked(text: str) -> str:
    return re.sub(r"0x[0-9a-fA-F]+", "0x?", text)


def test_same_llvm_ir_and_results_with_lazy_lifetimes(tmp_path: Path) -> None:
    eager, lazy = _run(CODE, ["eager"], tmp_path, "eager"), _run(CODE, ["lazy"], tmp_path, "lazy")
    assert eager["lazy"] == 0 and eager["eager"] > 20  # numba's way: every run computed them
    assert lazy["lazy"] > 20 and lazy["eager"] > 0  # most runs left them lazy; del-emitting and unrolling runs did not
    assert len(lazy["llvm"]) == 4 and all(lazy["llvm"])
    for theirs, ours in zip(eager["llvm"], lazy["llvm"]):
        assert _masked(ours) == _masked(theirs)
    assert lazy["out"] == eager["out"]


def test_first_commands_kernels_never_read_lifetimes() -> None:
    """The kernels the command line compiles are nopython, no generators, and their modules use no object mode and
    no ``literal_unroll``: the IR readers of the lifetimes ``lazy_lifetimes`` leaves lazy (object-mode lowering,
    loop lifting, generators) never run, and numba's unroller gets its lifetimes computed (test above)."""
    import importlib

    from dynslam2d.jitmanifest import KERNELS

    modules = {name.rsplit(".", 1)[0] for name, _ in KERNELS}
    assert len(modules) > 10
    for name, _ in KERNELS:
        module, qualname = name.rsplit(".", 1)
        kernel = getattr(importlib.import_module(module), qualname)
        func = getattr(kernel, "py_func", kernel)
        assert not inspect.isgeneratorfunction(func), name
        options = getattr(kernel, "targetoptions", {})
        assert not options.get("forceobj") and options.get("nopython", True), name
    for module in modules:
        text = Path(importlib.import_module(module).__file__).read_text()
        for word in ("objmode", "forceobj", "literal_unroll", "looplift"):
            assert word not in text, (module, word)
