"""Jumps of the front end: scan-to-scan pose increments that the robot's motion cannot explain.

A scan matcher that drifted while it matched its own freshly written map snaps back when it sees the old map
again: one scan's pose moves by decimetres and degrees in a single scan period, while the steps before and after
it are the robot's ordinary motion (leg_tracker's negative_2.bag, ``/right_scan``: 0.64 m and 14° at scan 404,
where its neighbours move 0.10 m and 5°; docs/slam.md, "negative_2: the stretch that maps walls twice"). Every
scan's match looks good — the jump is the correction, and the poses *before* it were off by about its size.

The step of scan ``i`` is compared with two predictions from the ``window`` steps before it (world frame,
component-wise medians, so a jump does not predict the step after it):

* **constant velocity**: their median velocity (m/s, rad/s) times the scan's own time step — right when the
  stamps follow the motion (a robot at a steady scan rate, a gap after dropped scans);
* **constant step**: their median step (m, rad), whatever the time steps — right when they do not (a log
  sub-sampled by distance travelled, whose stamps are ms or seconds apart for the same 0.17 m: Intel's
  ``intel-lab.flirtlib.log``, where the time step and the step length are uncorrelated).

The excess over the *nearer* prediction is the jump: a step either model explains is motion (the innovation test
of a Kalman filter's gating, Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, §5.4, against two motion models as in their multiple-model approach, §11.6 — with a median of
three steps as each prediction). On a steady scan rate both predictions are the same;
the second removes 25 of the 36 flags the first alone raised on steps Intel's robot made (docs/slam.md). It only
looks back, so the loop closer can use it while the run goes on (:class:`JumpCheck`) and the summary gives the
same flags from the trajectory.
"""

from __future__ import annotations

import math

import numpy as np

MODELS = ("velocity", "step")  #: the two predictions of a scan's step (module docstring)


def model_excess(stamps: np.ndarray, poses: np.ndarray,
                 window: int = 3) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each prediction's (shift m, turn rad, expected m): by how much each scan's step from the previous scan
    exceeds it, and the length of the step it predicts; ``"velocity"``: the median velocity of the ``window``
    steps before it × the scan's time step, ``"step"``: their median step (module docstring).

    ``stamps`` (n,) s, ``poses`` (n, 3) x, y (m), θ (rad) in one fixed frame (the front end's map frame).
    Every array (n,); 0 where fewer than ``window`` earlier steps (or a time step ≤ 1 µs) predict the step.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    n = stamps.shape[0]
    out = {k: (np.zeros(n), np.zeros(n), np.zeros(n)) for k in MODELS}
    m = n - 1 - window  # steps k = window … n-2, each predicted from steps k - window … k-1
    if n < 3 or m <= 0:
        return out
    dt = np.diff(stamps)
    d = np.diff(poses, axis=0)
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    ok = dt > 1e-6
    v = np.full_like(d, np.nan)
    v[ok] = d[ok] / dt[ok, None]
    prev_v = np.lib.stride_tricks.sliding_window_view(v, window, axis=0)[:m]  # (m, 3, window)
    prev_d = np.lib.stride_tricks.sliding_window_view(d, window, axis=0)[:m]
    cur = d[window:]
    good = ok[window:] & np.isfinite(prev_v).all(axis=(1, 2)) & np.isfinite(cur).all(axis=1)
    rows = np.flatnonzero(good) + window + 1
    preds = {"velocity": np.median(prev_v[good], axis=2) * dt[window:][good, None],
             "step": np.median(prev_d[good], axis=2)}
    for key, pred in preds.items():
        e = cur[good] - pred
        shift, turn, expected = out[key]
        shift[rows] = np.hypot(e[:, 0], e[:, 1])
        turn[rows] = np.abs(np.arctan2(np.sin(e[:, 2]), np.cos(e[:, 2])))
        expected[rows] = np.hypot(pred[:, 0], pred[:, 1])
    return out


def step_excess(stamps: np.ndarray, poses: np.ndarray,
                window: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(shift m, turn rad, steps) by which each scan's step exceeds *both* predictions of the motion before it
    (:func:`model_excess`): the smaller excess of the two, and the smaller excess in predicted steps (excess /
    predicted step length, a predicted standstill counting as 1e-9 m). Arguments as :func:`model_excess`."""
    (sv, tv, ev), (ss, ts, es) = (model_excess(stamps, poses, window)[k] for k in MODELS)
    return (np.minimum(sv, ss), np.minimum(tv, ts),
            np.minimum(sv / np.maximum(ev, 1e-9), ss / np.maximum(es, 1e-9)))


def jump_flags(stamps: np.ndarray, poses: np.ndarray, min_shift: float, ratio: float, min_turn: float = 0.0,
               window: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flag (n,) bool, shift (n,) m, turn (n,) rad): scans whose step exceeds both predictions of the motion
    before it (:func:`step_excess`) by at least ``min_shift`` m and ``ratio`` × each predicted step's length (a
    robot moving fast turns its velocity by more in one scan period), or by ``min_turn`` rad (≤ 0: no rotation
    bound; ``min_shift`` ≤ 0: no translation bound)."""
    shift, turn, steps = step_excess(stamps, poses, window)
    flag = np.zeros(shift.shape[0], dtype=bool)
    if min_shift > 0:
        flag |= (shift >= min_shift) & (steps >= ratio)
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
