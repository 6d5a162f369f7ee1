"""`simulate` output: scans bag + ground-truth folder read back equal to the simulation."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.inputs import open_source
from dynslam2d.io.groundtruth import read_ground_truth_folder
from dynslam2d.sim import simulate
from dynslam2d.sim.export import write_simulation


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    sim = simulate("paper", duration=3.0)
    out = tmp_path_factory.mktemp("sim")
    paths = write_simulation(sim, out, map_resolution=0.1)
    return sim, out, paths


def test_scans_bag_reads_back_as_the_simulated_scans(exported):
    sim, out, paths = exported
    back = list(open_source(paths["scans"]))
    assert len(back) == len(sim.scans)
    for a, b in zip(sim.scans, back):
        assert b.stamp == pytest.approx(a.stamp, abs=1e-9)  # bags store stamps to the nanosecond
        np.testing.assert_array_equal(b.ranges, a.ranges.astype(np.float32).astype(np.float64))
        assert b.angle_min == pytest.approx(a.angle_min, abs=1e-6)


def test_ground_truth_folder_round_trips(exported):
    sim, out, _ = exported
    gt = sim.ground_truth
    files = read_ground_truth_folder(out)
    np.testing.assert_allclose(files.trajectory.poses, gt.poses_in("first"), atol=1e-12)
    np.testing.assert_array_equal(files.labels, gt.labels)
    np.testing.assert_allclose(files.stamps, gt.stamps)
    ref_map = gt.static_map(0.1, frame="first")
    np.testing.assert_array_equal(files.static_map.occupied(), ref_map.occupied())
    assert files.static_map.origin == pytest.approx(ref_map.origin)
    rows = gt.mover_rows(frame="first")
    assert files.movers is not None and files.movers.shape == rows.shape
    np.testing.assert_allclose(files.movers["vx"], rows["vx"])
    np.testing.assert_array_equal(files.movers["kind"], rows["kind"])
    assert files.info["scenario"] == "paper" and files.info["scans"] == len(sim.scans)
    # the first pose is the origin of the first-scan frame
    np.testing.assert_allclose(files.trajectory.poses[0], 0.0, atol=1e-12)
    assert (out / "overview.png").stat().st_size > 10_000


def test_missing_ground_truth_folder_is_a_clear_error(tmp_path):
    with pytest.raises(DynSlamError, match="ground-truth folder not found"):
        read_ground_truth_folder(tmp_path / "nope")
    with pytest.raises(DynSlamError, match="gt_map.yaml is missing"):
        read_ground_truth_folder(tmp_path)
