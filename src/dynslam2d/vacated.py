"""The pipeline's per-scan vacated-footprint trace in one kernel call (docs/maps.md, "Vacated footprints").

:class:`VacatedTrace` gives the map view the tracker's map evidence reads for one scan: the finest map level, with
the outlines of long-occupied cells that this scan sees through (a parked vehicle driving off) counted as observed
free. It is :func:`dynslam2d.slam.cleanup.scan_clearing` followed by
:func:`dynslam2d.detect.mapevidence.vacated_outlines`, :meth:`VacatedHistory.persistent` and
:func:`yielding_view`, with the same values, but the scan's clearing geometry, the trace through the map and the
outlines' growth run in one kernel call on parameters packed once per pipeline and on work buffers kept between
scans (the separate calls cost about as much Python and allocation as the trace itself; docs/speed.md).

Frames and units: the laser pose in the map frame (m, rad); the clearing geometry in world cell units (m / the
level's resolution), as in :mod:`dynslam2d.slam.cleanup`.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.mapevidence import MapView, VacatedHistory, VacatedOutlines, vacated_core, yielding_view
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.cleanup import _scan_geometry
from dynslam2d.types import Pose2D, Scan

#: Index of each parameter in :attr:`VacatedTrace.params` (what :func:`vacated_scan_kernel` reads).
_RES, _MARGIN, _GRAZING, _MIN_SIN, _CORE, _OCC, _DEPTH, _NEAR, _OCC32, _MAX_SIDE, _MIN_CELLS, _MIN_EXTENT, \
    _MIN_SHARE = range(13)


@njit(cache=True)
def vacated_scan_kernel(ranges: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray, valid: np.ndarray, px: float,
                        py: float, th: float, logodds: np.ndarray, i0: int, j0: int, params: np.ndarray,
                        work: np.ndarray, window: np.ndarray
                        ) -> tuple[int, int, np.ndarray]:  # pragma: no cover - numba
    """One scan's vacated outlines: the clearing geometry of the beams (``ranges``, m, with their ``cos_a`` /
    ``sin_a`` and ``valid`` returns) from the laser at (``px``, ``py``, ``th``) (map frame, m, rad) as
    :func:`dynslam2d.slam.cleanup.scan_clearing` makes it, then :func:`vacated_core` on the map ``logodds``
    (column 0 / row 0 at absolute cell ``i0`` / ``j0``) with the parameters ``params`` (indices ``_RES`` …
    ``_MIN_SHARE``: the arguments of :func:`dynslam2d.detect.mapevidence.vacated_outlines_kernel` that do not
    change between scans) and the buffers ``work`` (int64, at least 2 · 64 · beams + 2 · (max_side² + 1)) and
    ``window`` (uint8, all 0, (2 · max_side + 1)²).

    Returns the number of distinct seen-through cells, the number of yielding outlines and, when there are any,
    one array holding their rows, their columns and their sizes one after the other (else an empty one)."""
    res = params[_RES]
    max_side = int(params[_MAX_SIDE])
    n = ranges.shape[0]
    # (``removed`` only makes the geometry's ``kept``, which is not read here: ``valid`` stands in for it)
    _, _, cx, cy, _, clear = _scan_geometry(ranges, cos_a, sin_a, valid, valid, px, py, th, res, params[_MARGIN],
                                            params[_GRAZING], params[_MIN_SIN])
    c = 64 * n
    g = max_side * max_side + 1
    rows, cols, sizes, nc = vacated_core(
        logodds, i0, j0, px / res, py / res, cx, cy, clear, params[_CORE], params[_OCC], params[_DEPTH],
        params[_NEAR], np.float32(params[_OCC32]), max_side, int(params[_MIN_CELLS]), res, params[_MIN_EXTENT],
        params[_MIN_SHARE], work[:c], work[c:2 * c], work[2 * c:2 * c + g], work[2 * c + g:2 * c + 2 * g], window)
    k = sizes.shape[0]
    if k == 0:
        return nc, 0, work[:0]
    total = rows.shape[0]
    out = np.empty(2 * total + k, dtype=np.int64)
    for q in range(total):  # (loops: a slice assignment compiles numba's shape-mismatch message, ≈ 17 helpers)
        out[q] = rows[q]
        out[total + q] = cols[q]
    for q in range(k):
        out[2 * total + q] = sizes[q]
    return nc, k, out


class VacatedTrace:
    """The vacated-footprint trace of one pipeline: its parameters, work buffers and persistence history.

    Args:
        clean: the clean-up pass's beam geometry (margins, grazing incidence, ray core; docs/maps.md).
        occupied_logodds: long-occupied threshold of the map evidence (``detect.tracker.map_occupied_logodds``).
        min_cells, max_extent, min_depth_m, min_share, scans: ``detect.tracker.map_vacate_*`` (m where a length).
        min_extent: an outline must be longer than this to yield, m (``detect.segment.max_extent``).
        near_logodds: log-odds above which a cell belongs to an outline.

    The parameters are read once, here; :meth:`view` is called once per scan, in time order.
    """

    def __init__(self, clean: CleanConfig, *, occupied_logodds: float, min_cells: int, max_extent: float,
                 min_depth_m: float, min_extent: float, min_share: float, scans: int,
                 near_logodds: float = 0.5) -> None:
        self.clean = clean
        self.occupied_logodds = float(occupied_logodds)
        self.min_cells = int(min_cells)
        self.max_extent = float(max_extent)
        self.min_depth_m = float(min_depth_m)
        self.min_extent = float(min_extent)
        self.min_share = float(min_share)
        self.near_logodds = float(near_logodds)
        self.history = VacatedHistory(scans)
        self.params = np.zeros(0)  # made for the map's resolution at the first scan (_prepare)
        self._res = math.nan
        self._beams = -1
        self._work = np.zeros(0, dtype=np.int64)
        self._window = np.zeros((0, 0), dtype=np.uint8)

    def _prepare(self, res: float, beams: int) -> None:
        """The parameters for cells of ``res`` (m) and buffers for ``beams`` beams (the values
        :func:`dynslam2d.detect.mapevidence.vacated_outlines` passes its kernel)."""
        if res != self._res:
            c = self.clean
            max_side = max(int(math.ceil(self.max_extent / res)), 1)
            self.params = np.array([res, float(c.margin_m), float(c.grazing_cells),
                                    math.sin(math.radians(c.min_incidence_deg)), float(c.ray_core),
                                    self.occupied_logodds, self.min_depth_m / res, self.near_logodds,
                                    float(np.float32(self.occupied_logodds)), float(max_side), float(self.min_cells),
                                    self.min_extent, self.min_share], dtype=np.float64)
            self._res = res
            self._window = np.zeros((2 * max_side + 1, 2 * max_side + 1), dtype=np.uint8)
        g = int(self.params[_MAX_SIDE]) ** 2 + 1
        self._work = np.empty(128 * beams + 2 * g, dtype=np.int64)
        self._beams = beams

    def view(self, view: MapView, scan: Scan, pose: Pose2D) -> MapView:
        """``view`` (the finest map level) as the tracker's map evidence reads it for ``scan`` at ``pose``: the
        outlines that yield and persisted (:class:`VacatedHistory`) count as observed free (a copy; else ``view``
        itself). Remembers this scan's candidates."""
        ranges = scan.ranges
        n = ranges.shape[0]
        if self.min_cells <= 0:
            return view
        if n == 0:  # (a scan without beams has no candidate: it breaks a persistence run)
            self.history.none()
            return view
        res = view.resolution
        if res != self._res or n != self._beams:
            self._prepare(res, n)
        cos_a, sin_a = scan.trig()
        valid = scan.valid_view()  # (the kernel only reads it: no copy)
        nc, k, out = vacated_scan_kernel(ranges, cos_a, sin_a, valid, float(pose.x), float(pose.y),
                                         float(pose.theta), view.logodds, view.i0, view.j0, self.params, self._work,
                                         self._window)
        if k == 0:  # no candidate (most scans)
            self.history.none()
            return view
        total = (out.shape[0] - k) // 2
        vac = VacatedOutlines(out[:total], out[total:2 * total], nc, k, tuple(out[2 * total:].tolist()))
        return yielding_view(view, self.history.persistent(view, vac))

