"""llvmlite's IR printer with less Python work and numba's ABI-size queries remembered give the same module text,
the same caches on llvmlite's objects and the same sizes (dynslam2d.jitprint, issue 13 item 2, docs/speed.md pass
cmp39)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")

#: Compiles the first ``argv[1]`` kernels of the README's first command (jitmanifest order, their callees and numba's
#: helpers with them) in fresh dispatchers, every module numba adds to a library printed with llvmlite's printer and
#: with jitprint's from the same caches, texts and caches compared; every ABI query both ways
#: (benchmarks/check_jitprint.py).
SHADOW = r"""
import json, os, sys, tempfile
os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(dir=sys.argv[3])
sys.path.insert(0, sys.argv[2])
import numba
from dynslam2d import jitcache, jitmanifest, jitwarm
jitcache.lean_numba_compile()
from check_jitprint import shadow
stats = shadow()
for name, sig in jitmanifest.KERNELS[: int(sys.argv[1])]:
    module, _, qual = name.rpartition(".")
    disp = getattr(__import__(module, fromlist=[qual]), qual)
    numba.njit(disp.py_func).compile(jitwarm.parse_signature(sig))
print(json.dumps(stats))
"""

#: One function using every instruction class jitprint formats, with the variants each one's text has (flags,
#: alignment, metadata, an alloca's count, a void call, names that need escaping), built twice: printed with
#: llvmlite's ``Block.descr`` and with jitprint's; both texts and which classes jitprint formatted.
CLASSES = r"""
import json
from llvmlite import ir
from dynslam2d import jitprint
assert jitprint.fast_blocks() and not jitprint.fast_blocks()
def build():
    m = ir.Module(name="m")
    i64, f64, i8p = ir.IntType(64), ir.DoubleType(), ir.IntType(8).as_pointer()
    pair = ir.LiteralStructType([i64, f64])
    fn = ir.Function(m, ir.FunctionType(i64, [i64, f64, pair, i8p]), name="f")
    sink = ir.Function(m, ir.FunctionType(ir.VoidType(), [i64]), name="sink")
    n, x, p, q = fn.args
    n.name, x.name = 'n"quoted', "x\\back"
    b = ir.IRBuilder(fn.append_basic_block("entry"))
    other, end = fn.append_basic_block("other block"), fn.append_basic_block("end")
    md = m.add_metadata([ir.Constant(i64, 7)])
    a1 = b.alloca(i64, name="a1")
    a2 = b.alloca(f64, size=ir.Constant(i64, 4), name="a2")
    a2.align = 16
    a3 = b.alloca(pair)
    a3.set_metadata("tag", md)
    st = b.store(n, a1)
    st2 = b.store(x, b.gep(a2, [ir.Constant(i64, 1)], inbounds=True))
    st2.align = 8
    st2.set_metadata("tag", md)
    v = b.load(a1, name="v")
    w = b.load(b.gep(a3, [ir.Constant(i64, 0), ir.Constant(ir.IntType(32), 1)]), name="w", align=8)
    w.set_metadata("tag", md)
    e = b.extract_value(p, 1, name="e")
    e2 = b.extract_value(p, [0])
    e2.set_metadata("tag", md)
    s = b.add(v, n, name="s", flags=["nsw"])
    s2 = b.fadd(w, e, flags=["fast"])
    s3 = b.mul(s, ir.Constant(i64, 3))
    s3.set_metadata("tag", md)
    s4 = b.xor(s3, s)
    ins = b.insert_value(p, s2, 1, name="ins")
    ins2 = b.insert_value(ins, s4, [0])
    ins2.set_metadata("tag", md)
    c = b.icmp_signed("<", s4, ir.Constant(i64, 0), name="c")
    c2 = b.fcmp_ordered(">=", s2, ir.Constant(f64, 1.5), flags=["nnan", "ninf"])
    c2.set_metadata("tag", md)
    c3 = b.fcmp_unordered("!=", s2, e)
    sel = b.select(c, s4, s3, name="sel")
    sel2 = b.select(c2, s2, e)
    sel2.set_metadata("tag", md)
    z = b.zext(c3, i64, name="z")
    fl = b.sitofp(sel, f64)
    bc = b.bitcast(a1, i8p)
    bc.set_metadata("tag", md)
    b.call(sink, [z])
    br = b.cbranch(c, other, end)
    br.set_metadata("tag", md)
    b = ir.IRBuilder(other)
    b.store(fl, b.bitcast(bc, f64.as_pointer()))
    b.branch(end)
    b = ir.IRBuilder(end)
    b.ret(sel)
    g = ir.Function(m, ir.FunctionType(ir.VoidType(), []), name="g")
    r = ir.IRBuilder(g.append_basic_block()).ret_void()
    r.set_metadata("tag", md)
    return m
plain = jitprint.block_descr.__wrapped__
fast = ir.values.Block.descr
ir.values.Block.descr = plain
theirs = str(build())
ir.values.Block.descr = fast
module = build()
ours = str(module)
used = sorted({type(i).__name__ for f in module.functions for b in f.blocks for i in b.instructions
               if type(i) in jitprint._FAST})
print(json.dumps({"same": theirs == ours, "formatted": used, "lines": len(ours.splitlines())}))
"""

#: Sizes and alignments of types whose two differ (and an identified struct, which is not remembered), asked twice
#: (the second answer from memory) after jitprint's install, against llvmlite's own queries.
ABI = r"""
import json
from llvmlite import ir
import llvmlite.binding as ll
from dynslam2d import jitprint
ll.initialize_native_target()
td = ll.create_target_data("e-m:e-p270:32:32-p271:32:32-p272:64:64-i64:64-f80:128-n8:16:32:64-S128")
i8, i64, f64 = ir.IntType(8), ir.IntType(64), ir.DoubleType()
ctx = ir.Context()
named = ctx.get_identified_type("jitprint_test")
named.set_body(i8, i64)
kinds = [i8, ir.IntType(1), i64, f64, ir.ArrayType(i8, 3), ir.LiteralStructType([i64, f64, i8]),
         ir.LiteralStructType([i8, i8]), i8.as_pointer(), ir.ArrayType(ir.LiteralStructType([f64, i8]), 5)]
def both(t, context=None):
    return [t.get_abi_size(td, context), t.get_abi_alignment(td, context)]
theirs = [both(t) for t in kinds]
named_theirs = both(named, ctx)
assert jitprint.abi_sizes() and not jitprint.abi_sizes()
ours = [both(t) for t in kinds] + [both(t) for t in kinds]
named_ours = [both(named, ctx), both(named, ctx)]
print(json.dumps({"same": ours == theirs + theirs, "pairs": theirs, "remembered": len(jitprint._ABI),
                  "named": named_ours == [named_theirs, named_theirs]}))
"""

#: Constants made by calling types (``ir.IntType(64)(5)``, ``Type.__call__``) with llvmlite's own method, then after
#: :func:`jitprint.constant_calls`: each constant's class, type and text.
CONSTANTS = r"""
import json
from llvmlite import ir
from dynslam2d import jitprint
i8, i64, f64 = ir.IntType(8), ir.IntType(64), ir.DoubleType()
st = ir.LiteralStructType([i64, f64])
cases = [(i8, 3), (i64, -7), (ir.IntType(1), True), (f64, 1.5), (ir.FloatType(), 0.25), (i8.as_pointer(), None),
         (ir.ArrayType(i8, 3), [1, 2, 3]), (st, [ir.Constant(i64, 4), 2.5]), (ir.VectorType(f64, 2), [1.0, 2.0]),
         (ir.ArrayType(i8, 2), bytearray(b"ab")), (st, ir.Undefined), (i64, None)]
def made():
    out = []
    for t, v in cases:
        c = t(v)
        out.append([type(c).__name__, c.type is t, str(c)])
    return out
theirs = made()
installed = [jitprint.constant_calls(), jitprint.constant_calls()]
print(json.dumps({"theirs": theirs, "ours": made(), "installed": installed,
                  "replaced": getattr(ir.types.Type.__call__, "_dynslam2d_constant", False)}))
"""


def _run(script: str, args: list[str]) -> dict:
    out = subprocess.run([sys.executable, "-c", script, *args], env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, timeout=900, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_same_text_caches_and_sizes_on_the_first_commands_kernels(tmp_path: Path) -> None:
    stats = _run(SHADOW, ["3", str(ROOT / "benchmarks"), str(tmp_path)])
    assert stats["modules"] >= 10 and stats["same"] == stats["modules"] and stats["differ"] == 0
    assert stats["formatted"] > 0.9 * stats["instructions"] > 5000  # (the rest through llvmlite's own str)
    assert stats["abi_same"] > 50 and stats["abi_differ"] == 0 and stats["abi_remembered"] > 0


def test_every_formatted_class_and_variant() -> None:
    stats = _run(CLASSES, [])
    assert stats["same"]
    assert stats["formatted"] == ["AllocaInstr", "Branch", "CastInstr", "ConditionalBranch", "ExtractValue",
                                  "FCMPInstr", "GEPInstr", "ICMPInstr", "InsertValue", "Instruction", "LoadInstr",
                                  "Ret", "SelectInstr", "StoreInstr"]


def test_remembered_abi_sizes() -> None:
    stats = _run(ABI, [])
    assert stats["same"] and stats["named"]
    assert stats["remembered"] == 18  # (not the identified struct: the module llvmlite parses declares it)
    assert any(size != align for size, align in stats["pairs"])


def test_constants_from_type_calls() -> None:
    stats = _run(CONSTANTS, [])
    assert stats["installed"] == [True, False] and stats["replaced"]
    assert stats["ours"] == stats["theirs"]
    assert len(stats["theirs"]) == 12 and all(same_type for _, same_type, _ in stats["theirs"])


def test_other_sources_left_alone(monkeypatch) -> None:
    from llvmlite.ir import types, values
    from numba.core.runtime import context

    from dynslam2d import jitprint

    # (numba's sources changed too: else lean_meminfos installs, and the answer would depend on the test order)
    descr, size, meminfos = values.Block.descr, types.Type.get_abi_size, context.NRTContext.get_meminfos
    call = types.Type.__call__
    monkeypatch.setattr(jitprint, "SOURCES", {**jitprint.SOURCES, "instructions": "0" * 16})
    monkeypatch.setattr(jitprint, "MEMINFO_SOURCES", {**jitprint.MEMINFO_SOURCES, "DataModel.traverse": "0" * 16})
    assert not jitprint.install()
    assert values.Block.descr is descr and types.Type.get_abi_size is size and types.Type.__call__ is call
    assert context.NRTContext.get_meminfos is meminfos
