"""Background compile of a cold first run (dynslam2d.jitwarm, issue 13 item 2, docs/speed.md).

The manifest of kernels and signatures must match what a real run compiles (else the second process compiles
the wrong things and the run waits as before); a cold run with the second process on must load kernels from the
cache that it did not compile itself; the process must leave with its parent and be off on one CPU or on request.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import TYPING_ERROR_PROBE

from dynslam2d import jitwarm
from dynslam2d.jitmanifest import KERNELS

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: After a run in this interpreter: every dynslam2d kernel that holds a compiled signature, as signature_text.
DUMP = r"""
import json, sys
from numba.core.registry import CPUDispatcher
from dynslam2d.jitwarm import signature_text
out = {}
for name, mod in list(sys.modules.items()):
    if mod is None or not name.startswith("dynslam2d"):
        continue
    for attr, obj in vars(mod).items():
        if isinstance(obj, CPUDispatcher) and obj.__module__ == name and obj.signatures:
            s = obj.stats
            out[f"{name}.{attr}"] = {"sigs": [signature_text(sig) for sig in obj.signatures],
                                     "hits": sum(s.cache_hits.values()), "misses": sum(s.cache_misses.values())}
print(json.dumps(out))
"""


def _run_and_dump(tmp_path: Path, env: dict[str, str], *run_args: str) -> dict:
    code = ("import sys\nfrom dynslam2d.cli import main\n"
            f"sys.argv = ['dynslam2d', 'run', '--out', {str(tmp_path / 'run')!r}, '--force', '-q', *{run_args!r}]\n"
            "try:\n    main()\nexcept SystemExit as e:\n    assert not e.code, e.code\n" + DUMP)
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_signature_text_reads_back():
    from numba.core import types as t

    sig = (t.Array(t.float64, 1, "C"), t.Array(t.float32, 2, "A", readonly=True), t.boolean, t.int64,
           t.Omitted(0.5), t.UniTuple(t.int64, 2))
    assert jitwarm.parse_signature(jitwarm.signature_text(sig)) == sig
    assert jitwarm.parse_signature(jitwarm.signature_text(sig[:1])) == sig[:1]


def test_manifest_matches_the_kernels_a_real_run_compiles(tmp_path):
    """The README's first command, with the background compile off: each kernel it holds afterwards has exactly
    the manifest's one signature, and no kernel is missing from the manifest (re-run benchmarks/record_kernels.py
    after changing a kernel's arguments).

    Run twice, the second run checked: a kernel compiled in the process (a cold cache, as after any kernel source
    change) compiles the kernels it calls too, whose signatures then show on their own dispatchers although the run
    never calls them from Python (``cleanup._scan_geometry`` inside ``_geometry_bounds``); loaded from the cache they
    do not, and they need no manifest entry: the background compile builds them with their callers."""
    env = {**os.environ, "PYTHONPATH": SRC, jitwarm.WORKER_ENV: "0"}
    _run_and_dump(tmp_path, env)  # (fills the cache if it is cold)
    got = {name: k["sigs"] for name, k in _run_and_dump(tmp_path, env).items()}
    want = {name: [sig] for name, sig in KERNELS}
    assert got == want
    assert len(KERNELS) >= 25


@pytest.mark.cold_compile
@pytest.mark.skipif(jitwarm.usable_cpus() < 2, reason="the background compile runs only with a second CPU")
def test_cold_run_loads_kernels_the_background_process_compiled(tmp_path):
    """A cold 3 s run in an empty cache: kernels it uses come from the cache, which only the second process can
    have filled (without it every kernel is a cache miss); the rest it compiled once. ~25 s of CPU."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop(jitwarm.WORKER_ENV, None)
    used = _run_and_dump(tmp_path, env, "--duration", "3")
    loaded = sorted(name for name, k in used.items() if k["hits"] and not k["misses"])
    late = {name for name, _ in KERNELS[-10:]}  # the second process starts from these
    assert len(loaded) >= 5 and late & set(loaded), used
    assert all(k["hits"] + k["misses"] == 1 for k in used.values()), used  # one signature, compiled or loaded once
    assert any(p.suffix == ".nbi" for p in (tmp_path / "cache").rglob("*"))


def test_off_on_request_and_on_one_cpu(monkeypatch):
    monkeypatch.setattr(jitwarm, "usable_cpus", lambda: 2)
    for off in ("0", "off", "False", "no"):
        monkeypatch.setenv(jitwarm.WORKER_ENV, off)
        assert not jitwarm.worker_wanted() and jitwarm.start_background_compile() is None
    monkeypatch.delenv(jitwarm.WORKER_ENV)
    assert jitwarm.worker_wanted()
    monkeypatch.setattr(jitwarm, "usable_cpus", lambda: 1)
    assert not jitwarm.worker_wanted() and jitwarm.start_background_compile() is None


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _sigint_ignored(pid: int) -> bool:
    """Whether process ``pid`` ignores SIGINT (/proc/PID/status SigIgn mask)."""
    with open(f"/proc/{pid}/status") as f:
        mask = next(int(line.split()[1], 16) for line in f if line.startswith("SigIgn:"))
    return bool(mask >> (signal.SIGINT - 1) & 1)


@pytest.mark.skipif(not sys.platform.startswith("linux") or jitwarm.usable_cpus() < 2,
                    reason="Linux /proc and a second CPU")
def test_background_process_ignores_ctrl_c_stops_on_request_and_dies_with_its_parent(tmp_path, monkeypatch):
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop(jitwarm.WORKER_ENV, None)
    # a parent that starts it and dies without clean-up (no atexit): the child must not outlive it
    code = ("import os\nfrom dynslam2d.jitwarm import start_background_compile\n"
            "b = start_background_compile()\nprint(b.proc.pid, flush=True)\n"
            "import time; time.sleep(1.5)\nos._exit(0)\n")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    pid = int(r.stdout.split()[0])
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pid)
    # in this process: a terminal's Ctrl-C goes to the foreground process group, which the child is not in, and
    # SIGINT sent to it anyway is ignored once it runs; stop() ends it
    monkeypatch.setenv("NUMBA_CACHE_DIR", env["NUMBA_CACHE_DIR"])
    monkeypatch.delenv(jitwarm.WORKER_ENV, raising=False)
    b = jitwarm.start_background_compile()
    assert b is not None and os.getpgid(b.proc.pid) != os.getpgid(0)
    deadline = time.monotonic() + 20
    while _sigint_ignored(b.proc.pid) is False and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _sigint_ignored(b.proc.pid)
    os.kill(b.proc.pid, signal.SIGINT)
    time.sleep(0.3)
    assert b.proc.poll() is None
    b.stop()
    assert b.proc.poll() is not None


def test_run_starts_the_background_process_only_on_a_cold_cache(monkeypatch):
    """``dynslam2d run``'s start-up check: nothing is started when the cache holds the kernels."""
    from dynslam2d import cli, jitcache

    started = []
    monkeypatch.setattr(jitcache, "lean_numba_compile", lambda: False)  # (numba of this test process left as it is)
    monkeypatch.setattr(jitcache, "lean_compile_gc", lambda: started.append("gc") or False)  # (nor its collector)
    monkeypatch.setattr(jitwarm, "start_background_compile", lambda: started.append(1) or "started")
    for cached, want in ((40, (False, None)), (0, (True, "started"))):
        monkeypatch.setattr(jitcache, "kernel_cache_state", lambda c=cached: jitcache.KernelCacheState(40, c))
        assert cli._cold_start() == want
    assert started == ["gc", 1]  # (the collector's thresholds changed on the cold cache only)


def test_lean_compile_gc_raises_generation_0_only_from_cpythons_defaults():
    """jitcache.lean_compile_gc: CPython's default thresholds become the compile's; thresholds the program has set
    are left as they are."""
    import gc

    from dynslam2d import jitcache

    before = gc.get_threshold()
    try:
        gc.set_threshold(700, 10, 10)
        assert jitcache.lean_compile_gc()
        assert gc.get_threshold() == jitcache.COMPILE_GC_THRESHOLD == (20000, 100, 10)
        assert not jitcache.lean_compile_gc()  # (no longer the defaults)
        gc.set_threshold(5000, 5, 5)
        assert not jitcache.lean_compile_gc() and gc.get_threshold() == (5000, 5, 5)
    finally:
        gc.set_threshold(*before)


#: A small kernel for the board tests (compiles in well under a second; since pass trk24 it runs inside
#: kernels_update.kalman_pairs, so it is no longer a manifest entry of its own: its signature is given here).
SMALL = ("dynslam2d.detect.kernels.accel_candidates", "(Array(float64, 2, 'C'), Array(float64, 2, 'C'), float64,)")

BOARD_RUN = r"""
import json, subprocess, sys, time
from pathlib import Path
from dynslam2d import jitcache, jitwarm
from numba.core import caching
name, sig, folder = sys.argv[1], sys.argv[2], Path(sys.argv[3])
board = jitwarm.CompileBoard(folder, "run")
(folder / f"bg.{name}").touch()  # the background process has started this kernel (it compiles it after 1 s)
worker = subprocess.Popen([sys.executable, "-c", sys.argv[4], name, sig, str(folder)])
load0 = caching.Cache.load_overload
board.install(other_alive=lambda: worker.poll() is None)
c0 = jitcache.compile_seconds()
disp = jitwarm._dispatcher(name)
disp.compile(jitwarm.parse_signature(sig))
waited = jitcache.compile_seconds() - c0
board.uninstall()
worker.wait()
s = disp.stats
print(json.dumps({"hits": sum(s.cache_hits.values()), "misses": sum(s.cache_misses.values()), "waited": waited,
                  "restored": caching.Cache.load_overload is load0, "marks": sorted(p.name for p in folder.iterdir())}))
"""

BOARD_BG = r"""
import sys, time
from dynslam2d import jitwarm
name, sig, folder = sys.argv[1:4]
board = jitwarm.CompileBoard(folder, "bg")
board.install()
time.sleep(1.0)
print(jitwarm.compile_kernels([(name, sig)], board=board), file=sys.stderr)
"""


def test_run_waits_for_a_kernel_the_background_process_is_compiling_and_loads_it(tmp_path):
    """Where the two processes meet: a cache miss on a kernel the background process is compiling waits for it
    and loads it (a cache hit, no compile in the run), and the wait counts as compile time (kernel_compile_s)."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    (tmp_path / "board").mkdir()
    r = subprocess.run([sys.executable, "-c", BOARD_RUN, *SMALL, str(tmp_path / "board"), BOARD_BG], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert (got["hits"], got["misses"]) == (1, 0), got
    assert got["waited"] > 0.5 and got["restored"] and got["marks"] == [], got


SKIP_RUNS = r"""
import json, sys
from pathlib import Path
from dynslam2d import jitwarm
name, sig, folder = sys.argv[1], sys.argv[2], Path(sys.argv[3])
board = jitwarm.CompileBoard(folder, "bg")
(folder / f"run.{name}").touch()  # the run is compiling it
first = jitwarm.compile_kernels([(name, sig)], board=board)
(folder / f"run.{name}").unlink()
second = jitwarm.compile_kernels([(name, sig)], board=board)
print(json.dumps([first, second]))
"""


def _board_script(script: str, tmp_path: Path):
    """Run ``script`` on the small kernel with an empty cache and board folder under ``tmp_path``; its last line's
    JSON."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    (tmp_path / "board").mkdir()
    r = subprocess.run([sys.executable, "-c", script, *SMALL, str(tmp_path / "board")], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_background_process_skips_a_kernel_the_run_is_compiling(tmp_path):
    assert _board_script(SKIP_RUNS, tmp_path) == [[], [SMALL[0]]]


BALANCED = r"""
import json, sys
from pathlib import Path
from dynslam2d import jitwarm
from dynslam2d.jitmanifest import KERNELS
name, sig, folder = sys.argv[1], sys.argv[2], Path(sys.argv[3])
other = next(k for k in KERNELS if k[0] == "dynslam2d.detect.kernels.cv_predict")
board = jitwarm.CompileBoard(folder, "bg")
(folder / f"run.{name}").touch()  # the run is compiling it
first = jitwarm.compile_balanced([(name, sig), other], {name: 5.0}, board=board)
(folder / f"run.{name}").unlink()
second = jitwarm.compile_balanced([(name, sig), other], {}, board=board)
third = jitwarm.compile_balanced([(name, sig), other], {}, board=board)
print(json.dumps([first, second, third]))
"""


def test_balanced_order_takes_the_largest_kernel_the_run_will_not_reach_first():
    # the run compiles pending kernels in order from run_at: before position 3 it has 0 + 1 + 1 + 5 = 7 s to go
    pending = [(0, 1.0), (1, 1.0), (2, 5.0), (3, 1.0), (4, 3.0)]
    assert jitwarm.next_kernel(pending, 0, 0.0) == 4  # 3 s fits before the run arrives (8 s); 5 s does not (2 s)
    assert jitwarm.next_kernel(pending, 0, 4.0) == 2  # the run is 4 s from done with its kernel: 5 s fits at 2
    # nothing fits: the most time to spare (the run waits 0.5 s for position 6, 1.5 s for position 5)
    assert jitwarm.next_kernel([(5, 2.0), (6, 3.0)], 5, 0.5) == 1
    # a kernel the run has passed without compiling it comes only when nothing is ahead of the run
    assert jitwarm.next_kernel([(1, 9.0), (4, 1.0)], 3, 0.0) == 1
    assert jitwarm.next_kernel([(1, 9.0)], 3, 0.0) == 0


def test_balanced_compile_skips_what_the_run_compiles_or_has_cached(tmp_path):
    other = "dynslam2d.detect.kernels.cv_predict"
    assert _board_script(BALANCED, tmp_path) == [[other], [SMALL[0]], []]


INDEX_COMPILE = r"""
import sys
from dynslam2d import jitwarm
jitwarm._dispatcher(sys.argv[1]).compile(jitwarm.parse_signature(sys.argv[2]))
"""

INDEX_READ = r"""
import json, pickle, sys
from dynslam2d import jitcache, jitwarm
from dynslam2d.jitmanifest import KERNELS
name, module = sys.argv[1], sys.argv[1].rpartition(".")[0]
other = next(k for k, _ in KERNELS if k == "dynslam2d.detect.kernels.cv_predict")
got = {"held": [jitcache.index_holds(name), jitcache.index_holds(other), jitwarm._cached(other)],
       "imported": module in sys.modules, "foreign": jitcache.index_holds("numpy.linalg.norm")}
exact = [jitcache._has_valid_index(jitwarm._dispatcher(k)) for k in (name, other)]
got["exact"] = exact
got["after_import"] = [jitcache.index_holds(k) for k in (name, other)]
path = jitwarm._dispatcher(name)._cache._cache_file._index_path
with open(path, "rb") as f:
    version = pickle.load(f)
    stamp, overloads = pickle.loads(f.read())
stale = []
for v, st in ((version, bytes(32)), ("0.0.0", stamp), (version, stamp)):
    with open(path, "wb") as f:
        pickle.dump(v, f, protocol=-1)
        f.write(pickle.dumps((st, overloads), protocol=-1))
    stale.append([jitcache.index_holds(name), jitcache._has_valid_index(jitwarm._dispatcher(name))])
got["stale"] = stale
print(json.dumps(got))
"""


def test_index_holds_tells_from_the_index_file_what_numba_would_without_importing(tmp_path):
    """The background process's view of the cache (``jitcache.index_holds``) is numba's own (``_has_valid_index``):
    a compiled kernel is held, another not, an index of another source or numba version is not; and it is read
    without importing the kernel's module."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    for script in (INDEX_COMPILE, INDEX_READ):
        r = subprocess.run([sys.executable, "-c", script, *SMALL], env=env, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got == {"held": [True, False, False], "imported": False, "foreign": None, "exact": [True, False],
                   "after_import": [True, False], "stale": [[False, False], [False, False], [True, True]]}, got


LEAN = r"""
import json, sys
import numpy as np
from dynslam2d import jitcache, jitwarm
lean = sys.argv[3] == "1"
if lean:
    assert jitcache.lean_numba_compile() and not jitcache.lean_numba_compile()  # (once)
from numba.core.compiler import Flags
a, b = Flags(), Flags()
a.nrt = True
b.nrt, b.boundscheck = True, False  # the same values as a's (boundscheck defaults to False), stored differently
equal = [a == b, a == Flags(), hash(a) == hash(tuple(sorted(a.values()))) == hash(b)]
disp = jitwarm._dispatcher(sys.argv[1])
disp.compile(jitwarm.parse_signature(sig := sys.argv[2]))
cres = disp.overloads[disp.signatures[0]]
rng = np.random.default_rng(3)
X0, X1 = rng.normal(size=(50, 4)), rng.normal(size=(50, 4))
print(json.dumps({"cfunc": cres.fndesc.llvm_cfunc_wrapper_name in cres.library.get_llvm_str(),
                  "out": disp(X0, X1, 1.0).tolist(), "equal": equal}))
"""


def test_lean_compile_drops_cfunc_wrappers_and_keeps_kernels_and_flag_semantics(tmp_path):
    """jitcache.lean_numba_compile: no C-callable wrapper beside a kernel compiled after it, the kernel's results
    unchanged, and numba's flag comparisons as before (equal values equal, whether stored or defaulted)."""
    name, sig = SMALL
    got = {}
    for lean in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{lean}")}
        r = subprocess.run([sys.executable, "-c", LEAN, name, sig, lean], env=env, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[lean] = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["0"]["cfunc"] and not got["1"]["cfunc"]
    assert got["0"]["out"] == got["1"]["out"] and len(got["1"]["out"]) > 5
    assert got["0"]["equal"] == got["1"]["equal"] == [True, False, True]


REMEMBERED = r"""
import json, re, sys
import numpy as np
from dynslam2d import jitcache, jitwarm
on = sys.argv[3] == "1"
if on:
    assert jitcache.remembered_call_typing() and not jitcache.remembered_call_typing()  # (once)
from numba.core import utils
from numba.core.types import functions
calls = [0, 0]  # calls typed, full template searches
typed, search = functions.BaseFunction.get_call_type, utils.order_by_target_specificity
def counted_typed(self, context, args, kws):
    calls[0] += 1
    return typed(self, context, args, kws)
def counted_search(*a, **k):
    calls[1] += 1
    return search(*a, **k)
functions.BaseFunction.get_call_type, utils.order_by_target_specificity = counted_typed, counted_search
disp = jitwarm._dispatcher(sys.argv[1])
disp.compile(jitwarm.parse_signature(sys.argv[2]))
ir = disp.inspect_llvm(disp.signatures[0])
ir = re.sub(r"B\d+v\d+|0x[0-9a-f]+", "", ir)  # numba's per-process function ids and dynamic names' addresses
""" + TYPING_ERROR_PROBE + r"""print(json.dumps({"ir": ir, "error": error, "calls": calls}))
"""


def _off_and_on(script: str, kernel_suffix: str, tmp_path) -> dict:
    """``script``'s JSON result for the manifest kernel whose name ends in ``kernel_suffix``, run in a fresh process
    with the rewrite off ("0") and on ("1"), each with its own empty numba cache."""
    name, sig = next((n, s) for n, s in KERNELS if n.endswith(kernel_suffix))
    got = {}
    for on in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{on}")}
        r = subprocess.run([sys.executable, "-c", script, name, sig, on], env=env, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        got[on] = json.loads(r.stdout.strip().splitlines()[-1])
    return got


def test_remembered_call_typing_gives_the_same_code_and_errors(tmp_path):
    """jitcache.remembered_call_typing: a kernel with many repeated calls of numba's functions (the correlative
    search's branch and bound) compiles to the same optimised LLVM IR as with numba's own template search, and a
    call no template accepts raises the same typing error."""
    got = _off_and_on(REMEMBERED, ".branch_and_bound", tmp_path)
    assert len(got["0"]["ir"]) > 10000 and got["0"]["ir"] == got["1"]["ir"]
    assert got["0"]["error"].startswith("TypingError") and got["0"]["error"] == got["1"]["error"]
    (typed0, search0), (typed1, search1) = got["0"]["calls"], got["1"]["calls"]
    assert typed0 == typed1 > 500 and search0 == typed0 and search1 < typed1 / 3  # (most calls repeat a typed one)


LEAN_INLINE = r"""
import copy, json, re, sys
import numpy as np
from dynslam2d import jitcache, jitwarm
on = sys.argv[3] == "1"
if on:
    assert jitcache.lean_inlining() and not jitcache.lean_inlining()  # (once)
copies, deep = [0], copy.deepcopy
def counted(*a, **k):
    copies[0] += 1
    return deep(*a, **k)
copy.deepcopy = counted
disp = jitwarm._dispatcher(sys.argv[1])
disp.compile(jitwarm.parse_signature(sys.argv[2]))
ir = disp.inspect_llvm(disp.signatures[0])
ir = re.sub(r"B\d+v\d+|0x[0-9a-f]+", "", ir)  # numba's per-process function ids and dynamic names' addresses
import numba
@numba.njit(inline="always")
def sq(x):
    y = x * x
    return y
@numba.njit
def twice(a):
    s = 0.0
    for v in a:
        s += sq(v) - sq(v + 1.0)
    return s
a = np.linspace(-3.0, 5.0, 17)
value = [twice(a), float(np.sum(a * a - (a + 1.0) * (a + 1.0)))]
@numba.njit(inline="always")
def inner(x):
    return min(x, "a")
@numba.njit
def outer(x):
    return inner(x) + 1.0
try:
    outer(1.0)
    error = ""
except numba.core.errors.TypingError as e:
    error = type(e).__name__ + str(e).split("\n")[0]
print(json.dumps({"ir": ir, "copies": copies[0], "value": value, "error": error}))
"""


def test_lean_inlining_gives_the_same_code_and_errors_with_fewer_copies(tmp_path):
    """jitcache.lean_inlining: a kernel with inline="always" callees (one inlined into another) compiles to the same
    optimised LLVM IR with far fewer deep copies of IR objects; a callee inlined at two sites computes what NumPy does;
    a typing error in an inlined callee is raised as before."""
    got = _off_and_on(LEAN_INLINE, "._movers_kernel", tmp_path)
    assert len(got["0"]["ir"]) > 10000 and got["0"]["ir"] == got["1"]["ir"]
    assert got["1"]["copies"] < got["0"]["copies"] / 3, (got["0"]["copies"], got["1"]["copies"])
    for on in ("0", "1"):
        assert got[on]["value"][0] == pytest.approx(got[on]["value"][1], rel=1e-12)
    assert got["0"]["error"].startswith("TypingError") and got["0"]["error"] == got["1"]["error"]


def test_lean_inlining_leaves_another_numba_alone(monkeypatch):
    from numba.core import inline_closurecall

    from dynslam2d import jitcache

    before = inline_closurecall.InlineWorker.inline_function
    monkeypatch.setattr(jitcache, "INLINE_IR_SOURCE", "0" * 16)
    assert not jitcache.lean_inlining()
    assert inline_closurecall.InlineWorker.inline_function is before


FIRST_COMPILE = r"""
import json
from numba.core import inline_closurecall
from numba.core.types import functions
from dynslam2d import jitcache
import numba
def installed():
    return [getattr(functions.BaseFunction.get_call_type, "_dynslam2d_remembered", False),
            getattr(inline_closurecall.InlineWorker.inline_function, "_dynslam2d_lean", False)]
assert jitcache.lean_numba_compile()
before = installed()
@numba.njit
def plus(x):
    return x + 1
value = plus(2)
print(json.dumps({"before": before, "after": installed(), "value": value}))
"""


def test_lean_compile_reads_numbas_sources_only_when_it_compiles(tmp_path):
    """lean_numba_compile installs the two source-checked rewrites of numba's functions at the first compile of the
    process (a warm run, which only loads kernels, does not read numba's sources for them)."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-c", FIRST_COMPILE], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == {"before": [False, False], "after": [True, True],
                                                              "value": 3}
