"""Point-to-line ICP in 2D (Censi, "An ICP variant using a point-to-line metric", ICRA 2008).

A reference cloud of points (m, one frame, e.g. the map frame) gets a unit normal per point from
the principal axes of its ``k`` nearest neighbours (:func:`line_cloud`); points whose neighbourhood
is not a thin line (a corner, clutter, a lone point) carry no normal and never take part. A scan's
points (m, laser frame) are then registered to it by Gauss–Newton on the point-to-line residuals

    r_i = n_jᵀ (R(θ) p_i + t − q_j),     q_j the nearest reference point to R(θ) p_i + t,

with robust Cauchy weights w_i = 1 / (1 + (r_i / k)²) (iteratively reweighted least squares) and
correspondences farther than ``max_distance`` dropped (:func:`register`). The Jacobian of r_i with
respect to (tx, ty, θ) is (n_x, n_y, n_jᵀ R'(θ) p_i).

Units: metres and radians throughout; poses are (x, y, θ) of the scan's frame in the cloud's frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: Smallest number of correspondences a registration step needs.
MIN_CORRESPONDENCES = 10


@dataclass(slots=True)
class LineCloud:
    """Reference points with line normals (see :func:`line_cloud`).

    Attributes:
        points: (n, 2) reference points, m.
        normals: (n, 2) unit normals of the local line through each point (0 where ``usable`` is False).
        usable: (n,) the point's neighbourhood is a line (it can anchor a point-to-line residual).
        tree: k-d tree over ``points``.
    """

    points: np.ndarray
    normals: np.ndarray
    usable: np.ndarray
    tree: cKDTree

    def __len__(self) -> int:
        return int(self.points.shape[0])


def line_cloud(points: np.ndarray, k: int = 10, max_thickness: float = 0.02, min_elongation: float = 4.0) -> LineCloud:
    """Normals of a 2D point cloud ``points`` (n, 2, m) from its ``k`` nearest neighbours (PCA).

    A point's normal is the eigenvector of the smallest eigenvalue of its neighbourhood's covariance.
    The point is ``usable`` when that neighbourhood is a thin line: standard deviation across the line
    ≤ ``max_thickness`` (m) and variance along it ≥ ``min_elongation`` × the variance across.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    tree = cKDTree(pts)
    if n < max(k, 2):
        return LineCloud(pts, np.zeros((n, 2)), np.zeros(n, dtype=bool), tree)
    _, idx = tree.query(pts, k=k)
    nb = pts[idx]  # (n, k, 2)
    d = nb - nb.mean(axis=1, keepdims=True)
    sxx = np.einsum("nk,nk->n", d[:, :, 0], d[:, :, 0]) / k
    syy = np.einsum("nk,nk->n", d[:, :, 1], d[:, :, 1]) / k
    sxy = np.einsum("nk,nk->n", d[:, :, 0], d[:, :, 1]) / k
    # closed-form eigen-decomposition of the 2×2 covariance
    half_tr = 0.5 * (sxx + syy)
    disc = np.sqrt(np.maximum(0.25 * (sxx - syy) ** 2 + sxy * sxy, 0.0))
    lo = half_tr - disc
    hi = half_tr + disc
    # eigenvector of the smallest eigenvalue: (sxy, lo − sxx), or an axis when sxy = 0
    nx = np.where(np.abs(sxy) > 1e-15, sxy, np.where(sxx <= syy, 1.0, 0.0))
    ny = np.where(np.abs(sxy) > 1e-15, lo - sxx, np.where(sxx <= syy, 0.0, 1.0))
    norm = np.hypot(nx, ny)
    ok = (norm > 0.0) & (lo <= max_thickness**2) & (hi >= min_elongation * np.maximum(lo, 0.0)) & (hi > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = np.where(ok[:, None], np.column_stack((nx, ny)) / norm[:, None], 0.0)
    return LineCloud(pts, normals, ok, tree)


@dataclass(slots=True)
class Registration:
    """Result of :func:`register`.

    Attributes:
        pose: (3,) (x m, y m, θ rad) of the scan in the cloud's frame after the last step.
        converged: the last step was below the tolerances within ``max_iterations``.
        iterations: Gauss–Newton steps taken.
        inliers: fraction of the scan's points with a usable correspondence at ``pose`` (0 … 1).
        rms: weighted RMS of the point-to-line residuals at the last step, m.
        min_eigenvalue: smallest eigenvalue of the last step's normal matrix, translation and rotation
            scaled to metres (rotation × the RMS point range): ≈ 0 along a direction the scan cannot fix.
        max_eigenvalue: largest eigenvalue of the same matrix.
    """

    pose: np.ndarray
    converged: bool
    iterations: int
    inliers: float
    rms: float
    min_eigenvalue: float
    max_eigenvalue: float


def register(
    cloud: LineCloud,
    pts: np.ndarray,
    start: np.ndarray,
    max_iterations: int = 10,
    max_distance: float = 0.3,
    kernel_scale: float = 0.03,
    tol_translation: float = 1e-4,
    tol_rotation: float = 1e-4,
) -> Registration:
    """Register laser-frame points ``pts`` (n, 2, m) to ``cloud`` from ``start`` (x m, y m, θ rad).

    Each step: transform, nearest usable reference point within ``max_distance`` (m), Cauchy-weighted
    (scale ``kernel_scale``, m) Gauss–Newton step on the point-to-line residuals (Censi 2008, Eq. 9 and
    its linearisation). Stops when a step moves less than ``tol_translation`` (m) and ``tol_rotation``
    (rad), after ``max_iterations`` steps, or when fewer than :data:`MIN_CORRESPONDENCES` points have a
    correspondence (then ``converged`` is False).
    """
    x, y, th = (float(v) for v in start)
    p = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
    n = p.shape[0]
    out = Registration(np.array([x, y, th]), False, 0, 0.0, math.nan, 0.0, 0.0)
    if n < MIN_CORRESPONDENCES or len(cloud) == 0:
        return out
    rho = math.sqrt(float(np.einsum("ij,ij->", p, p)) / n)
    for it in range(max_iterations):
        c, s = math.cos(th), math.sin(th)
        q = np.column_stack((c * p[:, 0] - s * p[:, 1] + x, s * p[:, 0] + c * p[:, 1] + y))
        d, j = cloud.tree.query(q, distance_upper_bound=max_distance)
        found = np.isfinite(d)
        found[found] = cloud.usable[j[found]]
        out.inliers = float(found.sum()) / n
        if int(found.sum()) < MIN_CORRESPONDENCES:
            return out
        jj = j[found]
        nrm = cloud.normals[jj]
        pf = p[found]
        r = np.einsum("ij,ij->i", nrm, q[found] - cloud.points[jj])
        # ∂(R(θ)p)/∂θ = (−s·px − c·py, c·px − s·py)
        dth = nrm[:, 0] * (-s * pf[:, 0] - c * pf[:, 1]) + nrm[:, 1] * (c * pf[:, 0] - s * pf[:, 1])
        J = np.column_stack((nrm[:, 0], nrm[:, 1], dth))
        w = 1.0 / (1.0 + (r / kernel_scale) ** 2)  # Cauchy weights (IRLS)
        H = J.T @ (J * w[:, None])
        g = J.T @ (w * r)
        out.rms = math.sqrt(float(np.sum(w * r * r)) / max(float(np.sum(w)), 1e-12))
        S = np.diag([1.0, 1.0, 1.0 / max(rho, 1e-3)])  # rotation in metres at the RMS range
        ev = np.linalg.eigvalsh(S @ H @ S)
        out.min_eigenvalue, out.max_eigenvalue = float(ev[0]), float(ev[-1])
        try:
            delta = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            return out
        if not np.all(np.isfinite(delta)):
            return out
        x += float(delta[0])
        y += float(delta[1])
        th += float(delta[2])
        out.pose = np.array([x, y, th])
        out.iterations = it + 1
        if math.hypot(delta[0], delta[1]) < tol_translation and abs(delta[2]) < tol_rotation:
            out.converged = True
            break
    return out
