"""Choose a recording's odometry (``--odom``), IMU (``--imu``) and laser mount, and attach them.

:func:`attach_odometry` wraps a scan source of any format in an
:class:`~dynslam2d.io.odometry.OdometrySource`:

* ROS bags: :func:`dynslam2d.io.odombag.read_bag_odometry` (nav_msgs/Odometry, TF,
  wheel speeds + IMU; sensor_msgs/Imu yaw rate);
* CARMEN logs: the laser pose fields of the laser records themselves (``FLASER`` /
  ``ROBOTLASER1`` ``x y theta`` / ``laser_x laser_y laser_theta``: the laser pose in the
  odometry frame at exactly the scan's stamp; in MIT CSAIL these are raw odometry), else
  the ``ODOM`` records interpolated at the scan stamps. In ``auto`` mode a log that is
  SLAM output (GMapping ``NEFF`` records, a TORO graph's ``VERTEX2``/``EDGE2`` records as
  in the flirtlib logs, "corrected" in its name, ``.gfs``) is not used: its poses are
  corrected, not odometry. The mount (for ``--frame
  base_link``) is the median of ``odom⁻¹ ⊕ laser`` over the laser records;
* the simulator: its own noisy odometry and IMU (``--odom auto``; ``none`` strips them).

Mode strings: ``"auto"`` (use what the recording has; problems become warnings and
the run continues laser only), ``"none"`` (laser only: today's behaviour exactly), or a
name (a bag topic, ``tf``; for CARMEN ``FLASER``/``ROBOTLASER1``/``laser`` or ``ODOM``):
then anything wrong is a DynSlamError.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.odometry import OdometryInput, OdometrySource, OdometryTrack, SourceWrapper
from dynslam2d.types import Pose2D, Scan, ScanSource, wrap_angle

__all__ = ["ODOM_MODES", "attach_odometry", "carmen_odometry"]

#: The fixed words of ``--odom`` / ``--imu`` (anything else names a topic or record type).
ODOM_MODES = ("auto", "none")
_CARMEN_LASER_NAMES = ("flaser", "robotlaser1", "laser")


def _median_mount(odom: np.ndarray, laser: np.ndarray) -> Pose2D | None:
    """Median of ``odom_i⁻¹ ⊕ laser_i`` over rows where both are finite (the static mount)."""
    good = np.all(np.isfinite(odom), axis=1) & np.all(np.isfinite(laser), axis=1)
    if not good.any():
        return None
    o, la = odom[good], laser[good]
    c, s = np.cos(o[:, 2]), np.sin(o[:, 2])
    dx, dy = la[:, 0] - o[:, 0], la[:, 1] - o[:, 1]
    mx = c * dx + s * dy
    my = -s * dx + c * dy
    mt = wrap_angle(la[:, 2] - o[:, 2])
    return Pose2D(float(np.median(mx)), float(np.median(my)), float(np.median(mt)))


def carmen_odometry(source: object, odom: str = "auto", imu: str = "auto",
                    laser_offset: Pose2D | None = None) -> OdometryInput:
    """Odometry of a :class:`~dynslam2d.io.carmen.CarmenSource` (see the module docstring)."""
    name = getattr(source, "path", "CARMEN log")
    if imu not in ODOM_MODES:
        raise DynSlamError(f"{name}: --imu {imu}: CARMEN logs hold no IMU records (use --imu auto or none)")
    out = OdometryInput(explicit=odom not in ODOM_MODES)
    if odom == "none":
        return out
    want = odom.lower()
    if want not in ODOM_MODES and want not in _CARMEN_LASER_NAMES and want != "odom":
        raise DynSlamError(
            f"{name}: --odom {odom}: a CARMEN log carries odometry as the laser records' pose fields "
            f"(--odom FLASER) or as ODOM records (--odom ODOM)")
    if want == "auto":
        extra = getattr(source, "meta", None).extra if getattr(source, "meta", None) is not None else {}
        counts = extra.get("records") or {}
        marks = {k: int(counts.get(k, 0)) for k in ("NEFF", "VERTEX2", "EDGE2") if counts.get(k, 0)}
        fname = str(name).lower()
        if marks or "corrected" in fname or fname.endswith((".gfs", ".gfs.gz")):
            why = (", ".join(f"{v} {k}" for k, v in marks.items()) + " records (SLAM output)") if marks \
                else "a corrected log (by its name)"
            out.warnings.append(
                f"odometry: not used: the log has {why}; its poses are SLAM-corrected, not odometry "
                f"(--odom FLASER / ROBOTLASER1 / ODOM uses them anyway)")
            return out
    records = list(source.records())  # type: ignore[attr-defined]
    kinds = sorted({r.kind for r in records})
    laser = np.array([r.laser_pose.as_array() if r.laser_pose is not None else (np.nan,) * 3 for r in records])
    robot = np.array([r.odom.as_array() if r.odom is not None else (np.nan,) * 3 for r in records])
    mount = _median_mount(robot, laser)
    if laser_offset is not None:
        out.mount, out.mount_source = laser_offset, "--laser-offset"
    elif mount is not None:
        out.mount, out.mount_source = mount, "CARMEN laser/odometry pose fields"
    failures: list[str] = []
    if want in ("auto", *_CARMEN_LASER_NAMES):
        finite = np.all(np.isfinite(laser), axis=1)
        varies = laser.shape[0] > 1 and bool(np.any(np.ptp(laser[finite], axis=0) > 0.0)) if finite.any() else False
        if not finite.any() or not varies:
            failures.append(f"the {'/'.join(kinds)} pose fields are {'not finite' if not finite.any() else 'constant'}")
        else:
            out.laser_poses = laser
            out.description = f"CARMEN {'/'.join(kinds)} pose fields"
            missing = int(np.count_nonzero(~finite))
            if missing:
                out.warnings.append(f"odometry: {missing} laser records have non-finite pose fields (no odom)")
            return out
    if want in ("auto", "odom"):
        od = source.odometry()  # type: ignore[attr-defined]
        if len(od) == 0:
            failures.append("no ODOM records")
        elif not np.all(np.isfinite(od.stamp)):
            failures.append("the ODOM records have no usable stamps (the scans' stamps were synthesized)")
        else:
            try:
                out.track = OdometryTrack(od.stamp, np.column_stack((od.x, od.y, od.theta)), "odom", "base",
                                          source="CARMEN ODOM records")
                out.description = "CARMEN ODOM records"
                if out.track.nonfinite:
                    out.warnings.append(f"odometry: {out.track.nonfinite} ODOM records with NaN/inf dropped")
                if laser_offset is None and mount is None:
                    out.warnings.append("odometry: the laser's offset on the robot is unknown; taken as zero "
                                        "(give --laser-offset x,y,yaw)")
                return out
            except DynSlamError as err:
                failures.append(str(err))
    msg = "; ".join(failures)
    if out.explicit:
        raise DynSlamError(f"{name}: --odom {odom}: {msg}")
    if failures and (want != "auto" or len(source.odometry()) > 0):  # type: ignore[attr-defined]
        out.warnings.append(f"odometry: {msg}; continuing without odometry (laser only)")
    return out


class _StripOdometry(SourceWrapper):
    """A simulated source with its odometry and/or IMU removed (``--odom none`` / ``--imu none``)."""

    def __init__(self, inner: ScanSource, keep_odom: bool, keep_imu: bool) -> None:
        super().__init__(inner)
        self.keep_odom, self.keep_imu = keep_odom, keep_imu
        if not keep_odom:
            self.meta.odometry = "sim IMU" if keep_imu else None
            self.meta.extra.pop("odometry", None)

    def __iter__(self) -> Iterator[Scan]:
        for scan in self.inner:
            yield scan.with_odometry(scan.odom if self.keep_odom else None,
                                     scan.yaw_rate if self.keep_imu else None)


def attach_odometry(inner: ScanSource, fmt: str, *, odom: str = "auto", imu: str = "auto",
                    laser_offset: Pose2D | None = None) -> ScanSource:
    """``inner`` with odometry / IMU attached as ``odom`` / ``imu`` ask (module docstring).

    ``fmt`` is the sniffed format ("sim", "carmen", "ros1-bag", "ros2-bag", "mcap").
    Returns ``inner`` itself when there is nothing to attach.
    """
    if fmt == "sim":
        for flag, value in (("--odom", odom), ("--imu", imu)):
            if value not in ODOM_MODES:
                raise DynSlamError(f"{inner.meta.origin}: {flag} {value}: a simulated source has only its own "
                                   f"odometry and IMU (use {flag} auto or none)")
        if laser_offset is not None:
            raise DynSlamError(f"{inner.meta.origin}: --laser-offset does not apply to a simulated source "
                               f"(its mount is in the odometry model)")
        if odom == "auto" and imu == "auto":
            return inner
        return _StripOdometry(inner, keep_odom=odom == "auto", keep_imu=imu == "auto")
    if odom == "none" and imu == "none" and laser_offset is None:
        return inner
    if fmt == "carmen":
        info = carmen_odometry(inner, odom, imu, laser_offset)
    else:
        from dynslam2d.io.odombag import read_bag_odometry
        from dynslam2d.io.rosbag import RosbagSource

        # a bag source listed its topics when it opened the bag: no second opening just for them
        known = inner.meta.extra.get("topics") if isinstance(inner, RosbagSource) else None
        try:
            info = read_bag_odometry(getattr(inner, "path", inner.meta.origin), inner.meta.frame_id,
                                     odom=odom, imu=imu, laser_offset=laser_offset,
                                     topics=dict(known) if isinstance(known, dict) else None)
        except DynSlamError as err:
            if odom not in ODOM_MODES or imu not in ODOM_MODES:
                raise
            # nothing was asked for explicitly: a recording whose odometry cannot be read still maps
            info = OdometryInput(warnings=[f"odometry: {err}; continuing without odometry (laser only)"])
    if info.empty and laser_offset is None:
        warnings = inner.meta.extra.setdefault("warnings", [])
        warnings.extend(w for w in info.warnings if w not in warnings)
        return inner
    if info.empty:
        info.mount, info.mount_source = laser_offset, "--laser-offset"  # type: ignore[assignment]
    return OdometrySource(inner, info)


def laser_to_base(poses: np.ndarray, mount: Pose2D) -> np.ndarray:
    """(n, 3) base poses ``laser_i ⊕ mount⁻¹`` from laser poses (any frame), m and rad."""
    from dynslam2d.io.odometry import compose_mount

    if not all(math.isfinite(v) for v in (mount.x, mount.y, mount.theta)):
        raise DynSlamError("laser mount is not finite")
    return compose_mount(poses, mount.inverse())
