"""The front end's correlative pre-search triggers with an odometry start (search_on_motion_with_odometry):
the previous scan's large motion does not trigger a search when the odometry predicted the start (it already
holds that motion); laser-only starts keep the motion trigger; a corrupted odometry step is still caught by the
poor-match trigger and the search recovers the pose. Simulated static room at 5 Hz: 0.13 rad per scan, above the
0.08 rad motion trigger."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.sim import SimSource
from dynslam2d.sim.scenarios import build_scenario
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.types import Pose2D

_CORRUPT = 50  # the scan whose odometry step is corrupted


@pytest.fixture(scope="module")
def room():
    """(scans with simulated odometry and IMU, ground-truth laser poses (N, 3)) of sim:static at 5 Hz, 20 s."""
    sim = SimSource(build_scenario("static", duration=20.0, rate_hz=5.0))
    return list(sim), sim.ground_truth.poses


def _run(scans, gt, odometry: bool, **cfg) -> tuple[HectorSlam, float]:
    """(processor after the run, largest position error against ground truth in the first scan's frame, m)."""
    slam = HectorSlam(SlamConfig(**cfg))
    g0 = Pose2D(*gt[0])
    worst = 0.0
    for s, g in zip(scans, gt):
        st = slam.process(s if odometry else s.with_odometry(None, None))
        d = g0.between(Pose2D(*g)).between(st.pose)
        worst = max(worst, math.hypot(d.x, d.y))
    return slam, worst


def test_the_motion_trigger_is_off_with_odometry_and_on_without(room) -> None:
    scans, gt = room
    steps = np.diff(gt[:, 2])
    assert np.median(np.abs(steps)) > SlamConfig().correlative_trigger_angle  # the motion trigger would fire
    odo, err_odo = _run(scans, gt, True)
    flag, err_flag = _run(scans, gt, True, search_on_motion_with_odometry=True)
    bare, err_bare = _run(scans, gt, False)
    # with odometry only the warm-up searches remain; with the flag on, or laser only, most scans search
    assert odo.pre_searches <= 5
    assert flag.pre_searches > 0.5 * len(scans)
    assert bare.pre_searches > 0.5 * len(scans)
    assert max(err_odo, err_flag, err_bare) < 0.01


@pytest.mark.parametrize("offset", [Pose2D(0.0, 0.0, 0.3), Pose2D(0.5, 0.0, 0.4), Pose2D(0.4, 0.3, -0.6)])
def test_a_corrupted_odometry_step_still_triggers_the_search(room, offset: Pose2D) -> None:
    """The odometry jumps by ``offset`` (in its own frame) at scan 50 and keeps the jump afterwards: only that
    scan's step is wrong. Its odometry start matches poorly, the poor-match trigger searches, and the search's
    pose wins — within 1 cm and 0.01 rad of the truth. With the poor-match trigger off no search runs there."""
    scans, gt = room
    g0 = Pose2D(*gt[0])
    for poor, expect in ((SlamConfig().poor_match_ratio, 1), (0.0, 0)):
        slam = HectorSlam(SlamConfig(poor_match_ratio=poor))
        for i, s in enumerate(scans[:_CORRUPT + 1]):
            n0 = slam.pre_searches
            st = slam.process(s.with_odometry(s.odom.compose(offset) if i >= _CORRUPT else s.odom, s.yaw_rate))
        assert slam.pre_searches - n0 == expect
        if expect:
            assert slam.counts["correlative"] == 1  # the search's pose won (the only winning search of the run)
            d = g0.between(Pose2D(*gt[_CORRUPT])).between(st.pose)
            assert math.hypot(d.x, d.y) < 0.01 and abs(d.theta) < 0.01
