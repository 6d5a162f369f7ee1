"""Check ``dynslam2d.jitssa`` against numba on every SSA reconstruction of the README's first command (issue 13 item 2,
docs/speed.md pass ssa36).

Runs ``dynslam2d run --out DIR`` (sim:paper) in this interpreter with an empty numba cache and the background compile
off, the command line's compile settings installed (``jitcache.lean_numba_compile``), and numba's ``ssa._run_ssa``
wrapped: each function's blocks are deep-copied twice, numba's ``_run_ssa`` runs on one copy and
``jitssa.sparse_run_ssa`` on the other, and the two results are compared in full (:func:`dump`: every block and
statement, which input object each is, the variables with their locations, phi nodes, the scope's names and
redefinitions, the warnings); numba's result on the real blocks goes on to the compile. The command line's variable
lists (``jitssa.fast_list_vars``) are installed first, and every statement's ``list_vars`` (and each assigned
instruction's) is compared with numba's own, object by object, on each function's blocks; every call of
``analysis.compute_use_defs`` in the run gets numba's and ``jitssa.fast_compute_use_defs``'s sets compared (contents
and iteration order) and returns numba's; so does every call of ``analysis.compute_live_map`` (numba's against
``jitssa.fast_compute_live_map``: the blocks in order, each set's contents). Prints a JSON line: SSA calls, same,
differing (each dumped to ``--out-dir``), statements, phi nodes, process CPU of numba's pass and of the sparse one
(garbage collector off), fallbacks to numba's pass, variable lists same / differing, ``compute_use_defs`` and
``compute_live_map`` calls same / differing and their CPU both ways. Every ``PostProcessor.run`` also has
``jitssa.canonical_blocks`` checked against numba's ``transforms.canonicalize_cfg`` and the control-flow graph it
shares against numba's own of the same blocks (:func:`shared_cfg`, pass ud38).

    PYTHONPATH=src python benchmarks/check_jitssa.py [--out-dir DIR]

Not run by pytest (tests/test_jitssa.py runs the same check on a few kernels).
"""

from __future__ import annotations

import argparse
import copy
import functools
import gc
import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

from scratch import scratch_dir


def dump(out: dict[Any, Any], given: dict[Any, Any], caught: list[Any]) -> list[Any]:
    """Every block of ``out`` (label, location, whether it is one of ``given``'s block objects, scope), every statement
    (type, text, location, which statement or assigned value of ``given`` it is the same object as, its variables with
    their locations and scopes; a phi node's incoming values and blocks), the scopes' names and redefinitions, and the
    warnings ``caught``. ``given`` is the dict of blocks the pass was given (its objects alive: ids are compared)."""
    from numba.core import ir

    origin: dict[int, Any] = {}
    for label, blk in given.items():
        origin[id(blk)] = ("block", label)
        for i, stmt in enumerate(blk.body):
            origin[id(stmt)] = ("stmt", label, i)
            if isinstance(stmt, ir.Assign):
                origin[id(stmt.value)] = ("value", label, i)
    scopes: list[Any] = []

    def scope_no(scope: Any) -> int:
        for i, known in enumerate(scopes):
            if known is scope:
                return i
        scopes.append(scope)
        return len(scopes) - 1

    rows: list[Any] = [["same dict", out is given]]
    for label, blk in out.items():
        rows.append(["block", label, repr(blk.loc), origin.get(id(blk)), scope_no(blk.scope), len(blk.body)])
        for stmt in blk.body:
            row = [type(stmt).__name__, str(stmt), repr(stmt.loc), origin.get(id(stmt)),
                   [(v.name, repr(v.loc), scope_no(v.scope)) for v in stmt.list_vars()]]
            if isinstance(stmt, ir.Assign):
                value = stmt.value
                row += [type(value).__name__, origin.get(id(value)), repr(getattr(value, "loc", None))]
                if isinstance(value, ir.Expr) and value.op == "phi":
                    row += [[repr(v) for v in value.incoming_values], list(value.incoming_blocks)]
            rows.append(row)
    for scope in scopes:
        rows.append(["scope", [(k, v.name, repr(v.loc)) for k, v in scope.localvars._con.items()],
                     dict(scope.redefined), {k: list(v) for k, v in scope.var_redefinitions.items()}])
    rows.append(["warnings", [(type(w.message).__name__, str(w.message)) for w in caught]])
    return rows


#: numba's variable-list methods replaced by ``jitssa.fast_list_vars``.
LIST_ATTRS = (("Inst", "_rec_list_vars"), ("Stmt", "list_vars"), ("Expr", "list_vars"))


def _lists(blocks: dict[Any, Any]) -> list[list[int]]:
    from numba.core import ir

    out = []
    for blk in blocks.values():
        for stmt in blk.body:
            out.append([id(v) for v in stmt.list_vars()])
            if isinstance(stmt, ir.Assign) and isinstance(stmt.value, ir.Inst):
                out.append([id(v) for v in stmt.value.list_vars()])
    return out


def shadow(out_dir: str | None = None) -> dict[str, Any]:
    """Install ``jitssa`` (so that ``jitssa.install`` at the first compile leaves this alone) and wrap numba's
    ``ssa._run_ssa`` so that every call is checked as described in the module docstring (numba's result is
    returned). Returns the live figures (a dict updated by each call)."""
    from numba.core import analysis, ir, ssa

    from dynslam2d import jitssa

    originals = [getattr(getattr(ir, c), n) for c, n in LIST_ATTRS]
    if not (jitssa.fast_list_vars() and jitssa.sparse_ssa() and jitssa.lean_use_defs() and jitssa.bit_live_map()):
        raise RuntimeError("jitssa not installed (numba's sources differ, or installed before)")
    numba_use_defs, numba_live_map = analysis.compute_use_defs.__wrapped__, analysis.compute_live_map.__wrapped__
    fasts = [getattr(getattr(ir, c), n) for c, n in LIST_ATTRS]
    numba_run_ssa = ssa._run_ssa._dynslam2d_original
    stats: dict[str, Any] = {"calls": 0, "same": 0, "differ": 0, "statements": 0, "phis": 0, "cpu_numba_s": 0.0,
                             "cpu_sparse_s": 0.0, "lists_same": 0, "lists_differ": 0, "fallbacks": 0,
                             "use_defs_same": 0, "use_defs_differ": 0, "cpu_use_defs_numba_s": 0.0,
                             "cpu_use_defs_lean_s": 0.0, "live_maps_same": 0, "live_maps_differ": 0,
                             "cpu_live_map_numba_s": 0.0, "cpu_live_map_bits_s": 0.0}

    def use_defs(blocks: Any) -> Any:  # numba's and jitssa's compute_use_defs: the same sets, filled in the same order
        t0 = time.process_time()
        theirs = numba_use_defs(blocks)
        t1 = time.process_time()
        ours = jitssa.fast_compute_use_defs(blocks)
        t2 = time.process_time()
        stats["cpu_use_defs_numba_s"] += t1 - t0
        stats["cpu_use_defs_lean_s"] += t2 - t1
        same = all({k: list(v) for k, v in a.items()} == {k: list(v) for k, v in b.items()}
                   and list(a) == list(b) for a, b in zip(theirs, ours))
        stats["use_defs_same" if same else "use_defs_differ"] += 1
        return theirs

    analysis._dynslam2d_compute_use_defs = use_defs

    def live_map(cfg: Any, blocks: Any, var_use_map: Any, var_def_map: Any) -> Any:  # numba's and jitssa's
        t0 = time.process_time()
        theirs = numba_live_map(cfg, blocks, var_use_map, var_def_map)
        t1 = time.process_time()
        ours = jitssa.fast_compute_live_map(cfg, blocks, var_use_map, var_def_map)
        t2 = time.process_time()
        stats["cpu_live_map_numba_s"] += t1 - t0
        stats["cpu_live_map_bits_s"] += t2 - t1
        same = list(theirs) == list(ours) and theirs == ours  # (numba sorts what it takes from these sets)
        stats["live_maps_same" if same else "live_maps_differ"] += 1
        return theirs

    analysis._dynslam2d_compute_live_map = live_map

    def put(funcs: list[Any]) -> None:
        for (c, n), f in zip(LIST_ATTRS, funcs):
            setattr(getattr(ir, c), n, f)

    def check(blocks: Any) -> Any:
        stats["calls"] += 1
        mine = _lists(blocks)
        put(originals)
        theirs = _lists(blocks)
        put(fasts)
        stats["lists_same" if mine == theirs else "lists_differ"] += 1
        a_in, b_in = copy.deepcopy(blocks), copy.deepcopy(blocks)
        fallbacks = jitssa.FALLBACKS[0]
        enabled = gc.isenabled()
        gc.disable()
        try:
            with warnings.catch_warnings(record=True) as caught_a:
                warnings.simplefilter("always")
                t0 = time.process_time()
                a_out = numba_run_ssa(dict(a_in))
                t1 = time.process_time()
            with warnings.catch_warnings(record=True) as caught_b:
                warnings.simplefilter("always")
                t2 = time.process_time()
                b_out = jitssa.sparse_run_ssa(dict(b_in), numba_run_ssa)
                t3 = time.process_time()
        finally:
            if enabled:
                gc.enable()
        stats["cpu_numba_s"] += t1 - t0
        stats["cpu_sparse_s"] += t3 - t2
        stats["fallbacks"] += jitssa.FALLBACKS[0] - fallbacks
        theirs, ours = dump(a_out, a_in, caught_a), dump(b_out, b_in, caught_b)
        if theirs == ours:
            stats["same"] += 1
        else:
            stats["differ"] += 1
            if out_dir:
                Path(out_dir, f"differ{stats['differ']}.json").write_text(json.dumps([theirs, ours], default=str))
        stats["statements"] += sum(len(b.body) for b in blocks.values())
        stats["phis"] += sum(1 for row in theirs if row[0] == "Assign" and len(row) > 8)  # phi nodes
        return numba_run_ssa(blocks)

    check._dynslam2d_sparse = True  # type: ignore[attr-defined]
    ssa._run_ssa = check
    shared_cfg(stats)
    return stats


def _ordered(x: Any) -> Any:
    """``x`` with every dict, set and sequence as a list in its iteration order (to compare orders too)."""
    if isinstance(x, dict):
        return [[_ordered(k), _ordered(v)] for k, v in x.items()]
    if isinstance(x, (set, frozenset, list, tuple)):
        return [_ordered(v) for v in x]
    return x


#: A control-flow graph's state (``numba.core.controlflow.CFGraph``): everything else is computed from it.
CFG_STATE = ("_nodes", "_edge_data", "_entry_point", "_preds", "_succs", "_dead_nodes")


def cfg_same(shared: Any, fresh: Any) -> bool:
    """Whether the graph ``shared`` (``jitssa.canonical_blocks``') is ``fresh``'s equal (numba's own, built from the
    same blocks): the same state with every set and dict in the same iteration order, and every analysis ``shared``
    has already computed (its ``functools.cached_property`` values, loops and back edges) the same as ``fresh``'s."""
    state = [_ordered(getattr(shared, name)) for name in CFG_STATE]
    if state != [_ordered(getattr(fresh, name)) for name in CFG_STATE]:
        return False
    cached = [name for name in vars(shared) if name not in CFG_STATE and isinstance(
        getattr(type(shared), name, None), functools.cached_property)]
    return all(_ordered(vars(shared)[name]) == _ordered(getattr(fresh, name)) for name in cached)


def shared_cfg(stats: dict[str, Any]) -> None:
    """Install ``jitssa.shared_cfg`` and check every ``PostProcessor.run`` of the run: ``jitssa.canonical_blocks``
    against numba's ``transforms.canonicalize_cfg`` (the same block objects under the same labels in the same order;
    a loop's new tail block in the same place) and the graph it hands to ``VariableLifetime`` against numba's
    ``compute_cfg_from_blocks`` of the new blocks (:func:`cfg_same`). Adds to ``stats``: calls, graphs shared and the
    same, graphs differing, canonicalisations that rewrote a loop (numba's graph then), CPU of numba's
    canonicalisation and second graph (with its back edges) against ``canonical_blocks``."""
    from numba.core import analysis, transforms

    from dynslam2d import jitssa

    if not jitssa.shared_cfg():
        raise RuntimeError("jitssa.shared_cfg not installed (numba's sources differ, or installed before)")
    stats.update({"postproc_calls": 0, "cfg_same": 0, "cfg_differ": 0, "cfg_rewritten": 0, "blocks_differ": 0,
                  "cpu_cfg_numba_s": 0.0, "cpu_cfg_shared_s": 0.0})
    ours_fn, numba_fn = jitssa.canonical_blocks, transforms.canonicalize_cfg

    def canonical(blocks: Any) -> Any:
        stats["postproc_calls"] += 1
        enabled = gc.isenabled()
        gc.disable()
        try:
            t0 = time.process_time()
            theirs = numba_fn(blocks)
            fresh = analysis.compute_cfg_from_blocks(theirs)
            fresh.topo_order()  # (its back edges: the live map's first question)
            t1 = time.process_time()
            ours, cfg = ours_fn(blocks)
            t2 = time.process_time()
        finally:
            if enabled:
                gc.enable()
        stats["cpu_cfg_numba_s"] += t1 - t0
        stats["cpu_cfg_shared_s"] += t2 - t1
        def same_block(k: Any) -> bool:  # the same object, or both new (a loop's rewrite) with the same statements
            a, b, given = ours[k], theirs[k], blocks.get(k)
            return a is b or (a is not given and b is not given and [str(x) for x in a.body] == [
                str(x) for x in b.body])

        if ours is blocks or list(ours) != list(theirs) or not all(same_block(k) for k in theirs):
            stats["blocks_differ"] += 1
        if cfg is None:
            stats["cfg_rewritten"] += 1
        else:
            stats["cfg_same" if cfg_same(cfg, analysis.compute_cfg_from_blocks(ours)) else "cfg_differ"] += 1
        return ours, cfg

    jitssa.canonical_blocks = canonical


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", help="where to write the dumps of differing results")
    args = ap.parse_args()
    work = scratch_dir("check_jitssa-")
    os.environ["NUMBA_CACHE_DIR"] = str(Path(work, "numba"))
    os.environ["DYNSLAM2D_COMPILE_WORKER"] = "0"
    from dynslam2d import jitcache

    for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile"):
        getattr(jitcache, name)()
    stats = shadow(out_dir=args.out_dir)
    from dynslam2d.cli import main as cli

    sys.argv = ["dynslam2d", "run", "--out", str(Path(work, "out")), "--force", "-q"]
    try:
        cli()
    except SystemExit:
        pass
    print(json.dumps(stats))


if __name__ == "__main__":
    main()
