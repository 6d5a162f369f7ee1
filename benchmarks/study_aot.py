"""Feasibility study (issue 13 items 2 and 3, pass aot40): the project's numba kernels compiled ahead of time with
``numba.pycc`` into one extension module, called without numba in the process.

    PYTHONPATH=src python benchmarks/study_aot.py capture INPUT   # record real arguments of the studied kernels
    PYTHONPATH=src python benchmarks/study_aot.py build           # AOT-compile them into WORK/aotkernels*.so
    PYTHONPATH=src python benchmarks/study_aot.py compare         # bits and warm timings, AOT against JIT
    PYTHONPATH=src python benchmarks/study_aot.py memory          # RSS of fresh processes: AOT only / numba JIT
    PYTHONPATH=src python benchmarks/study_aot.py --work W --name aotall build-all --fresh-flags   # all kernels
    PYTHONPATH=src python benchmarks/study_aot.py --work W memory-all --mods W/aotall    # RSS with every kernel
    PYTHONPATH=src python benchmarks/study_aot.py --work W held INPUT     # the signatures a JIT run holds
    PYTHONPATH=src python benchmarks/study_aot.py --work W --name aotheld build-all --fresh-flags --held W/held.json
    PYTHONPATH=src python benchmarks/study_aot.py --work W --name aotheld run-nonumba INPUT --out OUT  # no numba

Everything goes to ``--work`` (default <temp dir>/dynslam2d-aot). ``capture`` runs ``dynslam2d run INPUT`` with numba's
dispatcher call patched to deep-copy the arguments of the studied kernels' first calls (every ``--every``-th, at
most ``--keep``), and stops the run once each kernel has them. ``build`` exports each kernel's Python function
(``Dispatcher.py_func``) with the signature it compiled for in the capture (its return type included) through
``numba.pycc.CC`` and times the build. ``compare`` calls both versions on copies of each captured argument list,
compares every returned value and every argument array afterwards (arrays written in place) bit for bit, then times
them alternated (AOT, JIT, AOT, ...) and prints medians. ``memory`` starts fresh interpreters that load the
arguments and call every studied kernel once: one importing only numpy and the AOT module (and checking that
``numba`` is not in ``sys.modules``), one importing the kernel modules and calling the JIT kernels from the warm
cache. ``build-all`` exports every kernel of :mod:`dynslam2d.jitmanifest` (one signature each) into one module;
``--fresh-flags`` gives each kernel's compile its own copy of pycc's compiler flags (pycc hands one ``Flags`` object
to every export, and numba's pipeline clears its ``enable_ssa`` on the first, so later kernels are typed without SSA
and some fail to unify integer literals). Not run by pytest; numbers go to docs/speed.md (pass aot40).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

KERNELS = (
    "dynslam2d.slam.matcher.match_pyramid",
    "dynslam2d.slam.raycast.integrate_levels",
    "dynslam2d.detect.shapes.fit_cluster_rows",
    "dynslam2d.slam.ledgerkernels.record_cells",
)


def export_name(qual: str) -> str:
    """The AOT module's name of a kernel: its module's last part and its name."""
    mod, _, name = qual.rpartition(".")
    return f"{mod.rpartition('.')[2]}__{name}"


def _dispatcher(qual: str):  # noqa: ANN202
    import importlib

    mod, _, name = qual.rpartition(".")
    return getattr(importlib.import_module(mod), name)


def capture(args: argparse.Namespace) -> None:
    from numba.core import registry

    from dynslam2d.cli import main

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    seen: dict[str, int] = {}
    calls: dict[str, list] = {q: [] for q in KERNELS}
    wanted = {q.rpartition(".")[2]: q for q in KERNELS}
    base_call = registry.CPUDispatcher.__mro__[1].__call__

    class Enough(Exception):
        pass

    def call(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        qual = wanted.get(self.py_func.__name__)
        if qual is not None and f"{self.py_func.__module__}.{self.py_func.__name__}" == qual:
            n = seen[qual] = seen.get(qual, 0) + 1
            if n % args.every == 1 % args.every and len(calls[qual]) < args.keep:
                calls[qual].append(copy.deepcopy(a))
            if all(len(v) >= args.keep for v in calls.values()):
                raise Enough
        return base_call(self, *a, **k)

    registry.CPUDispatcher.__call__ = call
    sys.argv = ["dynslam2d", "run", args.input, "--out", str(work / "run"), "-q"]
    try:
        main()
    except (Enough, SystemExit):
        pass
    sigs = {}
    for q in KERNELS:
        d = _dispatcher(q)
        sig = d.nopython_signatures[0]
        sigs[q] = [str(sig.return_type), [str(t) for t in sig.args]]
        with open(work / f"args_{export_name(q)}.pkl", "wb") as fh:
            pickle.dump(calls[q], fh)
        print(f"{q}: {len(calls[q])} calls of {seen.get(q, 0)} kept; returns {sig.return_type}")
    with open(work / "signatures.pkl", "wb") as fh:
        pickle.dump({q: _dispatcher(q).nopython_signatures[0] for q in KERNELS}, fh)
    (work / "signatures.json").write_text(json.dumps(sigs, indent=1))


def held(args: argparse.Namespace) -> None:
    """``dynslam2d run INPUT`` with the JIT kernels, then every signature each dynslam2d dispatcher holds into
    ``--work``/held.json ({kernel: [signature text, ...]}), as benchmarks/bench_memory_floor.py records them."""
    from numba.core.registry import CPUDispatcher

    from dynslam2d.cli import main as cli_main
    from dynslam2d.jitwarm import signature_text

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    sys.argv = ["dynslam2d", "run", args.input, "--out", str(work / "run-held"), "-q"]
    try:
        cli_main()
    except SystemExit:
        pass
    out: dict[str, list[str]] = {}
    for name, mod in list(sys.modules.items()):
        if mod is None or not name.startswith("dynslam2d"):
            continue
        for attr, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name:
                for sig in obj.signatures:
                    out.setdefault(f"{name}.{attr}", []).append(signature_text(sig))
    (work / "held.json").write_text(json.dumps(out, indent=1))
    print(f"{len(out)} kernels, {sum(len(v) for v in out.values())} signatures")


def build(args: argparse.Namespace) -> None:
    import warnings

    work = Path(args.work)
    t0 = time.perf_counter()
    c0 = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from numba.pycc import CC
    for w in caught:
        print(f"warning at import: {w.category.__name__}: {str(w.message).splitlines()[0]}")
    with open(work / "signatures.pkl", "rb") as fh:
        sigs = pickle.load(fh)
    names = [q for q in KERNELS if q in sigs and (not args.only or export_name(q) in args.only.split(","))]
    modname = args.name
    cc = CC(modname)
    cc.output_dir = str(work)
    cc.verbose = False
    cc.target_cpu = args.cpu
    for q in names:
        cc.export(export_name(q), sigs[q])(_dispatcher(q).py_func)
    t_imp = time.perf_counter() - t0
    cc.compile()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    so = next(work.glob(f"{modname}*.so"))
    print(json.dumps({"cpu": args.cpu, "kernels": names, "so": str(so), "so_bytes": so.stat().st_size, "wall_s": wall,
                      "cpu_s_parent": cpu, "import_s": t_imp}))


def build_all(args: argparse.Namespace) -> None:
    """Every kernel of :mod:`dynslam2d.jitmanifest` (one signature each, its return type from the JIT compile of
    that signature, from the warm cache) exported into one AOT module; kernels pycc rejects are listed, left out
    and the rest built again."""
    import warnings

    from dynslam2d.jitmanifest import KERNELS as MANIFEST
    from dynslam2d.jitwarm import _dispatcher as disp_of
    from dynslam2d.jitwarm import parse_signature

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from numba.pycc import CC
    from numba.core import typing

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    entries = []
    pairs = [(n, t) for n, t in MANIFEST]
    if args.held:  # every (kernel, signature) a run held (JSON {kernel: [signature text, ...]})
        pairs = [(n, t) for n, texts in json.loads(Path(args.held).read_text()).items() for t in texts]
    numbered: dict[str, int] = {}
    for name, text in pairs:
        d = disp_of(name)
        argt = parse_signature(text)
        k = numbered[name] = numbered.get(name, -1) + 1
        if k:  # a second signature of a kernel: exported as export_name + "_s<k>"
            name = f"{name}_s{k}"
        if d._can_compile:
            d.compile(argt)
        if argt in d.overloads:
            entries.append((name, typing.signature(d.overloads[argt].signature.return_type, *argt), d.py_func))
        else:  # declared with its signature(s) in the source: numba compiled them at import
            held_sigs = [sg for sg in d.nopython_signatures if tuple(sg.args) == argt] or d.nopython_signatures
            entries.append((name, held_sigs[0], d.py_func))
    from numba.pycc.compiler import ExportEntry, ModuleCompiler

    failed: dict[str, str] = {}
    per_kernel: dict[str, float] = {}
    for name in args.exclude.split(","):
        if name:
            failed[name] = "excluded (--exclude)"
    # with --probe, each kernel typed and lowered alone by pycc's compiler first: which ones it rejects
    for name, sig, fn in entries if args.probe else ():
        t0 = time.perf_counter()
        try:
            ModuleCompiler([ExportEntry(export_name(name), sig, fn)], "probe", use_nrt=True)._cull_exports()
        except Exception as exc:  # noqa: BLE001 - any rejection is a finding
            lines = [ln for ln in str(exc).splitlines() if ln.strip()]
            failed[name] = f"{type(exc).__name__}: " + " | ".join(lines[:2] + lines[-3:])
            print(f"pycc rejects {name}: {failed[name]}", flush=True)
        per_kernel[name] = time.perf_counter() - t0
    (work / "per_kernel_s.json").write_text(json.dumps(per_kernel, indent=1))
    import numba.pycc.compiler as pycc_compiler

    current: list[str] = []
    plain_compile_extra = pycc_compiler.compile_extra

    def compile_extra(typingctx, targetctx, func, *rest, **kw):  # noqa: ANN001, ANN002, ANN003, ANN202
        current.append(f"{func.__module__}.{func.__name__}")  # the kernel pycc is compiling when it raises
        if args.fresh_flags:  # pycc hands one Flags object to every export's compile
            rest = (rest[0], rest[1], rest[2].copy(), *rest[3:])
        return plain_compile_extra(typingctx, targetctx, func, *rest, **kw)

    pycc_compiler.compile_extra = compile_extra
    while True:
        current.clear()
        cc = CC(args.name)
        cc.output_dir = str(work)
        cc.target_cpu = args.cpu
        names = [e for e in entries if e[0] not in failed]
        for name, sig, fn in names:
            cc.export(export_name(name), sig)(fn)
        t0 = time.perf_counter()
        c0 = time.process_time()
        try:
            cc.compile()
            break
        except Exception as exc:  # noqa: BLE001 - pycc's errors name the kernel only in their text
            lines = [ln for ln in str(exc).splitlines() if ln.strip()]
            msg = f"{type(exc).__name__}: " + " | ".join(lines[:2] + lines[-4:])
            if not current:
                raise
            failed[current[-1]] = msg
            print(f"left out {current[-1]} (after {len(current) - 1} kernels compiled in this build): {msg}",
                  flush=True)
    wall = time.perf_counter() - t0
    so = next(work.glob(f"{args.name}*.so"))
    print(json.dumps({"cpu": args.cpu, "kernels": len(names), "failed": failed, "so_bytes": so.stat().st_size,
                      "build_wall_s": wall, "build_cpu_s_parent": time.process_time() - c0}))


def _same(a, b) -> bool:  # noqa: ANN001
    import numpy as np

    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
                and a.tobytes() == b.tobytes())
    if isinstance(a, float):
        return isinstance(b, float) and np.float64(a).tobytes() == np.float64(b).tobytes()
    return type(a) is type(b) and a == b


def compare(args: argparse.Namespace) -> None:
    import importlib
    import statistics

    work = Path(args.work)
    sys.path.insert(0, str(work))
    aot = importlib.import_module(args.name)
    for q in KERNELS:
        en = export_name(q)
        if not hasattr(aot, en):
            continue
        jit = _dispatcher(q)
        with open(work / f"args_{en}.pkl", "rb") as fh:
            calls = pickle.load(fh)
        fa = getattr(aot, en)
        same = 0
        for a in calls:
            a1, a2 = copy.deepcopy(a), copy.deepcopy(a)
            r1, r2 = jit(*a1), fa(*a2)
            same += _same(r1, r2) and _same(a1, a2)
        reps = args.reps
        t_aot: list[float] = []
        t_jit: list[float] = []
        for rep in range(reps):
            pair = ((fa, t_aot), (jit, t_jit))
            for fn, acc in pair if rep % 2 == 0 else pair[::-1]:  # alternated, each first in half the rounds
                cs = [copy.deepcopy(a) for a in calls]
                t0 = time.perf_counter_ns()
                for a in cs:
                    fn(*a)
                acc.append((time.perf_counter_ns() - t0) / len(cs) / 1e3)
        ma, mj = statistics.median(t_aot), statistics.median(t_jit)
        print(f"{q}: {same}/{len(calls)} calls bit-identical (returns and arguments); per call AOT {ma:.1f} us, "
              f"JIT {mj:.1f} us, AOT/JIT x{ma / mj:.3f} (medians of {reps} alternated rounds)")


PROBE = r"""
import os, pickle, sys, json
PAGE = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE / 2**20
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM"):
            return int(line.split()[1]) / 1024
rows = [("interpreter", rss())]
import numpy
rows.append(("+ numpy", rss()))
work, mode, name, kernels = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(",")
sys.path.insert(0, work)
if mode == "aot":
    import importlib
    mod = importlib.import_module(name)
    fns = [getattr(mod, k) for k in kernels]
    rows.append(("+ the AOT module", rss()))
else:
    import importlib
    fns = []
    for q in kernels:
        m, _, n = q.rpartition(".")
        fns.append(getattr(importlib.import_module(m), n))
    rows.append(("+ numba and the kernels' modules", rss()))
args = [pickle.load(open(os.path.join(work, f"first_{a}.pkl"), "rb")) for a in sys.argv[5].split(",")]
rows.append(("+ one argument list per kernel", rss()))
for fn, a in zip(fns, args):
    fn(*a)
rows.append(("+ each kernel called once", rss()))
print(json.dumps({"rows": rows, "numba_loaded": "numba" in sys.modules, "llvmlite_loaded": "llvmlite" in sys.modules,
                  "hwm": hwm()}))
"""


def memory(args: argparse.Namespace) -> None:
    import importlib

    work = Path(args.work)
    sys.path.insert(0, str(work))
    aot = importlib.import_module(args.name)
    quals = [q for q in KERNELS if hasattr(aot, export_name(q))]
    ens = [export_name(q) for q in quals]
    for en in ens:  # the first captured call's arguments alone, so that the probe holds one argument list each
        with open(work / f"args_{en}.pkl", "rb") as fh, open(work / f"first_{en}.pkl", "wb") as out:
            pickle.dump(pickle.load(fh)[0], out)
    env = dict(os.environ)
    for mode, names in (("aot", ens), ("jit", quals)):
        # the JIT probe's first call fills the cache if it is cold: run it twice and keep the second
        for _ in range(2 if mode == "jit" else 1):
            res = subprocess.run([sys.executable, "-c", PROBE, str(work), mode, args.name, ",".join(names),
                                  ",".join(ens)], env=env, capture_output=True, text=True)
        if res.returncode != 0:
            raise SystemExit(res.stderr[-3000:])
        out = json.loads(res.stdout.strip().splitlines()[-1])
        print(f"{mode}: numba in sys.modules: {out['numba_loaded']}, llvmlite: {out['llvmlite_loaded']}, "
              f"VmHWM {out['hwm']:.1f} MiB")
        prev = 0.0
        for label, mib in out["rows"]:
            print(f"  {label:<40} RSS {mib:7.1f} MiB (+{mib - prev:5.1f})")
            prev = mib


def run_aot(args: argparse.Namespace) -> None:
    """``dynslam2d run INPUT --out OUT -q`` with every kernel of the AOT module ``--name`` in ``--work`` put in place
    of the JIT kernel in every dynslam2d module that holds it: a call whose argument types (numba's ``typeof``) are
    the exported signature's goes to the AOT function, any other to the JIT kernel (counted: pycc's wrapper checks
    neither dtype nor layout). numba stays imported (the modules import it); this checks the results, not memory."""
    import importlib
    from collections import Counter

    from numba.core.registry import CPUDispatcher

    from dynslam2d.cli import main as cli_main
    from dynslam2d.jitmanifest import KERNELS as MANIFEST

    sys.path.insert(0, args.work)
    aot = importlib.import_module(args.name)
    import dynslam2d.pipeline  # noqa: F401 - the run's modules, so that every holder of a kernel is patched

    for name, _t in MANIFEST:
        importlib.import_module(name.rpartition(".")[0])
    counts: Counter = Counter()
    swaps = {}
    from dynslam2d.jitwarm import parse_signature

    jit_only = set(args.jit.split(",")) if args.jit else set()

    def make(disp, fn, argt, name):  # noqa: ANN001, ANN202
        if args.trust:  # no type check: the kernels named by --jit always JIT, the others always AOT
            return disp if name in jit_only else fn

        def call(*a):  # noqa: ANN002, ANN202
            if len(a) == len(argt) and all(disp.typeof_pyval(x) == t for x, t in zip(a, argt)):
                counts[(name, "aot")] += 1
                return fn(*a)
            counts[(name, "jit")] += 1
            return disp(*a)
        return call

    for name, text in MANIFEST:
        en = export_name(name)
        if hasattr(aot, en):
            disp = _dispatcher(name)
            swaps[id(disp)] = make(disp, getattr(aot, en), parse_signature(text), name)
    n = 0
    for modname, mod in list(sys.modules.items()):
        if mod is None or not modname.startswith("dynslam2d"):
            continue
        for attr, obj in list(vars(mod).items()):
            if isinstance(obj, CPUDispatcher) and id(obj) in swaps:
                setattr(mod, attr, swaps[id(obj)])
                n += 1
    print(f"{n} module attributes now the AOT kernels ({len(swaps)} kernels)", flush=True)
    sys.argv = ["dynslam2d", "run", args.input, "--out", args.out, "-q"]
    try:
        cli_main()
    except SystemExit:
        pass
    jit_calls = {k[0]: v for k, v in counts.items() if k[1] == "jit"}
    print(f"calls: AOT {sum(v for k, v in counts.items() if k[1] == 'aot')}, JIT fallback {sum(jit_calls.values())} "
          f"{jit_calls}")


NONUMBA = r"""
import importlib.abc, importlib.machinery, json, os, sys, types


class Anything:
    # every numba / llvmlite name the run's modules touch at import: callable, subscriptable, with any attribute
    def __init__(self, *a, **k):
        pass

    def __call__(self, *a, **k):
        return Anything()

    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        return Anything()

    def __getitem__(self, key):
        return Anything()

    def __mro_entries__(self, bases):
        return (AnyBase,)


class AnyBase:
    # the base of a class the modules derive from a numba name
    def __init__(self, *a, **k):
        pass

work, name, inp, out = sys.argv[1:5]
AOT = {}


class Kernel:
    # what ``njit`` returns here: calls go to the AOT export whose argument types the arguments have
    def __init__(self, fn):
        self.py_func = fn
        self.qual = f"{fn.__module__}.{fn.__name__}"

    def __call__(self, *a):
        for fn, checks in AOT.get(self.qual, ()):
            if all(c(x) for c, x in zip(checks, a)):
                return fn(*a)
        raise TypeError(f"no AOT export of {self.qual} for these arguments")


def njit(*a, **k):
    if len(a) == 1 and callable(a[0]) and not k:
        return Kernel(a[0])
    return lambda fn: Kernel(fn)


class Stub(types.ModuleType):
    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        if attr[:1].isupper():  # a class name (isinstance checks, bases): an empty class
            value = type(attr, (), {"__init__": lambda self, *a, **k: None})
        else:
            value = Anything()
        setattr(self, attr, value)
        return value


class Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path, target=None):
        if fullname.split(".")[0] in ("numba", "llvmlite"):
            return importlib.machinery.ModuleSpec(fullname, self, is_package=True)
        return None

    def create_module(self, spec):
        m = Stub(spec.name)
        m.__path__ = []
        if spec.name == "numba":
            m.njit = m.jit = njit
        return m

    def exec_module(self, module):
        pass


sys.meta_path.insert(0, Finder())
import numpy as np

sys.path.insert(0, work)
aot = importlib.import_module(name)
sigs = json.load(open(os.path.join(work, "held.json")))
DT = {"float64": np.float64, "float32": np.float32, "int64": np.int64, "int32": np.int32, "int8": np.int8,
      "uint8": np.uint8, "uint16": np.uint16, "bool": np.bool_, "complex128": np.complex128, "complex64": np.complex64}


def check(t):
    # a cheap check of one argument against its numba type text's array part (dtype, ndim, C layout)
    if t.startswith("Array("):
        parts = [p.strip() for p in t[len("Array("):].split(",")]
        dt, nd, layout = DT[parts[0]], int(parts[1]), parts[2].strip("'")
        return lambda x: (isinstance(x, np.ndarray) and x.dtype == dt and x.ndim == nd
                          and (layout != "C" or x.flags.c_contiguous))
    return lambda x: True


def split_args(text):
    depth, cur, outl = 0, "", []
    for ch in text.strip()[1:-1]:
        if ch == "," and depth == 0:
            if cur.strip():
                outl.append(cur.strip())
            cur = ""
            continue
        depth += ch in "(["
        depth -= ch in ")]"
        cur += ch
    if cur.strip():
        outl.append(cur.strip())
    return outl


for qual, texts in sigs.items():
    mod, _, kname = qual.rpartition(".")
    base = f"{mod.rpartition('.')[2]}__{kname}"
    for k, text in enumerate(texts):
        AOT.setdefault(qual, []).append((getattr(aot, base + (f"_s{k}" if k else "")),
                                         [check(t) for t in split_args(text)]))
from dynslam2d.cli import main
import dynslam2d.pipeline  # noqa: F401
PAGE = os.sysconf("SC_PAGE_SIZE")
floor = int(open("/proc/self/statm").read().split()[1]) * PAGE / 2**20
sys.argv = ["dynslam2d", "run", inp, "--out", out, "-q"]
try:
    main()
except SystemExit as exc:
    if exc.code not in (0, None):
        raise
hwm = [int(line.split()[1]) / 1024 for line in open("/proc/self/status") if line.startswith("VmHWM")][0]
print(json.dumps({"VmHWM_MiB": hwm, "RSS_before_run_MiB": floor,
                  "numba_stubbed": type(sys.modules.get("numba")).__name__}))
"""


def run_nonumba(args: argparse.Namespace) -> None:
    """``dynslam2d run INPUT`` in a fresh interpreter where ``numba`` and ``llvmlite`` are empty stand-ins (their
    ``njit`` returns a placeholder that calls the AOT export of ``--work``/``--name`` whose argument types fit; every
    other name an inert stand-in): the peak RSS of a run without numba's import, contexts or kernels. ``--work`` holds
    ``held.json`` (the signatures a JIT run held) and a module built from it (``build-all --held``)."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", NONUMBA, args.work, args.name, args.input, args.out],
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-4000:])
    print(res.stdout.strip().splitlines()[-1], f"process wall {time.perf_counter() - t0:.1f} s")


PROBE_ALL = r"""
import importlib, json, os, pickle, sys
PAGE = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE / 2**20
rows = [("interpreter", rss())]
import numpy
rows.append(("+ numpy", rss()))
work, mods = sys.argv[1], sys.argv[2].split(",")
fns = {}
for m in mods:
    d, _, name = m.rpartition("/")
    sys.path.insert(0, d)
    mod = importlib.import_module(name)
    fns.update({k: getattr(mod, k) for k in dir(mod) if "__" in k and not k.startswith("_")})
rows.append((f"+ {len(mods)} AOT modules, {len(fns)} kernels", rss()))
calls = 0
for fn in sorted(os.listdir(work)):
    if fn.startswith("first_"):
        en = fn[len("first_"):-len(".pkl")]
        fns[en](*pickle.load(open(os.path.join(work, fn), "rb")))
        calls += 1
rows.append((f"+ {calls} of them called once", rss()))
print(json.dumps({"rows": rows, "numba": "numba" in sys.modules, "llvmlite": "llvmlite" in sys.modules}))
"""


def memory_all(args: argparse.Namespace) -> None:
    """RSS of a fresh interpreter that imports numpy and the AOT modules ``--mods`` (folder/name, comma-separated)
    and calls the kernels whose first captured arguments ``memory`` wrote into ``--work``."""
    res = subprocess.run([sys.executable, "-c", PROBE_ALL, args.work, args.mods], capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-3000:])
    out = json.loads(res.stdout.strip().splitlines()[-1])
    print(f"numba in sys.modules: {out['numba']}, llvmlite: {out['llvmlite']}")
    prev = 0.0
    for label, mib in out["rows"]:
        print(f"  {label:<40} RSS {mib:7.1f} MiB (+{mib - prev:5.1f})")
        prev = mib


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default=str(Path(tempfile.gettempdir()) / "dynslam2d-aot"))
    ap.add_argument("--name", default="aotkernels", help="the AOT extension module's name")
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("capture")
    p.add_argument("input")
    p.add_argument("--every", type=int, default=7)
    p.add_argument("--keep", type=int, default=40)
    p = sub.add_parser("held")
    p.add_argument("input")
    p = sub.add_parser("build")
    p.add_argument("--only", default="", help="comma-separated export names (default: all captured)")
    p.add_argument("--cpu", default="", help="LLVM CPU name: '' generic x86-64 (pycc's default, what a wheel "
                   "needs), 'host' as numba's JIT, or e.g. 'x86-64-v3'")
    p = sub.add_parser("build-all")
    p.add_argument("--cpu", default="host")
    p.add_argument("--probe", action="store_true", help="first type and lower each kernel alone (pycc's compiler)")
    p.add_argument("--exclude", default="", help="comma-separated kernels (module.name) left out")
    p.add_argument("--fresh-flags", action="store_true", help="a copy of pycc's compiler flags for each kernel")
    p.add_argument("--held", default="", help="JSON of the signatures a run held (default: jitmanifest's)")
    p = sub.add_parser("run")
    p.add_argument("input")
    p.add_argument("--out", required=True)
    p.add_argument("--trust", action="store_true", help="no per-call type check (see --jit)")
    p.add_argument("--jit", default="", help="with --trust: comma-separated kernels left to numba's JIT")
    p = sub.add_parser("run-nonumba")
    p.add_argument("input")
    p.add_argument("--out", required=True)
    p = sub.add_parser("compare")
    p.add_argument("--reps", type=int, default=15)
    sub.add_parser("memory")
    p = sub.add_parser("memory-all")
    p.add_argument("--mods", required=True)
    args = ap.parse_args()
    {"capture": capture, "held": held, "build": build, "build-all": build_all, "compare": compare, "memory": memory,
     "run": run_aot, "run-nonumba": run_nonumba,
     "memory-all": memory_all}[args.cmd](args)


if __name__ == "__main__":
    main()
