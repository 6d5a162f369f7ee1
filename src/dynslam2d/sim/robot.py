"""Scripted robot motion: the laser's pose in the world frame as a function of time.

The robot is a :class:`~dynslam2d.sim.movers.Keyframes` base motion (standing
still, or driving a waypoint path with turns in place at a bounded yaw rate)
plus a sinusoidal yaw oscillation ``A·sin(2π t / T + φ)`` on top — the
"oscillatory motion" of the robot in paper §3. Units: m, s, rad.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dynslam2d.sim.movers import Keyframes
from dynslam2d.types import Pose2D, wrap_angle


@dataclass(frozen=True, eq=False)
class ScriptedRobot:
    """Laser pose ``base(t) ⊕ yaw oscillation``, world frame.

    Attributes:
        base: base motion of the laser (position and heading), world frame.
        yaw_amplitude: amplitude A of the yaw oscillation, rad.
        yaw_period: period T of the oscillation, s (ignored when A = 0).
        yaw_phase: phase φ, rad.
    """

    base: Keyframes
    yaw_amplitude: float = 0.0
    yaw_period: float = 1.0
    yaw_phase: float = 0.0

    def sample(self, t: float | np.ndarray) -> np.ndarray:
        """(..., 3) laser poses ``x, y, theta`` (m, m, rad) at time(s) ``t`` s."""
        s = self.base.sample(t)
        out = s[..., :3].copy()
        if self.yaw_amplitude != 0.0:
            w = 2.0 * math.pi / self.yaw_period
            out[..., 2] = wrap_angle(out[..., 2] + self.yaw_amplitude * np.sin(w * np.asarray(t) + self.yaw_phase))
        return out

    def yaw_rate(self, t: float | np.ndarray) -> np.ndarray:
        """Exact yaw rate of the laser, rad/s."""
        s = self.base.sample(t)
        rate = s[..., 5].copy()
        if self.yaw_amplitude != 0.0:
            w = 2.0 * math.pi / self.yaw_period
            rate = rate + self.yaw_amplitude * w * np.cos(w * np.asarray(t) + self.yaw_phase)
        return rate

    def pose(self, t: float) -> Pose2D:
        """Laser pose at time ``t`` s, world frame."""
        return Pose2D.from_array(self.sample(float(t)))


def oscillating_in_place(x: float, y: float, heading: float, amplitude: float, period: float,
                         phase: float = 0.0, sway: Sequence[tuple[float, float]] | None = None,
                         sway_speed: float = 0.1) -> ScriptedRobot:
    """A robot standing at (x, y) yawing ``heading ± amplitude`` with ``period`` s (paper §3).

    ``sway``: optional extra points (m) the base shuttles through back and forth
    at ``sway_speed`` m/s (a robot that "moves a little"), keeping its heading.
    """
    if sway:
        pts = np.vstack(([x, y], np.asarray(sway, dtype=np.float64).reshape(-1, 2)))
        there_back = np.vstack((pts, pts[-2::-1]))
        seg = np.hypot(*np.diff(there_back, axis=0).T)
        times = np.concatenate(([0.0], np.cumsum(seg / sway_speed)))
        base = Keyframes(times, there_back, np.full(times.shape, heading), period=float(times[-1]))
    else:
        base = Keyframes(np.array([0.0]), np.array([[x, y]]), np.array([heading]))
    return ScriptedRobot(base, amplitude, period, phase)


def waypoint_path(points: Sequence[tuple[float, float]] | np.ndarray, speed: float, turn_rate: float = 0.8,
                  loop: bool = True, wobble_amplitude: float = 0.0, wobble_period: float = 3.0) -> ScriptedRobot:
    """A robot driving through ``points`` at ``speed`` m/s, facing along each leg,
    turning in place at ``turn_rate`` rad/s at each corner (no instant jumps).

    ``loop`` closes the circuit and repeats it; otherwise the robot stops at the
    last point. ``wobble_*`` adds a yaw oscillation on top (a wobbly platform).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if loop:
        pts = np.vstack((pts, pts[:1]))
    d = np.diff(pts, axis=0)
    legs_h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if loop:
        # last turn: back to the first leg's heading, by the shortest way
        legs_h = np.append(legs_h, legs_h[-1] + wrap_angle(legs_h[0] - legs_h[-1]))
    t = 0.0
    times, xy, hs = [0.0], [pts[0]], [legs_h[0]]
    for k in range(d.shape[0]):
        t += float(np.hypot(*d[k])) / speed
        times.append(t)
        xy.append(pts[k + 1])
        hs.append(legs_h[k])
        if k + 1 < legs_h.shape[0]:
            turn = abs(legs_h[k + 1] - legs_h[k])
            if turn > 0:
                t += turn / turn_rate
                times.append(t)
                xy.append(pts[k + 1])
                hs.append(legs_h[k + 1])
    times_a, xy_a, hs_a = np.array(times), np.array(xy), np.array(hs)
    # a closed circuit ends at the first leg's heading + 2πk, so it repeats seamlessly
    base = Keyframes(times_a, xy_a, hs_a, period=float(times_a[-1]) if loop else None)
    return ScriptedRobot(base, wobble_amplitude, wobble_period)
