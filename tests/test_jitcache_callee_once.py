"""A lazy callee linked by several kernels is optimised once, in the first, and linked optimised into the others
(dynslam2d.jitcache.CALLEE_OPTIMISED_ONCE, issue 13 item 2, docs/speed.md pass cmp49)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: argv[1] "1": the probe's callee in CALLEE_OPTIMISED_ONCE, "0": each caller optimises it (cmp41's way). Three
#: kernels of a module named inside the package (so that numba's compiles are a dynslam2d kernel's) call one callee;
#: every run of an LLVM module pipeline records whether the module holds the callee's unoptimised definition. Prints
#: the results, the pipelines that saw the callee, and each caller's functions' assembly (labels numbered per
#: function, constants' numbered suffixes dropped).
SCRIPT = r'''
import json, re, sys, types
import numpy as np
import llvmlite.binding as ll
from dynslam2d import jitbox, jitcache
MOD = "dynslam2d._callee_once_probe"
if sys.argv[1] == "1":
    jitcache.CALLEE_OPTIMISED_ONCE = frozenset({MOD + ".callee"})
assert jitcache.lazy_callee_code()
source = """
import math
import numpy as np
from numba import njit
@njit
def callee(a, k):
    out = np.empty(a.size)
    n = a.size
    for i in range(n):
        v = math.sqrt(abs(a[i])) * k + i
        if v > 10.0:
            v = math.log(v)
        w = abs(a[i]) / v if v > 0.0 else math.nan  # (a select, and below an integer remainder by a variable:
        out[i] = v / (1.0 + a[i] * a[i]) + w + (i * 7 + int(v)) % n  # what LLVM's code generator rewrites in place)
    if a.size == 0:
        raise ValueError("empty")
    return out
@njit
def first(a):
    return callee(a, 2.0).sum()
@njit
def second(a):
    return callee(a * 2.0, 3.0)[::2].sum()
@njit
def third(a, k):
    return callee(a, k)[-1] + callee(a[1:], k + 1.0)[0]
"""
module = types.ModuleType(MOD)
sys.modules[MOD] = module
exec(compile(source, "<callee_once_probe>", "exec"), module.__dict__)
seen = []
from numba.core import codegen
full = codegen.CPUCodegen._module_pass_manager
def marked(self, *args, **kwargs):
    passes, builder = full(self, *args, **kwargs)
    passes._probe_full = True
    return passes, builder
codegen.CPUCodegen._module_pass_manager = marked
run = ll.ModulePassManager.run
def counted(self, mod, pb):
    if not getattr(self, "_probe_full", False):  # (not numba's module pipeline)
        return run(self, mod, pb)
    seen.append([f.name for f in mod.functions if not f.is_declaration and "6callee" in f.name
                 and jitcache.UNUSED_SUFFIX not in f.name])
    return run(self, mod, pb)
ll.ModulePassManager.run = counted
a = np.linspace(-3.0, 7.0, 41)
res = [module.first(a), module.second(a), module.third(a, 1.5)]
def asm(lib):
    text = lib._codegen._tm.emit_assembly(lib._final_module.clone())
    funcs, cur, body = {}, None, []
    for line in text.splitlines():
        m = re.match(r"^([A-Za-z_$][\w.$]*):\s*$", line)
        if m and cur is None:
            cur, body = m.group(1), []
        elif cur is not None and line.startswith(".Lfunc_end"):
            t = re.sub(r"(\.const\.\w+\.[0-9a-f]{40}(?:\.sha1)?)(?:\.\d+)*", r"\1", "\n".join(body))
            labels = {}
            local = lambda x: labels.setdefault(x.group(0), f".L{len(labels)}")
            funcs[cur] = re.sub(r"\.L(?:BB|CPI|tmp)\d+_\d+", local, t)
            cur = None
        elif cur is not None:
            body.append(line)
    return funcs
out = {}
for name in ("first", "second", "third"):
    (cres,) = getattr(module, name).overloads.values()
    out[name] = asm(cres.library)
libs = [next(iter(getattr(module, n).overloads.values())).library for n in ("first", "second", "third")]
unused = any(jitcache.UNUSED_SUFFIX in f.name for lib in libs for f in lib._final_module.functions)
print(json.dumps({"res": [float(r) for r in res], "seen": seen, "asm": out, "unused": unused}))
'''


def test_callee_optimised_once_same_code(tmp_path):
    """With the callee in CALLEE_OPTIMISED_ONCE only the first caller's pipeline holds its unoptimised definition
    (each of the three does without), the results are the same, no caller keeps the unused copy, and every function
    of every caller (the callee's copy in each among them) compiles to the same assembly."""
    got = {}
    for on in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{on}"), "PYTHONHASHSEED": "0"}
        r = subprocess.run([sys.executable, "-c", SCRIPT, on], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[on] = json.loads(r.stdout.strip().splitlines()[-1])
    old, new = got["0"], got["1"]
    assert old["res"] == new["res"]
    assert sum(map(bool, old["seen"])) == 3 and sum(map(bool, new["seen"])) == 1
    assert not new["unused"] and not old["unused"]
    for name in ("first", "second", "third"):
        assert sorted(old["asm"][name]) == sorted(new["asm"][name])
        assert any("callee" in f for f in new["asm"][name])
        for f, text in old["asm"][name].items():
            assert new["asm"][name][f] == text, (name, f)
