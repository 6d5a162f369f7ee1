"""A kernel in dynslam2d.jitbox.LOOPS_NOT_VECTORISED is optimised without LLVM's loop vectoriser, every other kernel
with numba's pipeline, and both compute the same numbers (issue 13 item 2, docs/speed.md pass cmp50)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from dynslam2d import jitbox

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: argv[1] "1": the probe's kernel ``scaled`` in LOOPS_NOT_VECTORISED with its source's hash, "2": listed with
#: another hash (its source edited since it was measured), "0": not listed. Two kernels of a module named inside the
#: package (so that numba's compiles are a dynslam2d kernel's; its source in the file argv[2]) with the same loops;
#: prints their results and whether their optimised code holds vector loops.
SCRIPT = r'''
import json, sys, types
import numpy as np
from dynslam2d import jitbox
MOD = "dynslam2d._vectoriser_probe"
source = """
import numpy as np
from numba import njit
@njit
def scaled(a, b, n):
    out = np.empty(n)
    total = 0
    for i in range(n):
        out[i] = a[i] * 2.5 + b[i]
        total += i * 3
    return out, total
@njit
def other(a, b, n):
    out = np.empty(n)
    total = 0
    for i in range(n):
        out[i] = a[i] * 2.5 + b[i]
        total += i * 3
    return out, total
"""
open(sys.argv[2], "w").write(source)
module = types.ModuleType(MOD)
module.__file__ = sys.argv[2]
sys.modules[MOD] = module
exec(compile(source, sys.argv[2], "exec"), module.__dict__)
if sys.argv[1] != "0":
    digest = jitbox.source_hash(module.scaled.py_func)
    assert len(digest) == 16
    jitbox.LOOPS_NOT_VECTORISED = {MOD + ".scaled": digest if sys.argv[1] == "1" else "0" * 16}
a = np.linspace(-3.0, 7.0, 101)
b = np.cos(a)
res = {}
for name in ("scaled", "other"):
    kernel = getattr(module, name)
    out, total = kernel(a, b, a.size)
    ir = kernel.overloads[kernel.signatures[0]].library.get_llvm_str()
    res[name] = {"out": out.tobytes().hex(), "total": int(total), "vector": "vector.body" in ir}
print(json.dumps(res))
'''


def _probe(listed: str, tmp_path: Path) -> dict[str, dict[str, object]]:
    env = {"PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / listed), "PATH": "/usr/bin:/bin"}
    done = subprocess.run([sys.executable, "-c", SCRIPT, listed, str(tmp_path / f"probe{listed}.py")], env=env,
                          capture_output=True, text=True, timeout=300, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_listed_kernel_is_not_vectorised_and_computes_the_same(tmp_path: Path) -> None:
    plain = _probe("0", tmp_path)
    listed = _probe("1", tmp_path)
    assert plain["scaled"]["vector"] and plain["other"]["vector"]  # numba's pipeline vectorises these loops
    assert not listed["scaled"]["vector"]
    assert listed["other"]["vector"]  # a kernel not listed keeps numba's pipeline
    for name in ("scaled", "other"):
        assert listed[name]["out"] == plain[name]["out"] and listed[name]["total"] == plain[name]["total"]


def test_kernel_edited_since_measured_keeps_numbas_pipeline(tmp_path: Path) -> None:
    """A listed kernel whose source has another hash than the listed one is vectorised as numba does it."""
    stale = _probe("2", tmp_path)
    assert stale["scaled"]["vector"] and stale["other"]["vector"]


def test_pipeline_sources_guard(monkeypatch: object) -> None:
    assert jitbox._pipeline_sources_checked()  # the numba this project pins
    monkeypatch.setitem(jitbox.PIPELINE_SOURCES, "CPUCodegen._pass_builder", "0" * 16)  # type: ignore[attr-defined]
    assert not jitbox._pipeline_sources_checked()


def test_listed_kernels_exist_as_measured() -> None:
    """Every listed kernel exists and has the source whose stage was measured; a kernel edited since then is
    compiled with numba's pipeline: measure its stage in lockstep again (docs/speed.md, passes cmp50 and cmp51)
    and renew its hash in LOOPS_NOT_VECTORISED, or drop it from the list."""
    import importlib

    for name, digest in jitbox.LOOPS_NOT_VECTORISED.items():
        module, qualname = name.rsplit(".", 1)
        kernel = getattr(importlib.import_module(module), qualname)
        now = jitbox.source_hash(kernel.py_func)
        assert now == digest, f"{name} edited since measured (its source's hash now {now!r}; see this test's doc)"


#: Compiles the kernel argv[2] (``module.qualname``) for its manifest signature (an empty numba cache, the command
#: line's compile settings) and prints how many vector loops its optimised code holds, as listed (argv[1] "1") and
#: not ("0").
LISTED_PROBE = r'''
import sys
import dynslam2d.jitcache as jc
for name in ("plain_numba_errors", "load_blas_alone", "lean_numba_compile", "lean_compile_gc"):
    getattr(jc, name)()
from dynslam2d import jitbox
from dynslam2d.jitmanifest import KERNELS
from dynslam2d.jitwarm import _dispatcher, parse_signature
NAME = sys.argv[2]
if sys.argv[1] == "0":
    del jitbox.LOOPS_NOT_VECTORISED[NAME]
kernel = _dispatcher(NAME)
kernel.compile(parse_signature(dict(KERNELS)[NAME]))
print(kernel.overloads[kernel.signatures[0]].library.get_llvm_str().count("vector.body:"))
'''


def _vector_loops(name: str, tmp_path: Path) -> list[int]:
    """Vector loops in the optimised code of the kernel ``name`` compiled as listed, then with its entry removed."""
    counts = []
    for listed in ("1", "0"):
        env = {"PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / listed), "PATH": "/usr/bin:/bin",
               "DYNSLAM2D_COMPILE_WORKER": "0"}
        done = subprocess.run([sys.executable, "-c", LISTED_PROBE, listed, name], env=env, capture_output=True,
                              text=True, timeout=600, check=True)
        counts.append(int(done.stdout.strip().splitlines()[-1]))
    return counts


def test_associate_update_compiles_without_vector_loops(tmp_path: Path) -> None:
    """``associate_update`` (pass cmp144) is listed, and listing it takes the vector loops out of its code (numba's
    pipeline vectorises 14 of its loops, with the association gates' and the pair updates' code it links)."""
    listed, plain = _vector_loops("dynslam2d.detect.kernels_assign.associate_update", tmp_path)
    assert listed == 0 and plain > 0


def test_integrate_levels_compiles_without_vector_loops(tmp_path: Path) -> None:
    """The map update's ``integrate_levels`` (pass cmp148) is listed: its optimised code holds no vector loop (numba's
    pipeline vectorises some of its loops, with the ray kernel's code it links)."""
    listed, plain = _vector_loops("dynslam2d.slam.raycast.integrate_levels", tmp_path)
    assert listed == 0 and plain > 0
