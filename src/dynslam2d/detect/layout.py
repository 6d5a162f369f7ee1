"""Names of the packed per-cluster arrays of ``detect/`` and of the detection kind codes, in one place.

The tracker's per-scan numba kernels pass clusters as packed float arrays; these module-level
integers name their columns. numba freezes module-level integers into the compiled code as
constants, so the kernels index with these names at no cost (changing a value recompiles them).

- ``fits`` — (k, :data:`N_FIT_COLS`) rows of :func:`dynslam2d.detect.shapes.fit_clusters`:
  the rectangle (axis angle θ of e1 in rad, bounds along e1 and e2 in m, rms residual in m),
  the circle (centre x, y and radius in m, rms residual in m) and the centroid (x, y in m),
  all in the frame of the input points (the map frame in the tracker).
- ``lohi`` — (k, 4) refined rectangle bounds of :func:`dynslam2d.detect.kernels.classify_batch`:
  lo1, lo2, hi1, hi2 (m, along e1 and e2), i.e. ``lohi[:, LOHI_LO]`` is the (k, 2) lower corner
  and ``lohi[:, LOHI_HI]`` the upper one in (e1, e2) coordinates.
- kind codes — the kernels' int8 code of a detection's model; :class:`~dynslam2d.detect.measure.Detection`
  carries the name (:data:`KIND_NAMES` maps code → name, :data:`KIND_CODES` name → code).
- size kinds — per fit axis, what a measurement says about the object's extent along it.
- :class:`DetectionBatch` — the per-detection arrays of one scan, in the argument order of
  :func:`dynslam2d.detect.kernels.measure_batch` / ``gate_costs`` (pass it with ``*batch``);
  :class:`MeasureRows` — what ``measure_batch`` returns.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# ---------------------------------------------------------------- fits columns (shapes.fit_clusters)
F_THETA = 0  #: rectangle axis angle of e1, rad in [0, π/2)
F_LO1 = 1  #: rectangle lower bound along e1, m
F_HI1 = 2  #: rectangle upper bound along e1, m
F_LO2 = 3  #: rectangle lower bound along e2, m
F_HI2 = 4  #: rectangle upper bound along e2, m
F_RECT_RMS = 5  #: rectangle fit rms residual, m (inf when not fitted)
F_CIRCLE_X = 6  #: circle centre x, m
F_CIRCLE_Y = 7  #: circle centre y, m
F_CIRCLE_R = 8  #: circle radius, m
F_CIRCLE_RMS = 9  #: circle fit rms residual, m (inf when not fitted)
F_CENTROID_X = 10  #: mean of the cluster's points, x, m
F_CENTROID_Y = 11  #: mean of the cluster's points, y, m
N_FIT_COLS = 12  #: number of columns of ``fits``

#: Column ranges of ``fits``: the rectangle (θ, lo1, hi1, lo2, hi2, rms), the circle (cx, cy, r) with its
#: rms, the circle alone (cx, cy, r), the circle centre and the centroid (x, y).
FIT_RECT = slice(F_THETA, F_RECT_RMS + 1)
FIT_CIRCLE_FIT = slice(F_CIRCLE_X, F_CIRCLE_RMS + 1)
FIT_CIRCLE = slice(F_CIRCLE_X, F_CIRCLE_R + 1)
FIT_CIRCLE_CENTRE = slice(F_CIRCLE_X, F_CIRCLE_Y + 1)
FIT_CENTROID = slice(F_CENTROID_X, F_CENTROID_Y + 1)

# ---------------------------------------------------------------- lohi columns (kernels.classify_batch)
L_LO1 = 0  #: lower bound along e1, m
L_LO2 = 1  #: lower bound along e2, m
L_HI1 = 2  #: upper bound along e1, m
L_HI2 = 3  #: upper bound along e2, m
LOHI_LO = slice(L_LO1, L_LO2 + 1)  #: (lo1, lo2)
LOHI_HI = slice(L_HI1, L_HI2 + 1)  #: (hi1, hi2)

# ---------------------------------------------------------------- detection kinds
K_POINT, K_CIRCLE, K_RECT = 0, 1, 2  #: kind codes of the kernels (int8)
KIND_POINT = "point"
KIND_CIRCLE = "circle"
KIND_RECT = "rect"
#: kind name of each code (index = code)
KIND_NAMES = (KIND_POINT, KIND_CIRCLE, KIND_RECT)
#: kind code of each name
KIND_CODES = {name: code for code, name in enumerate(KIND_NAMES)}

# ---------------------------------------------------------------- per-axis size observation kinds
SIZE_NONE, SIZE_LOWER, SIZE_MEASURED = 0, 1, 2  #: nothing / a lower bound / the full extent seen



class DetectionBatch(NamedTuple):
    """Per-detection arrays of one scan (m detections, map frame), as the kernels take them.

    The field order is the kernels' argument order: ``measure_batch(rows, *batch, ...)``.
    """

    kind: np.ndarray  #: (m,) int8 kind code (K_*)
    theta: np.ndarray  #: (m,) rectangle axis angle of e1, rad
    lohi: np.ndarray  #: (m, 4) bounds lo1, lo2, hi1, hi2 along e1, e2 (columns L_*), m
    rel: np.ndarray  #: (m, 2, 2) bool: bound [axis, lower / upper] is real
    centroid: np.ndarray  #: (m, 2) mean of the points, m
    circle: np.ndarray  #: (m, 3) circle centre x, y and radius, m
    px: np.ndarray  #: (n,) x of the detections' points (concatenated), m
    py: np.ndarray  #: (n,) y of the detections' points, m
    start: np.ndarray  #: (m,) first index of each detection's points in px / py
    npts: np.ndarray  #: (m,) number of points of each detection


class MeasureRows(NamedTuple):
    """Result of :func:`dynslam2d.detect.kernels.measure_batch`: the fields of
    :class:`dynslam2d.detect.measure.Measurement` stacked over r rows (map frame, m, m²)."""

    z: np.ndarray  #: (r, 2) centre for association
    R: np.ndarray  #: (r, 2, 2) its covariance
    H: np.ndarray  #: (r, 2, 4) Kalman measurement matrix
    zm: np.ndarray  #: (r, 2) Kalman measurement
    Rm: np.ndarray  #: (r, 2, 2) its covariance
    size_obs: np.ndarray  #: (r, 2) observed extent along the fit axes
    size_kind: np.ndarray  #: (r, 2) int8 SIZE_*


__all__ = [
    "DetectionBatch", "MeasureRows",
    "FIT_CENTROID", "FIT_CIRCLE", "FIT_CIRCLE_CENTRE", "FIT_CIRCLE_FIT", "FIT_RECT", "F_CENTROID_X", "F_CENTROID_Y",
    "F_CIRCLE_R", "F_CIRCLE_RMS", "F_CIRCLE_X", "F_CIRCLE_Y", "F_HI1", "F_HI2", "F_LO1", "F_LO2", "F_RECT_RMS",
    "F_THETA", "KIND_CIRCLE", "KIND_CODES", "KIND_NAMES", "KIND_POINT", "KIND_RECT", "K_CIRCLE", "K_POINT",
    "K_RECT", "LOHI_HI", "LOHI_LO", "L_HI1", "L_HI2", "L_LO1", "L_LO2", "N_FIT_COLS", "SIZE_LOWER",
    "SIZE_MEASURED", "SIZE_NONE",
]
