"""Trajectory metrics, as evo defines them, for planar trajectories.

* :func:`associate` — nearest-stamp association (evo ``--t_max_diff``).
* :func:`align_se2` — the rigid 2D transform that best maps estimate onto
  reference (Umeyama 1991 without scale, restricted to the plane).
* :func:`ate` — absolute pose (trajectory) error, translation part
  (``evo_ape tum ref est -a``), plus the heading error.
* :func:`rpe` — relative pose error over ``delta`` frames or metres
  (``evo_rpe tum ref est --delta D --delta_unit f|m [--all_pairs]``).

Definitions follow evo 1.x (``evo/core/metrics.py``, ``filters.py``, ``sync.py``;
Grupp, MichaelGrupp/evo, 2017). Units: m and rad; statistics use the population standard
deviation (``numpy.std``, ddof=0), as evo does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.stamps import match_nearest
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import Pose2D, wrap_angle

DeltaUnit = Literal["frames", "m"]


@dataclass(frozen=True)
class ErrorStats:
    """Summary of a non-negative error array (evo's statistics set).

    ``rmse = sqrt(mean(e²))``, ``sse = Σ e²``, ``std`` is the population standard
    deviation (ddof=0). Units are those of the errors.
    """

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    n: int

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            raise DynSlamError("no errors to summarise (empty selection)")
        sq = e * e
        return cls(
            rmse=math.sqrt(float(np.mean(sq))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
            sse=float(np.sum(sq)),
            n=int(e.size),
        )

    def as_dict(self) -> dict[str, float | int]:
        return {
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "std": self.std,
            "min": self.min,
            "max": self.max,
            "sse": self.sse,
            "n": self.n,
        }


# --------------------------------------------------------------------------- association


def associate(
    ref: Trajectory, est: Trajectory, max_dt: float = 0.01, offset: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pair poses of ``ref`` and ``est`` by nearest stamp, as evo's ``associate_trajectories``.

    For every stamp of the *shorter* trajectory (``est`` when both have the same
    length) the nearest stamp of the other one is taken (ties: the earlier one),
    and the pair is kept when ``|Δt| <= max_dt`` (s). ``offset`` (s) is added to
    ``est``'s stamps first (evo ``--t_offset``). As in evo, a pose of the longer
    trajectory may be used by more than one pair.

    Returns:
        (i_ref, i_est): equal-length int arrays of indices into ``ref`` and
        ``est``, in the order of the shorter trajectory.

    Raises:
        DynSlamError: if either trajectory is empty or no pair is within ``max_dt``.
    """
    if len(ref) == 0 or len(est) == 0:
        raise DynSlamError(
            f"cannot associate trajectories: reference has {len(ref)} poses, estimate {len(est)}"
        )
    if not (max_dt >= 0.0):
        raise DynSlamError(f"max_dt must be >= 0 s, got {max_dt}")
    est_stamps = est.stamps + offset
    est_longer = len(est) > len(ref)
    short, long_ = (ref.stamps, est_stamps) if est_longer else (est_stamps, ref.stamps)
    i_short, i_long = match_nearest(short, long_, max_dt)
    if i_short.size == 0:
        raise DynSlamError(
            f"no matching stamps between reference ({len(ref)} poses, "
            f"{ref.stamps.min():.6f}..{ref.stamps.max():.6f} s) and estimate ({len(est)} poses, "
            f"{est_stamps.min():.6f}..{est_stamps.max():.6f} s) within max_dt = {max_dt} s"
        )
    return (i_short, i_long) if est_longer else (i_long, i_short)


# --------------------------------------------------------------------------- alignment


def align_se2(ref_xy: np.ndarray, est_xy: np.ndarray) -> Pose2D:
    """The rigid transform ``T`` (no scale) minimising ``Σ |ref_i − T·est_i|²``.

    Umeyama (1991) / Kabsch in 2D, closed form: with centred points ``r', e'``,
    ``θ = atan2(Σ e'x·r'y − e'y·r'x, Σ e'x·r'x + e'y·r'y)`` and
    ``t = mean(ref) − R(θ)·mean(est)``. Always a proper rotation (evo's SE(3)
    Umeyama on z = 0 data may pick an in-plane reflection for degenerate data;
    this never does). With one point (or all points coincident) θ = 0.

    Args:
        ref_xy, est_xy: (n, 2) associated positions, m.

    Returns:
        ``T`` as a :class:`Pose2D`; ``T.transform_points(est_xy)`` is the aligned estimate.
    """
    r = np.asarray(ref_xy, dtype=np.float64)
    e = np.asarray(est_xy, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 2 or r.shape != e.shape:
        raise DynSlamError(f"align_se2: need two (n, 2) arrays of equal shape, got {r.shape} and {e.shape}")
    if r.shape[0] == 0:
        raise DynSlamError("align_se2: no points to align")
    mr = r.mean(axis=0)
    me = e.mean(axis=0)
    rc = r - mr
    ec = e - me
    # Umeyama 1991 Eq. 40 specialised to 2D: maximise trace(R^T Σ r' e'^T).
    s = float(np.sum(ec[:, 0] * rc[:, 1] - ec[:, 1] * rc[:, 0]))
    c = float(np.sum(ec[:, 0] * rc[:, 0] + ec[:, 1] * rc[:, 1]))
    theta = math.atan2(s, c)
    ct, st = math.cos(theta), math.sin(theta)
    tx = mr[0] - (ct * me[0] - st * me[1])
    ty = mr[1] - (st * me[0] + ct * me[1])
    return Pose2D(float(tx), float(ty), theta)


def _apply(T: Pose2D, poses: np.ndarray) -> np.ndarray:
    """Left-multiply (n, 3) poses by T (T ⊕ p for each p)."""
    out = np.empty_like(poses)
    out[:, :2] = T.transform_points(poses[:, :2])
    out[:, 2] = wrap_angle(poses[:, 2] + T.theta)
    return out


# --------------------------------------------------------------------------- APE / ATE


@dataclass(frozen=True)
class AteResult:
    """Absolute trajectory error of an estimate against a reference.

    Attributes:
        trans: statistics of ``errors`` (m) — evo APE "translation part".
        rot: statistics of ``rot_errors`` (rad) — evo APE "angle_rad" in 2D.
        alignment: the transform applied to the estimate (identity without alignment):
            aligned = alignment ⊕ est.
        errors: (n,) |aligned est xy − ref xy| per associated pose, m.
        rot_errors: (n,) |wrap(aligned est yaw − ref yaw)|, rad.
        stamps: (n,) reference stamps of the associated poses, s.
        aligned: the associated, aligned estimate (stamps of the estimate).
    """

    trans: ErrorStats
    rot: ErrorStats
    alignment: Pose2D
    errors: np.ndarray
    rot_errors: np.ndarray
    stamps: np.ndarray
    aligned: Trajectory

    @property
    def rmse(self) -> float:
        return self.trans.rmse

    @property
    def mean(self) -> float:
        return self.trans.mean

    @property
    def median(self) -> float:
        return self.trans.median

    @property
    def std(self) -> float:
        return self.trans.std

    @property
    def max(self) -> float:
        return self.trans.max

    @property
    def min(self) -> float:
        return self.trans.min

    @property
    def n(self) -> int:
        return self.trans.n


def ate(
    ref: Trajectory,
    est: Trajectory,
    *,
    align: bool = True,
    max_dt: float = 0.01,
    offset: float = 0.0,
) -> AteResult:
    """Absolute trajectory error (evo APE, translation part), in the plane.

    Steps (as ``evo_ape tum ref est [-a] --t_max_diff max_dt``): associate by
    stamp (:func:`associate`); if ``align``, find ``T = align_se2(ref_xy, est_xy)``
    over all associated poses and replace every estimated pose ``P_i`` by
    ``T ⊕ P_i``; the per-pose error is ``e_i = |trans(P_i) − trans(Q_i)|`` (m).
    ``rmse = sqrt(mean(e²))`` is the usual "ATE".
    """
    i_ref, i_est = associate(ref, est, max_dt=max_dt, offset=offset)
    q = ref.poses[i_ref]
    p = est.poses[i_est]
    T = align_se2(q[:, :2], p[:, :2]) if align else Pose2D()
    pa = _apply(T, p) if align else p.copy()
    errors = np.hypot(pa[:, 0] - q[:, 0], pa[:, 1] - q[:, 1])
    rot_errors = np.abs(wrap_angle(pa[:, 2] - q[:, 2]))
    return AteResult(
        trans=ErrorStats.of(errors),
        rot=ErrorStats.of(rot_errors),
        alignment=T,
        errors=errors,
        rot_errors=rot_errors,
        stamps=ref.stamps[i_ref].copy(),
        aligned=Trajectory(est.stamps[i_est], pa, ref.frame),
    )


# --------------------------------------------------------------------------- RPE


@dataclass(frozen=True)
class RpeResult:
    """Relative pose error over pose pairs (i, j).

    Attributes:
        trans: statistics of ``trans_errors`` (m) — evo RPE "translation part".
        rot: statistics of ``rot_errors`` (rad) — evo RPE "angle_rad".
        trans_errors: (k,) |trans(E_ij)| per pair, m.
        rot_errors: (k,) |angle(E_ij)| per pair, rad.
        pairs: (k, 2) indices (i, j) into the *associated* pose lists.
        stamp_pairs: (k, 2) reference stamps of i and j, s.
        delta, delta_unit, all_pairs: how the pairs were chosen.
    """

    trans: ErrorStats
    rot: ErrorStats
    trans_errors: np.ndarray
    rot_errors: np.ndarray
    pairs: np.ndarray
    stamp_pairs: np.ndarray
    delta: float
    delta_unit: str
    all_pairs: bool

    @property
    def trans_rmse(self) -> float:
        return self.trans.rmse

    @property
    def trans_mean(self) -> float:
        return self.trans.mean

    @property
    def rot_rmse(self) -> float:
        return self.rot.rmse

    @property
    def rot_mean(self) -> float:
        return self.rot.mean

    @property
    def n(self) -> int:
        return self.trans.n


def rpe(
    ref: Trajectory,
    est: Trajectory,
    *,
    delta: float = 1,
    delta_unit: DeltaUnit = "frames",
    all_pairs: bool = False,
    max_dt: float = 0.01,
    offset: float = 0.0,
    rel_delta_tol: float = 0.1,
    pairs_from_reference: bool = False,
) -> RpeResult:
    """Relative pose error (evo RPE), in the plane.

    After association (:func:`associate`), for each pair (i, j):
    ``Q_rel = Q_i⁻¹ ⊕ Q_j`` (reference), ``P_rel = P_i⁻¹ ⊕ P_j`` (estimate),
    ``E = Q_rel⁻¹ ⊕ P_rel``; translation error ``|trans(E)| = |t(P_rel) − t(Q_rel)|``
    (m), rotation error ``|angle(E)| = |wrap(θ(P_rel) − θ(Q_rel))|`` (rad).
    A rigid alignment of the estimate does not change these, so there is none.

    Pairs (evo ``filters.id_pairs_from_delta``):

    * ``delta_unit="frames"``: consecutive pairs ``(0, Δ), (Δ, 2Δ), …``; with
      ``all_pairs``, every ``(i, i + Δ)``.
    * ``delta_unit="m"`` (path length along the estimate, or the reference with
      ``pairs_from_reference``): consecutive — mark pose 0, walk the path and
      mark a pose each time the distance travelled since the last mark reaches
      ``Δ``, pair successive marks; with ``all_pairs`` — for each i, the j > i
      whose path length from i is nearest Δ (the first such j), kept when within
      ``Δ·rel_delta_tol``. (evo 1.38 ``filter_pairs_by_path``.)

    Raises:
        DynSlamError: bad ``delta``/``delta_unit``, or no pair could be formed.
    """
    if delta_unit == "frames":
        if not float(delta).is_integer() or delta < 1:
            raise DynSlamError(f"RPE delta must be a positive integer number of frames, got {delta}")
    elif delta_unit == "m":
        if not (delta > 0.0) or not math.isfinite(delta):
            raise DynSlamError(f"RPE delta must be a positive distance in m, got {delta}")
    else:
        raise DynSlamError(f"RPE delta_unit must be 'frames' or 'm', got {delta_unit!r}")
    i_ref, i_est = associate(ref, est, max_dt=max_dt, offset=offset)
    q = ref.poses[i_ref]
    p = est.poses[i_est]
    n = q.shape[0]
    if delta_unit == "frames":
        d = int(delta)
        if all_pairs:
            i = np.arange(0, max(n - d, 0))
            pairs = np.column_stack((i, i + d))
        else:
            ids = np.arange(0, n, d)
            pairs = np.column_stack((ids[:-1], ids[1:]))
    else:
        base = q if pairs_from_reference else p
        pairs = _pairs_by_path(base[:, :2], float(delta), float(delta) * rel_delta_tol, all_pairs)
    pairs = pairs.reshape(-1, 2).astype(np.intp)
    if pairs.shape[0] == 0:
        raise DynSlamError(
            f"RPE: delta = {delta} ({delta_unit}) gives no pose pair among {n} associated poses; "
            "use a smaller delta"
        )
    qi, qj = q[pairs[:, 0]], q[pairs[:, 1]]
    pi, pj = p[pairs[:, 0]], p[pairs[:, 1]]
    q_rel = _between(qi, qj)
    p_rel = _between(pi, pj)
    trans_errors = np.hypot(p_rel[:, 0] - q_rel[:, 0], p_rel[:, 1] - q_rel[:, 1])
    rot_errors = np.abs(wrap_angle(p_rel[:, 2] - q_rel[:, 2]))
    stamps = ref.stamps[i_ref]
    return RpeResult(
        trans=ErrorStats.of(trans_errors),
        rot=ErrorStats.of(rot_errors),
        trans_errors=trans_errors,
        rot_errors=rot_errors,
        pairs=pairs,
        stamp_pairs=np.column_stack((stamps[pairs[:, 0]], stamps[pairs[:, 1]])),
        delta=float(delta),
        delta_unit=delta_unit,
        all_pairs=all_pairs,
    )


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a⁻¹ ⊕ b`` for (k, 3) pose arrays [x, y, yaw]."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx = b[:, 0] - a[:, 0]
    dy = b[:, 1] - a[:, 1]
    out = np.empty_like(a)
    out[:, 0] = c * dx + s * dy
    out[:, 1] = -s * dx + c * dy
    out[:, 2] = wrap_angle(b[:, 2] - a[:, 2])
    return out


def _pairs_by_path(xy: np.ndarray, delta: float, tol: float, all_pairs: bool) -> np.ndarray:
    """evo ``filter_pairs_by_path`` (evo 1.38) on (n, 2) positions (see :func:`rpe`)."""
    steps = np.linalg.norm(xy[:-1] - xy[1:], axis=1)
    if all_pairs:
        cum = np.concatenate(([0.0], np.cumsum(steps)))
        out = []
        for i in range(cum.size - 1):
            from_here = cum[i + 1 :] - cum[i]
            k = int(np.argmin(np.abs(from_here - delta)))  # first of equally near
            if abs(from_here[k] - delta) <= tol:
                out.append((i, i + 1 + k))
        return np.array(out, dtype=np.intp).reshape(-1, 2)
    ids = [0]
    current = 0.0
    for i in range(1, xy.shape[0]):
        current += float(steps[i - 1])
        if current >= delta:
            ids.append(i)
            current = 0.0
    a = np.array(ids, dtype=np.intp)
    return np.column_stack((a[:-1], a[1:]))
