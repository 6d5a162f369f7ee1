"""HectorSlam processor: thresholds, match/update split, bad input, rejection, end-to-end accuracy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.eval.trajectory import ate
from dynslam2d.io.trajectory import Trajectory
from dynslam2d.sim import LidarModel, cast_rays, paper_room, simulate
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam import processor as proc_mod
from dynslam2d.types import Pose2D, Scan

LIDAR = LidarModel(beams=360, noise_sigma=0.0)
WALLS = paper_room().segments


def scan_at(pose: Pose2D, stamp: float) -> Scan:
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + LIDAR.angles, WALLS)
    ranges, _ = LIDAR.measure(dist, np.random.default_rng(0))
    return LIDAR.make_scan(stamp, ranges)


def raw_scan(ranges, stamp: float = 0.0, range_min: float = 0.05) -> Scan:
    r = np.asarray(ranges, dtype=float)
    n = r.shape[0]
    inc = 2 * math.pi / max(n, 1)
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=inc, ranges=r, range_min=range_min,
                range_max=20.0)


def map_snapshot(slam: HectorSlam) -> list[np.ndarray]:
    return [lv.logodds.copy() for lv in slam.map.levels]


def same_map(a: list[np.ndarray], b: list[np.ndarray]) -> bool:
    return all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, b))


# --------------------------------------------------------------------------- thresholds / split

def test_first_scan_always_updates_and_defines_the_map_frame() -> None:
    slam = HectorSlam(SlamConfig())
    step = slam.process(scan_at(Pose2D(1.0, 0.5, 0.3), 0.0))
    assert step.map_updated and not step.rejected and step.index == 0
    assert step.pose == Pose2D()
    np.testing.assert_array_equal(step.covariance, np.zeros((3, 3)))


def test_map_update_thresholds() -> None:
    slam = HectorSlam(SlamConfig(map_update_distance_thresh=0.4, map_update_angle_thresh=0.06))
    w0 = Pose2D(0.0, 0.0, 0.0)
    slam.process(scan_at(w0, 0.0))
    moves = [(Pose2D(0.1, 0, 0), False), (Pose2D(0.3, 0, 0), False), (Pose2D(0.45, 0, 0), True),
             (Pose2D(0.5, 0, 0.03), False), (Pose2D(0.5, 0, 0.12), True)]
    for k, (p, expect) in enumerate(moves):
        step = slam.process(scan_at(p, 0.05 * (k + 1)))
        assert step.map_updated == expect, (k, step)
        assert math.hypot(step.pose.x - p.x, step.pose.y - p.y) < 0.02
    assert slam.n_map_updates == 3


def test_match_does_not_touch_the_map_and_update_map_uses_the_given_scan() -> None:
    slam = HectorSlam(SlamConfig())
    slam.process(scan_at(Pose2D(), 0.0))
    before = map_snapshot(slam)
    res = slam.match(scan_at(Pose2D(0.6, 0.1, 0.1), 0.1), predicted=Pose2D(0.55, 0.1, 0.1))
    assert same_map(before, map_snapshot(slam))
    assert math.hypot(res.pose.x - 0.6, res.pose.y - 0.1) < 0.01
    assert slam.pose == res.pose  # committed: next prediction starts here
    # update with a filtered scan (half of the beams removed): only those rays are written
    full = scan_at(Pose2D(0.6, 0.1, 0.1), 0.1)
    r = full.ranges.copy()
    r[180:] = np.nan
    assert slam.update_map(full.with_ranges(r), res.pose)
    after = map_snapshot(slam)
    assert not same_map(before, after)
    # below the thresholds nothing is written unless forced
    assert not slam.update_map(full, res.pose)
    assert slam.update_map(full, res.pose, force=True)


def test_constant_velocity_prediction() -> None:
    slam = HectorSlam(SlamConfig(constant_velocity=True, correlative_mode="never"))
    for k in range(6):
        slam.process(scan_at(Pose2D(0.08 * k, 0.0, 0.03 * k), 0.1 * k))
    pred, _ = slam._predict(0.6)
    assert pred.x == pytest.approx(0.48, abs=0.01) and pred.theta == pytest.approx(0.18, abs=0.005)
    zero = HectorSlam(SlamConfig(constant_velocity=False))
    zero.process(scan_at(Pose2D(), 0.0))
    zero.process(scan_at(Pose2D(0.08, 0, 0.03), 0.1))
    pred0, _ = zero._predict(0.2)
    assert pred0 == zero.pose


# --------------------------------------------------------------------------- bad input

def test_bad_inputs_are_skipped_with_reasons_never_crash() -> None:
    slam = HectorSlam(SlamConfig())
    good = scan_at(Pose2D(), 0.0)
    steps = [
        slam.process(raw_scan(np.full(360, np.inf), 0.0)),  # no returns before any map
        slam.process(good),  # becomes the first scan
        slam.process(raw_scan([2.0], 0.1)),  # a single beam
        slam.process(raw_scan(np.full(360, 0.2), 0.2)),  # all inside laser_min_dist (0.4 m)
        slam.process(raw_scan(np.full(360, np.nan), 0.3)),  # all NaN
        slam.process(raw_scan(np.array([]), 0.35)),  # no beams at all
    ]
    assert [s.skipped for s in steps] == [True, False, True, True, True, True]
    assert steps[1].map_updated and steps[1].pose == Pose2D()
    for s in steps[2:]:
        assert s.reason == "too_few_points" and not s.map_updated and s.pose == Pose2D()
    assert slam.summary()["reasons"]["too_few_points"] == 5
    assert slam.n_scans == 6 and slam.n_map_updates == 1
    # tracking continues afterwards, with a search because the previous scans were skipped
    after = slam.process(scan_at(Pose2D(0.3, 0.1, 0.2), 0.4))
    assert math.hypot(after.pose.x - 0.3, after.pose.y - 0.1) < 0.01


def test_time_gap_and_backward_stamp_are_counted_and_searched() -> None:
    slam = HectorSlam(SlamConfig())
    slam.process(scan_at(Pose2D(), 0.0))
    slam.process(scan_at(Pose2D(0.02, 0, 0), 0.05))
    gap = slam.process(scan_at(Pose2D(0.4, 0.3, 0.45), 5.0))  # 5 s later, moved a lot
    assert gap.time_gap and gap.used_correlative
    assert math.hypot(gap.pose.x - 0.4, gap.pose.y - 0.3) < 0.01 and abs(gap.pose.theta - 0.45) < 0.005
    back = slam.process(scan_at(Pose2D(0.4, 0.3, 0.45), 4.0))
    assert back.time_gap
    assert slam.summary()["reasons"]["time_gap"] == 2


def test_non_finite_values_never_reach_the_map(monkeypatch: pytest.MonkeyPatch) -> None:
    slam = HectorSlam(SlamConfig())
    slam.process(scan_at(Pose2D(), 0.0))
    before = map_snapshot(slam)
    # NaN / inf ranges are dropped; a NaN prediction is ignored
    r = scan_at(Pose2D(0.5, 0, 0.1), 0.1).ranges.copy()
    r[::3] = np.nan
    r[1::3] = np.inf
    step = slam.process(raw_scan(r, 0.1).with_ranges(r), predicted=Pose2D(math.nan, 0.0, 0.0))
    assert step.pose.is_finite() and not step.rejected
    # a non-finite pose passed to update_map is refused
    before = map_snapshot(slam)
    assert not slam.update_map(scan_at(Pose2D(), 0.2), Pose2D(math.inf, 0.0, 0.0), force=True)
    assert same_map(before, map_snapshot(slam))
    # a matcher that blows up: reported, pose falls back to the start, the map is untouched
    monkeypatch.setattr(proc_mod, "match_multires", lambda *a, **k: np.array([np.nan, 0.0, 0.0]))
    monkeypatch.setattr(proc_mod, "match_fit_at", lambda *a, **k: (np.array([np.nan, 0.0, 0.0]), None, None, None))
    pose_before = slam.pose
    bad = slam.process(scan_at(Pose2D(1.5, 0, 0.5), 0.3))
    assert bad.rejected and bad.reason == "non_finite_pose" and not bad.map_updated
    assert bad.pose == pose_before and bad.pose.is_finite()
    assert same_map(before, map_snapshot(slam))


def test_jump_and_score_collapse_are_rejected(monkeypatch: pytest.MonkeyPatch) -> None:
    slam = HectorSlam(SlamConfig())
    slam.process(scan_at(Pose2D(), 0.0))
    for k in range(1, 4):
        slam.process(scan_at(Pose2D(0.05 * k, 0, 0), 0.05 * k))
    before = map_snapshot(slam)
    real, real_fit = proc_mod.match_multires, proc_mod.match_fit_at
    monkeypatch.setattr(proc_mod, "match_multires", lambda lv, pts, s, *a, **k: s + np.array([14.0, 0.0, 0.0]))
    monkeypatch.setattr(proc_mod, "match_fit_at",
                        lambda lv, pts, x, y, th, *a, **k: (np.array([x + 14.0, y, th]), None, None, None))
    jump = slam.process(scan_at(Pose2D(0.6, 0, 0.3), 0.2))
    assert jump.rejected and jump.reason == "jump" and not jump.map_updated
    assert same_map(before, map_snapshot(slam))
    monkeypatch.setattr(proc_mod, "match_multires", real)
    monkeypatch.setattr(proc_mod, "match_fit_at", real_fit)
    # a scan of a different room: the score collapses, the scan is not written
    other = raw_scan(np.full(360, 0.7), 0.25)
    res = slam.process(other)
    assert res.rejected and res.reason == "endpoints_in_free_space" and not res.map_updated
    assert same_map(before, map_snapshot(slam))
    reasons = slam.summary()["reasons"]
    assert reasons["jump"] == 1 and reasons["endpoints_in_free_space"] == 1


# --------------------------------------------------------------------------- end to end

def _ate(steps, gt_first: np.ndarray, stamps: np.ndarray) -> float:
    est = Trajectory(stamps, np.array([[s.pose.x, s.pose.y, s.pose.theta] for s in steps]))
    ref = Trajectory(stamps, gt_first)
    return ate(ref, est).rmse


def test_static_room_ate_below_3cm() -> None:
    sim = simulate("static", seed=0, duration=12.0)
    slam = HectorSlam(SlamConfig())
    steps = [slam.process(s) for s in sim.scans]
    gt = sim.ground_truth.poses_in("first")
    rmse = _ate(steps, gt, sim.ground_truth.stamps)
    assert rmse < 0.03
    assert not any(s.rejected for s in steps)
    # the map is the room: a wall point seen from the start is occupied in the SLAM map
    gm = slam.gridmap()
    occ = gm.occupied()
    assert occ.sum() > 300


def test_static_room_at_low_rate_with_fast_turns() -> None:
    # 4 Hz: the robot yaws up to ≈0.25 rad between scans; GN alone would need the search
    sim = simulate("static", seed=1, duration=16.0, rate_hz=4.0, beams=361, fov=math.pi)
    slam = HectorSlam(SlamConfig())
    steps = [slam.process(s) for s in sim.scans]
    rmse = _ate(steps, sim.ground_truth.poses_in("first"), sim.ground_truth.stamps)
    assert rmse < 0.03


@pytest.mark.shared_data
def test_mit_csail_relations_beat_scan_matching_reference() -> None:
    from dynslam2d.eval.relations import relation_errors
    from dynslam2d.io.carmen import CarmenSource
    from dynslam2d.io.relations import read_relations

    scans = list(CarmenSource(shared_file("mit-csail/mit-csail.clf")))
    rel = read_relations(shared_file("mit-csail/mit-csail.relations"))
    slam = HectorSlam(SlamConfig())
    steps = [slam.process(s) for s in scans]
    traj = Trajectory(np.array([s.stamp for s in steps]),
                      np.array([[s.pose.x, s.pose.y, s.pose.theta] for s in steps]))
    r = relation_errors(traj, rel.t1, rel.t2, rel.dx, rel.dy, rel.dyaw)
    assert r.n_used == 1172
    # Kümmerle et al. 2009, MIT CSAIL, scan matching only: 0.106 ± 0.325 m
    assert r.trans_mean < 0.106 and r.trans_std < 0.325


def test_far_away_pose_cannot_exhaust_memory() -> None:
    slam = HectorSlam(SlamConfig(max_map_memory_mb=50.0))
    slam.process(scan_at(Pose2D(), 0.0))
    before = map_snapshot(slam)
    mem = slam.memory_bytes
    # a predicted pose 100 km away: matching finds nothing there, the map is not grown
    step = slam.process(scan_at(Pose2D(), 0.1), predicted=Pose2D(1e5, 0.0, 0.0))
    assert step.rejected and not step.map_updated
    assert not slam.update_map(scan_at(Pose2D(), 0.2), Pose2D(1e5, 0.0, 0.0), force=True)
    assert slam.summary()["reasons"]["map_too_large"] == 1
    assert slam.memory_bytes == mem and same_map(before, map_snapshot(slam))
    # growth within the limit still works
    assert slam.update_map(scan_at(Pose2D(), 0.3), Pose2D(30.0, 0.0, 0.0), force=True)
    assert slam.memory_bytes > mem


def test_the_points_a_map_update_integrates_are_always_finite() -> None:
    """Pass rest18 dropped ``_integrate``'s finite test of every point: the points come from ``_gate`` (both callers),
    which keeps only valid (finite, within the sensor's limits) returns times finite beam cosines and sines. Ranges
    NaN, ±inf, negative, far beyond the sensor's limit and exactly at it, with laser_max_dist infinite: every point
    finite, the map update the same as with the finite test."""
    n = 361
    r = np.linspace(0.5, 9.0, n)
    r[::7] = np.nan
    r[1::7] = np.inf
    r[2::7] = -np.inf
    r[3::7] = 1e308
    r[4::7] = -1.0
    r[5::7] = 30.0
    for cfg in (SlamConfig(), SlamConfig(laser_max_dist=math.inf, clear_no_return_dist=0.0)):
        slam = HectorSlam(cfg)
        scan = Scan(stamp=0.0, angle_min=-math.pi, angle_increment=2.0 * math.pi / n, ranges=r, range_min=0.1,
                    range_max=30.0)
        pts, clear, *_ = slam._gate(scan, True)
        assert pts.shape[0] > 0 and np.all(np.isfinite(pts)) and np.all(np.isfinite(clear))
        assert slam.update_map(scan, Pose2D(0.3, -0.2, 0.4), force=True)
        ref = HectorSlam(cfg)
        ok = np.all(np.isfinite(pts), axis=1)
        ref.map.integrate(Pose2D(0.3, -0.2, 0.4), pts[ok], clear if clear.shape[0] else None)
        for a, b in zip(slam.map.levels, ref.map.levels):
            assert np.array_equal(a.logodds, b.logodds) and (a.i0, a.j0) == (b.i0, b.j0)
