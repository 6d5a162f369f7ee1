"""numba's statement variables, use / def sets and live-variable map computed with less Python work give the same lists
and sets (dynslam2d.jitcache.lean_ir_analysis, issue 13 item 2, docs/speed.md pass cold36)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: In a fresh process: numba's IR of real kernels (loops, branches, inlined calls, tuples and keyword arguments in
#: expressions) before and after numba's SSA pass; every statement's variables and every function's live map with
#: numba's code and with the rewrite, compared in place.
SAME = r"""
import json
from numba.core import analysis, compiler, ir, ssa
from numba.core.analysis import compute_cfg_from_blocks, compute_use_defs
from dynslam2d import jitcache
numba_rec, numba_live, numba_ud = ir.Inst._rec_list_vars, analysis.compute_live_map, analysis.compute_use_defs
assert jitcache.lean_ir_analysis() and not jitcache.lean_ir_analysis()  # (once)
assert ir.Inst._rec_list_vars is not numba_rec  # (numba's functions: the same objects, new code)
assert analysis.compute_live_map is numba_live and analysis.compute_use_defs is numba_ud
numba_live, numba_ud = numba_live.__wrapped__, numba_ud.__wrapped__
from dynslam2d.detect import kernels, kernels_update
from dynslam2d.slam import matcher, raycast
funcs = [matcher.gated_points, matcher._match_core, raycast._rays, kernels.measure_batch, kernels.shape_update,
         kernels_update.update_pairs, kernels_update.association_gates]
stmts = vars_ = blocks_n = live_n = 0
for disp in funcs:
    fir0 = compiler.run_frontend(disp.py_func)
    for fir in (fir0, ssa.reconstruct_ssa(compiler.run_frontend(disp.py_func))):
        for block in fir.blocks.values():
            for stmt in block.body:
                for val in (stmt, stmt.__dict__, getattr(stmt, "value", None)):
                    ours = ir.Inst._rec_list_vars(stmt, val)
                    theirs = numba_rec(stmt, val)
                    assert [id(v) for v in ours] == [id(v) for v in theirs], (disp, stmt)
                    vars_ += len(ours)
                stmts += 1
        cfg = compute_cfg_from_blocks(fir.blocks)
        ud = compute_use_defs(fir.blocks)
        ud_numba = numba_ud(fir.blocks)
        assert ud.usemap == ud_numba.usemap and ud.defmap == ud_numba.defmap, disp
        ours = analysis.compute_live_map(cfg, fir.blocks, ud.usemap, ud.defmap)
        theirs = numba_live(cfg, fir.blocks, ud.usemap, ud.defmap)
        assert ours == theirs, disp
        blocks_n += len(ours)
        live_n += sum(len(v) for v in ours.values())
print(json.dumps({"stmts": stmts, "vars": vars_, "blocks": blocks_n, "live": live_n}))
"""

#: Another expected source: numba is left as it is.
OTHER = r"""
import json
from numba.core import analysis, ir
from dynslam2d import jitcache
rec, code = ir.Inst._rec_list_vars, analysis.compute_live_map.__code__
ud_code = analysis.compute_use_defs.__code__
jitcache.LIVE_MAP_SOURCE = "0" * 16
print(json.dumps({"installed": jitcache.lean_ir_analysis(),
                  "same": ir.Inst._rec_list_vars is rec and analysis.compute_live_map.__code__ is code
                  and analysis.compute_use_defs.__code__ is ud_code}))
"""


def _run(script: str, tmp_path: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_same_variables_and_live_maps_on_real_kernels(tmp_path: Path) -> None:
    res = _run(SAME, tmp_path)
    assert res["stmts"] > 5000 and res["vars"] > 10000  # every statement of seven kernels, twice
    assert res["blocks"] > 500 and res["live"] > 1000  # blocks with variables live across them


def test_other_sources_left_alone(tmp_path: Path) -> None:
    assert _run(OTHER, tmp_path) == {"installed": False, "same": True}
