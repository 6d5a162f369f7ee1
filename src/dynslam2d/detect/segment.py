"""Breakpoint segmentation of a 2D scan into clusters of consecutive beams.

Two consecutive valid beams i, j (at most ``max_skip_beams`` no-return beams between them)
belong to the same cluster when the Euclidean gap between their points is below a threshold
(paper Eq. 1):

- adaptive (Borges & Aldon 2004; the ABD that Konstantinidis et al. 2020 describe):
  ``D = clip(r_i·sin Δφ / sin(λ − Δφ) + 3σ_r, d_min, d_max)`` with Δφ the real angle between
  the two beams (so dropped beams widen the threshold);
- fixed (datmo's actual code, ``Datmo::Clustering`` in kostaskonkk/datmo): ``D = fixed_gap``.

On a 360° scan the last and first valid beams are compared too (wrap-around), and a cluster
may run across the end of the scan. Clusters with fewer than ``min_points`` points are dropped;
clusters with more than ``max_points`` points are marked as static structure (the fit marks
clusters that are too long). Everything is in the sensor frame; the kernel is one O(n) pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynslam2d.detect.config import SegmentConfig
from dynslam2d.detect.frozen import fast_init
from dynslam2d.detect.kernels import (
    DR_ADMIT,
    DR_EXT_LIM,
    DR_FREE,
    DR_FREE_RADIUS,
    DR_MAX_STRUCTURE,
    DR_MIN_FREE,
    DR_OCC,
    DR_SEG_MAX_EXTENT,
    detect_rows,
    world_points,
)
from dynslam2d.detect.shapes import fit_cluster_rows
from dynslam2d.detect.vehicles import doomed_clusters
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.types import Scan


@dataclass(frozen=True, slots=True, eq=False)
class Segmentation:
    """Clusters of one scan.

    Attributes:
        labels: (n_beams,) int32 cluster index of every beam, −1 for beams in no cluster
            (no return, or a dropped small cluster).
        beams: concatenated beam indices of all clusters, each cluster in scan order starting at
            its first beam (a wrapped cluster runs …, n−1, 0, 1, …).
        offsets: (k+1,) cluster c owns ``beams[offsets[c]:offsets[c+1]]``.
        structure: (k,) bool, True for clusters too large to be a moving object.
        wrapped: True if the scan was treated as a closed 360° ring.
        n_dropped: number of clusters dropped for having fewer than min_points points.
    """

    labels: np.ndarray
    beams: np.ndarray
    offsets: np.ndarray
    structure: np.ndarray
    wrapped: bool
    n_dropped: int

    @property
    def n_clusters(self) -> int:
        return int(self.offsets.shape[0] - 1)

    def cluster(self, c: int) -> np.ndarray:
        """Beam indices of cluster ``c``, in scan order."""
        return self.beams[self.offsets[c]:self.offsets[c + 1]]

    def sizes(self) -> np.ndarray:
        """(k,) number of points per cluster."""
        return np.diff(self.offsets)


@njit(cache=True, inline="always")
def _adjacent_trig(angles: np.ndarray, lam: float, trig: np.ndarray) -> None:
    """trig[a] = cos Δφ, sin Δφ, sin(λ − Δφ) and (Δφ ≥ λ) of beams a and a+1 (Δφ = |φ_{a+1} − φ_a|, folded to
    [0, π]): the trigonometry of :func:`_link` for adjacent beams, made once per beam geometry."""
    for a in range(angles.shape[0] - 1):
        dphi = abs(angles[a + 1] - angles[a])
        if dphi > math.pi:
            dphi = 2.0 * math.pi - dphi
        trig[a, 0] = math.cos(dphi)
        trig[a, 1] = math.sin(dphi)
        trig[a, 2] = math.sin(lam - dphi) if dphi < lam else 0.0
        trig[a, 3] = 1.0 if dphi >= lam else 0.0


@njit(cache=True, inline="always")
def _link(ranges: np.ndarray, angles: np.ndarray, trig: np.ndarray, a: int, b: int, fixed: bool, fixed_gap: float,
          lam: float, three_sigma: float, d_min: float, d_max: float) -> bool:
    """Valid beams a and b belong to the same cluster (paper Eq. 1): the gap between their points is below the
    fixed or adaptive threshold; adjacent beams (b = a + 1) read their trigonometry from ``trig``."""
    ra = ranges[a]
    rb = ranges[b]
    if b == a + 1:
        cd = trig[a, 0]
        sd = trig[a, 1]
        sl = trig[a, 2]
        wide = trig[a, 3] != 0.0
    else:
        dphi = abs(angles[b] - angles[a])
        if dphi > math.pi:
            dphi = 2.0 * math.pi - dphi
        cd = math.cos(dphi)
        wide = dphi >= lam
        sd = math.sin(dphi)
        sl = 0.0 if wide else math.sin(lam - dphi)
    gap2 = ra * ra + rb * rb - 2.0 * ra * rb * cd  # law of cosines (as Datmo::Clustering)
    if gap2 < 0.0:
        gap2 = 0.0
    if fixed:
        thr = fixed_gap
    else:
        # paper Eq. 1 / Borges & Aldon 2004 ABD, clamped to [d_min, d_max]
        if wide:
            thr = d_max
        else:
            thr = ra * sd / sl + three_sigma
            if thr < d_min:
                thr = d_min
            elif thr > d_max:
                thr = d_max
    return gap2 < thr * thr


#: columns of :func:`segment_params`' array (the segmentation's configuration values, ``_segment_kernel``'s ``q``)
SP_FIXED = 0  # 1.0 where SegmentConfig.mode is "fixed", else 0.0
SP_FIXED_GAP = 1  # SegmentConfig.fixed_gap, m
SP_LAMBDA = 2  # SegmentConfig.lambda_deg in rad
SP_THREE_SIGMA = 3  # 3 · SegmentConfig.sigma_r, m
SP_D_MIN = 4  # SegmentConfig.d_min, m
SP_D_MAX = 5  # SegmentConfig.d_max, m
SP_MAX_SKIP = 6  # SegmentConfig.max_skip_beams (an integer, exact in a float64)
SP_MIN_POINTS = 7  # SegmentConfig.min_points (an integer)
SP_MAX_POINTS = 8  # SegmentConfig.max_points (an integer)
_SP_N = 9


def segment_params(cfg: SegmentConfig) -> tuple[float, str, np.ndarray]:
    """``cfg``'s values the segmentation reads on every scan, made once: (λ in rad, the wrap-around mode, the float64
    array of columns ``SP_*`` that :func:`_segment_kernel` reads). One array argument instead of nine scalars, each
    converted in Python and typed and unboxed by numba's dispatcher on every call (docs/speed.md, passes trk48,
    trk49); the same floats the scalars were, the integers and the flag exact in a float64."""
    lam = math.radians(cfg.lambda_deg)
    q = np.empty(_SP_N)
    q[SP_FIXED] = 1.0 if cfg.mode == "fixed" else 0.0
    q[SP_FIXED_GAP] = float(cfg.fixed_gap)
    q[SP_LAMBDA] = lam
    q[SP_THREE_SIGMA] = 3.0 * float(cfg.sigma_r)
    q[SP_D_MIN] = float(cfg.d_min)
    q[SP_D_MAX] = float(cfg.d_max)
    q[SP_MAX_SKIP] = int(cfg.max_skip_beams)
    q[SP_MIN_POINTS] = int(cfg.min_points)
    q[SP_MAX_POINTS] = int(cfg.max_points)
    return lam, cfg.wrap_around, q


@njit(cache=True)
def _segment_kernel(ranges: np.ndarray, angles: np.ndarray, mask: np.ndarray, trig: np.ndarray, fill_trig: bool,
                    q: np.ndarray, wrap: bool, points: bool, cos_a: np.ndarray, sin_a: np.ndarray, pose_c: float,
                    pose_s: float, pose_x: float, pose_y: float, ref: bool, pose_th: float, gpar: np.ndarray,
                    reach: float) -> tuple:
    """The whole segmentation in one pass: the valid beams of ``mask``, the links between consecutive ones (the
    last to the first when ``wrap`` and more than two beams are valid), the runs of linked beams → (labels, beams,
    offsets, structure, n_dropped, wrapped, ax, ay, px, py, pts). ``q``: :func:`segment_params`' array (the mode
    flag, gap, λ, 3σ_r, d_min, d_max, max_skip_beams, min_points, max_points). ``fill_trig``: fill ``trig`` first
    (:func:`_adjacent_trig`). Where ``points``, the last five are
    :func:`~dynslam2d.detect.kernels.world_points` of the clusters' beams (``mask`` as its ``valid``; ``cos_a``,
    ``sin_a`` the beam angles' cos / sin, ``pose_c``, ``pose_s`` the pose's θ's, ``pose_x``, ``pose_y`` its position;
    map frame, m): the tracker's two calls as one (docs/speed.md, pass det25); else empty. Where ``ref``, two more:
    the free-space reference's arrays of this scan (:meth:`~dynslam2d.detect.freespace.FreeSpaceMemory.make_ref`:
    the ranges, +inf where ``mask`` is False, and the (7,) row of the pose's inverse — ``pose_th`` its θ, rad — then
    ``gpar``'s angle_min, increment and full-circle flag and ``reach``, the scan's range_max, m), the free-space
    memory's kernel folded into this call (docs/speed.md, pass trk60); else two empty arrays."""
    fixed = q[SP_FIXED] != 0.0
    fixed_gap = q[SP_FIXED_GAP]
    lam = q[SP_LAMBDA]
    three_sigma = q[SP_THREE_SIGMA]
    d_min = q[SP_D_MIN]
    d_max = q[SP_D_MAX]
    max_skip = int(q[SP_MAX_SKIP])
    min_points = int(q[SP_MIN_POINTS])
    max_points = int(q[SP_MAX_POINTS])
    n = ranges.shape[0]
    if fill_trig:
        _adjacent_trig(angles, lam, trig)
    valid_idx = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):  # (branch-free: the slot after the last valid beam is overwritten)
        valid_idx[m] = i
        m += 1 if mask[i] else 0
    wrap = wrap and m > 2
    # links[j] = 1 if valid beam j links to valid beam j+1 (the last one to the first when wrap)
    links = np.empty(m, dtype=np.uint8)
    links[:] = 0
    for j in range(m):
        if j == m - 1 and not wrap:
            break
        a = valid_idx[j]
        b = valid_idx[j + 1] if j + 1 < m else valid_idx[0]  # (the last to the first: no modulo per beam)
        skipped = b - a - 1 if b > a else b + n - a - 1
        if skipped > max_skip or (m == 1):
            continue
        if _link(ranges, angles, trig, a, b, fixed, fixed_gap, lam, three_sigma, d_min, d_max):
            links[j] = 1
    labels = np.empty(n, dtype=np.int32)
    labels[:] = -1
    beams = np.empty(m, dtype=np.int64)
    offsets = np.empty(m + 1, dtype=np.int64)
    offsets[:] = 0
    # start right after the last break so that no run is cut by the array end and clusters come in scan order (a
    # cluster wrapping past the end comes first); no valid beam (m = 0): no run, no cluster, the same empty results
    start = 0
    if wrap:
        start = -1
        for j in range(m - 1, -1, -1):
            if links[j] == 0:
                start = (j + 1) % m
                break
        if start == -1:  # one closed ring: a single cluster
            start = 0
    k = 0
    nb = 0
    dropped = 0
    count = 0
    j = start - 1
    for t in range(m):
        j += 1
        if j == m:
            j = 0
        beams[nb + count] = valid_idx[j]
        count += 1
        last = t == m - 1
        if last or links[j] == 0:
            if count >= min_points:
                for q in range(count):
                    labels[beams[nb + q]] = k
                nb += count
                k += 1
                offsets[k] = nb
            else:
                dropped += 1
            count = 0
    structure = np.empty(k, dtype=np.bool_)
    for c in range(k):
        structure[c] = offsets[c + 1] - offsets[c] > max_points
    beams = beams[:nb]
    if points:  # (one call site: world_points is inlined here, once)
        ax, ay, px, py, pts = world_points(ranges, mask, cos_a, sin_a, pose_c, pose_s, pose_x, pose_y, beams)
    else:
        ax = ay = px = py = np.empty(0)
        pts = np.empty((0, 2))
    if ref:  # (FreeSpaceMemory.make_ref's arrays, _ref_arrays' loop and its arithmetic of Pose2D.inverse)
        rr = np.empty(n)
        for i in range(n):
            rr[i] = ranges[i] if mask[i] else np.inf
        par = np.empty(7)
        par[0] = -pose_c * pose_x - pose_s * pose_y
        par[1] = pose_s * pose_x - pose_c * pose_y
        par[2] = (-pose_th + math.pi) % (2.0 * math.pi) - math.pi  # (types.wrap_angle, Python's float modulo)
        par[3] = gpar[0]
        par[4] = gpar[1]
        par[5] = gpar[2]
        par[6] = reach
    else:
        rr = par = np.empty(0)
    return labels, beams, offsets[:k + 1], structure, dropped, wrap, ax, ay, px, py, pts, rr, par


def is_full_circle(scan: Scan) -> bool:
    """True when the scan's beams cover 360° (n·|Δφ| ≥ 2π − 1.5|Δφ|)."""
    inc = abs(scan.angle_increment)
    return scan.n_beams * inc >= 2.0 * math.pi - 1.5 * inc


#: per beam geometry (n, angle_min, angle_increment): the beam angles (:attr:`Scan.angles`, the same values for every
#: scan of that geometry), per λ the adjacent beams' trigonometry (:func:`_adjacent_trig`), the angles' cos / sin,
#: whether the beams cover 360° (:func:`is_full_circle`) and (angle_min, increment, 1.0 / 0.0 for that flag) as the
#: float64 array a free-space reference's row holds (``_segment_kernel``'s ``gpar``); a few entries
_GEOMETRY: dict[tuple, tuple[np.ndarray, dict[float, np.ndarray], np.ndarray, np.ndarray, bool, np.ndarray]] = {}
_GEOMETRY_MAX = 16
_make_segmentation = fast_init(Segmentation)  # (the frozen dataclass without its __init__'s object.__setattr__)


def segment_scan(scan: Scan, config: SegmentConfig | None = None, valid: np.ndarray | None = None, *,
                 checked: bool = False) -> Segmentation:
    """Split ``scan`` into clusters of consecutive beams (paper Eq. 1).

    Args:
        scan: the scan (sensor frame).
        config: segmentation parameters (defaults if None).
        valid: optional (n,) bool mask of beams to use (default ``scan.valid_mask()``; zero
            ranges are always excluded).
        checked: ``valid`` is a C-contiguous bool mask that holds only beams of ``scan.valid_mask()`` with
            a range > 0 already (the tracker's): used as it is.

    Returns:
        A :class:`Segmentation`; a scan with no valid return gives zero clusters.
    """
    if not (checked and valid is not None):
        valid = scan.valid_mask() if valid is None else np.asarray(valid, dtype=bool) & scan.valid_mask()
        valid &= scan.ranges > 0.0
    return _segment(scan, config or SegmentConfig(), valid, None)[0]


def segment_points(scan: Scan, config: SegmentConfig, valid: np.ndarray, pose_x: float, pose_y: float,
                   pose_theta: float, params: tuple | None = None, ref: bool = False) -> tuple:
    """:func:`segment_scan` with ``checked`` (``valid``: a C-contiguous bool mask of beams of ``scan.valid_mask()``
    with a range > 0) and the beams in the map frame in the same call (the tracker's; docs/speed.md, pass det25):
    ``(segmentation, ax, ay, px, py, pts, r, par)`` with :func:`~dynslam2d.detect.kernels.world_points`' results for
    the pose (``pose_x``, ``pose_y`` in m, ``pose_theta`` in rad; invalid beams at the pose, ``px``, ``py``, ``pts`` the
    clusters' beams in the segmentation's order). ``params``: :func:`segment_params` of ``config`` when made already
    (the tracker's, once). ``r``, ``par``: where ``ref``, the arrays of the scan's free-space reference at the pose
    (:meth:`dynslam2d.detect.freespace.FreeSpaceMemory.ref_of`; ``valid`` as its mask), made in the same kernel call
    (docs/speed.md, pass trk60); else empty."""
    return _segment(scan, config, valid, (math.cos(pose_theta), math.sin(pose_theta), pose_x, pose_y, pose_theta),
                    params, ref)


_NO_TRIG = np.zeros(0)  # (cos / sin of no beams: segment_scan's call, which transforms no point)


def _scan_args(scan: Scan, cfg: SegmentConfig, params: tuple | None) -> tuple:
    """The segmentation kernel's per-geometry arguments for ``scan``: (angles, trig, fill_trig, cos_a, sin_a, gpar,
    wrap, q) (:data:`_GEOMETRY`'s entry of its beam geometry, made on its first scan; ``trig`` the adjacent beams'
    trigonometry for ``cfg``'s λ, ``fill_trig`` True where it is new and the kernel fills it; ``wrap`` the wrap-around
    mode's answer; ``q``: :func:`segment_params`' array, ``params`` when given, else made here)."""
    key = (scan.ranges.shape[0], scan.angle_min, scan.angle_increment)
    geo = _GEOMETRY.get(key)
    if geo is None:
        if len(_GEOMETRY) >= _GEOMETRY_MAX:
            _GEOMETRY.clear()
        a = scan.angles
        full = is_full_circle(scan)
        geo = _GEOMETRY[key] = (a, {}, np.cos(a), np.sin(a), full,
                                np.array([float(scan.angle_min), float(scan.angle_increment), 1.0 if full else 0.0]))
    angles, trigs, cos_a, sin_a, full, gpar = geo
    lam, mode, q = segment_params(cfg) if params is None else params
    trig = trigs.get(lam)
    fill = trig is None
    if fill:
        trig = trigs[lam] = np.zeros((max(key[0], 1), 4))
    # (the wrap-around mode; ``full``: is_full_circle of the key's beam count and increment, kept with them)
    if mode == "auto":
        wrap = full
    elif mode == "always":
        wrap = True
    elif mode == "never":
        wrap = False
    else:
        raise KeyError(mode)
    return angles, trig, fill, cos_a, sin_a, gpar, wrap, q


def _segment(scan: Scan, cfg: SegmentConfig, mask: np.ndarray, pose: tuple | None, params: tuple | None = None,
             ref: bool = False) -> tuple:
    """The segmentation kernel's call for :func:`segment_scan` (``pose`` None) and :func:`segment_points` (``pose``:
    cos θ, sin θ, x, y, θ): (segmentation, ax, ay, px, py, pts, r, par). ``params``: :func:`segment_params` of ``cfg``
    (None: made here); ``ref``: with the free-space reference's arrays ``r``, ``par`` (needs ``pose``)."""
    angles, trig, fill, cos_a, sin_a, gpar, wrap, q = _scan_args(scan, cfg, params)
    if pose is None:
        points, cos_a, sin_a, c, s, x, y, th = False, _NO_TRIG, _NO_TRIG, 1.0, 0.0, 0.0, 0.0, 0.0
    else:
        points = True
        c, s, x, y, th = pose
    labels, beams, offsets, structure, dropped, wrapped, ax, ay, px, py, pts, r, par = _segment_kernel(
        scan.ranges, angles, mask, trig, fill, q, wrap, points, cos_a, sin_a, c, s, x, y, ref and points, th, gpar,
        float(scan.range_max) if ref else 0.0)
    return _make_segmentation(labels, beams, offsets, structure, wrapped, dropped), ax, ay, px, py, pts, r, par


#: columns of the tracker's array of :func:`~dynslam2d.detect.shapes.fit_cluster_rows`' scalar arguments
#: (:func:`detect_scan`'s ``fq``; ``Tracker._fit_q``): the integers exact in a float64, converted back in the kernel
FQ_CRITERION = 0  # shapes.CRITERIA's code of FitConfig.criterion (an integer)
FQ_D0 = 1  # FitConfig.closeness_d0, m
FQ_CIRCLE_MIN_POINTS = 2  # FitConfig.circle_min_points (an integer)
FQ_STRIDE = 3  # FitConfig.coarse_stride (an integer)
FQ_POINT_MAX_POINTS = 4  # FitConfig.point_max_points
FQ_POINT_MAX_EXTENT = 5  # FitConfig.point_max_extent, m
FQ_MAX_EXTENT = 6  # vehicles.extent_limit, m
FQ_THIN = 7  # the short side below which a cluster cannot be a circle, m (−inf: no such side)
FQ_CIRCLE_MAX_RADIUS = 8  # FitConfig.circle_max_radius, m
FQ_DEPTH_RATIO = 9  # FitConfig.circle_min_depth_ratio
FQ_RESIDUAL_RATIO = 10  # FitConfig.circle_residual_ratio
N_FQ = 11


@njit(cache=True)
def detect_scan(ranges: np.ndarray, angles: np.ndarray, mask: np.ndarray, trig: np.ndarray, fill_trig: bool,
                q: np.ndarray, wrap: bool, cos_a: np.ndarray, sin_a: np.ndarray, pose_c: float, pose_s: float,
                pose_x: float, pose_y: float, ref: bool, pose_th: float, gpar: np.ndarray, range_max: float,
                fit_angles: np.ndarray, fit_trig: np.ndarray, fq: np.ndarray, p: np.ndarray, has_map: bool,
                logodds: np.ndarray, i0: int, j0: int, res: float, dphi: float) -> tuple:
    """The tracker's detection chain in one call (docs/speed.md, pass trk72: one dispatch instead of three, and
    none of the Python between them): :func:`_segment_kernel` with the beams in the map frame (its arguments as
    :func:`segment_points` gives them, ``reach`` = ``range_max`` where ``ref``), the shape fits of the clusters not
    marked as structure (:func:`~dynslam2d.detect.shapes.fit_cluster_rows` on ``fit_angles`` / ``fit_trig`` with
    ``fq``'s ``FQ_*`` values, the circles the classification never reads skipped) and
    :func:`~dynslam2d.detect.kernels.detect_rows` (``p``: ``detect_params``' array; the sensor at ``pose_x``,
    ``pose_y``; ``range_max`` in m, ``dphi`` the beams' |increment| in rad; the map ``logodds`` / ``i0`` / ``j0`` /
    ``res`` where ``has_map``). Returns the segmentation's (beams, offsets, n_dropped, wrapped) (its labels and
    structure flags: :func:`segmentation_of`), the clusters' (m, 2) map-frame points ``pts``, the free-space
    reference's ``r``, ``par`` (empty without ``ref``), then ``detect_rows``' 31 results in their order but that the
    leg merge's first ten and its ``mmev`` (first, second, ki, kinds, fits, lohi, rel, starts, npts; mbeams, pts,
    mmev) come as one tuple where a pair was merged and as None where none was, its ``px``, ``py`` following it
    (27 values: pass det109). ``mmev``'s kept detections' columns (where a pair was merged and ``has_map``) are
    written too: column r < nk the kept detection ``ki[r]``'s column of the fractions (the values its own detection
    reads), so that ``mmev`` holds every final row's evidence."""
    # (True, typed as a bool and not as a literal: a literal argument would compile the callee once more)
    yes = ranges.shape[0] >= 0
    labels, beams, offsets, structure, dropped, wrapped, ax, ay, px, py, pts, rr, par = _segment_kernel(
        ranges, angles, mask, trig, fill_trig, q, wrap, yes, cos_a, sin_a, pose_c, pose_s, pose_x, pose_y, ref,
        pose_th, gpar, range_max if ref else 0.0)
    k = structure.shape[0]
    # (the clusters the classification drops whatever their fit, not fitted: passed to detect_rows as structure, the
    # classification's only read of it; pass det118)
    doomed = doomed_clusters(px, py, offsets, structure, fit_trig, p[DR_EXT_LIM], p[DR_ADMIT] != 0.0,
                             p[DR_SEG_MAX_EXTENT], has_map, logodds, i0, j0, res, p[DR_OCC], p[DR_FREE],
                             int(p[DR_FREE_RADIUS]), p[DR_MAX_STRUCTURE], p[DR_MIN_FREE])
    fit_mask = np.empty(k, dtype=np.bool_)
    for c in range(k):
        fit_mask[c] = not doomed[c]
    fits = fit_cluster_rows(px, py, offsets, fit_mask, fit_angles, fit_trig, int(fq[FQ_CRITERION]), fq[FQ_D0],
                            int(fq[FQ_CIRCLE_MIN_POINTS]), int(fq[FQ_STRIDE]), yes, fq[FQ_POINT_MAX_POINTS],
                            fq[FQ_POINT_MAX_EXTENT], fq[FQ_MAX_EXTENT], fq[FQ_THIN], fq[FQ_CIRCLE_MAX_RADIUS],
                            fq[FQ_DEPTH_RATIO], fq[FQ_RESIDUAL_RATIO])
    (starts, npts, kinds, lohi, rel, sfits, mfr, first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2, px2,
     py2, mbeams, mpts, mmev, theta, centroid, circle, z, R, H, zm, Rm, size_obs, size_kind) = detect_rows(
        px, py, beams, offsets, fits, doomed, pose_x, pose_y, ranges, mask, ax, ay, wrapped, range_max, dphi, p,
        has_map, logodds, i0, j0, res)
    if ki.shape[0] and mmev.shape[1]:  # (a pair merged, with a map: the kept rows' columns)
        for r in range(ki.shape[0]):
            for e in range(3):
                mmev[e, r] = mfr[e, ki[r]]
    # (the leg merge's twelve arrays as one tuple where a pair was merged, else None: without a pair they are empty or
    # the selected rows again, and each array returned costs Python a boxed object, ≈ 0.2–0.3 µs; pass det109)
    merged = (first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2, mbeams, mpts, mmev) if first.shape[0] \
        else None
    return (beams, offsets, dropped, wrapped, pts, rr, par, starts, npts, kinds, lohi, rel, sfits, mfr, merged, px2,
            py2, theta, centroid, circle, z, R, H, zm, Rm, size_obs, size_kind)


def segmentation_of(beams: np.ndarray, offsets: np.ndarray, n: int, max_points: int, wrapped: bool,
                    dropped: int) -> Segmentation:
    """The :class:`Segmentation` :func:`_segment_kernel` returns, from its ``beams``, ``offsets`` (the clusters' beam
    indices), the scan's beam count ``n``, ``SegmentConfig.max_points``, ``wrapped`` and the dropped count: its
    ``labels`` (cluster c on the beams ``beams[offsets[c]:offsets[c + 1]]``, −1 elsewhere; int32) and ``structure``
    (more than ``max_points`` points) made as the kernel makes them. :func:`detect_scan` returns neither (the
    tracker reads them only when ``last_segmentation`` is read; pass det109)."""
    sizes = np.diff(offsets)
    labels = np.full(n, -1, dtype=np.int32)
    labels[beams] = np.repeat(np.arange(sizes.shape[0], dtype=np.int32), sizes)
    return _make_segmentation(labels, beams, offsets, sizes > max_points, wrapped, dropped)
