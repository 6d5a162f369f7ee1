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


@dataclass(slots=True, eq=False)
class Detection:
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


def _row_view(array: str, cols: slice, doc: str) -> property:
    """A read-only property: the columns ``cols`` of row ``self._j`` of the array attribute ``array`` (a view)."""

    def get(self: ScanDetection) -> np.ndarray:
        return getattr(self, array)[self._j, cols]

    return property(get, doc=doc)


def _mev_value(row: int, doc: str) -> property:
    """A read-only property: row ``row`` (structure, free, unknown) of the scan's (3, nd) map-evidence array ``_mev`` at
    column ``self._j``, as a Python float (0.0 without a map: ``_mev`` None)."""

    def get(self: ScanDetection) -> float:
        m = self._mev
        return 0.0 if m is None else m.item(row, self._j)

    return property(get, doc=doc)


class ScanDetection(Detection):
    """A :class:`Detection` of the tracker's current scan whose small per-detection values are read from the scan's
    arrays when asked for, not made when the detection is made: the tracker makes one per cluster per scan and reads
    them for few. ``centroid``, ``lo``, ``hi``, ``rel``, ``circle`` are views of rows of the scan's fit and bound
    arrays (the values of a :class:`Detection` built with them); ``theta`` and ``map_structure`` / ``map_free`` /
    ``map_unknown`` are Python floats read from the fit row and the map-evidence column (docs/speed.md, pass det32:
    boxed floats kept by every detection cost their free, scans later, in cache misses). A copy (``copy`` /
    ``pickle``) is a plain :class:`Detection`.

    ``fits``: the scan's (k, N_FIT_COLS) fit rows (:func:`dynslam2d.detect.shapes.fit_clusters`; ``theta`` is column
    ``F_THETA``), ``lohi``: (k, 4) bounds lo1, lo2, hi1, hi2, ``rel``: (k, 2, 2) real-bound flags
    (:mod:`dynslam2d.detect.layout`); ``mev``: (3, k) fractions of the points on long-occupied, observed-free and
    never-observed map cells (:mod:`dynslam2d.detect.mapevidence`), or None without a map (all three 0); ``j``: this
    detection's row of them (column of ``mev``); ``a0``: when ≥ 0, ``points`` is the scan's array of every
    detection's points and this detection's are its rows from ``a0`` on (``n_points`` of them).

    ``free_fraction`` may be given as a float, or left to be computed when first read (few are read): as an object
    with ``fraction(points)`` (the scan's free-space test, :class:`dynslam2d.detect.freespace.FreeTest`), or as a
    pair of scan detections (a merged pair of legs: their fractions weighted by their point counts)."""

    __slots__ = ("_fits", "_lohi", "_rel", "_j", "_ff", "_pts", "_a0", "_mev")

    def __init__(self, beams: np.ndarray, points: np.ndarray, kind: str, n_points: int, free_fraction: float | object,
                 fits: np.ndarray, lohi: np.ndarray, rel: np.ndarray, mev: np.ndarray | None, j: int,
                 a0: int = -1) -> None:
        self.beams = beams
        self._pts = points
        self._a0 = a0
        self.kind = kind
        self.n_points = n_points
        self._ff = free_fraction
        self.person = False
        self._fits = fits
        self._lohi = lohi
        self._rel = rel
        self._mev = mev
        self._j = j

    centroid = _row_view("_fits", FIT_CENTROID, "(2,) mean of the points, m")

    @property
    def theta(self) -> float:
        """Rectangle axis angle of e1, rad in [0, π/2): the row's ``F_THETA`` column (0 for a merged pair of legs)."""
        return self._fits.item(self._j, F_THETA)

    map_structure = _mev_value(0, "fraction of the points on long-occupied map cells (0 without a map)")
    map_free = _mev_value(1, "fraction of the points on observed-free map cells (0 without a map)")
    map_unknown = _mev_value(2, "fraction of the points on never-observed map cells (0 without a map)")

    @property
    def circle(self) -> np.ndarray:
        """(3,) circle centre x, y and radius, m: a view of the row's circle columns. A row whose circle fit the tracker
        skipped (NaN columns: a cluster the classification did not make a circle, ``shapes.fit_cluster_rows``) is
        fitted first, with the same function on the same points (:func:`dynslam2d.detect.shapes.fit_circle`), and
        the row kept."""
        f = self._fits
        j = self._j
        r = f[j, F_CIRCLE_R]
        if r != r:
            f[j, F_CIRCLE_X:F_CIRCLE_RMS + 1] = fit_circle(self.points)
        return f[j, FIT_CIRCLE]
    lo = _row_view("_lohi", LOHI_LO, "(2,) lower bounds along e1, e2, m")
    hi = _row_view("_lohi", LOHI_HI, "(2,) upper bounds along e1, e2, m")
    rel = _row_view("_rel", slice(None), "(2, 2) bool: bound [axis, lower / upper] is real")

    @property
    def points(self) -> np.ndarray:
        """(n, 2) map-frame points, m: rows ``a0 … a0 + n_points − 1`` of the ``points`` given (a view made when read:
        the tracker reads a detection's points for few detections per scan), or that array itself when no ``a0``
        (≥ 0) was given."""
        a0 = self._a0
        return self._pts if a0 < 0 else self._pts[a0:a0 + self.n_points]

    @points.setter
    def points(self, value: np.ndarray) -> None:
        self._pts = value
        self._a0 = -1

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


def scan_detections(beams: np.ndarray, points: np.ndarray, starts: list[int], npts: list[int], kinds: list[int],
                    free_fraction: float | object, fits: np.ndarray, lohi: np.ndarray, rel: np.ndarray,
                    mev: np.ndarray | None, _new=object.__new__) -> list[ScanDetection]:
    """The scan detections of one scan, detection j being ``ScanDetection(beams[a0:a0 + n], points, KIND_NAMES[kd], n,
    free_fraction, fits, lohi, rel, mev, j, a0)`` with ``a0, n, kd = starts[j], npts[j], kinds[j]`` (``beams`` /
    ``points``: the scan's concatenated beams and (n, 2) map-frame points of its detections; every detection shares
    ``free_fraction``, the scan's free-space test or 0, and the scan's (3, nd) map evidence ``mev`` or None): the
    slots set directly in one loop, without a constructor call per detection (the tracker makes ≈ 30 per scan).
    ``tests/test_detect_birth_fast.py`` compares every slot with the constructor's."""
    out = []
    append, names, cls = out.append, KIND_NAMES, ScanDetection
    for j, a0, n, kd in zip(range(len(starts)), starts, npts, kinds):
        d = _new(cls)
        d.beams = beams[a0:a0 + n]
        d._pts = points
        d._a0 = a0
        d.kind = names[kd]
        d.n_points = n
        d._ff = free_fraction
        d.person = False
        d._fits = fits
        d._lohi = lohi
        d._rel = rel
        d._mev = mev
        d._j = j
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
