"""numba's SSA pass run only on the statements holding each violator, numba's variable lists in one traversal, its
use / def sets with each assignment listed once and its live-variable map over bit masks give the same lists, sets, IR
and code (dynslam2d.jitssa, issue 13 item 2, docs/speed.md passes cold36, ssa36, uni36)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")

#: Compiles the first ``argv[1]`` kernels of the README's first command (jitmanifest order; their callees and numba's
#: helpers with them) in fresh dispatchers, with every SSA reconstruction run both ways on copies of its blocks and
#: compared in full, and every statement's variable list compared with numba's (benchmarks/check_jitssa.py).
SHADOW = r"""
import json, sys
sys.path.insert(0, sys.argv[2])
import numba
from check_jitssa import shadow
from dynslam2d import jitmanifest, jitwarm
stats = shadow()
names = []
for name, sig in jitmanifest.KERNELS[: int(sys.argv[1])]:
    module, _, qual = name.rpartition(".")
    disp = getattr(__import__(module, fromlist=[qual]), qual)
    numba.njit(disp.py_func).compile(jitwarm.parse_signature(sig))
    names.append(name)
stats["kernels"] = names
print(json.dumps(stats))
"""

#: numba's IR of real kernels (loops, branches, inlined calls, tuples and keyword arguments in expressions) before and
#: after the SSA pass; every statement's variables (``list_vars`` of the statement and of its value, and
#: ``_rec_list_vars`` of the statement, its attribute dict and its value), every function's use / def sets (contents
#: and iteration order) and live map with numba's code and with jitssa's, compared in place.
SAME = r"""
import json
from numba.core import analysis, compiler, ir, ssa
from numba.core.analysis import compute_cfg_from_blocks
from dynslam2d import jitssa
ATTRS = (("Inst", "_rec_list_vars"), ("Stmt", "list_vars"), ("Expr", "list_vars"))
def put(funcs):
    for (c, n), f in zip(ATTRS, funcs):
        setattr(getattr(ir, c), n, f)
numba_lists = [getattr(getattr(ir, c), n) for c, n in ATTRS]
numba_ud, numba_live = analysis.compute_use_defs, analysis.compute_live_map
assert jitssa.install() and not jitssa.install()  # (once)
fast_lists = [getattr(getattr(ir, c), n) for c, n in ATTRS]
assert all(a is not b for a, b in zip(numba_lists, fast_lists))
assert analysis.compute_use_defs is numba_ud and analysis.compute_live_map is numba_live  # (the same objects, new code)
numba_ud, numba_live = numba_ud.__wrapped__, numba_live.__wrapped__
from dynslam2d.detect import kernels, kernels_update
from dynslam2d.slam import matcher, raycast
funcs = [matcher.gated_points, matcher._match_core, raycast._rays, kernels.measure_batch, kernels.shape_update,
         kernels_update.update_pairs, kernels_update.association_gates]
def lists(fir):
    out = []
    for block in fir.blocks.values():
        for stmt in block.body:
            value = getattr(stmt, "value", None)
            out.append([id(v) for v in stmt.list_vars()])
            if isinstance(value, ir.Inst):
                out.append([id(v) for v in value.list_vars()])
            for val in (stmt, stmt.__dict__, value):
                out.append([id(v) for v in ir.Inst._rec_list_vars(stmt, val)])
    return out
def use_defs(fir):
    ud = analysis.compute_use_defs(fir.blocks)
    return [{k: list(v) for k, v in m.items()} for m in ud], ud
stmts = vars_ = blocks_n = live_n = 0
for disp in funcs:
    fir0 = compiler.run_frontend(disp.py_func)
    for fir in (fir0, ssa.reconstruct_ssa(compiler.run_frontend(disp.py_func))):
        ours = lists(fir)
        ud_ours, ud = use_defs(fir)
        put(numba_lists)
        theirs = lists(fir)
        analysis._dynslam2d_compute_use_defs, fast_ud = numba_ud, analysis._dynslam2d_compute_use_defs
        ud_theirs, _ = use_defs(fir)
        analysis._dynslam2d_compute_use_defs = fast_ud
        put(fast_lists)
        assert ours == theirs, disp
        assert ud_ours == ud_theirs, disp
        stmts += sum(len(b.body) for b in fir.blocks.values())
        vars_ += sum(len(x) for x in ours)
        cfg = compute_cfg_from_blocks(fir.blocks)
        live = analysis.compute_live_map(cfg, fir.blocks, ud.usemap, ud.defmap)
        assert list(live) == list(fir.blocks) and live == numba_live(cfg, fir.blocks, ud.usemap, ud.defmap), disp
        blocks_n += len(live)
        live_n += sum(len(v) for v in live.values())
print(json.dumps({"stmts": stmts, "vars": vars_, "blocks": blocks_n, "live": live_n}))
"""

#: argv[1] "1": dynslam2d.jitssa installed, "0": numba's own. Compiles the matcher's ``gated_points`` and the
#: segmenter's kernel (loops, variables assigned in several blocks) in fresh dispatchers and prints their LLVM IR
#: and results on a simulated scan.
CODE = r"""
import json, math, sys
import numpy as np
import numba
from dynslam2d import jitssa
if sys.argv[1] == "1":
    assert jitssa.install() and not jitssa.install()  # (once)
from numba.core import ir, postproc, ssa
from dynslam2d.slam import matcher
kernel = numba.njit(matcher.gated_points.py_func)
rng = np.random.default_rng(7)
n = 721
ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
r = rng.uniform(0.05, 32.0, n)
r[rng.random(n) < 0.1] = np.nan
out = kernel(r, np.cos(ang), np.sin(ang), np.isfinite(r), 0.1, 30.0, 0.2, 25.0, 10.0, True)
llvm = "\n".join(kernel.inspect_llvm().values())
print(json.dumps({"llvm": llvm, "out": [np.asarray(o).tolist() for o in out],
                  "installed": [bool(getattr(ssa._run_ssa, "_dynslam2d_sparse", False)),
                                bool(getattr(ir.Inst, "_dynslam2d_fast", False)),
                                bool(getattr(postproc.PostProcessor.run, "_dynslam2d_shared_cfg", False))]}))
"""

#: Hand-made IR: a statement sharing its assigned expression with another (numba's pass would mutate the second
#: through the first's copy), and the same IR without the sharing; both ways on copies, compared in full.
SHARED = r"""
import copy, json, sys, warnings
sys.path.insert(0, sys.argv[1])
from numba.core import compiler, ir, ssa
from check_jitssa import dump
from dynslam2d import jitssa
from dynslam2d.slam import matcher
assert jitssa.fast_list_vars()
def both(blocks):
    a_in, b_in = copy.deepcopy(blocks), copy.deepcopy(blocks)
    before = jitssa.FALLBACKS[0]
    with warnings.catch_warnings(record=True) as wa:
        warnings.simplefilter("always")
        a_out = ssa._run_ssa(dict(a_in))
    with warnings.catch_warnings(record=True) as wb:
        warnings.simplefilter("always")
        b_out = jitssa.sparse_run_ssa(dict(b_in), ssa._run_ssa)
    return dump(a_out, a_in, wa) == dump(b_out, b_in, wb), jitssa.FALLBACKS[0] - before
blocks = compiler.run_frontend(matcher.gated_points.py_func).blocks
plain = both(blocks)
# share one expression between two assignments of a variable assigned in several blocks (an SSA violator)
label, i, stmt = next((label, i, s) for label, blk in blocks.items() for i, s in enumerate(blk.body)
                      if isinstance(s, ir.Assign) and isinstance(s.value, ir.Expr) and s.value.op == "binop")
blk = blocks[label]
twin = ir.Assign(value=stmt.value, target=blk.scope.redefine("twin", stmt.loc), loc=stmt.loc)
blk.body.insert(i + 1, twin)
print(json.dumps({"plain": plain, "shared": both(blocks)}))
"""


def _run(script: str, args: list[str], tmp_path: Path, tag: str) -> dict:
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path / f"numba-{tag}"))
    res = subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_same_ssa_ir_on_the_first_commands_kernels(tmp_path: Path) -> None:
    stats = _run(SHADOW, ["6", str(ROOT / "benchmarks")], tmp_path, "shadow")
    assert len(stats["kernels"]) == 6
    assert stats["calls"] >= 6 and stats["same"] == stats["calls"] and stats["differ"] == 0
    assert stats["lists_same"] == stats["calls"] and stats["lists_differ"] == 0
    assert stats["phis"] > 10 and stats["fallbacks"] == 0  # violators were rewritten, by the sparse pass itself
    assert stats["postproc_calls"] > 50 and stats["cfg_same"] > 50  # every PostProcessor.run's graph shared ...
    assert stats["cfg_same"] + stats["cfg_rewritten"] == stats["postproc_calls"]  # ... unless a loop was rewritten
    assert stats["cfg_differ"] == 0 and stats["blocks_differ"] == 0


#: A loop with two back edges (``continue`` in a ``for`` loop: numba's canonicalisation gives it a tail block, and
#: its graph is then built again) and one without, compiled with every ``PostProcessor.run`` checked
#: (benchmarks/check_jitssa.py's ``shared_cfg``); their results.
LOOPS = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
import numba
from check_jitssa import shared_cfg
stats = {}
shared_cfg(stats)
def two_back_edges(n):
    s = 0
    for i in range(n):
        if i % 3 == 0:
            continue
        s += i
    return s
def one_back_edge(n):
    s = 0.0
    for i in range(n):
        s += i * 0.5
    return s
stats["out"] = [numba.njit(two_back_edges)(10), numba.njit(one_back_edge)(10)]
print(json.dumps(stats))
"""


def test_same_lists_use_defs_and_live_maps_on_real_kernels(tmp_path: Path) -> None:
    res = _run(SAME, [], tmp_path, "same")
    assert res["stmts"] > 5000 and res["vars"] > 30000  # every statement of seven kernels, twice
    assert res["blocks"] > 500 and res["live"] > 1000  # blocks with variables live across them


def test_same_code_and_results(tmp_path: Path) -> None:
    theirs, ours = _run(CODE, ["0"], tmp_path, "0"), _run(CODE, ["1"], tmp_path, "1")
    assert theirs["installed"] == [False, False, False] and ours["installed"] == [True, True, True]
    assert ours["llvm"] == theirs["llvm"] and "phi" in ours["llvm"]
    assert ours["out"] == theirs["out"]


def test_shared_cfg_is_numbas_graph(tmp_path: Path) -> None:
    res = _run(LOOPS, [str(ROOT / "benchmarks")], tmp_path, "loops")
    assert res["out"] == [27, 22.5]
    assert res["cfg_rewritten"] >= 1 and res["cfg_same"] >= 10  # both paths taken
    assert res["cfg_same"] + res["cfg_rewritten"] == res["postproc_calls"]
    assert res["cfg_differ"] == 0 and res["blocks_differ"] == 0


def test_shared_ir_objects_go_to_numbas_pass(tmp_path: Path) -> None:
    res = _run(SHARED, [str(ROOT / "benchmarks")], tmp_path, "shared")
    assert res["plain"] == [True, 0]
    assert res["shared"] == [True, 1]


def test_other_sources_left_alone() -> None:
    script = r"""
import json
from numba.core import ir, ssa
from dynslam2d import jitssa
from numba.core import analysis, postproc
def now():
    return (ssa._run_ssa, ir.Inst._rec_list_vars, ir.Stmt.list_vars, ir.Expr.list_vars,
            analysis.compute_use_defs.__code__, analysis.compute_live_map.__code__, postproc.PostProcessor.run)
before = now()
jitssa.SOURCES["analysis"] = "0" * 16
jitssa.POSTPROC_SOURCES["postproc"] = "0" * 16
done = jitssa.install()
after = now()
print(json.dumps({"done": done, "same": all(a is b for a, b in zip(before, after))}))
"""
    res = subprocess.run([sys.executable, "-c", script], env=dict(os.environ, PYTHONPATH=SRC), capture_output=True,
                         text=True, check=True)
    assert json.loads(res.stdout.strip().splitlines()[-1]) == {"done": False, "same": True}
