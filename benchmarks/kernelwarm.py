"""Load every cached numba kernel and the modules a run imports late, before a benchmark's measured run (not run by
pytest; imported by the benchmarks).

A benchmark warms its kernels with a throw-away pipeline over the first scans (60 in most), but some kernels are
first called later: on negative_2/right the loop closer's ``graph_distances``, ``_ring_correlation`` and second
``_score_pyramid`` signature, the filter's ``observed_boxes_kernel`` and ``_rows_exclusion_kernel`` and the
matcher's ``_support_kernel`` are first called after scan 60, so numba loads them from its cache (≈ 100 ms in all)
inside the measured run, ≈ 0.2 ms a scan on a mean over 434 scans (both checkouts alike). :func:`load_cached_kernels`
loads, after the warm-up, every signature numba's cache holds for every kernel of the loaded ``dynslam2d`` modules
(the checkout the process imports, either side of an A/B): the measured run then finds them loaded.
The pose graph's first optimisation imports ``scipy.sparse`` and loads SciPy's SuperLU (``dynslam2d.lazyscipy``) the
same way, ≈ 90 ms of thread CPU, after the warm-up on negative_2 (its first loop); :func:`preload` does both after
the warm-up. The cache holds only what some run compiled for the source as it is now: in a fresh checkout, or after
a kernel module changed (numba drops that module's index), those kernels were compiled inside the measured run
(release 39's ``ab_1``). :func:`compile_recorded`, also in :func:`preload`, compiles (or loads) every signature
:data:`RUN_KERNELS` records that the dispatchers still lack, so the warm-up pays that too. Re-record it
(``python benchmarks/kernelwarm.py --record``) after a kernel's signature changes; ``--check`` compiles or loads
each entry and lists the ones that fail. :func:`kernel_cache_calls` counts numba's cache look-ups (loads and
compiles) so that a benchmark can show that none happened inside its measured run.

Loading a signature the run never calls changes nothing it computes: numba dispatches a call to the overload of its
exact argument types when it holds one, and a run's types are in the cache after any run of the same input (the
warm-up's or an earlier one); only the process's memory grows (≈ 1-2 MiB for the kernels of a real run).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

#: every (kernel, argument types) that a run of the benchmarks' inputs (:data:`RECORD_INPUTS`) holds at its end with
#: a cold cache, callees included; written by ``python benchmarks/kernelwarm.py --record`` (do not edit by hand)
RUN_KERNELS = Path(__file__).with_name("run_kernels.json")

#: the inputs :func:`record` runs: bench_digest.py's twelve (the six real recordings of the release lockstep, the
#: other two leg_tracker bags and four sims) and the README's first command's sim:paper
RECORD_INPUTS = ("negative_2/right", "negative_2/left", "negative_2/rear", "positive_1", "overtakes", "mit-csail",
                 "positive_7", "demo", "sim:drive", "sim:crowd", "sim:stop-and-go", "sim:corridor", "sim:paper")

#: numba's repr of a literal type, ``Literal[int](64)`` (a module constant one kernel passes to another, e.g.
#: ``mapevidence._free_steps``'s ``cap``): read as ``literal(64)`` (``numba.core.types.literal``)
_LITERAL = re.compile(r"Literal\[\w+\]\(")


def _dispatchers(prefix: str, extra: Iterable[ModuleType] = ()) -> Iterator[Any]:
    """The numba CPU dispatchers defined in the loaded ``prefix`` modules, and those that the ``extra`` modules (an
    A/B's other side imported under names of its own) hold or reach through a module they import; each once."""
    from numba.core.registry import CPUDispatcher

    seen: set[int] = set()
    mods = [m for n, m in list(sys.modules.items()) if m is not None and (n == prefix or n.startswith(prefix + "."))]
    for module, own in [(m, True) for m in mods] + [(m, False) for m in extra]:
        values = list(vars(module).values())
        if not own:  # (one level down: ``from . import kernels as k`` in the other side's module)
            values += [v for m in values if isinstance(m, ModuleType) for v in list(vars(m).values())]
        for obj in values:
            if isinstance(obj, CPUDispatcher) and id(obj) not in seen and (
                    not own or getattr(obj, "__module__", None) == module.__name__):
                seen.add(id(obj))
                yield obj


def _cached_signatures(disp: Any) -> list[tuple[Any, ...]]:
    """The argument types of the overloads numba's cache index holds for ``disp`` for this machine's code generator
    and the kernel's bytecode as it is now (numba's index key: signature, codegen magic tuple, code hashes); empty
    when the kernel does not cache or numba's internals differ."""
    cache = getattr(disp, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    try:
        index = cache_file._load_index()
        magic = disp.targetctx.codegen().magic_tuple()
        sigs = []
        for key in index:
            sig, key_magic, _ = key
            if key_magic == magic and cache._index_key(sig, disp.targetctx.codegen()) == key:
                sigs.append(tuple(sig))
        return sigs
    except Exception:  # noqa: BLE001 - not a disk-caching kernel, or numba internals changed: nothing to load
        return []


def load_cached_kernels(prefix: str = "dynslam2d", extra: Iterable[ModuleType] = ()) -> int:
    """Load into their dispatchers every signature numba's cache holds for the kernels of the loaded ``prefix``
    modules (and those of ``extra``, see :func:`_dispatchers`) that the dispatcher does not hold yet; returns how
    many were loaded. A signature whose load fails is
    left to the run (numba compiles it there, as without this call); nothing is compiled here."""
    loaded = 0
    for disp in _dispatchers(prefix, extra):
        for sig in _cached_signatures(disp):
            if sig in disp.overloads:
                continue
            try:
                cres = disp._cache.load_overload(sig, disp.targetctx)
                if cres is None:
                    continue
                # (what Dispatcher.compile does with a cache hit, without compiling on a miss)
                disp.targetctx.insert_user_function(cres.entry_point, cres.fndesc, [cres.library])
                disp.add_overload(cres)
            except Exception:  # noqa: BLE001 - left to the run, as without this call
                continue
            loaded += 1
    return loaded


def kernel_cache_calls(prefix: str = "dynslam2d", extra: Iterable[ModuleType] = ()) -> int:
    """numba's cache look-ups so far (hits: loads, misses: compiles) over the kernels of the loaded ``prefix``
    modules: the same count before and after a measured run means that no kernel was loaded or compiled in it."""
    return sum(sum(d.stats.cache_hits.values()) + sum(d.stats.cache_misses.values())
               for d in _dispatchers(prefix, extra))


#: modules the per-scan path imports inside a function on its first use, which may come after a warm-up: the pose
#: graph's optimisation and the second search's components (``slam/posegraph.py``, ``slam/secondsearch.py``)
LATE_IMPORTS = ("scipy.sparse",)


def load_late_imports() -> list[str]:
    """Import :data:`LATE_IMPORTS` and load ``dynslam2d.lazyscipy``'s compiled SciPy parts (its ``_loaded`` cache,
    filled as the run's first call would fill it), for the checkout this process imports; returns what was loaded
    here (none of it when the warm-up got there)."""
    import importlib

    done = [m for m in LATE_IMPORTS if m not in sys.modules]
    for m in done:
        importlib.import_module(m)
    try:
        import dynslam2d.lazyscipy as lazy
    except ImportError:  # (a checkout before it)
        return done
    loaded = getattr(lazy, "_loaded", None)
    if loaded is not None:
        for what in ("superlu", "components"):
            loaded(what)
            done.append(f"dynslam2d.lazyscipy {what}")
    return done


def _project_types(prefix: str = "dynslam2d") -> dict[str, Any]:
    """numba types the loaded ``prefix`` modules define, by their names (``dynslam2d.jitvec.vec4``: a callee's
    argument type in the record)."""
    from numba.core import types

    out: dict[str, Any] = {}
    for n, m in list(sys.modules.items()):
        if m is not None and (n == prefix or n.startswith(prefix + ".")):
            for v in list(vars(m).values()):
                if isinstance(v, types.Type) and str(v).isidentifier():
                    out.setdefault(str(v), v)
    return out


def parse_signature(text: str) -> tuple[Any, ...]:
    """The numba argument types of a signature's text (``dynslam2d.jitwarm.signature_text``'s, as in
    :mod:`dynslam2d.jitmanifest` and :data:`RUN_KERNELS`): ``dynslam2d.jitwarm.parse_signature``'s names (numba's
    types), and also literal types (``Literal[int](64)``) and the types the loaded ``dynslam2d`` modules define
    (import the kernel's module first)."""
    from numba.core import types

    names: dict[str, Any] = dict(vars(types))
    names.update(_project_types())
    names.update(bool=types.boolean, omitted=lambda default: types.Omitted(default), literal=types.literal)
    sig = eval(_LITERAL.sub("literal(", text), {"__builtins__": {}}, names)  # noqa: S307 - recorded numba names only
    return tuple(sig)


def recorded_kernels(path: Path = RUN_KERNELS) -> list[tuple[str, str]]:
    """The (kernel, signature text) pairs of :data:`RUN_KERNELS` and of :mod:`dynslam2d.jitmanifest` (the
    process's checkout's), each once, the manifest's first; the record's part is empty when its file is missing."""
    pairs: list[tuple[str, str]] = []
    try:
        from dynslam2d.jitmanifest import KERNELS
        pairs += [(n, s) for n, s in KERNELS]
    except ImportError:  # (a checkout before it)
        pass
    if path.is_file():
        pairs += [(n, s) for n, s in json.loads(path.read_text())]
    return list(dict.fromkeys(pairs))


def _dispatcher(name: str) -> Any:
    """The dispatcher ``module.attr`` of the process's checkout (its module imported when it is not yet)."""
    import importlib

    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def compile_recorded(kernels: Iterable[tuple[str, str]] | None = None) -> tuple[int, list[str]]:
    """Compile, or load from numba's cache, each recorded (kernel, signature) (:func:`recorded_kernels` by default)
    that the process's checkout's dispatcher does not hold yet: what :func:`load_cached_kernels` cannot load when the
    cache does not hold it (a fresh checkout, or a kernel module changed since the cache was written: the
    warm-up compiles what it reaches, the rest would compile inside the measured run). Returns (how many were
    compiled or loaded, the pairs that failed: signature not parsed, or the kernel does not compile for it). A
    kernel this checkout does not have (an older or newer checkout than the record) is skipped, not failed."""
    done, failed = 0, []
    for name, text in (recorded_kernels() if kernels is None else kernels):
        try:
            disp = _dispatcher(name)
        except (ImportError, AttributeError):
            continue
        try:
            args = parse_signature(text)
            if args in disp.overloads or not getattr(disp, "_can_compile", True):
                continue
            disp.compile(args)
        except Exception:  # noqa: BLE001 - left to the run, as without this call; reported to the caller
            failed.append(f"{name} {text}")
            continue
        done += 1
    return done, failed


def preload(extra: Iterable[ModuleType] = ()) -> None:
    """After a warm-up: :func:`load_cached_kernels` (``extra``: an A/B's other side's modules),
    :func:`compile_recorded` (the process's own checkout) and :func:`load_late_imports`, so that the measured run
    loads or compiles nothing the warm-up did not reach."""
    load_cached_kernels(extra=extra)
    compile_recorded()
    load_late_imports()


def held_signatures(prefix: str = "dynslam2d") -> list[tuple[str, str]]:
    """(kernel, signature text) of every overload the loaded ``prefix`` modules' dispatchers hold."""
    from numba.core.registry import CPUDispatcher

    from dynslam2d.jitwarm import signature_text

    mods = [(n, m) for n, m in list(sys.modules.items())
            if m is not None and (n == prefix or n.startswith(prefix + "."))]
    return [(f"{n}.{attr}", signature_text(sig)) for n, m in mods for attr, obj in list(vars(m).items())
            if isinstance(obj, CPUDispatcher) and obj.__module__ == n for sig in obj.signatures]


def record(data: Path, inputs: Iterable[str] = RECORD_INPUTS) -> list[tuple[str, str]]:
    """Run a ``Pipeline`` over every scan of each input (bench_digest.py's names; one missing under ``data`` is
    skipped) in this process and return :func:`held_signatures`, sorted. Run it with an empty numba cache
    (``NUMBA_CACHE_DIR``, as ``--record`` does) so that the callees a caller loaded from the cache would hide are
    compiled and held too."""
    from bench_digest import INPUTS
    from bench_pipeline import scan_loop_gc

    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    for name in inputs:
        rel, topic = INPUTS.get(name, (name, None))
        path = rel if rel.startswith("sim:") else str(data / rel)
        if not rel.startswith("sim:") and not Path(path).exists():
            print(f"{name}: missing under {data}, skipped", file=sys.stderr)
            continue
        pipe = Pipeline()
        with scan_loop_gc():
            for scan in open_source(path, topic):
                pipe.process(scan)
        print(f"{name}: done, {len(held_signatures())} signatures held", file=sys.stderr)
    return sorted(set(held_signatures()))


def main() -> None:
    ap = argparse.ArgumentParser(description="Record the kernels and signatures the benchmarks' inputs call "
                                             f"(written to {RUN_KERNELS.name}, read by preload()), or check them.")
    ap.add_argument("--record", action="store_true", help="run every input (cold numba cache in a temporary "
                    "folder) and write the record")
    ap.add_argument("--check", action="store_true", help="compile or load every recorded signature in this "
                    "process and list the ones that fail")
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    ap.add_argument("--inputs", nargs="+", default=list(RECORD_INPUTS))
    args = ap.parse_args()
    if args.record:
        import os
        import subprocess
        import tempfile

        if "NUMBA_CACHE_DIR" not in os.environ:
            with tempfile.TemporaryDirectory(prefix="kernelwarm-record-") as tmp:
                env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
                raise SystemExit(subprocess.call([sys.executable, __file__, *sys.argv[1:]], env=env))
        pairs = record(args.data, args.inputs)
        RUN_KERNELS.write_text(json.dumps(pairs, indent=0) + "\n")
        print(f"{len(pairs)} signatures of {len({n for n, _ in pairs})} kernels written to {RUN_KERNELS}")
    if args.check:
        done, failed = compile_recorded()
        print(f"{done} recorded signatures compiled or loaded, {len(failed)} failed")
        for f in failed:
            print(f"  failed: {f}")
        raise SystemExit(1 if failed else 0)


if __name__ == "__main__":
    main()
