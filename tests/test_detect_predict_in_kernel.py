"""Pass trk145: the scan's Kalman prediction (``cv_predict``) runs inside the association's kernel
(``kernels_assign.associate_update`` with ``predict``) when nothing reads the state rows between the two, and in
``Tracker._associate_update`` itself on a scan without an association (no detection), and in ``_predict`` on the
tracker's first prediction (so that the runs that record the kernels called from Python find it): the tracks' states,
covariances and reports are those of a tracker that predicts in ``_predict`` as before, on every scan."""

from __future__ import annotations

import dataclasses

import numpy as np

import dynslam2d.detect.tracker as tracker_mod
from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D


class _PredictFirst(Tracker):
    """The former order: ``cv_predict`` in ``_predict`` on every scan (never left to the association's kernel)."""

    def _predict(self, dt: float) -> None:
        super()._predict(dt)
        if self._predict_in_kernel:
            self._predict_in_kernel = False
            FQ = self._FQ
            tracker_mod.cv_predict(self._X, self._P, self._rows(), FQ[0], FQ[1])


def test_prediction_in_the_association_kernel_is_the_former_prediction() -> None:
    sim = simulate("crowd", duration=6.0, seed=4)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    new, ref = Tracker(DetectConfig()), _PredictFirst(DetectConfig())
    seen = {"in_kernel": 0, "without_association": 0, "scans": 0, "from_python": 0}
    former, former_cv = tracker_mod.associate_update, tracker_mod.cv_predict
    in_new = [False]

    def counted(*a):
        seen["in_kernel"] += bool(a[-1])
        return former(*a)

    def cv(*a):
        seen["from_python"] += in_new[0]
        return former_cv(*a)

    def new_update(*a):
        in_new[0] = True
        try:
            return Tracker.update(new, *a)
        finally:
            in_new[0] = False

    new.update = new_update
    tracker_mod.associate_update, tracker_mod.cv_predict = counted, cv
    try:
        for i, (scan, pose) in enumerate(zip(sim.scans, poses)):
            if i % 9 == 8:  # (no valid beam: no detection, the live tracks predicted without an association)
                scan = dataclasses.replace(scan, ranges=np.full_like(scan.ranges, np.nan))
                seen["without_association"] += new.n_tracks >= 2
            got, want = new.update(scan, pose), ref.update(scan, pose)
            assert not new._predict_in_kernel
            rows, rrows = new._rows(), ref._rows()
            assert rows.tobytes() == rrows.tobytes()
            assert new._X[rows].tobytes() == ref._X[rrows].tobytes()
            assert new._P[rows].tobytes() == ref._P[rrows].tobytes()
            assert [(r.id, r.state, r.velocity.tobytes(), r.covariance.tobytes(), r.m_reason) for r in got] == \
                [(r.id, r.state, r.velocity.tobytes(), r.covariance.tobytes(), r.m_reason) for r in want]
            seen["scans"] += 1
    finally:
        tracker_mod.associate_update, tracker_mod.cv_predict = former, former_cv
    # (cv_predict called from Python by the tracker's first prediction, then on the scans without an association: the
    # runs that record the kernels called from Python find it)
    assert seen["in_kernel"] > 50 and seen["without_association"] > 5, seen
    assert 1 + seen["without_association"] <= seen["from_python"] < seen["scans"] // 4, seen
