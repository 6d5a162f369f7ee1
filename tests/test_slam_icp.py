"""Point-to-line ICP (slam/icp.py): normals, registration on simulated scans, refusal of degenerate / empty cases."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.sim import LidarModel, cast_rays, polyline_segments
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.icp import line_cloud, register
from dynslam2d.types import Pose2D

LIDAR = LidarModel(beams=360, noise_sigma=0.01)
#: an 8 m × 6 m room with a 1 m × 0.6 m box in it, all walls axis-aligned
ROOM = np.vstack((polyline_segments([(-3.0, -2.0), (5.0, -2.0), (5.0, 4.0), (-3.0, 4.0)], closed=True),
                  polyline_segments([(2.0, 1.0), (3.0, 1.0), (3.0, 1.6), (2.0, 1.6)], closed=True)))
POINTS = HectorSlam(SlamConfig()).scan_points  # the SLAM's range gates


def _points(pose: Pose2D, walls: np.ndarray, seed: int) -> np.ndarray:
    """Laser-frame returns (m) of a simulated scan at ``pose`` with 1 cm range noise."""
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + LIDAR.angles, walls)
    ranges, _ = LIDAR.measure(dist, np.random.default_rng(seed))
    return POINTS(LIDAR.make_scan(0.0, ranges))[0]


def test_normals_are_perpendicular_to_walls_and_corners_are_not_usable() -> None:
    pose = Pose2D(1.0, 0.5, 0.3)
    cloud = line_cloud(pose.transform_points(_points(pose, ROOM, 0)))
    assert cloud.usable.mean() > 0.8
    # the room's walls are axis-aligned: every usable normal is along x or y (1 cm range noise tilts the
    # 10-point fits by 0.7° on average)
    n = cloud.normals[cloud.usable]
    tilt = np.degrees(np.arcsin(np.minimum(np.abs(n[:, 0]), np.abs(n[:, 1]))))
    assert tilt.mean() < 1.0 and tilt.max() < 6.0
    assert np.allclose(np.hypot(n[:, 0], n[:, 1]), 1.0)
    # an L-shaped pair of point rows: the corner point's neighbourhood is no line
    xs = np.arange(0.0, 1.0, 0.05)
    corner = line_cloud(np.vstack((np.column_stack((xs, 0 * xs)), np.column_stack((0 * xs[1:], xs[1:])))))
    assert not corner.usable[0]
    assert corner.usable[10] and abs(corner.normals[10, 1]) > 0.999


def test_registration_recovers_the_pose_of_a_simulated_scan() -> None:
    # reference: a scan at p0 in the world frame; the scan at p1, started 6 cm / 1.7° off its true pose
    p0, p1 = Pose2D(1.0, 0.5, 0.3), Pose2D(1.25, 0.62, 0.38)
    cloud = line_cloud(p0.transform_points(_points(p0, ROOM, 1)))
    pts = _points(p1, ROOM, 2)
    start = np.array([p1.x + 0.05, p1.y - 0.03, p1.theta + 0.03])
    reg = register(cloud, pts, start, max_iterations=20)
    assert reg.converged and reg.inliers > 0.8
    err = math.hypot(reg.pose[0] - p1.x, reg.pose[1] - p1.y)
    assert err < 0.004, err  # from 0.058 m
    assert abs(reg.pose[2] - p1.theta) < 0.002
    assert reg.rms < 0.02  # ≈ the 1 cm range noise


def test_a_corridor_leaves_its_axis_unconstrained() -> None:
    # two long parallel walls: nothing fixes the position along x
    walls = np.vstack((polyline_segments([(-30.0, -1.0), (30.0, -1.0)]),
                       polyline_segments([(-30.0, 1.0), (30.0, 1.0)])))
    pose = Pose2D(0.0, 0.2, 0.0)
    cloud = line_cloud(pose.transform_points(_points(pose, walls, 3)))
    reg = register(cloud, _points(pose, walls, 4), np.array([0.0, 0.2, 0.0]))
    room = Pose2D(1.0, 0.5, 0.3)
    ok = register(line_cloud(room.transform_points(_points(room, ROOM, 5))), _points(room, ROOM, 6), room.as_array())
    # (grazing returns far down the corridor leave a little information along the axis)
    assert reg.min_eigenvalue < 0.03 * reg.max_eigenvalue
    assert ok.min_eigenvalue > 0.2 * ok.max_eigenvalue


def test_no_correspondence_is_no_convergence() -> None:
    p0 = Pose2D(1.0, 0.5, 0.3)
    cloud = line_cloud(p0.transform_points(_points(p0, ROOM, 7)))
    far = register(cloud, _points(p0, ROOM, 8), np.array([p0.x + 50.0, p0.y, p0.theta]), max_distance=0.3)
    assert not far.converged and far.inliers < 0.05
    empty = register(line_cloud(np.zeros((0, 2))), _points(p0, ROOM, 9), p0.as_array())
    assert not empty.converged and empty.iterations == 0
