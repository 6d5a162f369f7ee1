"""Map metrics: an estimated occupancy map against a ground-truth map.

Formulas and the choices behind them are in ``docs/metrics.md``; in short:

* **Comparison grid.** The ground-truth lattice (its resolution and cell alignment),
  extended with unknown cells where needed so that every observed cell of the estimate
  lands on it. The estimate is resampled onto it by *nearest cell centre*: each
  comparison cell takes the value of the estimate cell that contains the point
  ``T⁻¹ · c`` (``c`` = the comparison cell's centre in the ground-truth frame, ``T`` = the
  SE(2) transform from the estimate's frame into the ground-truth frame, i.e. the ATE
  alignment of the trajectories); outside the estimate → unknown. Best with equal
  resolutions (the SLAM map and the simulator's ground truth are both 0.05 m); an
  estimate much finer than the ground truth is subsampled, not pooled.
* **Sets.** ``A`` = ground-truth occupied cells (value > 0.5), ``B`` = estimated occupied
  cells (probability > ``occupied_threshold``, unknown is not occupied).
* **Tolerances** use Euclidean distances between cell centres (scipy's exact EDT): a cell
  of ``A`` is *matched* if a cell of ``B`` lies within ``tolerance`` of it, and vice versa.

All distances in m, areas in m².
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.types import Pose2D

#: Added to distance thresholds so that a neighbour at exactly the tolerance counts
#: despite floating-point rounding of the EDT, m.
_EPS = 1e-9


@dataclass(frozen=True)
class MapMetrics:
    """Result of :func:`map_metrics` (see ``docs/metrics.md`` for every formula).

    Attributes:
        iou: strict IoU of occupied cells, ``|A∩B| / |A∪B|`` (paper Eq. 9); NaN if both empty.
        iou_tolerant: IoU with a distance tolerance, ``I / (I + |A unmatched| + |B unmatched|)``
            with ``I = (|A matched| + |B matched|) / 2``; equals ``iou`` at tolerance 0.
        weighted_rmse: class-balanced weighted RMSE (paper Eq. 10) between the estimated
            probability and the ground truth over cells known in both;
            ``sqrt((mse_occupied + mse_free) / 2)``. NaN if no such cell.
        rmse_occupied, rmse_free: the RMSE within each ground-truth class (NaN if empty).
        precision: share of estimated occupied cells within tolerance of a GT occupied cell.
        recall: share of *observable* GT occupied cells (within tolerance of a cell the
            estimate observed) that have an estimated occupied cell within tolerance.
        recall_all: the same over all GT occupied cells (penalises unexplored structure).
        f1: ``2·precision·recall / (precision + recall)`` (observable recall).
        ghost_area_m2: area of estimated occupied cells farther than ``ghost_distance``
            from any GT occupied cell, m².
        ghost_cells: their count.
        n_truth_occupied, n_estimate_occupied: ``|A|`` and ``|B|`` on the comparison grid.
        n_truth_observable: GT occupied cells counted by ``recall``.
        n_compared_occupied, n_compared_free: cells in the weighted RMSE, per GT class.
        resolution_m: cell side of the comparison grid, m.
        tolerance_m, ghost_distance_m, occupied_threshold: the parameters used.
    """

    iou: float
    iou_tolerant: float
    weighted_rmse: float
    rmse_occupied: float
    rmse_free: float
    precision: float
    recall: float
    recall_all: float
    f1: float
    ghost_area_m2: float
    ghost_cells: int
    n_truth_occupied: int
    n_estimate_occupied: int
    n_truth_observable: int
    n_compared_occupied: int
    n_compared_free: int
    resolution_m: float
    tolerance_m: float
    ghost_distance_m: float
    occupied_threshold: float

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python mapping of every field (floats and ints; NaN stays NaN)."""
        return {k: (float(v) if isinstance(v, float) else int(v)) for k, v in asdict(self).items()}


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den > 0 else math.nan


def comparison_grids(
    estimate: GridMap, truth: GridMap, transform: Pose2D | None = None
) -> tuple[np.ndarray, np.ndarray, float, tuple[float, float]]:
    """Put the estimate and the ground truth on one grid (the ground-truth lattice).

    The ground-truth lattice is extended by whole cells (filled with unknown) until it
    covers the footprint of the estimate's observed cells mapped by ``transform``. The
    estimate is resampled by nearest cell centre (module docstring).

    Args:
        estimate: estimated map (probabilities, NaN unknown), in its own frame.
        truth: ground-truth map (1 occupied, 0 free, NaN unknown), ground-truth frame.
        transform: pose of the estimate's frame in the ground-truth frame (maps estimate
            coordinates into ground-truth coordinates); None = identity.

    Returns:
        ``(est, gt, resolution, origin)``: two (H, W) float arrays on the same cells (row 0
        at the bottom), the cell side (m) and the world (x, y) of the lower-left corner of
        cell (0, 0) in the ground-truth frame (m).
    """
    T = transform if transform is not None else Pose2D()
    res = truth.resolution
    gt = truth.prob
    ox, oy = truth.origin
    h, w = gt.shape
    # Footprint of the estimate's observed cells in the ground-truth frame.
    known = estimate.known()
    pad = (0, 0, 0, 0)  # (left, right, bottom, top) in cells
    if known.any():
        rows = np.flatnonzero(known.any(axis=1))
        cols = np.flatnonzero(known.any(axis=0))
        er = estimate.resolution
        ex0, ey0 = estimate.origin
        corners = np.array(
            [
                [ex0 + cols[0] * er, ey0 + rows[0] * er],
                [ex0 + (cols[-1] + 1) * er, ey0 + rows[0] * er],
                [ex0 + cols[0] * er, ey0 + (rows[-1] + 1) * er],
                [ex0 + (cols[-1] + 1) * er, ey0 + (rows[-1] + 1) * er],
            ]
        )
        cw = T.transform_points(corners)
        left = max(0, int(math.ceil((ox - cw[:, 0].min()) / res)))
        bottom = max(0, int(math.ceil((oy - cw[:, 1].min()) / res)))
        right = max(0, int(math.ceil((cw[:, 0].max() - (ox + w * res)) / res)))
        top = max(0, int(math.ceil((cw[:, 1].max() - (oy + h * res)) / res)))
        pad = (left, right, bottom, top)
    left, right, bottom, top = pad
    if any(pad):
        gt = np.pad(gt, ((bottom, top), (left, right)), constant_values=np.nan)
        ox -= left * res
        oy -= bottom * res
    H, W = gt.shape
    # Nearest cell centre: comparison cell centre → estimate frame → the estimate cell containing it.
    xs = ox + (np.arange(W) + 0.5) * res
    ys = oy + (np.arange(H) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)
    inv = T.inverse()
    c, s = math.cos(inv.theta), math.sin(inv.theta)
    ex = c * X - s * Y + inv.x
    ey = s * X + c * Y + inv.y
    col = np.floor((ex - estimate.origin[0]) / estimate.resolution).astype(np.int64)
    row = np.floor((ey - estimate.origin[1]) / estimate.resolution).astype(np.int64)
    eh, ew = estimate.shape
    inside = (col >= 0) & (col < ew) & (row >= 0) & (row < eh)
    est = np.full((H, W), np.nan)
    est[inside] = estimate.prob[row[inside], col[inside]]
    return est, gt, res, (ox, oy)


def distance_to(mask: np.ndarray, resolution: float) -> np.ndarray:
    """Euclidean distance (m) from every cell centre to the nearest cell of ``mask`` (inf if none)."""
    if not mask.any():
        return np.full(mask.shape, np.inf)
    from scipy.ndimage import distance_transform_edt  # on use: runs without ground truth never need it

    return distance_transform_edt(~mask, sampling=resolution)


@dataclass(frozen=True, eq=False)
class CellSets:
    """The cell sets every map metric is built from, on the comparison grid.

    Attributes:
        estimate, truth: the resampled estimate (probability, NaN unknown) and the ground truth.
        resolution, origin: the comparison grid's cell side (m) and lower-left corner (m).
        truth_occupied (A), estimate_occupied (B), known (estimate observed): (H, W) bool.
        truth_matched: A cells with a B cell within the tolerance; estimate_matched: the converse.
        observable: A cells within the tolerance of a cell the estimate observed.
        ghost: B cells farther than the ghost distance from every A cell.
        tolerance, ghost_distance, occupied_threshold: the parameters the sets were built with (m, m, probability).
    """

    estimate: np.ndarray
    truth: np.ndarray
    resolution: float
    origin: tuple[float, float]
    truth_occupied: np.ndarray
    estimate_occupied: np.ndarray
    known: np.ndarray
    truth_matched: np.ndarray
    estimate_matched: np.ndarray
    observable: np.ndarray
    ghost: np.ndarray
    tolerance: float = 0.10
    ghost_distance: float = 0.20
    occupied_threshold: float = 0.65


def cell_sets(
    estimate: GridMap,
    truth: GridMap,
    transform: Pose2D | None = None,
    tolerance: float = 0.10,
    ghost_distance: float = 0.20,
    occupied_threshold: float = 0.65,
) -> CellSets:
    """Resample ``estimate`` onto the ground truth's grid and classify the cells (see :class:`CellSets`)."""
    est, gt, res, origin = comparison_grids(estimate, truth, transform)
    with np.errstate(invalid="ignore"):
        A = np.nan_to_num(gt, nan=0.0) > 0.5
        B = np.nan_to_num(est, nan=0.0) > occupied_threshold
    known = np.isfinite(est)
    d_to_a = distance_to(A, res)
    return CellSets(
        estimate=est, truth=gt, resolution=res, origin=origin,
        truth_occupied=A, estimate_occupied=B, known=known,
        truth_matched=A & (distance_to(B, res) <= tolerance + _EPS),
        estimate_matched=B & (d_to_a <= tolerance + _EPS),
        observable=A & (distance_to(known, res) <= tolerance + _EPS),
        ghost=B & (d_to_a > ghost_distance + _EPS),
        tolerance=float(tolerance), ghost_distance=float(ghost_distance), occupied_threshold=float(occupied_threshold),
    )


def map_metrics(
    estimate: GridMap,
    truth: GridMap,
    transform: Pose2D | None = None,
    tolerance: float = 0.10,
    ghost_distance: float = 0.20,
    occupied_threshold: float = 0.65,
) -> MapMetrics:
    """Compare an estimated map with the ground truth (formulas in ``docs/metrics.md``).

    Args:
        estimate: estimated map, probabilities in [0, 1], NaN = unknown, its own frame.
        truth: ground-truth map, 1 occupied / 0 free / NaN unknown or outside, GT frame.
        transform: pose of the estimate frame in the GT frame (the SE(2) ATE alignment that
            maps the estimated trajectory onto the true one); None = identity.
        tolerance: distance within which an occupied cell counts as matched, m (≥ 0).
        ghost_distance: estimated occupied cells farther than this from any GT occupied
            cell are ghosts, m.
        occupied_threshold: estimated probability above which a cell is occupied
            (map_server ``occupied_thresh``), dimensionless.

    Returns:
        :class:`MapMetrics`.
    """
    if not (tolerance >= 0.0 and ghost_distance >= 0.0):
        raise DynSlamError(
            f"map metrics: tolerance ({tolerance} m) and ghost distance ({ghost_distance} m) must be >= 0"
        )
    return map_metrics_of(cell_sets(estimate, truth, transform, tolerance, ghost_distance, occupied_threshold))


def map_metrics_of(cs: CellSets) -> MapMetrics:
    """The :class:`MapMetrics` of cell sets already built by :func:`cell_sets` (what :func:`map_metrics`
    computes after building them; a caller that also draws the sets builds them once)."""
    est, gt, A, B, est_known = cs.estimate, cs.truth, cs.truth_occupied, cs.estimate_occupied, cs.known
    res = cs.resolution
    n_a, n_b = int(A.sum()), int(B.sum())

    # Strict IoU (paper Eq. 9).
    iou = _ratio(int((A & B).sum()), int((A | B).sum()))

    # Tolerant matching (Euclidean distance between cell centres).
    n_am, n_bm = int(cs.truth_matched.sum()), int(cs.estimate_matched.sum())
    inter = 0.5 * (n_am + n_bm)
    iou_tol = _ratio(inter, inter + (n_a - n_am) + (n_b - n_bm))

    precision = _ratio(n_bm, n_b)
    n_obs = int(cs.observable.sum())
    recall = _ratio(int((cs.truth_matched & cs.observable).sum()), n_obs)
    recall_all = _ratio(n_am, n_a)
    if math.isnan(precision) or math.isnan(recall):
        f1 = math.nan
    elif precision + recall == 0.0:
        f1 = 0.0
    else:
        f1 = 2.0 * precision * recall / (precision + recall)

    # Ghost area: estimated occupied cells far from any static structure.
    n_ghost = int(cs.ghost.sum())

    # Class-balanced weighted RMSE (paper Eq. 10): x_i = GT value, y_i = estimated
    # probability over cells known in both; σ_i = 1/(2·N_occ) on GT-occupied cells and
    # 1/(2·N_free) on GT-free ones, so Σσ_i = 1 and each class weighs one half.
    both = est_known & np.isfinite(gt)
    occ = both & A
    free = both & ~A
    sq = (np.where(both, est, 0.0) - np.where(both, gt, 0.0)) ** 2
    n_occ, n_free = int(occ.sum()), int(free.sum())
    mse_occ = float(sq[occ].mean()) if n_occ else math.nan
    mse_free = float(sq[free].mean()) if n_free else math.nan
    if n_occ and n_free:
        wrmse = math.sqrt(0.5 * mse_occ + 0.5 * mse_free)
    elif n_occ or n_free:
        # Only one class present: its weights are the only ones, Eq. 10 reduces to its RMSE.
        wrmse = math.sqrt(mse_occ if n_occ else mse_free)
    else:
        wrmse = math.nan

    return MapMetrics(
        iou=iou,
        iou_tolerant=iou_tol,
        weighted_rmse=wrmse,
        rmse_occupied=math.sqrt(mse_occ) if n_occ else math.nan,
        rmse_free=math.sqrt(mse_free) if n_free else math.nan,
        precision=precision,
        recall=recall,
        recall_all=recall_all,
        f1=f1,
        ghost_area_m2=n_ghost * res * res,
        ghost_cells=n_ghost,
        n_truth_occupied=n_a,
        n_estimate_occupied=n_b,
        n_truth_observable=n_obs,
        n_compared_occupied=n_occ,
        n_compared_free=n_free,
        resolution_m=res,
        tolerance_m=cs.tolerance,
        ghost_distance_m=cs.ghost_distance,
        occupied_threshold=cs.occupied_threshold,
    )


def load_run_map(run_dir: str | os.PathLike[str]) -> GridMap:
    """The estimated map of a results folder, with probabilities where available.

    ``map.yaml``/``map.pgm`` (trinary) gives the geometry; when ``map_logodds.npy`` (same
    cells, row 0 at the bottom) is present, the probabilities are ``1/(1+e^(−L))`` on
    every cell that the PGM marks known or whose log-odds is non-zero (a cell never
    updated has L = 0 and stays unknown). Without it, the trinary values (1 / 0 / NaN)
    are returned, and the weighted RMSE then measures the thresholded map.

    Raises:
        DynSlamError: if the files are missing or their shapes disagree.
    """
    from dynslam2d.io.mapfile import read_map

    d = Path(run_dir)
    yaml_path = d / "map.yaml"
    if not yaml_path.exists():
        raise DynSlamError(f"{yaml_path}: no map in this results folder")
    grid = read_map(yaml_path)
    lo_path = d / "map_logodds.npy"
    if not lo_path.exists():
        return grid
    try:
        lo = np.load(lo_path).astype(np.float64)
    except (OSError, ValueError) as exc:
        raise DynSlamError(f"{lo_path}: cannot read log-odds array ({exc})") from exc
    if lo.shape != grid.shape:
        raise DynSlamError(f"{lo_path}: log-odds shape {lo.shape} differs from map.yaml's {grid.shape}")
    known = grid.known() | (lo != 0.0)
    prob = np.where(known, 1.0 / (1.0 + np.exp(-np.clip(lo, -50.0, 50.0))), np.nan)
    return GridMap(prob, grid.resolution, grid.origin)


__all__ = ["MapMetrics", "comparison_grids", "load_run_map", "map_metrics", "map_metrics_of"]
