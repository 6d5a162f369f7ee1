"""benchmarks/scratch.py's folders are gone when the script that made them ends (normally, on an exception, on
Ctrl-C, on SIGTERM), are left in place when kept, and the benchmark paths that use it leave nothing in the temporary
folder (each run here under a private TMPDIR, so another process's folders never count)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"

#: A script that makes two scratch folders (one with a file in a subfolder), prints them, then ends as argv[1] says.
MAKER = r"""
import os, sys, time
sys.path.insert(0, sys.argv[2])
from scratch import scratch_dir
a = scratch_dir("numba-cold-")
b = scratch_dir("bench-compile-", keep=sys.argv[1] == "keep")
os.makedirs(os.path.join(a, "run"))
open(os.path.join(a, "run", "index.nbi"), "w").write("x")
print(a, b, flush=True)
how = sys.argv[1]
if how == "raise":
    raise RuntimeError("a benchmark failed")
if how == "exit":
    raise SystemExit("usage error")
if how in ("sigint", "sigterm"):
    import signal
    signal.signal(signal.SIGINT, signal.default_int_handler)  # (a terminal's Ctrl-C even when started in background)
    time.sleep(60)
"""


def _env(tmp: Path, **extra: str) -> dict[str, str]:
    return {**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": str(ROOT / "src"), **extra}


def _left(tmp: Path) -> list[str]:
    return sorted(p.name for p in tmp.iterdir())


@pytest.mark.parametrize("how", ["normal", "raise", "exit", "sigint", "sigterm"])
def test_scratch_folders_removed_however_the_script_ends(tmp_path, how):
    proc = subprocess.Popen([sys.executable, "-c", MAKER, how, str(BENCH)], env=_env(tmp_path),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    made = proc.stdout.readline().split()
    assert len(made) == 2 and all(Path(m).parent == tmp_path for m in made)
    if how in ("sigint", "sigterm"):
        assert all(Path(m).is_dir() for m in made)  # (still running: its folders are there)
        time.sleep(0.2)
        proc.send_signal(signal.SIGINT if how == "sigint" else signal.SIGTERM)
    proc.communicate(timeout=60)
    assert proc.returncode != 0 if how != "normal" else proc.returncode == 0
    assert _left(tmp_path) == []


def test_kept_folders_stay(tmp_path):
    res = subprocess.run([sys.executable, "-c", MAKER, "keep", str(BENCH)], env=_env(tmp_path), capture_output=True,
                         text=True, timeout=60)
    a, b = res.stdout.split()
    assert _left(tmp_path) == [Path(b).name]  # keep=True: kept; the other one removed
    tmp2 = tmp_path / "env"
    tmp2.mkdir()
    res = subprocess.run([sys.executable, "-c", MAKER, "normal", str(BENCH)], env=_env(tmp2, BENCH_KEEP_SCRATCH="1"),
                         capture_output=True, text=True, timeout=60)
    assert len(_left(tmp2)) == 2  # BENCH_KEEP_SCRATCH=1 keeps both


def test_forked_child_does_not_remove_the_makers_folder(tmp_path):
    code = (f"import os, sys; sys.path.insert(0, {str(BENCH)!r}); from scratch import scratch_dir\n"
            "a = scratch_dir('x-')\n"
            "pid = os.fork()\n"
            "if pid == 0:\n    sys.exit(0)\n"
            "os.waitpid(pid, 0); print(os.path.isdir(a))\n")
    res = subprocess.run([sys.executable, "-c", code], env=_env(tmp_path), capture_output=True, text=True, timeout=60)
    assert res.stdout.split() == ["True"], res.stderr
    assert _left(tmp_path) == []


def test_check_docs_scratch_removed_unless_kept(tmp_path):
    """check_docs.py's own scratch folder (the real path, a trivial command in it): gone at exit, kept with --keep."""
    code = (f"import sys; sys.path.insert(0, {str(BENCH)!r}); import check_docs as cd\n"
            "from pathlib import Path\n"
            "keep = Path(sys.argv[1]) if len(sys.argv) > 1 else None\n"
            "rc, out, work, s = cd.run_commands(['echo 42 > figure.txt', 'cat figure.txt'], keep=keep)\n"
            "print(rc, out.strip(), (work / 'figure.txt').is_file())\n")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    res = subprocess.run([sys.executable, "-c", code], env=_env(tmp), capture_output=True, text=True, timeout=120)
    assert res.stdout.split() == ["0", "42", "True"], res.stderr
    assert _left(tmp) == []
    kept = tmp_path / "kept"
    kept.mkdir()
    res = subprocess.run([sys.executable, "-c", code, str(kept)], env=_env(tmp), capture_output=True, text=True,
                         timeout=120)
    assert res.stdout.split() == ["0", "42", "True"], res.stderr
    assert _left(tmp) == [] and len(_left(kept)) == 1


def test_bench_compile_cold_probe_leaves_nothing(tmp_path):
    """bench_compile.py's cold probe (its numba-cold-* cache and bench-compile-* run folder) on a probe that imports
    one small module: both folders gone when the script ends."""
    probe = ("import json, sys, os; import dynslam2d.types; os.makedirs(sys.argv[1]); "
             "print(json.dumps({'cache': os.environ['NUMBA_CACHE_DIR']}))")
    code = (f"import sys, json; sys.path.insert(0, {str(BENCH)!r}); import bench_compile as bc\n"
            f"print(json.dumps(bc.cold_probe({str(ROOT / 'src')!r}, {probe!r})))\n")
    res = subprocess.run([sys.executable, "-c", code], env=_env(tmp_path), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert str(tmp_path) in res.stdout  # the probe's cache was made under the private TMPDIR ...
    assert _left(tmp_path) == []  # ... and is gone
