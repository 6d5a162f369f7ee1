"""Check ``dynslam2d.jitprint`` against llvmlite on every module numba prints in a cold run of the README's first
command (issue 13 item 2, docs/speed.md pass cmp39).

Runs ``dynslam2d run --out DIR`` (sim:paper) in this interpreter with an empty numba cache and the background compile
off, the command line's compile settings installed (``jitcache.lean_numba_compile``). Every module handed to
``CPUCodeLibrary.add_ir_module`` is printed twice before numba prints it: with llvmlite's own ``Block.descr`` and,
after every llvmlite string cache reachable from the module (``_StrCaching`` / ``_StringReferenceCaching`` slots of
each type, value, block and instruction) is put back as it was, with ``jitprint.block_descr``; the two texts and the
two sets of caches left behind are compared (:func:`compare`). Every ``Type.get_abi_size`` / ``get_abi_alignment``
query gets ``jitprint``'s answer and llvmlite's own compared. Prints a JSON line: modules, same, differing (each
dumped to ``--out-dir``), instructions, CPU of both printers (first print of each module), ABI queries same /
differing and how many were answered from memory.

``--dump DIR`` writes, in compile order, every module's text as handed to LLVM and every library's final module
after LLVM's optimisation; with ``--plain`` jitprint is not installed (llvmlite's own code throughout), so two runs
(``PYTHONHASHSEED=0``) can be compared file by file (:func:`masked` hides object addresses).

    PYTHONPATH=src python benchmarks/check_jitprint.py [--out-dir DIR] [--dump DIR [--plain] [--asm]
        [--callees-optimised] [--numba-meminfos]] [--input PATH]

Not run by pytest (tests/test_jitprint.py runs the same check on a few kernels).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

from scratch import scratch_dir

STR, REF = "_StrCaching__cached_str", "_StringReferenceCaching__cached_refstr"


def _reachable(root: Any) -> list[Any]:
    """Every llvmlite ``ir`` object reachable from ``root`` through instance attributes, lists, tuples, dicts and sets
    (in a fixed order: the order of discovery)."""
    seen: set[int] = set()
    out: list[Any] = []
    stack = [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (list, tuple)):
            stack.extend(reversed(obj))
            continue
        if isinstance(obj, dict):  # (its keys and values: no transient (key, value) tuple, whose id may recur)
            for k, v in reversed(list(obj.items())):
                stack += (v, k)
            continue
        if isinstance(obj, (set, frozenset)) and not type(obj).__module__.startswith("llvmlite.ir"):
            continue  # (plain sets hold names)
        if not type(obj).__module__.startswith("llvmlite.ir"):
            continue
        out.append(obj)
        attrs = getattr(obj, "__dict__", None)
        if attrs:
            stack.extend(v for k, v in reversed(list(attrs.items())) if k not in (STR, REF))
    return out


def caches(objs: list[Any]) -> list[tuple[int, Any, Any]]:
    """Each object's llvmlite string caches (absent: None)."""
    return [(id(o), getattr(o, "__dict__", {}).get(STR), getattr(o, "__dict__", {}).get(REF)) for o in objs]


def restore(objs: list[Any], state: list[tuple[int, Any, Any]]) -> None:
    """Put the caches of :func:`caches` back (removing those added since)."""
    for o, (_, s, r) in zip(objs, state):
        d = getattr(o, "__dict__", None)
        if d is None:
            continue
        for key, value in ((STR, s), (REF, r)):
            if value is None:
                d.pop(key, None)
            else:
                d[key] = value


def compare(module: Any, stats: dict[str, Any], out_dir: str | None) -> None:
    """Print ``module`` with llvmlite's ``Block.descr`` and with ``jitprint.block_descr`` from the same caches; count
    it as same when the texts and the caches left on every reachable object are equal. Leaves jitprint's caches."""
    from llvmlite.ir import values

    from dynslam2d import jitprint

    fast = values.Block.descr
    plain = fast.__wrapped__
    objs = _reachable(module)
    before = caches(objs)
    enabled = gc.isenabled()
    gc.disable()
    try:
        values.Block.descr = plain
        t0 = time.process_time()
        theirs = str(module)
        t1 = time.process_time()
        after_theirs = caches(objs)
        restore(objs, before)
        values.Block.descr = fast
        t2 = time.process_time()
        ours = str(module)
        t3 = time.process_time()
    finally:
        values.Block.descr = fast
        if enabled:
            gc.enable()
    after_ours = caches(objs)
    stats["modules"] += 1
    stats["cpu_llvmlite_s"] += t1 - t0
    stats["cpu_jitprint_s"] += t3 - t2
    stats["instructions"] += sum(len(b.instructions) for f in module.functions for b in f.blocks)
    stats["formatted"] += sum(type(i) in jitprint._FAST for f in module.functions for b in f.blocks
                              for i in b.instructions)
    same = theirs == ours and after_theirs == after_ours and len(_reachable(module)) == len(objs)
    stats["same" if same else "differ"] += 1
    if not same and out_dir:
        Path(out_dir, f"differ{stats['differ']}.json").write_text(json.dumps(
            {"llvmlite": theirs, "jitprint": ours, "caches_same": after_theirs == after_ours,
             "caches_differ": [[type(o).__name__, repr(o)[:200], a[1:], b[1:], _holders(o, objs)] for o, a, b in zip(
                 objs, after_theirs, after_ours) if a != b][:20]}))


def _holders(obj: Any, objs: list[Any]) -> list[str]:
    """Which of ``objs`` hold ``obj`` in which attribute (for the dump of a differing module)."""
    out = []
    for o in objs:
        for k, v in getattr(o, "__dict__", {}).items():
            if v is obj or (isinstance(v, (list, tuple)) and any(x is obj for x in v)):
                out.append(f"{type(o).__name__}.{k}: {str(o)[:120] if not isinstance(o, type(obj)) else ''}")
    return out[:5]


def shadow(out_dir: str | None = None) -> dict[str, Any]:
    """Install ``jitprint`` (so that its install at the first compile leaves this alone), check every module numba
    adds to a library (:func:`compare`) and every ABI query against llvmlite's own; returns the live figures."""
    from llvmlite.ir import types
    from numba.core import codegen

    from dynslam2d import jitprint

    if not (jitprint.fast_blocks() and jitprint.abi_sizes()):
        raise RuntimeError("jitprint not installed (llvmlite's sources differ, or installed before)")
    stats: dict[str, Any] = {"modules": 0, "same": 0, "differ": 0, "instructions": 0, "formatted": 0,
                             "cpu_llvmlite_s": 0.0, "cpu_jitprint_s": 0.0, "abi_same": 0, "abi_differ": 0,
                             "abi_remembered": 0}
    add = codegen.CPUCodeLibrary.add_ir_module

    def checked_add(self: Any, ir_module: Any) -> Any:
        compare(ir_module, stats, out_dir)
        return add(self, ir_module)

    codegen.CPUCodeLibrary.add_ir_module = checked_add

    def checked(name: str) -> Any:
        ours = getattr(types.Type, name)
        theirs = ours.__wrapped__

        def query(self: Any, target_data: Any, context: Any = None) -> Any:
            known = len(jitprint._ABI)
            mine = ours(self, target_data, context)
            stats["abi_remembered"] += len(jitprint._ABI) == known and jitprint._abi_key(self, context) is not None
            stats["abi_same" if mine == theirs(self, target_data, context) else "abi_differ"] += 1
            return mine

        return query

    for name in ("get_abi_size", "get_abi_alignment"):
        setattr(types.Type, name, checked(name))
    return stats


def masked(text: str) -> str:
    """``text`` with object addresses hidden (``0x…``, dynamic globals' names, ``inttoptr (i64 <address>``)."""
    text = re.sub(r"0x[0-9a-fA-F]+", "0x?", text)
    text = re.sub(r"numba\.dynamic\.globals\.[0-9a-fA-F]+", "numba.dynamic.globals.?", text)
    return re.sub(r"inttoptr \(i64 \d+", "inttoptr (i64 ?", text)


def dump(folder: str, asm: bool = False) -> None:
    """Write every module handed to ``add_ir_module`` (its text, as numba gives it to LLVM) and every library's final
    module after LLVM's optimisation (masked) to ``folder``, numbered in compile order; with ``asm`` also the
    assembly of every library that gets machine code (``asm-<library>-<n>.s``, from a copy of its final module,
    addresses masked), named by library so that two runs compare file by file whatever their order."""
    from numba.core import codegen

    if asm:
        seen: dict[str, int] = {}
        specific = codegen.JITCodeLibrary._finalize_specific

        def dumped_specific(self: Any) -> Any:
            text = self._codegen._tm.emit_assembly(self._final_module.clone())
            n = seen[self.name] = seen.get(self.name, 0) + 1
            name = re.sub(r"[^A-Za-z0-9_.]+", "_", re.sub(r"0x[0-9a-fA-F]+", "", self.name))[:150]
            Path(folder, f"asm-{name}-{n}.s").write_text(re.sub(r"\$-?\d{9,}", "$?", masked(text)))
            return specific(self)

        codegen.JITCodeLibrary._finalize_specific = dumped_specific

    Path(folder).mkdir(parents=True, exist_ok=True)
    count = [0]
    add, final = codegen.CPUCodeLibrary.add_ir_module, codegen.CPUCodeLibrary._optimize_final_module

    def write(kind: str, text: str) -> None:
        count[0] += 1
        Path(folder, f"{count[0]:04d}-{kind}.ll").write_text(masked(text))

    def dumped_add(self: Any, ir_module: Any) -> Any:
        write("module", str(ir_module))
        return add(self, ir_module)

    def dumped_final(self: Any) -> Any:
        final(self)
        write("final", str(self._final_module))

    codegen.CPUCodeLibrary.add_ir_module = dumped_add
    codegen.CPUCodeLibrary._optimize_final_module = dumped_final


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", help="where to write the dumps of differing modules")
    ap.add_argument("--dump", help="write every module and final module to this folder (no comparison)")
    ap.add_argument("--plain", action="store_true", help="with --dump: llvmlite's own printer and ABI queries")
    ap.add_argument("--asm", action="store_true", help="with --dump: also each library's assembly")
    ap.add_argument("--callees-optimised", action="store_true",
                    help="jitcache.CALLEE_OPTIMISED_IN_CALLER off: a lazy callee optimised before its callers link it")
    ap.add_argument("--input", help="run this input instead of the README's sim:paper (a path or sim:NAME)")
    ap.add_argument("--numba-meminfos", action="store_true",
                    help="numba's own get_meminfos (jitprint.lean_meminfos not installed)")
    args = ap.parse_args()
    work = scratch_dir("check_jitprint-")
    os.environ["NUMBA_CACHE_DIR"] = str(Path(work, "numba"))
    os.environ["DYNSLAM2D_COMPILE_WORKER"] = "0"
    from dynslam2d import jitcache, jitprint

    if args.callees_optimised:
        jitcache.CALLEE_OPTIMISED_IN_CALLER = False
    if args.numba_meminfos:
        jitprint.MEMINFO_SOURCES = {}  # (its install at the first compile: off)
    for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile"):
        getattr(jitcache, name)()
    stats: dict[str, Any] = {}
    if args.dump:
        if args.plain:
            jitprint.SOURCES = {**jitprint.SOURCES, "values": "0" * 16}  # (its install at the first compile: off)
        import dynslam2d.jitbox  # noqa: F401  (its optimisation wrappers first, as in a run; dump wraps them)

        dump(args.dump, asm=args.asm)
        stats["plain"] = args.plain
    else:
        stats = shadow(out_dir=args.out_dir)
    from dynslam2d.cli import main as cli

    sys.argv = ["dynslam2d", "run", *([args.input] if args.input else []), "--out", str(Path(work, "out")), "--force",
                "-q"]
    try:
        cli()
    except SystemExit:
        pass
    print(json.dumps(stats))


if __name__ == "__main__":
    main()
