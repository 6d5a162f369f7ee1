"""Cold compile of the README's first command by function (issue 13 item 2): runs ``dynslam2d run --out DIR``
(sim:paper) in a fresh interpreter with an empty numba cache and records, from numba's ``numba:compile``
events, the CPU time each function spends in numba's compiler excluding the functions it compiles in turn
(kernels, their callees and numba's own helpers such as ``np.empty``'s implementation).

    PYTHONPATH=src python benchmarks/bench_compile.py [--src src] [--top 25]
    PYTHONPATH=src python benchmarks/bench_compile.py --wait [--src src]
    PYTHONPATH=src python benchmarks/bench_compile.py --trace [--src src]
    PYTHONPATH=src python benchmarks/bench_compile.py --split [--src src] [--top 25]

Prints the process CPU of the whole run, the compile CPU summed over functions, their count (and the number of
compilations: numba's helpers such as ``np.empty``'s are compiled once per signature), the time in Python's cyclic
garbage collector (``gc.callbacks``; it lands on whichever function is compiling), the peak RSS, the system CPU and
minor page faults of the process (``getrusage``), the CPU inside
llvmlite's calls (numba's ``numba:llvm_lock`` event: LLVM's IR parsing, optimisation and machine code) in all and
per function, and the largest functions; this profile runs with the background compile off
(``DYNSLAM2D_COMPILE_WORKER=0``), so it counts all the compile work.

``--wait`` instead measures what a user waits for: the README's first command from an empty cache as the command
line runs it (the background compile on where there is a second CPU: do not pin it to one core with taskset),
and prints the wall time from interpreter start to exit, ``kernel_compile_s`` from summary.json, the run's
process CPU and the CPU of the processes it started (the background compile). ``--trace`` runs it the same way and
prints the timeline of both processes: every ``Dispatcher.compile`` call of a dynslam2d kernel or numba helper that
compiled (C) or loaded from the cache (L), with its start and end (s from the start), and which functions both
processes compiled. ``--split`` runs the profile's cold run (background compile off) and splits its compile CPU
the other way: by numba compiler pass (exclusive of the compiles a pass starts in turn: type inference compiles
the callees it types), by LLVM phase (the module pipeline, machine code, parsing numba's IR text, linking the
callees' modules), the Python wrappers numba builds for kernels called from Python and for those compiled only as
another kernel's callee, and the functions compiled for more than one signature. Not run by pytest; numbers go
to docs/speed.md with this command and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from scratch import scratch_dir

#: Probe code: the README's first command in this interpreter (``sys.argv[1]``: the results folder).
RUN_FIRST_COMMAND = r"""
from dynslam2d.cli import main
sys.argv = ["dynslam2d", "run", "--out", sys.argv[1], "--force", "-q"]
try:
    main()
except SystemExit:
    pass
"""

PROBE = r"""
import json, sys, time
c0 = time.process_time()
import dynslam2d.jitcache as jc  # what the command line's main() does before numba is imported:
for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile"):  # (older checkouts lack some)
    getattr(jc, name, lambda: None)()
from numba.core import event
excl, stack, n = {}, [], [0]
class Exclusive(event.Listener):
    def on_start(self, ev):
        f = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
        name = f"{f.__module__}.{f.__qualname__}" if f else "?"
        now = time.process_time()
        if stack:
            stack[-1][1] += now - stack[-1][2]
        stack.append([name, 0.0, now])
    def on_end(self, ev):
        now = time.process_time()
        name, acc, t = stack.pop()
        excl[name] = excl.get(name, 0.0) + acc + now - t
        n[0] += 1
        if stack:
            stack[-1][2] = now
event.register("numba:compile", Exclusive())
llvm, ll_t0 = {}, [0.0, 0]  # CPU inside llvmlite's calls (numba's "numba:llvm_lock" event; outermost only)
class LLVM(event.Listener):
    def on_start(self, ev):
        ll_t0[1] += 1
        if ll_t0[1] == 1:
            ll_t0[0] = time.process_time()
    def on_end(self, ev):
        ll_t0[1] -= 1
        if ll_t0[1] == 0:
            name = stack[-1][0] if stack else "?"
            llvm[name] = llvm.get(name, 0.0) + time.process_time() - ll_t0[0]
event.register("numba:llvm_lock", LLVM())
import gc, resource
collector, gc_t0 = [0.0, 0, 0], [0.0]  # the cyclic garbage collector: CPU s, collections, full ones
def _gc(phase, info):
    if phase == "start":
        gc_t0[0] = time.process_time()
    else:
        collector[0] += time.process_time() - gc_t0[0]
        collector[1] += 1
        collector[2] += info["generation"] == 2
gc.callbacks.append(_gc)
""" + RUN_FIRST_COMMAND + r"""
print(json.dumps({"process_cpu": time.process_time() - c0, "per": excl, "compilations": n[0], "gc": collector,
                  "llvm": llvm,
                  "rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "sys_cpu": resource.getrusage(resource.RUSAGE_SELF).ru_stime,
                  "minflt": resource.getrusage(resource.RUSAGE_SELF).ru_minflt}))
"""


WAIT = r"""
import json, resource, sys, time
""" + RUN_FIRST_COMMAND + r"""
kids = resource.getrusage(resource.RUSAGE_CHILDREN)
import gc
print(json.dumps({"process_cpu": time.process_time(), "children_cpu": kids.ru_utime + kids.ru_stime,
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "gc_on": gc.isenabled(), "gc_threshold": gc.get_threshold(), "gc_frozen": gc.get_freeze_count(),
                  "gc_collections": [g["collections"] for g in gc.get_stats()]}))
"""


TRACER = r"""
import json, os, sys, time
def _log(*row):
    with open(os.environ["TRACE_FILE"], "a") as f:
        f.write(json.dumps(row) + "\n")
def _install_tracer(who):
    from numba.core import dispatcher as _d
    orig, depth = _d.Dispatcher.compile, [0]
    def compile(self, sig):
        n0, h0 = sum(self._cache_misses.values()), sum(self._cache_hits.values())
        t0 = time.time(); depth[0] += 1
        try:
            return orig(self, sig)
        finally:
            depth[0] -= 1
            miss, hit = sum(self._cache_misses.values()) - n0, sum(self._cache_hits.values()) - h0
            if miss or hit:
                fn = self.py_func
                _log(who, f"{fn.__module__}.{fn.__qualname__}", t0, time.time(), "C" if miss else "L", depth[0])
    _d.Dispatcher.compile = compile
"""

TRACE_RUN = TRACER + r"""
import dynslam2d.jitcache as jc
for name in ("plain_numba_errors", "load_blas_alone"):
    getattr(jc, name, lambda: None)()
_install_tracer("run")
import dynslam2d.jitwarm as jw
_Popen = jw.subprocess.Popen
class _Shim:  # the background process as the command line starts it, with the tracer installed first
    def __getattr__(self, k):
        return getattr(__import__("subprocess"), k)
    def Popen(self, args, **kw):
        _log("run", "<spawn background compile>", time.time(), time.time(), "M", 0)
        i = args.index("-m")
        return _Popen(args[:i] + ["-c", os.environ["TRACE_WORKER"]] + args[i + 2:], **kw)
jw.subprocess = _Shim()
""" + RUN_FIRST_COMMAND + r"""
_log("run", "<exit>", time.time(), time.time(), "M", 0)
"""

TRACE_WORKER = TRACER + r"""
_log("bg", "<start>", time.time(), time.time(), "M", 0)
import dynslam2d.jitwarm as jw
def _traced(inner):
    def traced(*a, **k):
        _install_tracer("bg")
        return inner(*a, **k)
    return traced
for _name in ("compile_kernels", "compile_balanced"):  # (whichever the checkout's main() calls)
    if hasattr(jw, _name):
        setattr(jw, _name, _traced(getattr(jw, _name)))
jw.main(sys.argv[1:])
"""


SPLIT = PROBE.replace('event.register("numba:compile", Exclusive())', r"""
event.register("numba:compile", Exclusive())
from numba.core import codegen as _cg, compiler_machinery as _cm, cpu as _cpu
passes, pass_stack, phases, sigs = {}, [], {}, []
_run_pass = _cm.PassManager._runPass
def _timed_pass(self, index, pss, state):  # exclusive CPU per numba pass
    now = time.process_time()
    if pass_stack:
        pass_stack[-1][1] += now - pass_stack[-1][2]
    pass_stack.append([pss.name(), 0.0, now])
    try:
        return _run_pass(self, index, pss, state)
    finally:
        now = time.process_time()
        name, acc, t = pass_stack.pop()
        passes[name] = passes.get(name, 0.0) + acc + now - t
        if pass_stack:
            pass_stack[-1][2] = now
_cm.PassManager._runPass = _timed_pass
def _phase(cls, attr, key):  # inclusive CPU of one of numba's LLVM steps (or of its wrapper builder)
    plain = getattr(cls, attr)
    def timed(*a, **k):
        t = time.process_time()
        try:
            return plain(*a, **k)
        finally:
            row = phases.setdefault(key if key != "wrapper" else ("wrapper, callee" if len(stack) > 1
                                                                    else "wrapper, called from Python"), [0.0, 0])
            row[0] += time.process_time() - t
            row[1] += 1
    setattr(cls, attr, timed)
import dynslam2d.jitbox  # (its LLVM pipeline in place first: the one timed)
_phase(_cg.CPUCodeLibrary, "_optimize_final_module", "LLVM module pipeline")
_phase(_cg.JITCodeLibrary, "_finalize_specific", "LLVM machine code")
_phase(_cg.CPUCodeLibrary, "add_ir_module", "LLVM IR parse (numba's text)")
_phase(_cg.CPUCodeLibrary, "add_linking_library", "LLVM linking callees")
_phase(_cpu.CPUContext, "create_cpython_wrapper", "wrapper")
class Sigs(event.Listener):
    def on_start(self, ev):
        f = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
        sigs.append([f"{f.__module__}.{f.__qualname__}" if f else "?", str((ev.data or {}).get("args"))])
    def on_end(self, ev):
        pass
event.register("numba:compile", Sigs())
""").replace('"llvm": llvm,', '"llvm": llvm, "passes": passes, "phases": phases, "sigs": sigs,')


def split(src: str, top: int) -> None:
    """The cold run's compile CPU by numba pass, LLVM phase, Python wrapper and signature (``--split``)."""
    data = cold_probe(src, SPLIT)
    total = sum(data["per"].values())
    print(f"compile CPU {total:.1f} s in {len(data['per'])} functions; of it in LLVM "
          f"{sum(data['llvm'].values()):.1f} s; load average {os.getloadavg()[0]:.2f}; src {src}")
    print("numba passes (exclusive CPU; native_lowering holds the LLVM phases below):")
    for name, s in sorted(data["passes"].items(), key=lambda kv: -kv[1])[:top]:
        print(f"{s:6.2f} s  {name}")
    print("LLVM phases and Python wrappers (inclusive CPU, calls):")
    for name, (s, n) in sorted(data["phases"].items(), key=lambda kv: -kv[1][0]):
        print(f"{s:6.2f} s  {n:4d}  {name}")
    by: dict[str, list[str]] = {}
    for name, args in data["sigs"]:
        by.setdefault(name, []).append(args)
    print("compiled for more than one signature (compiles, exclusive CPU of all):")
    for name, args in sorted(by.items(), key=lambda kv: -len(kv[1])):
        if len(args) > 1:
            print(f"{len(args):4d}  {data['per'].get(name, 0.0):6.2f} s  {name}: " + "; ".join(sorted(set(args)))[:400])


def trace(src: str) -> None:
    """One cold run as ``wait`` starts it, with both processes' compile and cache-load timeline."""
    folder = Path(scratch_dir("bench-compile-"))
    log = folder / "trace.jsonl"
    t0 = time.time()
    env = dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=scratch_dir("numba-cold-"),
               TRACE_FILE=str(log), TRACE_WORKER=TRACE_WORKER)
    res = subprocess.run([sys.executable, "-c", TRACE_RUN, str(folder / "run")], env=env, capture_output=True,
                         text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    rows = sorted((json.loads(line) for line in log.read_text().splitlines()), key=lambda r: r[2])
    for who, name, a, b, kind, depth in rows:
        print(f"{who:3s} {a - t0:7.2f} {b - t0:7.2f} {b - a:6.2f} {kind} {'  ' * depth}{name}")
    compiled = {who: {r[1] for r in rows if r[0] == who and r[4] == "C"} for who in ("run", "bg")}
    summary = json.loads((folder / "run" / "summary.json").read_text())
    print(f"compiled by both: {sorted(compiled['run'] & compiled['bg'])}")
    print(f"wall {time.time() - t0:.1f} s; kernel_compile_s {summary['kernel_compile_s']:.1f} s; load average "
          f"{os.getloadavg()[0]:.2f}; src {src}")


def wait(src: str) -> None:
    """One cold run of the README's first command as a user starts it: wall time and CPU."""
    env = dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=scratch_dir("numba-cold-"))
    out = Path(scratch_dir("bench-compile-")) / "run"
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", WAIT, str(out)], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    data = json.loads(res.stdout.strip().splitlines()[-1])
    summary = json.loads((out / "summary.json").read_text())
    print(f"cold wait {wall:.1f} s wall; kernel_compile_s {summary['kernel_compile_s']:.1f} s; run process CPU "
          f"{data['process_cpu']:.1f} s, background compile CPU {data['children_cpu']:.1f} s; run peak RSS "
          f"{data['peak_rss_mib']:.0f} MiB; collector after the run: on {data['gc_on']}, thresholds "
          f"{tuple(data['gc_threshold'])}, frozen {data['gc_frozen']}, collections {data['gc_collections']}; "
          f"load average {os.getloadavg()[0]:.2f}; src {src}")


def cold_probe(src: str, probe: str) -> dict:
    """Run ``probe`` (Python code; argv[1] an output folder) on the checkout ``src`` with an empty numba cache and
    no background compile, in a fresh process; its last stdout line parsed as JSON."""
    env = dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=scratch_dir("numba-cold-"),
               DYNSLAM2D_COMPILE_WORKER="0")
    out = scratch_dir("bench-compile-") + "/run"
    res = subprocess.run([sys.executable, "-c", probe, out], env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--wait", action="store_true", help="the wall-time wait of a cold run instead of the profile")
    ap.add_argument("--trace", action="store_true", help="the timeline of both processes' compiles and loads")
    ap.add_argument("--split", action="store_true",
                    help="compile CPU by numba pass, LLVM phase, Python wrapper and signature (background off)")
    args = ap.parse_args()
    if args.split:
        split(args.src, args.top)
        return
    if args.wait or args.trace:
        (trace if args.trace else wait)(args.src)
        return
    data = cold_probe(args.src, PROBE)
    per = sorted(data["per"].items(), key=lambda kv: -kv[1])
    print(f"process CPU {data['process_cpu']:.1f} s; compile CPU {sum(v for _, v in per):.1f} s "
          f"in {len(per)} functions ({data['compilations']} compilations: a function compiled for several "
          f"signatures counts once per signature)")
    if "gc" in data:
        print(f"garbage collector {data['gc'][0]:.1f} s CPU in {data['gc'][1]} collections ({data['gc'][2]} full; "
              f"within the figures above); peak RSS {data['rss_mib']:.0f} MiB; load average {os.getloadavg()[0]:.2f}")
    if "minflt" in data:  # (system CPU and page faults: e.g. CPython's frame-stack chunks mapped per call, pass cold28)
        print(f"of the process CPU, system {data['sys_cpu']:.1f} s; minor page faults {data['minflt']}")
    llvm = data.get("llvm", {})
    if llvm:
        print(f"of the compile CPU, in LLVM (llvmlite's calls: IR parsing, optimisation, machine code): "
              f"{sum(llvm.values()):.1f} s")
    for name, s in per[:args.top]:
        print(f"{s:6.2f} s  {name}" + (f"  (LLVM {llvm.get(name, 0.0):.2f} s)" if llvm else ""))


if __name__ == "__main__":
    main()
