"""Partial views give no false speed: walls that slide into view while the robot drives along them
(cut by the field of view, by an occluding pillar, by the range limit, seen at grazing angles)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import CONFIRMED, Tracker
from dynslam2d.sim import cast_rays, rect_segments
from dynslam2d.sim.world import polyline_segments
from dynslam2d.types import Pose2D, Scan

FOV = math.radians(240.0)
N = 680
ANGLES = -0.5 * FOV + np.arange(N) * FOV / (N - 1)
# a 30 m corridor 3 m wide with door recesses (the wall is cut into pieces), pillars that occlude it
WALLS = np.vstack([
    polyline_segments([(-5.0, 1.5), (3.0, 1.5), (3.0, 2.3), (4.0, 2.3), (4.0, 1.5), (12.0, 1.5), (12.0, 2.3),
                       (13.0, 2.3), (13.0, 1.5), (25.0, 1.5)]),
    polyline_segments([(-5.0, -1.5), (25.0, -1.5)]),
    rect_segments(6.0, 1.2, 0.0, 0.3, 0.3),
    rect_segments(16.0, -1.2, 0.0, 0.3, 0.3),
])


def render(pose: Pose2D, stamp: float, range_max: float, seed: int) -> Scan:
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + ANGLES, WALLS, np.zeros(WALLS.shape[0], dtype=np.int32),
                        np.zeros((0, 3)), np.zeros(0, dtype=np.int32))
    r = dist + np.random.default_rng(seed).normal(0.0, 0.01, dist.shape)
    r[~np.isfinite(dist) | (dist > range_max)] = np.inf
    return Scan(stamp=stamp, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]), ranges=r,
                range_min=0.05, range_max=range_max)


@pytest.mark.parametrize("range_max", [30.0, 4.0])
def test_walls_sliding_into_view_never_gain_speed(range_max: float) -> None:
    """The robot drives 12 s at 1 m/s along the corridor (slight yaw wobble): the wall pieces enter the
    field of view at its edges, leave the range limit, hide behind pillars. No track on them may move
    faster than 0.6 m/s (measured 0.52 m/s, on the concave cluster of a door recess whose visible sides
    change; before the one-real-bound anchoring a wall piece reached 2.8 m/s), and none enters M."""
    tr = Tracker()
    fastest = 0.0
    rate = 10.0
    for i in range(int(12 * rate)):
        t = i / rate
        pose = Pose2D(-3.0 + 1.0 * t, 0.2 * math.sin(0.7 * t), 0.08 * math.sin(1.3 * t))
        tracks = tr.update(render(pose, t, range_max, i), pose)
        assert not any(k.in_m for k in tracks), [k.m_reason for k in tracks if k.in_m]
        for k in tracks:
            if k.state == CONFIRMED and k.n_points:
                fastest = max(fastest, k.speed)
    assert fastest < 0.6
