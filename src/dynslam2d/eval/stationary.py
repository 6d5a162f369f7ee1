"""Scoring runs of a sensor that never moves (e.g. leg_tracker's stationary bags).

With a motionless laser the right trajectory is no motion at all, and the right map
holds only what is always there. Two numbers follow:

- **drift**: the largest and the final distance (m) and rotation (rad) of the estimated
  pose from the first one;
- **residue area**: m² of cells that are occupied in the run's map (p > 0.65) but free
  (observed, p < 0.5) in a *background map* built from a single scan of per-beam
  median ranges, integrated once at the identity pose with the same SLAM settings
  (beams that rarely return clear free space up to the sensor's range).
  People who walked past and ended up in the map are counted here; walls are not
  (the median scan sees them), and cells the background never observed are not either.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import Pose2D, Scan, wrap_angle


def median_background_scan(scans: Iterable[Scan], min_valid_share: float = 0.5) -> Scan:
    """One scan whose range per beam is the median of that beam's valid returns.

    Beams with a return in fewer than ``min_valid_share`` of the scans get no return
    (+inf: the sensor usually saw nothing along them). All scans must share the beam
    geometry of the first one.
    """
    first: Scan | None = None
    rows: list[np.ndarray] = []
    for s in scans:
        if first is None:
            first = s
        rows.append(np.where(s.valid_mask(), s.ranges, np.nan))
    if first is None:
        raise ValueError("median_background_scan: no scans")
    stack = np.vstack(rows)
    valid_share = np.isfinite(stack).mean(axis=0)
    with warnings.catch_warnings():  # beams with no return at all: NaN, handled below
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(stack, axis=0)
    med[valid_share < min_valid_share] = np.inf
    return first.with_ranges(med)


def background_map(background: Scan, config: SlamConfig | None = None) -> GridMap:
    """The map of ``background`` integrated once at the identity pose (finest level).

    Beams without a return clear free space up to the sensor's ``range_max`` (the sensor
    saw nothing within its reach along them)."""
    cfg = (config or SlamConfig()).model_copy(update={"clear_no_return_dist": float(background.range_max)})
    slam = HectorSlam(cfg)
    slam.update_map(background, Pose2D(), force=True)
    return slam.gridmap(0)


def residue_area(run_map: GridMap, background: GridMap, occupied_threshold: float = 0.65) -> float:
    """m² of cells occupied in ``run_map`` whose centre falls on a free cell of ``background``."""
    occ = run_map.occupied(occupied_threshold)
    if not occ.any():
        return 0.0
    xs, ys = run_map.cell_centers()
    pts = np.column_stack((xs[occ], ys[occ]))
    cells = background.world_to_cell(pts)
    h, w = background.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < w) & (cells[:, 1] >= 0) & (cells[:, 1] < h)
    prob = np.full(pts.shape[0], np.nan)
    prob[inside] = background.prob[cells[inside, 1], cells[inside, 0]]
    with np.errstate(invalid="ignore"):
        free = prob < 0.5
    return float(free.sum()) * run_map.resolution**2


@dataclass(frozen=True)
class StationaryScore:
    """Drift (m, rad) and residue area (m²) of a run of a motionless sensor."""

    drift_max_m: float
    drift_final_m: float
    rotation_max_rad: float
    residue_area_m2: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def stationary_score(trajectory: Trajectory, run_map: GridMap, background: GridMap) -> StationaryScore:
    """Score a run of a sensor that did not move (see the module docstring)."""
    d = np.hypot(*(trajectory.xy - trajectory.xy[0]).T)
    rot = np.abs(wrap_angle(trajectory.yaw - trajectory.yaw[0]))
    return StationaryScore(
        drift_max_m=float(d.max()),
        drift_final_m=float(d[-1]),
        rotation_max_rad=float(rot.max()),
        residue_area_m2=residue_area(run_map, background),
    )
