"""The value types of detection: a fitted cluster (:class:`Detection`) and what it measures of a track
(:class:`Measurement`).

A 2D scan sees only the sides of an object that face the sensor, so the centre of a box is
observable along an axis only when its extent along that axis is known. For each axis k of the
fitted rectangle (e1, e2) detection decides which of the two bounds [lo_k, hi_k] are real (``Detection.rel``):

- a **face** bound: the sensor lies beyond it and the points on it span a visible side;
- an **edge** bound realised by a cluster end point: real when the beam just outside the
  cluster hits something behind the end (or nothing), an artificial break when that
  neighbour is closer (occlusion) or continues the same surface (a grazing wall broken by
  the breakpoint threshold).

The centre along k is then the middle of two real bounds, one real bound plus half the
tracked size, or unobserved (the prediction, with a large variance). This is what keeps wall
pieces whose ends slide with the robot from acquiring a velocity along the wall
(docs/architecture.md: a robot rotating at 1 rad/s must not make walls look like movers).

The tracker computes this for every cluster of a scan in the numba kernels
:func:`dynslam2d.detect.kernels.classify_batch` and :func:`dynslam2d.detect.kernels.measure_batch`;
:mod:`dynslam2d.detect.reference` holds the same rules as plain per-detection Python, the readable
reference the kernels are tested against.

Frames: everything here is in the map frame (points already transformed with the scan's
pose); the sensor position is the laser origin in that frame. Units m, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynslam2d.detect.config import FitConfig
from dynslam2d.detect.layout import (
    F_CIRCLE_R,
    F_CIRCLE_RMS,
    F_CIRCLE_X,
    F_THETA,
    FIT_CENTROID,
    FIT_CIRCLE,
    KIND_NAMES,
    LOHI_HI,
    LOHI_LO,
)
from dynslam2d.detect.shapes import fit_circle


class DetectionShape:
    """What a detection derives from its fit (its extent, the fit frame's coordinates, default sizes): the methods of
    :class:`Detection` and :class:`ScanDetection` (no slots of its own: a scan detection keeps only its scan's arrays
    and its row, docs/speed.md, pass det32)."""

    __slots__ = ()

    @property
    def extent(self) -> np.ndarray:
        return self.hi - self.lo

    def to_uv(self, xy: np.ndarray) -> np.ndarray:
        """Map-frame (…, 2) points → (e1, e2) coordinates of the fit."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        xy = np.asarray(xy, dtype=np.float64)
        return np.stack((c * xy[..., 0] + s * xy[..., 1], -s * xy[..., 0] + c * xy[..., 1]), axis=-1)

    def from_uv(self, uv: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([c * uv[0] - s * uv[1], s * uv[0] + c * uv[1]])

    def default_sizes(self, cfg: FitConfig) -> np.ndarray:
        """Sizes along e1, e2 to assume when no track knows them: the extent where both bounds
        are real, else max(extent, min(default_depth, default_depth_ratio · other extent)), m."""
        ext = self.extent
        out = ext.copy()
        for k in (0, 1):
            if not (self.rel[k, 0] and self.rel[k, 1]):
                out[k] = max(ext[k], min(cfg.default_depth, cfg.default_depth_ratio * max(ext[1 - k], 0.0)))
        return out


@dataclass(slots=True, eq=False)
class Detection(DetectionShape):
    """One cluster, fitted, in the map frame.

    Attributes:
        beams: (n,) beam indices of the cluster in scan order.
        points: (n, 2) map-frame points, m.
        centroid: (2,) mean of the points, m.
        kind: "rect", "circle" or "point" (:data:`dynslam2d.detect.layout.KIND_NAMES`).
        theta: rectangle axis angle of e1, rad in [0, π/2).
        lo, hi: (2,) rectangle bounds along e1, e2, m.
        rel: (2, 2) bool, rel[k, 0] / rel[k, 1]: lower / upper bound along axis k is real.
        circle: (3,) circle centre x, y and radius, m (kind "circle").
        n_points: number of points.
        free_fraction: fraction of the points lying where an earlier scan saw through (free space,
            :mod:`dynslam2d.detect.freespace`; set by the tracker, 0 when unknown).
        map_structure, map_free, map_unknown: fractions of the points on long-occupied / observed-free /
            never observed cells of the SLAM map
        person: a merged pair of legs (tracker, ``fit.person_merge``): measured at the middle of the legs
            (:mod:`dynslam2d.detect.mapevidence`; set by the tracker, 0 without a map).
    """

    beams: np.ndarray
    points: np.ndarray
    centroid: np.ndarray
    kind: str
    theta: float
    lo: np.ndarray
    hi: np.ndarray
    rel: np.ndarray
    circle: np.ndarray
    n_points: int
    free_fraction: float = 0.0
    map_structure: float = 0.0
    map_free: float = 0.0
    map_unknown: float = 0.0
    person: bool = False



class ScanArrays:
    """One scan's detection arrays, shared by its :class:`ScanDetection` objects (each holds this record and its row).

    ``beams``: the concatenated beam indices of the detections' points, ``pts``: their (n, 2) map-frame points, m;
    detection j's are rows ``starts[j] − off`` … ``+ npts[j] − 1`` of them (``off``: 0 for the scan's clusters, the
    number of points before the persons' for the merged pairs of legs, whose ``starts`` index the batch's points
    after the merge). ``kinds``: (k,) int8 kind codes (:data:`dynslam2d.detect.layout.KIND_NAMES`); ``fits``: (k,
    N_FIT_COLS) fit rows (:func:`dynslam2d.detect.shapes.fit_clusters`), ``lohi``: (k, 4) bounds lo1, lo2, hi1, hi2,
    ``rel``: (k, 2, 2) real-bound flags (:mod:`dynslam2d.detect.layout`); ``mev``: (3, k) fractions of the points on
    long-occupied, observed-free and never-observed map cells (:mod:`dynslam2d.detect.mapevidence`), or None
    without a map."""

    __slots__ = ("beams", "pts", "off", "starts", "npts", "kinds", "fits", "lohi", "rel", "mev")

    def __init__(self, beams: np.ndarray, pts: np.ndarray, off: int, starts: np.ndarray, npts: np.ndarray,
                 kinds: np.ndarray, fits: np.ndarray, lohi: np.ndarray, rel: np.ndarray,
                 mev: np.ndarray | None) -> None:
        self.beams = beams
        self.pts = pts
        self.off = off
        self.starts = starts
        self.npts = npts
        self.kinds = kinds
        self.fits = fits
        self.lohi = lohi
        self.rel = rel
        self.mev = mev


def _row_view(array: str, cols: slice, doc: str) -> property:
    """A read-only property: the columns ``cols`` of row ``self._j`` of the scan's array ``array`` (a
    :class:`ScanArrays` attribute; a view)."""

    def get(self: ScanDetection) -> np.ndarray:
        return getattr(self._s, array)[self._j, cols]

    return property(get, doc=doc)


def _mev_value(row: int, doc: str) -> property:
    """A read-only property: row ``row`` (structure, free, unknown) of the scan's (3, k) map-evidence array at column
    ``self._j``, as a Python float (0.0 without a map: ``mev`` None)."""

    def get(self: ScanDetection) -> float:
        m = self._s.mev
        return 0.0 if m is None else m.item(row, self._j)

    return property(get, doc=doc)


class ScanDetection(DetectionShape):
    """A detection of the tracker's current scan, with the fields of a :class:`Detection` (read-only but
    ``free_fraction`` and ``person``): the scan's arrays (:class:`ScanArrays`, ``_s``) and its row ``_j`` of them, in
    an object of four slots (not a subclass of the dataclass, whose fifteen slots every detection would carry). Its
    values are read from the arrays when asked for, not made when the detection is made (the tracker makes one per
    cluster per scan and reads them for few; a detection kept scans later costs its free in cache misses per object
    and cache line it owns, docs/speed.md, passes det31 and det32): ``beams`` and ``points`` are views of its rows of
    the scan's beams and points, ``centroid``, ``lo``, ``hi``, ``rel``, ``circle`` of its fit and bound rows (the
    values of a :class:`Detection` built with them); ``kind``, ``n_points``, ``theta`` and ``map_structure`` /
    ``map_free`` / ``map_unknown`` are Python values of its row and map-evidence column. The tracker's per-pair
    readers take the scan's batch arrays by index instead (``Tracker._update_tracks``). A copy (``copy`` /
    ``pickle``) is a plain :class:`Detection`.

    ``free_fraction`` may be given as a float, or left to be computed when first read (few are read): as an object
    with ``fraction(points)`` (the scan's free-space test, :class:`dynslam2d.detect.freespace.FreeTest`), or as a
    pair of scan detections (a merged pair of legs: their fractions weighted by their point counts)."""

    __slots__ = ("_s", "_j", "_ff", "person")

    def __init__(self, arrays: ScanArrays, j: int, free_fraction: float | object = 0.0,
                 person: bool = False) -> None:
        self._s = arrays
        self._j = j
        self._ff = free_fraction
        self.person = person

    @property
    def beams(self) -> np.ndarray:
        """(n,) beam indices of the cluster in scan order: a view of the scan's beams, made when read."""
        s = self._s
        j = self._j
        a = s.starts.item(j) - s.off
        return s.beams[a:a + s.npts.item(j)]

    @property
    def points(self) -> np.ndarray:
        """(n, 2) map-frame points, m: a view of the scan's points, made when read."""
        s = self._s
        j = self._j
        a = s.starts.item(j) - s.off
        return s.pts[a:a + s.npts.item(j)]

    @property
    def n_points(self) -> int:
        """Number of points."""
        return self._s.npts.item(self._j)

    @property
    def kind(self) -> str:
        """"rect", "circle" or "point" (:data:`dynslam2d.detect.layout.KIND_NAMES` of the row's kind code)."""
        return KIND_NAMES[self._s.kinds.item(self._j)]

    @property
    def theta(self) -> float:
        """Rectangle axis angle of e1, rad in [0, π/2): the row's ``F_THETA`` column (0 for a merged pair of legs)."""
        return self._s.fits.item(self._j, F_THETA)

    map_structure = _mev_value(0, "fraction of the points on long-occupied map cells (0 without a map)")
    map_free = _mev_value(1, "fraction of the points on observed-free map cells (0 without a map)")
    map_unknown = _mev_value(2, "fraction of the points on never-observed map cells (0 without a map)")
    centroid = _row_view("fits", FIT_CENTROID, "(2,) mean of the points, m")

    @property
    def circle(self) -> np.ndarray:
        """(3,) circle centre x, y and radius, m: a view of the row's circle columns. A row whose circle fit the tracker
        skipped (NaN columns: a cluster the classification did not make a circle, ``shapes.fit_cluster_rows``) is
        fitted first, with the same function on the same points (:func:`dynslam2d.detect.shapes.fit_circle`), and
        the row kept."""
        f = self._s.fits
        j = self._j
        r = f[j, F_CIRCLE_R]
        if r != r:
            f[j, F_CIRCLE_X:F_CIRCLE_RMS + 1] = fit_circle(self.points)
        return f[j, FIT_CIRCLE]
    lo = _row_view("lohi", LOHI_LO, "(2,) lower bounds along e1, e2, m")
    hi = _row_view("lohi", LOHI_HI, "(2,) upper bounds along e1, e2, m")
    rel = _row_view("rel", slice(None), "(2, 2) bool: bound [axis, lower / upper] is real")

    @property
    def free_fraction(self) -> float:
        """Fraction of the points lying where an earlier scan saw through (:class:`Detection`), computed when first
        read if it was given as a test or a pair of legs (class docstring) and kept."""
        v = self._ff
        if type(v) is float:
            return v
        if type(v) is tuple:  # a merged pair of legs (Tracker._merge_legs): the point-weighted mean
            da, db = v
            na, nb = da.n_points, db.n_points
            v = (na * da.free_fraction + nb * db.free_fraction) / (na + nb)
        elif hasattr(v, "fraction"):
            v = v.fraction(self.points)
        else:
            return v
        self._ff = v
        return v

    @free_fraction.setter
    def free_fraction(self, value: float) -> None:
        self._ff = value

    def __reduce__(self) -> tuple:
        return Detection, (self.beams, self.points, self.centroid, self.kind, self.theta, self.lo, self.hi, self.rel,
                           self.circle, self.n_points, self.free_fraction, self.map_structure, self.map_free,
                           self.map_unknown, self.person)


def scan_detections(arrays: ScanArrays, free_fraction: float | object,
                    _new=object.__new__) -> list[ScanDetection]:
    """The scan detections of one scan (``arrays``: its :class:`ScanArrays`), detection j being
    ``ScanDetection(arrays, j, free_fraction)`` (every detection shares ``free_fraction``, the scan's free-space test
    or 0): the slots set directly in one loop, without a constructor call per detection (the tracker makes ≈ 30 per
    scan). ``tests/test_detect_birth_fast.py`` compares every slot with the constructor's."""
    out = []
    append, cls = out.append, ScanDetection
    for j in range(arrays.starts.shape[0]):
        d = _new(cls)
        d._s = arrays
        d._j = j
        d._ff = free_fraction
        d.person = False
        append(d)
    return out


@dataclass(slots=True)
class Measurement:
    """What a detection says about a track's state [p_x, p_y, v_x, v_y] (map frame).

    Attributes:
        z, R: (2,) centre and (2, 2) covariance, used for association (an unobserved axis gets the
            middle of the visible extent with variance sigma_unobserved²).
        H, zm, Rm: the linear measurement used for the Kalman update, (m, 4), (m,), (m, m): one
            position row per observed axis, and along an unobserved axis a zero-velocity
            pseudo-measurement (nothing shows motion there, so none is inferred).
        size_obs, size_kind: per fit axis, the observed extent (m) and SIZE_NONE / SIZE_LOWER /
            SIZE_MEASURED (:mod:`dynslam2d.detect.layout`).
    """

    z: np.ndarray
    R: np.ndarray
    size_obs: np.ndarray
    size_kind: np.ndarray
    H: np.ndarray
    zm: np.ndarray
    Rm: np.ndarray
