"""Relative-pose ("relations") metric of Kümmerle et al. 2009.

R. Kümmerle, B. Steder, C. Dornhege, M. Ruhnke, G. Grisetti, C. Stachniss,
A. Kleiner: "On measuring the accuracy of SLAM algorithms", Autonomous Robots
27(4):387–407, 2009. A relation (t1, t2, δ*) says that the robot's pose at t2,
expressed in its frame at t1, is δ* = x*_t1⁻¹ ⊕ x*_t2 = (dx, dy, dyaw)
(shared/data/README.md "Relations"). The paper's metric is

    ε(δ) = 1/N Σ_ij trans(δ_ij ⊖ δ*_ij)² + rot(δ_ij ⊖ δ*_ij)²

and its result tables report, per dataset, the translational and rotational
parts separately as mean ± standard deviation, both of the **absolute** error
and of the **squared** error (e.g. MIT CSAIL, sequential scan matching:
absolute translational error 0.106 ± 0.325 m, maximum 3.570 m).

What :func:`relation_errors` computes, per relation whose two stamps both have
a pose within ``tol``:

    est_rel = est(t1)⁻¹ ⊕ est(t2)
    e_trans = |est_rel.xy − (dx, dy)|                  (m)
    e_rot   = |wrap(est_rel.yaw − dyaw)|               (rad)

``e_trans`` is |trans(δ ⊖ δ*)| for δ ⊖ δ* = δ*⁻¹ ⊕ δ (a rotation does not change
a vector's length). Note that Cartographer's ``compute_relations_metrics``
instead takes the translation of (x_t1⁻¹ x_t2)·δ*⁻¹, which is
``t − R R*ᵀ t*`` and differs from ours when the rotational error is large.
Reported statistics: mean, population std (ddof=0; Cartographer uses n−1,
a factor sqrt(n/(n−1)) larger, 0.04 % at n = 1172), rmse, median, max, of the
absolute errors (``trans``, ``rot``) and of the squared errors (``trans_sq``
in m², ``rot_sq`` in rad²). The "Kümmerle number" to compare with the paper is
``trans.mean ± trans.std``; the paper gives rotations in degrees
(``rot_deg_mean``/``rot_deg_std``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.eval.trajectory import ErrorStats
from dynslam2d.stamps import nearest_sorted
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import wrap_angle

#: Default stamp tolerance, s: relation files give stamps to 1 µs and the
#: CSAIL relations all match scans of the .clf within 1 ms.
RELATION_STAMP_TOL_S = 1e-3


class RelationsLike(Protocol):
    """Anything with equal-length arrays t1, t2 (s), dx, dy (m), dyaw (rad)."""

    t1: np.ndarray
    t2: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dyaw: np.ndarray


@dataclass(frozen=True)
class RelationResult:
    """Errors of a trajectory against a set of relations.

    Attributes:
        trans: statistics of ``trans_errors`` (absolute translational error, m).
        rot: statistics of ``rot_errors`` (absolute rotational error, rad).
        trans_sq: statistics of ``trans_errors²`` (m²), the paper's squared error.
        rot_sq: statistics of ``rot_errors²`` (rad²).
        trans_errors: (n_used,) per-relation translational error, m.
        rot_errors: (n_used,) per-relation rotational error, rad.
        used: (N,) bool, True for the input relations that were evaluated
            (both stamps matched a pose within ``tol``); errors follow their order.
        unmatched_t1, unmatched_t2: (N,) bool, which end of each relation had no pose.
    """

    trans: ErrorStats
    rot: ErrorStats
    trans_sq: ErrorStats
    rot_sq: ErrorStats
    trans_errors: np.ndarray
    rot_errors: np.ndarray
    used: np.ndarray
    unmatched_t1: np.ndarray
    unmatched_t2: np.ndarray

    @property
    def n_used(self) -> int:
        return int(np.count_nonzero(self.used))

    @property
    def n_unmatched(self) -> int:
        return int(self.used.size - np.count_nonzero(self.used))

    @property
    def trans_mean(self) -> float:
        return self.trans.mean

    @property
    def trans_std(self) -> float:
        return self.trans.std

    @property
    def trans_rmse(self) -> float:
        return self.trans.rmse

    @property
    def rot_mean(self) -> float:
        return self.rot.mean

    @property
    def rot_std(self) -> float:
        return self.rot.std

    @property
    def rot_rmse(self) -> float:
        return self.rot.rmse

    @property
    def rot_deg_mean(self) -> float:
        return math.degrees(self.rot.mean)

    @property
    def rot_deg_std(self) -> float:
        return math.degrees(self.rot.std)


def relation_errors(
    traj: Trajectory,
    t1: np.ndarray,
    t2: np.ndarray,
    dx: np.ndarray,
    dy: np.ndarray,
    dyaw: np.ndarray,
    tol: float = RELATION_STAMP_TOL_S,
) -> RelationResult:
    """Kümmerle relation errors of ``traj`` (see the module docstring for the definition).

    Args:
        traj: the estimated trajectory (poses of the laser, m/rad).
        t1, t2: (N,) relation stamps, s (same clock as ``traj.stamps``).
        dx, dy, dyaw: (N,) reference relative pose x_t1⁻¹ ⊕ x_t2, m and rad.
        tol: a relation stamp matches the nearest trajectory stamp within ``tol`` s;
            relations with an unmatched end are left out and counted in
            ``n_unmatched``.

    Raises:
        DynSlamError: arrays of different lengths or non-finite values, an empty
            trajectory or relation set, or no relation with both ends matched.
    """
    arrs = [np.asarray(a, dtype=np.float64).reshape(-1) for a in (t1, t2, dx, dy, dyaw)]
    n = arrs[0].size
    if any(a.size != n for a in arrs):
        raise DynSlamError(
            "relations: t1, t2, dx, dy, dyaw must have the same length, got "
            + ", ".join(str(a.size) for a in arrs)
        )
    if n == 0:
        raise DynSlamError("relations: no relations given")
    for name, a in zip(("t1", "t2", "dx", "dy", "dyaw"), arrs):
        if not np.all(np.isfinite(a)):
            i = int(np.flatnonzero(~np.isfinite(a))[0])
            raise DynSlamError(f"relations: {name} of relation {i} is not finite ({a[i]})")
    if len(traj) == 0:
        raise DynSlamError("relations: the trajectory has no poses")
    if not (tol >= 0.0):
        raise DynSlamError(f"relations: tol must be >= 0 s, got {tol}")
    r_t1, r_t2, r_dx, r_dy, r_dyaw = arrs

    order = np.argsort(traj.stamps, kind="stable")
    stamps = traj.stamps[order]
    poses = traj.poses[order]
    k1, d1 = nearest_sorted(stamps, r_t1)
    ok1 = d1 <= tol
    k2, d2 = nearest_sorted(stamps, r_t2)
    ok2 = d2 <= tol
    used = ok1 & ok2
    if not np.any(used):
        raise DynSlamError(
            f"relations: none of the {n} relations has a pose within {tol} s at both stamps "
            f"(trajectory {stamps[0]:.6f}..{stamps[-1]:.6f} s, relations "
            f"{min(r_t1.min(), r_t2.min()):.6f}..{max(r_t1.max(), r_t2.max()):.6f} s)"
        )
    a = poses[k1[used]]
    b = poses[k2[used]]
    # est_rel = est(t1)⁻¹ ⊕ est(t2) (Kümmerle 2009, δ_ij; data README "Relations")
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    ddx = b[:, 0] - a[:, 0]
    ddy = b[:, 1] - a[:, 1]
    rel_x = c * ddx + s * ddy
    rel_y = -s * ddx + c * ddy
    rel_yaw = b[:, 2] - a[:, 2]
    e_t = np.hypot(rel_x - r_dx[used], rel_y - r_dy[used])
    e_r = np.abs(wrap_angle(rel_yaw - r_dyaw[used]))
    return RelationResult(
        trans=ErrorStats.of(e_t),
        rot=ErrorStats.of(e_r),
        trans_sq=ErrorStats.of(e_t * e_t),
        rot_sq=ErrorStats.of(e_r * e_r),
        trans_errors=e_t,
        rot_errors=e_r,
        used=used,
        unmatched_t1=~ok1,
        unmatched_t2=~ok2,
    )


def relation_errors_from(
    traj: Trajectory, relations: RelationsLike, tol: float = RELATION_STAMP_TOL_S
) -> RelationResult:
    """:func:`relation_errors` with the arrays taken from any object that has
    attributes ``t1, t2, dx, dy, dyaw`` (e.g. ``dynslam2d.io.relations.read_relations(path)``)."""
    try:
        fields = [getattr(relations, name) for name in ("t1", "t2", "dx", "dy", "dyaw")]
    except AttributeError as e:
        raise DynSlamError(f"relations object lacks a field: {e}") from None
    return relation_errors(traj, *fields, tol=tol)
