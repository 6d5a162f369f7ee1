"""The command line loads SciPy's BLAS extension on its own (jitcache.load_blas_alone, issue 13 item 3): numba's
BLAS check then finds it without importing the whole of scipy.linalg, and kernels that call BLAS still work."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

PROBE = textwrap.dedent("""
    import sys
    from dynslam2d.jitcache import load_blas_alone
    first = load_blas_alone()
    import numba
    import numpy as np

    @numba.njit
    def dot(a, b):
        return np.dot(a, b)

    v = dot(np.arange(6.0).reshape(2, 3), np.array([1.0, 2.0, 3.0]))
    print(first, load_blas_alone(), "scipy.linalg" in sys.modules, v[0], v[1])
    """)


def test_numba_finds_blas_without_scipy_linalg(tmp_path) -> None:
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    first, again, linalg, v0, v1 = out.stdout.split()
    assert (first, again, linalg) == ("True", "False", "False")  # loaded once; scipy.linalg never imported
    assert (float(v0), float(v1)) == (8.0, 26.0)  # np.dot inside a kernel goes through the extension's BLAS


def test_without_the_helper_numba_imports_scipy_linalg(tmp_path) -> None:
    probe = "import sys, numba.np.arraymath; print('scipy.linalg' in sys.modules)"
    env = dict(os.environ, PYTHONPATH=SRC, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.split() == ["True"]  # what the helper avoids (numba's own check)
