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
