"""The run and its background compile never both compile one kernel (dynslam2d.jitwarm.CompileBoard, pass cmp95).

Pass cmp84 saw both processes compile ``record_cells``, ``level_rows`` and ``stand_marks``: the background process
looked at the board before it imported ``slam.ledgerkernels``, whose three kernels declare their signatures and so
compile at the import, without asking the board, while the run was compiling them. Each process now marks a kernel
before it looks for the other's mark (two that arrive at once both see the other's; the background process yields),
and the background process's compiles at an import go through the same claim.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from dynslam2d import jitwarm

SRC = str(Path(__file__).resolve().parents[1] / "src")
NAME = "dynslam2d.probe.kernel"


def _both_arrive_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, first: str) -> tuple[list[str], dict]:
    """Both processes (as threads, a dict as numba's cache) miss the kernel's cache entry at once: each is held at
    its first look at the other's mark until the other has reached its own (``first``'s thread starts first).
    Returns who compiled and the cache."""
    folder = tmp_path / "board"
    folder.mkdir()
    cache: dict[str, str] = {}
    compiled: list[str] = []
    barrier = threading.Barrier(2, timeout=2.0)
    held: set[str] = set()
    busy = jitwarm.CompileBoard.busy

    def meeting_busy(self: jitwarm.CompileBoard, who: str, name: str) -> bool:
        if who != self.me and self.me not in held:  # (the first look at the other's mark: wait for the other's)
            held.add(self.me)
            try:
                barrier.wait()
            except threading.BrokenBarrierError:
                pass
        return busy(self, who, name)

    monkeypatch.setattr(jitwarm.CompileBoard, "busy", meeting_busy)

    def process(me: str) -> None:
        board = jitwarm.CompileBoard(folder, me)
        data, _ = board.take(NAME, lambda: cache.get(NAME), lambda: True, max_wait_s=10.0)
        if data is None:
            compiled.append(me)
            time.sleep(0.1)  # the compile
            cache[NAME] = me
            board.clear(NAME)  # (numba's save)

    threads = [threading.Thread(target=process, args=(me,)) for me in (first, "bg" if first == "run" else "run")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30.0)
    return compiled, cache


@pytest.mark.parametrize("first", ["run", "bg"])
def test_two_processes_that_miss_a_kernel_at_once_compile_it_once(tmp_path, monkeypatch, first):
    compiled, cache = _both_arrive_at_once(tmp_path, monkeypatch, first)
    assert compiled == ["run"] and cache == {NAME: "run"}  # the background process yielded and loaded it
    assert not list((tmp_path / "board").iterdir())


def test_background_claim_yields_to_the_run_and_holds_a_kernel_marked_for_it(tmp_path):
    run, bg = jitwarm.CompileBoard(tmp_path, "run"), jitwarm.CompileBoard(tmp_path, "bg")
    run.mark(NAME)
    assert not bg.claim(NAME) and not bg.busy("bg", NAME)  # the run is compiling it: no mark left behind
    run.clear(NAME)
    assert bg.claim(NAME) and bg.busy("bg", NAME)
    run.mark(NAME)
    assert bg.claim(NAME)  # claimed before the run arrived: the run waits for it
    data, waited = run.take(NAME, lambda: None, lambda: True, max_wait_s=0.2)
    assert data is None and waited >= 0.2  # (it waited, the other never saved it: compiles it itself, marked)


#: A module whose kernel declares its signature, so that it compiles when the module is imported (as
#: ``slam.ledgerkernels`` does), loaded under a dynslam2d name so that the board claims it.
EAGER = '''
from numba import njit

@njit("float64(float64)", cache=True)
def kernel(x):
    return 2.0 * x + 1.0
'''

LOAD = r"""
import importlib.util, sys
def load(path):
    spec = importlib.util.spec_from_file_location("dynslam2d.probe", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.kernel
"""

IMPORT_BG = LOAD + r"""
import json, time
from pathlib import Path
import numba
from dynslam2d import jitwarm
path, folder = sys.argv[1], Path(sys.argv[2])
board = jitwarm.CompileBoard(folder, "bg")
board.install()
(folder / "ready").touch()
t0 = time.perf_counter()
kernel = load(path)  # the background process imports the module: the declared signature compiles here
s = kernel.stats
print(json.dumps({"hits": sum(s.cache_hits.values()), "misses": sum(s.cache_misses.values()),
                  "s": time.perf_counter() - t0, "value": kernel(2.0)}))
"""

IMPORT_RUN = LOAD + r"""
import json, subprocess, time
from pathlib import Path
from dynslam2d import jitwarm
path, folder = sys.argv[1], Path(sys.argv[2])
board = jitwarm.CompileBoard(folder, "run")
board.install()
board.mark("dynslam2d.probe.kernel")  # the run has started compiling the kernel (its import is under way)
bg = subprocess.Popen([sys.executable, "-c", sys.argv[3], path, str(folder)], stdout=subprocess.PIPE, text=True)
while not (folder / "ready").exists() and bg.poll() is None:
    time.sleep(0.01)
time.sleep(0.5)  # the background process is importing the module
kernel = load(path)
s = kernel.stats
got = json.loads(bg.communicate(timeout=120)[0].strip().splitlines()[-1])
board.uninstall()
print(json.dumps({"bg": got, "run": [sum(s.cache_hits.values()), sum(s.cache_misses.values())],
                  "marks": sorted(p.name for p in folder.iterdir() if p.name != "ready")}))
"""


def test_an_import_in_the_background_does_not_compile_a_kernel_the_run_is_compiling(tmp_path):
    """A kernel that compiles when its module is imported (a declared signature): the background process's import
    waits for the run's compile and loads it instead of compiling it a second time."""
    (tmp_path / "probe.py").write_text(EAGER)
    (tmp_path / "board").mkdir()
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-c", IMPORT_RUN, str(tmp_path / "probe.py"), str(tmp_path / "board"),
                        IMPORT_BG], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["run"] == [0, 1] and got["marks"] == [], got  # the run compiled it and its mark went with the save
    assert (got["bg"]["hits"], got["bg"]["misses"]) == (1, 0) and got["bg"]["value"] == 5.0, got
    assert got["bg"]["s"] > 0.4, got  # (it waited for the run's compile)
