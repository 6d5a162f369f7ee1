"""Core value types: a laser scan, a 2D pose, and the scan-source protocol.

Conventions (docs/architecture.md): SI units and radians, REP-103 axes
(x forward, y left). A scan's angles and points are in the sensor (laser)
frame; a :class:`Pose2D` returned by SLAM is the laser pose in the map frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from dynslam2d.errors import DynSlamError

#: Tolerance, in beams, between the beam count implied by angle_min/max/increment
#: and the number of ranges. Drivers disagree on whether angle_max is the last
#: beam or one past it, so one beam of slack is accepted.
ANGLE_COUNT_TOLERANCE_BEAMS = 1.01
#: Largest |beam angle| accepted, rad. Scanners use [-π, π] or [0, 2π]; anything
#: beyond two turns is corrupt metadata.
MAX_ABS_ANGLE = 4.0 * math.pi
#: (angle_min, angle_increment, beams) → read-only (cos, sin) of the beam angles: every scan of a laser has the
#: same beam geometry, so the trigonometry is computed once per laser (Scan.trig), not once per scan and stage
_TRIG: dict[tuple[float, float, int], tuple[np.ndarray, np.ndarray]] = {}
#: at most this many beam geometries are kept (a log holds one per laser)
_TRIG_MAX = 16


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Wrap an angle (rad) or array of angles to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A rigid 2D pose (x, y in m, theta in rad): the pose of a child frame in a parent frame.

    ``a.compose(b)`` is ``a ⊕ b`` (b expressed in a's frame, result in a's parent frame);
    ``a.inverse()`` is ``a⁻¹``; ``a.between(b)`` is ``a⁻¹ ⊕ b``, the relative motion used
    by the Kümmerle relations.
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def compose(self, other: Pose2D) -> Pose2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            float((self.theta + other.theta + math.pi) % (2.0 * math.pi) - math.pi),  # (wrap_angle's operations)
        )

    def inverse(self) -> Pose2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y,
                      float((-self.theta + math.pi) % (2.0 * math.pi) - math.pi))  # (wrap_angle's operations)

    def between(self, other: Pose2D) -> Pose2D:
        """Relative pose ``self⁻¹ ⊕ other``: ``other`` expressed in ``self``'s frame."""
        return self.inverse().compose(other)

    def transform_points(self, points: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """Map (n, 2) points from this pose's child frame into its parent frame, m. The arithmetic is float64;
        ``dtype`` is the result's (float32: each value rounded once, without a float64 copy)."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        pts = np.asarray(points, dtype=np.float64)
        out = np.empty(pts.shape, dtype=dtype)
        out[:, 0] = c * pts[:, 0] - s * pts[:, 1] + self.x
        out[:, 1] = s * pts[:, 0] + c * pts[:, 1] + self.y
        return out

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    def as_matrix(self) -> np.ndarray:
        """3×3 homogeneous transform, child → parent."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, -s, self.x], [s, c, self.y], [0.0, 0.0, 1.0]])

    @classmethod
    def from_array(cls, a: np.ndarray | list[float] | tuple[float, float, float]) -> Pose2D:
        return cls(float(a[0]), float(a[1]), float(a[2]))

    def is_finite(self) -> bool:
        return math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.theta)


#: the slots' own setters, what :class:`Pose2D`'s ``__init__`` writes (below)
_POSE_SET_X, _POSE_SET_Y, _POSE_SET_THETA = Pose2D.x.__set__, Pose2D.y.__set__, Pose2D.theta.__set__  # type: ignore


def _pose_init(self: Pose2D, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> None:
    """``Pose2D(x, y, theta)``: the dataclass's own ``__init__`` (the same parameters and defaults, the values stored
    as given) writing the three slots through their descriptors instead of ``object.__setattr__`` per field (the
    frozen dataclass's generated form): ≈ 40 % less time per pose, made several times on every scan."""
    _POSE_SET_X(self, x)
    _POSE_SET_Y(self, y)
    _POSE_SET_THETA(self, theta)


_pose_init.__qualname__ = "Pose2D.__init__"
Pose2D.__init__ = _pose_init  # type: ignore[method-assign]


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One 2D laser scan, as ``sensor_msgs/LaserScan`` describes it.

    Attributes:
        stamp: acquisition time of the first beam, s (Unix time for real logs,
            seconds since start for simulated ones).
        angle_min: angle of beam 0 in the sensor frame, rad (counter-clockwise positive).
        angle_increment: angle between consecutive beams, rad (may be negative).
        ranges: (n,) float64 ranges in m. NaN, ±inf, r < range_min and r > range_max
            are "no return" (REP-117); :meth:`valid_mask` says which beams hold a return.
        range_min, range_max: the sensor's valid range interval, m.
        frame_id: the sensor frame's name.
        intensities: optional (n,) float64 intensities, sensor units.
        angle_max: angle of the last beam as the source wrote it, rad (kept so a
            bag round trip is lossless); defaults to ``angle_min + (n-1)·increment``.
        time_increment, scan_time: as in LaserScan, s (0 when unknown).
        odom: the LASER's pose in the odometry frame at ``stamp`` (m, rad), when the
            recording has odometry (wheel odometry, TF ``odom → base_link`` composed with
            ``base_link → laser``, CARMEN odometry, or dead reckoning with IMU yaw);
            None for laser-only input. Only differences between scans are meaningful.
        yaw_rate: the sensor's yaw rate at ``stamp`` from an IMU, rad/s, or None.
    """

    stamp: float
    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    range_min: float
    range_max: float
    frame_id: str = "laser"
    intensities: np.ndarray | None = None
    angle_max: float | None = None
    time_increment: float = 0.0
    scan_time: float = 0.0
    odom: Pose2D | None = None
    yaw_rate: float | None = None
    # (caches, not constructor arguments: ``dataclasses.replace`` must not carry another scan's angles or mask)
    _angles: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    _valid: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    #: :meth:`trig`'s (cos, sin), kept by its first call (several stages ask for it on every scan)
    _trig: tuple[np.ndarray, np.ndarray] | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        ranges = np.ascontiguousarray(self.ranges, dtype=np.float64)
        if ranges.ndim != 1:
            raise DynSlamError(f"scan at stamp {self.stamp}: ranges must be 1-D, got shape {ranges.shape}")
        object.__setattr__(self, "ranges", ranges)
        n = ranges.shape[0]
        if self.intensities is not None:
            inten = np.ascontiguousarray(self.intensities, dtype=np.float64)
            if inten.shape[0] == 0:
                inten = None
            elif inten.shape != ranges.shape:
                raise DynSlamError(
                    f"scan at stamp {self.stamp}: {inten.shape[0]} intensities for {n} ranges"
                )
            object.__setattr__(self, "intensities", inten)
        for name in ("stamp", "angle_min", "angle_increment", "range_min", "range_max"):
            if not math.isfinite(getattr(self, name)):
                raise DynSlamError(f"scan at stamp {self.stamp}: {name} is not finite")
        if n > 1 and self.angle_increment == 0.0:
            raise DynSlamError(f"scan at stamp {self.stamp}: angle_increment is 0 with {n} beams")
        if self.range_max <= self.range_min or self.range_min < 0:
            raise DynSlamError(
                f"scan at stamp {self.stamp}: invalid range limits [{self.range_min}, {self.range_max}]"
            )
        last = self.angle_min + (n - 1) * self.angle_increment
        if abs(self.angle_min) > MAX_ABS_ANGLE or abs(last) > MAX_ABS_ANGLE:
            raise DynSlamError(
                f"scan at stamp {self.stamp}: beam angles {self.angle_min:.6g} … {last:.6g} rad "
                f"are outside ±{MAX_ABS_ANGLE:.2f} rad"
            )
        if self.angle_max is None:
            object.__setattr__(self, "angle_max", float(last))
        elif n > 1:
            implied = (self.angle_max - self.angle_min) / self.angle_increment + 1.0
            if not math.isfinite(implied) or abs(implied - n) > ANGLE_COUNT_TOLERANCE_BEAMS:
                raise DynSlamError(
                    f"scan at stamp {self.stamp}: angle metadata implies {implied:.1f} beams "
                    f"(angle_min={self.angle_min:.6f}, angle_max={self.angle_max:.6f}, "
                    f"increment={self.angle_increment:.6f}) but the scan has {n} ranges"
                )

    @property
    def n_beams(self) -> int:
        return int(self.ranges.shape[0])

    @property
    def angles(self) -> np.ndarray:
        """(n,) beam angles in the sensor frame, rad: ``angle_min + i·angle_increment``."""
        if self._angles is None:
            a = self.angle_min + np.arange(self.n_beams, dtype=np.float64) * self.angle_increment
            object.__setattr__(self, "_angles", a)
            return a
        return self._angles

    def trig(self) -> tuple[np.ndarray, np.ndarray]:
        """(cos, sin) of :attr:`angles`, (n,) read-only arrays shared by every scan with the same beam
        geometry (elementwise the same values as ``np.cos(angles[m])`` for any selection ``m``)."""
        t = self._trig
        if t is not None:  # (this scan's own earlier answer: the same arrays)
            return t
        key = (self.angle_min, self.angle_increment, self.ranges.shape[0])  # (n_beams: the same int)
        t = _TRIG.get(key)
        if t is None:
            a = self.angles
            t = (np.cos(a), np.sin(a))
            for arr in t:
                arr.flags.writeable = False
            if len(_TRIG) >= _TRIG_MAX:
                _TRIG.clear()
            _TRIG[key] = t
        object.__setattr__(self, "_trig", t)
        return t

    @property
    def fov(self) -> float:
        """Field of view covered by the beams, rad (n·|increment|)."""
        return abs(self.angle_increment) * self.n_beams

    def valid_mask(self, min_range: float | None = None, max_range: float | None = None) -> np.ndarray:
        """(n,) bool: beams that hold a return (finite and within [range_min, range_max]).

        ``min_range``/``max_range`` tighten the sensor's own limits (for range gates). Without
        them the mask is computed once per scan and each call returns a fresh copy.
        """
        if min_range is None and max_range is None and self._valid is not None:
            return self._valid.copy()
        lo = self.range_min if min_range is None else max(self.range_min, min_range)
        hi = self.range_max if max_range is None else min(self.range_max, max_range)
        r = self.ranges
        # (NaN compares False without a floating-point warning in NumPy's comparisons: no errstate context, whose
        # enter and exit cost more than the three tests on a scan)
        valid = ranges_valid(r, lo, hi)
        if min_range is None and max_range is None:
            # computed once per scan (the pipeline's stages ask 5-6 times; a copy costs a fraction of
            # the tests) and handed out as copies, which callers may change; ranges never change
            object.__setattr__(self, "_valid", valid)
            return valid.copy()
        return valid

    def valid_view(self) -> np.ndarray:
        """(n,) bool: :meth:`valid_mask` without limits, the scan's own cached array and not a copy — for readers that
        never write to it (the kernels that only read the mask); computed on the scan's first call."""
        valid = self._valid
        if valid is None:
            self.valid_mask()
            valid = self._valid
        return valid

    def has_valid_mask(self) -> bool:
        """Whether the scan holds its :meth:`valid_mask` already (computed by a first call, or adopted)."""
        return self._valid is not None

    def adopt_valid_mask(self, valid: np.ndarray) -> None:
        """Keep ``valid`` as the scan's :meth:`valid_mask` (no limits): for a caller that computed exactly those values
        in a pass of its own (:meth:`dynslam2d.detect.body.BodyFilter.mask`). ``valid`` must be a (n,) bool array that
        nobody writes to afterwards; a mask the scan holds already is kept."""
        if self._valid is None:
            object.__setattr__(self, "_valid", valid)

    def points(self, mask: np.ndarray | None = None) -> np.ndarray:
        """(m, 2) Cartesian points in the sensor frame, m, of the beams in ``mask``
        (default: the valid beams). Paper Eq. 4: s_i = (r_i cos α_i, r_i sin α_i)."""
        m = self.valid_mask() if mask is None else mask
        r = self.ranges[m]
        c, s = self.trig()
        return np.column_stack((r * c[m], r * s[m]))

    def with_ranges(self, ranges: np.ndarray, stamp: float | None = None) -> Scan:
        """A copy with new ranges (same beam geometry), e.g. a filtered scan."""
        return Scan(
            stamp=self.stamp if stamp is None else stamp,
            angle_min=self.angle_min,
            angle_increment=self.angle_increment,
            ranges=ranges,
            range_min=self.range_min,
            range_max=self.range_max,
            frame_id=self.frame_id,
            intensities=self.intensities,
            angle_max=self.angle_max,
            time_increment=self.time_increment,
            scan_time=self.scan_time,
            odom=self.odom,
            yaw_rate=self.yaw_rate,
        )

    def without(self, mask: np.ndarray) -> Scan:
        """A copy with the beams in ``mask`` ((n,) bool) set to no return (NaN): the same as
        ``with_ranges(np.where(mask, np.nan, ranges))`` without re-validating the unchanged geometry
        (the pipeline drops the robot's body, known movers and removed beams this way every scan)."""
        mask = np.asarray(mask, dtype=bool)
        ranges = self.ranges.copy()
        np.copyto(ranges, np.nan, where=mask)  # (the values of np.where(mask, nan, ranges), in half the time)
        valid = self._valid
        # valid and not mask (for bool arrays ``valid > mask`` is ``valid & ~mask`` in one operation)
        return _copy_scan(self, ranges, None if valid is None else np.greater(valid, mask))

    def with_odometry(self, odom: Pose2D | None, yaw_rate: float | None = None) -> Scan:
        """A copy carrying ``odom`` (laser pose in the odometry frame) and ``yaw_rate`` (rad/s).

        Every other field is this (already validated) scan's, so the checks are not run again:
        sources attach odometry to every scan of a log.
        """
        out = _copy_scan(self)
        object.__setattr__(out, "odom", odom)
        object.__setattr__(out, "yaw_rate", yaw_rate)
        return out

    def same_as(self, other: Scan) -> bool:
        """Exact equality of every field, NaN == NaN (used by round-trip tests)."""
        def arr_eq(a: np.ndarray | None, b: np.ndarray | None) -> bool:
            if a is None or b is None:
                return a is None and b is None
            return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))

        return (
            self.stamp == other.stamp
            and self.angle_min == other.angle_min
            and self.angle_increment == other.angle_increment
            and self.angle_max == other.angle_max
            and self.range_min == other.range_min
            and self.range_max == other.range_max
            and self.frame_id == other.frame_id
            and self.time_increment == other.time_increment
            and self.scan_time == other.scan_time
            and arr_eq(self.ranges, other.ranges)
            and arr_eq(self.intensities, other.intensities)
        )


#: Each slot's setter, in ``Scan.__slots__`` order (:func:`_copy_scan`; ``tests/test_types.py`` checks the order).
(_SET_STAMP, _SET_ANGLE_MIN, _SET_ANGLE_INCREMENT, _SET_RANGES, _SET_RANGE_MIN, _SET_RANGE_MAX, _SET_FRAME_ID,
 _SET_INTENSITIES, _SET_ANGLE_MAX, _SET_TIME_INCREMENT, _SET_SCAN_TIME, _SET_ODOM, _SET_YAW_RATE, _SET_ANGLES,
 _SET_VALID, _SET_TRIG) = _SCAN_SETTERS = tuple(Scan.__dict__[name].__set__ for name in Scan.__slots__)
_SCAN_SLOTS = ("stamp", "angle_min", "angle_increment", "ranges", "range_min", "range_max", "frame_id", "intensities",
               "angle_max", "time_increment", "scan_time", "odom", "yaw_rate", "_angles", "_valid", "_trig")
_NEW = object.__new__


def ranges_valid(ranges: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(n,) bool: the ``ranges`` (m) that hold a return, finite and within [``lo``, ``hi``] m (:meth:`Scan.valid_mask`;
    the loop closer's packed keyframes test their decoded ranges the same way)."""
    return np.isfinite(ranges) & (ranges >= lo) & (ranges <= hi)


def _copy_scan(scan: Scan, ranges: np.ndarray | None = None, valid: np.ndarray | None = None) -> Scan:
    """A shallow copy of ``scan`` without ``__init__``'s checks; with ``ranges``, those ranges and the valid mask
    ``valid`` (None: not computed yet) instead of the scan's. Every slot written by its own setter, one statement
    each (half the time of a loop over the slots' setters and an ``attrgetter`` of all slots, pass front25)."""
    out = _NEW(Scan)
    _SET_STAMP(out, scan.stamp)
    _SET_ANGLE_MIN(out, scan.angle_min)
    _SET_ANGLE_INCREMENT(out, scan.angle_increment)
    _SET_RANGE_MIN(out, scan.range_min)
    _SET_RANGE_MAX(out, scan.range_max)
    _SET_FRAME_ID(out, scan.frame_id)
    _SET_INTENSITIES(out, scan.intensities)
    _SET_ANGLE_MAX(out, scan.angle_max)
    _SET_TIME_INCREMENT(out, scan.time_increment)
    _SET_SCAN_TIME(out, scan.scan_time)
    _SET_ODOM(out, scan.odom)
    _SET_YAW_RATE(out, scan.yaw_rate)
    _SET_ANGLES(out, scan._angles)
    _SET_TRIG(out, scan._trig)  # (the same beam geometry: the same (cos, sin))
    if ranges is None:
        _SET_RANGES(out, scan.ranges)
        _SET_VALID(out, scan._valid)
    else:
        _SET_RANGES(out, ranges)
        _SET_VALID(out, valid)
    return out


@dataclass(slots=True)
class SourceMeta:
    """What a scan source holds, as far as is known before reading it all.

    Attributes:
        format: short format name ("ros1-bag", "ros2-bag", "mcap", "carmen", "sim").
        origin: the file or folder read (or "sim:<scenario>").
        topic: the LaserScan topic (bags) or record type (CARMEN) used.
        count: number of scans, or None when it cannot be known without reading.
        beams: beams per scan (of the first scan), or None if unknown.
        fov: field of view, rad, or None.
        rate_hz: nominal scan rate, Hz, or None.
        frame_id: sensor frame id, or None.
        range_min, range_max: sensor range limits, m, or None.
        extra: format-specific details (e.g. other topics in a bag).
        odometry: where ``Scan.odom`` / ``Scan.yaw_rate`` come from (e.g. "/odom (nav_msgs/Odometry)",
            "tf odom→base_link", "CARMEN ODOM", "sim"), or None when scans carry none.
    """

    format: str
    origin: str
    topic: str | None = None
    count: int | None = None
    beams: int | None = None
    fov: float | None = None
    rate_hz: float | None = None
    frame_id: str | None = None
    range_min: float | None = None
    range_max: float | None = None
    extra: dict[str, object] = field(default_factory=dict)
    odometry: str | None = None


@runtime_checkable
class ScanSource(Protocol):
    """An iterable of :class:`Scan` in time order, with metadata.

    ``len(source)`` gives the scan count where it is known (``meta.count``) and
    raises ``TypeError`` otherwise. Iterating twice reads the input twice.
    """

    meta: SourceMeta

    def __iter__(self) -> Iterator[Scan]: ...

    def __len__(self) -> int: ...


class SourceWrapper:
    """A scan source that wraps another: same ``meta`` and length; every other attribute
    (``ground_truth`` of a simulated source, ``path`` of a bag, …) is the inner source's."""

    def __init__(self, inner: ScanSource) -> None:
        self.inner = inner
        self.meta: SourceMeta = inner.meta

    def __len__(self) -> int:
        return len(self.inner)

    def __getattr__(self, name: str) -> object:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


@dataclass(frozen=True, slots=True)
class Box:
    """An oriented rectangle, the paper's object state x = [p_x, p_y, θ, l, w] (paper Eq. 2).

    Attributes:
        px, py: centre, m (in whatever frame the producer states; the tracker uses the map frame).
        theta: heading of the length axis, rad in [-π, π).
        length: side along ``theta``, m.
        width: side perpendicular to ``theta``, m.
    """

    px: float
    py: float
    theta: float
    length: float
    width: float

    @property
    def center(self) -> np.ndarray:
        return np.array([self.px, self.py])

    def corners(self) -> np.ndarray:
        """(4, 2) corners, counter-clockwise from (+l/2, −w/2) in the box frame, m."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        hl, hw = 0.5 * self.length, 0.5 * self.width
        local = np.array([[hl, -hw], [hl, hw], [-hl, hw], [-hl, -hw]])
        return np.column_stack((self.px + c * local[:, 0] - s * local[:, 1],
                                self.py + s * local[:, 0] + c * local[:, 1]))

    def as_array(self) -> np.ndarray:
        """[p_x, p_y, θ, l, w] (paper Eq. 2)."""
        return np.array([self.px, self.py, self.theta, self.length, self.width])


@dataclass(frozen=True, slots=True, eq=False)
class Track:
    """A tracked object as reported after one scan (map frame, SI units).

    Attributes:
        id: track id, unique over a tracker's life (1, 2, …).
        state: "tentative", "confirmed" or "coasting" (deleted tracks are not reported).
        stamp: stamp of the scan this report belongs to, s.
        box: the object's box (centre, heading, length, width), map frame.
        velocity: (2,) centre velocity v_x, v_y, m/s, map frame.
        covariance: (4, 4) covariance of [p_x, p_y, v_x, v_y] (m², m²/s, m²/s²).
        age: time since the track was born, s.
        hits: number of scans with a detection assigned.
        misses: consecutive scans without a detection (0 when updated in this scan).
        kind: shape model of the last detection: "rect", "circle" or "point".
        in_m: True if the track is in the dynamic set M (paper Eq. 3).
        m_reason: why it is or is not in M (human-readable).
        beams: indices of the scan beams assigned to this track in this scan (empty when coasting).
        n_points: len(beams).
        remembered: True if the track is in M only because it moved before and has stopped (track
            memory, docs/maps.md).
    """

    id: int
    state: str
    stamp: float
    box: Box
    velocity: np.ndarray
    covariance: np.ndarray
    age: float
    hits: int
    misses: int
    kind: str
    in_m: bool
    m_reason: str
    beams: np.ndarray
    n_points: int
    remembered: bool = False

    @property
    def center(self) -> np.ndarray:
        return self.box.center

    @property
    def heading(self) -> float:
        return self.box.theta

    @property
    def size(self) -> tuple[float, float]:
        """(length, width), m."""
        return self.box.length, self.box.width

    @property
    def speed(self) -> float:
        return float(math.hypot(self.velocity[0], self.velocity[1]))
