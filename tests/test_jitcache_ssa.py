"""numba's SSA pass without its debug-logging calls gives the same IR and code (dynslam2d.jitcache.quiet_ssa_debug,
issue 13 item 2, docs/speed.md pass cold35)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: argv[1] "1": the rewrite installed first, "0": numba's own. Compiles the matcher's ``gated_points`` (loops, variables
#: assigned in several blocks: SSA violators) in a fresh dispatcher and prints its SSA IR, its LLVM IR, its result on a
#: simulated scan and how many times numba's ssa logger was asked to log.
SSA = r"""
import json, logging, math, sys
import numpy as np
import numba
from numba.core import compiler, ssa
from dynslam2d import jitcache
on = sys.argv[1] == "1"
if on:
    assert jitcache.quiet_ssa_debug() and not jitcache.quiet_ssa_debug()  # (once)
calls = [0]
debug = logging.Logger.debug
def counting(self, *a, **k):
    if self is ssa._logger:
        calls[0] += 1
    return debug(self, *a, **k)
logging.Logger.debug = counting
from dynslam2d.slam import matcher
func = matcher.gated_points.py_func
fir = compiler.run_frontend(func)
fir = ssa.reconstruct_ssa(fir)
import io, contextlib
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    fir.dump()
kernel = numba.njit(func)
rng = np.random.default_rng(7)
n = 721
ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
r = rng.uniform(0.05, 32.0, n)
r[rng.random(n) < 0.1] = np.nan
out = kernel(r, np.cos(ang), np.sin(ang), np.isfinite(r), 0.1, 30.0, 0.2, 25.0, 10.0, True)
llvm = "\n".join(kernel.inspect_llvm().values())
import re
print(json.dumps({"ssa_ir": re.sub(r"0x[0-9a-f]+", "0x", buf.getvalue()), "llvm": llvm,
                  "out": [np.asarray(o).tolist() for o in out],
                  "calls": calls[0], "installed": bool(getattr(ssa, "_dynslam2d_quiet", False))}))
"""

#: The rewrite with another expected source, or with the ssa logger at DEBUG: numba is left as it is.
OTHER = r"""
import json, logging, sys
from numba.core import ssa
from dynslam2d import jitcache
codes = {name: f.__code__ for name, f in vars(ssa).items() if callable(f) and hasattr(f, "__code__")}
jitcache.SSA_SOURCE = "0" * 16
other = jitcache.quiet_ssa_debug()
jitcache.SSA_SOURCE = sys.argv[1]
ssa._logger.setLevel(logging.DEBUG)
debugging = jitcache.quiet_ssa_debug()
same = all(getattr(ssa, name).__code__ is code for name, code in codes.items())
print(json.dumps({"other": other, "debugging": debugging, "same": same}))
"""


def _run(script: str, arg: str, tmp_path: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path / f"numba-{arg}"))
    res = subprocess.run([sys.executable, "-c", script, arg], env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_same_ssa_ir_and_code_without_the_log_calls(tmp_path: Path) -> None:
    theirs, ours = _run(SSA, "0", tmp_path), _run(SSA, "1", tmp_path)
    assert not theirs["installed"] and ours["installed"]
    assert theirs["calls"] > 100 and ours["calls"] == 0  # numba's logs each statement of each block pass
    assert ours["ssa_ir"] == theirs["ssa_ir"] and "phi" in ours["ssa_ir"]
    assert ours["llvm"] == theirs["llvm"]
    assert ours["out"] == theirs["out"]


def test_other_sources_left_alone(tmp_path: Path) -> None:
    from dynslam2d import jitcache

    res = _run(OTHER, jitcache.SSA_SOURCE, tmp_path)
    assert res == {"other": False, "debugging": False, "same": True}
