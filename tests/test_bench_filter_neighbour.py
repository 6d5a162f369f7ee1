"""benchmarks/bench_filter_neighbour.py still runs against the package (a smoke run over the first scans of a
simulated scene; speed never asserted): it finds no ``Track`` built during ``Pipeline.process`` and prints its
first/second-read and neighbour lines."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_bench_filter_neighbour_runs(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "TMPDIR": str(tmp_path)}
    res = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_filter_neighbour.py"), "sim:paper",
                          "--scans", "80"], env=env, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    out = res.stdout
    assert "Track objects built during process (all pipelines), by caller: none" in out, out
    for tag in ("moving_index (reports)", "mover_pack (reports)", "mover_exclusions (kernel)"):
        assert tag in out, out
    for mode in ("plain", "reports", "scan", "spin", "sweep"):
        assert f"  {mode} " in out, out
