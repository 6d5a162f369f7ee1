"""llvmlite's builder placed before a block's last instruction without searching the block gives the place
llvmlite's own search gives, and the same IR (dynslam2d.jitcache ``lean_positions``, issue 13 item 2, docs/speed.md
pass cmp70)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Builds one function with llvmlite's builder (argv[1] "lean": ``lean_positions`` installed), placing instructions
#: before the entry block's terminator (as numba's ``alloca_once`` does) and before a middle instruction, and prints
#: each anchor and the module's text.
SCRIPT = r"""
import json, sys
from llvmlite import ir
from dynslam2d import jitcache
if sys.argv[1] == "lean":
    assert jitcache.lean_positions() and not jitcache.lean_positions()
i64 = ir.IntType(64)
mod = ir.Module("m")
fn = ir.Function(mod, ir.FunctionType(i64, [i64]), "f")
entry, body = fn.append_basic_block("entry"), fn.append_basic_block("body")
b = ir.IRBuilder(entry)
first = b.add(fn.args[0], ir.Constant(i64, 1))
middle = b.mul(first, ir.Constant(i64, 3))
b.branch(body)
b.position_at_end(body)
b.ret(middle)
anchors = []
for k in range(5):
    with b.goto_entry_block():  # before the terminator
        anchors.append(b._anchor)
        b.alloca(i64, name=f"slot{k}")
b.position_before(middle)
anchors.append(b._anchor)
b.sub(first, ir.Constant(i64, 2), name="early")
b.position_before(fn.blocks[1].terminator)
anchors.append(b._anchor)
print(json.dumps({"anchors": anchors, "text": str(mod)}))
"""


def _run(mode: str) -> dict:
    import json

    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    res = subprocess.run([sys.executable, "-c", SCRIPT, mode], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_same_places_and_ir_as_llvmlites_search() -> None:
    theirs, ours = _run("plain"), _run("lean")
    assert theirs["anchors"] == [2, 3, 4, 5, 6, 1, 0]
    assert ours == theirs


def test_other_llvmlite_left_alone() -> None:
    script = r"""
import json
from llvmlite.ir import builder
from dynslam2d import jitcache
before = builder.IRBuilder.position_before
jitcache.POSITION_BEFORE_SOURCE = "0" * 16
print(json.dumps([jitcache.lean_positions(), builder.IRBuilder.position_before is before]))
"""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert res.stdout.strip().splitlines()[-1] == "[false, true]"
