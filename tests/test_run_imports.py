"""What a command-line run on a CARMEN log without ground truth imports (issue 13 item 3): NumPy's optional
submodules stay unexecuted when SciPy copies NumPy's namespace (lazynumpy.py), and the ground-truth scoring,
the bag reader and SciPy's optimiser are never imported; a deferred NumPy submodule still works when used."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: Modules a CARMEN run without ground truth must not execute (each was, or could be, imported at top level).
NOT_IMPORTED = (
    "numpy.f2py.crackfortran", "numpy.testing._private.utils", "numpy.ctypeslib._ctypeslib", "charset_normalizer",
    "dynslam2d.eval.trajectory", "dynslam2d.eval.removal", "dynslam2d.eval.motionclass", "dynslam2d.eval.maps",
    "dynslam2d.viz.errorsplot", "rosbags", "scipy.optimize",
)

RUN = textwrap.dedent("""
    import json, sys
    from dynslam2d.cli import main
    watched = tuple(sys.argv[3].split(","))
    sys.argv = ["dynslam2d", "run", sys.argv[1], "--out", sys.argv[2], "-q", "--force"]
    try:
        main()
    except SystemExit as exc:
        assert exc.code in (0, None), exc.code
    import scipy.sparse.linalg, scipy.ndimage  # what the loop closure and clean-up pass import (a short log may not)
    loaded = sorted(m for m in sys.modules if m.startswith(watched))
    import numpy as np
    np.testing.assert_array_equal(np.polynomial.Polynomial([1.0, 2.0])(np.array([3.0])), [7.0])  # still usable
    print(json.dumps({"loaded": loaded, "figure": "matplotlib.figure" in sys.modules}))
    """)


def _carmen_log(path: Path, n: int = 40, beams: int = 90) -> None:
    """A short FLASER log: a robot 0.05 m a scan along a corridor 3 m wide (walls at y = ±1.5 m)."""
    rows = []
    for i in range(n):
        x, t = 0.05 * i, 100.0 + 0.1 * i
        ranges = []
        for k in range(beams):
            a = -math.pi / 2 + math.pi * k / (beams - 1)
            s = math.sin(a)
            ranges.append(min(1.5 / abs(s) if abs(s) > 1e-6 else 20.0, 20.0))
        rr = " ".join(f"{r:.3f}" for r in ranges)
        rows.append(f"FLASER {beams} {rr} {x:.3f} 0.0 0.0 {x:.3f} 0.0 0.0 {t:.3f} test {t:.3f}")
    path.write_text("\n".join(rows) + "\n")


def test_carmen_run_leaves_ground_truth_bags_and_numpy_extras_unimported(tmp_path) -> None:
    log = tmp_path / "corridor.clf"
    _carmen_log(log)
    env = dict(os.environ, PYTHONPATH=SRC, DYNSLAM2D_COMPILE_WORKER="0")
    out = subprocess.run([sys.executable, "-c", RUN, str(log), str(tmp_path / "out"), ",".join(NOT_IMPORTED)],
                         env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["figure"]  # the run drew its figures (the same process, so the check covers their imports)
    assert (tmp_path / "out" / "map.png").is_file()
    assert got["loaded"] == []


def test_deferred_numpy_submodules_run_on_first_use() -> None:
    probe = textwrap.dedent("""
        import sys
        import numpy
        from dynslam2d.lazynumpy import DEFERRED, defer_numpy_submodules
        done = defer_numpy_submodules()
        assert set(done) <= set(DEFERRED) and "testing" in done and "f2py" in done, done
        import scipy.sparse  # copies numpy's namespace: touches every deferred submodule's name
        assert "numpy.testing._private.utils" not in sys.modules and "numpy.f2py.crackfortran" not in sys.modules
        from numpy.testing import assert_equal  # first use executes the module as an import would
        assert_equal(1, 1)
        assert "numpy.testing._private.utils" in sys.modules
        import numpy.f2py
        assert callable(numpy.f2py.run_main) and "numpy.f2py.crackfortran" in sys.modules
        assert defer_numpy_submodules() == []  # once only
        print("ok")
        """)
    out = subprocess.run([sys.executable, "-c", probe], env=dict(os.environ, PYTHONPATH=SRC), capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-3000:]
