"""Per-scan shortcuts (cached valid mask, Scan.without), numba's cache folder and the compile clock
(issue 13 items 1-2). Speed itself is measured in benchmarks/, never asserted here."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from dynslam2d.jitcache import compile_seconds
from dynslam2d.pipeline import run
from dynslam2d.sim import simulate
from dynslam2d.types import Scan

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _scan() -> Scan:
    r = np.linspace(0.5, 9.0, 360)
    r[::7] = np.nan
    r[5] = 0.01  # below range_min
    r[9] = 50.0  # beyond range_max
    return Scan(stamp=1.0, angle_min=-3.0, angle_increment=6.0 / 359, ranges=r, range_min=0.05, range_max=8.0)


def test_valid_mask_is_cached_but_every_call_gets_its_own_copy() -> None:
    s = _scan()
    first = s.valid_mask()
    expected = np.isfinite(s.ranges) & (s.ranges >= 0.05) & (s.ranges <= 8.0)
    np.testing.assert_array_equal(first, expected)
    first[:] = False  # a caller changing its mask must not change the scan's
    np.testing.assert_array_equal(s.valid_mask(), expected)
    assert s.valid_mask() is not s.valid_mask()
    # tightened gates are computed, not taken from the cache
    np.testing.assert_array_equal(s.valid_mask(max_range=4.0), expected & (s.ranges <= 4.0))
    np.testing.assert_array_equal(s.valid_mask(), expected)


def test_without_equals_with_ranges_and_keeps_the_mask_consistent() -> None:
    s = _scan()
    drop = np.zeros(s.n_beams, dtype=bool)
    drop[40:90] = True
    for warm in (False, True):  # with and without a cached mask on the original
        if warm:
            s.valid_mask()
        out = s.without(drop)
        ref = s.with_ranges(np.where(drop, np.nan, s.ranges))
        assert out.same_as(ref)
        np.testing.assert_array_equal(out.valid_mask(), ref.valid_mask())
        assert not out.valid_mask()[40:90].any()
        np.testing.assert_array_equal(out.angles, s.angles)
    assert np.isfinite(s.ranges[40:90]).sum() > 0  # the original is untouched


def test_cache_folder_default_and_user_choice(tmp_path: Path) -> None:
    code = ("import os, dynslam2d, dynslam2d.filter as f; "
            "print(os.environ['NUMBA_CACHE_DIR']); print(f._exclusion_kernel._cache._cache_path)")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=SRC, XDG_CACHE_HOME=str(tmp_path / "xdg"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    folder, kernel_path = out.stdout.split("\n")[:2]
    from dynslam2d.jitcache import kernel_sources_fingerprint
    # one subfolder per version of the kernel sources (numba checks only a kernel's own file)
    assert folder == str(tmp_path / "xdg" / "dynslam2d" / "numba" / f"k-{kernel_sources_fingerprint()}")
    assert kernel_path.startswith(folder)  # the kernels cache outside site-packages: a reinstall keeps them
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    folder, kernel_path = out.stdout.split("\n")[:2]
    assert folder == str(tmp_path / "mine") and kernel_path.startswith(folder)


def test_compile_clock_counts_compiles_not_calls() -> None:
    from numba import njit

    @njit
    def plus_one(x):  # type: ignore[no-untyped-def]
        return x + 1

    c0 = compile_seconds()
    assert plus_one(1) == 2
    c1 = compile_seconds()
    assert c1 > c0
    assert plus_one(2) == 3
    assert compile_seconds() == c1  # a compiled kernel's call is no compile


def test_run_reports_compile_time_of_kernels_compiled_during_the_run() -> None:
    from numba import njit

    sim = simulate("paper", duration=0.5)

    class CompilesOnce:
        def __init__(self) -> None:
            @njit
            def twice(x):  # type: ignore[no-untyped-def]
                return 2 * x

            self.kernel = twice

        def on_scan(self, scan, step, pipeline):  # type: ignore[no-untyped-def]
            self.kernel(step.index)

        def on_finish(self, result, pipeline):  # type: ignore[no-untyped-def]
            pass

    run(sim.source(), observers=[CompilesOnce()])  # warm every project kernel first
    cold = run(sim.source(), observers=[CompilesOnce()])
    warm = run(sim.source())
    assert cold.kernel_compile_s > 0.0
    assert warm.kernel_compile_s == 0.0
    assert cold.summary()["kernel_compile_s"] == round(cold.kernel_compile_s, 3)


def test_assignment_solver_is_scipys_without_scipy_optimize() -> None:
    code = ("import sys, numpy as np; from dynslam2d.detect.lsap import linear_sum_assignment as f; "
            "print('scipy.optimize' in sys.modules); "
            "c = np.random.default_rng(3).random((9, 6)); c[c > 0.85] = 1e9; r, k = f(c); "
            "from scipy.optimize import linear_sum_assignment as g; r2, k2 = g(c); "
            "print(r.tolist() == r2.tolist() and k.tolist() == k2.tolist(), len(r))")
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": SRC},
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True", "6"]


def test_release_free_memory_returns_the_heap_to_the_os() -> None:
    """glibc raises its mmap threshold after a large block is freed, so the next arrays of that size
    come from the heap and stay there once freed; release_free_memory gives them back."""
    code = (
        "import numpy as np\n"
        "from dynslam2d.memtrim import release_free_memory\n"
        "def rss():\n"
        "    return int(open('/proc/self/statm').read().split()[1]) * 4096 / 2**20\n"
        "big = np.ones(30 * 2**20 // 8); del big  # raises the dynamic mmap threshold to 30 MiB\n"
        "arrs = [np.ones(2**20 // 8) for _ in range(25)]  # 25 x 1 MiB, now from the heap\n"
        "keep = np.ones(10)  # a small block above them keeps the heap top from shrinking by itself\n"
        "del arrs\n"
        "before = rss(); ok = release_free_memory(); after = rss()\n"
        "print(ok, before - after)\n")
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": SRC},
                         capture_output=True, text=True, check=True).stdout.split()
    if out[0] == "False":  # not glibc: nothing to release, nothing to test
        return
    assert float(out[1]) > 15.0


def test_draw_grey_draws_the_pixels_of_a_float_imshow_with_an_overlay() -> None:
    """The map figures' low-memory image (uint16 colormap indices resampled as data) gives exactly the
    pixels of the float image through the "gray" colormap with the erased cells drawn over it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgba

    from dynslam2d.viz.mapplot import draw_grey

    rng = np.random.default_rng(5)
    img = rng.random((301, 207))
    img[rng.random(img.shape) < 0.2] = 0.8
    img[0, :] = 1.0
    img[:, 0] = 0.0
    erased = rng.random(img.shape) < 0.05
    extent = (-3.0, 7.35, -1.0, 14.05)

    def render(new: bool) -> np.ndarray:
        fig, ax = plt.subplots(figsize=(2.3, 3.1))  # fewer pixels than cells: resampling picks cells
        if new:
            draw_grey(ax, img, extent, erased, "#ffb000")
        else:
            ax.imshow(img, cmap="gray", vmin=0.0, vmax=1.0, origin="lower", extent=extent, interpolation="nearest")
            over = np.zeros(img.shape + (4,))
            over[erased] = to_rgba("#ffb000")
            ax.imshow(over, origin="lower", extent=extent, interpolation="nearest", zorder=1)
        fig.canvas.draw()
        out = np.asarray(fig.canvas.buffer_rgba()).copy()
        plt.close(fig)
        return out

    old, new = render(False), render(True)
    assert (new[..., :3] == np.array([255, 176, 0])).all(axis=-1).sum() > 100  # erased cells drawn
    np.testing.assert_array_equal(old, new)
