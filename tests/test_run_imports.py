"""What a command-line run on a CARMEN log without ground truth imports (issue 13 item 3): NumPy's optional
submodules stay unexecuted when SciPy copies NumPy's namespace (lazynumpy.py), the pose graph's and the loop
closure's SciPy functions come without ``scipy.sparse.linalg``'s and ``scipy.sparse.csgraph``'s packages (so
without ``scipy.linalg``), ``scipy.special`` stays unexecuted under ``scipy.ndimage`` (lazyscipy.py), and the
ground-truth scoring, the bag reader and SciPy's optimiser are never imported; a deferred NumPy or SciPy
submodule still works when used, and the SciPy functions loaded alone give SciPy's results bit for bit."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[1] / "src")

#: Modules a CARMEN run without ground truth must not execute (each was, or could be, imported at top level).
NOT_IMPORTED = (
    "numpy.f2py.crackfortran", "numpy.testing._private.utils", "numpy.ctypeslib._ctypeslib", "charset_normalizer",
    "dynslam2d.eval.trajectory", "dynslam2d.eval.removal", "dynslam2d.eval.motionclass", "dynslam2d.eval.maps",
    "dynslam2d.viz.errorsplot", "rosbags", "scipy.optimize",
    "scipy.linalg._", "scipy.sparse.linalg._isolve", "scipy.sparse.linalg._eigen",
    "scipy.sparse.linalg._dsolve.linsolve", "scipy.sparse.csgraph._laplacian", "scipy.special._ufuncs",
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
    # what a long log's loop closure and clean-up pass run (a short log may not): the pose graph's solve, the
    # connected components of the loop closer's graph, the clean-up's convolution, the track figure's median filter
    import types
    import numpy as np
    from dynslam2d.slam.posegraph import PoseGraph, diag_info
    from dynslam2d.slam.secondsearch import ties
    g = PoseGraph()
    for k in range(6):
        g.add_node((float(k), 0.1 * k, 0.0))
    for k in range(5):
        g.add_edge(k, k + 1, (1.0, 0.0, 0.0), diag_info(0.03, 0.01))
    g.add_edge(0, 5, (5.0, 0.0, 0.0), diag_info(0.02, 0.005), loop=True)
    g.optimise(kernel="none", outlier_chi2=None)
    closer = types.SimpleNamespace(config=types.SimpleNamespace(weak_score=0.0), graph=g, kf_weak=[False] * 6,
                                   kf_score=[1.0] * 6)
    assert ties(closer).tolist() == [0] * 6
    import scipy.ndimage
    scipy.ndimage.convolve(np.ones((8, 8)), np.ones((3, 3)), mode="constant")
    scipy.ndimage.median_filter(np.ones(9), size=3)
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


def test_scipy_parts_loaded_alone_give_scipys_results_and_deferred_special_runs_on_first_use() -> None:
    probe = textwrap.dedent("""
        import sys
        import numpy as np
        import scipy.sparse as sp
        from dynslam2d.lazyscipy import connected_components, defer_scipy_submodules, splu
        assert defer_scipy_submodules() and not defer_scipy_submodules()  # once only
        rng = np.random.default_rng(5)
        n = 120
        a = sp.random(n, n, density=0.05, random_state=6, format="csc")
        a = (a + a.T + 8.0 * sp.eye(n)).tocsc()
        b = rng.normal(size=n)
        mine = splu(a.copy(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        x = mine.solve(b)
        graph = sp.coo_matrix((np.ones(60), (rng.integers(0, n, 60), rng.integers(0, n, 60))), shape=(n, n)).tocsr()
        count, labels = connected_components(graph, directed=False)
        import scipy.ndimage
        gone = ("scipy.linalg._", "scipy.sparse.linalg._isolve", "scipy.sparse.csgraph._laplacian",
                "scipy.special._ufuncs")
        assert not [m for m in sys.modules if m.startswith(gone)], [m for m in sys.modules if m.startswith(gone)]
        from scipy.special import gamma  # first use executes the deferred module as an import would
        assert gamma(5.0) == 24.0 and "scipy.special._ufuncs" in sys.modules
        from scipy.sparse.csgraph import connected_components as public_cc
        from scipy.sparse.linalg import splu as public_splu  # the packages still import over the parts loaded alone
        ref = public_splu(a.copy(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        assert x.tobytes() == ref.solve(b).tobytes()
        assert np.array_equal(mine.perm_c, ref.perm_c) and (mine.L != ref.L).nnz == 0 and (mine.U != ref.U).nnz == 0
        count_ref, labels_ref = public_cc(graph, directed=False)
        assert count == count_ref and np.array_equal(labels, labels_ref)
        print("ok")
        """)
    out = subprocess.run([sys.executable, "-c", probe], env=dict(os.environ, PYTHONPATH=SRC), capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-3000:]


def test_a_scipy_module_not_found_alone_is_reported_and_unregistered() -> None:
    from dynslam2d.lazyscipy import _load_alone

    name = "scipy.sparse.csgraph._no_such_module"
    with pytest.raises(ImportError):
        _load_alone((name,))
    assert name not in sys.modules
