"""People: two swinging legs, a person who starts walking enters M fast; standing people do not."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.config import Config
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import cast_rays, rect_segments
from dynslam2d.types import Pose2D, Scan

N = 768
FOV = math.radians(270.0)
ANGLES = -0.5 * FOV + np.arange(N) * FOV / (N - 1)
ROOM = rect_segments(3.0, 0.0, 0.0, 12.0, 8.0)
RATE = 7.5  # Hz, as the leg_tracker recordings


def legs(cx: float, cy: float, heading: float, phase: float, walking: bool) -> np.ndarray:
    """Two leg circles (r 0.06 m) 0.2 m apart across the heading; while walking they swing ±0.2 m along it."""
    c, s = math.cos(heading), math.sin(heading)
    swing = 0.2 * math.sin(phase) if walking else 0.0
    out = []
    for side, sw in ((1.0, swing), (-1.0, -swing)):
        out.append((cx + c * sw - s * 0.1 * side, cy + s * sw + c * 0.1 * side, 0.06))
    return np.array(out)


def scene(t: float, start: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Circles of a person standing at (4, 1) until ``start`` then walking along −y at ``speed``, and of a
    person standing all the time at (2, −2); per-circle ids 1 (walker) and 2 (stander)."""
    walk = max(0.0, t - start)
    walker = legs(4.0, 1.0 - speed * walk, -0.5 * math.pi, 2.0 * math.pi * 0.9 * walk, t > start)
    stander = legs(2.0, -2.0, 0.3, 0.0, False)
    return np.vstack((walker, stander)), np.array([1, 1, 2, 2], dtype=np.int32)


def render(pose: Pose2D, t: float, circles: np.ndarray, ids: np.ndarray, seed: int) -> tuple[Scan, np.ndarray]:
    dist, lab = cast_rays((pose.x, pose.y), pose.theta + ANGLES, ROOM, np.zeros(ROOM.shape[0], dtype=np.int32),
                          circles, ids)
    r = dist + np.random.default_rng(seed).normal(0.0, 0.01, dist.shape)
    return Scan(stamp=t, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]), ranges=r,
                range_min=0.05, range_max=20.0), lab


def run_walker(start: float = 3.0, speed: float = 1.2, duration: float = 6.0, robot_speed: float = 0.0):
    """Pipeline over the scene; returns per scan (t, labels, removed, tracks)."""
    pipe = Pipeline(Config())
    out = []
    for i in range(int(duration * RATE)):
        t = i / RATE
        pose = Pose2D(robot_speed * t, 0.0, 0.0)
        circles, ids = scene(t, start, speed)
        scan, lab = render(pose, t, circles, ids, i)
        step = pipe.process(scan)
        out.append((t, lab, step.removed, step.tracks))
    return out


def test_walking_person_enters_m_within_half_a_second_and_standing_one_never() -> None:
    start = 3.0
    out = run_walker(start=start)
    first = next(t for t, lab, removed, tracks in out if t > start and removed[lab == 1].mean() > 0.5)
    assert first - start <= 0.5 + 1e-9
    assert not any(removed[lab == 2].any() for _, lab, removed, _ in out)
    assert not any(removed[lab == 1].any() for t, lab, removed, _ in out if t <= start)
