"""Hector-style SLAM processor: one scan in, one pose out (hector_mapping
``HectorSlamProcessor``; docs/slam.md).

``HectorSlam.process(scan)`` = :meth:`~HectorSlam.match` (pose estimate, no map change) +
:meth:`~HectorSlam.update_map` (integrate into every level if the distance / angle
thresholds are exceeded, always on the first scan). A pipeline that removes moving
objects calls the two halves itself: match with the movers' points removed, then update
the map with the filtered scan.

Frames: every pose is the **laser** pose in the map frame; the map frame is the laser pose
of the first accepted scan (or the ``predicted`` pose given with it).
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.correlative import correlative_search
from dynslam2d.slam.grid import MapTooLargeError, MultiResMap
from dynslam2d.slam.matcher import (
    BIN_ANGLE,
    Degeneracy,
    LevelFit,
    covariance_world,
    degeneracy,
    degeneracy_values,
    evaluate,
    free_fraction,
    gated_points,
    match_fit_at,
    match_multires,
    no_drop,
    support_at,
    unit_axis,
)
from dynslam2d.slam.recovery import REJECT_AMBIGUOUS, ScanPeriod, needs_recovery, recover
from dynslam2d.types import Pose2D, Scan, wrap_angle

#: Reasons a scan is skipped (no matching, no map update).
SKIP_TOO_FEW_POINTS = "too_few_points"
#: Reasons a match is rejected (pose reported, map not updated).
REJECT_NON_FINITE = "non_finite_pose"
REJECT_JUMP = "jump"
REJECT_LOW_SCORE = "low_score"
REJECT_FREE_SPACE = "endpoints_in_free_space"
#: The pose is predicted (motion model / odometry), the scan kept out of the map (issue 10 item 3).
PREDICT_TOO_CLOSE = "too_close"  # most returns closer than laser_min_dist: something against the sensor
PREDICT_NARROW = "narrow_sector"  # the returns cover too small an angle to fix the pose
PREDICT_UNSUPPORTED = "unsupported_jump"  # moved beyond the motion model without enough structure
PREDICT_LOST = "lost"  # lost, and no relocalisation clearly better than its alternatives
#: States of the processor.
STATE_TRACKING = "tracking"
STATE_LOST = "lost"
#: Where a pose came from.
SOURCE_SCAN = "scan"  # the scan match alone
SOURCE_SCAN_PRIOR = "scan+prior"  # the scan along well-constrained directions, the prior along degenerate ones
SOURCE_PREDICTION = "prediction"  # motion model / odometry only
SOURCE_RELOCALISED = "relocalised"  # wide search after being lost
#: 'auto' correlative mode searches on the first matches, before a score average exists.
_WARMUP_SEARCHES = 3
#: A degenerate direction stays degenerate while its ratio is below this × degeneracy_threshold.
_DEGENERACY_HYSTERESIS = 1.5
#: odometry_prior "all": a match farther from the odometry prediction than this squared Mahalanobis
#: distance (χ² with 3 degrees of freedom, 99 %) is not fused with it.
_ODOMETRY_GATE_CHI2 = 11.34
#: Interpolated probability below which an endpoint counts as landing in known free space.
FREE_SPACE_PROB = 0.45
#: the pose components a prediction knows: all, or only θ (an IMU's yaw without the motion model); shared, read only
_ALL_AXES = np.ones(3, dtype=bool)
_ALL_AXES.flags.writeable = False
_THETA_AXIS = np.array([False, False, True])
_THETA_AXIS.flags.writeable = False
#: the covariance of a scan that was not matched (copied into each MatchResult that reads it: callers may change theirs)
_NO_MATCH_COVARIANCE = np.diag([1e6, 1e6, math.pi**2])
#: ``MatchResult._covariance_of`` of a result not (yet) matched: its covariance is a copy of _NO_MATCH_COVARIANCE,
#: made when first read (a matched scan replaces it in ``_fit`` before anyone reads it)
_NO_MATCH: tuple = ()
#: ``MatchResult.hessian`` of a result not (yet) matched: zeros, shared by every such result (read-only; a match
#: replaces the array in ``_fit``, nothing writes into it)
_ZERO_HESSIAN = np.zeros((3, 3))
_ZERO_HESSIAN.flags.writeable = False


def _wrap(a: float) -> float:
    """:func:`~dynslam2d.types.wrap_angle` of a float (the same operations)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _between(a: Pose2D, b: Pose2D) -> tuple[float, float, float]:
    """(x, y, θ) of ``a.between(b)`` (``a⁻¹ ⊕ b``) without the two intermediate :class:`Pose2D`: the same float
    operations in the same order as ``Pose2D.inverse`` and ``Pose2D.compose``, so the same bits."""
    c, s = math.cos(a.theta), math.sin(a.theta)
    ix, iy, ith = -c * a.x - s * a.y, s * a.x - c * a.y, _wrap(-a.theta)
    c, s = math.cos(ith), math.sin(ith)
    return ix + c * b.x - s * b.y, iy + s * b.x + c * b.y, _wrap(ith + b.theta)


def _compose(a: Pose2D, x: float, y: float, theta: float) -> Pose2D:
    """``a.compose(Pose2D(x, y, theta))`` (the same operations as ``Pose2D.compose``)."""
    c, s = math.cos(a.theta), math.sin(a.theta)
    return Pose2D(a.x + c * x - s * y, a.y + s * x + c * y, _wrap(a.theta + theta))


@dataclass(slots=True)
class MatchResult:
    """Result of matching one scan against the current map (the map is not changed).

    Attributes:
        pose: estimated laser pose in the map frame (m, rad). For a skipped scan or a rejected
            jump / non-finite match this is the start estimate.
        start: the start estimate used (m, rad).
        covariance: (3, 3) σ²·H⁻¹ in world units (m², m·rad, rad²), order (x, y, θ).
        hessian: (3, 3) raw Gauss–Newton Hessian at ``pose`` on level 0, in level-0 cell / rad
            units — what hector_mapping publishes as "covariance" (hector_slam issue #35).
        score: mean interpolated occupancy probability of the endpoints on level 0 at ``pose``
            (0 … 1; 0 on an empty map).
        n_points: valid returns used (after the range gates).
        free_fraction: fraction of the endpoints that land in known free space (level 1) at ``pose``.
        used_correlative: a correlative search seeded Gauss–Newton.
        rejected: the match is not fit to be written into the map.
        reason: why it was skipped / rejected (None if fine).
        skipped: the scan had too little data to match (``reason`` says why).
        time_gap: the stamp jumped by more than ``max_time_gap`` (or went backwards).
        first: this is the first scan (the map is empty; pose = start estimate).
        match_ms: wall time of the matching, ms.
        points: (n, 2) the gated returns in the laser frame, m (what the map update uses).
        clear_points: (m, 2) ends of the free-space clearing rays in the laser frame, m.
        degeneracy: smallest / largest eigenvalue of the normalized match Hessian (0 … 1; NaN when
            not matched) — Zhang et al. 2016.
        degenerate: some direction of the match is degenerate (below ``degeneracy_threshold``).
        support_points: endpoints on occupied map cells at ``pose`` (count).
        support_spread: angle covered by their bearings, rad.
        low_support: the pose is not backed by a well-supported match (predicted, or matched with
            fewer than ``support_min_points`` points / less than ``support_min_spread``).
        prior: where the prediction came from: "odometry", "imu", "motion_model" or None.
        pose_source: "scan", "scan+prior", "prediction" or "relocalised".
        state: "tracking" or "lost" after this scan.
    """

    pose: Pose2D
    start: Pose2D
    _covariance: np.ndarray | None  # (see the covariance property)
    hessian: np.ndarray
    score: float
    n_points: int
    free_fraction: float = 0.0
    used_correlative: bool = False
    rejected: bool = False
    reason: str | None = None
    skipped: bool = False
    time_gap: bool = False
    first: bool = False
    match_ms: float = 0.0
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)
    clear_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)
    degeneracy: float = math.nan
    degenerate: bool = False
    support_points: int = 0
    support_spread: float = 0.0
    low_support: bool = False
    prior: str | None = None
    pose_source: str = SOURCE_SCAN
    state: str = STATE_TRACKING
    sigma2: float = math.nan
    #: (Hessian, σ², cell side m) the covariance is computed from when first read (most scans never read it);
    #: ``_NO_MATCH`` (empty): the no-match covariance, copied when first read
    _covariance_of: tuple[np.ndarray, float, float] | None = field(default=None, repr=False)

    @property
    def covariance(self) -> np.ndarray:
        """(3, 3) σ²·H⁻¹ in world units (m², m·rad, rad²), order (x, y, θ); computed on first access."""
        if self._covariance is None and self._covariance_of is not None:
            of = self._covariance_of
            self._covariance = covariance_world(*of) if of else _NO_MATCH_COVARIANCE.copy()
            self._covariance_of = None
        return self._covariance

    @covariance.setter
    def covariance(self, value: np.ndarray) -> None:
        self._covariance = value
        self._covariance_of = None


@dataclass(slots=True)
class _Prior:
    """The motion prediction of one scan: pose (map frame), where it came from, which pose
    components it knows (x, y, θ) and whether a motion model exists for gating."""

    pose: Pose2D
    kind: str | None
    axes: np.ndarray
    gate: bool
    delta: tuple[float, float, float] | None = None  # (x m, y m, θ rad) of the odometry increment since the
    # previous scan (laser frame): ``prev_odom.between(odom)``'s values


@dataclass(slots=True)
class SlamStep:
    """What :meth:`HectorSlam.process` returns for one scan.

    Attributes:
        index: 0-based index of the scan among all scans given to this processor.
        stamp: the scan's stamp, s.
        pose: laser pose in the map frame (m, rad).
        covariance: (3, 3) world-unit covariance (m², m·rad, rad²).
        hessian: (3, 3) raw Hessian, level-0 cells / rad.
        score: match quality (see :class:`MatchResult`).
        free_fraction: fraction of endpoints in known free space (see :class:`MatchResult`).
        map_updated: the scan was integrated into the map.
        rejected: the match was judged bad and not written into the map.
        skipped: the scan was not matched (too little data).
        reason: skip / reject reason, or None.
        used_correlative: a correlative search seeded the match.
        time_gap: a stamp gap or backward stamp was seen before this scan.
        n_points: returns used.
        match_ms, update_ms: wall times, ms.
        degeneracy, degenerate, support_points, support_spread, low_support, pose_source, state:
            pose confidence, see :class:`MatchResult`.
    """

    index: int
    stamp: float
    pose: Pose2D
    covariance: np.ndarray
    hessian: np.ndarray
    score: float
    free_fraction: float
    map_updated: bool
    rejected: bool
    skipped: bool
    reason: str | None
    used_correlative: bool
    time_gap: bool
    n_points: int
    match_ms: float
    update_ms: float
    degeneracy: float = math.nan
    degenerate: bool = False
    support_points: int = 0
    support_spread: float = 0.0
    low_support: bool = False
    pose_source: str = SOURCE_SCAN
    state: str = STATE_TRACKING


class HectorSlam:
    """Multi-resolution log-odds mapping + scan-to-map matching, no odometry required.

    >>> from dynslam2d.slam import HectorSlam, SlamConfig
    >>> slam = HectorSlam(SlamConfig())
    >>> # for scan in source: step = slam.process(scan)
    """

    def __init__(self, config: SlamConfig | None = None) -> None:
        self.config = config if config is not None else SlamConfig()
        c = self.config
        self.map = MultiResMap(
            c.map_resolution, c.map_levels, c.logodds_free, c.logodds_occupied,
            c.occupied_logodds_cap, c.map_growth_margin, int(c.max_map_memory_mb * 1e6),
            c.grazing_stop_cells, c.grazing_min_incidence_deg,
        )
        self.counts: Counter[str] = Counter()
        self.n_scans = 0
        self.n_map_updates = 0
        self._last_pose: Pose2D | None = None
        self._last_stamp: float | None = None
        # (vx, vy, ω) in the previous laser frame, per s (floats: only the constant-velocity start reads them)
        self._velocity: tuple[float, float, float] | None = None
        self._last_motion = (0.0, 0.0)  # (|Δxy| m, |Δθ| rad) between the last two poses
        self._last_map_pose: Pose2D | None = None
        self._score_avg: float | None = None
        self._force_search = False
        self._odometry_start = False  # the scan being matched starts from the odometry's prediction
        self._n_accepted = 0  # accepted matches against a non-empty map
        self._last_odom: Pose2D | None = None  # Scan.odom of the previous scan
        self._last_yaw_rate: float | None = None
        self._state = STATE_TRACKING
        self._unsupported_since: float | None = None  # stamp of the first scan of the current unsupported run
        self.lost_events = 0
        #: front-end correlative searches run before the match ('auto' triggers or 'always'), whether or not
        #: their pose won (``counts["correlative"]`` counts only the winners)
        self.pre_searches = 0
        self.relocalisations = 0
        self._refused: tuple[float, Pose2D, int] | None = None  # (since, pose, scan number) of a refused weak match
        self._degenerate_prev = (False, False)  # (translation, rotation) degenerate on the last matched scan
        self._last_relocalise: float | None = None  # stamp of the last relocalisation attempt
        self._history: deque[tuple[float, Pose2D]] = deque()  # accepted (stamp, pose) of the last velocity_window s
        self._sigma2: float | None = None  # running residual variance of accepted matches (probability²)
        self._dt: float | None = None  # stamp of the scan being matched minus the previous one's, s
        self._period = ScanPeriod()  # typical stamp gap (the motion gate's floor with recovery on)
        self._last_points: tuple[Scan | None, np.ndarray, np.ndarray] | None = None  # scan_points of the last match
        #: (points, Σ x² + y² of them) of the last match's points (:meth:`_gate`), for :func:`degeneracy`
        self._sumsq: tuple[np.ndarray, float] | None = None
        # (result, pose, (count, spread)): the support the matcher's kernel took at the pose _match_against_map gave
        # that result; :meth:`_support` uses it while the result still holds that same pose object
        self._support_of: tuple[MatchResult, Pose2D, tuple[int, float]] | None = None
        #: the last :meth:`_fit`'s evaluation (its ``degeneracy``: the matcher's analysis of its Hessian, if taken)
        self._fit_of: LevelFit | None = None

    # ---- properties --------------------------------------------------------------------
    @property
    def pose(self) -> Pose2D | None:
        """The last estimated laser pose in the map frame, or None before the first scan."""
        return self._last_pose

    @property
    def memory_bytes(self) -> int:
        """Bytes held by the map levels."""
        return self.map.memory_bytes

    def gridmap(self, level: int = 0) -> GridMap:
        """The map of ``level`` (0 = finest) as probabilities, NaN = never observed, cropped to the
        observed area."""
        return self.map.to_gridmap(level)

    def logodds(self, level: int = 0) -> tuple[np.ndarray, tuple[float, float]]:
        """(raw log-odds array (H, W), row 0 at the bottom; world (x, y) of the lower-left corner
        of cell (0, 0), m) of ``level``, cropped to the observed area."""
        return self.map.export_logodds(level)

    def summary(self) -> dict[str, object]:
        """Counters for a run summary: scans, map updates, skip/reject reasons, memory."""
        return {
            "scans": self.n_scans,
            "map_updates": self.n_map_updates,
            "reasons": dict(self.counts),
            "memory_bytes": self.memory_bytes,
            "map_grows": sum(lv.n_grows for lv in self.map.levels),
            "lost_events": self.lost_events,
            "relocalisations": self.relocalisations,
        }

    @property
    def state(self) -> str:
        """"tracking" or "lost" (no supported match for ``lost_after`` s; see :meth:`match`)."""
        return self._state

    # ---- preprocessing -----------------------------------------------------------------
    def scan_points(self, scan: Scan) -> tuple[np.ndarray, np.ndarray]:
        """(returns (n, 2), clearing-ray ends (m, 2)) in the laser frame, m.

        Returns: finite ranges inside the sensor limits and strictly inside
        (laser_min_dist, laser_max_dist) (hector_mapping HectorMappingRos.cpp). Clearing rays (only if
        ``clear_no_return_dist`` > 0): beams without a return, ending at that distance.
        """
        return self._gate(scan, False)[:2]

    def _gate(self, scan: Scan, stats: bool, drop: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, int, int, int, float]:
        """:meth:`scan_points` and, with ``stats``, (valid returns, those within laser_min_dist, bearing bins of the
        returns, Σ x² + y² of the returns for :func:`~dynslam2d.slam.matcher.degeneracy`) for the too-close and
        narrow-view tests (:func:`~dynslam2d.slam.matcher.gated_points`); ``drop`` (n,) bool: beams taken as without
        a return (those of ``scan.without(drop)``)."""
        c = self.config
        cos_a, sin_a = scan.trig()
        valid = scan.valid_view()  # (the kernel only reads it: no copy)
        # (one kernel call for the gates, the points, the clearing-ray ends and the per-scan tests' counts)
        return gated_points(scan.ranges, cos_a, sin_a, valid, float(scan.range_min),
                            float(scan.range_max), float(c.laser_min_dist), float(c.laser_max_dist),
                            float(c.clear_no_return_dist), stats,
                            no_drop(scan.ranges.shape[0]) if drop is None else drop)

    # ---- prediction --------------------------------------------------------------------
    def predict(self, stamp: float) -> Pose2D:
        """The start estimate :meth:`match` would use for a scan at ``stamp`` (map frame):
        the previous pose, or the constant-velocity prediction when configured."""
        return self._predict(stamp)[0]

    def _predict(self, stamp: float) -> tuple[Pose2D, bool]:
        """Start estimate for a scan at ``stamp`` and whether a time gap was seen."""
        c = self.config
        gap = False
        dt = None
        if self._last_stamp is not None:
            dt = stamp - self._last_stamp
            if dt < 0.0 or dt > c.max_time_gap:
                gap = True
        if self._last_pose is None:
            return Pose2D(), gap
        if c.constant_velocity and not gap and self._velocity is not None and dt is not None:
            vx, vy, vth = self._velocity
            return self._last_pose.compose(Pose2D(vx * dt, vy * dt, vth * dt)), gap
        return self._last_pose, gap

    # ---- motion prior -------------------------------------------------------------------
    def _prior(self, scan: Scan, start: Pose2D, gap: bool) -> _Prior:
        """The prediction of ``scan``'s pose: the odometry delta since the previous scan
        (prev_odom⁻¹ ⊕ odom) applied to the previous pose; else the constant-velocity motion model
        with the IMU yaw rate for the rotation; else the motion model alone."""
        c = self.config
        last = self._last_pose
        all_axes = _ALL_AXES
        if last is None or gap:
            return _Prior(start, None, all_axes, False)
        dt = scan.stamp - self._last_stamp if self._last_stamp is not None else 0.0
        odom = scan.odom
        if c.use_odometry and odom is not None and self._last_odom is not None and odom.is_finite():
            # (``d = last_odom.between(odom)``, ``last.compose(d)``: the same float operations in the same order,
            # without the intermediate poses)
            dx, dy, dth = _between(self._last_odom, odom)
            return _Prior(_compose(last, dx, dy, dth), "odometry", all_axes, True, (dx, dy, dth))
        # (:meth:`_model_rates` inline while tracking: the same operations without the call)
        moving = False
        cv = last
        h = self._history
        if self._state == STATE_TRACKING and len(h) >= 2:
            (t0, p0), (t1, p1) = h[0], h[-1]
            dth = t1 - t0
            if dth > 0.0:
                moving = True
                c_, s_ = math.cos(p1.theta), math.sin(p1.theta)
                dx, dy = p1.x - p0.x, p1.y - p0.y
                v0 = (c_ * dx + s_ * dy) / dth
                v1 = (-s_ * dx + c_ * dy) / dth
                v2 = float((p1.theta - p0.theta + math.pi) % (2.0 * math.pi) - math.pi) / dth
                # (_compose(last, v0 * dt, v1 * dt, v2 * dt) inline: the same operations)
                vx, vy, vth = v0 * dt, v1 * dt, v2 * dt
                c_, s_ = math.cos(last.theta), math.sin(last.theta)
                cv = Pose2D(last.x + c_ * vx - s_ * vy, last.y + s_ * vx + c_ * vy,
                            (last.theta + vth + math.pi) % (2.0 * math.pi) - math.pi)
        w = scan.yaw_rate
        if c.use_odometry and w is not None and math.isfinite(w) and dt > 0.0:
            w0 = self._last_yaw_rate if self._last_yaw_rate is not None else w
            th = float(wrap_angle(last.theta + 0.5 * (w0 + w) * dt))  # trapezoidal integration of the rate
            axes = all_axes if c.motion_prior else _THETA_AXIS
            return _Prior(Pose2D(cv.x, cv.y, th), "imu", axes, moving)
        if c.motion_prior:
            return _Prior(cv, "motion_model", all_axes, moving)
        return _Prior(cv, None, all_axes, moving)

    def _model_velocity(self) -> np.ndarray | None:
        """(vx m/s, vy m/s, ω rad/s) of the motion model in the last pose's frame: the motion between the
        oldest and newest accepted pose of the last ``velocity_window`` s (a one-scan difference is too
        noisy to hold along a degenerate direction for seconds)."""
        v = self._model_rates()
        return None if v is None else np.array(v)

    def _model_rates(self) -> tuple[float, float, float] | None:
        """:meth:`_model_velocity` as three floats (the same values; no array on every scan's prediction)."""
        h = self._history
        if len(h) < 2:
            return None
        (t0, p0), (t1, p1) = h[0], h[-1]
        dt = t1 - t0
        if not dt > 0.0:
            return None
        c, s_ = math.cos(p1.theta), math.sin(p1.theta)
        dx, dy = p1.x - p0.x, p1.y - p0.y
        # (float(wrap_angle(a)) inline: the same operations without the call)
        return (c * dx + s_ * dy) / dt, (-s_ * dx + c * dy) / dt, float(
            (p1.theta - p0.theta + math.pi) % (2.0 * math.pi) - math.pi) / dt

    def _moving_prediction(self) -> np.ndarray | None:
        """The last pose advanced by the motion model's velocity over the current stamp gap (floored at the
        median scan period, capped at max_time_gap) — kept across a time gap for the recovery search; None
        without a velocity or a moving robot."""
        v = self._model_velocity()
        if v is None or self._last_pose is None or self._dt is None:
            return None
        t = min(self._period.floor(self._dt), self.config.max_time_gap)
        p = self._last_pose.compose(Pose2D(float(v[0] * t), float(v[1] * t), float(v[2] * t)))
        return p.as_array() if p.is_finite() else None

    def _gate_limits(self, dt: float) -> tuple[float, float]:
        """Largest deviation (m, rad) from the prediction the motion model allows ``dt`` s after the
        last accepted pose.

        The model's velocity is the mean over the last ``velocity_window`` W, so under an
        acceleration of at most a it lags the true velocity by up to a·W/2, and the velocity can
        change by a·dt during the step: the position may deviate by a·dt·(W/2 + dt), plus the fixed
        tolerances."""
        c = self.config
        dt = max(dt, 0.0)
        if c.recovery:  # jittered stamps understate the motion a gap allowed (slam/recovery.py)
            dt = max(dt, self._period.median)  # (ScanPeriod.floor)
        k = dt * (0.5 * c.velocity_window + dt)
        return c.max_linear_accel * k + c.gate_distance, c.max_angular_accel * k + c.gate_angle

    # ---- matching ----------------------------------------------------------------------
    def match(self, scan: Scan, predicted: Pose2D | None = None, commit: bool = True,
              drop: np.ndarray | None = None) -> MatchResult:
        """Estimate the laser pose of ``scan`` against the current map; the map is not changed.

        ``predicted`` overrides the internal start estimate (previous pose, or constant velocity).
        With ``commit`` (default) the result becomes the processor's current pose (the start of
        the next prediction) and the counters are updated; pass False to only look. ``drop`` (n,) bool:
        match ``scan.without(drop)`` (those beams taken as without a return), the same result without the copy.

        Beyond the reference (issue 10): odometry / IMU / the motion model predict the pose;
        the prediction holds along directions the scan cannot constrain (degenerate Hessian);
        scans with something against the sensor, a narrow view, or a jump beyond the motion
        model without enough structure keep the predicted pose and stay out of the map; after
        ``lost_after`` s without a supported match the processor is lost and relocalises with a
        wide search, accepting only a clear winner.
        """
        c = self.config
        t0 = time.perf_counter()
        # (:meth:`_gate` with its statistics, inline: the same kernel call)
        cos_a, sin_a = scan.trig()
        ranges = scan.ranges
        pts, clear, n_valid, n_close, spread_bins, sumsq = gated_points(
            ranges, cos_a, sin_a, scan.valid_view(), float(scan.range_min), float(scan.range_max),
            float(c.laser_min_dist), float(c.laser_max_dist), float(c.clear_no_return_dist), True,
            no_drop(ranges.shape[0]) if drop is None else drop)
        # the map update of this same scan reuses them (read-only; not those of a scan with beams dropped)
        self._last_points = (scan if drop is None else None, pts, clear)
        self._sumsq = (pts, sumsq)  # (degeneracy's Σ x² + y² of these points)
        # (:meth:`_predict` inline: the same start estimate and gap from the same operations)
        ls = self._last_stamp
        dt = self._dt = scan.stamp - ls if ls is not None else None
        gap = dt is not None and (dt < 0.0 or dt > c.max_time_gap)
        last = self._last_pose
        if last is None:
            start = Pose2D()
        elif c.constant_velocity and not gap and self._velocity is not None and dt is not None:
            vx, vy, vth = self._velocity
            start = last.compose(Pose2D(vx * dt, vy * dt, vth * dt))
        else:
            start = last
        prior = self._prior(scan, start, gap)
        laser_start = start
        if prior.kind in ("odometry", "imu"):
            start = prior.pose if prior.kind == "odometry" else Pose2D(start.x, start.y, prior.pose.theta)
        if predicted is not None:
            if not predicted.is_finite():
                predicted = None
            else:
                start = predicted
        first = self.map.levels[0].logodds.size == 0  # (MultiResMap.empty, read directly)
        zero = _ZERO_HESSIAN
        # (every field positionally, in the declaration order: the keyword form's values, ≈ 40 % less time)
        res = MatchResult(
            start, start, None, zero, 0.0, int(pts.shape[0]), 0.0, False, False, None, False, gap, first, 0.0, pts,
            clear, math.nan, False, 0, 0.0, False, prior.kind, SOURCE_SCAN, self._state, math.nan, _NO_MATCH,
        )
        if pts.shape[0] < c.min_points:
            res.skipped = True
            res.rejected = True
            res.reason = SKIP_TOO_FEW_POINTS
            self._use_prediction(res, prior, None)
        elif first:
            res.covariance = np.zeros((3, 3))
        elif not c.laser_min_dist <= 0.0 and n_valid > 0 and n_close > c.too_close_fraction * n_valid:
            # (:meth:`_too_close_counts` of the counts, inline: the same tests on every scan without the call)
            self._use_prediction(res, prior, PREDICT_TOO_CLOSE)
        elif spread_bins * BIN_ANGLE < c.min_sector:  # angular_spread(pts)
            self._use_prediction(res, prior, PREDICT_NARROW)
        elif self._state == STATE_LOST:
            if self._last_relocalise is None or scan.stamp - self._last_relocalise >= c.relocalise_interval \
                    or scan.stamp < self._last_relocalise:
                self._last_relocalise = scan.stamp
                self._relocalise(res, pts, prior)
            else:
                self._use_prediction(res, prior, PREDICT_LOST)
        else:
            self._odometry_start = prior.kind == "odometry" and predicted is None
            # (_odometry_information is None unless the prior is the odometry's and odometry_prior "all")
            info = self._odometry_information(prior) if prior.kind == "odometry" and c.odometry_prior == "all" \
                else None
            if info is None:  # (:meth:`_match_tracking` without an odometry prior, inline: the same steps)
                self._match_against_map(res, pts)
                if res.reason != REJECT_NON_FINITE and res.reason != REJECT_JUMP:
                    self._apply_prior_and_gate(res, pts, prior, scan.stamp)
                else:
                    res.low_support = True  # pose = start estimate
            else:
                self._match_tracking(res, pts, prior, scan.stamp, info)
            self._odometry_start = False  # (the laser-only seed below starts without the odometry's motion)
            if res.low_support and prior.kind == "odometry" and predicted is None:
                # odometry is a prior, not a replacement: when the odometry-seeded match finds little
                # support (odometry slipped or glitched), try the laser-only seed too and keep the better
                alt = MatchResult(
                    pose=laser_start, start=laser_start, _covariance=res.covariance, hessian=zero, score=0.0,
                    n_points=res.n_points, time_gap=gap, first=first, points=pts, clear_points=clear,
                    prior=prior.kind, state=self._state,
                )
                self._match_tracking(alt, pts, prior, scan.stamp)
                if alt.support_points > res.support_points:
                    res = alt
        res.match_ms = (time.perf_counter() - t0) * 1e3
        if commit:
            self._commit(scan, res)
        return res

    def _match_tracking(self, res: MatchResult, pts: np.ndarray, prior: _Prior, stamp: float,
                        info: np.ndarray | None = None) -> None:
        """Match from ``res.start`` (with ``info``: the odometry prior on all directions), then the prior
        along degenerate directions and the motion gate."""
        self._match_against_map(res, pts)
        if info is not None and res.reason is None and self._sigma2:
            # odometry_prior "all": the scan's match must agree with the odometry within their joint noise
            # (Mahalanobis test on the difference, covariance Σ_odom + σ²H⁻¹, χ² 3 dof 99 %) — a wheel slip or
            # glitch must not pull the pose — and then the two are fused: the match is refined with the prior
            # σ²Σ_odom⁻¹ added to the normal equations
            d = prior.pose.between(res.pose)
            x = np.array([d.x, d.y, d.theta])
            joint = np.linalg.inv(info / self._sigma2) + res.covariance
            if float(x @ np.linalg.solve(joint, x)) < _ODOMETRY_GATE_CHI2:
                p = self._refine(pts, res.pose.as_array(), prior.pose.as_array(), info)
                if np.all(np.isfinite(p)):
                    self._fit(res, pts, Pose2D(float(p[0]), float(p[1]), float(wrap_angle(p[2]))))
        if res.reason != REJECT_NON_FINITE and res.reason != REJECT_JUMP:
            self._apply_prior_and_gate(res, pts, prior, stamp)
        else:
            res.low_support = True  # pose = start estimate (with odometry: the odometry prediction)

    def _odometry_information(self, prior: _Prior) -> np.ndarray | None:
        """The odometry prior on every direction (``odometry_prior: all``), in the matcher's units: σ²·Σ⁻¹
        with Σ the odometry increment's covariance from the noise model and σ² the scans' residual
        variance (the matcher minimises Σr², whose information is H/σ²), world units (1/m², 1/rad²)."""
        c = self.config
        if c.odometry_prior != "all" or prior.kind != "odometry" or prior.delta is None or self._sigma2 is None:
            return None
        dx, dy, dth = prior.delta
        d = math.hypot(dx, dy)
        a = abs(dth)
        var_xy = c.odometry_noise_floor_xy**2 + (c.odometry_noise_translation * d) ** 2
        var_th = c.odometry_noise_floor_theta**2 + (c.odometry_noise_rotation * a) ** 2
        return self._sigma2 * np.diag([1.0 / var_xy, 1.0 / var_xy, 1.0 / var_th])

    def _too_close_counts(self, n: int, close: int) -> bool:
        """More than ``too_close_fraction`` of the ``n`` valid returns (``close`` of them closer than
        laser_min_dist: :func:`~dynslam2d.slam.matcher.close_count`'s counts, taken by :meth:`_gate`)."""
        c = self.config
        if c.laser_min_dist <= 0.0:
            return False
        return n > 0 and close > c.too_close_fraction * n

    def _use_prediction(self, res: MatchResult, prior: _Prior, reason: str | None) -> None:
        """Keep the predicted pose; the scan stays out of the map."""
        res.pose = prior.pose if prior.kind is not None or self._last_pose is not None else res.start
        res.pose_source = SOURCE_PREDICTION
        res.rejected = True
        res.low_support = True
        if reason is not None:
            res.reason = reason

    def _support(self, res: MatchResult, pts: np.ndarray, pose: Pose2D) -> None:
        """:func:`~dynslam2d.slam.matcher.support_at` of ``pose`` into ``res`` (the matcher's, taken in its kernel
        call, when ``pose`` is the one :meth:`_match_against_map` gave ``res``: the same map, points and pose)."""
        c = self.config
        of = self._support_of
        if of is not None and of[0] is res and of[1] is pose:
            res.support_points, res.support_spread = of[2]
        else:
            res.support_points, res.support_spread = support_at(self.map.levels[0], pts, pose.x, pose.y, pose.theta,
                                                                c.support_probability)
        res.low_support = res.support_points < c.support_min_points or res.support_spread < c.support_min_spread

    def _refine(self, pts: np.ndarray, seed: np.ndarray, prior_pose: np.ndarray | None = None,
                prior_info: np.ndarray | None = None) -> np.ndarray:
        c = self.config
        return match_multires(
            self.map.levels, pts, seed, c.iterations_coarse, c.iterations_finest, c.hector_gradient_bug,
            c.step_mode == "lm", c.lm_lambda_init, c.lm_lambda_max, c.max_rotation_step,
            c.max_translation_step, prior_pose, prior_info,
        )

    def _fit(self, res: MatchResult, pts: np.ndarray, pose: Pose2D, fit: LevelFit | None = None) -> None:
        """Hessian, score and covariance of ``pose`` into ``res`` (``fit``: already evaluated there)."""
        c = self.config
        if fit is None:
            fit = evaluate(self.map.levels[0], pts, pose.as_array(), c.hector_gradient_bug)
        self._fit_of = fit
        res.pose = pose
        res.hessian = fit.hessian
        res.score = fit.score
        res.sigma2 = fit.cost / max(pts.shape[0] - 3, 1)
        sigma2 = c.covariance_sigma**2 if c.covariance_sigma is not None else res.sigma2
        res._covariance, res._covariance_of = None, (fit.hessian, sigma2, self.map.levels[0].resolution)  # lazy

    def _apply_prior_and_gate(self, res: MatchResult, pts: np.ndarray, prior: _Prior, stamp: float) -> None:
        """Degeneracy analysis of the match; the prior along degenerate directions; the motion gate."""
        c = self.config
        # (degeneracy's values, the Degeneracy record made below only when a prior needs it): the matcher's, taken
        # in its kernel call with this Hessian (the same threshold, points and Σ x² + y²), else computed here
        fit = self._fit_of
        dv = fit.degeneracy if fit is not None and fit.hessian is res.hessian else None
        if dv is None:
            sq = self._sumsq
            ratio, t_ratio, r_ratio, ax, ay, rho, lam_max, t_deg, r_deg = degeneracy_values(
                res.hessian, self.map.levels[0].resolution, pts, c.degeneracy_threshold,
                sq[1] if sq is not None and sq[0] is pts else None)
        else:
            ratio, t_ratio, r_ratio, ax, ay, rho, lam_max, t_deg, r_deg = dv  # (the axis not normalised yet)
        # hysteresis: a degenerate direction stays degenerate until its ratio clearly rises above the threshold
        hi = _DEGENERACY_HYSTERESIS * c.degeneracy_threshold
        prev = self._degenerate_prev
        t_deg |= prev[0] and t_ratio < hi
        r_deg |= prev[1] and r_ratio < hi
        self._degenerate_prev = (t_deg, r_deg)
        res.degeneracy = ratio
        res.degenerate = degenerate = t_deg or r_deg  # (Degeneracy.any)
        if degenerate and prior.kind is not None and c.prior_weight > 0.0 and prior.pose.is_finite():
            if dv is not None:
                ax, ay = unit_axis(ax, ay)
            deg = Degeneracy(ratio, t_ratio, r_ratio, np.array([ax, ay]), rho, lam_max, t_deg, r_deg)
            info = deg.prior_information(c.prior_weight, prior.axes)
            if np.any(info):
                pp = prior.pose.as_array()
                p = self._refine(pts, pp, pp, info)
                if np.all(np.isfinite(p)):
                    self._fit(res, pts, Pose2D(float(p[0]), float(p[1]), float(wrap_angle(p[2]))))
                    res.pose_source = SOURCE_SCAN_PRIOR
        # (:meth:`_support` inline: the matcher's support while the result still holds the pose it was taken at)
        of = self._support_of
        if of is not None and of[0] is res and of[1] is res.pose:
            res.support_points, res.support_spread = of[2]
            res.low_support = res.support_points < c.support_min_points or res.support_spread < c.support_min_spread
        else:
            self._support(res, pts, res.pose)
        # the motion gate refuses only weak matches: a well-supported one skips the deviation and the limits (pure
        # arithmetic, the same outcome)
        if prior.gate and res.low_support and self._last_stamp is not None:
            dx, dy, dth = _between(prior.pose, res.pose)
            lim_d, lim_a = self._gate_limits(stamp - self._last_stamp)
            if math.hypot(dx, dy) > lim_d or abs(dth) > lim_a:
                refused = self._refused
                # a weak match the previous (refused) weak match predicts is two agreeing observations:
                # the robot did accelerate beyond the model (a car speeding up), accept it
                if refused is not None and refused[2] == self.n_scans - 1 and self._confirms(refused, res, stamp):
                    self._refused = None
                    return
                self._refused = (refused[0] if refused else stamp, res.pose, self.n_scans)
                self._use_prediction(res, prior, PREDICT_UNSUPPORTED)
                return
        self._refused = None

    def _confirms(self, refused: tuple[float, Pose2D, int], res: MatchResult, stamp: float) -> bool:
        """The weak match ``res`` continues the previous refused weak match with the model's velocity."""
        v = self._model_velocity()
        dt = stamp - self._last_stamp if self._last_stamp is not None else 0.0
        step = Pose2D(float(v[0] * dt), float(v[1] * dt), float(v[2] * dt)) if v is not None else Pose2D()
        d = refused[1].compose(step).between(res.pose)
        lim_d, lim_a = self._gate_limits(dt)
        return math.hypot(d.x, d.y) <= lim_d and abs(d.theta) <= lim_a

    def _relocalise(self, res: MatchResult, pts: np.ndarray, prior: _Prior) -> None:
        """Lost: a wide correlative search around the prediction (on every scan that is neither too
        close nor too narrow); accepted only if its score is high enough and beats the best pose
        elsewhere (runner-up) by ``relocalise_margin``."""
        c = self.config
        levels = self.map.levels
        lvl = levels[min(c.correlative_level, len(levels) - 1)]
        cr = correlative_search(
            lvl, pts, prior.pose.as_array(), c.relocalise_linear_window, c.relocalise_angular_window,
            c.correlative_angular_step, c.correlative_max_points, c.correlative_max_height,
            0.0, 0.0, runner_up_distance=0.5, runner_up_angle=0.3, runner_up_wrap=c.relocalise_runner_up_wrap,
            # the two refusals below, given to the search: it prunes by them and returns None below the score (the
            # same pose whenever it returns one; a runner-up that refuses stays one that refuses)
            min_score=c.relocalise_min_score, min_margin=c.relocalise_margin,
        )
        res.used_correlative = True
        if cr is None or cr.score < c.relocalise_min_score or cr.score - (cr.runner_up or 0.0) < c.relocalise_margin:
            self._use_prediction(res, prior, PREDICT_LOST)
            return
        p = self._refine(pts, cr.pose)
        if not np.all(np.isfinite(p)):
            self._use_prediction(res, prior, PREDICT_LOST)
            return
        self._fit(res, pts, Pose2D(float(p[0]), float(p[1]), float(wrap_angle(p[2]))))
        self._support(res, pts, res.pose)
        sq = self._sumsq
        deg = degeneracy(res.hessian, self.map.resolution, pts, c.degeneracy_threshold,
                         sq[1] if sq is not None and sq[0] is pts else None)
        res.degeneracy = deg.ratio
        res.degenerate = deg.any
        res.pose_source = SOURCE_RELOCALISED
        res.rejected = True  # the first scan after relocalising is not written into the map
        res.reason = "relocalised"

    def _match_against_map(self, res: MatchResult, pts: np.ndarray,
                           prior_pose: np.ndarray | None = None, prior_info: np.ndarray | None = None) -> None:
        c = self.config
        levels = self.map.levels
        start = None  # (res.start.as_array(), made when a search, the recovery or the caches read it)
        mode = c.correlative_mode
        # a start the odometry predicted already holds the previous scan's motion: large motion alone does not
        # trigger the search there (search_on_motion_with_odometry); the poor-match trigger below still does
        big_motion = (not self._odometry_start or c.search_on_motion_with_odometry) and (
            self._last_motion[0] > c.correlative_trigger_distance
            or self._last_motion[1] > c.correlative_trigger_angle
        )
        pre_search = mode == "always" or (
            mode == "auto"
            and (big_motion or res.time_gap or self._force_search or self._n_accepted < _WARMUP_SEARCHES)
        )
        # (the first refine of the scan; the per-scan caches of :meth:`_scan_context` are made only for a second one)
        a = res.start
        best_p, best_s, first_fit = self._refine_fit(levels, pts, prior_pose, prior_info, float(a.x), float(a.y),
                                                     float(a.theta))  # (the floats of res.start.as_array())
        ctx = None
        if mode != "never" and not pre_search and self._score_avg is not None:
            pre_search = best_s < c.poor_match_ratio * self._score_avg
        if pre_search:
            self.pre_searches += 1
            start = res.start.as_array()
            ctx = self._scan_context(levels, pts, prior_pose, prior_info, start, best_p, best_s, first_fit)
            found = self._search(ctx, start)
            if found is not None and found[1] > best_s:
                best_p, best_s = found
                res.used_correlative = True
        ambiguous = False
        jump_d, jump_a = c.max_jump_distance, c.max_jump_angle
        if c.recovery and self._score_avg is not None and needs_recovery(c, self._dt, best_s, self._score_avg):
            # (needs_recovery's own first test, before the call: False without recovery or a score average)
            # large-motion recovery (slam/recovery.py): a window grown with the gap, best vs runner-up
            if ctx is None:
                start = res.start.as_array()
                ctx = self._scan_context(levels, pts, prior_pose, prior_info, start, best_p, best_s, first_fit)
            rec = recover(c, levels, pts, start, best_p, best_s, self._dt,
                          lambda seed: self._refine_cached(ctx, seed)[0], self._moving_prediction())
            if rec is not None:
                self.counts["recovery"] += 1
                res.used_correlative |= rec.changed
                best_p, best_s, ambiguous = rec.pose, rec.score, rec.ambiguous
                # the searched window is a plausible motion: the jump limits open to it
                jump_d, jump_a = max(jump_d, math.sqrt(2.0) * rec.linear_window), max(jump_a, rec.angular_window)

        bx, by, bth = best_p.tolist()  # (Python floats: the same values, and wrapped by the same operations)
        if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bth)):
            res.rejected = True
            res.reason = REJECT_NON_FINITE
            return
        pi = math.pi
        th = (bth + pi) % (2.0 * pi) - pi  # (_wrap(bth))
        pose = Pose2D(bx, by, th)
        # _between(res.start, pose) inline (the same float operations in the same order, as in _between / _wrap)
        a = res.start
        ca, sa = math.cos(a.theta), math.sin(a.theta)
        ix, iy, ith = -ca * a.x - sa * a.y, sa * a.x - ca * a.y, (-a.theta + pi) % (2.0 * pi) - pi
        ca, sa = math.cos(ith), math.sin(ith)
        dx, dy, dth = ix + ca * bx - sa * by, iy + sa * bx + ca * by, (ith + th + pi) % (2.0 * pi) - pi
        if math.hypot(dx, dy) > jump_d or abs(dth) > jump_a:
            res.rejected = True
            res.reason = REJECT_JUMP
            return
        # a refine's free fraction was taken at (x, y, wrap_angle(θ)) of its result: this pose when the result is
        # best_p
        best_fit = ctx[4].get(best_p.tobytes()) if ctx is not None else first_fit
        at = None
        # a refine's evaluation at this same pose (its H, cost and score: evaluate with the same gradient weights),
        # instead of evaluating it again; the pose's bytes are best_p's when wrapping left θ's bits as they were
        # (the matcher wraps θ already: nearly always)
        if c.hector_gradient_bug:
            at_fit = None
        elif th == bth and math.copysign(1.0, th) == math.copysign(1.0, bth):
            at_fit = best_fit
        else:
            at = pose.as_array()
            # (the first refine's entry is keyed by best_p's bytes, which are not at's: θ's bits differ)
            at_fit = ctx[4].get(at.tobytes()) if ctx is not None else None
        self._fit(res, pts, pose, at_fit[0] if at_fit is not None else None)
        avg = self._score_avg
        free = best_fit[1] if best_fit is not None else None
        if free is None:
            free = free_fraction(levels[min(1, len(levels) - 1)], pts, pose.as_array() if at is None else at,
                                 FREE_SPACE_PROB)
        res.free_fraction = free
        # the refine's support was taken at this pose too (x, y, wrap_angle(θ) of its result)
        sup = best_fit[2] if best_fit is not None else None
        self._support_of = (res, pose, sup) if sup is not None else None
        if res.score < c.reject_score_min or (avg is not None and res.score < c.reject_score_ratio * avg):
            res.rejected = True
            res.reason = REJECT_LOW_SCORE
        elif res.free_fraction > c.reject_free_fraction:
            res.rejected = True
            res.reason = REJECT_FREE_SPACE
        elif ambiguous:
            res.rejected = True
            res.reason = REJECT_AMBIGUOUS

    def _refine_cached(self, ctx: tuple, seed: np.ndarray) -> tuple[np.ndarray, float]:
        """(pose, score) of refining ``seed`` on this scan (``ctx`` of :meth:`_match_against_map`), once per seed."""
        refined = ctx[5]
        key = np.asarray(seed, dtype=np.float64).tobytes()  # (the matcher's float64 start)
        out = refined.get(key)
        if out is None:  # (the poses are not written to by their users)
            out = refined[key] = self._refine_once(ctx, seed)
        return out

    def _scan_context(self, levels: list, pts: np.ndarray, prior_pose: np.ndarray | None,
                      prior_info: np.ndarray | None, start: np.ndarray, p: np.ndarray, score: float,
                      entry: tuple | None) -> tuple:
        """The per-scan caches of a scan that refines more than once, holding its first refine (``start`` → ``p``,
        ``score``, its fit ``entry``): (levels, points, prior pose, prior information, fits, refined).

        fits: pose bytes → (LevelFit, free fraction, support) of every refine of this scan: _fit, the free-space test
        and the support reuse them at the same pose (the winner is not always the latest refine: a correlative seed
        that refines to a lower score leaves the first refine's pose). refined: seed bytes → (pose, score) of every
        refine of this scan: the map and the points do not change within the scan, so a seed refined before (a
        correlative search's pose equal to the start, or a recovery seed equal to an earlier one) refines to the
        same pose."""
        fits: dict[bytes, tuple[LevelFit, float | None, tuple[int, float] | None]] = {}
        if entry is not None:
            fits[p.tobytes()] = entry
        refined: dict[bytes, tuple[np.ndarray, float]] = {start.tobytes(): (p, score)}
        return levels, pts, prior_pose, prior_info, fits, refined

    def _refine_once(self, ctx: tuple, seed: np.ndarray) -> tuple[np.ndarray, float]:
        """Match from ``seed``: (pose, level 0's score there; −1 if not finite); its fit kept in ``ctx``'s fits."""
        sx, sy, sth = np.asarray(seed, dtype=np.float64).tolist()  # (the matcher's float64 start)
        p, score, entry = self._refine_fit(ctx[0], ctx[1], ctx[2], ctx[3], sx, sy, sth)
        if entry is not None:
            ctx[4][p.tobytes()] = entry
        return p, score

    def _refine_fit(self, levels: list, pts: np.ndarray, prior_pose: np.ndarray | None,
                    prior_info: np.ndarray | None, sx: float, sy: float, sth: float
                    ) -> tuple[np.ndarray, float, tuple[LevelFit, float | None, tuple[int, float] | None] | None]:
        """Match from the world pose (``sx`` m, ``sy`` m, ``sth`` rad): (pose, level 0's score there, (its LevelFit,
        free fraction, support)); −1 and None if the pose is not finite."""
        c = self.config
        sq = self._sumsq  # (the degeneracy analysis of the evaluation's Hessian, from the same call)
        # (level 0's evaluation, the free fraction and the support at the result, from the matcher's call)
        p, fit, free, sup = match_fit_at(
            levels, pts, sx, sy, sth, c.iterations_coarse, c.iterations_finest, c.hector_gradient_bug,
            c.step_mode == "lm", c.lm_lambda_init, c.lm_lambda_max, c.max_rotation_step, c.max_translation_step,
            FREE_SPACE_PROB, c.support_probability, c.degeneracy_threshold,
            sq[1] if sq is not None and sq[0] is pts else None, prior_pose, prior_info)
        x, y, th = p.tolist()  # (Python floats: one conversion instead of three element reads)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)):
            return p, -1.0, None
        if fit is None:
            fit = evaluate(levels[0], pts, p)
        return p, fit.score, (fit, free, sup)

    def _search(self, ctx: tuple, start: np.ndarray) -> tuple[np.ndarray, float] | None:
        """The front end's correlative search around ``start``, its pose refined; None if it found nothing."""
        c = self.config
        levels, pts = ctx[0], ctx[1]
        lvl = levels[min(c.correlative_level, len(levels) - 1)]
        cr = correlative_search(
            lvl, pts, start, c.correlative_linear_window, c.correlative_angular_window,
            c.correlative_angular_step, c.correlative_max_points, c.correlative_max_height,
            c.correlative_translation_weight, c.correlative_rotation_weight,
        )
        if cr is None:
            return None
        return self._refine_cached(ctx, cr.pose)

    def _commit(self, scan: Scan, res: MatchResult) -> None:
        c = self.config
        stamp = scan.stamp
        self.n_scans += 1
        if res.time_gap:
            self.counts["time_gap"] += 1
            self._velocity = None
        if res.used_correlative:
            self.counts["correlative"] += 1
        if res.reason is not None:
            self.counts[res.reason] += 1
        if res.degenerate:
            self.counts["degenerate"] += 1
        self._last_odom = scan.odom if scan.odom is not None and scan.odom.is_finite() else None
        self._last_yaw_rate = scan.yaw_rate if scan.yaw_rate is not None and math.isfinite(scan.yaw_rate) else None
        ps = res.pose_source
        if res.first or ps == SOURCE_RELOCALISED or ps == SOURCE_PREDICTION:
            self._update_state(stamp, res)
        else:  # (:meth:`_update_state` of a matched scan, inline: nearly every scan)
            self._unsupported_since = None
            res.state = self._state
        if self._last_stamp is not None:
            self._period.add(stamp - self._last_stamp)
        if res.skipped and res.pose_source != SOURCE_PREDICTION:
            self._last_stamp = stamp
            self._force_search = True
            return
        prev = self._last_pose
        self._last_pose = res.pose
        if prev is not None:
            # (_between(prev, res.pose) inline: the same float operations in the same order)
            p = res.pose
            ca, sa = math.cos(prev.theta), math.sin(prev.theta)
            ix, iy = -ca * prev.x - sa * prev.y, sa * prev.x - ca * prev.y
            ith = (-prev.theta + math.pi) % (2.0 * math.pi) - math.pi
            ca, sa = math.cos(ith), math.sin(ith)
            dx, dy = ix + ca * p.x - sa * p.y, iy + sa * p.x + ca * p.y
            dth = (ith + p.theta + math.pi) % (2.0 * math.pi) - math.pi
            self._last_motion = (math.hypot(dx, dy), abs(dth))
            dt = stamp - self._last_stamp if self._last_stamp is not None else 0.0
            if 0.0 < dt <= c.max_time_gap and not res.rejected:
                self._velocity = (dx / dt, dy / dt, dth / dt)  # (the array division's values, no array)
        self._last_stamp = stamp
        self._force_search = res.rejected
        # with recovery on, a forward gap keeps the motion history: the recovery searches around the velocity
        keep = c.recovery and self._dt is not None and self._dt > 0.0
        if (res.time_gap and not keep) or self._state == STATE_LOST:
            self._history.clear()
        if not res.rejected or res.first:
            self._history.append((stamp, res.pose))
            while len(self._history) > 2 and stamp - self._history[1][0] >= c.velocity_window:
                self._history.popleft()
        if not res.rejected and not res.first:
            self._n_accepted += 1
            a = c.score_average_rate
            self._score_avg = res.score if self._score_avg is None else (1 - a) * self._score_avg + a * res.score
            if math.isfinite(res.sigma2):
                self._sigma2 = res.sigma2 if self._sigma2 is None else (1 - a) * self._sigma2 + a * res.sigma2

    def _update_state(self, stamp: float, res: MatchResult) -> None:
        """Tracking ↔ lost: lost after ``lost_after`` s of scans whose match could not be accepted (the
        pose was predicted); found by relocalising."""
        c = self.config
        if res.first:
            return
        if res.pose_source == SOURCE_RELOCALISED:
            self._state = STATE_TRACKING
            self.relocalisations += 1
            self._unsupported_since = None
        elif res.pose_source == SOURCE_PREDICTION:
            if self._unsupported_since is None:
                self._unsupported_since = stamp
            elif self._state == STATE_TRACKING and stamp - self._unsupported_since >= c.lost_after:
                self._state = STATE_LOST
                self.lost_events += 1
                self._velocity = None  # hold the pose; the motion model is no longer trusted
        else:
            self._unsupported_since = None
        res.state = self._state

    # ---- map update --------------------------------------------------------------------
    def needs_map_update(self, pose: Pose2D) -> bool:
        """True on the first scan or once the pose moved beyond the distance / angle thresholds
        from the last map update (HectorSlamProcessor::update)."""
        last = self._last_map_pose
        if last is None or self.map.levels[0].logodds.size == 0:  # (MultiResMap.empty, read directly)
            return True
        # the θ of last.between(pose) (its x, y are not read): _wrap(_wrap(−θ_last) + θ), the two calls inline (the
        # same float operations in the same order)
        pi = math.pi
        dth = ((-last.theta + pi) % (2.0 * pi) - pi + pose.theta + pi) % (2.0 * pi) - pi
        c = self.config
        return math.hypot(pose.x - last.x, pose.y - last.y) > c.map_update_distance_thresh \
            or abs(dth) > c.map_update_angle_thresh

    def update_map(self, scan: Scan, pose: Pose2D, force: bool = False, drop: np.ndarray | None = None) -> bool:
        """Integrate ``scan`` taken at laser pose ``pose`` into every level, if the thresholds
        say so (or ``force``). Non-finite poses and scans with fewer than ``min_points`` returns
        never touch the map. ``drop`` (n,) bool: integrate ``scan.without(drop)`` (those beams taken as without a
        return), the same map without the copy. Returns True if the map was updated."""
        isfinite = math.isfinite
        if not (isfinite(pose.x) and isfinite(pose.y) and isfinite(pose.theta)):  # (Pose2D.is_finite)
            self.counts["update_refused_non_finite"] += 1
            return False
        if not (force or self.needs_map_update(pose)):
            return False
        last = self._last_points
        if drop is None and last is not None and last[0] is scan:
            pts, clear = last[1], last[2]
        else:
            pts, clear = self._gate(scan, False, drop)[:2]
        return self._integrate(pts, clear, pose)

    def _integrate(self, pts: np.ndarray, clear: np.ndarray, pose: Pose2D) -> bool:
        """Integrate the gated points ``pts`` / no-return ends ``clear`` (laser frame, m) at the finite laser pose
        ``pose`` (both callers test it first) unless fewer than ``min_points``; True if the map was updated."""
        if pts.shape[0] < self.config.min_points:
            return False
        # (``pts`` are :meth:`_gate`'s, both callers': finite ranges of valid beams times the finite cos / sin of
        # validated beam angles, always finite — pass rest18 dropped the per-update finite test of every point)
        try:
            self.map.integrate(pose, pts, clear if clear.shape[0] else None)
        except MapTooLargeError:
            self.counts["map_too_large"] += 1
            return False
        self._last_map_pose = pose
        self.n_map_updates += 1
        return True

    # ---- both --------------------------------------------------------------------------
    def process(self, scan: Scan, predicted: Pose2D | None = None) -> SlamStep:
        """Match ``scan`` and, unless the match was rejected or skipped, update the map."""
        res = self.match(scan, predicted)
        t0 = time.perf_counter()
        updated = False
        if not res.rejected and self.needs_map_update(res.pose) and res.pose.is_finite():
            updated = self._integrate(res.points, res.clear_points, res.pose)
        update_ms = (time.perf_counter() - t0) * 1e3
        return SlamStep(
            index=self.n_scans - 1,
            stamp=scan.stamp,
            pose=res.pose,
            covariance=res.covariance,
            hessian=res.hessian,
            score=res.score,
            free_fraction=res.free_fraction,
            map_updated=updated,
            rejected=res.rejected,
            skipped=res.skipped,
            reason=res.reason,
            used_correlative=res.used_correlative,
            time_gap=res.time_gap,
            n_points=res.n_points,
            match_ms=res.match_ms,
            update_ms=update_ms,
            degeneracy=res.degeneracy,
            degenerate=res.degenerate,
            support_points=res.support_points,
            support_spread=res.support_spread,
            low_support=res.low_support,
            pose_source=res.pose_source,
            state=res.state,
        )
