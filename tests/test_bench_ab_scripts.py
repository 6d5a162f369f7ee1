"""The in-process / lockstep A/B benchmark scripts still run against the package (smoke runs, speed never asserted):
each runs over the first scans of a simulated scene with ``--other`` pointing at this same ``src/``, and must end
cleanly, find its results identical and report no kernel loaded or compiled inside its measured runs (the
``kernelwarm.preload`` after its warm-up). A script that hooks a function the package no longer has
(``bench_detect_ab.py``'s ``trackdetect.fit_clusters`` after pass trk72 fused the detection chain) fails here."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"

#: script → (arguments, texts its output must hold); a few scans of a simulated scene each
RUNS = {
    "bench_detect_ab.py": (["sim:paper", "--scans", "12", "--reps", "1"],
                           ["detect_scan (fused call)", "Tracker._detect (the step)", "free fraction"]),
    "bench_slam_ab.py": (["sim:paper", "--scans", "56"], ["match_multires", "ledger ms per scan", "MultiResMap"]),
    "bench_clutter_ab.py": (["sim:paper", "on:", "--scans", "12"], ["off", "on "]),
}


@pytest.mark.parametrize("script", sorted(RUNS))
def test_ab_script_runs_on_the_package_against_itself(script):
    args, texts = RUNS[script]
    other = [] if script == "bench_clutter_ab.py" else ["--other", str(SRC)]
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    res = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args, *other], env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    out = res.stdout
    for t in texts:
        assert t in out, out
    assert "DIFFERENT" not in out, out
    assert "no calls" not in out or script != "bench_detect_ab.py", out
    loads = re.findall(r"loaded or compiled: (?:other (\d+), this (\d+)|(\d+))", out)
    assert loads, out
    assert all(int(x) == 0 for m in loads for x in m if x), out
