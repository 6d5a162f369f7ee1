"""The repository stays clean under the ruff rules of pyproject.toml ([tool.ruff]).

CI runs only the README's test command, so lint is part of the suite: any finding in src/, tests/ or
benchmarks/ fails this test with ruff's own report.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(importlib.util.find_spec("ruff") is None, reason="ruff not installed (pip install '.[test]')")
def test_ruff_finds_nothing():
    res = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "src", "tests", "benchmarks"],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    assert res.returncode == 0, f"ruff check found problems:\n{res.stdout}{res.stderr}"
