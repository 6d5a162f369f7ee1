"""Cold compile of the README's first command split by kernel and by compiler stage (issue 13 item 2).

Runs ``dynslam2d run --out DIR`` (sim:paper) in a fresh interpreter with an empty numba cache and the background
compile off (as ``bench_compile.py``'s profile) and charges every CPU second of numba's compiler, exclusively, to
the function being compiled (numba's ``numba:compile`` events) and to one stage:

- ``typing``: numba's type-inference passes (``numba:run_pass`` events whose pass name holds ``type_inference``);
- ``lowering``: ``native_lowering`` outside llvmlite's calls (numba building the LLVM IR in Python);
- ``llvm_opt``: the module pipeline on the kernel's linked library (``CPUCodeLibrary._optimize_final_module``);
- ``llvm_code``: machine code (``JITCodeLibrary._finalize_specific``);
- ``llvm_other``: the rest of llvmlite's calls (IR parsing, verification, linking);
- ``other``: numba's other passes (bytecode, SSA, rewrites, inlining) and the dispatcher's work around them
  (cache writes);
- ``gc``: Python's cyclic garbage collector (``gc.callbacks``), which lands on whichever function is compiling.

When a library is finalized, the IR instructions of its own (unoptimised) modules and of the callees' (optimised)
libraries linked into it are counted, and the linked callees' code alone (their functions kept, their Python and C
wrappers dropped when unreferenced, as in the caller) is put through the same module pipeline and machine code in
a module of its own (``callees alone``: an estimate of the LLVM CPU the caller spends again on code another library
already optimised and compiled). That extra work is charged to ``probe`` and left out of every other figure. Also
lists the callees linked into most libraries.

    PYTHONPATH=src python benchmarks/bench_compile_split.py [--src src] [--top 15] [--json OUT]

Not run by pytest; numbers go to docs/speed.md with the command and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_compile import RUN_FIRST_COMMAND, cold_probe  # noqa: E402

PROBE = r"""
import json, sys, time
c0 = time.process_time()
import dynslam2d.jitcache as jc
for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile"):
    getattr(jc, name, lambda: None)()
import dynslam2d.jitbox  # installs one_llvm_optimisation before the wrappers below
from numba.core import event, codegen
import llvmlite.binding as ll
acc = {}          # (function, stage) -> CPU s
stack = [["<none>", "outside"]]
last = [time.process_time()]
ncomp = {}
passes, pass_t = [], {}  # open numba passes; "pass function" -> exclusive CPU s outside llvmlite
def _switch():
    now = time.process_time()
    key = tuple(stack[-1])
    acc[key] = acc.get(key, 0.0) + now - last[0]
    if passes and not key[1].startswith("llvm_") and key[1] not in ("probe", "gc"):
        pk = passes[-1] + " " + key[0]
        pass_t[pk] = pass_t.get(pk, 0.0) + now - last[0]
    last[0] = now
def _push(name, stage):
    _switch(); stack.append([name, stage])
def _pop():
    _switch(); stack.pop()
def _fn():
    for name, _ in reversed(stack):
        if name != "<none>":
            return name
    return "<none>"
class Compile(event.Listener):
    def on_start(self, ev):
        f = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
        name = f"{f.__module__}.{f.__qualname__}" if f else "?"
        ncomp[name] = ncomp.get(name, 0) + 1
        _push(name, "other")
    def on_end(self, ev):
        _pop()
class Passes(event.Listener):
    def on_start(self, ev):
        p = ev.data["name"].split(" [")[0]
        stage = "typing" if "type_inference" in p else "lowering" if p == "native_lowering" else "other"
        _push(_fn(), stage)
        passes.append(p)
    def on_end(self, ev):
        _pop()
        passes.pop()
depth = [0]
class LLVM(event.Listener):
    def on_start(self, ev):
        depth[0] += 1
        if depth[0] == 1:
            top = stack[-1][1]
            _push(_fn(), top if top.startswith("llvm_") or top == "probe" else "llvm_other")
    def on_end(self, ev):
        depth[0] -= 1
        if depth[0] == 0:
            _pop()
import gc
def _gc(phase, info):  # Python's cyclic collector: its own stage, on whichever function is compiling
    if phase == "start":
        _push(_fn(), "gc")
    else:
        _pop()
gc.callbacks.append(_gc)
event.register("numba:compile", Compile())
event.register("numba:run_pass", Passes())
event.register("numba:llvm_lock", LLVM())
def _timed(cls, attr, stage):
    orig = getattr(cls, attr)
    def wrapped(self, *a, **k):
        _push(_fn(), stage)
        try:
            return orig(self, *a, **k)
        finally:
            _pop()
    setattr(cls, attr, wrapped)
_timed(codegen.CPUCodeLibrary, "_optimize_final_module", "llvm_opt")
_timed(codegen.JITCodeLibrary, "_finalize_specific", "llvm_code")
def _ninstr(mod):
    return sum(1 for line in str(mod).splitlines() if line.startswith("  ") and not line.startswith("  ;"))
libs = []  # per finalized library: function, own instructions, [(linked library, instructions)]
_finalize = codegen.CPUCodeLibrary.finalize
def finalize(self):
    _push(_fn(), "probe")
    try:
        own = _ninstr(self._final_module)
        linked, seen = [], set()
        for lib in self._linking_libraries:
            if lib not in seen:
                seen.add(lib)
                lib._ensure_finalized()
                linked.append((lib.name, _ninstr(lib._get_module_for_linking())))
        alone = 0.0
        if seen:  # the linked callees' code optimised and compiled on its own, as a cost estimate
            cg = self._codegen
            m = ll.parse_assembly(str(cg._create_empty_module("callees")))
            for lib in seen:  # (linkonce_odr definitions are linked only where referenced: none here)
                mod = lib._get_module_for_linking().clone()
                for f in mod.functions:
                    if not f.is_declaration:
                        wrapper = f.name.startswith(("_ZN7cpython", "cfunc."))
                        f.linkage = "linkonce_odr" if wrapper else "weak_odr"
                m.link_in(mod)
            t0 = time.process_time()
            pm, pb = cg._module_pass_manager()
            pm.run(m, pb)
            cg._tm.emit_object(m)
            alone = time.process_time() - t0
        libs.append((_fn(), self.name, own, linked, alone))
    finally:
        _pop()
    return _finalize(self)
codegen.CPUCodeLibrary.finalize = finalize
""" + RUN_FIRST_COMMAND + r"""
_switch()
print(json.dumps({"process_cpu": time.process_time() - c0, "acc": [[k[0], k[1], v] for k, v in acc.items()],
                  "ncomp": ncomp, "libs": libs, "passes": pass_t}))
"""

STAGES = ("typing", "lowering", "llvm_opt", "llvm_code", "llvm_other", "other", "gc")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--json", help="also write the raw per-function figures here")
    args = ap.parse_args()
    data = cold_probe(args.src, PROBE)
    if args.json:
        Path(args.json).write_text(json.dumps(data))
    per: dict[str, dict[str, float]] = {}
    for name, stage, s in data["acc"]:
        per.setdefault(name, {})[stage] = per.get(name, {}).get(stage, 0.0) + s
    share: dict[str, tuple[int, int]] = {}
    callers: dict[str, list[int]] = {}
    alone: dict[str, float] = {}
    for fn, _lib, own, linked, cost in data["libs"]:
        alone[fn] = alone.get(fn, 0.0) + cost
        o, t = share.get(fn, (0, 0))
        share[fn] = (o + own, t + own + sum(n for _, n in linked))
        for lib, n in linked:
            callers.setdefault(lib, []).append(n)
    probe = sum(v.get("probe", 0.0) for v in per.values())
    outside = per.pop("<none>", {})
    rows = []
    for name, st in per.items():
        total = sum(v for k, v in st.items() if k in STAGES)
        own, tot = share.get(name, (0, 0))
        frac = 1.0 - own / tot if tot else 0.0
        rows.append((total, name, st, frac, alone.get(name, 0.0)))
    rows.sort(key=lambda r: -r[0])
    sums = {k: sum(r[2].get(k, 0.0) for r in rows) for k in STAGES}
    print(f"process CPU {data['process_cpu']:.1f} s (of it outside compiles {sum(outside.values()):.1f} s, "
          f"probe's own counting {probe:.1f} s); compile CPU {sum(sums.values()):.1f} s in {len(rows)} functions "
          f"({sum(data['ncomp'].values())} compilations); load average {os.getloadavg()[0]:.2f}")
    print("stages: " + ", ".join(f"{k} {v:.1f} s" for k, v in sums.items())
          + f"; the linked callees' code optimised and compiled alone {sum(r[4] for r in rows):.1f} s")
    by_pass: dict[str, float] = {}
    for k, v in data["passes"].items():
        by_pass[k.split(" ")[0]] = by_pass.get(k.split(" ")[0], 0.0) + v
    print("numba passes outside LLVM: " + ", ".join(
        f"{k} {v:.2f}" for k, v in sorted(by_pass.items(), key=lambda kv: -kv[1]) if v >= 0.1))
    print("largest (pass, function) outside LLVM: " + ", ".join(
        f"{k} {v:.2f}" for k, v in sorted(data["passes"].items(), key=lambda kv: -kv[1])[:args.top]))
    print("| function | total | typing | lowering | LLVM (opt + code + other) | callee IR share | callees alone "
          "| gc | n |")
    for total, name, st, frac, callee in rows[:args.top]:
        llvm = st.get("llvm_opt", 0.0) + st.get("llvm_code", 0.0) + st.get("llvm_other", 0.0)
        print(f"| {name} | {total:.2f} | {st.get('typing', 0.0):.2f} | {st.get('lowering', 0.0):.2f} | {llvm:.2f} "
              f"({st.get('llvm_opt', 0.0):.2f} + {st.get('llvm_code', 0.0):.2f} + {st.get('llvm_other', 0.0):.2f}) "
              f"| {frac:.0%} | {callee:.2f} | {st.get('gc', 0.0):.2f} | {data['ncomp'].get(name, 0)} |")
    print("callee libraries linked into most libraries (name, times linked, IR instructions each):")
    for lib, ns in sorted(callers.items(), key=lambda kv: -len(kv[1]) * max(kv[1]))[:args.top]:
        print(f"  {len(ns):3d} x {max(ns):6d}  {lib}")
    multi = sorted((n, k) for k, n in data["ncomp"].items() if n > 1 and k.startswith("dynslam2d."))
    print(f"dynslam2d functions compiled more than once: {multi}")


if __name__ == "__main__":
    main()
