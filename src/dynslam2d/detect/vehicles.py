"""Vehicle-size clusters: tracked only where the SLAM map has seen free space (docs/maps.md).

``detect.segment.max_extent`` (3 m) makes every cluster whose fitted rectangle has a longer side
static structure: that keeps walls out of the tracker, but also a 4 m car or a 5 m van.
A cluster longer than ``max_extent`` and at most ``vehicle_max_extent`` is kept as a detection
only where the map is the witness that the object is not a wall (the same per-point evidence
as the tracker's, :mod:`dynslam2d.detect.mapevidence`):

* at most ``vehicle_max_structure`` of its points lie on long-occupied map cells (a wall the
  robot has mapped is long-occupied; a vehicle that stood long enough to be written into the
  map is too, so a parked vehicle stays structure until it has left its place), and
* at least ``vehicle_min_free`` of its points lie in cells earlier scans saw through (a vehicle
  driving over the floor; a wall seen for the first time is in unknown cells, never free).

Without a map (the first scan, or ``detect.tracker.map_evidence: false``) no long cluster is kept.
Frames: map frame; units m.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.layout import F_HI1, F_HI2, F_LO1, F_LO2
from dynslam2d.detect.mapevidence import MapView, map_evidence


def extent_limit(config: DetectConfig) -> float:
    """The longest fitted rectangle side any cluster may have to be classified, m."""
    seg = config.segment
    return max(seg.max_extent, seg.vehicle_max_extent)


@njit(cache=True)
def long_kept(keep: np.ndarray, fits: np.ndarray, max_extent: float) -> np.ndarray:
    """Indices (ascending, int64) of the kept clusters (``keep``) whose fitted rectangle (``fits`` rows,
    :func:`~dynslam2d.detect.shapes.fit_clusters`) has a side longer than ``max_extent`` (m): numpy's
    ``flatnonzero(keep & (maximum(hi1 − lo1, hi2 − lo2) > max_extent))`` in one pass (a NaN side is never longer,
    as ``np.maximum`` propagates it)."""
    out = np.empty(keep.shape[0], dtype=np.int64)
    m = 0
    for c in range(keep.shape[0]):
        if not keep[c]:
            continue
        e1 = fits[c, F_HI1] - fits[c, F_LO1]
        e2 = fits[c, F_HI2] - fits[c, F_LO2]
        if e1 != e1 or e2 != e2:
            continue
        if e1 > max_extent or e2 > max_extent:
            out[m] = c
            m += 1
    return out[:m]


def admit_long_clusters(keep: np.ndarray, fits: np.ndarray, offsets: np.ndarray, px: np.ndarray, py: np.ndarray,
                        view: MapView | None, config: DetectConfig) -> int:
    """In place: ``keep[c]`` = False for every kept cluster ``c`` longer than ``segment.max_extent`` whose
    points fail the map test of the module docstring. ``fits`` are the rows of
    :func:`~dynslam2d.detect.shapes.fit_clusters`, ``offsets`` the segmentation's, ``px``/``py`` the
    clusters' map-frame points (m). Returns the number of long clusters left kept."""
    seg = config.segment
    long_ = long_kept(keep, fits, float(seg.max_extent))  # (none on most scans: one call, no temporaries)
    if long_.shape[0] == 0:
        return 0
    if view is None:
        keep[long_] = False
        return 0
    sel = np.concatenate([np.arange(offsets[c], offsets[c + 1]) for c in long_.tolist()])
    tc = config.tracker
    structure, free, _ = map_evidence(np.column_stack((px[sel], py[sel])), view, tc.map_occupied_logodds,
                                      tc.map_free_logodds, tc.map_free_radius)
    n = (offsets[long_ + 1] - offsets[long_]).astype(np.float64)
    bounds = np.concatenate(([0], np.cumsum(n).astype(np.int64)))[:-1]
    s_share = np.add.reduceat(structure.astype(np.float64), bounds) / n
    f_share = np.add.reduceat(free.astype(np.float64), bounds) / n
    ok = (s_share <= seg.vehicle_max_structure) & (f_share >= seg.vehicle_min_free)
    keep[long_[~ok]] = False
    return int(ok.sum())


__all__ = ["admit_long_clusters", "extent_limit", "long_kept"]
