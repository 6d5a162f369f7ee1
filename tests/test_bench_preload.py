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


def _package(tmp_path: Path, monkeypatch, pkg: str, source: str) -> str:
    """A package ``pkg`` with module ``kern`` holding ``source``, importable, its kernels cached in a folder of this
    test only (a cache left by an earlier run at the same temporary path cannot stand in for a compile); returns the
    module's name."""
    from numba.core import config

    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba-cache"))
    (tmp_path / pkg).mkdir()
    (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / pkg / "kern.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    return f"{pkg}.kern"


def test_preload_loads_every_cached_signature_and_the_run_then_loads_nothing(tmp_path, monkeypatch):
    kw = _kernelwarm()
    pkg = "neg71preload"
    name = _package(tmp_path, monkeypatch, pkg, SOURCE)
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


LITERAL_SOURCE = '''
import numpy as np
from numba import njit

CAP = 64


@njit(cache=True)
def capped(x, cap):
    return min(x, cap)


@njit(cache=True)
def caller(x):
    return capped(x, CAP)  # (a module constant: the callee is compiled for ``Literal[int](64)``)
'''


def test_a_literal_signature_is_parsed_and_compiled_by_the_preload(tmp_path, monkeypatch):
    kw = _kernelwarm()
    pkg = "bch88literal"
    name = _package(tmp_path, monkeypatch, pkg, LITERAL_SOURCE)
    try:
        mod = _fresh(name)
        assert mod.caller(100) == 64
        held = kw.held_signatures(pkg)
        literal = [(n, s) for n, s in held if "Literal[int](64)" in s]
        assert [n for n, _ in literal] == [f"{name}.capped"], held
        mod = _fresh(name)  # a new process's view
        done, failed = kw.compile_recorded(held + [(f"{pkg}.gone.kernel", "(int64,)")])  # (one this side lacks)
        assert failed == [] and done == 2
        assert len(mod.capped.overloads) == 1 and len(mod.caller.overloads) == 1
        assert kw.compile_recorded(held) == (0, [])  # (held already)
        assert kw.compile_recorded([(f"{name}.capped", "(int64, Nonsense[int](3),)")])[1]  # a failure is listed
    finally:
        for n in (name, pkg):
            sys.modules.pop(n, None)


def test_every_recorded_kernel_parses_and_names_a_kernel_of_this_checkout():
    """Each (kernel, signature) of jitmanifest.py and benchmarks/run_kernels.json reads back to the same text and
    names a numba kernel: a signature the preload could not parse would be compiled inside a measured run."""
    from numba.core.registry import CPUDispatcher

    from dynslam2d.jitwarm import signature_text

    kw = _kernelwarm()
    pairs = kw.recorded_kernels()
    assert len(pairs) > 40 and kw.RUN_KERNELS.is_file()
    assert any("Literal[" in s for _, s in pairs)  # (mapevidence._free_steps's cap)
    assert any("vec4" in s for _, s in pairs)  # (a type of the project's: jitvec.py)
    for name, text in pairs:
        module, _, attr = name.rpartition(".")
        assert isinstance(getattr(importlib.import_module(module), attr), CPUDispatcher), name
        assert signature_text(kw.parse_signature(text)) == text, name
