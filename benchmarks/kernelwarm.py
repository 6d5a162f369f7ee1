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
the warm-up. :func:`kernel_cache_calls` counts numba's cache look-ups (loads and compiles) so that a benchmark can
show that none happened inside its measured run.

Loading a signature the run never calls changes nothing it computes: numba dispatches a call to the overload of its
exact argument types when it holds one, and a run's types are in the cache after any run of the same input (the
warm-up's or an earlier one); only the process's memory grows (≈ 1-2 MiB for the kernels of a real run).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from types import ModuleType
from typing import Any


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


def preload(extra: Iterable[ModuleType] = ()) -> None:
    """After a warm-up: :func:`load_cached_kernels` (``extra``: an A/B's other side's modules) and
    :func:`load_late_imports`, so that the measured run loads nothing the warm-up did not reach."""
    load_cached_kernels(extra=extra)
    load_late_imports()
