"""Kümmerle et al. 2009 relation metric: hand-made relations, and a CSAIL odometry smoke test."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.errors import DynSlamError
from dynslam2d.eval.relations import relation_errors, relation_errors_from
from dynslam2d.io.trajectory import Trajectory

HALF_PI = math.pi / 2

# Estimated trajectory: a unit square walked counter-clockwise, turning at each corner.
TRAJ = Trajectory(
    np.array([10.0, 10.5, 11.0, 11.5]),
    np.array([[0.0, 0.0, 0.0], [1.0, 0.0, HALF_PI], [1.0, 1.0, HALF_PI], [0.0, 1.0, math.pi]]),
)

# (t1, t2, dx, dy, dyaw) — reference relative poses x_t1⁻¹ ⊕ x_t2
RELATIONS = np.array(
    [
        # est 10.0→10.5 is (1, 0, π/2): reference off by 0.1 m in y and 0.05 rad
        [10.0, 10.5, 1.0, 0.1, HALF_PI + 0.05],
        # est 10.5→11.5: world displacement (-1, 1) seen from heading π/2 is (1, 1)
        [10.5, 11.5, 1.0, 1.0, HALF_PI],
        # stamps 0.4 ms off still match; dyaw given as π/2 − 2π must wrap to no error
        [10.0004, 11.0, 1.0, 1.0, HALF_PI - 2 * math.pi],
        # t2 < t1 (as in the Intel relations): the inverse relative pose
        [11.5, 10.5, -1.0, 1.0, -HALF_PI],
        # no pose at 12.0
        [12.0, 10.0, 0.0, 0.0, 0.0],
        # no pose at 10.25 (between two poses)
        [10.0, 10.25, 0.5, 0.0, 0.0],
    ]
)


def _run(rel: np.ndarray = RELATIONS, **kw: float):
    return relation_errors(TRAJ, rel[:, 0], rel[:, 1], rel[:, 2], rel[:, 3], rel[:, 4], **kw)


def test_hand_made_relations() -> None:
    r = _run()
    assert r.used.tolist() == [True, True, True, True, False, False]
    assert r.n_used == 4 and r.n_unmatched == 2
    assert r.unmatched_t1.tolist() == [False, False, False, False, True, False]
    assert r.unmatched_t2.tolist() == [False, False, False, False, False, True]
    assert r.trans_errors == pytest.approx([0.1, 0.0, 0.0, 0.0], abs=1e-12)
    assert r.rot_errors == pytest.approx([0.05, 0.0, 0.0, 0.0], abs=1e-12)
    # mean and population std of |Δt| = (0.1, 0, 0, 0)
    assert r.trans_mean == pytest.approx(0.025, abs=1e-12)
    assert r.trans_std == pytest.approx(math.sqrt((0.075**2 + 3 * 0.025**2) / 4), abs=1e-12)  # 0.043301
    assert r.trans_rmse == pytest.approx(0.05, abs=1e-12)
    assert r.trans.max == pytest.approx(0.1, abs=1e-12)
    assert r.rot_mean == pytest.approx(0.0125, abs=1e-12)
    assert r.rot_deg_mean == pytest.approx(math.degrees(0.0125), abs=1e-10)
    # squared errors (the paper's second table): mean of (0.01, 0, 0, 0)
    assert r.trans_sq.mean == pytest.approx(0.0025, abs=1e-12)
    assert r.rot_sq.mean == pytest.approx(0.0025 / 4, abs=1e-12)


def test_relation_in_the_world_frame_would_be_wrong() -> None:
    # Giving the world-frame displacement (-1, 1) instead of the t1-frame one (1, 1)
    # is an error of |(-1,1) − (1,1)| = 2 m: the convention matters.
    rel = np.array([[10.5, 11.5, -1.0, 1.0, HALF_PI]])
    assert _run(rel).trans_errors == pytest.approx([2.0], abs=1e-12)


def test_stamp_tolerance() -> None:
    r = _run(tol=1e-4)  # the 0.4 ms-off stamp no longer matches
    assert r.used.tolist() == [True, True, False, True, False, False]
    assert r.n_unmatched == 3


def test_from_any_object_with_the_fields() -> None:
    rel = SimpleNamespace(
        t1=RELATIONS[:, 0], t2=RELATIONS[:, 1], dx=RELATIONS[:, 2], dy=RELATIONS[:, 3], dyaw=RELATIONS[:, 4]
    )
    r = relation_errors_from(TRAJ, rel)
    assert r.n_used == 4
    assert r.trans_errors == pytest.approx([0.1, 0.0, 0.0, 0.0], abs=1e-12)
    with pytest.raises(DynSlamError, match="lacks a field"):
        relation_errors_from(TRAJ, SimpleNamespace(t1=[], t2=[]))


def test_errors() -> None:
    with pytest.raises(DynSlamError, match="none of the 1 relations"):
        relation_errors(TRAJ, [20.0], [21.0], [0.0], [0.0], [0.0])
    with pytest.raises(DynSlamError, match="same length"):
        relation_errors(TRAJ, [10.0, 10.5], [10.5], [0.0], [0.0], [0.0])
    with pytest.raises(DynSlamError, match="no relations"):
        relation_errors(TRAJ, [], [], [], [], [])
    with pytest.raises(DynSlamError, match="dx of relation 0 is not finite"):
        relation_errors(TRAJ, [10.0], [10.5], [np.nan], [0.0], [0.0])


def test_csail_odometry_against_the_published_relations() -> None:
    """Smoke test on real data: the raw odometry of mit-csail.clf scored with the
    1172 CSAIL relations. Odometry drifts, so its error must be finite and well
    above the 0.106 m that sequential scan matching reaches in Kümmerle et al.
    (measured here: 1.68 ± 5.29 m, max 23.0 m; 5.1 ± 8.2 deg)."""
    from dynslam2d.io.carmen import CarmenSource
    from dynslam2d.io.relations import read_relations

    src = CarmenSource(shared_file("mit-csail/mit-csail.clf"))
    records = [r for r in src.records() if r.odom is not None]
    traj = Trajectory(
        np.array([r.scan.stamp for r in records]),
        np.array([r.odom.as_array() for r in records]),
        frame="odom",
    )
    assert len(traj) == 1988
    rel = read_relations(shared_file("mit-csail/mit-csail.relations"))
    r = relation_errors_from(traj, rel)
    assert r.n_used == 1172 and r.n_unmatched == 0  # data README: all relations match at 1 ms
    assert np.all(np.isfinite(r.trans_errors)) and np.all(np.isfinite(r.rot_errors))
    assert 0.5 < r.trans_mean < 5.0
    assert r.trans.max > 5.0
    assert 1.0 < r.rot_deg_mean < 20.0
    # The relation convention x_t1⁻¹ ⊕ x_t2 fits odometry better than the reverse
    # (data README): swapping t1/t2 makes the error clearly larger.
    swapped = relation_errors(traj, rel.t2, rel.t1, rel.dx, rel.dy, rel.dyaw)
    assert swapped.trans_mean > 1.2 * r.trans_mean
