"""The llvmlite IR modules numba has handed to LLVM freed by reference counting once their compile ends, the same
code (dynslam2d.jitcache ``free_spent_ir``, issue 13 item 2, docs/speed.md pass cmp71)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Compiles three functions (argv[1] "lean": ``free_spent_ir`` installed first) with the collector off — a callee
#: compiled inside its caller's compile, array helpers numba compiles for them, a loop with branches — then a fourth
#: after the first three's modules are gone (numba's shared constants such as ``cgutils.true_bit`` must survive), and
#: prints each function's LLVM IR, its results, and the llvmlite IR objects the collector then finds dead.
SCRIPT = r"""
import gc, json, sys
import numpy as np
from numba import njit
from dynslam2d import jitbox, jitcache  # (jitbox's array boxer in both: free_spent_ir imports it)
if sys.argv[1] == "lean":
    assert jitcache.free_spent_ir() and not jitcache.free_spent_ir()
gc.disable()

@njit(cache=False)
def callee(x, k):
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = x[i] * k if x[i] > 0 else -x[i]
    return out

@njit(cache=False)
def caller(x):
    s = 0.0
    y = callee(x, 2.0)
    for i in range(y.size):
        if y[i] > 1.5:
            s += y[i]
        elif y[i] < 0.5:
            break
    return s, np.zeros((2, x.size))

@njit(cache=False)
def counts(a):
    n = np.zeros(4, np.int64)
    for v in a:
        n[v % 4] += 1
    return n

@njit(cache=False)
def later(a, b):
    return (a > b) and not (a == 0)

x = np.array([1.0, -2.0, 3.0, 0.25, 4.0])
res = [caller(x)[0], counts(np.arange(11)).tolist()]
gc.set_debug(gc.DEBUG_SAVEALL)
gc.collect()
dead = sum(1 for o in gc.garbage if type(o).__module__.startswith("llvmlite.ir"))
gc.set_debug(0)
gc.garbage.clear()
res.append([later(3, 2), later(0, -1), later(1, 2)])
ir = {f.__name__: [f.inspect_llvm(sig) for sig in f.signatures] for f in (callee, caller, counts, later)}
print(json.dumps({"res": res, "dead": dead, "ir": ir}))
"""


def _run(mode: str, tmp_path: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), NUMBA_CACHE_DIR=str(tmp_path / mode))
    res = subprocess.run([sys.executable, "-c", SCRIPT, mode], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_modules_freed_without_the_collector_and_the_same_code(tmp_path: Path) -> None:
    theirs, ours = _run("plain", tmp_path), _run("lean", tmp_path)
    assert theirs["dead"] > 2000  # numba's own: every instruction, block and function in cycles
    assert ours["dead"] < theirs["dead"] / 50
    assert ours["res"] == theirs["res"] == [18.0, [3, 3, 3, 2], [True, False, False]]
    assert ours["ir"] == theirs["ir"]


#: ``free_spent_ir`` with numba's ``add_ir_module`` (argv[1] "numba") or llvmlite's ``ir`` sources ("llvmlite") not as
#: checked: prints whether it installed and whether numba's method is still its own.
LEFT_ALONE = r"""
import json, sys
from numba.core import codegen
from dynslam2d import jitcache, jitprint
before = codegen.CPUCodeLibrary.add_ir_module
if sys.argv[1] == "numba":
    jitcache.ADD_IR_MODULE_SOURCE = "0" * 16
else:
    jitprint.SOURCES = {**jitprint.SOURCES, "values": "0" * 16}
print(json.dumps([jitcache.free_spent_ir(), codegen.CPUCodeLibrary.add_ir_module is before]))
"""


def test_other_numba_or_llvmlite_left_alone() -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    for which in ("numba", "llvmlite"):
        res = subprocess.run([sys.executable, "-c", LEFT_ALONE, which], env=env, capture_output=True, text=True,
                             check=True)
        assert json.loads(res.stdout.strip().splitlines()[-1]) == [False, True], which
