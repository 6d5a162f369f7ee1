"""The kernels' returned arrays are boxed without numba's per-array unpickle (dynslam2d.jitbox, docs/speed.md
pass unpickle)."""

from __future__ import annotations

import json
import subprocess
import sys

#: In a fresh interpreter (numba's C side keeps the first ``_numba_unpickle`` it sees, so the counter must be in
#: place before any compiled code runs): N calls of the matcher's ``gated_points`` (two arrays returned per call),
#: then one call of a kernel that raises (numba unpickles the exception's details: shows the counter counts).
PROBE = r"""
import json, sys
import numba.core.serialize as ser
calls = [0]
orig = ser._numba_unpickle
def counting(*a):
    calls[0] += 1
    return orig(*a)
ser._numba_unpickle = counting
import numpy as np
from dynslam2d.jitbox import njit
from dynslam2d.slam.matcher import gated_points
a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
r = 1.0 + 0.01 * np.arange(360.0)
r[::7] = np.inf
valid = np.isfinite(r)
args = (r, np.cos(a), np.sin(a), valid, 0.1, 30.0, 0.2, 25.0, 3.0, True)
got = gated_points(*args)
want = gated_points.py_func(*args)
same = all(np.array_equal(g, w) and g.dtype == w.dtype and type(g) is np.ndarray and g.flags.writeable
           for g, w in zip(got[:2], want[:2])) and got[2:] == want[2:]
refs = sys.getrefcount(np.ndarray)
before = calls[0]
for _ in range(500):
    gated_points(*args)
boxing = calls[0] - before
leaked = sys.getrefcount(np.ndarray) - refs

@njit(cache=False)
def fails(x):
    if x > 0:
        raise ValueError("positive")
    return x

before = calls[0]
try:
    fails(1.0)
except ValueError:
    pass
print(json.dumps({"same": same, "boxing": boxing, "leaked": leaked, "raise": calls[0] - before,
                  "n": int(got[0].shape[0])}))
"""


def test_returned_arrays_need_no_unpickle() -> None:
    """500 calls of a kernel returning two arrays call ``_numba_unpickle`` 0 times (numba's own boxing: 1000) and
    leave ``np.ndarray``'s reference count as it was (numba's own: +1000); the arrays equal the Python function's,
    are plain writable ndarrays; a raising kernel still unpickles its exception (1 call), so the counter works."""
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["same"]
    assert res["n"] > 300
    assert res["boxing"] == 0
    assert res["leaked"] == 0
    assert res["raise"] == 1


#: In a fresh interpreter and numba cache: compile a plain numba function of this script, then the matcher's
#: ``gated_points`` (a kernel with a callee), counting the LLVM function pipelines and "cheap" module pipelines numba
#: builds for each; with ``undo`` the optimisations jitbox skips are put back first. Prints the counts and the
#: kernel's outputs.
ONCE = r"""
import json, sys
import numpy as np
import numba
from numba.core import codegen
import dynslam2d.jitbox as jitbox
library = codegen.CPUCodeLibrary
if sys.argv[1] == "undo":
    library._optimize_functions = library._optimize_functions.__wrapped__
    library._optimize_final_module = library._optimize_final_module.__wrapped__
built = [0]
orig = codegen.CPUCodegen._function_pass_manager
def counting(self, **kw):
    built[0] += 1
    return orig(self, **kw)
codegen.CPUCodegen._function_pass_manager = counting
module = codegen.CPUCodegen._module_pass_manager
def counting_cheap(self, **kw):
    built[0] += kw.get("cost") == "cheap"
    return module(self, **kw)
codegen.CPUCodegen._module_pass_manager = counting_cheap
@numba.njit
def plain(x):
    return np.sqrt(x) * 2.0 + 1.0
plain(np.arange(4.0))  # (also numba's one-time set-up: its runtime's functions)
before = built[0]
from dynslam2d.slam.matcher import gated_points
a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
r = 1.0 + 0.01 * np.arange(360.0) + 0.37 * np.sin(7 * a)
r[::7] = np.inf
args = (r, np.cos(a), np.sin(a), np.isfinite(r), 0.1, 30.0, 0.2, 25.0, 3.0, True)
got = gated_points(*args)
kernel = built[0] - before
want = gated_points.py_func(*args)
same = all(np.array_equal(g, w) for g, w in zip(got[:2], want[:2])) and got[2:] == want[2:]
print(json.dumps({"kernel": kernel, "plain": before, "same_as_python": same,
                  "out": [g.tolist() for g in got[:2]], "rest": [float(v) for v in got[2:]],
                  "installed": jitbox.one_llvm_optimisation()}))
"""


def test_kernels_are_optimised_once_with_the_same_results(tmp_path) -> None:
    """jitbox.one_llvm_optimisation: compiling a dynslam2d kernel builds no per-function LLVM pipeline and no cheap
    module pipeline (numba's own: one per function of every module added, one per library), a numba function of
    another module still gets them; the kernel
    returns the Python function's values, bit for bit the same as the kernel compiled with numba's two
    optimisations; installing again is refused."""
    import os

    res = {}
    for mode in ("once", "undo"):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / mode)}
        out = subprocess.run([sys.executable, "-c", ONCE, mode], capture_output=True, text=True, check=True, env=env,
                             timeout=300)
        res[mode] = json.loads(out.stdout.strip().splitlines()[-1])
    once, undo = res["once"], res["undo"]
    assert once["kernel"] == 0 and undo["kernel"] > 5
    assert once["plain"] > 0 and undo["plain"] > 0
    assert once["same_as_python"] and undo["same_as_python"]
    assert once["out"] == undo["out"] and once["rest"] == undo["rest"] and len(once["out"][0]) > 300
    assert not once["installed"]


def test_bit_casts_match_numpy_views() -> None:
    """jitbox.float_bits / float_from_bits / word_at (pass cold28): the bits NumPy's ``.view`` gives, on special
    values (signed zeros, infinities, NaNs with payloads, subnormals) and random ones, and every word offset of a
    byte array; arguments of other types are refused at typing."""
    import numpy as np
    import pytest
    from numba.core.errors import TypingError

    from dynslam2d.jitbox import float_bits, float_from_bits, njit, word_at

    @njit(cache=False)
    def casts(x, i, m):  # pragma: no cover - numba
        fb = np.empty(x.shape[0], dtype=np.int64)
        ff = np.empty(i.shape[0])
        for k in range(x.shape[0]):
            fb[k] = float_bits(x[k])
        for k in range(i.shape[0]):
            ff[k] = float_from_bits(i[k])
        w = np.empty(m.shape[0] - 7, dtype=np.uint64)
        for k in range(w.shape[0]):
            w[k] = word_at(m, k)
        return fb, ff, w

    rng = np.random.default_rng(28)
    special = np.array([0.0, -0.0, np.inf, -np.inf, 5e-324, -2.2e-308, 1.0, np.nan])
    payload = np.array([0x7FF0000000000001, 0xFFF8000000000123 - (1 << 64)], dtype=np.int64).view(np.float64)
    x = np.concatenate([special, payload, rng.normal(size=50) * 10.0 ** rng.integers(-300, 300, 50)])
    i = np.concatenate([x.view(np.int64), rng.integers(-(1 << 63), (1 << 63) - 1, 50, dtype=np.int64)])
    m = rng.integers(0, 256, 67, dtype=np.uint8)
    fb, ff, w = casts(x, i, m)
    assert np.array_equal(fb, x.view(np.int64))
    assert np.array_equal(ff.view(np.int64), i)  # (bit for bit, NaN payloads included)
    assert np.array_equal(w, [m[k:k + 8].view(np.uint64)[0] for k in range(60)])

    @njit(cache=False)
    def wrong(v):  # pragma: no cover - numba
        return float_bits(v)

    with pytest.raises(TypingError):
        wrong(np.float32(1.0))
