"""Tracking of moving objects in the map frame: ``Tracker(config).update(scan, pose)``.

Per scan (after DATMO's loop, Konstantinidis et al. 2020 and ``Datmo::callback`` in
kostaskonkk/datmo, with prediction, exclusive association and track confirmation added;
see docs/tracking.md):

1. bad input: a non-finite pose skips the scan; time going backwards, a gap > ``max_dt`` or a
   pose jump (faster than ``max_pose_speed`` / ``max_pose_rate``) drops every track; all counted
   in :attr:`Tracker.stats`, no exception;
2. predict every track to the scan stamp with the real dt (constant-velocity Kalman filter on
   the box centre, white-noise-acceleration Q(dt));
3. segment the scan (paper Eq. 1), transform the points into the map frame with the pose of
   the same scan, fit rectangle / circle / point models (paper Eq. 2);
4. exclusive association: Hungarian (``scipy.optimize.linear_sum_assignment``'s algorithm, as a kernel:
   :mod:`dynslam2d.detect.kernels_assign`) on the
   Mahalanobis distance of the centre innovation, gated by χ² and a Euclidean distance;
5. Kalman update with the measurement of :func:`dynslam2d.detect.kernels.measure_batch` (which carries the
   track's size and heading: 90° ambiguity resolved against the track's axis), size and heading
   smoothing;
6. management: tentative → confirmed (M of N hits) → coasting (no detection, prediction only)
   → deleted (coasted longer than ``max_coast_time``, covariance blow-up, absurd speed);
7. the dynamic set M (paper Eq. 3): speed > v_min for ``sustain_updates`` consecutive
   updates, velocity well determined, and a net displacement ≥ ``min_displacement`` since
   birth; a track leaves M after ``sustain_updates`` updates below ``v_exit_ratio``·v_min.

Frames: the pose given with a scan is the laser pose in the map frame; every reported
quantity is in the map frame (m, rad, m/s).

Speed: steps 3–5 run as one numba kernel call per scan each (:mod:`dynslam2d.detect.kernels`:
classification and bounds of all clusters, the measurements, the gate, the Kalman updates, the
free-space and fragment tests); only the per-track bookkeeping stays in Python (≈0.8 ms per
720-beam scan with 10 movers, ``benchmarks/bench_detect.py``). The Kalman states and covariances of
all live tracks are two arrays owned by the tracker (``_X``, ``_P``; each track keeps one row for
life, its ``x`` / ``P`` are views of it): the prediction, the association and the reports read
them as whole arrays, the Kalman results are written back in one scatter per scan. The shape state
(box axis angle, sizes, radius, largest partial views, kind, heading and known-size flags) lives in two
more arrays on the same rows (``_G``, ``_Gi``; ``g`` / ``gi`` views per track, properties such as
``theta_box`` or ``size`` read them one track at a time): the measurement priors, the shape update, the
association's inputs and the reported boxes are one kernel call each over all pairs / tracks.

Modules: this one holds ``Tracker`` (``update`` and its orchestration, the prediction, the association, births,
fragments and clutter retirement); its steps are mixin classes it inherits, one module each (docs/speed.md, pass
trktable): :mod:`~dynslam2d.detect.tracktable` (the track records and their rows), :mod:`~dynslam2d.detect.trackdetect`
(step 3), :mod:`~dynslam2d.detect.trackupdate` (step 5), :mod:`~dynslam2d.detect.trackmanage` (steps 6–7),
:mod:`~dynslam2d.detect.trackreport` (the reports). The steps stay methods (``self._detect(…)``), so a benchmark can
time one by setting an instance attribute of that name (``benchmarks/bench_tracker_ab.py --phases``).
"""

from __future__ import annotations

import copy
import math
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.detect.kernels import (
    cv_predict,
    fit_params,
)
from dynslam2d.detect.kernels_assign import LSAP_MESSAGES, associate_update
from dynslam2d.detect.kernels_update import (
    C_BN,
    birth_rows,
    fragment_hosts_rows,
    update_params,
)
from dynslam2d.detect.layout import (
    KIND_CIRCLE,
    KIND_NAMES,
    KIND_RECT,
    SIZE_MEASURED,
    DetectionBatch,
    MeasureRows,
)
from dynslam2d.detect.mapevidence import MapView
from dynslam2d.detect.measure import Detection
from dynslam2d.detect.segment import Segmentation
from dynslam2d.detect.shapes import search_angles
from dynslam2d.detect.trackdetect import TrackDetect
from dynslam2d.detect.trackmanage import TrackManage
from dynslam2d.detect.trackreport import TrackReport, TrackReports
from dynslam2d.detect.tracktable import (  # noqa: F401  (_Track, _new_track, … : the names tests import from here)
    _HALF_PI,
    _NO_BEAMS,
    _NO_IDX,
    _NO_STATE,
    _ROWS0,
    COASTING,
    CONFIRMED,
    TENTATIVE,
    TrackRows,
    _new_track,
    _past_entry,
    _past_points,
    _shape_rows,
    _Track,
)
from dynslam2d.detect.trackupdate import TrackUpdate, _nearest_age  # noqa: F401  (_nearest_age: tests import it here)
from dynslam2d.types import Pose2D, Scan, wrap_angle

_NO_MEV = np.zeros((0, 3))  # (Tracker._births' map evidence without a map: never read)
# (associate_update's arguments without a claimed detection / a track to veto: shared, never written)
_NO_CLAIM = np.zeros(0, dtype=np.bool_)
_NO_ROWS = np.zeros(0, dtype=np.int64)
_NO_MS = np.zeros(0)


@dataclass
class TrackerStats:
    """Counters of what the tracker saw and did (bad input is counted here, never raised)."""

    scans: int = 0
    skipped_nonfinite_pose: int = 0
    empty_scans: int = 0
    time_resets: int = 0
    pose_jumps: int = 0
    clusters: int = 0
    structure_clusters: int = 0
    dropped_small_clusters: int = 0
    detections: int = 0
    tracks_born: int = 0
    tracks_deleted: int = 0
    deleted_coasting: int = 0
    deleted_covariance: int = 0
    deleted_speed: int = 0
    deleted_tentative: int = 0
    deleted_structure: int = 0  # still clutter on long-occupied map cells (structure_retire_updates)
    unborn_structure: int = 0  # detections on map structure given no track (structure_birth_min)
    revived_structure: int = 0  # dormant (retired) tracks back to life when their object left the structure
    rejected_updates: int = 0
    merged_fragments: int = 0
    merged_leg_pairs: int = 0
    accel_bounded: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


def _cv_fill(F: np.ndarray, Q: np.ndarray, dt: float, q: float) -> None:
    """Write :func:`_cv_matrices`' values for a step of ``dt`` s into ``F`` (an identity but for its two dt entries)
    and ``Q`` (zero but for its eight noise entries), (4, 4) each: the entries that change with dt, ten element
    writes instead of two arrays built (``Tracker._predict``, once per scan; docs/speed.md, pass trk25)."""
    q11, q12, q22 = q * dt ** 3 / 3.0, q * dt ** 2 / 2.0, q * dt
    F[0, 2] = F[1, 3] = dt
    Q[0, 0] = Q[1, 1] = q11
    Q[0, 2] = Q[1, 3] = Q[2, 0] = Q[3, 1] = q12
    Q[2, 2] = Q[3, 3] = q22


def _cv_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity transition F and white-noise-acceleration Q for state [x, y, vx, vy] (the continuous
    white-noise acceleration model, Bar-Shalom, Li & Kirubarajan 2001, §6.2.2)."""
    q11, q12, q22 = q * dt ** 3 / 3.0, q * dt ** 2 / 2.0, q * dt
    # (flat lists reshaped: the same values, half the cost of nested lists)
    F = np.array([1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]).reshape(4, 4)
    Q = np.array([q11, 0.0, q12, 0.0, 0.0, q11, 0.0, q12, q12, 0.0, q22, 0.0, 0.0, q12, 0.0, q22]).reshape(4, 4)
    return F, Q


def _default_sizes(lohi: list[float], rel: list[list[bool]], fit) -> list[float]:
    """:meth:`Detection.default_sizes` as a list of floats (the same arithmetic on the same values), from the
    detection's row of the scan's ``lohi`` (lo1, lo2, hi1, hi2) and ``rel`` as lists."""
    lo0, lo1, hi0, hi1 = lohi
    (r00, r01), (r10, r11) = rel
    e0, e1 = hi0 - lo0, hi1 - lo1
    o0 = e0 if r00 and r01 else max(e0, min(fit.default_depth, fit.default_depth_ratio * max(e1, 0.0)))
    o1 = e1 if r10 and r11 else max(e1, min(fit.default_depth, fit.default_depth_ratio * max(e0, 0.0)))
    return [o0, o1]


class Tracker(TrackDetect, TrackUpdate, TrackManage, TrackReport, TrackRows):
    """Detect and track moving objects from 2D scans in the map frame.

    ``update(scan, pose)`` takes a scan and the laser pose **of that scan** in the map frame and
    returns the live tracks (tentative, confirmed, coasting). See the module docstring.
    """

    def __init__(self, config: DetectConfig | None = None) -> None:
        self.config = config or DetectConfig()
        self.stats = TrackerStats()
        self._tracks: list[_Track] = []
        # the Kalman states and covariances of the live tracks (struct of arrays: the prediction runs on all of
        # them at once, the reports copy them in one go); each _Track keeps its row for life (k.row; rows of
        # deleted tracks are reused by births) and its x / P are views of that row (re-pointed only when the
        # arrays grow, by doubling)
        # (_X (rows, 4), _P (rows, 4, 4))
        # … and their shape state (the same rows; columns G_* / GI_* of detect/kernels.py): the association, the shape
        # update and the reports read and write it for all tracks in one kernel call or gather each (_G, _Gi)
        # … and their counters (state code, hits, misses, the M-of-N counts; columns C_* of detect/kernels_update.py)
        # and last hits' stamps (s): the update kernel writes them for the updated tracks, the management step tests
        # and writes them as columns (docs/speed.md, pass cnt36; _CI, _CL)
        # … and their windows of the last updates (map evidence, riding test: TrackRows, docs/speed.md pass trk26;
        # _MEV, _RIDE, _WN); all but _Gi and _RIDE views of two flat buffers (TrackRows._alloc_tables, pass trk129)
        self._init_rows(_ROWS0, self.config.tracker.sustain_updates)
        self._rows_used = 0  # rows 0 … _rows_used − 1 have been handed out
        # the prediction's F and Q (_cv_fill writes this step's entries into them; read only by the kernel and the
        # rare paths of _predict, never kept beyond the scan)
        # (one (2, 4, 4) array, F then Q: one argument of the association's kernel, which runs the prediction)
        fq = np.zeros((2, 4, 4))
        fq[0] = np.eye(4)
        self._FQ = fq
        self._predict_in_kernel = False  # (this scan's cv_predict left to the association's kernel: _predict)
        self._cv_called = False  # (cv_predict called from Python once: only then is the prediction left to it)
        self._FQ_of = (math.nan, math.nan)  # (the dt (s) and accel_noise _FQ holds the entries of; NaN: none yet)
        self._free_rows: list[int] = []  # rows of deleted tracks, reused first
        self._order: np.ndarray | None = None  # the rows of self._tracks in their order (None: to be built)
        self._next_id = 1
        self._last_stamp: float | None = None
        self._last_pose: Pose2D | None = None
        self._angles = search_angles(self.config.fit.angle_step_deg)
        tc = self.config.tracker
        self._free = FreeSpaceMemory(tc.free_ref_ages, tc.free_margin) if tc.free_space_check else None
        self._ref_ages = np.array(self._free.ref_ages if self._free is not None else (), dtype=np.float64)
        self._ref_ages_l = self._ref_ages.tolist()  # (the same ages as floats: the one-track search, _vacated_one)
        self._cur_ref = None
        self._map: MapView | None = None  # the SLAM map given with the current scan (read only)
        self._pose: Pose2D | None = None
        self._pose_cs: tuple[float, float] = (1.0, 0.0)  # cos / sin of self._pose.theta
        self._scan: Scan | None = None
        self._pose_hist: deque = deque()  # (stamp, x, y, θ) of the last still_time seconds
        self._laser_still: bool | None = False  # (None: not compared yet in this scan, _is_still)
        self._dt = 0.0
        self._body_near: np.ndarray | None = None
        self._body_key: np.ndarray | None = None  # body beams the grown mask below was made from
        self._body_bytes = b""  # (their bytes: the key is this tracker's own copy, never written)
        self._body_grown: np.ndarray = np.zeros(0, dtype=bool)
        self._fit_p = fit_params(self.config.fit)
        self._upd_p = update_params(self._fit_p, self.config.fit, tc)  # (update_pairs' configuration values)
        self._detect_setup()  # (detect_rows' and fit_cluster_rows' configuration values: _det_p, _fit_args)
        self._batch: DetectionBatch | None = None  # per-detection arrays of the current scan (kernels)
        # the sources of the detections' map evidence (set by _detect with a map): (3, nd) fractions of points on
        # long-occupied, observed-free, never-observed cells of the scan's detections before the leg merge, and the
        # merge's kept detections, pairs and point counts (empty: no merge; kernels.shape_update)
        self._mev_src: tuple = (np.zeros((3, 0)), _NO_IDX, _NO_IDX, _NO_IDX, _NO_IDX)
        self._default: MeasureRows | None = None  # default measurements of the current scan's detections
        self._merged: set[int] = set()  # ids of tracks in M merged with structure in this scan (_associate_update)
        # this scan's ids of the updated tracks (update, _update_tracks)
        self._updated: set[int] = set()
        # clutter retirement (structure_retire_updates): confirmed still tracks on map structure, out of the
        # Kalman tracking but kept (and reported) while their object is seen, so that a parked mover keeps
        # its id and standing history until it leaves (_clutter_detections)
        self._dormant: list[_Track] = []
        # False: no live track is remembered (the prediction skips its search for them; set by _remember, _revive)
        self._maybe_remembered = False
        # … and the places of detections on structure that got no track: (m, 4) centre x, y (m, map frame), reach
        # (m) and the stamp last seen (s); like a dormant track, such a place keeps its detection from live tracks
        self._marks = np.zeros((0, 4))
        #: Segmentation and detections of the last processed scan (for inspection / plots).
        self.last_segmentation: Segmentation | None = None
        self.last_detections: list[Detection] = []

    # ------------------------------------------------------------------ public
    def reset(self) -> None:
        """Forget every track and the free-space evidence (ids keep counting up)."""
        self._tracks.clear()
        self._dormant.clear()
        self._marks = self._marks[:0]
        self._rows_used = 0
        self._free_rows.clear()
        self._order = None
        if self._free is not None:
            self._free.clear()

    @property
    def n_tracks(self) -> int:
        return len(self._tracks)

    def update(self, scan: Scan, pose: Pose2D, map_view: MapView | None = None,
               body_beams: np.ndarray | None = None) -> TrackReports:
        """Process one scan with the laser pose of the same scan (map frame); return the live tracks' reports: a
        sequence of :class:`dynslam2d.types.Track` (the live tracks', then the dormant ones'), each built when first
        read (:class:`dynslam2d.detect.trackreport.TrackReports`, its values as of this scan).

        ``map_view``: the SLAM map built from earlier scans (finest level, read only); with it and
        ``tracker.map_evidence`` the set M also needs the map's agreement (docs/tracking.md).
        ``body_beams``: (beams,) bool, the beams found to look at the robot's own body
        (:class:`dynslam2d.detect.body.BodyFilter`); given, only tracks on beams within
        ``tracker.ride_beam_window`` of them can be taken as riding with the robot (a car or a person
        keeping pace elsewhere is not the body). None: every near track can."""
        st = self.stats
        self._body_near = None
        if body_beams is not None and body_beams.shape[0] == scan.ranges.shape[0]:  # (scan.n_beams, no property call)
            # the body beams rarely change: the grown mask is kept while they stay the same
            key = self._body_key
            # (np.array_equal's answer for the bool masks, without its Python wrapper: the same dtype, shape and bytes)
            if key is None or key.dtype != body_beams.dtype or key.shape != body_beams.shape or \
                    self._body_bytes != body_beams.tobytes():
                w = self.config.tracker.ride_beam_window
                near = body_beams.astype(bool).copy()
                for d in range(1, w + 1):
                    near[d:] |= body_beams[:-d]
                    near[:-d] |= body_beams[d:]
                self._body_key = body_beams.copy()
                self._body_bytes = self._body_key.tobytes()
                self._body_grown = near
            self._body_near = self._body_grown
        self._map = map_view if self.config.tracker.map_evidence else None
        self._pose = pose
        self._pose_cs = ((math.cos(pose.theta), math.sin(pose.theta)) if pose is not None
                         and math.isfinite(pose.theta) else (1.0, 0.0))
        self._scan = scan
        self._laser_still = self._still(float(scan.stamp), pose)
        st.scans += 1
        t = float(scan.stamp)
        if pose is None or not pose.is_finite():
            st.skipped_nonfinite_pose += 1
            return self._report(t, updated=set())
        dt = 0.0
        if self._last_stamp is not None:
            dt = t - self._last_stamp
            tc = self.config.tracker
            if dt < 0.0 or dt > tc.max_dt:
                st.time_resets += 1
                self.reset()
                dt = 0.0
            elif self._last_pose is not None and self._is_jump(self._last_pose, pose, dt):
                st.pose_jumps += 1
                self.reset()
        self._last_stamp, self._last_pose = t, pose
        self._dt = dt
        self._predict(dt)
        if self.config.tracker.aspect_prior is not None:  # (without it _motion_prior changes nothing)
            for k in self._tracks:
                if k.has_heading and k.kind == KIND_RECT and k.state != TENTATIVE:  # (_motion_prior skips tentative)
                    self._motion_prior(k)
        dets = self._detect(scan, pose)
        self._merged = set()
        if not dets and not scan.valid_view().any():  # (the scan's own mask: only read)
            st.empty_scans += 1
        # (the ids of the updated tracks: filled by _update_tracks in its loop over the pairs, in the pairs' order)
        updated: set[int] = set()
        self._updated = updated
        # (the detections no applied pair took, increasing: the association's kernel lists them; pass trk138)
        nrej, unused = self._associate_update(dets, t)
        st.rejected_updates += nrej
        self._manage(t, updated)
        if (self._map is not None and self.config.tracker.structure_birth_min <= 1.0) or self._dormant or \
                self._marks.shape[0]:
            unused = self._clutter_detections(dets, unused, t, updated)
        if self.config.tracker.confirm_hits > 1:  # births stay tentative: hosts can be found in one batch
            hosts = self._hosts_of_fragments(unused, updated)
            # (… and the births made in one batch after them, in the same order: a birth changes no host; pass trk38)
            born = []
            for di, host in zip(unused, hosts):
                if host is not None:  # a piece of an object already updated: its beams belong to it
                    host.beams = np.concatenate((host.beams, dets[di].beams))
                    host.ci[C_BN] = -1  # (its beams: no longer one segment of the batch's, pass rep149)
                    st.merged_fragments += 1
                else:
                    born.append(di)
            if born:
                self._births(dets, t, born, updated)
        else:
            for di in unused:
                det = dets[di]
                host = self._host_of_fragment(det, updated)
                if host is not None:
                    host.beams = np.concatenate((host.beams, det.beams))
                    host.ci[C_BN] = -1
                    st.merged_fragments += 1
                    continue
                self._birth(det, t, di)
                updated.add(self._tracks[-1].id)
        out = self._report(t, updated)
        if self._dormant:
            out.extend(self._dormant_reports(t))
        return out

    def _host_of_fragment(self, det: Detection, updated: set[int]) -> _Track | None:
        """The updated confirmed track whose box (grown by fit.fragment_margin) holds the detection."""
        margin = self.config.fit.fragment_margin
        best, best_d = None, math.inf
        for k in self._tracks:
            if k.id not in updated or k.state != CONFIRMED:
                continue
            c, s = math.cos(k.theta_box), math.sin(k.theta_box)
            rel = det.points - k.x[:2]
            u = np.abs(rel[:, 0] * c + rel[:, 1] * s) - 0.5 * k.size[0]
            v = np.abs(-rel[:, 0] * s + rel[:, 1] * c) - 0.5 * k.size[1]
            d = float(np.max(np.maximum(u, v)))
            if d < margin and d < best_d:
                best, best_d = k, d
        return best

    def _hosts_of_fragments(self, dets: list[int], updated: set[int]) -> list[_Track | None]:
        """:meth:`_host_of_fragment` for several of this scan's detections (indices) in one kernel call."""
        if not dets:
            return []
        # (the updated confirmed tracks: those _manage kept as such (its counter tests' outcome), then those revived
        # since (_clutter_detections appends them), in the order of the live tracks; pass cnt36)
        firm, n = self._firm_updated
        cand = firm + [k for k in self._tracks[n:] if k.id in updated and k.state == CONFIRMED] \
            if len(self._tracks) > n else firm
        if not cand:
            return [None] * len(dets)
        b = self._batch
        # (the candidates' centres and shapes read from their rows in the kernel; docs/speed.md, pass trk24)
        idx = fragment_hosts_rows(b.px, b.py, b.start, b.npts, np.array(dets, dtype=np.int64), self._X, self._G,
                                  np.array([k.row for k in cand], dtype=np.int64),
                                  float(self.config.fit.fragment_margin))
        return [cand[i] if i >= 0 else None for i in idx.tolist()]

    # ------------------------------------------------------------------ steps
    def _is_jump(self, a: Pose2D, b: Pose2D, dt: float) -> bool:
        tc = self.config.tracker
        d = math.hypot(b.x - a.x, b.y - a.y)
        r = abs(float(wrap_angle(b.theta - a.theta)))
        if dt <= 1e-9:
            return d > 1e-3 or r > 1e-3
        return d / dt > tc.max_pose_speed or r / dt > tc.max_pose_rate

    def _predict(self, dt: float) -> None:
        self._predict_in_kernel = False
        if not self._tracks or dt <= 0.0:
            return
        FQ = self._FQ  # (the tracker's own (2, 4, 4) array, F and Q, their dt entries written for this step)
        F, Q = FQ[0], FQ[1]
        q = self.config.tracker.accel_noise
        dt0, q0 = self._FQ_of
        if dt != dt0 or q != q0:  # (the same step as the last scan's, as in a simulated scene: the entries are there)
            _cv_fill(F, Q, dt, q)
            self._FQ_of = (dt, q)
        order = self._rows()
        tracks = self._tracks
        # coasting through a stop: it stays where it stood (from k.x / k.P, before the rows are written). Only
        # _remember makes a track remembered and it raises _maybe_remembered then: without it no track is, and the
        # pass over the tracks is skipped; a pass that finds none lowers it
        still = ()
        if self._maybe_remembered and self.config.memory.enabled:
            rem = [i for i, k in enumerate(tracks) if k.remembered]
            if rem:
                still = [(i, self._stationary_prediction(tracks[i], F, dt)) for i in rem if tracks[i].misses > 0]
            else:
                self._maybe_remembered = False
        # (the predicted rows are read from the state arrays by the association's kernel: its stacked copies are not
        # kept; pass trk129)
        if order.shape[0] >= 2:
            # numpy's products bit for bit, the rows written in the kernel (the tracks' x / P are views of them).
            # Nothing reads the state rows between here and the association (the detection step does not; only the
            # aspect prior and the stationary rows below do): the association's kernel runs cv_predict first, one
            # dispatch less a scan (_associate_update; without an association it is called there; pass trk145).
            # The tracker's first such prediction calls it from Python all the same: the runs that record the
            # kernels called from Python (jitmanifest, the AOT module's build) then find it, which the rare paths
            # alone (no detection, a stationary prediction, the aspect prior) would not guarantee
            if not still and self.config.tracker.aspect_prior is None and self._cv_called:
                self._predict_in_kernel = True
                return
            cv_predict(self._X, self._P, order, F, Q)
            self._cv_called = True
            for i, (x, p) in still:
                self._X[order[i]], self._P[order[i]] = x, p
        else:  # (one track: numpy's matrix-vector product, whose sums the kernel does not reproduce)
            X = self._X[order] @ F.T
            P = F @ self._P[order] @ F.T + Q
            for i, (x, p) in still:
                X[i], P[i] = x, p
            self._X[order] = X
            self._P[order] = P

    def _stationary_prediction(self, k: _Track, F: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Prediction of a remembered (stopped) track that is not detected, with a stationary motion model
        (detect.memory): the centre stays, the velocity is 0, the position covariance grows by a small random walk and
        is kept at most ``memory.max_position_sigma``, the velocity covariance at most ``memory.max_speed_sigma``
        (it may start again: the velocity keeps some uncertainty and its coupling to the position)."""
        mc = self.config.memory
        x = k.x.copy()
        x[2:] = 0.0
        P = F @ k.P @ F.T
        P[0, 0] += mc.stationary_noise * dt
        P[1, 1] += mc.stationary_noise * dt
        sp = math.sqrt(max(P[0, 0], P[1, 1], 0.0))
        sv = math.sqrt(max(P[2, 2], P[3, 3], 0.0))
        a = min(1.0, mc.max_position_sigma / sp) if sp > 0.0 else 1.0
        b = min(1.0, mc.max_speed_sigma / sv) if sv > 0.0 else 1.0
        S = np.array([a, a, b, b])
        return x, P * S[:, None] * S[None, :]  # S P S: still a covariance


    def __deepcopy__(self, memo: dict) -> Tracker:
        """A deep copy whose tracks' x / P / g / gi are views of the copy's own state arrays (a plain deep copy would
        make them arrays of their own)."""
        new = object.__new__(type(self))
        memo[id(self)] = new
        for name, value in self.__dict__.items():
            setattr(new, name, copy.deepcopy(value, memo))
        new._table_views()  # (the tables as views of the copy's own buffers again)
        new._repoint()
        return new


    def _associate_update(self, dets: list[Detection], t: float) -> tuple[int, list[int]]:
        """The association of the scan's detections ``dets`` to the live tracks and the update of the pairs found
        (their Kalman and shape updates, then :meth:`_updated_pairs`), at the scan's stamp ``t`` (s); returns how
        many pairs' updates did not apply and the indices of the detections that no applied update took, increasing.
        Both kernels run in one call (``kernels_assign.associate_update``, pass trk108)."""
        self._managed = None  # (the management kernel's outputs when this call ran it: _manage reads them)
        if not self._tracks or not dets:
            if self._predict_in_kernel:  # (_predict left it to the association's kernel: no association to run)
                self._predict_in_kernel = False
                FQ = self._FQ
                cv_predict(self._X, self._P, self._rows(), FQ[0], FQ[1])
            return 0, list(range(len(dets)))
        # One kernel call (kernels_assign.associate_scan, docs/speed.md pass trk75): the gates (association_gates: the
        # tracks' sizes, flags and axis angles from their shape rows; the Mahalanobis gate and distance gate, a
        # rectangle measured again with the track's own sizes (a side the detection "measured" too short, e.g. a
        # grazing side, must not break the association); the size-jump gate: a tracked object does not double its
        # size from one scan to the next, a person track coasting past a wall must not take the wall's cluster — only
        # for coasting tracks whose size is known; passes trk24, call35, cnt36), then with a map the detections
        # claimed by a dormant track or a kept place taken out and the veto of detections merged with structure (see
        # below), then the gated costs' assignment, the established tracks' first, then the tentative tracks' on the
        # detections left, each pair kept where the gates allow it (SciPy's solver written again step for step, the
        # same pairs; detect/kernels_assign.py, pass trk21).
        #
        # The veto: a detection in which a track in M merged with long-standing structure — at least
        # map_structure_stop of its points on long-occupied map cells and its longer side more than merge_size_jump
        # beyond the track's, while the track's own points were not on structure (mean ≤ map_structure_max) — is
        # refused to that track. A person walking up to a wall joins the wall's cluster; updating the person's track
        # with it would carry M onto the wall. A track in M left with no detection leaves M (_manage) and keeps
        # refusing such detections (merged) until a detection of its own size updates it. A dormant track, or the
        # place of a detection on structure that got no track, keeps its object's detections on structure
        # (_clutter_detections): no live track takes them, as the clutter track would have kept them before it was
        # retired (or without the rule, born on them).
        claimed, vrows, ms = _NO_CLAIM, _NO_ROWS, _NO_MS
        if self._map is not None:
            if self._dormant or self._marks.shape[0]:
                claimed = self._claims(self._structure_column(dets))
            rows = [i for i, k in enumerate(self._tracks) if k.in_m or k.merged]
            if rows:  # (the tracks in M or merged, and the detections' structure fractions: _structure_column's)
                vrows = np.array(rows, dtype=np.int64)
                ev = self._ms_ev if dets is self.last_detections else None
                ms = ev[0] if ev is not None else np.array(self._structure_column(dets), dtype=np.float64)
        #
        # Then, in the same call (pass trk108: nothing in Python between the two fed the update), the update of the
        # pairs found (kernels_update.update_pairs): the track priors of the measurements (each track's sizes /
        # radius), the measurements (size σ 0.05 m), the Kalman updates, the physical acceleration bound (once a
        # track's velocity is established — ``accel_bound_after`` updates — one update may change it by at most
        # ``max_accel``·dt: speeds no longer jump from scan to scan with the shape of a partial view or a leg
        # swinging; the exact test with Python's math.hypot bit for bit, detect/kernels_update.py), the new states
        # and covariances written into the tracks' rows where applied (the kernel updates copies of the stacked rows:
        # the prior Xs / Ps stays as it is), then the shapes and, in the same loop, the riding and map-evidence
        # windows of the updated tracks from their new rows, and the windows of the re-acquired tracks (those that
        # missed scans) restarted to this push's entries (passes trk24, trk26, upd34). The configuration's values go
        # as one array built with the tracker (``_upd_p``, kernels_update.update_params; pass call35). The
        # bookkeeping per track follows in Python (_updated_pairs, _update_tracks).
        dm = self._default
        bound, lim, lim2 = self._accel_limits()
        p = self._pose
        c, s = self._pose_cs
        status, vetoed, nb, top, applied, unused, nrej, self._managed = associate_update(
            self._F, self._Fi, self._Gi, self._rows(), dm.z, dm.R, *self._batch, self._upd_p, claimed, vrows, ms,
            self._RIDE, bound, lim, lim2, *self._mev_src, self._map is not None, float(p.x), float(p.y), c, s, t,
            self._FQ, self._predict_in_kernel)
        self._predict_in_kernel = False
        if status:
            raise ValueError(LSAP_MESSAGES[status])  # (SciPy's error for such a cost matrix)
        if vetoed.shape[0]:
            tracks, add = self._tracks, self._merged.add
            for i in vetoed.tolist():
                add(tracks[i].id)
        if applied.shape[0] or nb or top:  # (no update ran, or none applied and nothing to count or grow: no-op)
            self._updated_pairs(applied, dets, t, nb, top)
        return nrej, unused.tolist()

    def _birth(self, det: Detection, t: float, j: int) -> None:
        """A new tentative track from detection ``det`` (index ``j`` of this scan's detections)."""
        cfg = self.config
        size, known = self._birth_shape(det, j)
        b = self._batch  # (the detection's kind and axis angle: its batch row, not its properties, ScanDetection)
        kind = KIND_NAMES[b.kind.item(j)]
        g, gi = _shape_rows(b.theta.item(j), size, known, b.circle.item(j, 2) if kind == KIND_CIRCLE else 0.0,
                            kind, kind == KIND_RECT)
        has_map, has_free = self._map is not None, self._free is not None
        d = self._default  # reference.measure(det, None, None, cfg.fit) of every detection
        z = d.z[j]
        k = _new_track(self._next_id, t, z.copy(), g, gi, det.beams, [det],
                       [_past_entry(t, det)] if has_free else [])
        self._next_id += 1
        self._add_row(k, None, None)
        if cfg.tracker.confirm_hits <= 1:
            k.state = CONFIRMED  # (in its counter row, which _add_row just made)
        self._start_windows(k.row, ((det.map_structure, det.map_free, det.map_unknown),) if has_map else ())
        # (the state and the initial covariance written into the new rows directly: _birth_state's values, without
        # the (4, 4) temporary it copies from; through k.x / k.P, the views of its rows that _add_row made, instead of
        # indexing the arrays again: ≈ 1 µs less a birth, docs/speed.md pass mgr34)
        x = k.x
        x[:2] = z
        x[2] = 0.0
        x[3] = 0.0
        Pr = k.P
        Pr.fill(0.0)
        Pr[:2, :2] = d.R[j]
        Pr[2, 2] = Pr[3, 3] = cfg.tracker.init_speed_sigma ** 2
        self.stats.tracks_born += 1

    def _births(self, dets: list[Detection], t: float, js: list[int], updated: set[int]) -> None:
        """:meth:`_birth` of the detections ``js`` (indices of this scan's ``dets``, in that order), tentative tracks
        (``confirm_hits`` > 1), their ids added to ``updated``: the rows taken one by one as :meth:`_birth` takes them,
        then written for all births in one kernel call (state, covariance, shape, counters, windows:
        ``kernels_update.birth_rows``, the same values), then each track's record made with views of its rows
        (docs/speed.md, pass trk38)."""
        tc = self.config.tracker
        has_map, has_free = self._map is not None, self._free is not None
        take = self._take_row
        rows = [take() for _ in js]
        bd = [dets[j] for j in js]
        # (the detections' map evidence, as _start_windows pushes it: (nb, 3); without a map never read)
        mev = np.array([(d.map_structure, d.map_free, d.map_unknown) for d in bd]) if has_map else _NO_MEV
        b = self._batch
        dm = self._default  # reference.measure(det, None, None, cfg.fit) of every detection
        ja = np.array(js, dtype=np.int64)
        X, P, G, Gi, CI, CL = self._X, self._P, self._G, self._Gi, self._CI, self._CL
        birth_rows(X, P, G, Gi, CI, CL, self._MEV, self._WN, np.array(rows, dtype=np.int64), ja, b.kind, b.theta,
                   b.lohi, b.rel, b.circle, dm.z, dm.R, dm.size_kind, mev, self._upd_p,
                   float(tc.init_speed_sigma ** 2), has_map, t)
        bxy = dm.z.take(ja, axis=0)  # (the birth places: the centres z, one array; each track's its row)
        tracks, add, new, nid = self._tracks, updated.add, _new_track, self._next_id
        for r, det, xy in zip(rows, bd, bxy):
            k = new(nid, t, xy, G[r], Gi[r], det.beams, [det], [_past_entry(t, det)] if has_free else [])
            k.row = r
            k.x = X[r]
            k.P = P[r]
            k.ci = CI[r]
            k.cl = CL[r:r + 1]
            tracks.append(k)
            add(nid)
            nid += 1
        self._next_id = nid
        self._order = None
        self.stats.tracks_born += len(js)

    def _birth_state(self, det: Detection, j: int) -> tuple[np.ndarray, np.ndarray, list[float], list[bool]]:
        """The measured centre z (2,), initial covariance P (4, 4), sizes and known-size flags of a track started
        from detection ``det`` (index ``j`` of this scan's detections), map frame, m."""
        cfg = self.config
        d = self._default  # reference.measure(det, None, None, cfg.fit) of every detection
        z = d.z[j]
        P = np.zeros((4, 4))
        P[:2, :2] = d.R[j]
        P[2, 2] = P[3, 3] = cfg.tracker.init_speed_sigma ** 2
        size, known = self._birth_shape(det, j)
        return z, P, size, known

    def _birth_shape(self, det: Detection, j: int) -> tuple[list[float], list[bool]]:
        """The sizes (m) and known-size flags of a track started from detection ``det`` (index ``j`` of this scan's
        detections)."""
        b = self._batch
        kind = KIND_NAMES[b.kind.item(j)]
        if kind == KIND_RECT:
            size = _default_sizes(b.lohi[j].tolist(), b.rel[j].tolist(), self.config.fit)
            sk0, sk1 = self._default.size_kind[j].tolist()
            return size, [sk0 == SIZE_MEASURED, sk1 == SIZE_MEASURED]
        if kind == KIND_CIRCLE:
            return [float(2.0 * det.circle[2])] * 2, [True, True]
        lo0, lo1, hi0, hi1 = self._batch.lohi[j].tolist()
        return [max(hi0 - lo0, 0.05), max(hi1 - lo1, 0.05)], [False, False]  # (np.maximum(det.extent, 0.05))


    def _retire(self, k: _Track) -> None:
        """Make ``k`` (a confirmed track being retired as structure in :meth:`_manage`) dormant: out of the live
        tracks (its state-array row is freed, so its state becomes its own copy, at rest), kept in
        ``_dormant``."""
        x = k.x.copy()
        x[2:] = 0.0
        k.x, k.P, k.g, k.gi, k.ci, k.cl = x, k.P.copy(), k.g.copy(), k.gi.copy(), k.ci.copy(), k.cl.copy()
        k.mev_kept = self._mev(k).copy()  # (its row's windows go with the row; a revival without a map keeps this)
        k.fast = 0
        k.slow_since = None
        k.reason = "not in M: still, on long-occupied map cells (retired as structure)"
        self._dormant.append(k)

    def _clutter_detections(self, dets: list[Detection], unused: list[int], t: float,
                            updated: set[int]) -> list[int]:
        """Clutter retirement's handling of the detections no track took (docs/real.md "Fewer clutter tracks").

        A dormant track (:meth:`_retire`) keeps the unused detections whose centroid lies within half its box's
        longer side plus ``fit.fragment_margin`` of its centre: their beams are its beams in this scan's report
        (the map's evidence ledger keeps recording what it writes, slam/erasure.py). Such a detection with fewer
        than ``structure_birth_min`` of its points on long-occupied cells has left the structure: its object
        moves, and the dormant track comes back to life with it (:meth:`_revive`; it keeps its id, its birth
        place and its standing history, which the retroactive erasure needs). Other detections with at least
        ``structure_birth_min`` on long-occupied cells get no track and join no track as a fragment (an
        unassociated piece of wall beside a mover in M is not part of it); their places are kept (``_marks``) so
        that no live track takes them in later scans either. Dormant tracks and places unseen for
        ``max_coast_time`` are deleted. Returns the detections left for births and fragments."""
        tc = self.config.tracker
        st = self.stats
        dorm = self._dormant
        if dorm:
            n0 = len(dorm)
            dorm[:] = [k for k in dorm if t - k.last_hit <= tc.max_coast_time]
            st.tracks_deleted += n0 - len(dorm)
            for k in dorm:
                if k.last_hit != t:  # (retired in this scan: it keeps the beams of its last update)
                    k.beams = _NO_BEAMS
                    k.misses += 1
        marks = self._marks
        if marks.shape[0]:
            marks = marks[t - marks[:, 3] <= tc.max_coast_time]
        birth_max = tc.structure_birth_min if self._map is not None else 1.1
        nd = len(dorm)
        if (nd or marks.shape[0]) and unused:
            gaps = self._claim_gaps(unused, marks)
            best, gap = gaps.argmin(axis=1).tolist(), gaps.min(axis=1).tolist()  # nearest dormant track / place
        else:
            best = gap = None
        revived: set[int] = set()
        new_marks = []
        margin = self.config.fit.fragment_margin
        out = []
        ms = self._structure_column(dets) if unused else ()  # (the detections' map_structure, one list a scan)
        for r, di in enumerate(unused):
            det = dets[di]
            on_structure = ms[di] >= birth_max
            if on_structure:
                lo0, lo1, hi0, hi1 = self._batch.lohi[di].tolist()
                reach = 0.5 * max(hi0 - lo0, hi1 - lo1) + margin
            if gap is not None and gap[r] <= 0.0:
                i = best[r]
                if i >= nd:  # a place of structure without a track
                    if on_structure:
                        marks[i - nd] = (det.centroid[0], det.centroid[1], reach, t)
                        st.unborn_structure += 1
                        continue
                elif i not in revived:
                    k = dorm[i]
                    if on_structure:
                        k.beams = det.beams if k.last_hit != t else np.concatenate((k.beams, det.beams))
                        k.last_hit = t
                        k.misses = 0
                        continue
                    self._revive(k, det, t, di)
                    updated.add(k.id)
                    revived.add(i)
                    continue
            if on_structure:
                new_marks.append((det.centroid[0], det.centroid[1], reach, t))
                st.unborn_structure += 1
                continue
            out.append(di)
        if revived:
            dorm[:] = [k for i, k in enumerate(dorm) if i not in revived]
        self._marks = np.vstack((marks, new_marks)) if new_marks else marks
        return out

    def _claim_gaps(self, sel: list[int], marks: np.ndarray) -> np.ndarray:
        """(len(sel), dormant + len(marks)) distance from the centroid of each detection ``sel`` to the centre of
        each dormant track, then of each place ``marks``, minus its reach (half the dormant track's longer side
        plus ``fit.fragment_margin``; a place's own reach), m (≤ 0: the detection is that object)."""
        dorm = self._dormant
        margin = self.config.fit.fragment_margin
        cen = np.concatenate((np.array([(k.x.item(0), k.x.item(1)) for k in dorm]).reshape(-1, 2), marks[:, :2]))
        reach = np.concatenate((np.array([0.5 * max(k.size) + margin for k in dorm]), marks[:, 2]))
        c = self._batch.centroid[sel]  # (the detections' centroids, this scan's batch)
        return np.hypot(c[:, 0, None] - cen[None, :, 0], c[:, 1, None] - cen[None, :, 1]) - reach[None, :]

    def _claims(self, ms: list[float]) -> np.ndarray:
        """(n,) bool: the detection has at least ``structure_birth_min`` of its points on long-occupied cells
        (``ms``: the detections' ``map_structure``, :meth:`_structure_column`) and is a dormant track's object or that
        of a kept place (:meth:`_claim_gaps`)."""
        out = np.zeros(len(ms), dtype=bool)
        smin = self.config.tracker.structure_birth_min
        sel = [di for di, v in enumerate(ms) if v >= smin]
        if sel:
            out[sel] = (self._claim_gaps(sel, self._marks) <= 0.0).any(axis=1)
        return out

    def _revive(self, k: _Track, det: Detection, t: float, j: int) -> None:
        """A dormant track whose object left the structure (detection ``det``, index ``j``) back among the live
        tracks: restarted at the detection like a birth (state, covariance, shape, evidence lists), keeping its
        id, birth time and place, hits and state (docs/real.md "Fewer clutter tracks")."""
        z, P, size, known = self._birth_state(det, j)
        self.stats.revived_structure += 1
        k.theta_box, k.size, k.size_known, k.kind = det.theta, size, known, det.kind
        k.radius = float(det.circle[2]) if det.kind == KIND_CIRCLE else 0.0
        k.has_heading = det.kind == KIND_RECT
        k.hits += 1
        k.misses = 0
        k.last_hit = t
        k.beams = det.beams
        k.free = [det.free_fraction]
        mev = ((det.map_structure, det.map_free, det.map_unknown),) if self._map is not None else k.mev_kept
        k.mev_kept = None
        k.past = [_past_entry(t, det)] if self._free is not None else []
        k.past_a = 0
        k.person, k.person_streak, k.rode = False, 0, False
        k.reason = "not in M: left the map structure it was retired on"
        self._maybe_remembered = True  # (a revived track keeps its flags: _predict looks again)
        self._add_row(k, (z[0], z[1], 0.0, 0.0), P)
        self._start_windows(k.row, mev)  # (no riding entry; the map evidence of this detection, or as retired)
