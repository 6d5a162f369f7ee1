"""Jumps of the front end: scan-to-scan pose increments that the robot's motion cannot explain.

A scan matcher that drifted while it matched its own freshly written map snaps back when it sees the old map
again: one scan's pose moves by decimetres and degrees in a single scan period, while the steps before and after
it are the robot's ordinary motion (leg_tracker's negative_2.bag, ``/right_scan``: 0.64 m and 14° at scan 404,
where its neighbours move 0.10 m and 5°; docs/slam.md, "negative_2: the stretch that maps walls twice"). Every
scan's match looks good — the jump is the correction, and the poses *before* it were off by about its size.

The step of scan ``i`` is compared with the motion just before it: the median velocity (world frame, m/s and
rad/s, component-wise) of the ``window`` steps before it, times the scan's own time step. The excess is the jump
(a constant-velocity check, the innovation test of a Kalman filter's gating, Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, §5.4 — with a median of three steps as the
prediction, so the jump does not predict the step after it). It only looks back, so the loop closer can use it
while the run goes on (:class:`JumpCheck`) and the summary gives the same flags from the trajectory.
"""

from __future__ import annotations

import math

import numpy as np


def step_excess(stamps: np.ndarray, poses: np.ndarray,
                window: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(shift m, turn rad, expected m) by which each scan's step from the previous scan exceeds the motion before
    it, and the length of the step that motion predicts.

    ``stamps`` (n,) s, ``poses`` (n, 3) x, y (m), θ (rad) in one fixed frame (the front end's map frame).
    Returns three (n,) arrays; 0 where fewer than ``window`` earlier steps predict the step. ``window``: steps
    before it whose median velocity predicts the step.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    n = stamps.shape[0]
    shift, turn, expected = np.zeros(n), np.zeros(n), np.zeros(n)
    if n < 3:
        return shift, turn, expected
    dt = np.diff(stamps)
    d = np.diff(poses, axis=0)
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    ok = dt > 1e-6
    v = np.full_like(d, np.nan)
    v[ok] = d[ok] / dt[ok, None]
    m = d.shape[0] - window  # steps k = window … n-2, each predicted from v[k - window:k]
    if m <= 0:
        return shift, turn, expected
    prev = np.lib.stride_tricks.sliding_window_view(v, window, axis=0)[:m]  # (m, 3, window)
    cur = d[window:]
    good = ok[window:] & np.isfinite(prev).all(axis=(1, 2)) & np.isfinite(cur).all(axis=1)
    pred = np.median(prev[good], axis=2) * dt[window:][good, None]
    e = cur[good] - pred
    rows = np.flatnonzero(good) + window + 1
    shift[rows] = np.hypot(e[:, 0], e[:, 1])
    turn[rows] = np.abs(np.arctan2(np.sin(e[:, 2]), np.cos(e[:, 2])))
    expected[rows] = np.hypot(pred[:, 0], pred[:, 1])
    return shift, turn, expected


def jump_flags(stamps: np.ndarray, poses: np.ndarray, min_shift: float, ratio: float, min_turn: float = 0.0,
               window: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flag (n,) bool, shift (n,) m, turn (n,) rad): scans whose step exceeds the motion before it
    (:func:`step_excess`) by at least ``min_shift`` m and ``ratio`` × the predicted step's length (a robot
    moving fast turns its velocity by more in one scan period), or by ``min_turn`` rad (≤ 0: no rotation bound;
    ``min_shift`` ≤ 0: no translation bound)."""
    shift, turn, expected = step_excess(stamps, poses, window)
    flag = np.zeros(shift.shape[0], dtype=bool)
    if min_shift > 0:
        flag |= (shift >= min_shift) & (shift >= ratio * expected)
    if min_turn > 0:
        flag |= turn >= min_turn
    return flag, shift, turn


class JumpCheck:
    """:func:`jump_flags` one scan at a time, for the loop closer (the same flags as on the whole trajectory)."""

    def __init__(self, min_shift: float, ratio: float, min_turn: float = 0.0, window: int = 3) -> None:
        self.min_shift, self.ratio, self.min_turn, self.window = min_shift, ratio, min_turn, window
        self._recent: list[tuple[float, float, float, float]] = []

    def update(self, stamp: float, x: float, y: float, theta: float) -> bool:
        """Add the next scan's pose (s; m, m, rad); True when its step is a jump (:func:`jump_flags`)."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(theta)):
            return False
        self._recent.append((stamp, x, y, theta))
        if len(self._recent) > self.window + 2:
            del self._recent[0]
        if len(self._recent) < self.window + 2:
            return False
        a = np.array(self._recent)
        return bool(jump_flags(a[:, 0], a[:, 1:], self.min_shift, self.ratio, self.min_turn, self.window)[0][-1])
