"""A 2D occupancy grid in world units: the exchange type for maps.

Ground-truth maps from the simulator, SLAM output and map files on disk all
pass through :class:`GridMap`. Layout: ``prob[row, col]`` with **row 0 at the
bottom** (smallest y), column 0 at the left (smallest x), so that
``world = origin + (col + 0.5, row + 0.5) · resolution`` is the centre of a cell.
``origin`` is the world position (m) of the lower-left corner of cell (0, 0),
exactly the ``origin`` of a ROS map_server YAML. Files on disk store rows
top-down; :mod:`dynslam2d.io.mapfile` does the flip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Value used in ``prob`` for cells never observed.
UNKNOWN = np.nan


@dataclass(slots=True, eq=False)
class GridMap:
    """Occupancy probabilities on a regular grid.

    Attributes:
        prob: (H, W) float64 occupancy probability in [0, 1]; NaN = unknown. Row 0 is
            the bottom of the map (smallest y).
        resolution: cell side, m.
        origin: (x, y) of the lower-left corner of cell (0, 0) in the map frame, m.
    """

    prob: np.ndarray
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        self.prob = np.asarray(self.prob, dtype=np.float64)
        if self.prob.ndim != 2:
            raise ValueError(f"GridMap.prob must be 2-D, got shape {self.prob.shape}")
        if not self.resolution > 0:
            raise ValueError(f"GridMap.resolution must be > 0, got {self.resolution}")
        self.origin = (float(self.origin[0]), float(self.origin[1]))

    @property
    def shape(self) -> tuple[int, int]:
        return self.prob.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the map in the map frame, m (for imshow)."""
        h, w = self.prob.shape
        x0, y0 = self.origin
        return (x0, x0 + w * self.resolution, y0, y0 + h * self.resolution)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) world points (m) → (n, 2) integer (col, row) indices (may lie outside)."""
        xy = np.asarray(xy, dtype=np.float64)
        return np.floor((xy - np.asarray(self.origin)) / self.resolution).astype(np.int64)

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """(X, Y) world coordinates of every cell centre, each (H, W), m."""
        h, w = self.prob.shape
        xs = self.origin[0] + (np.arange(w) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(h) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)

    def occupied(self, threshold: float = 0.65) -> np.ndarray:
        """(H, W) bool: cells with probability above ``threshold`` (unknown → False)."""
        # an unknown cell counts as probability 0 (as np.nan_to_num(prob, nan=0) > threshold), without the
        # map-sized float64 copy nan_to_num makes (docs/speed.md, memory)
        with np.errstate(invalid="ignore"):
            out = self.prob > threshold
            if 0.0 > threshold:
                out |= np.isnan(self.prob)
        return out

    def free(self, threshold: float = 0.196) -> np.ndarray:
        """(H, W) bool: cells with probability below ``threshold`` (unknown → False)."""
        # an unknown cell counts as probability 1 (as np.nan_to_num(prob, nan=1) < threshold), without a copy
        with np.errstate(invalid="ignore"):
            out = self.prob < threshold
            if 1.0 < threshold:
                out |= np.isnan(self.prob)
        return out

    def known(self) -> np.ndarray:
        """(H, W) bool: cells that hold an observation (not NaN)."""
        return np.isfinite(self.prob)
