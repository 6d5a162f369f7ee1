"""numba's context refresh skipped only when it would install nothing: the same lowering tables and IR, registrations
made after a refresh still installed, by installing only the registries whose lists grew
(dynslam2d.jitcache.lean_refresh, issue 13 item 2, docs/speed.md passes cmp47 and cmp48)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")

#: In a fresh process (``argv[1]``: ``lean`` or ``numba``): functions that miss lookups on purpose (arrays: the
#: ``__array__`` lookup of ``make_array``; a static getitem on a tuple), compiled, then an ``@overload`` and a
#: ``lower_builtin`` defined after those compiles and used; prints each function's unoptimised IR text, the results,
#: how many registry reads a refresh of an unchanged context makes, and the lowering table's size.
PROBE = r"""
import json, sys
import numpy as np
from numba import njit, types
from numba.core import imputils
from numba.cpython import mathimpl
from numba.core.registry import cpu_target
from numba.core.typing import templates
from numba.extending import overload, type_callable
from dynslam2d import jitcache
import re
partial = [0]
if sys.argv[1] == "lean":
    assert jitcache.lean_refresh() and not jitcache.lean_refresh()
    grown = jitcache._install_grown
    def counted_grown(*args):
        done = grown(*args)
        partial[0] += done
        return done
    jitcache._install_grown = counted_grown
reads = [0]
stream = templates.BaseRegistryLoader.new_registrations
def counted(self, name):
    reads[0] += 1
    return stream(self, name)
templates.BaseRegistryLoader.new_registrations = counted
ir = {}
def keep(f):
    return {str(k): f.inspect_llvm(k) for k in f.signatures}

@njit(cache=False)
def arrays(a, b, t):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i % b.shape[0]] + t[1]
    b[0] = t[0]
    return s, a[1:].copy()

out = [arrays(np.arange(5.0), np.ones(3), (2.0, 3.0))[0]]
ir["arrays"] = keep(arrays)
ctx = cpu_target.target_context
ctx.refresh()
reads[0] = 0
ctx.refresh()
ctx.refresh()
idle_reads = reads[0]

def twice(x):  # an overload defined after the first compiles: its lowering is registered then
    pass

@overload(twice)
def _twice(x):
    return lambda x: 2.0 * x

def thrice(x):  # a lower_builtin appended to numba's builtin registry after the first compiles
    pass

@type_callable(thrice)
def _thrice_type(context):
    def typer(x):
        return types.float64
    return typer

@imputils.lower_builtin(thrice, types.float64)
def _thrice_impl(context, builder, sig, args):
    return builder.fmul(args[0], context.get_constant(types.float64, 3.0))

@njit(cache=False)
def later(x):
    return twice(x) + thrice(x)

out.append(later(1.5))
ir["later"] = keep(later)

def once(x):  # a second overload and a lower_builtin, used together in one function
    pass

@overload(once)
def _once(x):
    return lambda x: x + 1.0

def quad(x):
    pass

@type_callable(quad)
def _quad_type(context):
    def typer(x):
        return x
    return typer

@imputils.lower_builtin(quad, types.float64)
def _quad_impl(context, builder, sig, args):
    return builder.fmul(args[0], context.get_constant(types.float64, 4.0))

@mathimpl.registry.lower(quad, types.int64)  # (two registries grown before one refresh: installed in numba's order)
def _quad_int(context, builder, sig, args):
    return builder.mul(args[0], context.get_constant(types.int64, 4))

def name(obj):  # a process-independent name (no addresses)
    text = f"{getattr(obj, '__module__', None)}.{getattr(obj, '__qualname__', repr(obj))}"
    return re.sub(r" at 0x[0-9a-f]+", "", text)

def tables():  # every implementation and template in the contexts' tables, in the order numba would select them
    tctx = ctx.typing_context
    return {
        "defns": sorted((name(k), [(repr(sig), name(impl)) for sig, impl in sel.versions])
                        for k, sel in ctx._defns.items()),
        "getattrs": sorted((str(k), [(repr(sig), name(impl)) for sig, impl in sel.versions])
                           for k, sel in ctx._getattrs.items()),
        "functions": sorted((name(k), [name(type(t)) for t in v]) for k, v in tctx._functions.items()),
        "globals": sorted(name(k) for k in tctx._globals),
    }

ctx.refresh()  # the target context's refresh installs the typing registrations above too
fresh = tables()

@njit(cache=False)
def both(x, n):
    return once(x) * quad(x) + twice(x) + quad(n)

out.append(both(0.5, 3))
ir["both"] = keep(both)
print(json.dumps({"out": out, "ir": ir, "idle_reads": idle_reads, "defns": len(ctx._defns), "fresh": fresh,
                  "tables": tables(), "partial": partial[0]}))
"""


def _probe(kind: str) -> dict:
    res = subprocess.run([sys.executable, "-c", PROBE, kind], capture_output=True, text=True, timeout=300,
                         env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin", "NUMBA_DISABLE_PERFORMANCE_WARNINGS": "1",
                              "PYTHONHASHSEED": "0"})  # (numba registers some implementations in set order)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_refresh_skipped_only_when_nothing_new() -> None:
    lean, numba = _probe("lean"), _probe("numba")
    # the same results and the same unoptimised IR, also of a function using registrations made after a refresh
    assert lean["out"] == numba["out"] == [lean["out"][0], 7.5, 1.5 * 2.0 + 1.0 + 12.0]
    assert lean["ir"] == numba["ir"]
    assert lean["defns"] == numba["defns"]
    # the same tables, each key's implementations in the same order: the registrations made after the first refreshes
    # installed by installing only the registries whose lists grew (pass cmp48), in numba's order
    assert lean["fresh"] == numba["fresh"]
    assert lean["tables"] == numba["tables"]
    assert lean["partial"] > 0
    # a refresh of an unchanged context reads no registry (numba's reads every loader's lists every time)
    assert lean["idle_reads"] == 0
    assert numba["idle_reads"] > 50


def test_other_sources_leave_numba_alone() -> None:
    code = ("from dynslam2d import jitcache\n"
            "jitcache.REFRESH_SOURCES = {**jitcache.REFRESH_SOURCES, 'stream_list': '0' * 16}\n"
            "from numba.core import base\n"
            "print(jitcache.lean_refresh(), getattr(base.BaseContext.refresh, '_dynslam2d_refresh', False))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin"})
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["False", "False"]
