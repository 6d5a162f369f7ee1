"""Step 3 of ``Tracker.update`` (detect/tracker.py): the scan's detections in the map frame (segmentation, paper
Eq. 1; shape fits, paper Eq. 2; classification, the map-evidence columns, the leg merge of people) and their
default measurements. Split out of ``detect/tracker.py`` (docs/speed.md, pass trktable)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels import detect_rows, measure_batch
from dynslam2d.detect.layout import F_THETA, KIND_POINT, DetectionBatch, MeasureRows
from dynslam2d.detect.measure import Detection, ScanDetection, scan_detections
from dynslam2d.detect.segment import segment_scan
from dynslam2d.detect.shapes import CRITERIA
from dynslam2d.detect.vehicles import _NO_MAP, extent_limit
from dynslam2d.types import Pose2D, Scan


class TrackDetect:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the detection step (``_detect``, ``_merge_legs``)."""

    def _beam_trig(self, scan: Scan) -> tuple[np.ndarray, np.ndarray]:
        """cos / sin of the beam angles, cached per beam geometry (sensor frame)."""
        key = (scan.n_beams, float(scan.angle_min), float(scan.angle_increment))
        if self._trig_key != key:
            a = scan.angles
            self._trig = (np.cos(a), np.sin(a))
            self._trig_key = key
        return self._trig

    def _detect(self, scan: Scan, pose: Pose2D) -> list[Detection]:
        cfg = self.config
        st = self.stats
        ranges = scan.ranges
        valid = scan.valid_mask()  # (a copy)
        if not scan.range_min > 0.0:  # (else every valid range is ≥ range_min > 0 already: the test changes nothing)
            valid &= ranges > 0.0
        seg = segment_scan(scan, cfg.segment, valid, checked=True)
        self.last_segmentation = seg
        st.clusters += seg.n_clusters
        st.dropped_small_clusters += seg.n_dropped
        self._batch = None
        if seg.n_clusters == 0:
            self.last_detections = []
            if self._free is not None:
                self._free.add(scan, pose, valid)
            return []
        cos_a, sin_a = self._beam_trig(scan)
        # the beams in the map frame (pose.transform_points of the beams, invalid ones at the pose), the clusters'
        # fits, the classification and bounds of every cluster (reference.classify_and_bound), the vehicle-size
        # clusters' map test (detect/vehicles.py), the kept clusters' rows and their points' map evidence (per point:
        # only the detections' points are tested; structure clusters, most of the points, are not detections) and
        # the leg merge's pairs and arrays (_merge_legs): one kernel call (kernels.detect_rows)
        view = self._map
        fc, sc, tc = cfg.fit, cfg.segment, cfg.tracker
        if view is None:
            lo, i0, j0, res = _NO_MAP, 0, 0, 1.0
        else:
            lo, i0, j0, res = view.logodds, int(view.i0), int(view.j0), float(view.resolution)
        px0 = float(pose.x)
        py0 = float(pose.y)
        (pts, starts, npts, kinds, lohi, rel, fits, mfr, first, second, ki, kinds2, fits2, lohi2, rel2, starts2, npts2,
         px2, py2, mbeams, ppts, theta, centroid, circle) = detect_rows(
            ranges, valid, cos_a, sin_a, math.cos(pose.theta), math.sin(pose.theta), px0, py0, seg.beams, seg.offsets,
            seg.structure, seg.wrapped, self._angles, CRITERIA[fc.criterion], fc.closeness_d0, fc.circle_min_points,
            fc.coarse_stride, int(sc.max_skip_beams), float(scan.range_max), abs(float(scan.angle_increment)),
            extent_limit(cfg), self._fit_p, sc.vehicle_max_extent > sc.max_extent, float(sc.max_extent),
            float(sc.vehicle_max_structure), float(sc.vehicle_min_free), view is not None, lo, i0, j0, res,
            float(tc.map_occupied_logodds), float(tc.map_free_logodds), int(tc.map_free_radius), fc.person_merge,
            float(fc.leg_max_extent), float(fc.leg_pair_distance))
        nd = starts.shape[0]
        st.structure_clusters += seg.n_clusters - nd
        # free-space evidence per detection (0 where unknown). The free-space fraction is read for few detections
        # (births, updates whose entry is read: Tracker._free_values): each detection keeps this scan's test (the
        # memory's references now, before it gains this scan) and computes its fraction when first read
        # (ScanDetection.free_fraction)
        frac = 0.0
        fs = ff = fu = [0.0] * nd
        free = self._free
        if free is not None:
            self._cur_ref = free.make_ref(scan, pose, valid)
            if nd and (test := free.test_at(float(scan.stamp))) is not None:
                frac = test
            free.add(scan, pose, valid, self._cur_ref)
        if view is not None:
            fs, ff, fu = mfr.tolist()
        # (their centroid, bounds, flags and circle stay rows of fits / lohi / rel until read, their points rows of pts:
        # ScanDetection; all made in one loop, scan_detections)
        dets = scan_detections(seg.beams, pts, starts.tolist(), npts.tolist(), kinds.tolist(),
                               (fits[:, F_THETA] if first.shape[0] else theta).tolist(), frac, fs, ff, fu, fits, lohi,
                               rel)
        if first.shape[0]:
            dets = self._merge_legs(dets, first, second, ki, fits2, lohi2, rel2, mbeams, ppts)
        st.detections += len(dets)
        self.last_detections = dets
        if dets:
            m = len(dets)
            self._batch = DetectionBatch(kind=kinds2, theta=theta, lohi=lohi2, rel=rel2, centroid=centroid,
                                         circle=circle, px=px2, py=py2, start=starts2, npts=npts2)
            no_prior = self._no_prior.get(m)
            if no_prior is None:
                # (no track prior: the same arrays for every scan with m detections; the kernel only reads them)
                if len(self._no_prior) >= 64:
                    self._no_prior.clear()
                no_prior = self._no_prior[m] = (np.arange(m), np.zeros((m, 2)), np.zeros(m, dtype=bool),
                                                np.full(m, -1.0), np.zeros(m))
            self._default = self._measure_rows(*no_prior)
            # (the detections' bounds and real-bound flags: read as Python lists by row, for births and detections on
            # structure only (_birth_state, _clutter_detections): one row's tolist each, not the whole arrays' per scan)
        return dets

    def _merge_legs(self, dets: list[Detection], first: np.ndarray, second: np.ndarray, ki: np.ndarray,
                    fits: np.ndarray, lohi: np.ndarray, rel: np.ndarray, mbeams: np.ndarray,
                    pts: np.ndarray) -> list[ScanDetection]:
        """People (leg_tracker, Leigh et al. ICRA 2015, pairs legs): two leg-sized detections (both sides
        ≤ ``fit.leg_max_extent``) whose centres lie within ``fit.leg_pair_distance`` become one person
        detection, measured at the middle of the two legs with the point model. A leg swinging forward while
        the other stands does not move the person's centre by a full stride, so its speed does not jump.
        Returns the detection list, merged pairs appended at the end: the detections ``ki`` of ``dets`` (those in no
        pair), then one per pair (``first[r]``, ``second[r]``), reading the merged ``fits``, ``lohi``, ``rel``, the
        persons' beams ``mbeams`` and their (n, 2) points ``pts`` (the pairs and arrays by
        :func:`dynslam2d.detect.kernels.merge_legs`, inside ``detect_rows``)."""
        m = first.shape[0]
        new_dets = [dets[j] for j in ki.tolist()]
        row = len(new_dets)
        o = 0
        append, new, cls = new_dets.append, object.__new__, ScanDetection
        for a, b in zip(first.tolist(), second.tolist()):
            da, db = dets[a], dets[b]
            na, nb = da.n_points, db.n_points
            n = na + nb
            # (centroid = circle centre = the legs' middle, lo / hi their box, no real bound, theta 0: rows of the
            # merged arrays, as a scan detection's). ScanDetection(mbeams[o:o + n], pts, KIND_POINT, 0.0, n, (da, db),
            # <the point-weighted map evidence>, fits, lohi, rel, row, o) with person True, its slots set directly
            # (as scan_detections does: no constructor call per pair); the free fraction is computed when read
            det = new(cls)
            det.beams = mbeams[o:o + n]
            det._pts = pts
            det._a0 = o
            det.kind = KIND_POINT
            det.theta = 0.0
            det.n_points = n
            det._ff = (da, db)
            det.map_structure = (na * da.map_structure + nb * db.map_structure) / n
            det.map_free = (na * da.map_free + nb * db.map_free) / n
            det.map_unknown = (na * da.map_unknown + nb * db.map_unknown) / n
            det.person = True
            det._fits = fits
            det._lohi = lohi
            det._rel = rel
            det._j = row
            append(det)
            row += 1
            o += n
        self.stats.merged_leg_pairs += m
        return new_dets

    def _measure_rows(self, det: np.ndarray, sizes: np.ndarray, has_sizes: np.ndarray, radius: np.ndarray,
                      size_sigma: np.ndarray) -> MeasureRows:
        """:func:`dynslam2d.detect.reference.measure` of this scan's detections ``det`` with the given track
        priors, batched (see :func:`dynslam2d.detect.kernels.measure_batch`)."""
        return MeasureRows(*measure_batch(det, *self._batch, sizes, has_sizes, radius, size_sigma, self._fit_p))
