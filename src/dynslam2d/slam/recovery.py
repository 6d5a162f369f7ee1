"""Large-motion recovery of the front end (issue 12, Intel: scans 0.6 s apart; docs/slam.md,
"Large motion between scans").

Gauss–Newton on the multi-resolution map only converges within about one coarse cell of its
start; the front end's ``auto`` correlative seed covers a fixed window. When consecutive scans
are far apart in time (a sub-sampled or dropped-scan recording) or the match is weak, the
robot may have moved beyond both, and a wrong match written into the map corrupts it for
good. This module, called by :class:`~dynslam2d.slam.processor.HectorSlam` after its own
match, then

1. searches a window that grows with the time gap (``recovery_linear_window`` +
   ``recovery_linear_speed``·dt, up to ``recovery_max_linear_window``; likewise for the
   rotation) with the correlative branch-and-bound matcher (Olson 2009; Hess et al. 2016)
   around the previous pose and around the pose the velocity predicts across the gap, asking
   each time for the best pose and the best pose elsewhere (the runner-up);
2. refines them with Gauss–Newton; among the poses whose refined score (mean occupancy
   probability of the endpoints on the finest level) is within ``recovery_margin`` of the best,
   the one nearest the velocity prediction wins; without a velocity, the front end's own match
   is replaced only by a pose scoring ``recovery_switch_margin`` higher;
3. calls the match *ambiguous* when the best pose farther than ``recovery_distinct_distance``
   / ``recovery_distinct_angle`` from the winner scores within ``recovery_margin`` of it:
   the pose is still reported, but the scan is kept out of the map. The search's runner-up
   neighbourhood wraps around the circle (``recovery_runner_up_wrap``): in a window of ±π, or
   just short of it, the best pose turned by 2π would otherwise be the runner-up, refine back onto
   the best pose and leave the real alternative unseeded (the margin overstated).

It runs only on measured conditions: a stamp gap above ``recovery_min_gap``, or, when
``recovery_score_ratio`` is above 0 (default 0: gaps only), a match score below that fraction of
the running average of accepted scores. Poses are laser poses in the map frame (m, rad).
"""

from __future__ import annotations

import math
from bisect import bisect_left as _bisect_left
from bisect import insort as _insort
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.correlative import correlative_search
from dynslam2d.slam.grid import GridLevel
from dynslam2d.slam.matcher import evaluate
from dynslam2d.types import wrap_angle

_INF = math.inf
#: Reason of a recovered match kept out of the map.
REJECT_AMBIGUOUS = "ambiguous_match"


@dataclass(slots=True)
class Recovery:
    """Outcome of one recovery search.

    Attributes:
        pose: (3,) the chosen pose, world (x m, y m, θ rad).
        score: its refined score on the finest level (0 … 1).
        margin: its score minus the best distinct alternative's (score units; +inf if none).
        ambiguous: ``margin`` < ``recovery_margin``: keep the scan out of the map.
        changed: the chosen pose is not the front end's own match.
        linear_window: translation half-width searched, m.
        angular_window: rotation half-width searched, rad.
    """

    pose: np.ndarray
    score: float
    margin: float
    ambiguous: bool
    changed: bool
    linear_window: float
    angular_window: float


class ScanPeriod:
    """The typical time between scans: median of the last ``n`` positive stamp gaps, s.

    Some logs' stamps jitter by a large part of the scan period (the sub-sampled Intel log: two scans
    0.006 s apart that are 0.33 m apart), so a single gap can understate the motion it allowed; the
    motion gate then uses max(gap, median gap)."""

    def __init__(self, n: int = 31) -> None:
        self._gaps: deque[float] = deque(maxlen=n)
        self._sorted: list[float] = []  # the same gaps in ascending order
        self._n = n
        # the middle index of a full window of odd length (−1: even n, every add takes the general path)
        self._mid = n // 2 if n % 2 else -1
        #: Median gap, s (0 before the first); kept up to date by :meth:`add` (a plain attribute: the motion gate
        #: reads it on every scan)
        self.median = 0.0

    def add(self, dt: float) -> None:
        """Record the gap ``dt`` s between two consecutive scans (ignored unless positive and finite)."""
        if dt > 0.0 and dt < _INF:  # (NaN fails both)
            srt = self._sorted
            if len(srt) == self._n:
                gaps = self._gaps
                del srt[_bisect_left(srt, gaps[0])]  # the gap the append drops (equal floats are alike)
                gaps.append(dt)
                _insort(srt, dt)
                if self._mid >= 0:  # a full window of odd length (on every scan once full): its fixed middle
                    self.median = float(srt[self._mid])
                    return
            else:
                self._gaps.append(dt)
                _insort(srt, dt)
            # statistics.median's value (np.median's) from the sorted window kept up to date: the middle one, or
            # the mean of the middle two, without sorting the window on every scan
            n = len(srt)
            i = n // 2
            self.median = float(srt[i] if n % 2 else (srt[i - 1] + srt[i]) / 2)

    def floor(self, dt: float) -> float:
        """``dt`` raised to the median gap, s."""
        return max(dt, self.median)


def needs_recovery(config: SlamConfig, dt: float | None, score: float, score_avg: float | None) -> bool:
    """Whether the match of a scan ``dt`` s after the previous one, scoring ``score`` against a running
    average ``score_avg`` (None before the first accepted match), calls for the recovery search."""
    c = config
    if not c.recovery or score_avg is None:
        return False
    if dt is not None and (dt > c.recovery_min_gap or dt < 0.0):
        return True
    return not (score >= c.recovery_score_ratio * score_avg)


def windows(config: SlamConfig, dt: float | None) -> tuple[float, float]:
    """(translation m, rotation rad) half-widths of the search ``dt`` s after the previous scan: the
    base window plus the largest motion the speed limits allow in dt, capped."""
    c = config
    t = min(max(dt or 0.0, 0.0), c.max_time_gap)
    lin = min(c.recovery_linear_window + c.recovery_linear_speed * t, c.recovery_max_linear_window)
    ang = min(c.recovery_angular_window + c.recovery_angular_speed * t, c.recovery_max_angular_window)
    return lin, ang


def _distinct(a: np.ndarray, b: np.ndarray, dist: float, angle: float) -> bool:
    return math.hypot(a[0] - b[0], a[1] - b[1]) > dist or abs(float(wrap_angle(a[2] - b[2]))) > angle


def recover(
    config: SlamConfig,
    levels: list[GridLevel],
    pts: np.ndarray,
    start: np.ndarray,
    current: np.ndarray,
    current_score: float,
    dt: float | None,
    refine: Callable[[np.ndarray], np.ndarray],
    moving: np.ndarray | None = None,
) -> Recovery | None:
    """Search around ``start`` (the front end's start estimate, world pose) and, if given, around
    ``moving`` (the pose the motion model predicts across the gap: the last velocity kept) for
    laser-frame points ``pts`` (n, 2, m).

    ``current`` / ``current_score`` are the front end's own match and its finest-level score;
    ``refine`` runs the multi-resolution Gauss–Newton from a seed. Returns None if the map level
    is empty.
    """
    c = config
    lin, ang = windows(c, dt)
    lvl = levels[min(c.correlative_level, len(levels) - 1)]
    cands: list[tuple[np.ndarray, float, bool]] = []
    if np.all(np.isfinite(current)):
        cands.append((current, current_score, False))
    centres = [start] if moving is None or not _distinct(moving, start, 0.5 * lin, 0.5 * ang) else [start, moving]
    for centre in centres:
        cr = correlative_search(
            lvl, pts, centre, lin, ang, c.correlative_angular_step, c.correlative_max_points,
            c.correlative_max_height, c.correlative_translation_weight, c.correlative_rotation_weight,
            runner_up_distance=c.recovery_distinct_distance, runner_up_angle=c.recovery_distinct_angle,
            runner_up_wrap=c.recovery_runner_up_wrap,
        )
        if cr is None:
            continue
        for seed in (cr.pose, cr.runner_up_pose):
            if seed is None:
                continue
            p = refine(seed)
            if np.all(np.isfinite(p)):
                p = np.array([p[0], p[1], float(wrap_angle(p[2]))])
                cands.append((p, evaluate(levels[0], pts, p, c.hector_gradient_bug).score, True))
    if not cands:
        return None
    # with a velocity, each pose's score is penalised by its squared deviation from the velocity's prediction
    # (a starved map ahead of the robot makes a step back score higher); among poses within the margin of the
    # best, the one nearest the prediction (without one: nearest the front end's own match) wins, and without
    # a velocity another pose wins only by the switch margin: a wide window in a half-mapped place holds many
    # poses that score a little higher by chance
    ref = moving if moving is not None else (current if np.all(np.isfinite(current)) else start)
    if moving is not None:
        cands = [(p, s - c.recovery_motion_weight * ((p[0] - ref[0]) ** 2 + (p[1] - ref[1]) ** 2)
                  - c.recovery_motion_angle_weight * float(wrap_angle(p[2] - ref[2])) ** 2, f) for p, s, f in cands]
    top = max(x[1] for x in cands)
    tied = [x for x in cands if x[1] >= top - c.recovery_margin]
    best = min(tied, key=lambda x: math.hypot(x[0][0] - ref[0], x[0][1] - ref[1])
               + abs(float(wrap_angle(x[0][2] - ref[2]))))
    challenger = max(cands, key=lambda x: x[1])
    if moving is None and challenger is not best and challenger[1] >= best[1] + c.recovery_switch_margin:
        best = challenger
    others = [s for p, s, _ in cands if _distinct(p, best[0], c.recovery_distinct_distance, c.recovery_distinct_angle)]
    margin = best[1] - max(others) if others else math.inf
    changed = best[2]
    if moving is not None:  # the finest-level score of the winner, without the penalty
        best = (best[0], evaluate(levels[0], pts, best[0], c.hector_gradient_bug).score, best[2])
    return Recovery(best[0], float(best[1]), float(margin), margin < c.recovery_margin, bool(changed), lin, ang)
