"""The written map is rendered with the grazing-incidence stop (slam.written_grazing_stop_cells,
docs/maps.md "Walls seen at grazing incidence") while the matcher's map, and so the trajectory, stay
as they were."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.config import Config
from dynslam2d.eval.maps import map_metrics
from dynslam2d.pipeline import run
from dynslam2d.sim.simulation import simulate
from dynslam2d.slam.cleanup import CleanupRecorder


def _config(written: float, loop: bool = True) -> Config:
    cfg = Config()
    cfg.slam.written_grazing_stop_cells = written
    cfg.loop.enabled = loop
    return cfg


@pytest.fixture(scope="module")
def stopgo_runs() -> tuple:
    """stop-and-go's first 15 s (the robot oscillates in the room and sees the corridor walls only at
    grazing incidence), with the written map's stop at 0 (the online map) and 1 cell, the clean-up pass on."""
    sim = simulate("stop-and-go", duration=15.0)
    out = {}
    for g in (0.0, 1.0):
        cleaner = CleanupRecorder(Config().clean)
        # the pass without its restore step (docs/maps.md "Walls that grazing rays cleared"), which would
        # otherwise put back the same wall cells in both maps
        no_restore = CleanupRecorder(Config().clean.model_copy(update={"restore_min_hits": 0}))
        out[g] = (run(sim.source(), _config(g), observers=[cleaner, no_restore]), no_restore.result, cleaner.result)
    return sim, out


def test_written_map_keeps_grazing_walls_and_the_trajectory(stopgo_runs: tuple) -> None:
    sim, out = stopgo_runs
    (plain, clean_plain, restored_plain), (stop, clean_stop, _) = out[0.0], out[1.0]
    # matching is untouched: the same poses to the last bit, the same per-scan scores
    assert np.array_equal(plain.trajectory.poses, stop.trajectory.poses)
    assert np.array_equal(plain.scores, stop.scores)
    assert "written_render_ms" in stop.summary()["loop_closure"]
    assert "written_render_ms" not in plain.summary()["loop_closure"]
    assert Config().slam.written_grazing_stop_cells == 0.0  # off by default: the written map is the online map
    truth = sim.ground_truth.static_map(plain.grid.resolution, frame="first")  # the SLAM map frame
    m_plain, m_stop = map_metrics(plain.grid, truth), map_metrics(stop.grid, truth)
    assert m_plain.recall < 0.975  # rays running along the corridor walls cleared wall cells
    assert m_stop.recall > m_plain.recall + 0.008  # 0.943 -> 0.955 on this code
    assert m_stop.precision >= m_plain.precision - 0.002
    # the clean-up pass cleans the written map (map.pgm): it keeps the gain
    c_plain, c_stop = map_metrics(clean_plain.grid, truth), map_metrics(clean_stop.grid, truth)
    assert c_stop.recall > c_plain.recall + 0.008
    assert clean_stop.grid.shape == stop.grid.shape
    # the default pass restores those cells from its counts, without the render
    r_plain = map_metrics(restored_plain.grid, truth)
    assert r_plain.recall > c_plain.recall + 0.02  # 0.943 -> 0.975 on this code (the render: 0.955)
    assert r_plain.precision >= c_plain.precision - 0.002


def test_written_map_without_keyframes_is_the_online_map() -> None:
    """With loop closure off there are no keyframes to render: the written map is the matcher's map,
    whatever the option says (docs/maps.md)."""
    sim = simulate("stop-and-go", duration=4.0)
    a = run(sim.source(), _config(0.0, loop=False))
    b = run(sim.source(), _config(1.0, loop=False))
    assert np.array_equal(a.trajectory.poses, b.trajectory.poses)
    np.testing.assert_array_equal(a.logodds, b.logodds)
