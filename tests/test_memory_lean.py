"""Peak-memory measures of issue 13 item 3 keep the results: lazy imports, the figures' grey indices computed
in row blocks, the pre-sized re-render of the loop closure and the checkpointer letting go of the pipeline."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from conftest import ScanList
from test_loops import _block_loop_world, _loop_path, _scans

from dynslam2d.config import Config
from dynslam2d.gridmap import GridMap
from dynslam2d.io.checkpoint import Checkpointer
from dynslam2d.pipeline import _presize_render, run
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
