"""Peak-memory measures of issue 13 item 3 keep the results: lazy imports, the figures' grey indices computed
in row blocks, the pre-sized re-render of the loop closure and the checkpointer letting go of the pipeline."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from conftest import ScanList
from test_loops import _block_loop_world, _loop_path, _scans
from test_memory import _config as _memory_config
from test_memory import _parked_scene

from dynslam2d.config import Config
from dynslam2d.gridmap import GridMap
from dynslam2d.io.checkpoint import Checkpointer
from dynslam2d.pipeline import _presize_render, run
from dynslam2d.sim.simulation import SimSource
from dynslam2d.slam.processor import HectorSlam
from dynslam2d.types import Pose2D, SourceMeta
from dynslam2d.viz.mapplot import UNKNOWN_GREY, grey_indices, occupancy_image, occupancy_indices


def test_pipeline_import_leaves_figures_and_solvers_unloaded() -> None:
    """``import dynslam2d.pipeline`` (what a run imports before its first scan) loads neither matplotlib
    nor SciPy's sparse solvers / optimiser / ndimage: each costs start-up time and resident memory."""
    code = ("import sys, dynslam2d.pipeline, dynslam2d.cli; "
            "print(','.join(m for m in ('matplotlib', 'scipy.sparse', 'scipy.optimize', 'scipy.ndimage') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def _whole_image_indices(img: np.ndarray) -> np.ndarray:
    """The colormap lookup on the whole image at once (the former draw_grey), 256 greys."""
    return np.clip((np.clip(img, 0.0, 1.0) * 256).astype(np.int64), 0, 255).astype(np.uint16)


def test_grey_indices_in_row_blocks_equal_the_whole_image() -> None:
    rng = np.random.default_rng(3)
    prob = rng.uniform(0.0, 1.0, (700, 37))  # several 256-row blocks and a partial last one
    prob[rng.uniform(size=prob.shape) < 0.2] = np.nan
    prob[0, 0], prob[1, 0] = 0.0, 1.0
    grid = GridMap(prob, 0.05, (0.0, 0.0))
    img = occupancy_image(grid)
    expected = _whole_image_indices(img)
    got = occupancy_indices(grid)
    np.testing.assert_array_equal(got, expected)
    assert got[0, 0] == 255 and got[1, 0] == 0  # free white, occupied black
    assert got[np.isnan(prob)].min() == got[np.isnan(prob)].max() == int(UNKNOWN_GREY * 256)
    np.testing.assert_array_equal(occupancy_indices(grid, fade=0.35),
                                  _whole_image_indices(1.0 - 0.35 * (1.0 - img)))
    np.testing.assert_array_equal(grey_indices(img), expected)


def _loop_run():
    gt = _loop_path(step=0.25, laps=1.3)
    scans = _scans(_block_loop_world(), gt, seed=2)
    meta = SourceMeta(format="sim", origin="test:block-loop", count=len(scans), beams=360)
    return scans, meta


def test_presized_render_allocates_once_and_gives_the_same_map(tmp_path) -> None:
    scans, meta = _loop_run()
    ckpt = Checkpointer(tmp_path / "ckpt", every_s=0.0, every_scans=0)
    result = run(ScanList(scans, meta), Config(), observers=[ckpt])
    # the checkpointer lets go of the pipeline at the end (its maps would live on through the figures)
    assert ckpt._pipeline is None and ckpt.n_scans == len(scans)
    loop = result.loop
    assert loop is not None and len(loop.keyframes) > 10
    cfg = result.config.slam.model_copy(update={"map_levels": 1})
    grown, sized = HectorSlam(cfg), HectorSlam(cfg)
    _presize_render(sized, loop)
    assert sized.map.levels[0].n_grows == 1
    for kf, p in zip(loop.keyframes, loop.node_poses):
        pose = Pose2D(float(p[0]), float(p[1]), float(p[2]))
        grown.update_map(kf.kept(), pose, force=True)
        sized.update_map(kf.kept(), pose, force=True)
    assert sized.map.levels[0].n_grows == 1  # every cell the keyframes touch was inside the first allocation
    assert grown.map.levels[0].n_grows > 1
    np.testing.assert_array_equal(sized.logodds(0)[0], grown.logodds(0)[0])
    assert sized.logodds(0)[1] == grown.logodds(0)[1]


def test_counter_reserved_once_counts_the_same() -> None:
    """The clean-up recount (after loop closure) reserves its counts once: same counts as growing."""
    from dynslam2d.slam.cleanup import VisibilityCounter

    gt = _loop_path(step=0.5, laps=1.0)
    scans = _scans(_block_loop_world(), gt, seed=4)
    items = [(s, Pose2D(float(p[0]), float(p[1]), float(p[2]))) for s, p in zip(scans, gt)]
    grown, sized = VisibilityCounter(0.05), VisibilityCounter(0.05)
    assert sized.reserve(items)
    shape0 = sized.hits.shape
    for s, p in items:
        grown.add(s, p)
        sized.add(s, p)
    assert sized.hits.shape == shape0  # no growth after the reservation
    assert sized.nbytes < grown.nbytes  # growing by half a side at a time over-allocates
    assert grown.hits.sum() > 1000
    for a, b in ((grown.hits, sized.hits), (grown.through, sized.through), (grown.switches, sized.switches)):
        ia = np.argwhere(a > 0) + (grown.j0, grown.i0)
        ib = np.argwhere(b > 0) + (sized.j0, sized.i0)
        np.testing.assert_array_equal(ia, ib)  # the same absolute cells, in the same (row-major) order
        np.testing.assert_array_equal(a[a > 0], b[b > 0])


# ---- fifth pass (docs/speed.md, "Memory and compile, fifth pass") ------------------------------------------------

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _modules_after(statement: str, names: tuple[str, ...]) -> list[str]:
    """The ``names`` in ``sys.modules`` after running ``statement`` in a fresh interpreter."""
    code = f"import sys; {statement}; print(','.join(m for m in {names!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": SRC})
    return [m for m in out.stdout.strip().split(",") if m]


def test_cli_import_loads_no_kernels_config_or_figures() -> None:
    """``import dynslam2d.cli`` (every command's start: ``--help``, ``config dump``, ``info``) loads neither numba
    (77 MiB and most of a second) nor pydantic, SciPy, matplotlib or rosbags: each command imports what it uses."""
    assert _modules_after("import dynslam2d.cli", ("numba", "llvmlite", "pydantic", "scipy", "matplotlib",
                                                   "rosbags", "PIL")) == []


def test_pipeline_import_loads_no_figures_bags_or_linear_algebra() -> None:
    """A run's imports before its first scan: no matplotlib / PIL (figures, after the run), no rosbags (bags only),
    no scipy.linalg or scipy.sparse (the pose graph's solver imports them when it first solves)."""
    assert _modules_after("import dynslam2d.pipeline, dynslam2d.results, dynslam2d.cli",
                          ("matplotlib", "PIL", "rosbags", "scipy.linalg", "scipy.sparse", "scipy.optimize",
                           "scipy.ndimage")) == []


def test_plain_numba_errors_set_before_numba_and_never_over_the_user() -> None:
    """The command line has numba format its typing errors without colorama (a shorter cold compile); a setting
    of the user's is kept, and once numba is imported nothing changes."""
    code = ("import os, sys\n"
            "os.environ.pop('NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING', None)\n"
            "from dynslam2d.cli import main\n"
            "sys.argv = ['dynslam2d', '--help']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "import numba.core.errors as e\n"
            "from dynslam2d.jitcache import plain_numba_errors\n"
            "print(os.environ.get('NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING'), type(e.termcolor()).__name__, "
            "plain_numba_errors(), file=sys.stderr)\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**env, "PYTHONPATH": SRC}).stderr.split()[-3:]
    assert out == ["1", "NOPColorScheme", "False"]
    code2 = ("import os; from dynslam2d.jitcache import plain_numba_errors; "
             "print(plain_numba_errors(), repr(os.environ['NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING']))")
    out2 = subprocess.run([sys.executable, "-c", code2], capture_output=True, text=True, check=True,
                          env={**env, "PYTHONPATH": SRC, "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING": ""})
    assert out2.stdout.split() == ["False", "''"]  # the user's (empty: highlighting on) setting is kept


def _traced_peak(fn, *args):
    """(result, peak bytes numpy and Python allocated while ``fn(*args)`` ran)."""
    import tracemalloc

    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        out = fn(*args)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return out, peak


def test_map_export_is_the_logistic_of_the_logodds_in_about_one_float64_per_cell() -> None:
    """``to_gridmap`` (the run's map export, at the end of the run loop and of every re-render) computes
    1 / (1 + exp(−l)) in place: the same float64 values as the whole-array expression, with a peak of the
    output's 8 bytes per cell plus the unobserved mask (it was 4 map-sized float64 arrays)."""
    from dynslam2d.slam.grid import MultiResMap

    rng = np.random.default_rng(5)
    m = MultiResMap(0.05, 1, -0.4, 0.85)
    lv = m.levels[0]
    lv.ensure(0, 0, 899, 599)  # 600 × 900 cells with margins
    lv.logodds[:] = rng.normal(0.0, 4.0, lv.shape).astype(np.float32)
    lv.uidx[:] = np.where(rng.uniform(size=lv.shape) < 0.7, 7, 0).astype(np.int32)
    lv.uidx[:40] = 0  # unobserved rows: the export crops them
    grid, peak = _traced_peak(m.to_gridmap, 0)
    r0, r1, c0, c1 = lv.known_bounds()
    lo = lv.logodds[r0:r1, c0:c1].astype(np.float64)
    expected = 1.0 / (1.0 + np.exp(-lo))
    expected[lv.uidx[r0:r1, c0:c1] < 1] = np.nan
    np.testing.assert_array_equal(grid.prob, expected)  # bit for bit (NaN where unobserved)
    cells = grid.prob.size
    assert cells > 400_000
    assert peak < 10 * cells + 2**20, peak / cells  # 8 B/cell for the output, 1 for the mask


def test_map_entropy_in_blocks_equals_the_whole_array_sum_in_a_fraction_of_the_memory() -> None:
    """The loop closure's map check (``map_entropy``) sums the same float64 terms as the whole-array expression
    (bit-identical: one float64 array of terms summed once), with temporaries of one block instead of a float64
    copy of the map and one observed-cell-sized array per operation."""
    from dynslam2d.pipeline import _ENTROPY_BLOCK, map_entropy

    rng = np.random.default_rng(9)
    lo = rng.normal(0.0, 5.0, (900, 700)).astype(np.float32)
    lo[rng.uniform(size=lo.shape) < 0.3] = 0.0  # unobserved cells
    lo[0, :4] = (60.0, -60.0, 1e-3, -1e-3)  # clipped at both ends, near 0.5
    obs = lo[lo != 0.0].astype(np.float64)
    p = np.clip(1.0 / (1.0 + np.exp(-obs)), 1e-12, 1.0 - 1e-12)
    expected = float(-np.sum(p * np.log(p) + (1.0 - p) * np.log1p(-p)))
    got, peak = _traced_peak(map_entropy, lo)
    assert got == expected
    n = obs.size
    assert n > 4 * _ENTROPY_BLOCK  # several blocks and a partial last one
    # the observed values (float32), their terms (float64), the mask and two blocks of float64
    assert peak < 12 * n + lo.size + 4 * 8 * _ENTROPY_BLOCK + 2**20, peak / n
    assert map_entropy(np.zeros((5, 5), dtype=np.float32)) == 0.0


def test_run_frees_the_front_end_map_before_the_loop_closure_finishes() -> None:
    """``run`` lets go of the front end's map levels as soon as the results hold its export, before the loop
    closure's final optimisation and re-render allocate theirs; the summary still reports the map's bytes."""
    import dynslam2d.pipeline as P
    from dynslam2d.slam.loops import LoopCloser

    order: list[str] = []
    release, finish = P._release_map, LoopCloser.finish

    def spy_release(pipe, grid):
        order.append("release")
        return release(pipe, grid)

    def spy_finish(self):
        order.append("finish")
        return finish(self)

    class Levels:
        sizes: list[int] = []
        finite_after_release = 0

        def on_scan(self, scan, step, pipeline) -> None:
            pass

        def on_finish(self, result, pipeline) -> None:
            Levels.sizes = [lv.logodds.size + lv.prob.size + lv.uidx.size for lv in pipeline.slam.map.levels]
            # a checkpoint written now (Ctrl-C during the loop closure's finish) must get the real map
            Levels.finite_after_release = int(np.isfinite(pipeline.gridmap().prob).sum())

    scans, meta = _loop_run()
    P._release_map, LoopCloser.finish = spy_release, spy_finish
    try:
        result = run(ScanList(scans, meta), Config(), observers=[Levels()])
    finally:
        P._release_map, LoopCloser.finish = release, finish
    assert order[:2] == ["release", "finish"]
    assert Levels.sizes and not any(Levels.sizes)
    assert Levels.finite_after_release > 1000
    assert result.memory_bytes > 0 and result.summary()["map_cells"] == list(result.grid.shape)
    assert np.isfinite(result.grid.prob).sum() > 1000


def test_lean_clean_up_frees_its_counts_and_cleans_the_same_map() -> None:
    """The command line's clean-up recorder (``keep_counts=False``) lets go of the counter before the cleaned
    copies are made and keeps no count windows; the cleaned map, log-odds, erased and restored cells and the
    stats are those of the recorder that keeps everything."""
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    kept, lean = CleanupRecorder(cfg.clean, cfg.slam), CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    result = run(ScanList(scans, meta), cfg, observers=[kept, lean])
    a, b = kept.result, lean.result
    assert a is not None and b is not None
    assert kept.counter is not None and lean.counter is None
    assert a.hits.shape == a.grid.shape and a.hits.sum() > 1000
    assert b.hits.size == b.through.size == b.switches.size == 0
    assert a.stats["erased_cells"] + a.stats["restored_cells"] > 0  # the pass changed something to compare
    np.testing.assert_array_equal(a.grid.prob, b.grid.prob)
    np.testing.assert_array_equal(a.logodds, b.logodds)
    np.testing.assert_array_equal(a.erased, b.erased)
    np.testing.assert_array_equal(a.restored, b.restored)
    assert {k: v for k, v in a.stats.items() if k != "pass_time_s"} == \
        {k: v for k, v in b.stats.items() if k != "pass_time_s"}
    assert result.grid.shape == a.grid.shape


def test_run_releases_the_erasure_ledgers_and_keeps_their_summary() -> None:
    """After the loop ``run`` folds the erasure ledgers, keeps their summary and erased cells and lets the per-track
    records go (before the re-render and the clean-up pass); ledgers of ended tracks keep only their rows' room."""
    from dynslam2d.slam.erasure import EvidenceLedger

    seen: dict[str, object] = {}
    release = EvidenceLedger.release

    def spy(self):
        # every ended record's pending buffer was cut to its rows when its track ended
        seen["slack_ended"] = sum(rec._pk.shape[1] - rec._n_rows for led in self._ended.values() for rec in led.levels)
        seen["pending_ended"] = sum(rec._n_rows for led in self._ended.values() for rec in led.levels)
        seen["ended"] = len(self._ended)
        seen["before"] = EvidenceLedger.summary(self)
        release(self)
        seen["records_after"] = len(self._ledgers) + len(self._ended)

    EvidenceLedger.release = spy
    try:
        result = run(SimSource(_parked_scene()), _memory_config(True, True, every_scan=True))
    finally:
        EvidenceLedger.release = release
    assert seen["records_after"] == 0 and seen["slack_ended"] == 0 and seen["pending_ended"] > 0
    assert seen["ended"] > 0 and result.memory["cells_recorded"] > 100 and result.memory["erasures"] > 0
    assert result.memory["cells_recorded"] == seen["before"]["cells_recorded"]  # type: ignore[index]
    assert {k: result.memory[k] for k in seen["before"]} == seen["before"]  # type: ignore[union-attr]


def test_cached_submaps_keep_only_their_probabilities() -> None:
    """The loop closer's cached submap grids keep their probability cache and let the log-odds and update indices
    go (read-only broadcasts of "unknown" of the same shape: no memory, writes fail)."""
    import pytest

    from dynslam2d.slam.grid import MultiResMap
    from dynslam2d.slam.loops import _keep_probabilities

    grid = MultiResMap(0.05, 2, -0.4, 0.9, 50.0, 10)
    ang = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    grid.integrate(Pose2D(), np.column_stack((3.0 * np.cos(ang), 3.0 * np.sin(ang))))
    lv = grid.levels[0]
    shape, prob = lv.shape, lv.prob.copy()
    assert (lv.uidx >= 0).sum() > 1000
    _keep_probabilities(lv)
    assert lv.shape == shape and not lv.empty
    np.testing.assert_array_equal(lv.prob, prob)
    assert lv.logodds.base is not None and lv.logodds.base.nbytes <= 4 and lv.uidx.base.nbytes <= 4
    assert not lv.logodds.any() and (lv.uidx == -1).all()
    with pytest.raises(ValueError):
        lv.logodds[0, 0] = 1.0


def test_saved_figure_lets_go_of_its_images_and_pixels(tmp_path) -> None:
    """``save_png`` writes the PNG, then empties the figure: the map image (and matplotlib's resampled copy of it)
    and the Agg pixel buffer go before the run's next figure is drawn."""
    import weakref

    from dynslam2d.viz.figure import new_figure, save_png

    fig = new_figure((4.0, 3.0))
    ax = fig.subplots()
    img = ax.imshow(np.arange(40_000, dtype=np.uint16).reshape(200, 200))
    path = save_png(fig, tmp_path / "f.png", dpi=50)
    assert path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert fig.axes == [] and not hasattr(fig.canvas, "renderer")
    ref = weakref.ref(img)
    del img
    assert ref() is None  # nothing in the figure keeps the image artist alive: freed without the garbage collector


def test_occupied_and_free_masks_without_a_float64_copy() -> None:
    """``GridMap.occupied`` / ``free`` (the clean-up pass, map.pgm, the map metrics) give nan_to_num's masks —
    an unknown cell as probability 0 / 1, infinities as the largest floats — for any threshold, in about one
    byte per cell (nan_to_num copied the float64 map first)."""
    rng = np.random.default_rng(2)
    prob = rng.uniform(-0.2, 1.2, (400, 500))
    prob[rng.uniform(size=prob.shape) < 0.3] = np.nan
    prob[0, :4] = (np.inf, -np.inf, 0.65, 0.196)
    grid = GridMap(prob, 0.05, (0.0, 0.0))
    for t in (-0.5, 0.0, 0.196, 0.65, 1.0, 1.5):
        np.testing.assert_array_equal(grid.occupied(t), np.nan_to_num(prob, nan=0.0) > t)
        np.testing.assert_array_equal(grid.free(t), np.nan_to_num(prob, nan=1.0) < t)
    _, peak = _traced_peak(grid.occupied, 0.65)
    assert peak < 2 * prob.size + 2**16, peak / prob.size
    _, peak = _traced_peak(grid.free, 0.196)
    assert peak < 2 * prob.size + 2**16, peak / prob.size


def test_released_results_are_written_byte_for_byte_the_same(tmp_path) -> None:
    """``write_outputs(release=True)`` (the command line) lets the log-odds, keyframes and maps go as soon as they
    are written or drawn; every file it writes is the one written without it."""
    from dynslam2d.results import write_outputs
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    runs = []
    for _ in range(2):
        rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
        runs.append((run(ScanList(scans, meta), cfg, observers=[rec]), rec.result))
    (res_a, cl_a), (res_b, cl_b) = runs
    assert cl_a is not None and cl_b is not None and res_b.loop is not None and res_b.loop.keyframes
    a = write_outputs(res_a, tmp_path / "a", cleaned=cl_a).paths
    b = write_outputs(res_b, tmp_path / "b", cleaned=cl_b, release=True).paths
    assert res_b.grid is None and cl_b.grid is None and cl_b.logodds is None and res_b.logodds.size == 0
    assert not res_b.loop.keyframes and res_a.grid is not None and res_a.loop.keyframes
    assert list(a) == list(b) and {"map.png", "tracks.png", "map_logodds_online.npy", "map_online.pgm"} <= set(a)
    for name in sorted(set(a) - {"summary.json", "run.json"}):  # (these two hold timings)
        assert a[name].read_bytes() == b[name].read_bytes(), name


def test_level_growth_holds_the_old_level_and_one_new_array_not_both_levels() -> None:
    """``GridLevel.ensure`` grows its three arrays one at a time, each old one let go before the next new one is
    made: the memory it adds while growing is about one new array above the grown level's own size, not the whole
    old level on top of the new one (the old code's peak: old + new). Content and geometry are kept."""
    import tracemalloc

    from dynslam2d.slam.grid import GridLevel, encode_probs

    rng = np.random.default_rng(3)
    lv = GridLevel(0.05)
    tracemalloc.start()  # before the level's arrays exist: their frees are counted too
    try:
        lv.ensure(0, 0, 799, 599)
        lv.logodds[:] = rng.normal(0.0, 3.0, lv.shape).astype(np.float32)
        lv.prob[:] = encode_probs(rng.uniform(size=lv.shape).astype(np.float32))
        lv.uidx[:] = rng.integers(-1, 50, lv.shape).astype(np.int32)
        before = {k: getattr(lv, k).copy() for k in ("logodds", "prob", "uidx")}
        i0, j0, (h, w) = lv.i0, lv.j0, lv.shape
        old_bytes = lv.nbytes
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        lv.ensure(i0 - 300, j0 - 10, i0 + w + 300, j0 + h - 1)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    new_bytes = lv.nbytes
    assert new_bytes > 1.5 * old_bytes
    # grown level minus the old one, plus one array of the new size: the one-at-a-time transient (old and new levels
    # side by side would be new_bytes)
    assert peak <= new_bytes - old_bytes + new_bytes // 3 + 2**16, (peak, old_bytes, new_bytes)
    c0, r0 = i0 - lv.i0, j0 - lv.j0
    for k, old in before.items():
        arr = getattr(lv, k)
        assert arr.shape == lv.shape and arr.flags.c_contiguous
        np.testing.assert_array_equal(arr[r0:r0 + h, c0:c0 + w], old)
    grown = np.ones(lv.shape, dtype=bool)
    grown[r0:r0 + h, c0:c0 + w] = False
    assert (lv.logodds[grown] == 0).all() and (lv.prob[grown] == 0).all() and (lv.uidx[grown] == 0).all()


def test_map_export_after_freeing_what_it_does_not_read_is_the_same() -> None:
    """At the run loop's end ``run`` frees the coarser levels and the finest level's probability cache before it
    exports the finest level (less memory at the loop's end): the export reads neither, so it is the same."""
    from dynslam2d.pipeline import _MapExport, _release_unexported
    from dynslam2d.slam.grid import MultiResMap

    rng = np.random.default_rng(8)
    m = MultiResMap(0.05, 3, -0.4, 0.85)
    for lv in m.levels:
        lv.ensure(0, 0, 399, 299)
        lv.logodds[:] = rng.normal(0.0, 3.0, lv.shape).astype(np.float32)
        lv.uidx[:] = np.where(rng.uniform(size=lv.shape) < 0.6, 4, 0).astype(np.int32)
    a = _MapExport.of(m)
    _release_unexported(m)
    assert m.levels[0].prob.size == 0 and all(lv.nbytes == 0 for lv in m.levels[1:])
    b = _MapExport.of(m)
    np.testing.assert_array_equal(a.logodds, b.logodds)
    np.testing.assert_array_equal(a.unknown, b.unknown)
    assert a.origin == b.origin and a.resolution == b.resolution


_HEAP_PROBE = r"""
import sys
import numpy as np
from dynslam2d.memtrim import map_large_blocks
if sys.argv[1] == "1":
    assert map_large_blocks()
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * 4096
big = np.ones(24 * 2**20, dtype=np.uint8)  # a map-sized array, freed: glibc's default raises its threshold to it
del big
base = rss()
blocks, keep = [], []
for _ in range(5):  # 25 MiB in 5 MiB arrays, each with a live 64 kB block after it (in the heap either way)
    blocks.append(np.ones(5 * 2**20, dtype=np.uint8))
    keep.append(bytearray(64_000))
del blocks
print((rss() - base) / 2**20)
"""


def test_fixed_mmap_threshold_returns_freed_arrays_to_the_os() -> None:
    """``memtrim.map_large_blocks`` (the command line sets it): once a map-sized array was freed, glibc by default
    puts later arrays of up to that size in its heap, where freed ones stay resident below live small blocks; with
    the threshold fixed they are mappings of their own and leave the process when freed. Linux/glibc only."""
    import ctypes

    import pytest

    from dynslam2d.memtrim import _glibc

    if _glibc("mallopt", ctypes.c_int, ctypes.c_int) is None:
        pytest.skip("glibc's allocator only")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    kept = {flag: float(subprocess.run([sys.executable, "-c", _HEAP_PROBE, flag], capture_output=True, text=True,
                                       check=True, env=env).stdout) for flag in ("0", "1")}
    assert kept["1"] < 4.0, kept  # MiB still resident after freeing 25 MiB of arrays
    assert kept["0"] > 16.0, kept  # (the default keeps them: the test measures what the setting changes)


def test_released_results_draw_without_either_float64_map(tmp_path, monkeypatch) -> None:
    """With ``release=True`` neither float64 map (the online one, the cleaned one drawn in map.png) is alive when
    matplotlib draws map.png or tracks.png: the figures get grey indices (issue 13 item 3; a reference in
    ``write_outputs`` kept the drawn map through both figures)."""
    import gc
    import weakref

    import dynslam2d.viz.figures as F
    from dynslam2d.results import write_outputs
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    res = run(ScanList(scans, meta), cfg, observers=[rec])
    assert rec.result is not None
    maps = [weakref.ref(res.grid.prob), weakref.ref(rec.result.grid.prob)]
    alive: dict[str, int] = {}

    def spy(name, fn):  # type: ignore[no-untyped-def]
        def drawn(*a, **k):  # type: ignore[no-untyped-def]
            gc.collect()
            alive[name] = sum(m() is not None for m in maps)
            return fn(*a, **k)
        return drawn

    monkeypatch.setattr(F, "plot_map", spy("map.png", F.plot_map))
    monkeypatch.setattr(F, "plot_tracks", spy("tracks.png", F.plot_tracks))
    cleaned, rec.result = rec.result, None
    write_outputs(res, tmp_path, cleaned=cleaned, release=True)
    assert alive == {"map.png": 0, "tracks.png": 0}
