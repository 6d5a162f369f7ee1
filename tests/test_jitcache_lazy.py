"""A kernel compiled only as another kernel's callee gets its machine code when Python first calls it
(dynslam2d.jitcache.lazy_callee_code, issue 13 item 2, docs/speed.md pass cold34)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: argv[1] "1": lazy callees on (installed before the first compile), "0": numba's way. Compiles the matcher's
#: ``gated_points`` (which calls ``_bearing_bin``) by calling it on a simulated scan, then calls ``_bearing_bin``
#: from Python.
LAZY = r"""
import json, math, sys
import numpy as np
from dynslam2d import jitcache
on = sys.argv[1] == "1"
if on:
    assert jitcache.lazy_callee_code() and not jitcache.lazy_callee_code()  # (once)
from dynslam2d.slam import matcher
rng = np.random.default_rng(7)
n = 721
ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
r = rng.uniform(0.05, 32.0, n)
r[rng.random(n) < 0.1] = np.nan
valid = np.isfinite(r)
out = matcher.gated_points(r, np.cos(ang), np.sin(ang), valid, 0.1, 30.0, 0.2, 25.0, 10.0, True)
callee = matcher._bearing_bin
entry = [type(c.entry_point).__name__ for c in callee.overloads.values()]
import gc
helpers = sorted({e.fndesc.modname for e in gc.get_objects() if isinstance(e, jitcache.LazyEntry)})
cached = [jitcache.index_holds("dynslam2d.slam.matcher.gated_points"),
          jitcache.index_holds("dynslam2d.slam.matcher._bearing_bin")]
xs, ys = rng.normal(size=200) * 5.0, rng.normal(size=200) * 5.0
bins = [callee(float(x), float(y), 64) for x, y in zip(xs, ys)]
ref = [int(math.floor((math.atan2(y, x) + math.pi) / (2.0 * math.pi) * 64)) % 64 for x, y in zip(xs, ys)]
after = [type(c.entry_point).__name__ for c in callee.overloads.values()]
print(json.dumps({"out": [np.asarray(o).tolist() for o in out], "entry": entry, "cached": cached, "bins": bins,
                  "ref": ref, "after": after, "helpers": helpers,
                  "cached_after": jitcache.index_holds("dynslam2d.slam.matcher._bearing_bin")}))
"""


def test_lazy_callee_gives_the_same_results_and_its_code_when_python_calls_it(tmp_path):
    """With lazy_callee_code: the caller computes what it computes with numba's own way; the callee (and numba's
    helpers without a Python wrapper), compiled only for the caller, holds a stand-in entry and no cache entry (the
    caller has one); a call from Python then compiles its machine code, computes the bearing bins Python's atan2
    gives, and writes the callee's cache entry."""
    got = {}
    for on in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{on}")}
        r = subprocess.run([sys.executable, "-c", LAZY, on], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[on] = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["0"]["out"] == got["1"]["out"] and len(got["1"]["out"][0]) > 100
    assert got["0"]["entry"] == ["builtin_function_or_method"] and got["0"]["cached"] == [True, True]
    assert got["1"]["entry"] == ["LazyEntry"] and got["1"]["cached"] == [True, False]
    for on in ("0", "1"):
        assert got[on]["bins"] == got[on]["ref"]
    assert got["1"]["after"] == ["builtin_function_or_method"] and got["1"]["cached_after"]
    # numba's own helpers compiled for the kernel without a Python wrapper (np.empty's impl: pass cold35) are lazy too
    assert got["0"]["helpers"] == [] and any(m.startswith("numba.") for m in got["1"]["helpers"])


def test_lazy_callee_code_leaves_another_numba_alone(monkeypatch):
    from numba.core import dispatcher

    from dynslam2d import jitcache

    before = dispatcher.Dispatcher.add_overload
    monkeypatch.setitem(jitcache.LAZY_SOURCES, "Dispatcher.compile", "0" * 16)
    assert not jitcache.lazy_callee_code()
    assert dispatcher.Dispatcher.add_overload is before
