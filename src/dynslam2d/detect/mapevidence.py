"""Static evidence from the SLAM map: is a point on long-occupied structure or in observed free space?

The map is the strongest witness of what does not move (docs/architecture.md): an endpoint on a cell
that many earlier scans hit is structure; an endpoint in a cell that earlier scans passed
through (log-odds below zero: more free observations than hits) is space that was empty a
moment ago, so whatever returns from there now has moved in. A cell that was never observed
(log-odds 0, e.g. a wall sliding into view as the robot drives) is evidence of neither.

The tracker uses two per-point flags (docs/tracking.md, "Static evidence from the map"):

- **structure**: the point's own cell has log-odds ≥ ``occupied_logodds`` (hector's hit adds
  logit(0.9) = 2.2 and a free pass logit(0.4) = −0.4, so the tracker's default 6.0 needs at
  least three net hits);
- **free**: the point's own cell has log-odds ≤ ``free_logodds`` (default −0.35: at least one net
  free observation) and no cell within ``free_radius`` cells is occupied (log-odds > 0.5): a
  wall point that range noise put one cell in front of the wall still has the wall next to it,
  while the hidden back of a moving object is merely unknown.

Frames: map frame (the finest map level's world coordinates), units m. The map is read only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True, slots=True, eq=False)
class MapView:
    """Read-only view of one log-odds grid level.

    Attributes:
        logodds: (H, W) float32 log-odds, indexed [row, col] = [y, x] in cells; 0 = unknown.
        i0, j0: absolute cell index of column 0 / row 0 (cell (i, j) is centred at (i·res, j·res)).
        resolution: cell side, m.
    """

    logodds: np.ndarray
    i0: int
    j0: int
    resolution: float

    @classmethod
    def of_level(cls, level: object) -> MapView | None:
        """A view of a :class:`dynslam2d.slam.grid.GridLevel` (None while the level is empty)."""
        lo = level.logodds
        if lo.size == 0:
            return None
        return cls(lo, int(level.i0), int(level.j0), float(level.resolution))


@njit(cache=True)
def map_evidence_kernel(px: np.ndarray, py: np.ndarray, logodds: np.ndarray, i0: int, j0: int, res: float,
                        occ_thr: float, free_thr: float, free_radius: int, structure: np.ndarray,
                        free: np.ndarray, unknown: np.ndarray, near_thr: float = 0.5) -> None:
    """Fill ``structure`` / ``free`` (n,) bool for the map-frame points (``px``, ``py``, m): the point's
    cell is long-occupied (log-odds ≥ ``occ_thr``); the point's cell is observed free (log-odds ≤
    ``free_thr``) with no occupied cell (log-odds > ``near_thr``) within ``free_radius``; ``unknown``: the point's cell
    was never observed (log-odds 0, or outside the grid)."""
    h = logodds.shape[0]
    w = logodds.shape[1]
    for i in range(px.shape[0]):
        structure[i] = False
        free[i] = False
        unknown[i] = True
        x = px[i]
        y = py[i]
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        cx = int(np.floor(x / res + 0.5)) - i0  # hector's cell rounding (slam/grid.py)
        cy = int(np.floor(y / res + 0.5)) - j0
        if cx < 0 or cy < 0 or cx >= w or cy >= h:
            continue
        unknown[i] = logodds[cy, cx] == 0.0
        if logodds[cy, cx] >= occ_thr:
            structure[i] = True
            continue
        if logodds[cy, cx] > free_thr:
            continue
        ok = True
        for dy in range(-free_radius, free_radius + 1):
            for dx in range(-free_radius, free_radius + 1):
                yy = cy + dy
                xx = cx + dx
                if 0 <= yy < h and 0 <= xx < w and logodds[yy, xx] > near_thr:
                    ok = False
                    break
            if not ok:
                break
        free[i] = ok


def map_evidence(points: np.ndarray, view: MapView | None, occupied_logodds: float = 6.0,
                 free_logodds: float = -0.35, free_radius: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(structure, free, unknown): three (n,) bool arrays for the (n, 2) map-frame points (module docstring;
    unknown = the point's cell was never observed).

    Example:
        >>> import numpy as np
        >>> lo = np.zeros((5, 5), dtype=np.float32); lo[2, 2] = 7.0; lo[:, 4] = -1.0
        >>> s, f, u = map_evidence(np.array([[0.0, 0.0], [0.15, 0.0]]), MapView(lo, -2, -2, 0.05))
        >>> s.tolist(), f.tolist(), u.tolist()
        ([True, False], [False, False], [False, True])
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    structure = np.zeros(n, dtype=bool)
    free = np.zeros(n, dtype=bool)
    unknown = np.ones(n, dtype=bool)
    if view is None or n == 0:
        return structure, free, unknown
    map_evidence_kernel(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), view.logodds,
                        int(view.i0), int(view.j0), float(view.resolution), float(occupied_logodds),
                        float(free_logodds), int(free_radius), structure, free, unknown)
    return structure, free, unknown
