"""numba's reference counts lowered without the dead extracts of every member find the same meminfos and give the
same machine code; the kernels of ``NUMBA_MEMINFOS_IN`` keep numba's own lowering (dynslam2d.jitprint.lean_meminfos,
issue 13 item 2, docs/speed.md passes cmp40 and cmp43)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")

#: For each type: the types of the meminfos numba's ``get_meminfos`` finds in a value of it and the instructions it
#: emits, then the same with jitprint's.
MEMINFOS = r"""
import json
from llvmlite import ir
from numba.core import types
from numba.core.registry import cpu_target
from dynslam2d import jitprint
ctx = cpu_target.target_context
arr1, arr2 = types.float64[:], types.int32[:, ::1]
TYPES = [types.float64, types.UniTuple(types.int64, 3), arr1, arr2, types.UniTuple(arr2, 4),
         types.Tuple([types.float64, arr1, types.int64, arr2]), types.Optional(arr1), types.Optional(types.float64),
         types.Tuple([types.UniTuple(arr1, 2), types.float64]), types.Tuple([types.int64, types.boolean])]
def walk():
    out = []
    for ty in TYPES:
        fn = ir.Function(ir.Module(), ir.FunctionType(ir.VoidType(), [ctx.get_value_type(ty)]), name="f")
        b = ir.IRBuilder(fn.append_basic_block())
        found = ctx.nrt.get_meminfos(b, ty, fn.args[0])
        out.append([[str(t) for t, _ in found], len(b.block.instructions)])
    return out
numba_own = walk()
assert jitprint.lean_meminfos() and not jitprint.lean_meminfos()
print(json.dumps({"numba": numba_own, "lean": walk()}))
"""

#: Small functions with arrays, a tuple of arrays picked by a run-time index and an optional, compiled in a fresh
#: process with numba's ``get_meminfos`` (``argv[1] == "numba"``), jitprint's, or jitprint's with ``rows`` among
#: the kernels that keep numba's (``"keep"``); their assembly and each one's unoptimised IR instruction count.
ASM = r"""
import json, re, sys
import numpy as np
import numba
from numba.core import codegen
from dynslam2d import jitprint
if sys.argv[1] == "keep":
    jitprint.NUMBA_MEMINFOS_IN = frozenset({"__main__.rows"})
if sys.argv[1] != "numba":
    assert jitprint.lean_meminfos()
count = {}
add = codegen.CPUCodeLibrary.add_ir_module
def counted(self, m):
    for f in m.functions:
        count[f.name] = count.get(f.name, 0) + sum(len(b.instructions) for b in f.blocks)
    return add(self, m)
codegen.CPUCodeLibrary.add_ir_module = counted

def rows(a, b, k):
    acc = 0.0
    pair = (a, a)
    for i in range(a.shape[0]):
        x = a[i] * 2.0
        row = b[i % b.shape[0]]
        if x > 1.0:
            row = b[0]
            pair = (b[0], b[1])
        acc += x + row[0] + pair[i % 2][0]
        for j in range(k):
            acc += acc * j
    return acc, pair[1]

def opt(a, flag):
    v = a if flag else None
    s = 0.0
    if v is not None:
        s = v.sum()
    out = np.empty(3)
    out[:] = s
    return out

out = {}
for fn, sig in ((rows, "(f8[:], f8[:, :], i8)"), (opt, "(f8[:], b1)")):
    disp = numba.njit(fn)
    disp.compile(sig)
    text = next(iter(disp.inspect_asm().values()))
    out[fn.__name__] = re.sub(r"0x[0-9a-fA-F]+|\b\d{9,}\b", "?", text)
def own(name):
    return sum(n for f, n in count.items() if f.startswith(f"_ZN8__main__{len(name)}{name}B"))
print(json.dumps({"asm": out, "rows": own("rows"), "opt": own("opt")}))
"""


def _run(script: str, *args: str, cache: Path | None = None) -> dict:
    env = {"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin", "PYTHONHASHSEED": "0"}
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    out = subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_same_meminfos_fewer_instructions() -> None:
    out = _run(MEMINFOS)
    numba_own, lean = out["numba"], out["lean"]
    assert [found for found, _ in lean] == [found for found, _ in numba_own]
    assert [len(found) for found, _ in lean] == [0, 0, 1, 1, 4, 2, 1, 0, 2, 0]
    assert all(n_lean <= n_numba for (_, n_lean), (_, n_numba) in zip(lean, numba_own))
    assert sum(n for _, n in lean) < sum(n for _, n in numba_own) // 2  # (an array: 1 extract of 13)


def test_same_machine_code_kept_kernels_numbas(tmp_path: Path) -> None:
    numba_own = _run(ASM, "numba", cache=tmp_path / "a")
    lean = _run(ASM, "lean", cache=tmp_path / "b")
    keep = _run(ASM, "keep", cache=tmp_path / "c")
    assert lean["asm"] == numba_own["asm"] == keep["asm"]
    assert lean["rows"] < numba_own["rows"] and lean["opt"] < numba_own["opt"]
    assert keep["rows"] == numba_own["rows"]  # (in NUMBA_MEMINFOS_IN: numba's extracts)
    assert keep["opt"] == lean["opt"]


def test_kept_kernel_names() -> None:
    script = ("import json\nfrom dynslam2d import jitprint\n"
              "print(json.dumps([sorted(jitprint.NUMBA_MEMINFOS_IN),"
              " jitprint._mangled_stems('dynslam2d.slam.raycast.integrate_levels')]))\n")
    names, stems = _run(script)
    assert "dynslam2d.slam.raycast.integrate_levels" in names
    assert stems == ["_ZN9dynslam2d4slam7raycast16integrate_levels",
                     "_ZN7cpython9dynslam2d4slam7raycast16integrate_levels"]


def test_other_sources_left_alone() -> None:
    script = ("from dynslam2d import jitprint\n"
              "from numba.core.runtime import context\n"
              "before = context.NRTContext.get_meminfos\n"
              "jitprint.MEMINFO_SOURCES = {**jitprint.MEMINFO_SOURCES, 'StructModel.traverse': '0' * 16}\n"
              "assert not jitprint.lean_meminfos()\n"
              "assert context.NRTContext.get_meminfos is before\n"
              "print('{}')\n")
    assert _run(script) == {}
