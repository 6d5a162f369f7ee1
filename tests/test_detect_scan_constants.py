"""Pass trk138: what ``Tracker.update`` keeps from one scan to the next instead of making it again — the prediction's
F and Q entries (written only when the step dt or ``accel_noise`` changed) and the body beams' bytes (the grown mask's
key compared by one ``tobytes`` a scan) — are what the former code made on every scan."""

from __future__ import annotations

import numpy as np

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.tracker import _cv_matrices
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D


def _grown(body: np.ndarray, w: int) -> np.ndarray:
    """The body beams grown by ``w`` beams each side (the former ``update``'s loop, on a fresh copy)."""
    near = body.astype(bool).copy()
    for d in range(1, w + 1):
        near[d:] |= body[:-d]
        near[:-d] |= body[d:]
    return near


def test_prediction_matrices_and_body_mask_are_those_of_each_scan() -> None:
    sim = simulate("crowd", duration=6.0, seed=4)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    tr = Tracker(DetectConfig())
    w = tr.config.tracker.ride_beam_window
    n = sim.scans[0].ranges.shape[0]
    body = np.zeros(n, dtype=bool)  # (the caller's array: changed in place on some scans, replaced on others)
    body[:5] = True
    seen = {"same_dt": 0, "new_dt": 0, "noise": 0, "in_place": 0, "predicted": 0}
    former_predict = Tracker._predict
    last: list = [None]

    def predict(self, dt: float) -> None:
        former_predict(self, dt)
        if self._tracks and dt > 0.0:
            F, Q = self._FQ  # (one (2, 4, 4) array: F, then Q; pass trk145)
            want_F, want_Q = _cv_matrices(dt, self.config.tracker.accel_noise)
            assert F.tobytes() == want_F.tobytes() and Q.tobytes() == want_Q.tobytes()
            seen["predicted"] += 1
            seen["same_dt" if dt == last[0] else "new_dt"] += 1
            last[0] = dt

    Tracker._predict = predict
    try:
        for i, (scan, pose) in enumerate(zip(sim.scans, poses)):
            if i == 40:  # (a configuration changed between scans: the entries follow it)
                tr.config.tracker.accel_noise *= 3.0
                seen["noise"] += 1
            if i % 7 == 3:
                # (in place: the tracker's key is its own copy; each beam toggled twice, so that a mask comes back to
                # one seen before the last change)
                body[(i // 14) * 13 % n] ^= True
                seen["in_place"] += 1
            elif i % 11 == 5:
                body = body.copy()
            tr.update(scan, pose, None, body)
            assert tr._body_near.tobytes() == _grown(body, w).tobytes()
    finally:
        Tracker._predict = former_predict
    assert seen["predicted"] > 50 and seen["same_dt"] > 10 and seen["new_dt"] > 3 and seen["in_place"] > 5, seen
