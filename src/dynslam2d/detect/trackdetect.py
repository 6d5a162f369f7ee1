"""Step 3 of ``Tracker.update`` (detect/tracker.py): the scan's detections in the map frame (segmentation, paper
Eq. 1; shape fits, paper Eq. 2; classification, the map-evidence columns, the leg merge of people) and their
default measurements. Split out of ``detect/tracker.py`` (docs/speed.md, pass trktable)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels import (
    _P_CIRCLE_DEPTH_RATIO,
    _P_CIRCLE_MAX_RADIUS,
    _P_CIRCLE_MIN_RADIUS,
    _P_CIRCLE_RES_RATIO,
    _P_POINT_MAX_EXTENT,
    _P_POINT_MAX_POINTS,
    detect_params,
    measure_batch,
    merge_legs,
)
from dynslam2d.detect.layout import (
    F_THETA,
    FIT_CENTROID,
    FIT_CIRCLE,
    DetectionBatch,
    MeasureRows,
)
from dynslam2d.detect.measure import Detection, ScanArrays, ScanDetection, scan_detections
from dynslam2d.detect.segment import (
    FQ_CIRCLE_MAX_RADIUS,
    FQ_CIRCLE_MIN_POINTS,
    FQ_CRITERION,
    FQ_D0,
    FQ_DEPTH_RATIO,
    FQ_MAX_EXTENT,
    FQ_POINT_MAX_EXTENT,
    FQ_POINT_MAX_POINTS,
    FQ_RESIDUAL_RATIO,
    FQ_STRIDE,
    FQ_THIN,
    N_FQ,
    SP_MAX_POINTS,
    Segmentation,
    _scan_args,
    detect_scan,
    segment_params,
    segmentation_of,
)
from dynslam2d.detect.shapes import CRITERIA
from dynslam2d.detect.tracktable import _NO_IDX
from dynslam2d.detect.vehicles import _NO_MAP, extent_limit
from dynslam2d.types import Pose2D, Scan

#: no map evidence (the leg merge's ``mev`` argument without a map: no column; shared, never written)
_NO_MEV = np.zeros((3, 0))
_tuple_new = tuple.__new__


def _thin(depth_ratio: float, min_radius: float) -> float:
    """The short side (m) below which a cluster cannot be a circle: ``circle_min_depth_ratio`` · ``circle_min_radius``
    (a circle needs short side ≥ ratio · r with r ≥ the minimum radius; −inf for a negative ratio, which the
    configuration refuses)."""
    return depth_ratio * min_radius if depth_ratio >= 0.0 else -math.inf


class TrackDetect:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the detection step (``_detect``, ``_merge_legs``)."""

    #: the rectangle search's table of cos, sin and atan2 of ``_angles`` (``shapes.fit_cluster_rows`` fills it on
    #: the first call) and the angles it was made for
    _fit_trig: np.ndarray | None = None
    _fit_trig_of: np.ndarray | None = None
    #: this scan's ``map_structure`` column (:meth:`_structure_column`: the detection list it is of and the list;
    #: None: not read yet) and the (3, nd) map evidence of the final rows it is read from (None: from the detections)
    _ms: tuple[list, list[float]] | None = None
    #: the segmentation's per-geometry arguments (``segment._scan_args``' with ``fill`` False) for the beam geometry
    #: key (beam count, angle_min, angle_increment) and ``_seg_p`` they were made for (None: none yet)
    _scan_geo: tuple | None = None
    _ms_ev: np.ndarray | None = None

    #: :attr:`last_segmentation`'s value: a Segmentation, None, or the arguments of the one made when it is read
    _seg: object = None

    @property
    def last_segmentation(self) -> Segmentation | None:
        """The segmentation of the last scan :meth:`_detect` saw (its clusters, paper Eq. 1; None before the first):
        made from the kernel's arrays when first read (nothing in the pipeline reads it per scan; docs/speed.md,
        pass det81), the same object on every later read."""
        s = self._seg
        if type(s) is tuple:  # (q: the segmentation's segment_params array)
            beams, offsets, n, q, wrapped, dropped = s
            s = self._seg = segmentation_of(beams, offsets, n, int(q[SP_MAX_POINTS]), wrapped, dropped)
        return s

    @last_segmentation.setter
    def last_segmentation(self, value: Segmentation | None) -> None:
        self._seg = value

    def _detect_setup(self) -> None:
        """The detection step's configuration values, made once per tracker (after ``_fit_p``): ``_seg_p``, the
        segmentation's (:func:`~dynslam2d.detect.segment.segment_params`), ``_det_p``,
        :func:`~dynslam2d.detect.kernels.detect_params`' array for ``detect_rows``, and ``_fit_q``,
        ``fit_cluster_rows``' eleven scalar arguments after its arrays (but ``skip``, True) as the float64 array of
        columns ``segment.FQ_*`` that :func:`~dynslam2d.detect.segment.detect_scan` reads (the same floats the call
        converted on every scan before pass trk49; the integers exact in a float64, made integers again in the
        kernel; docs/speed.md passes trk49, trk72)."""
        cfg = self.config
        fc, fp = cfg.fit, self._fit_p
        ext_lim = extent_limit(cfg)
        self._seg_p = segment_params(cfg.segment)
        self._det_p = detect_params(fp, cfg.segment, fc, cfg.tracker, ext_lim)
        fq = np.empty(N_FQ)
        fq[FQ_CRITERION] = CRITERIA[fc.criterion]
        fq[FQ_D0] = fc.closeness_d0
        fq[FQ_CIRCLE_MIN_POINTS] = fc.circle_min_points
        fq[FQ_STRIDE] = fc.coarse_stride
        fq[FQ_POINT_MAX_POINTS] = fp.item(_P_POINT_MAX_POINTS)
        fq[FQ_POINT_MAX_EXTENT] = fp.item(_P_POINT_MAX_EXTENT)
        fq[FQ_MAX_EXTENT] = ext_lim
        fq[FQ_THIN] = _thin(fp.item(_P_CIRCLE_DEPTH_RATIO), fp.item(_P_CIRCLE_MIN_RADIUS))
        fq[FQ_CIRCLE_MAX_RADIUS] = fp.item(_P_CIRCLE_MAX_RADIUS)
        fq[FQ_DEPTH_RATIO] = fp.item(_P_CIRCLE_DEPTH_RATIO)
        fq[FQ_RESIDUAL_RATIO] = fp.item(_P_CIRCLE_RES_RATIO)
        self._fit_q = fq

    def _detect(self, scan: Scan, pose: Pose2D) -> list[Detection]:
        cfg = self.config
        st = self.stats
        ranges = scan.ranges
        # (every valid range is ≥ range_min > 0 already where range_min > 0: the scan's own mask, not a copy — nothing
        # below writes to it, the kernels and the free-space reference only read it; else a copy without the zeros)
        if scan.range_min > 0.0:
            valid = scan.valid_view()
        else:
            valid = scan.valid_mask()  # (a copy)
            valid &= ranges > 0.0
        # the whole chain in one kernel call (segment.detect_scan, pass trk72): the segmentation and every beam in
        # the map frame (invalid ones at the pose), with the free-space memory's reference of this scan (its arrays:
        # FreeSpaceMemory.make_ref's, pass trk60); the shape fits (without the circle fits the classification never
        # reads: shapes.fit_cluster_rows, NaN columns that ScanDetection.circle fits when read); the classification
        # and bounds of every cluster (reference.classify_and_bound), the vehicle-size clusters' map test
        # (detect/vehicles.py), the kept clusters' rows and their points' map evidence; where people are merged and
        # there are two detections or more, the leg pairs merged; the final rows' DetectionBatch columns and their
        # default measurements (MeasureRows' fields): kernels.detect_rows, passes fus40, trk41. The configuration's
        # values in arrays made once (_seg_p, _fit_q, _det_p: _detect_setup, passes trk49, trk72)
        free = self._free
        angles = self._angles
        ftrig = self._fit_trig
        if ftrig is None or self._fit_trig_of is not angles:
            ftrig = self._fit_trig = np.full((3, angles.shape[0]), np.nan)
            self._fit_trig_of = angles
        view = self._map
        if view is None:
            lo, i0, j0, res = _NO_MAP, 0, 0, 1.0
        else:
            lo, i0, j0, res = view.logodds, int(view.i0), int(view.j0), float(view.resolution)
        x, y, th = float(pose.x), float(pose.y), pose.theta
        # (the segmentation's per-geometry arguments: _scan_args' once per beam geometry and tracker, kept with the
        # geometry's key and with ``fill`` False after the first call, whose kernel call fills the trigonometry)
        key = (ranges.shape[0], scan.angle_min, scan.angle_increment)
        geo = self._scan_geo
        if geo is None or geo[0] != key or geo[1] is not self._seg_p:
            args = _scan_args(scan, cfg.segment, self._seg_p)
            geo = self._scan_geo = (key, self._seg_p, args[:2] + (False,) + args[3:])
        else:
            args = geo[2]
        sangles, strig, fill, cos_a, sin_a, gpar, wrap, q = args
        (beams, offsets, dropped, wrapped, pts, rr, rpar, starts, npts, kinds, lohi, rel, fits, mfr, mg, px, py,
         theta, centroid, circle, *default) = detect_scan(
            ranges, sangles, valid, strig, fill, q, wrap, cos_a, sin_a, math.cos(th), math.sin(th), x, y,
            free is not None, th, gpar, float(scan.range_max), angles, ftrig, self._fit_q, self._det_p,
            view is not None, lo, i0, j0, res, abs(float(scan.angle_increment)))
        # (last_segmentation, made when read: segment.segmentation_of)
        self._seg = (beams, offsets, ranges.shape[0], q, wrapped, dropped)
        ncl = offsets.shape[0] - 1
        st.clusters += ncl
        st.dropped_small_clusters += dropped
        self._batch = None
        self._ms = self._ms_ev = None
        if ncl == 0:
            self.last_detections = []
            if free is not None:
                free.step(scan, pose, rr, rpar, False)
            return []
        nd = starts.shape[0]
        st.structure_clusters += ncl - nd
        # free-space evidence per detection (0 where unknown). The free-space fraction is read for few detections
        # (births, updates whose entry is read: Tracker._free_values): each detection keeps this scan's test (the
        # memory's references now, before it gains this scan) and computes its fraction when first read
        # (ScanDetection.free_fraction)
        frac = 0.0
        if free is not None:  # (ref_of, test_at before the scan is added, add: one call, FreeSpaceMemory.step)
            self._cur_ref, test = free.step(scan, pose, rr, rpar, nd != 0)
            if test is not None:
                frac = test
        mev = None
        if view is not None:
            mev = mfr
            # (the detections' map evidence, (3, nd), as the updates push it into their tracks' windows; a leg merge
            # below names its reordered and merged detections' sources: kernels.shape_update)
            self._mev_src = (mfr, _NO_IDX, _NO_IDX, _NO_IDX, _NO_IDX)
        # (each detection is the scan's arrays and its row: its beams, points, kind, counts, fit values and map evidence
        # are read from them when asked for, ScanDetection; all made in one loop, scan_detections)
        dets = scan_detections(ScanArrays(beams, pts, 0, starts, npts, kinds, fits, lohi, rel, mev), frac)
        kfits = fits  # (the rows detect_rows' theta, centroid and circle are of)
        if mg is not None:  # (a pair merged: _merge_legs makes the persons' detections of the kernel's merge)
            first, second, ki, kinds2, kfits, lohi2, rel2, starts2, npts2, mbeams, mpts, mmev = mg
            n0 = px.shape[0] - mbeams.shape[0]  # (the detections' points before the persons')
            dets, kinds, fits, lohi, rel, starts, npts, px, py = self._merge_legs(
                dets, kinds, fits, lohi, rel, starts, npts, px[:n0], py[:n0], beams, mev,
                (first, second, ki, kinds2, kfits, lohi2, rel2, starts2, npts2, px, py, mbeams, mpts, mmev))
        st.detections += len(dets)
        self.last_detections = dets
        if dets:
            m = len(dets)
            if fits is kfits:  # (the kernel's final rows: their columns and default measurements made there)
                # (the named tuples made by tuple.__new__ of their fields in order, as their generated __new__ does)
                self._batch = _tuple_new(DetectionBatch, (kinds, theta, lohi, rel, centroid, circle, px, py, starts,
                                                          npts))
                self._default = _tuple_new(MeasureRows, default)
                # (their (3, nd) map evidence: the structure column read from it, _structure_column)
                self._ms_ev = mmev if mg is not None and mev is not None else mev
            else:  # (rows other than the kernel's final ones: a subclass' _merge_legs)
                self._batch = DetectionBatch(kinds, fits[:, F_THETA].copy(), lohi, rel, fits[:, FIT_CENTROID].copy(),
                                             fits[:, FIT_CIRCLE].copy(), px, py, starts, npts)
                # (no track prior: every row its own detection, no sizes, no radius, size σ 0)
                self._default = self._measure_rows(np.arange(m), np.zeros((m, 2)), np.zeros(m, dtype=bool),
                                                   np.full(m, -1.0), np.zeros(m))
            # (the detections' bounds and real-bound flags: read as Python lists by row, for births and detections on
            # structure only (_birth_state, _clutter_detections): one row's tolist each, not the whole arrays' per scan)
        return dets

    def _structure_column(self, dets: list[Detection]) -> list[float]:
        """``map_structure`` of the detections ``dets`` in their order, Python floats (the fraction of each one's
        points on long-occupied map cells, 0.0 without a map): for this scan's detections the final rows' evidence
        row as one list, read once a scan when first asked for (docs/speed.md, pass trk72); else (another list, no
        map, or rows of a subclass' ``_merge_legs``) the detections' own values, kept for the same list."""
        ms = self._ms
        if ms is None or ms[0] is not dets:
            ev = self._ms_ev if dets is self.last_detections else None
            ms = self._ms = (dets, ev[0].tolist() if ev is not None else [d.map_structure for d in dets])
        return ms[1]

    def _merge_legs(self, dets: list[Detection], kinds: np.ndarray, fits: np.ndarray, lohi: np.ndarray,
                    rel: np.ndarray, starts: np.ndarray, npts: np.ndarray, px: np.ndarray, py: np.ndarray,
                    beams: np.ndarray, mev: np.ndarray | None = None, merged: tuple | None = None) -> tuple:
        """People (leg_tracker, Leigh et al. ICRA 2015, pairs legs): two leg-sized detections (both sides
        ≤ ``fit.leg_max_extent``) whose centres lie within ``fit.leg_pair_distance`` become one person
        detection, measured at the middle of the two legs with the point model. A leg swinging forward while
        the other stands does not move the person's centre by a full stride, so its speed does not jump.
        Returns the detection list and the per-detection batch arrays, merged pairs appended at the end (the
        pairs, arrays, the persons' points and map evidence by :func:`dynslam2d.detect.kernels.merge_legs`;
        ``beams``: the beams of ``px``, ``py``; ``mev``: the detections' (3, nd) map evidence, or None without a
        map; ``merged``: ``merge_legs``' results on these arguments when already made, by
        :func:`dynslam2d.detect.kernels.detect_rows` in ``_detect``)."""
        fc = self.config.fit
        npts0 = npts
        if merged is None:
            merged = merge_legs(px, py, beams, starts, npts, kinds, fits, lohi, rel, _NO_MEV if mev is None else mev,
                                float(fc.leg_max_extent), float(fc.leg_pair_distance))
        first, second, ki, kinds, fits, lohi, rel, starts, npts, px, py, mbeams, pts, mmev = merged
        m = first.shape[0]
        if m == 0:  # (the arrays are the arguments themselves)
            return dets, kinds, fits, lohi, rel, starts, npts, px, py
        new_dets = list(map(dets.__getitem__, ki.tolist()))  # (the kept detections in their new order)
        row = len(new_dets)
        # (the persons are rows row … of the merged arrays: their beams and points rows starts − n0 of mbeams / pts
        # (the persons' points, (n, 2)); centroid = circle centre = the legs' middle, lo / hi their box, no real
        # bound, theta 0, kind point; their map evidence, point-weighted, in their columns of mmev, the kept
        # detections keeping their own columns of mev: all made by the kernel). ScanDetection(arrays, row, (da, db),
        # True) per pair, its slots set directly (as scan_detections does: no constructor call per pair); the free
        # fraction is computed when read
        arrays = ScanArrays(mbeams, pts, px.shape[0] - mbeams.shape[0], starts, npts, kinds, fits, lohi, rel,
                            None if mev is None else mmev)
        append, new, cls = new_dets.append, object.__new__, ScanDetection
        for a, b in zip(first.tolist(), second.tolist()):
            det = new(cls)
            det._s = arrays
            det._j = row
            det._ff = (dets[a], dets[b])
            det.person = True
            append(det)
            row += 1
        self.stats.merged_leg_pairs += m
        if self._map is not None:  # (the sources of the detections' map evidence in their new order: _detect)
            self._mev_src = (self._mev_src[0], ki, first, second, npts0)
        return new_dets, kinds, fits, lohi, rel, starts, npts, px, py

    def _measure_rows(self, det: np.ndarray, sizes: np.ndarray, has_sizes: np.ndarray, radius: np.ndarray,
                      size_sigma: np.ndarray) -> MeasureRows:
        """:func:`dynslam2d.detect.reference.measure` of this scan's detections ``det`` with the given track
        priors, batched (see :func:`dynslam2d.detect.kernels.measure_batch`)."""
        return MeasureRows(*measure_batch(det, *self._batch, sizes, has_sizes, radius, size_sigma, self._fit_p))
