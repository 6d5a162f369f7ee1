"""ATE / RPE / association / SE(2) alignment, against hand-computed values and evo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.eval.trajectory import align_se2, associate, ate, rpe
from dynslam2d.io.trajectory import Trajectory
from dynslam2d.types import Pose2D


def _traj(poses: list[tuple[float, float, float]], t0: float = 0.0, dt: float = 1.0) -> Trajectory:
    return Trajectory(t0 + dt * np.arange(len(poses), dtype=float), np.array(poses, dtype=float))


def _moved(G: Pose2D, traj: Trajectory) -> Trajectory:
    """G ⊕ every pose: the same trajectory seen from another map frame."""
    return Trajectory(
        traj.stamps.copy(),
        np.array([G.compose(traj.pose(i)).as_array() for i in range(len(traj))]),
    )


REF4 = _traj([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, math.pi / 2), (0.0, 2.0, math.pi)])


# --------------------------------------------------------------------------- alignment / ATE


def test_rigidly_moved_trajectory_has_zero_ate_and_recovers_inverse_transform() -> None:
    G = Pose2D(2.0, -1.0, 0.5)
    est = _moved(G, REF4)
    res = ate(REF4, est, align=True)
    assert res.n == 4
    assert res.rmse < 1e-12 and res.max < 1e-12
    assert res.rot.max < 1e-12
    inv = G.inverse()
    assert res.alignment.x == pytest.approx(inv.x, abs=1e-12)
    assert res.alignment.y == pytest.approx(inv.y, abs=1e-12)
    assert res.alignment.theta == pytest.approx(inv.theta, abs=1e-12)
    # without alignment the same pair is far off: pose 0 alone is |(2, -1)| away
    assert ate(REF4, est, align=False).errors[0] == pytest.approx(math.sqrt(5.0))


def test_constant_offset_without_alignment_is_the_offset() -> None:
    est = Trajectory(REF4.stamps, REF4.poses + np.array([0.3, 0.4, 0.0]))
    res = ate(REF4, est, align=False)
    assert res.errors == pytest.approx([0.5] * 4, abs=1e-12)
    assert res.rmse == pytest.approx(0.5) and res.mean == pytest.approx(0.5)
    assert res.std == pytest.approx(0.0, abs=1e-12)
    assert res.alignment == Pose2D()
    # aligned, a pure offset disappears, and the alignment is (-0.3, -0.4, 0)
    al = ate(REF4, est, align=True)
    assert al.rmse < 1e-12
    assert (al.alignment.x, al.alignment.y) == pytest.approx((-0.3, -0.4), abs=1e-12)
    assert al.alignment.theta == pytest.approx(0.0, abs=1e-12)


def test_three_pose_ate_by_hand_without_alignment() -> None:
    ref = _traj([(0, 0, 0), (1, 0, 0), (2, 0, 0)])
    est = _traj([(0, 0.1, 0), (1, -0.2, 0), (2, 0.2, 0)])
    res = ate(ref, est, align=False)
    # errors 0.1, 0.2, 0.2
    assert res.rmse == pytest.approx(math.sqrt((0.01 + 0.04 + 0.04) / 3), abs=1e-12)  # 0.173205
    assert res.mean == pytest.approx(0.5 / 3, abs=1e-12)
    assert res.median == pytest.approx(0.2, abs=1e-12)
    assert res.max == pytest.approx(0.2, abs=1e-12) and res.min == pytest.approx(0.1, abs=1e-12)
    # population std: deviations -1/15, 1/30, 1/30
    assert res.std == pytest.approx(math.sqrt((1 / 225 + 2 / 900) / 3), abs=1e-12)  # 0.047140


def test_three_pose_ate_by_hand_with_alignment() -> None:
    # Offsets (+0.1, -0.2, +0.1) in y are symmetric about the centroid: the best
    # rigid fit is the identity, so the aligned errors stay 0.1, 0.2, 0.1.
    ref = _traj([(0, 0, 0), (1, 0, 0), (2, 0, 0)])
    est = _traj([(0, 0.1, 0), (1, -0.2, 0), (2, 0.1, 0)])
    res = ate(ref, est, align=True)
    assert res.alignment.theta == pytest.approx(0.0, abs=1e-12)
    assert (res.alignment.x, res.alignment.y) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert res.rmse == pytest.approx(math.sqrt(0.06 / 3), abs=1e-12)  # 0.141421


def test_alignment_rotates_when_it_should() -> None:
    # est = reference square rotated by 0.2 rad about its centre and scaled by 1.1:
    # the best rigid fit undoes the rotation, and each corner is left 0.1·√2 off.
    sq = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]) + [5.0, 3.0]
    R = Pose2D(0.0, 0.0, 0.2)
    est_xy = R.transform_points((sq - [5.0, 3.0]) * 1.1) + [5.0, 3.0]
    T = align_se2(sq, est_xy)
    assert T.theta == pytest.approx(-0.2, abs=1e-12)
    err = np.linalg.norm(T.transform_points(est_xy) - sq, axis=1)
    assert err == pytest.approx([0.1 * math.sqrt(2)] * 4, abs=1e-12)


def test_align_se2_is_a_least_squares_minimum() -> None:
    i = np.arange(20, dtype=float)
    ref = np.column_stack((np.cos(0.3 * i) * i * 0.1, np.sin(0.5 * i)))
    est = Pose2D(-3.0, 2.0, 2.5).transform_points(ref) + 0.05 * np.column_stack((np.sin(3 * i), np.cos(7 * i)))
    T = align_se2(ref, est)

    def cost(p: Pose2D) -> float:
        return float(np.sum((ref - p.transform_points(est)) ** 2))

    c0 = cost(T)
    for d in (1e-4, -1e-4):
        assert cost(Pose2D(T.x + d, T.y, T.theta)) > c0
        assert cost(Pose2D(T.x, T.y + d, T.theta)) > c0
        assert cost(Pose2D(T.x, T.y, T.theta + d)) > c0
    assert T.theta == pytest.approx(-2.5, abs=0.05)


def test_align_se2_rejects_bad_input() -> None:
    with pytest.raises(DynSlamError):
        align_se2(np.zeros((3, 2)), np.zeros((2, 2)))
    with pytest.raises(DynSlamError):
        align_se2(np.zeros((0, 2)), np.zeros((0, 2)))


# --------------------------------------------------------------------------- association


def test_associate_nearest_within_max_dt() -> None:
    ref = Trajectory(np.array([0.0, 1.0, 2.0, 3.0]), np.zeros((4, 3)))
    est = Trajectory(np.array([0.005, 1.02, 2.0, 2.999, 10.0]), np.zeros((5, 3)))
    i_ref, i_est = associate(ref, est, max_dt=0.01)
    assert i_ref.tolist() == [0, 2, 3]
    assert i_est.tolist() == [0, 2, 3]
    # a looser window takes 1.02 too
    assert associate(ref, est, max_dt=0.05)[0].tolist() == [0, 1, 2, 3]
    # offset is added to the estimate's stamps (evo --t_offset)
    assert associate(ref, est, max_dt=0.01, offset=-0.02)[0].tolist() == [1]


def test_associate_ties_pick_the_earlier_and_unsorted_is_fine() -> None:
    ref = Trajectory(np.array([1.0]), np.zeros((1, 3)))
    est = Trajectory(np.array([1.25, 0.75]), np.zeros((2, 3)))
    i_ref, i_est = associate(ref, est, max_dt=0.5)
    assert i_ref.tolist() == [0] and i_est.tolist() == [1]  # 0.75 is earlier


def test_associate_nothing_matches_is_a_clear_error() -> None:
    ref = Trajectory(np.array([0.0, 1.0]), np.zeros((2, 3)))
    est = Trajectory(np.array([100.0, 101.0]), np.zeros((2, 3)))
    with pytest.raises(DynSlamError, match="no matching stamps.*max_dt = 0.01"):
        ate(ref, est)


# --------------------------------------------------------------------------- RPE

# Reference relative motions between consecutive poses, and the estimate's.
REF_STEPS = [Pose2D(1, 0, 0), Pose2D(1, 0, math.pi / 2), Pose2D(1, 0, 0)]
EST_STEPS = [Pose2D(1.1, 0, 0), Pose2D(1, 0.1, math.pi / 2 + 0.05), Pose2D(1, 0, 0)]


def _chain(steps: list[Pose2D], start: Pose2D = Pose2D()) -> Trajectory:
    poses = [start]
    for s in steps:
        poses.append(poses[-1].compose(s))
    return Trajectory.from_poses(np.arange(len(poses), dtype=float), poses)


def test_rpe_consecutive_frames_by_hand() -> None:
    ref, est = _chain(REF_STEPS), _chain(EST_STEPS)
    res = rpe(ref, est, delta=1)
    # per pair: translation 0.1, 0.1, 0; rotation 0, 0.05, 0
    assert res.trans_errors == pytest.approx([0.1, 0.1, 0.0], abs=1e-12)
    assert res.rot_errors == pytest.approx([0.0, 0.05, 0.0], abs=1e-12)
    assert res.trans_rmse == pytest.approx(math.sqrt(0.02 / 3), abs=1e-12)  # 0.081650
    assert res.trans_mean == pytest.approx(0.2 / 3, abs=1e-12)
    assert res.rot_rmse == pytest.approx(math.sqrt(0.0025 / 3), abs=1e-12)  # 0.028868
    assert res.rot_mean == pytest.approx(0.05 / 3, abs=1e-12)
    assert res.pairs.tolist() == [[0, 1], [1, 2], [2, 3]]
    assert res.stamp_pairs.tolist() == [[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]]


def test_rpe_delta_two_consecutive_and_all_pairs_by_hand() -> None:
    ref, est = _chain(REF_STEPS), _chain(EST_STEPS)
    # consecutive, Δ = 2: ids 0, 2 → one pair (0, 2):
    # ref 0→2 = (2, 0, π/2), est 0→2 = (2.1, 0.1, π/2 + 0.05)
    r = rpe(ref, est, delta=2)
    assert r.pairs.tolist() == [[0, 2]]
    assert r.trans_errors == pytest.approx([math.hypot(0.1, 0.1)], abs=1e-12)
    assert r.rot_errors == pytest.approx([0.05], abs=1e-12)
    # all pairs, Δ = 2: (0, 2) and (1, 3); ref 1→3 = (1, 1, π/2),
    # est 1→3 = (1 − sin 0.05, 0.1 + cos 0.05, π/2 + 0.05)
    a = rpe(ref, est, delta=2, all_pairs=True)
    assert a.pairs.tolist() == [[0, 2], [1, 3]]
    e13 = math.hypot(-math.sin(0.05), 0.1 + math.cos(0.05) - 1.0)  # 0.110677
    assert a.trans_errors == pytest.approx([math.hypot(0.1, 0.1), e13], abs=1e-12)
    assert a.rot_errors == pytest.approx([0.05, 0.05], abs=1e-12)


def test_rpe_is_invariant_to_a_rigid_move_of_the_estimate() -> None:
    ref, est = _chain(REF_STEPS), _chain(EST_STEPS)
    moved = _moved(Pose2D(10.0, -4.0, 2.0), est)
    a, b = rpe(ref, est), rpe(ref, moved)
    assert b.trans_errors == pytest.approx(a.trans_errors, abs=1e-12)
    assert b.rot_errors == pytest.approx(a.rot_errors, abs=1e-12)


def test_rpe_delta_in_metres() -> None:
    # straight line, 0.5 m steps in the reference, 0.54 m in the estimate (8 % scale error).
    n = 7
    ref = _traj([(0.5 * i, 0.0, 0.0) for i in range(n)])
    est = _traj([(0.54 * i, 0.0, 0.0) for i in range(n)])
    r = rpe(ref, est, delta=1.0, delta_unit="m")
    # path along the estimate: marks at 0, 2 (1.08 m), 4, 6 → pairs (0,2), (2,4), (4,6)
    assert r.pairs.tolist() == [[0, 2], [2, 4], [4, 6]]
    assert r.trans_errors == pytest.approx([0.08, 0.08, 0.08], abs=1e-12)
    # pairs from the reference path instead: same marks here (1.0 m ≥ 1.0 m)
    assert rpe(ref, est, delta=1.0, delta_unit="m", pairs_from_reference=True).pairs.tolist() == [
        [0, 2], [2, 4], [4, 6]]
    # all pairs within 10 %: j with path from i nearest 1.0 m (1.08 m, two steps), for i = 0..4
    a = rpe(ref, est, delta=1.0, delta_unit="m", all_pairs=True)
    assert a.pairs.tolist() == [[i, i + 2] for i in range(5)]
    # a 5 % tolerance rejects 1.08 m (and 0.54 m): no pair at all
    with pytest.raises(DynSlamError, match="no pose pair"):
        rpe(ref, est, delta=1.0, delta_unit="m", all_pairs=True, rel_delta_tol=0.05)


def test_rpe_errors() -> None:
    ref, est = _chain(REF_STEPS), _chain(EST_STEPS)
    with pytest.raises(DynSlamError, match="no pose pair"):
        rpe(ref, est, delta=10)
    with pytest.raises(DynSlamError, match="positive integer"):
        rpe(ref, est, delta=1.5)
    with pytest.raises(DynSlamError, match="delta_unit"):
        rpe(ref, est, delta=1, delta_unit="s")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- cross-check with evo


def _golden_pair() -> tuple[Trajectory, Trajectory]:
    """A deterministic 60-pose reference and a moved, perturbed estimate with
    jittered stamps (±3 ms) and every 7th pose dropped."""
    i = np.arange(60, dtype=float)
    t = 1000.0 + 0.1 * i
    ref = np.column_stack(
        (2 * np.cos(0.1 * i) + 0.05 * i, np.sin(0.13 * i), 0.2 * np.sin(0.07 * i) + 0.05 * i)
    )
    noisy = ref + np.column_stack((0.03 * np.sin(1.7 * i), 0.02 * np.cos(2.3 * i), 0.01 * np.sin(0.9 * i)))
    G = Pose2D(1.5, -0.7, 0.4)
    est = np.array([G.compose(Pose2D.from_array(p)).as_array() for p in noisy])
    keep = (np.arange(60) % 7) != 3
    return Trajectory(t, ref), Trajectory((t + 0.003 * np.sin(i))[keep], est[keep])


def test_matches_evo_numbers() -> None:
    """Expected values computed with evo 1.38.1 on the same data written as TUM
    (write_tum), via sync.associate_trajectories(max_diff=0.01), traj.align
    (SE(3) Umeyama, no scale), metrics.APE / metrics.RPE."""
    ref, est = _golden_pair()
    a = ate(ref, est)
    assert a.n == 51
    assert a.rmse == pytest.approx(0.025274410235641552, abs=1e-9)
    assert a.mean == pytest.approx(0.024055888543488262, abs=1e-9)
    assert a.median == pytest.approx(0.025933284525982217, abs=1e-9)
    assert a.std == pytest.approx(0.007753066434822605, abs=1e-9)
    assert a.max == pytest.approx(0.036030775444282834, abs=1e-9)
    assert a.rot.rmse == pytest.approx(0.00748563876126456, abs=1e-9)  # APE angle_rad
    r1 = rpe(ref, est, delta=1)
    assert r1.n == 50
    assert r1.trans_rmse == pytest.approx(0.04183661064815324, abs=1e-9)
    assert r1.trans_mean == pytest.approx(0.039795388412425144, abs=1e-9)
    assert r1.rot_rmse == pytest.approx(0.00773328419224155, abs=1e-9)
    assert r1.rot_mean == pytest.approx(0.006412803027833864, abs=1e-9)
    r3 = rpe(ref, est, delta=3, all_pairs=True)
    assert r3.n == 48
    assert r3.trans_rmse == pytest.approx(0.02783635275566048, abs=1e-9)
    assert r3.rot_mean == pytest.approx(0.01353555888739775, abs=1e-9)
    rm = rpe(ref, est, delta=1.0, delta_unit="m")
    assert rm.n == 8
    assert rm.trans_rmse == pytest.approx(0.03633139686323901, abs=1e-9)
    assert rm.rot_rmse == pytest.approx(0.010266406588495576, abs=1e-9)
