"""Moving objects and their trajectories, in the simulator's world frame.

Every trajectory is a :class:`Keyframes` object: poses ``(x, y, heading)`` at
given times, linearly interpolated in between, optionally periodic. Because
motion is piecewise linear in time, the ground-truth velocity is exact (the
slope of the current piece), never a finite difference. Builders cover the
motions a scene needs:

- :func:`square_loop` — a closed square circuit at constant speed (paper §3);
- :func:`ping_pong` — back and forth along a polyline (a line or the paper's
  L-shaped route), with optional dwell at both ends;
- :func:`random_waypoints` — a person's random-waypoint walk in a rectangle;
- :func:`timeline` — scripted go/wait steps (stop-and-go, parking, leaving).

Shapes are :class:`Rect` (``length`` along the heading × ``width`` across) and
:class:`Circle`. Units: m, s, rad, m/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dynslam2d.types import wrap_angle


@dataclass(frozen=True, eq=False)
class Keyframes:
    """A piecewise-linear trajectory ``t ↦ (x, y, heading)``.

    Attributes:
        times: (n,) non-decreasing key times, s. Two equal consecutive times
            make an instantaneous jump (used for heading changes at corners).
        xy: (n, 2) positions at the key times, m.
        heading: (n,) headings at the key times, rad (interpolated linearly as
            given, so pass unwrapped values for a smooth turn).
        period: if set, the motion repeats: time is taken modulo ``period``
            (``times`` must span [0, period] and the last key equal the first).
            If None, the first/last key is held before/after the key range.
        offset: time shift, s: the pose at time t is the key pose at t + offset.
    """

    times: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    period: float | None = None
    offset: float = 0.0

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=np.float64).ravel()
        xy = np.asarray(self.xy, dtype=np.float64).reshape(-1, 2)
        h = np.broadcast_to(np.asarray(self.heading, dtype=np.float64), t.shape).copy()
        if t.shape[0] < 1 or xy.shape[0] != t.shape[0]:
            raise ValueError("Keyframes: times and xy must have the same, non-zero length")
        if np.any(np.diff(t) < 0):
            raise ValueError("Keyframes: times must be non-decreasing")
        if self.period is not None and not (self.period > 0 and abs(t[-1] - t[0] - self.period) < 1e-9):
            raise ValueError("Keyframes: a periodic trajectory's keys must span exactly one period")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "heading", h)

    @property
    def end_time(self) -> float:
        """Time (s, before ``offset``) of the last key."""
        return float(self.times[-1])

    def sample(self, t: float | np.ndarray) -> np.ndarray:
        """State at time(s) ``t`` (s): array (..., 6) of ``x, y, heading, vx, vy, omega``.

        Velocities (m/s, rad/s) are the exact slope of the active piece; zero
        while holding before the first or after the last key.
        """
        t_arr = np.asarray(t, dtype=np.float64)
        tau = t_arr + self.offset
        times = self.times
        n = times.shape[0]
        out = np.zeros(t_arr.shape + (6,))
        if n == 1:
            out[..., 0:2] = self.xy[0]
            out[..., 2] = wrap_angle(self.heading[0])
            return out
        moving = np.ones(tau.shape, dtype=bool)
        if self.period is not None:
            tau = times[0] + np.mod(tau - times[0], self.period)
        else:
            moving = (tau >= times[0]) & (tau < times[-1])
            tau = np.clip(tau, times[0], times[-1])
        i = np.clip(np.searchsorted(times, tau, side="right") - 1, 0, n - 2)
        dt = times[i + 1] - times[i]
        pos_dt = dt > 0
        safe_dt = np.where(pos_dt, dt, 1.0)
        f = np.where(pos_dt, np.clip((tau - times[i]) / safe_dt, 0.0, 1.0), 1.0)
        dxy = self.xy[i + 1] - self.xy[i]
        dh = self.heading[i + 1] - self.heading[i]
        out[..., 0:2] = self.xy[i] + f[..., None] * dxy
        out[..., 2] = wrap_angle(self.heading[i] + f * dh)
        live = (moving & pos_dt)[..., None]
        out[..., 3:5] = np.where(live, dxy / safe_dt[..., None], 0.0)
        out[..., 5] = np.where(live[..., 0], dh / safe_dt, 0.0)
        return out


def _add(times: list, xy: list, hs: list, t: float, p: np.ndarray, h: float) -> None:
    """Append one key (time s, position m, heading rad) to the key lists."""
    times.append(t)
    xy.append(p)
    hs.append(h)


def _legs(points: np.ndarray, speed: float | Sequence[float], heading: float | None,
          pauses: Sequence[float] | None, t0: float = 0.0,
          start_heading: float | None = None) -> tuple[list[float], list[np.ndarray], list[float]]:
    """Key lists for driving through ``points`` in order.

    ``heading=None`` points the object along each leg (instant turn at corners);
    a number keeps that heading fixed. ``pauses[i]`` is the dwell at point i, s.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    nleg = pts.shape[0] - 1
    speeds = np.broadcast_to(np.asarray(speed, dtype=np.float64), (max(nleg, 1),))
    dwell = np.zeros(pts.shape[0]) if pauses is None else np.asarray(pauses, dtype=np.float64)
    if np.any(speeds <= 0):
        raise ValueError("trajectory speeds must be > 0")

    def leg_heading(k: int, prev: float) -> float:
        if heading is not None:
            return float(heading)
        d = pts[k + 1] - pts[k]
        if np.hypot(*d) == 0:
            return prev
        return math.atan2(d[1], d[0])

    h = float(heading) if heading is not None else (
        start_heading if start_heading is not None else (leg_heading(0, 0.0) if nleg else 0.0))
    times, xy, hs = [t0], [pts[0]], [h]
    t = t0
    for k in range(nleg):
        if dwell[k] > 0:
            t += float(dwell[k])
            _add(times, xy, hs, t, pts[k], h)
        hk = leg_heading(k, h)
        if hk != h:  # instantaneous turn
            _add(times, xy, hs, t, pts[k], hk)
            h = hk
        t += float(np.hypot(*(pts[k + 1] - pts[k])) / speeds[k])
        _add(times, xy, hs, t, pts[k + 1], h)
    if dwell[-1] > 0:
        t += float(dwell[-1])
        _add(times, xy, hs, t, pts[-1], h)
    return times, xy, hs


def loop_path(points: Sequence[tuple[float, float]] | np.ndarray, speed: float, heading: float | None = None,
              phase: float = 0.0, pauses: Sequence[float] | None = None) -> Keyframes:
    """Closed circuit through ``points`` (back to the first) at ``speed`` m/s.

    ``phase`` ∈ [0, 1) is the fraction of the period already travelled at t = 0.
    ``heading=None`` heads along the path, a number keeps a fixed heading (rad).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    closed = np.vstack((pts, pts[:1]))
    dwell = None if pauses is None else list(pauses) + [0.0]
    times, xy, hs = _legs(closed, speed, heading, dwell)
    if heading is None and hs[-1] != hs[0]:  # turn back to the first leg's heading at the end
        _add(times, xy, hs, times[-1], closed[-1], hs[0])
    period = times[-1]
    return Keyframes(np.array(times), np.array(xy), np.array(hs), period=period, offset=phase * period)


def square_loop(center: tuple[float, float], side: float, speed: float, heading: float | None = 0.0,
                phase: float = 0.0, clockwise: bool = False) -> Keyframes:
    """A square circuit of side ``side`` m centred at ``center`` (paper §3: the boxes'
    small and large square paths). Starts at the lower-left corner at phase 0."""
    cx, cy = center
    h = side / 2.0
    corners = [(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)]
    if clockwise:
        corners = corners[:1] + corners[:0:-1]
    return loop_path(corners, speed, heading, phase)


def ping_pong(points: Sequence[tuple[float, float]] | np.ndarray, speed: float, heading: float | None = 0.0,
              pause: float = 0.0, phase: float = 0.0) -> Keyframes:
    """Back and forth along a polyline (2 points: a line; 3: the paper's L-shaped
    route), dwelling ``pause`` s at both ends. ``phase`` ∈ [0, 1) as in :func:`loop_path`."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    there_back = np.vstack((pts, pts[-2::-1]))
    dwell = np.zeros(there_back.shape[0])
    dwell[pts.shape[0] - 1] = pause
    dwell[-1] = pause
    times, xy, hs = _legs(there_back, speed, heading, dwell)
    if hs[-1] != hs[0]:
        _add(times, xy, hs, times[-1], there_back[-1], hs[0])
    period = times[-1]
    return Keyframes(np.array(times), np.array(xy), np.array(hs), period=period, offset=phase * period)


def random_waypoints(rng: np.random.Generator, region: tuple[float, float, float, float], duration: float,
                     speed_range: tuple[float, float] = (0.6, 1.4), pause_range: tuple[float, float] = (0.0, 2.0),
                     start: tuple[float, float] | None = None) -> Keyframes:
    """A random-waypoint walk (a person) inside the rectangle ``region`` = (xmin, xmax, ymin, ymax).

    Repeatedly: pick a uniform point in the region, walk to it in a straight
    line at a uniform speed from ``speed_range`` (m/s), stand for a uniform time
    from ``pause_range`` (s). The region is convex, so the walk never leaves it.
    Keys are generated until ``duration`` s is covered; heading follows the walk.
    """
    xmin, xmax, ymin, ymax = region
    p = np.array(start if start is not None else (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)))
    times, xy, hs = [0.0], [p], [float(rng.uniform(-math.pi, math.pi))]
    t = 0.0
    while t <= duration:
        q = np.array((rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)))
        d = q - p
        dist = float(np.hypot(*d))
        if dist < 0.3:
            continue
        h = math.atan2(d[1], d[0])
        _add(times, xy, hs, t, p, h)
        t += dist / rng.uniform(*speed_range)
        _add(times, xy, hs, t, q, h)
        pause = rng.uniform(*pause_range)
        if pause > 0:
            t += pause
            _add(times, xy, hs, t, q, h)
        p = q
    return Keyframes(np.array(times), np.array(xy), np.array(hs))


def timeline(start: tuple[float, float], steps: Sequence[tuple], heading: float | None = None,
             start_heading: float = 0.0) -> Keyframes:
    """Scripted motion from ``start``: steps ``("wait", seconds)`` or
    ``("go", (x, y), speed)``; the last pose is held afterwards (parked).

    ``heading=None`` faces along each drive (keeping the last heading while
    waiting); a number keeps it fixed.
    """
    p = np.asarray(start, dtype=np.float64)
    h = start_heading if heading is None else float(heading)
    times, xy, hs = [0.0], [p], [h]
    t = 0.0
    for step in steps:
        if step[0] == "wait":
            t += float(step[1])
            _add(times, xy, hs, t, p, h)
        elif step[0] == "go":
            q = np.asarray(step[1], dtype=np.float64)
            if heading is None:
                d = q - p
                hn = math.atan2(d[1], d[0])
                if hn != h:
                    _add(times, xy, hs, t, p, hn)
                    h = hn
            t += float(np.hypot(*(q - p))) / float(step[2])
            _add(times, xy, hs, t, q, h)
            p = q
        else:
            raise ValueError(f"timeline: unknown step {step[0]!r} (use 'wait' or 'go')")
    return Keyframes(np.array(times), np.array(xy), np.array(hs))


@dataclass(frozen=True)
class Rect:
    """An oriented rectangle: ``length`` along the heading × ``width`` across, m."""

    length: float
    width: float
    kind: str = "rect"


@dataclass(frozen=True)
class Circle:
    """A disc of ``radius`` m (a person's cross-section at laser height)."""

    radius: float
    kind: str = "circle"

    @property
    def length(self) -> float:
        return 2.0 * self.radius

    @property
    def width(self) -> float:
        return 2.0 * self.radius


@dataclass(frozen=True, slots=True)
class MoverState:
    """Ground truth of one mover at one instant, world frame.

    ``length``/``width`` are the rectangle's sides (along/across the heading) or
    the circle's diameter twice; ``vx, vy`` in m/s, ``omega`` in rad/s.
    """

    id: int
    kind: str
    x: float
    y: float
    heading: float
    length: float
    width: float
    vx: float
    vy: float
    omega: float = 0.0

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


@dataclass(frozen=True, eq=False)
class Mover:
    """A moving object: label ``id`` (≥ 1, the beam label of its hits), a
    descriptive ``name``, a shape and a trajectory."""

    id: int
    name: str
    shape: Rect | Circle
    trajectory: Keyframes

    def __post_init__(self) -> None:
        if self.id < 1:
            raise ValueError(f"mover ids start at 1 (0 is static structure), got {self.id}")

    @property
    def kind(self) -> str:
        return self.shape.kind

    def state(self, t: float) -> MoverState:
        """Ground-truth state at time ``t`` s."""
        x, y, h, vx, vy, om = self.trajectory.sample(t)
        return MoverState(self.id, self.kind, float(x), float(y), float(h), float(self.shape.length),
                          float(self.shape.width), float(vx), float(vy), float(om))
