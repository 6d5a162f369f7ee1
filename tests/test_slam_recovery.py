"""Large-motion recovery of the front end (slam/recovery.py; issue 12, Intel's 0.6 s gaps)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.eval.trajectory import ate
from dynslam2d.io.trajectory import Trajectory
from dynslam2d.sim import simulate
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.recovery import ScanPeriod, needs_recovery, windows


def _run(scans, config: SlamConfig) -> tuple[HectorSlam, np.ndarray]:
    slam = HectorSlam(config)
    poses = np.array([slam.process(s).pose.as_array() for s in scans])
    return slam, poses


def test_recovery_keeps_a_run_with_large_gaps_on_track() -> None:
    # a 180° laser in the paper room, robot yawing up to ≈1 rad/s, only every 30th scan kept: 1.5 s gaps,
    # up to ≈1.5 rad of turn between scans — beyond the front end's ±0.9 rad correlative window
    sim = simulate("static", seed=5, fov=math.pi, beams=181)
    keep = slice(None, None, 30)
    scans = sim.scans[keep]
    stamps = sim.ground_truth.stamps[keep]
    ref = Trajectory(stamps, sim.ground_truth.poses_in("first")[keep])
    off_slam, off = _run(scans, SlamConfig(recovery=False))
    on_slam, on = _run(scans, SlamConfig(recovery=True))
    ate_off = ate(ref, Trajectory(stamps, off)).rmse
    ate_on = ate(ref, Trajectory(stamps, on)).rmse
    assert ate_off > 0.25  # without it the run breaks
    assert ate_on < 0.15
    assert on_slam.counts["recovery"] > 0.9 * len(scans[1:])  # every gap searched
    assert off_slam.counts["recovery"] == 0


def test_recovery_is_not_triggered_on_a_normal_run() -> None:
    sim = simulate("static", seed=0, duration=12.0)  # 20 Hz, 360° laser
    slam_on, on = _run(sim.scans, SlamConfig(recovery=True))
    _, off = _run(sim.scans, SlamConfig(recovery=False))
    assert slam_on.counts["recovery"] == 0
    np.testing.assert_allclose(on, off, atol=1e-9)


def test_trigger_and_window_follow_the_gap_and_the_score() -> None:
    c = SlamConfig(recovery=True)
    assert not needs_recovery(c, 0.05, 0.8, 0.8)
    assert needs_recovery(c, 0.6, 0.8, 0.8)  # gap
    assert needs_recovery(c, -0.1, 0.8, 0.8)  # backward stamp
    assert not needs_recovery(c, 0.05, 0.4, 0.8)  # weak matches do not trigger by default (ratio 0)
    assert needs_recovery(SlamConfig(recovery=True, recovery_score_ratio=0.6), 0.05, 0.4, 0.8)  # 0.4 < 0.6 × 0.8
    assert not needs_recovery(c, 0.6, 0.8, None)  # nothing accepted yet
    assert not needs_recovery(SlamConfig(recovery=False), 5.0, 0.1, 0.8)
    lin0, ang0 = windows(c, 0.0)
    lin, ang = windows(c, 0.5)
    assert (lin0, ang0) == (0.5, 0.9)
    assert math.isclose(lin, 1.0) and math.isclose(ang, 1.4)
    assert windows(c, 30.0) == (1.2, min(0.9 + 1.0 * c.max_time_gap, math.pi))


def test_scan_period_is_the_median_gap() -> None:
    p = ScanPeriod()
    assert p.floor(0.2) == 0.2
    for dt in (0.6, 0.01, 0.7, 0.5, -1.0, float("nan"), 0.62):
        p.add(dt)
    assert math.isclose(p.median, 0.6)
    assert math.isclose(p.floor(0.01), 0.6) and p.floor(2.0) == 2.0
