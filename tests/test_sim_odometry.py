"""Simulated odometry and IMU: the noise model, what scans carry, and the bag round trip."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.inputs import open_source
from dynslam2d.io.odometry import compose_mount
from dynslam2d.io.trajectory import read_tum
from dynslam2d.sim import SimSource, simulate
from dynslam2d.sim.export import write_simulation
from dynslam2d.sim.odometry import OdometryModel, simulate_odometry
from dynslam2d.sim.robot import waypoint_path
from dynslam2d.types import Pose2D


def _odom_array(scans) -> np.ndarray:
    return np.array([s.odom.as_array() for s in scans])


def _relative(poses: np.ndarray) -> np.ndarray:
    """Poses re-expressed in the frame of the first one."""
    first = Pose2D.from_array(poses[0]).inverse()
    return np.array([first.compose(Pose2D.from_array(p)).as_array() for p in poses])


def test_perfect_odometry_is_the_true_laser_motion():
    mount = Pose2D(0.2, -0.05, 0.1)
    sim = simulate("crowd", duration=4.0, beams=90, odometry_model=OdometryModel.perfect(mount))
    gt = sim.ground_truth
    odom = _odom_array(sim.scans)
    # the laser pose in the odometry frame differs from the world pose by one rigid transform
    # (odom frame = the BASE pose at t = 0, so the first laser odom pose is the mount itself)
    assert np.allclose(odom[0], mount.as_array(), atol=1e-12)
    rel_odom, rel_gt = _relative(odom), _relative(gt.poses)
    err = np.abs(rel_odom - rel_gt)
    err[:, 2] = np.abs((rel_odom[:, 2] - rel_gt[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    assert err[:, :2].max() < 2e-3 and err[:, 2].max() < 2e-3  # interpolation of 50 Hz samples only
    assert np.ptp(rel_gt[:, 0]) > 1.0  # the robot really drove
    # the IMU yaw rate is the robot's yaw rate
    rate = np.array([s.yaw_rate for s in sim.scans])
    true_rate = sim.scenario.robot.yaw_rate(gt.stamps)
    assert np.abs(rate - true_rate).max() < 0.05


def test_base_and_laser_differ_by_the_mount():
    mount = Pose2D(0.3, 0.0, 0.0)
    # turning in place: the laser, 0.3 m ahead of the turning centre, would stand still only if
    # it sat at the base origin; here the BASE turns in place, so the laser moves on a circle
    robot = waypoint_path([(0, 0), (1, 0)], speed=0.5, turn_rate=1.0, loop=False)
    odo = simulate_odometry(robot, 2.0, seed=1, model=OdometryModel.perfect(mount))
    base = odo.truth.poses
    laser = compose_mount(base, mount)
    back = compose_mount(laser, mount.inverse())
    assert np.allclose(back, base, atol=1e-12)
    assert np.allclose(np.hypot(*(laser[:, :2] - base[:, :2]).T), 0.3)


def test_noise_model_scale_error_seed_and_scans_unchanged():
    model = OdometryModel(scale_error=0.05, translation_noise=0.0, rotation_noise=0.0, rotation_per_metre=0.0,
                          yaw_scale_error=0.0, yaw_bias_per_metre=0.0)
    a = SimSource("crowd", duration=6.0, beams=90, odometry_model=model)
    true_len = a.odometry.truth.path_length()
    assert true_len > 2.0
    assert a.odometry.track.path_length() / true_len == pytest.approx(1.05, abs=1e-6)
    noisy1 = SimSource("crowd", duration=6.0, beams=90)
    noisy2 = SimSource("crowd", duration=6.0, beams=90)
    other = SimSource("crowd", duration=6.0, beams=90, seed=99)
    assert np.array_equal(noisy1.odometry.track.poses, noisy2.odometry.track.poses)
    assert not np.array_equal(noisy1.odometry.track.poses[:20], other.odometry.track.poses[:20])
    # default noise: the odometry drifts (final error > 1 mm) but stays near the truth (< 0.5 m after 6 s)
    drift = np.hypot(*(noisy1.odometry.track.poses[-1, :2] - noisy1.odometry.truth.poses[-1, :2]))
    assert 1e-3 < drift < 0.5
    # the IMU has its bias: mean error over a run ≈ gyro_bias
    imu = noisy1.odometry.imu
    omega = noisy1.scenario.robot.yaw_rate(imu.stamps)
    assert np.mean(imu.yaw_rate - omega) == pytest.approx(OdometryModel().gyro_bias, abs=0.002)
    # odometry never changes the scans (its random streams are separate)
    s1 = next(iter(a))
    s2 = next(iter(noisy1))
    assert s1.same_as(s2) and s1.odom is not None and s1.yaw_rate is not None
    assert a.meta.odometry == "sim"


def test_odom_none_strips_the_simulated_odometry():
    src = open_source("sim:crowd", duration=1.0, odom="none", imu="none")
    scans = list(src)
    assert all(s.odom is None and s.yaw_rate is None for s in scans)
    assert src.meta.odometry is None
    keep_imu = list(open_source("sim:crowd", duration=1.0, odom="none"))
    assert all(s.odom is None and s.yaw_rate is not None for s in keep_imu)


@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_simulated_bag_round_trip(tmp_path, storage):
    """simulate → bag with /odom /tf /tf_static /imu → read back: the same scan.odom and yaw_rate."""
    sim = simulate("crowd", duration=3.0, beams=90)
    paths = write_simulation(sim, tmp_path, storage=storage, map_resolution=0.2)
    expected = _odom_array(sim.scans)
    src = open_source(paths["scans"])
    scans = list(src)
    assert src.meta.odometry.startswith("/odom (nav_msgs/Odometry)")
    assert src.meta.extra["odometry"]["mount"] == pytest.approx([0.15, 0.0, 0.0])
    got = _odom_array(scans)
    assert np.abs(got - expected).max() < 1e-6
    rates = np.array([s.yaw_rate for s in scans])
    assert np.abs(rates - np.array([s.yaw_rate for s in sim.scans])).max() < 1e-9
    # TF odom→base_link (composed with tf_static base_link→laser) gives the same poses
    via_tf = _odom_array(open_source(paths["scans"], odom="tf"))
    assert np.abs(via_tf - expected).max() < 1e-6
    # odom.tum: the same laser poses, re-anchored at the first scan
    tum = read_tum(tmp_path / "odom.tum")
    assert np.abs(tum.poses - _relative(expected)).max() < 1e-9
    assert np.array_equal(tum.stamps, sim.ground_truth.stamps)
