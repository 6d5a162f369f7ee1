"""jitcache.roomy_call / roomy_compile_stack (issue 13 item 2, pass cold28): numba's compiles run in a fresh 2 MiB
chunk of CPython's frame stack, so that no call of the compiler's loops maps and unmaps a 16 KiB chunk."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import TYPING_ERROR_PROBE

from dynslam2d import jitcache

SRC = str(Path(__file__).resolve().parents[1] / "src")

needs_data_stack = pytest.mark.skipif(
    sys.implementation.name != "cpython" or sys.version_info < (3, 11) or not sys.platform.startswith("linux"),
    reason="CPython's frame stack in chunks (3.11+); page faults counted by getrusage (Linux)")


def _leaf() -> None:
    return None


#: ``_leaf`` with a frame larger than ``_faults_at``'s (100 unused value-stack slots more): below the last
#: ``_faults_at`` frame that fits in a chunk, it does not fit, at every chunk boundary
_wide_leaf = type(_leaf)(_leaf.__code__.replace(co_stacksize=_leaf.__code__.co_stacksize + 100), globals())


def _faults_at(depth: int, calls: int) -> int:
    """Minor page faults of ``calls`` calls of a trivial function made ``depth`` frames below here."""
    import resource

    if depth:
        return _faults_at(depth - 1, calls)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(calls):
        _wide_leaf()
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


@needs_data_stack
def test_roomy_call_keeps_a_deep_call_loop_inside_one_chunk():
    """A loop of calls made at every depth from 0 to 400 frames (several 16 KiB chunk boundaries): called plainly,
    at some depths each call maps a new chunk and faults its page in; through roomy_call, at none."""
    calls = 300
    plain = [_faults_at(d, calls) for d in range(400)]
    roomy = [jitcache.roomy_call(_faults_at, d, calls) for d in range(400)]
    assert max(plain) >= calls  # (the thrash this guards against: one chunk per call at a boundary)
    assert max(roomy) < calls // 10
    assert jitcache.roomy_call(divmod, 7, 2) == (3, 1) and jitcache.roomy_call(int, "7", base=8) == 7


ROOMY = r"""
import json, re, sys
import numpy as np
from dynslam2d import jitcache
on = sys.argv[1] == "1"
if on:
    assert jitcache.roomy_compile_stack() and not jitcache.roomy_compile_stack()  # (once)
import numba
from numba.core import dispatcher
@numba.njit
def callee(x):
    s = 0.0
    for v in x:
        s += v * v
    return s
@numba.njit
def caller(x):
    y = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        y[i] = callee(x[: i + 1])
    return y
""" + TYPING_ERROR_PROBE + r"""x = np.random.default_rng(5).normal(size=40)
out = caller(x)
ir = re.sub(r"B\d+v\d+|0x[0-9a-f]+", "", caller.inspect_llvm(caller.signatures[0]))
print(json.dumps({"out": out.tolist(), "ir": ir, "error": error,
                  "roomy": getattr(dispatcher.Dispatcher.compile, "_dynslam2d_roomy", False)}))
"""


@needs_data_stack
def test_roomy_compile_stack_gives_the_same_code_and_errors(tmp_path):
    """jitcache.roomy_compile_stack: a kernel calling another compiles to the same LLVM IR and results as with
    numba's own compile, a typing error is raised as before, and a compile after the error still works."""
    got = {}
    for on in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{on}")}
        r = subprocess.run([sys.executable, "-c", ROOMY, on], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[on] = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["1"]["roomy"] and not got["0"]["roomy"]
    assert len(got["0"]["out"]) == 40 and got["0"]["out"] == got["1"]["out"]
    assert len(got["0"]["ir"]) > 1000 and got["0"]["ir"] == got["1"]["ir"]
    assert got["0"]["error"].startswith("TypingError") and got["0"]["error"] == got["1"]["error"]
    assert "callee" in got["1"]["ir"]  # (the callee was compiled inside the caller's compile)
