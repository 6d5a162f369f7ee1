"""Large-motion recovery of the front end (slam/recovery.py; issue 12, Intel's 0.6 s gaps)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.eval.trajectory import ate
from dynslam2d.io.trajectory import Trajectory
from dynslam2d.sim import LidarModel, cast_rays, paper_room, simulate
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.correlative import correlative_search
from dynslam2d.slam.matcher import evaluate, match_multires
from dynslam2d.slam.recovery import ScanPeriod, needs_recovery, recover, windows
from dynslam2d.types import Pose2D, Scan, wrap_angle


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


# --------------------------------------------------------------------------- runner-up wrap (±π searches)

_LIDAR = LidarModel(beams=360, noise_sigma=0.0)
_WALLS = paper_room().segments


def _room_scan(pose: Pose2D, stamp: float, blank: bool = False) -> Scan:
    """A noiseless 360° scan of the simulated paper room from ``pose`` (world, m / rad); all returns gone if blank."""
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + _LIDAR.angles, _WALLS)
    ranges, _ = _LIDAR.measure(dist, np.random.default_rng(0))
    return _LIDAR.make_scan(stamp, np.full(ranges.shape, np.inf) if blank else ranges)


def _mapped_at_origin(config: SlamConfig) -> tuple[HectorSlam, float]:
    """The paper room mapped from (0, 0, 0) for 0.35 s; returns the processor and the next stamp, s."""
    slam = HectorSlam(config)
    for k in range(8):
        slam.process(_room_scan(Pose2D(0.0, 0.0, 0.0), 0.05 * k))
    return slam, 0.4


@pytest.mark.parametrize("heading", [math.pi, math.pi - 0.01, -math.pi + 0.01])
def test_relocalisation_accepts_a_half_turn_with_the_wrapped_runner_up(heading: float) -> None:
    """Lost at heading 0, found again turned by ≈π: the ±π relocalisation search holds the answer in its first and
    last rotation rows, and without the wrap the runner-up is the best pose itself turned by 2π (margin ≈ 0,
    the relocalisation refused, the processor stays lost)."""
    truth = Pose2D(0.2, -0.1, heading)
    out = {}
    for wrap in (True, False):
        c = SlamConfig(relocalise_runner_up_wrap=wrap)
        slam, t = _mapped_at_origin(c)
        while slam.state != "lost":  # blank scans until lost_after (1 s) has passed
            slam.process(_room_scan(Pose2D(0.0, 0.0, 0.0), t, blank=True))
            t += 0.05
        scan = _room_scan(truth, t)
        pts, _ = slam.scan_points(scan)
        cr = correlative_search(slam.map.levels[c.correlative_level], pts, np.zeros(3), c.relocalise_linear_window,
                                c.relocalise_angular_window, c.correlative_angular_step, c.correlative_max_points,
                                c.correlative_max_height, 0.0, 0.0, runner_up_distance=0.5, runner_up_angle=0.3,
                                runner_up_wrap=wrap)
        out[wrap] = (cr.score - cr.runner_up, slam.process(scan), slam.state)
    margin, res, state = out[True]
    assert margin > 0.15 > SlamConfig().relocalise_margin  # the real alternative: the room's half-turn look-alike
    assert res.pose_source == "relocalised" and state == "tracking"
    assert math.hypot(res.pose.x - truth.x, res.pose.y - truth.y) < 0.02
    assert abs(wrap_angle(res.pose.theta - truth.theta)) < 0.01
    old_margin, old_res, old_state = out[False]
    assert old_margin < 0.02  # a neighbour of the best orientation one row away around the circle
    assert old_res.pose_source == "prediction" and old_state == "lost"


def test_runner_up_wraps_for_a_window_just_short_of_a_half_turn() -> None:
    """A ±(π − 0.02) window holds its two ends 0.04 rad apart around the circle: with the wrap the runner-up
    neighbourhood (0.3 rad) spans both ends, without it the other end is the runner-up."""
    slam, _ = _mapped_at_origin(SlamConfig())
    pts, _ = slam.scan_points(_room_scan(Pose2D(0.2, -0.1, math.pi), 0.4))
    margins = {}
    for wrap in (True, False):
        cr = correlative_search(slam.map.levels[1], pts, np.zeros(3), 2.0, math.pi - 0.02, None, 240, 4, 0.0, 0.0,
                                runner_up_distance=0.5, runner_up_angle=0.3, runner_up_wrap=wrap)
        assert abs(abs(cr.pose[2]) - (math.pi - 0.02)) < 1e-9  # the best is an end row
        d = abs(wrap_angle(cr.runner_up_pose[2] - cr.pose[2]))
        margins[wrap] = (cr.score - cr.runner_up, d)
    assert margins[True][0] > SlamConfig().relocalise_margin and margins[True][1] > 0.3  # the half-turn look-alike
    assert margins[False][0] < 0.01 and margins[False][1] < 0.3


def test_recovery_over_every_rotation_measures_its_margin_against_a_distinct_pose() -> None:
    """A gap long enough for a ±π recovery window (max_time_gap raised to 5 s, a 2.5 s gap, no rotation penalty so
    that a half turn can win): the robot turned by π. Without the wrap the search's runner-up is the best pose
    turned by 2π, refined back onto it, so the room's half-turn look-alike is never seeded and the margin is taken
    against the front end's own (poor) match; with it the look-alike is the runner-up and sets the margin."""
    c0 = SlamConfig(max_time_gap=5.0, correlative_rotation_weight=0.0, correlative_translation_weight=0.0)
    slam, t = _mapped_at_origin(c0)
    levels = slam.map.levels
    pts, _ = slam.scan_points(_room_scan(Pose2D(0.2, -0.1, math.pi), t + 2.5))

    def refine(seed: np.ndarray) -> np.ndarray:
        return match_multires(levels, pts, seed, c0.iterations_coarse, c0.iterations_finest, c0.hector_gradient_bug,
                              False, c0.lm_lambda_init, c0.lm_lambda_max, c0.max_rotation_step,
                              c0.max_translation_step, None, None)

    own = np.zeros(3)
    own_score = evaluate(levels[0], pts, own).score
    recs = {}
    for wrap in (True, False):
        c = c0.model_copy(update={"recovery_runner_up_wrap": wrap})
        rec = recover(c, levels, pts, own, own, own_score, 2.5, refine)
        assert rec.angular_window == pytest.approx(math.pi)
        assert math.hypot(rec.pose[0] - 0.2, rec.pose[1] + 0.1) < 0.05 and abs(wrap_angle(rec.pose[2] - math.pi)) < 0.02
        recs[wrap] = rec
    twin = refine(np.array([-0.2, 0.1, 0.0]))  # the half-turn look-alike
    twin_score = evaluate(levels[0], pts, twin).score
    assert recs[True].margin == pytest.approx(recs[True].score - twin_score, abs=0.01)
    assert recs[True].margin < 0.1
    assert recs[False].margin == pytest.approx(recs[False].score - own_score, abs=1e-9) and recs[False].margin > 0.15
