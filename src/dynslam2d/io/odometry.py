"""Odometry and IMU tracks, their interpolation at scan stamps, and attaching them to scans.

The contract with the rest of the project (``Scan.odom``, ``Scan.yaw_rate``):

* ``Scan.odom`` is the LASER's pose in the odometry frame at the scan's stamp:
  ``odom_T_base(t) ⊕ base_T_laser``, where ``odom_T_base(t)`` is the robot base
  pose interpolated at ``t`` from an :class:`OdometryTrack` and ``base_T_laser``
  is the static mount of the laser on the base (TF ``base_link → laser``).
* ``Scan.yaw_rate`` is the yaw rate about +z at the scan's stamp, rad/s, from an
  :class:`ImuTrack` (an IMU's ``angular_velocity.z``; the IMU's z axis is taken to
  be parallel to the laser's, REP 103 "z up").

Interpolation (:func:`interpolate_poses`) is linear in x and y and in the wrapped
yaw difference between the two bracketing samples, applied to the BASE pose; the
static mount is composed afterwards, so the laser pose is exactly the rigid-body
pose of the mounted sensor (interpolating laser poses directly would shorten the
laser's arc in turns). A stamp outside the track's time span by more than
``tolerance`` s, or inside a gap between samples longer than ``max_gap`` s, gets
no pose (``Scan.odom = None``) — never an extrapolation beyond ``tolerance``.
:class:`OdometrySource` counts such scans in ``meta.extra["odometry"]``.

Frames: poses are (x, y, yaw) in m and rad, REP 103 axes; stamps in s on the
scans' clock (header stamps of the bag, or the CARMEN log's timestamps).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceWrapper, wrap_angle

__all__ = [
    "DEFAULT_MAX_GAP_S",
    "DEFAULT_TOLERANCE_S",
    "DEFAULT_IMU_WINDOW_S",
    "ImuTrack",
    "OdometryInput",
    "OdometrySource",
    "OdometryTrack",
    "compose_mount",
    "interpolate_poses",
    "parse_laser_offset",
]

#: How far (s) outside an odometry track's time span a scan may lie and still get a
#: pose (extrapolated along the first/last segment). Beyond it: ``odom = None``.
DEFAULT_TOLERANCE_S = 0.1
#: Longest gap (s) between two odometry samples that is interpolated across;
#: a scan inside a longer gap gets ``odom = None`` (the robot may have done anything).
DEFAULT_MAX_GAP_S = 0.5
#: Width (s) of the window, centred on the scan stamp, over which IMU yaw rates
#: are averaged (fewer than one sample in it: linear interpolation instead).
DEFAULT_IMU_WINDOW_S = 0.05


def _as_poses(poses: Any) -> np.ndarray:
    arr = np.ascontiguousarray(poses, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, 3)
    return arr.reshape(-1, 3)


@dataclass(frozen=True, eq=False)
class OdometryTrack:
    """Timed planar poses of a body (``child_frame_id``) in the odometry frame (``frame_id``).

    Attributes:
        stamps: (n,) strictly increasing times, s.
        poses: (n, 3) ``x, y, yaw`` of the body in the odometry frame, m and rad.
        frame_id: the odometry frame's name (e.g. "odom").
        child_frame_id: the body's name (e.g. "base_link"); the laser mount is relative to it.
        source: a human-readable description (e.g. "/odom (nav_msgs/Odometry)").
        dropped: samples removed on construction (non-finite values or repeated stamps).

    Construction sorts by stamp, drops non-finite samples and repeated stamps (keeping
    the first) and counts them in ``dropped``; a track left with no sample raises
    DynSlamError naming ``source``.
    """

    stamps: np.ndarray
    poses: np.ndarray
    frame_id: str = "odom"
    child_frame_id: str = "base_link"
    source: str = "odometry"
    dropped: int = 0
    nonfinite: int = 0

    def __post_init__(self) -> None:
        stamps = np.ascontiguousarray(self.stamps, dtype=np.float64).reshape(-1)
        poses = _as_poses(self.poses)
        if poses.shape[0] != stamps.shape[0]:
            raise DynSlamError(f"{self.source}: {stamps.shape[0]} stamps for {poses.shape[0]} poses")
        good = np.isfinite(stamps) & np.all(np.isfinite(poses), axis=1)
        nonfinite = int(stamps.shape[0] - np.count_nonzero(good))
        stamps, poses = stamps[good], poses[good]
        if stamps.shape[0] == 0:
            what = f" ({nonfinite} samples, none finite)" if nonfinite else ""
            raise DynSlamError(f"{self.source}: no usable odometry samples{what}")
        order = np.argsort(stamps, kind="stable")
        stamps, poses = stamps[order], poses[order]
        keep = np.concatenate(([True], np.diff(stamps) > 0.0))
        repeated = int(np.count_nonzero(~keep))
        stamps, poses = stamps[keep], poses[keep].copy()
        poses[:, 2] = wrap_angle(poses[:, 2])
        object.__setattr__(self, "stamps", stamps)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "dropped", int(self.dropped) + nonfinite + repeated)
        object.__setattr__(self, "nonfinite", int(self.nonfinite) + nonfinite)

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    @property
    def span(self) -> tuple[float, float]:
        """(first, last) stamp, s."""
        return float(self.stamps[0]), float(self.stamps[-1])

    def at(self, t: np.ndarray | float, *, tolerance: float = DEFAULT_TOLERANCE_S,
           max_gap: float = DEFAULT_MAX_GAP_S) -> tuple[np.ndarray, np.ndarray]:
        """Body poses at time(s) ``t``: ``(poses (m, 3), ok (m,) bool)``; see :func:`interpolate_poses`."""
        return interpolate_poses(self.stamps, self.poses, t, tolerance=tolerance, max_gap=max_gap)

    def path_length(self) -> float:
        """Length of the polyline through the positions, m."""
        if len(self) < 2:
            return 0.0
        return float(np.sum(np.hypot(np.diff(self.poses[:, 0]), np.diff(self.poses[:, 1]))))


@dataclass(frozen=True, eq=False)
class ImuTrack:
    """Yaw rates about +z from an IMU: (n,) ``stamps`` s (increasing) and ``yaw_rate`` rad/s.

    Non-finite samples and repeated stamps are dropped on construction (counted in
    ``dropped``); a track left empty raises DynSlamError naming ``source``.
    """

    stamps: np.ndarray
    yaw_rate: np.ndarray
    frame_id: str = "imu"
    source: str = "imu"
    dropped: int = 0

    def __post_init__(self) -> None:
        stamps = np.ascontiguousarray(self.stamps, dtype=np.float64).reshape(-1)
        rate = np.ascontiguousarray(self.yaw_rate, dtype=np.float64).reshape(-1)
        if rate.shape != stamps.shape:
            raise DynSlamError(f"{self.source}: {stamps.shape[0]} stamps for {rate.shape[0]} yaw rates")
        good = np.isfinite(stamps) & np.isfinite(rate)
        dropped = int(stamps.shape[0] - np.count_nonzero(good))
        stamps, rate = stamps[good], rate[good]
        if stamps.shape[0] == 0:
            raise DynSlamError(f"{self.source}: no usable IMU samples")
        order = np.argsort(stamps, kind="stable")
        stamps, rate = stamps[order], rate[order]
        keep = np.concatenate(([True], np.diff(stamps) > 0.0))
        dropped += int(np.count_nonzero(~keep))
        object.__setattr__(self, "stamps", stamps[keep])
        object.__setattr__(self, "yaw_rate", rate[keep])
        object.__setattr__(self, "dropped", int(self.dropped) + dropped)

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    def at(self, t: float, *, window: float = DEFAULT_IMU_WINDOW_S, tolerance: float = DEFAULT_TOLERANCE_S,
           max_gap: float = DEFAULT_MAX_GAP_S) -> float | None:
        """Yaw rate at ``t`` (rad/s): the mean of the samples within ``±window/2`` of ``t``;
        with none there, linear interpolation between the bracketing samples (None outside
        the span by more than ``tolerance`` or inside a gap longer than ``max_gap``)."""
        s = self.stamps
        lo = int(np.searchsorted(s, t - 0.5 * window, side="left"))
        hi = int(np.searchsorted(s, t + 0.5 * window, side="right"))
        if hi > lo:
            return float(np.mean(self.yaw_rate[lo:hi]))
        n = s.shape[0]
        if t < s[0] - tolerance or t > s[-1] + tolerance:
            return None
        if n == 1 or t <= s[0]:
            return float(self.yaw_rate[0])
        if t >= s[-1]:
            return float(self.yaw_rate[-1])
        k = int(np.searchsorted(s, t, side="right")) - 1
        if s[k + 1] - s[k] > max_gap:
            return None
        a = (t - s[k]) / (s[k + 1] - s[k])
        return float((1.0 - a) * self.yaw_rate[k] + a * self.yaw_rate[k + 1])


def interpolate_poses(stamps: np.ndarray, poses: np.ndarray, t: np.ndarray | float, *,
                      tolerance: float = DEFAULT_TOLERANCE_S,
                      max_gap: float = DEFAULT_MAX_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """Planar poses at times ``t`` from samples ``(stamps (n,), poses (n, 3))``.

    Between samples k and k+1 (``a = (t − t_k)/(t_{k+1} − t_k)``):
    ``x = x_k + a·(x_{k+1} − x_k)``, same for y, ``yaw = wrap(yaw_k + a·wrap(yaw_{k+1} − yaw_k))``.
    Within ``tolerance`` s before the first / after the last sample the first / last
    segment is extended (a single sample is held). Returns ``(out (m, 3), ok (m,))``;
    ``ok`` is False (and ``out`` NaN) outside the span by more than ``tolerance``, or
    inside a gap longer than ``max_gap`` s (unless ``t`` falls on a sample).
    """
    ts = np.atleast_1d(np.asarray(t, dtype=np.float64))
    s = np.asarray(stamps, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    m, n = ts.shape[0], s.shape[0]
    out = np.full((m, 3), np.nan)
    ok = np.zeros(m, dtype=bool)
    if n == 0:
        return out, ok
    inside = (ts >= s[0] - tolerance) & (ts <= s[-1] + tolerance)
    if n == 1:
        out[inside] = p[0]
        ok[inside] = True
        return out, ok
    k = np.clip(np.searchsorted(s, ts, side="right") - 1, 0, n - 2)
    t0, t1 = s[k], s[k + 1]
    a = (ts - t0) / (t1 - t0)
    d = p[k + 1] - p[k]
    d[:, 2] = wrap_angle(d[:, 2])
    out[:, :2] = p[k, :2] + a[:, None] * d[:, :2]
    out[:, 2] = wrap_angle(p[k, 2] + a * d[:, 2])
    on_sample = (np.abs(ts - t0) <= 1e-9) | (np.abs(ts - t1) <= 1e-9)
    interior = (ts > s[0]) & (ts < s[-1])
    gap_ok = ~interior | ((t1 - t0) <= max_gap) | on_sample
    ok = inside & gap_ok
    out[~ok] = np.nan
    return out, ok


def compose_mount(base: np.ndarray, mount: Pose2D) -> np.ndarray:
    """(m, 3) laser poses ``base_i ⊕ mount`` from (m, 3) base poses (m, rad)."""
    b = _as_poses(base)
    c, s = np.cos(b[:, 2]), np.sin(b[:, 2])
    out = np.empty_like(b)
    out[:, 0] = b[:, 0] + c * mount.x - s * mount.y
    out[:, 1] = b[:, 1] + s * mount.x + c * mount.y
    out[:, 2] = wrap_angle(b[:, 2] + mount.theta)
    return out


def parse_laser_offset(text: str, option: str = "--laser-offset") -> Pose2D:
    """``"x,y,yaw"`` (m, m, rad; also space-separated) → the base_link → laser Pose2D
    (``option`` names the command-line option in the error message)."""
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise DynSlamError(f"{option} {text!r}: expected three numbers x,y,yaw (m, m, rad), e.g. -0.12,0,0")
    return Pose2D(*values)


@dataclass(eq=False)
class OdometryInput:
    """What a recording offers for ``Scan.odom`` / ``Scan.yaw_rate``, chosen by ``--odom``/``--imu``.

    Attributes:
        track: base poses in the odometry frame, or None (no odometry).
        mount: the static base → laser transform (``base_link → laser``), m and rad.
        mount_source: where ``mount`` came from ("tf_static", "--laser-offset", "CARMEN
            laser/odometry pose fields", "identity (unknown)", …).
        imu: yaw rates, or None.
        laser_poses: per-scan laser poses in the odometry frame keyed by nothing but
            order (CARMEN records carry them exactly at the scan stamps): (n, 3) or None.
            When set it is used instead of ``track``.
        description: the one-line ``SourceMeta.odometry`` text.
        warnings: things the user should know (fallbacks, dropped samples).
        explicit: True when the user named the source (then zero coverage is an error).
    """

    track: OdometryTrack | None = None
    mount: Pose2D = field(default_factory=Pose2D)
    mount_source: str = "identity"
    imu: ImuTrack | None = None
    laser_poses: np.ndarray | None = None
    description: str | None = None
    warnings: list[str] = field(default_factory=list)
    explicit: bool = False
    explicit_imu: bool = False  # the user named the IMU topic (then zero coverage is an error)
    tolerance: float = DEFAULT_TOLERANCE_S
    max_gap: float = DEFAULT_MAX_GAP_S

    @property
    def empty(self) -> bool:
        return self.track is None and self.imu is None and self.laser_poses is None


class OdometrySource(SourceWrapper):
    """Wraps a scan source; yields its scans with ``odom`` and ``yaw_rate`` attached.

    ``meta`` is the inner source's, with ``meta.odometry`` set to the input's description
    and ``meta.extra["odometry"]`` a dict: ``source``, ``imu``, ``mount`` ([x, y, yaw]),
    ``mount_source``, and after iterating ``scans``, ``with_odom``, ``without_odom``
    (outside the span or in a gap), ``with_yaw_rate``. Warnings are appended to
    ``meta.extra["warnings"]``.

    Raises:
        DynSlamError: (while iterating) odometry that was asked for explicitly covers no
            scan at all — named with both time spans.
    """

    def __init__(self, inner: ScanSource, odometry: OdometryInput) -> None:
        super().__init__(inner)
        self.odometry = odometry
        self.meta.odometry = odometry.description
        self.stats: dict[str, Any] = {}
        warnings = self.meta.extra.setdefault("warnings", [])
        for w in odometry.warnings:
            if w not in warnings:
                warnings.append(w)
        self._reset_stats()

    def _reset_stats(self) -> None:
        o = self.odometry
        self.stats = {
            "source": o.description,
            "imu": None if o.imu is None else o.imu.source,
            "mount": [o.mount.x, o.mount.y, o.mount.theta],
            "mount_source": o.mount_source,
            "scans": 0,
            "with_odom": 0,
            "without_odom": 0,
            "with_yaw_rate": 0,
            "has_odometry": o.track is not None or o.laser_poses is not None,  # not only an IMU
        }
        if o.track is not None:
            self.stats["span"] = list(o.track.span)
            self.stats["samples"] = len(o.track)
        self.meta.extra["odometry"] = self.stats

    def __iter__(self) -> Iterator[Scan]:
        self._reset_stats()
        o = self.odometry
        st = self.stats
        first_stamp = last_stamp = None
        for index, scan in enumerate(self.inner):
            odom: Pose2D | None = None
            if o.laser_poses is not None:
                if index < o.laser_poses.shape[0] and bool(np.all(np.isfinite(o.laser_poses[index]))):
                    odom = Pose2D.from_array(o.laser_poses[index])
            elif o.track is not None:
                if o.explicit and index == 0 and scan.stamp > o.track.span[1] + o.tolerance:
                    a, b = o.track.span
                    raise DynSlamError(
                        f"{self.meta.origin}: {o.description}: odometry stamps {a:.3f}…{b:.3f} s end before "
                        f"the first scan ({scan.stamp:.3f} s); different clocks? (use --odom none for laser only)")
                base, ok = o.track.at(scan.stamp, tolerance=o.tolerance, max_gap=o.max_gap)
                if ok[0]:
                    odom = Pose2D.from_array(compose_mount(base, o.mount)[0])
            if o.explicit_imu and index == 0 and o.imu is not None and scan.stamp > o.imu.stamps[-1] + o.tolerance:
                raise DynSlamError(
                    f"{self.meta.origin}: {o.imu.source}: IMU stamps {o.imu.stamps[0]:.3f}…{o.imu.stamps[-1]:.3f} s "
                    f"end before the first scan ({scan.stamp:.3f} s); different clocks? (use --imu none)")
            rate = None if o.imu is None else o.imu.at(scan.stamp, tolerance=o.tolerance, max_gap=o.max_gap)
            st["scans"] += 1
            if odom is not None:
                st["with_odom"] += 1
            elif o.track is not None or o.laser_poses is not None:
                st["without_odom"] += 1
            if rate is not None:
                st["with_yaw_rate"] += 1
            if first_stamp is None:
                first_stamp = scan.stamp
            last_stamp = scan.stamp
            yield scan.with_odometry(odom, rate)
        has_odom = o.track is not None or o.laser_poses is not None
        if has_odom and st["without_odom"]:
            where = ""
            if o.track is not None:
                a, b = o.track.span
                where = f" (odometry covers {a:.3f}…{b:.3f} s, scans {first_stamp:.3f}…{last_stamp:.3f} s)"
            msg = (f"odometry: {st['without_odom']} of {st['scans']} scans outside the odometry's time span "
                   f"or in a gap{where}; those scans are matched laser only")
            warnings = self.meta.extra.setdefault("warnings", [])
            if msg not in warnings:
                warnings.append(msg)
            if o.explicit and st["with_odom"] == 0:
                raise DynSlamError(f"{self.meta.origin}: {o.description}: no scan lies within the odometry's "
                                   f"stamps{where}; different clocks? (use --odom none for laser only)")
        if o.imu is not None and st["scans"] and st["with_yaw_rate"] < st["scans"]:
            a, b = float(o.imu.stamps[0]), float(o.imu.stamps[-1])
            where = f" (IMU covers {a:.3f}…{b:.3f} s, scans {first_stamp:.3f}…{last_stamp:.3f} s)"
            if o.explicit_imu and st["with_yaw_rate"] == 0:
                raise DynSlamError(f"{self.meta.origin}: {o.imu.source}: no scan lies within the IMU's stamps{where}; "
                                   "different clocks? (use --imu none)")
            msg = (f"IMU: {st['scans'] - st['with_yaw_rate']} of {st['scans']} scans outside the IMU's time span "
                   f"or in a gap{where}; those scans have no yaw rate")
            warnings = self.meta.extra.setdefault("warnings", [])
            if msg not in warnings:
                warnings.append(msg)


def rewrite_trajectory_frame(run_dir: Any, mount: Pose2D) -> None:
    """Turn a results folder's ``trajectory.tum`` from laser poses into base poses.

    Each pose becomes ``laser_i ⊕ mount⁻¹`` (``mount`` = base_link → laser, m and rad); the
    map frame is unchanged (the first LASER pose). ``summary.json`` gets
    ``trajectory_frame: "base_link"`` and ``base_to_laser: [x, y, yaw]``. Both files are
    rewritten atomically.
    """
    import json
    from pathlib import Path

    from dynslam2d.io.atomic import write_text_atomic
    from dynslam2d.io.trajectory import Trajectory, read_tum, write_tum

    d = Path(run_dir)
    traj = read_tum(d / "trajectory.tum")
    base = compose_mount(traj.poses, mount.inverse())
    write_tum(d / "trajectory.tum", Trajectory(traj.stamps, base, traj.frame),
              comment="base_link pose in the map frame (the map frame is the first laser pose)")
    path = d / "summary.json"
    if path.exists():
        summary = json.loads(path.read_text())
        summary.update(base_frame_fields(mount))
        write_text_atomic(path, json.dumps(summary, indent=2) + "\n")


def base_frame_fields(mount: Pose2D) -> dict[str, Any]:
    """The summary.json fields :func:`rewrite_trajectory_frame` sets: the trajectory's frame and the mount."""
    return {"trajectory_frame": "base_link", "base_to_laser": [mount.x, mount.y, mount.theta]}
