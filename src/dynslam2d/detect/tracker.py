"""Tracking of moving objects in the map frame: ``Tracker(config).update(scan, pose)``.

Per scan (datmo.md §10.4–10.8, with the fixes listed there):

1. bad input: a non-finite pose skips the scan; time going backwards, a gap > ``max_dt`` or a
   pose jump (faster than ``max_pose_speed`` / ``max_pose_rate``) drops every track; all counted
   in :attr:`Tracker.stats`, no exception;
2. predict every track to the scan stamp with the real dt (constant-velocity Kalman filter on
   the box centre, white-noise-acceleration Q(dt));
3. segment the scan (paper Eq. 1), transform the points into the map frame with the pose of
   the same scan, fit rectangle / circle / point models (paper Eq. 2);
4. exclusive association: Hungarian (``scipy.optimize.linear_sum_assignment``) on the
   Mahalanobis distance of the centre innovation, gated by χ² and a Euclidean distance;
5. Kalman update with the measurement of :mod:`dynslam2d.detect.measure` (which carries the
   track's size and heading: 90° ambiguity resolved against the track's axis), size and heading
   smoothing;
6. management: tentative → confirmed (M of N hits) → coasting (no detection, prediction only)
   → deleted (coasted longer than ``max_coast_time``, covariance blow-up, absurd speed);
7. the dynamic set M (paper Eq. 3): speed > v_min for ``sustain_updates`` consecutive
   updates, velocity well determined, and a net displacement ≥ ``min_displacement`` since
   birth; a track leaves M after ``sustain_updates`` updates below ``v_exit_ratio``·v_min.

Frames: the pose given with a scan is the laser pose in the map frame; every reported
quantity is in the map frame (m, rad, m/s).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.measure import (
    KIND_CIRCLE,
    KIND_POINT,
    KIND_RECT,
    SIZE_LOWER,
    SIZE_MEASURED,
    Detection,
    classify_and_bound,
    measure,
)
from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.detect.segment import Segmentation, segment_scan
from dynslam2d.detect.shapes import CRITERIA, fit_clusters, search_angles
from dynslam2d.types import Box, Pose2D, Scan, Track, wrap_angle

TENTATIVE = "tentative"
CONFIRMED = "confirmed"
COASTING = "coasting"
_HALF_PI = 0.5 * math.pi
_BIG = 1e12


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
    rejected_updates: int = 0
    merged_fragments: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass(eq=False)
class _Track:
    id: int
    x: np.ndarray  # [px, py, vx, vy], map frame
    P: np.ndarray  # 4×4
    born: float
    last_hit: float
    birth_xy: np.ndarray
    theta_box: float  # axis angle of size[0], rad
    size: np.ndarray  # sizes along theta_box and theta_box + π/2, m
    size_known: np.ndarray  # bool (2,)
    radius: float
    kind: str
    state: str = TENTATIVE
    hits: int = 1
    misses: int = 0
    history: list[bool] = field(default_factory=lambda: [True])
    fast: int = 0
    in_m: bool = False
    reason: str = "not in M: tentative track"
    beams: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    has_heading: bool = False
    size_lb: np.ndarray = field(default_factory=lambda: np.zeros(2))  # largest partial views per axis, m
    free: list[float] = field(default_factory=list)
    past: list[tuple[float, np.ndarray]] = field(default_factory=list)
    slow_since: float | None = None
    probation: bool = False  # in M, re-acquired after a gap: must show free-space evidence again


def _cv_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity transition F and white-noise-acceleration Q for state [x, y, vx, vy]."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    q11, q12, q22 = q * dt ** 3 / 3.0, q * dt ** 2 / 2.0, q * dt
    Q = np.array([[q11, 0, q12, 0], [0, q11, 0, q12], [q12, 0, q22, 0], [0, q12, 0, q22]])
    return F, Q


def _wrap_quarter(a: float) -> float:
    """Wrap to [−π/4, π/4): the difference between two rectangle axis angles (90° ambiguity)."""
    return (a + 0.25 * math.pi) % _HALF_PI - 0.25 * math.pi


class Tracker:
    """Detect and track moving objects from 2D scans in the map frame.

    ``update(scan, pose)`` takes a scan and the laser pose **of that scan** in the map frame and
    returns the live tracks (tentative, confirmed, coasting). See the module docstring.
    """

    def __init__(self, config: DetectConfig | None = None) -> None:
        self.config = config or DetectConfig()
        self.stats = TrackerStats()
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._last_stamp: float | None = None
        self._last_pose: Pose2D | None = None
        self._angles = search_angles(self.config.fit.angle_step_deg)
        tc = self.config.tracker
        self._free = FreeSpaceMemory(tc.free_ref_ages, tc.free_margin) if tc.free_space_check else None
        self._pair_meas: dict[tuple[int, int], object] = {}
        self._cur_ref = None
        #: Segmentation and detections of the last processed scan (for inspection / plots).
        self.last_segmentation: Segmentation | None = None
        self.last_detections: list[Detection] = []

    # ------------------------------------------------------------------ public
    def reset(self) -> None:
        """Forget every track and the free-space evidence (ids keep counting up)."""
        self._tracks.clear()
        if self._free is not None:
            self._free.clear()

    @property
    def n_tracks(self) -> int:
        return len(self._tracks)

    def update(self, scan: Scan, pose: Pose2D) -> list[Track]:
        """Process one scan with the laser pose of the same scan (map frame); return the live tracks."""
        st = self.stats
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
        self._predict(dt)
        for k in self._tracks:
            if k.has_heading and k.kind == KIND_RECT:
                self._motion_prior(k)
        dets = self._detect(scan, pose)
        if not dets and not scan.valid_mask().any():
            st.empty_scans += 1
        pairs = self._associate(dets)
        updated: set[int] = set()
        used = set()
        vac = self._vacated([self._tracks[ti] for ti, _ in pairs], t)
        for ti, di in pairs:
            trk, det = self._tracks[ti], dets[di]
            if self._update_track(trk, det, t, vac.get(trk.id, 0.0)):
                updated.add(trk.id)
                used.add(di)
            else:
                st.rejected_updates += 1
        self._manage(t, updated)
        for di, det in enumerate(dets):
            if di in used:
                continue
            host = self._host_of_fragment(det, updated)
            if host is not None:  # a piece of an object already updated: its beams belong to it
                host.beams = np.concatenate((host.beams, det.beams))
                st.merged_fragments += 1
                continue
            self._birth(det, t)
            updated.add(self._tracks[-1].id)
        return self._report(t, updated)

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

    # ------------------------------------------------------------------ steps
    def _is_jump(self, a: Pose2D, b: Pose2D, dt: float) -> bool:
        tc = self.config.tracker
        d = math.hypot(b.x - a.x, b.y - a.y)
        r = abs(float(wrap_angle(b.theta - a.theta)))
        if dt <= 1e-9:
            return d > 1e-3 or r > 1e-3
        return d / dt > tc.max_pose_speed or r / dt > tc.max_pose_rate

    def _predict(self, dt: float) -> None:
        if not self._tracks or dt <= 0.0:
            return
        F, Q = _cv_matrices(dt, self.config.tracker.accel_noise)
        X = np.stack([k.x for k in self._tracks])
        P = np.stack([k.P for k in self._tracks])
        X = X @ F.T
        P = F @ P @ F.T + Q
        for i, k in enumerate(self._tracks):
            k.x = X[i]
            k.P = P[i]

    def _detect(self, scan: Scan, pose: Pose2D) -> list[Detection]:
        cfg = self.config
        st = self.stats
        seg = segment_scan(scan, cfg.segment)
        self.last_segmentation = seg
        st.clusters += seg.n_clusters
        st.dropped_small_clusters += seg.n_dropped
        valid = scan.valid_mask() & (scan.ranges > 0.0)
        r = np.where(valid, scan.ranges, 0.0)
        a = scan.angles
        pts_all = pose.transform_points(np.column_stack((r * np.cos(a), r * np.sin(a))))
        sensor = np.array([pose.x, pose.y])
        if seg.n_clusters == 0:
            self.last_detections = []
            if self._free is not None:
                self._free.add(scan, pose, valid)
            return []
        pts = pts_all[seg.beams]
        fit_mask = ~seg.structure
        fits = fit_clusters(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), seg.offsets,
                            fit_mask, self._angles, CRITERIA[cfg.fit.criterion], cfg.fit.closeness_d0,
                            cfg.fit.circle_min_points, cfg.fit.coarse_stride)
        dets: list[Detection] = []
        max_ext = cfg.segment.max_extent
        for c in range(seg.n_clusters):
            if seg.structure[c]:
                st.structure_clusters += 1
                continue
            row = fits[c]
            if max(row[2] - row[1], row[4] - row[3]) > max_ext:
                st.structure_clusters += 1
                continue
            a0, a1 = seg.offsets[c], seg.offsets[c + 1]
            det = classify_and_bound(seg.beams[a0:a1], pts[a0:a1], row, sensor, scan.ranges, valid, pts_all,
                                     seg.wrapped, cfg.segment.max_skip_beams, scan.range_max, cfg.fit,
                                     abs(scan.angle_increment))
            dets.append(det)
        if self._free is not None:
            self._cur_ref = self._free.make_ref(scan, pose, valid)
            free = self._free.seen_through(pts, float(scan.stamp))
            for det in dets:
                a0 = seg.offsets[seg.labels[det.beams[0]]]
                det.free_fraction = float(free[a0:a0 + det.n_points].mean())
            self._free.add(scan, pose, valid, self._cur_ref)
        st.detections += len(dets)
        self.last_detections = dets
        return dets

    def _associate(self, dets: list[Detection]) -> list[tuple[int, int]]:
        n, m = len(self._tracks), len(dets)
        if n == 0 or m == 0:
            return []
        tc = self.config.tracker
        Z = np.empty((m, 2))
        R = np.empty((m, 2, 2))
        C = np.empty((m, 2))
        for j, d in enumerate(dets):
            meas = measure(d, None, None, self.config.fit)
            Z[j], R[j], C[j] = meas.z, meas.R, d.centroid
        X = np.stack([k.x[:2] for k in self._tracks])
        Pp = np.stack([k.P[:2, :2] for k in self._tracks])
        reach = np.array([0.5 * float(k.size.max()) for k in self._tracks])
        S = Pp[:, None, :, :] + R[None, :, :, :]  # (n, m, 2, 2)
        e = Z[None, :, :] - X[:, None, :]
        det_s = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            d2 = (S[..., 1, 1] * e[..., 0] ** 2 - 2.0 * S[..., 0, 1] * e[..., 0] * e[..., 1]
                  + S[..., 0, 0] * e[..., 1] ** 2) / det_s
        dist = np.hypot(C[None, :, 0] - X[:, None, 0], C[None, :, 1] - X[:, None, 1])
        near = dist < tc.gate_distance + reach[:, None]
        # a rectangle measured with the track's own sizes (a side the detection "measured" too short,
        # e.g. a grazing side, must not break the association); kept for the update of chosen pairs
        self._pair_meas = {}
        for i, j in zip(*np.nonzero(near)):
            k, d = self._tracks[i], dets[j]
            if d.kind != KIND_RECT or not k.has_heading or k.kind != KIND_RECT:
                continue
            m2 = measure(d, self._sizes_in_fit_axes(k, d), None, self.config.fit, size_sigma=0.05)
            self._pair_meas[(k.id, id(d))] = m2
            s2 = k.P[:2, :2] + m2.R
            e2 = m2.z - k.x[:2]
            try:
                alt = float(e2 @ np.linalg.solve(s2, e2))
            except np.linalg.LinAlgError:
                continue
            if not d2[i, j] <= alt:
                d2[i, j] = alt
        ok = np.isfinite(d2) & (d2 < tc.gate_chi2) & near
        if not ok.any():
            return []
        cost = np.where(ok, d2, _BIG)
        # established tracks choose first; tentative ones share what is left
        firm = np.array([k.state != TENTATIVE for k in self._tracks])
        pairs: list[tuple[int, int]] = []
        taken = np.zeros(m, dtype=bool)
        for group in (firm, ~firm):
            if not group.any():
                continue
            rows_idx = np.flatnonzero(group)
            sub = cost[rows_idx][:, ~taken]
            cols_idx = np.flatnonzero(~taken)
            if sub.size == 0:
                continue
            rr, cc = linear_sum_assignment(sub)
            for r, c in zip(rr, cc):
                i, j = int(rows_idx[r]), int(cols_idx[c])
                if ok[i, j]:
                    pairs.append((i, j))
                    taken[j] = True
        return pairs

    def _update_track(self, k: _Track, det: Detection, t: float, vacated: float = 0.0) -> bool:
        cfg = self.config
        tc = cfg.tracker
        swap = False
        sizes_fit = None
        if det.kind == KIND_RECT and k.has_heading:
            swap = self._swapped(k, det)
            sizes_fit = self._sizes_in_fit_axes(k, det)
        radius = k.radius if (det.kind == KIND_CIRCLE and k.kind == KIND_CIRCLE and k.radius > 0) else None
        meas = None
        if sizes_fit is not None and radius is None:
            meas = self._pair_meas.get((k.id, id(det)))
        if meas is None:
            meas = measure(det, sizes_fit, radius, cfg.fit, size_sigma=0.05)
        H = meas.H
        S = H @ k.P @ H.T + meas.Rm
        y = meas.zm - H @ k.x
        try:
            Sinv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            return False
        K = k.P @ H.T @ Sinv
        x_new = k.x + K @ y
        P_new = k.P - K @ H @ k.P
        P_new = 0.5 * (P_new + P_new.T)
        if not (np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new))):
            return False
        k.x, k.P = x_new, P_new
        # shape: heading (90° ambiguity) and sizes along the track's own axes
        if det.kind == KIND_RECT:
            if not k.has_heading or k.kind != KIND_RECT:
                k.theta_box = det.theta
                k.has_heading = True
                swap = False
                k.size = det.default_sizes(cfg.fit)
                k.size_known = meas.size_kind == SIZE_MEASURED
            else:
                informative = det.rel.any(axis=1).all() or float(det.extent.max()) > 0.3
                if informative:
                    k.theta_box = float(wrap_angle(k.theta_box + tc.heading_gain * _wrap_quarter(det.theta - k.theta_box)))
                for a in (0, 1):
                    ta = 1 - a if swap else a
                    obs, kind = float(meas.size_obs[a]), int(meas.size_kind[a])
                    if kind == SIZE_MEASURED:
                        if k.size_known[ta]:
                            k.size[ta] += tc.size_gain * (obs - k.size[ta])
                        else:
                            k.size[ta] = obs
                            k.size_known[ta] = True
                    elif kind == SIZE_LOWER:
                        k.size_lb[ta] = max(k.size_lb[ta], obs)
                        if obs > k.size[ta]:
                            k.size[ta] = obs
        elif det.kind == KIND_CIRCLE:
            r = float(det.circle[2])
            k.radius = r if k.kind != KIND_CIRCLE or k.radius <= 0 else k.radius + tc.size_gain * (r - k.radius)
            k.size = np.array([2.0 * k.radius, 2.0 * k.radius])
        elif det.kind == KIND_POINT and k.kind == KIND_POINT:
            k.size = np.maximum(det.extent, 0.05)
        if k.misses > 0:
            # re-acquired after a gap: the free-space evidence must be rebuilt from this object
            k.past.clear()
            k.free.clear()
            k.fast = 0
            k.probation = k.in_m
        k.kind = det.kind
        k.hits += 1
        k.misses = 0
        k.last_hit = t
        k.history.append(True)
        k.beams = det.beams
        k.free.append(max(det.free_fraction, vacated))
        if len(k.free) > tc.sustain_updates:
            del k.free[0]
        if self._free is not None:
            k.past.append((t, det.points))
            while k.past and t - k.past[0][0] > self._free.max_age:
                del k.past[0]
        return True

    @staticmethod
    def _swapped(k: _Track, det: Detection) -> bool:
        """True when the detection's first axis is the track's second (90° ambiguity)."""
        return int(round((det.theta - k.theta_box) / _HALF_PI)) % 2 == 1

    def _sizes_in_fit_axes(self, k: _Track, det: Detection) -> np.ndarray:
        """The track's sizes along the detection's axes e1, e2, m."""
        return k.size[::-1].copy() if self._swapped(k, det) else k.size.copy()

    def _motion_prior(self, k: _Track) -> None:
        """Hidden side of a moving box whose other side is measured: a side parallel to the motion is
        the length, one across it the width (``aspect_prior`` = width / length; cars and carts move
        along their long axis). Moves the hidden size by ``size_gain`` per update, never below the
        largest partial view."""
        tc = self.config.tracker
        if tc.aspect_prior is None or k.state == TENTATIVE or k.size_known.all() or not k.size_known.any():
            return
        speed = math.hypot(k.x[2], k.x[3])
        if speed < tc.prior_min_speed:
            return
        a = 0 if not k.size_known[0] else 1  # the hidden axis
        ax = k.theta_box + a * _HALF_PI
        c = abs(math.cos(ax) * k.x[2] + math.sin(ax) * k.x[3]) / speed
        if c > 0.9:  # hidden axis along the motion: it is the length
            prior = k.size[1 - a] / tc.aspect_prior
        elif c < 0.45:  # across the motion: the width
            prior = k.size[1 - a] * tc.aspect_prior
        else:
            return
        prior = min(max(prior, k.size_lb[a]), self.config.segment.max_extent)
        k.size[a] += tc.size_gain * (prior - k.size[a])

    def _vacated(self, tracks: list[_Track], t: float) -> dict[int, float]:
        """Per track id: the largest fraction of its earlier points (at the free-space reference ages)
        that the current scan sees through — a receding object leaves free space behind its visible
        face. One vectorised test for all tracks."""
        out: dict[int, float] = {}
        if self._free is None or self._cur_ref is None:
            return out
        chunks: list[np.ndarray] = []
        owners: list[tuple[int, int]] = []
        for k in tracks:
            if not k.past:
                continue
            ages = np.array([t - p[0] for p in k.past])
            for a in self._free.ref_ages:
                j = int(np.argmin(np.abs(ages - a)))
                if ages[j] > 0.0:
                    chunks.append(k.past[j][1])
                    owners.append((k.id, k.past[j][1].shape[0]))
        if not chunks:
            return out
        free = self._free.seen_through_by(self._cur_ref, np.vstack(chunks))
        i = 0
        for tid, n in owners:
            f = float(free[i:i + n].mean()) if n else 0.0
            out[tid] = max(out.get(tid, 0.0), f)
            i += n
        return out

    def _birth(self, det: Detection, t: float) -> None:
        cfg = self.config
        meas = measure(det, None, None, cfg.fit)
        P = np.zeros((4, 4))
        P[:2, :2] = meas.R
        P[2, 2] = P[3, 3] = cfg.tracker.init_speed_sigma ** 2
        if det.kind == KIND_RECT:
            size = det.default_sizes(cfg.fit)
            known = meas.size_kind == SIZE_MEASURED
        elif det.kind == KIND_CIRCLE:
            size = np.full(2, 2.0 * det.circle[2])
            known = np.ones(2, dtype=bool)
        else:
            size = np.maximum(det.extent, 0.05)
            known = np.zeros(2, dtype=bool)
        k = _Track(id=self._next_id, x=np.array([meas.z[0], meas.z[1], 0.0, 0.0]), P=P, born=t, last_hit=t,
                   birth_xy=meas.z.copy(), theta_box=det.theta, size=np.asarray(size, dtype=np.float64),
                   size_known=np.asarray(known, dtype=bool), radius=float(det.circle[2]) if det.kind == KIND_CIRCLE
                   else 0.0, kind=det.kind, beams=det.beams, has_heading=det.kind == KIND_RECT,
                   free=[det.free_fraction], past=[(t, det.points)] if self._free is not None else [])
        if cfg.tracker.confirm_hits <= 1:
            k.state = CONFIRMED
        self._next_id += 1
        self._tracks.append(k)
        self.stats.tracks_born += 1

    def _manage(self, t: float, updated: set[int]) -> None:
        tc = self.config.tracker
        st = self.stats
        keep: list[_Track] = []
        for k in self._tracks:
            if k.id not in updated:
                k.misses += 1
                k.history.append(False)
                k.beams = np.zeros(0, dtype=np.int64)
                if k.state == CONFIRMED:
                    k.state = COASTING
            elif k.state == COASTING:
                k.state = CONFIRMED
            if k.state == TENTATIVE:
                h = k.history[: tc.confirm_window]
                if sum(h) >= tc.confirm_hits:
                    k.state = CONFIRMED
                elif sum(h) + (tc.confirm_window - len(h)) < tc.confirm_hits or k.misses > 0 and len(
                        k.history) >= tc.confirm_window:
                    st.deleted_tentative += 1
                    st.tracks_deleted += 1
                    continue
            if k.state == COASTING and t - k.last_hit > tc.max_coast_time:
                st.deleted_coasting += 1
                st.tracks_deleted += 1
                continue
            pv = k.P[:2, :2]
            if not np.all(np.isfinite(k.P)) or math.sqrt(max(pv[0, 0], pv[1, 1])) > tc.max_position_sigma:
                st.deleted_covariance += 1
                st.tracks_deleted += 1
                continue
            speed = math.hypot(k.x[2], k.x[3])
            if speed > tc.max_object_speed:
                st.deleted_speed += 1
                st.tracks_deleted += 1
                continue
            if k.id in updated:
                self._dynamic(k, speed, t)
            keep.append(k)
        self._tracks = keep

    def _dynamic(self, k: _Track, speed: float, t: float) -> None:
        """Paper Eq. 3 with persistence, certainty and displacement conditions."""
        tc = self.config.tracker
        if speed > 1e-9:
            u = k.x[2:] / speed
            sig = math.sqrt(max(float(u @ k.P[2:, 2:] @ u), 0.0))
        else:
            sig = math.sqrt(max(k.P[2, 2], k.P[3, 3]))
        fast = speed > tc.v_min and sig < tc.max_speed_sigma
        k.fast = k.fast + 1 if fast else 0
        if speed < tc.v_exit_ratio * tc.v_min:
            k.slow_since = t if k.slow_since is None else k.slow_since
        else:
            k.slow_since = None
        disp = float(np.hypot(*(k.x[:2] - k.birth_xy)))
        if k.in_m and k.probation and self._free is not None and len(k.free) >= tc.sustain_updates:
            k.probation = False
            if sum(k.free) / len(k.free) < tc.free_min_fraction:
                k.in_m = False
                k.fast = 0
                k.reason = ("left M: after a gap the detections show no motion into free space "
                            "(a different, static object)")
                return
        if k.in_m:
            slow_for = 0.0 if k.slow_since is None else t - k.slow_since
            if k.slow_since is not None and slow_for >= tc.m_exit_time:
                k.in_m = False
                k.reason = (f"left M: speed {speed:.2f} m/s below {tc.v_exit_ratio * tc.v_min:.2f} for "
                            f"{slow_for:.1f} s")
            elif k.slow_since is not None:
                k.reason = f"in M (hysteresis): slow ({speed:.2f} m/s) for {slow_for:.1f} s"
            else:
                k.reason = f"in M: speed {speed:.2f} m/s, moved {disp:.2f} m since birth"
            return
        if k.state == TENTATIVE:
            k.reason = "not in M: tentative track"
        elif speed <= tc.v_min:
            k.reason = f"not in M: speed {speed:.2f} m/s ≤ v_min {tc.v_min:.2f}"
        elif sig >= tc.max_speed_sigma:
            k.reason = f"not in M: velocity uncertain (σ {sig:.2f} m/s)"
        elif k.fast < tc.sustain_updates:
            k.reason = f"not in M: speed > v_min for {k.fast}/{tc.sustain_updates} updates"
        elif disp < tc.min_displacement:
            k.reason = f"not in M: moved {disp:.2f} m < {tc.min_displacement:.2f} m since birth"
        elif self._free is not None and (not k.free or sum(k.free) / len(k.free) < tc.free_min_fraction):
            k.reason = (f"not in M: points on free space {sum(k.free) / max(len(k.free), 1):.2f} < "
                        f"{tc.free_min_fraction:.2f} (static structure)")
        else:
            k.in_m = True
            k.reason = (f"in M: speed {speed:.2f} m/s > v_min for {k.fast} updates, moved {disp:.2f} m "
                        "since birth")

    # ------------------------------------------------------------------ output
    def _report(self, t: float, updated: set[int]) -> list[Track]:
        out = []
        tc = self.config.tracker
        for k in self._tracks:
            vx, vy = float(k.x[2]), float(k.x[3])
            speed = math.hypot(vx, vy)
            if k.kind == KIND_CIRCLE:
                theta = math.atan2(vy, vx) if speed > 0.5 * tc.v_min else 0.0
                length = width = 2.0 * k.radius
            else:
                sa, sb = float(k.size[0]), float(k.size[1])
                if speed > 0.5 * tc.v_min:
                    vdir = math.atan2(vy, vx)
                    q = int(round(float(wrap_angle(vdir - k.theta_box)) / _HALF_PI))
                    theta = k.theta_box + q * _HALF_PI
                    length, width = (sa, sb) if q % 2 == 0 else (sb, sa)
                elif sb > sa:
                    theta, length, width = k.theta_box + _HALF_PI, sb, sa
                else:
                    theta, length, width = k.theta_box, sa, sb
                theta = float(wrap_angle(theta))
            beams = k.beams if k.id in updated else np.zeros(0, dtype=np.int64)
            out.append(Track(id=k.id, state=k.state, stamp=t,
                             box=Box(float(k.x[0]), float(k.x[1]), theta, float(length), float(width)),
                             velocity=np.array([vx, vy]), covariance=k.P.copy(), age=t - k.born, hits=k.hits,
                             misses=k.misses, kind=k.kind, in_m=k.in_m, m_reason=k.reason, beams=beams,
                             n_points=int(beams.shape[0])))
        return out
