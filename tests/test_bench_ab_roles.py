"""benchmarks/ab_roles.py: the release lockstep's two roles read back and combined (new / previous with the new
release as "this", as "other" with the ratio inverted, and their geometric mean)."""

from __future__ import annotations

import importlib
import math
import sys
from pathlib import Path


def _ab_roles():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        return importlib.import_module("ab_roles")
    finally:
        sys.path.pop(0)


def _output(name: str, median: float, mean: float, track: float, loads: int = 0) -> str:
    """A bench_pipeline_ab.py block with these "this" / "other" ratios (other side's figures 1.000)."""
    return (f"{name}: 434 scans, pipeline CPU ms/scan median: other 1.000, this {median:.3f}, ratio {median:.3f} "
            f"(median per-scan ratio 1.000); inside the measured runs kernels loaded or compiled: other 0, this "
            f"{loads}, modules imported: other 0, this 0\n"
            f"  pipeline CPU ms/scan mean: other 1.000, this {mean:.3f}, ratio {mean:.3f}; p95: other 1.0, this 1.0, "
            f"ratio 1.000\n"
            f"  track       other   0.800  this   0.800  ratio {track:.3f}   mean: other   0.8  this   0.8  ratio "
            f"{track:.3f}\n")


def test_both_roles_and_their_geometric_mean(tmp_path):
    ar = _ab_roles()
    a, b = tmp_path / "ab_2.txt", tmp_path / "ab_2s.txt"
    # new as "this" reads 0.96 / 2 % low; as "other" the previous release's script reads previous / new = 1.00
    a.write_text(_output("sim:drive", 0.96, 0.98, 0.90) + _output("mit-csail", 1.02, 1.00, 1.00, loads=3))
    b.write_text(_output("sim:drive", 1.00, 1.00, 1.25) + _output("positive_1", 0.5, 0.5, 0.5))
    lines = ar.both_roles(a, b)
    drive = next(x for x in lines if x.startswith("sim:drive") and " pipeline " in x).split()
    assert [float(v) for v in drive[2:8]] == [0.96, 1.0, round(math.sqrt(0.96), 3), 0.98, 1.0,
                                             round(math.sqrt(0.98), 3)]
    track = next(x for x in lines if x.startswith("sim:drive") and " track " in x).split()
    assert [float(v) for v in track[2:5]] == [0.9, 0.8, round(math.sqrt(0.72), 3)]
    assert "kernels loaded inside" in next(x for x in lines if x.startswith("mit-csail") and " pipeline " in x)
    only = next(x for x in lines if x.startswith("positive_1") and " pipeline " in x).split()
    assert only[2] == "-" and float(only[3]) == 2.0  # (one role only: no geometric mean)
    assert lines[-1].startswith("whole pipeline, geometric mean over the 1 inputs with both roles: median "
                                f"{math.sqrt(0.96):.3f}, mean {math.sqrt(0.98):.3f}")
