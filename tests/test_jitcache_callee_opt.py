"""A kernel compiled only as another kernel's callee is optimised once, in its caller's module, and on its own only
when Python first calls it (dynslam2d.jitcache.CALLEE_OPTIMISED_IN_CALLER, issue 13 item 2, docs/speed.md pass
cmp41)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: argv[1] "1": a lazy callee's optimisation left to its callers, "0": the callee optimised before its callers link
#: it (pass cold34's way). Compiles the matcher's ``gated_points`` (which calls ``_bearing_bin``) by calling it on a
#: simulated scan, then calls ``_bearing_bin`` from Python; prints the callee library's module text (addresses
#: hidden) and the IR its callers link, before and after that call.
SCRIPT = r"""
import json, math, re, sys
import numpy as np
from dynslam2d import jitcache
jitcache.CALLEE_OPTIMISED_IN_CALLER = sys.argv[1] == "1"
assert jitcache.lazy_callee_code()
from dynslam2d.slam import matcher
def text(module):
    return re.sub(r"0x[0-9a-fA-F]+", "0x?", str(module))
def instructions(module):
    return sum(1 for line in str(module).splitlines() if line.startswith("  ") and not line.startswith("  ;"))
rng = np.random.default_rng(11)
n = 721
ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
r = rng.uniform(0.05, 32.0, n)
r[rng.random(n) < 0.1] = np.nan
valid = np.isfinite(r)
out = matcher.gated_points(r, np.cos(ang), np.sin(ang), valid, 0.1, 30.0, 0.2, 25.0, 10.0, True)
callee = matcher._bearing_bin
(cres,) = callee.overloads.values()
lib = cres.entry_point.library
linked = lib._get_module_for_linking()
before = {"unoptimised": bool(getattr(lib, "_dynslam2d_unoptimised", False)), "final": instructions(lib._final_module),
          "linked": instructions(linked), "linked_text": text(linked)}
xs, ys = rng.normal(size=300) * 5.0, rng.normal(size=300) * 5.0
bins = [callee(float(x), float(y), 64) for x, y in zip(xs, ys)]
ref = [int(math.floor((math.atan2(y, x) + math.pi) / (2.0 * math.pi) * 64)) % 64 for x, y in zip(xs, ys)]
after = {"unoptimised": bool(getattr(lib, "_dynslam2d_unoptimised", False)), "final": instructions(lib._final_module),
         "final_text": text(lib._final_module), "linked_text": text(lib._get_module_for_linking()),
         "entry": [type(c.entry_point).__name__ for c in callee.overloads.values()],
         "cached": jitcache.index_holds("dynslam2d.slam.matcher._bearing_bin")}
print(json.dumps({"out": [np.asarray(o).tolist() for o in out], "bins": bins, "ref": ref, "before": before,
                  "after": after}))
"""


def test_callee_optimised_in_its_caller_and_on_its_own_when_python_calls_it(tmp_path):
    """The caller computes the same with the callee's optimisation left to it; the callee's own module stays as
    numba lowered it (more instructions than once optimised) until Python calls it, and is then optimised to the
    same module (lines) as when it was optimised before its caller linked it; the IR later callers link stays the
    unoptimised one; the callee computes the bins Python's atan2 gives and is written to the cache."""
    got = {}
    for on in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{on}")}
        r = subprocess.run([sys.executable, "-c", SCRIPT, on], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[on] = json.loads(r.stdout.strip().splitlines()[-1])
    old, new = got["0"], got["1"]
    assert old["out"] == new["out"] and len(new["out"][0]) > 100
    for g in (old, new):
        assert g["bins"] == g["ref"]
        assert g["after"]["entry"] == ["builtin_function_or_method"] and g["after"]["cached"]
    assert not old["before"]["unoptimised"] and new["before"]["unoptimised"]
    assert new["before"]["final"] > old["before"]["final"] and new["before"]["linked"] > old["before"]["linked"]
    assert not new["after"]["unoptimised"] and new["after"]["final"] == old["after"]["final"]
    # the same module but for the order of two global declarations (the modules were linked in another order)
    assert sorted(new["after"]["final_text"].splitlines()) == sorted(old["after"]["final_text"].splitlines())
    assert new["after"]["linked_text"] == new["before"]["linked_text"]
