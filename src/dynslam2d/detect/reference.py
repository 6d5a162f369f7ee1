"""Readable reference of the detection rules: plain per-detection Python, not used at run time.

The tracker classifies and measures every cluster of a scan in one pass of the numba kernels
:func:`dynslam2d.detect.kernels.classify_batch` and :func:`dynslam2d.detect.kernels.measure_batch`.
This module states the same rules one detection at a time, as readable code: it is the oracle that
``tests/test_detect_kernels.py`` compares the kernels against (bit for bit) and what
``tests/test_detect_shapes.py`` checks the rules with. Not part of the package's public API.

A 2D scan sees only the sides of an object that face the sensor, so the centre of a box is
observable along an axis only when its extent along that axis is known. For each axis k of the
fitted rectangle (e1, e2), :func:`classify_and_bound` decides which of the two bounds [lo_k, hi_k]
are real:

- a **face** bound: the sensor lies beyond it and the points on it span a visible side;
- an **edge** bound realised by a cluster end point: real when the beam just outside the
  cluster hits something behind the end (or nothing), an artificial break when that
  neighbour is closer (occlusion) or continues the same surface (a grazing wall broken by
  the breakpoint threshold) (:func:`_endpoint_real`).

:func:`measure` then takes the centre along k as the middle of two real bounds, one real bound plus
half the tracked size, or unobserved (the prediction, with a large variance).

Frames: map frame (points already transformed with the scan's pose); the sensor position is the
laser origin in that frame. Units m, rad.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect import layout as L
from dynslam2d.detect.config import FitConfig
from dynslam2d.detect.measure import Detection, Measurement
from dynslam2d.detect.shapes import circle_center_fixed_radius

_H_POS = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


def _endpoint_real(det_uv: np.ndarray, pos: int, k: int, lo_k: float, hi_k: float, beam: int, step: int,
                   ranges: np.ndarray, valid: np.ndarray, pts_map_all: np.ndarray, to_uv, wrapped: bool,
                   max_skip: int, range_max: float, cfg: FitConfig, s_uv: np.ndarray, dphi: float) -> bool:
    """Is the cluster end at ``pos`` (0 or n−1, beam index ``beam``) a real object edge along axis k?"""
    n = ranges.shape[0]
    # the face the end lies on runs along axis k; the next beam would meet that face line
    # r·Δφ / sin β farther on (β = incidence): a sparsely sampled (grazing) face ends anywhere in that gap
    ray = det_uv[pos] - s_uv
    rn = math.hypot(ray[0], ray[1])
    if rn > 0.0:
        sin_b = abs(ray[1 - k]) / rn
        if rn * dphi / max(sin_b, 1e-3) > cfg.edge_max_gap:
            return False
    j = beam
    found = -1
    for _ in range(max_skip + 1):
        j += step
        if wrapped:
            j %= n
        elif j < 0 or j >= n:
            return False  # end of a partial scan: the object may continue outside the field of view
        if valid[j]:
            found = j
            break
    r_e = ranges[beam]
    if found < 0:
        return bool(r_e < 0.95 * range_max)  # nothing behind within reach: a silhouette edge
    r_j = ranges[found]
    if r_j < r_e - cfg.edge_range_jump:
        return False  # something in front occludes the end
    q = to_uv(pts_map_all[found])
    o = 1 - k
    if abs(q[o] - det_uv[pos, o]) < cfg.edge_line_tolerance and (q[k] < lo_k + cfg.face_tolerance
                                                                  or q[k] > hi_k - cfg.face_tolerance):
        return False  # the same surface continues beyond the break (grazing wall)
    return True


def classify_and_bound(beams: np.ndarray, pts: np.ndarray, fit_row: np.ndarray, sensor_xy: np.ndarray,
                       ranges: np.ndarray, valid: np.ndarray, pts_map_all: np.ndarray, wrapped: bool,
                       max_skip: int, range_max: float, cfg: FitConfig, dphi: float = 0.0) -> Detection:
    """Build a :class:`Detection` from one cluster and its row of
    :func:`dynslam2d.detect.shapes.fit_clusters` (map frame); ``dphi`` = |angle increment|, rad."""
    n = int(pts.shape[0])
    theta = float(fit_row[L.F_THETA])
    lo = np.array([fit_row[L.F_LO1], fit_row[L.F_LO2]])
    hi = np.array([fit_row[L.F_HI1], fit_row[L.F_HI2]])
    rect_rms = float(fit_row[L.F_RECT_RMS])
    circ = np.array([fit_row[L.F_CIRCLE_X], fit_row[L.F_CIRCLE_Y], fit_row[L.F_CIRCLE_R]])
    circ_rms = float(fit_row[L.F_CIRCLE_RMS])
    centroid = np.array([fit_row[L.F_CENTROID_X], fit_row[L.F_CENTROID_Y]])
    ext = hi - lo
    rel = np.zeros((2, 2), dtype=bool)
    if n <= cfg.point_max_points or max(ext[0], ext[1]) < cfg.point_max_extent:
        kind = L.KIND_POINT
    elif (n >= cfg.circle_min_points and cfg.circle_min_radius <= circ[2] <= cfg.circle_max_radius
          and circ_rms < cfg.circle_residual_ratio * rect_rms
          and min(ext[0], ext[1]) >= cfg.circle_min_depth_ratio * circ[2]
          and np.hypot(*(circ[:2] - sensor_xy)) > np.hypot(*(centroid - sensor_xy))):
        kind = L.KIND_CIRCLE
    else:
        kind = L.KIND_RECT
    det = Detection(beams, pts, centroid, kind, theta, lo, hi, rel, circ, n)
    if kind != L.KIND_RECT:
        return det
    lo, hi = det.lo, det.hi  # refined in place below (faces)
    uv = det.to_uv(pts)
    s_uv = det.to_uv(sensor_xy)
    to_uv = det.to_uv
    tol = cfg.face_tolerance
    for k in (0, 1):
        o = 1 - k
        near = -1
        if s_uv[k] < lo[k]:
            near = 0
        elif s_uv[k] > hi[k]:
            near = 1
        face = False
        face_line = 0.0
        if near >= 0:
            b = lo[k] if near == 0 else hi[k]
            on = np.abs(uv[:, k] - b) < tol
            if on.sum() >= 2:
                face = float(uv[on, o].max() - uv[on, o].min()) >= cfg.min_face_span
                face_line = float(uv[on, k].mean())
                if face:  # the side's line is its points' median, not their noisy extreme
                    if near == 0:
                        lo[k] = face_line
                    else:
                        hi[k] = face_line
        for side in (0, 1):
            b = lo[k] if side == 0 else hi[k]
            if face and side == near:
                rel[k, side] = True
                continue
            d0 = abs(uv[0, k] - b)
            d1 = abs(uv[n - 1, k] - b)
            if min(d0, d1) >= tol:
                # interior extreme: with a face on the other side it is noise, else a real extreme
                rel[k, side] = (not face) and ext[k] >= cfg.min_face_span
                continue
            if face and ext[k] < cfg.min_face_span:
                continue  # the "far bound" is the face itself seen through noise
            if face:
                # points clearly off the face (measured from its median line, not its noisy extreme)
                if int((np.abs(uv[:, k] - face_line) > tol).sum()) < cfg.min_side_points:
                    continue  # no side seen running away from the face: the depth is noise
            pos = 0 if d0 <= d1 else n - 1
            step = -1 if pos == 0 else 1
            rel[k, side] = _endpoint_real(uv, pos, k, lo[k], hi[k], int(beams[pos]), step, ranges, valid,
                                          pts_map_all, to_uv, wrapped, max_skip, range_max, cfg, s_uv, dphi)
    return det


def measure(det: Detection, sizes: np.ndarray | None, radius: float | None, cfg: FitConfig,
            size_sigma: float = 0.0) -> Measurement:
    """Centre measurement of a detection.

    Args:
        det: the detection.
        sizes: (2,) sizes along the fit axes e1, e2 known by the track (None: defaults).
        radius: the track's radius for circles (None: the fitted one).
        cfg: fit parameters.
        size_sigma: uncertainty of ``sizes``, m (adds (σ/2)² along anchored axes).
    """
    size_obs = np.zeros(2)
    size_kind = np.zeros(2, dtype=np.int8)
    if det.kind == L.KIND_POINT:
        s2 = cfg.sigma_point ** 2
        R = np.diag([s2, s2])
        return Measurement(det.centroid.copy(), R, size_obs, size_kind, _H_POS, det.centroid.copy(), R)
    if det.kind == L.KIND_CIRCLE:
        cx, cy, r = det.circle
        if radius is not None and radius > 0:
            cx, cy, _ = circle_center_fixed_radius(det.points[:, 0].copy(), det.points[:, 1].copy(),
                                                   float(cx), float(cy), float(radius))
        s2 = (1.5 * cfg.sigma_position) ** 2
        size_obs[:] = 2.0 * det.circle[2]
        size_kind[:] = L.SIZE_MEASURED
        z = np.array([cx, cy])
        R = np.diag([s2, s2])
        return Measurement(z, R, size_obs, size_kind, _H_POS, z, R)
    lo, hi = det.lo, det.hi
    ext0, ext1 = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    sz = det.default_sizes(cfg) if sizes is None else sizes
    sp2 = cfg.sigma_position ** 2
    uv = [0.0, 0.0]
    var = [0.0, 0.0]
    observed = [True, True]
    kinds = [L.SIZE_LOWER, L.SIZE_LOWER]
    rel = det.rel
    for k, ext_k in ((0, ext0), (1, ext1)):
        rl, rh = bool(rel[k, 0]), bool(rel[k, 1])
        size_k = max(float(sz[k]), ext_k)
        if sizes is not None and rel[k, 0] != rel[k, 1]:
            size_k = float(sz[k])  # anchored on the one real bound with the track's size (kernels.measure_batch)
        if rl and rh:
            uv[k] = 0.5 * (lo[k] + hi[k])
            var[k] = sp2
            kinds[k] = L.SIZE_MEASURED
        elif rl or rh:
            uv[k] = lo[k] + 0.5 * size_k if rl else hi[k] - 0.5 * size_k
            unc = size_sigma if sizes is not None else 0.5 * size_k
            var[k] = sp2 + 0.25 * unc * unc
        else:
            uv[k] = 0.5 * (lo[k] + hi[k])
            var[k] = cfg.sigma_unobserved ** 2
            observed[k] = False
    c, s = math.cos(det.theta), math.sin(det.theta)
    # rotation with columns e1 = (c, s), e2 = (−s, c)
    z = np.array([c * uv[0] - s * uv[1], s * uv[0] + c * uv[1]])
    v0, v1 = var
    R = np.array([[c * c * v0 + s * s * v1, c * s * (v0 - v1)], [c * s * (v0 - v1), s * s * v0 + c * c * v1]])
    H = np.zeros((2, 4))
    zm = np.zeros(2)
    rm = np.zeros((2, 2))
    axes = ((c, s), (-s, c))
    for k in (0, 1):
        if observed[k]:
            H[k, 0], H[k, 1] = axes[k]
            zm[k] = uv[k]
            rm[k, k] = var[k]
        else:
            H[k, 2], H[k, 3] = axes[k]
            rm[k, k] = cfg.sigma_unobserved_speed ** 2
    return Measurement(z, R, np.array([ext0, ext1]), np.array(kinds, dtype=np.int8), H, zm, rm)


__all__ = ["classify_and_bound", "measure"]
