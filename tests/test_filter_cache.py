"""filter_scan with the caller's valid mask and sensor-frame points (the pipeline computes them once
per scan for its two filter calls) gives exactly what it computes itself."""

from __future__ import annotations

import numpy as np

from dynslam2d.filter import FilterConfig, filter_scan
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D


def test_precomputed_points_give_the_same_removal() -> None:
    sim = simulate("paper", duration=0.5)
    scan = sim.scans[3]
    pose = Pose2D(0.4, -0.2, 0.3)
    pts = pose.transform_points(scan.points())
    centres = pts[[40, 200, 500]] + 0.05  # boxes on scan points, so that beams are removed
    args = (centres, np.array([0.2, 1.0, -2.0]), np.array([0.8, 1.2, 0.6]), np.array([0.5, 0.4, 0.6]),
            np.array([1.0, 0.0, 0.5]))
    cfg = FilterConfig()
    removed, by = filter_scan(cfg, scan, pose, *args)
    valid = scan.valid_mask()
    removed2, by2 = filter_scan(cfg, scan, pose, *args, valid=valid, local_points=scan.points(valid))
    assert removed.sum() >= 10
    np.testing.assert_array_equal(removed, removed2)
    np.testing.assert_array_equal(by, by2)
    assert set(np.unique(by[removed])) == {0, 1, 2}
