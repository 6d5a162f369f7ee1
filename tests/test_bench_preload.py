"""The benchmarks' preload (benchmarks/kernelwarm.py): every signature numba's cache holds is loaded into a fresh
dispatcher before a measured run, so that the run neither loads nor compiles a kernel."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np

SOURCE = '''
from numba import njit


@njit(cache=True)
def plus_one(x):
    return x + 1


@njit(cache=True)
def scaled(a, s):
    return a * s
'''


def _kernelwarm():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        return importlib.import_module("kernelwarm")
    finally:
        sys.path.pop(0)


def _fresh(name: str):
    """Module ``name`` imported anew (new dispatchers, nothing compiled or loaded in them)."""
    sys.modules.pop(name, None)
    return importlib.import_module(name)


def test_preload_loads_every_cached_signature_and_the_run_then_loads_nothing(tmp_path, monkeypatch):
    kw = _kernelwarm()
    pkg = "neg71preload"
    (tmp_path / pkg).mkdir()
    (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / pkg / "kern.py").write_text(SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    name = f"{pkg}.kern"
    try:
        mod = _fresh(name)
        assert mod.plus_one(1) == 2 and mod.plus_one(1.5) == 2.5  # two signatures compiled and cached
        assert np.array_equal(mod.scaled(np.arange(3.0), 2.0), [0.0, 2.0, 4.0])

        mod = _fresh(name)  # a new process's view: the cache holds them, the dispatchers nothing
        assert all(len(d.overloads) == 0 for d in (mod.plus_one, mod.scaled))
        assert kw.load_cached_kernels(pkg) == 3
        assert len(mod.plus_one.overloads) == 2 and len(mod.scaled.overloads) == 1
        assert kw.load_cached_kernels(pkg) == 0  # (already held: nothing loaded twice)
        before = kw.kernel_cache_calls(pkg)
        assert before == 0
        assert mod.plus_one(41) == 42 and mod.plus_one(0.25) == 1.25
        assert np.array_equal(mod.scaled(np.arange(3.0), 3.0), [0.0, 3.0, 6.0])
        assert kw.kernel_cache_calls(pkg) == before  # the calls loaded and compiled nothing

        # an A/B's other side: a module of another name, its kernels reached through ``extra``
        other = _fresh(name)
        assert kw.load_cached_kernels("no-such-prefix") == 0
        assert kw.load_cached_kernels("no-such-prefix", extra=[other]) == 3

        # the source changed since: numba's index is stale, nothing is loaded (the run compiles, as without it)
        (tmp_path / pkg / "kern.py").write_text(SOURCE.replace("x + 1", "x + 10"))
        importlib.invalidate_caches()
        mod = _fresh(name)
        assert kw.load_cached_kernels(pkg) == 0
        assert mod.plus_one(1) == 11
        assert kw.kernel_cache_calls(pkg) == 1  # that compile is counted
    finally:
        for n in (name, pkg):
            sys.modules.pop(n, None)
