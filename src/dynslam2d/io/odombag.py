"""Odometry, TF and IMU in ROS bags: read them for ``Scan.odom``/``Scan.yaw_rate``, write them.

Reading (:func:`read_bag_odometry`) chooses one odometry source (``--odom``):

* ``nav_msgs/Odometry`` on a topic: the pose of ``child_frame_id`` (the base) in
  ``header.frame_id`` (the odometry frame) at ``header.stamp``;
* TF: the first transform that moves on the way from the laser frame up the tree
  (``/tf``, ``tf2_msgs/TFMessage``; ROS 1 and ROS 2), normally ``odom → base_link``;
* dead reckoning from wheel speeds (``barc/Encoder``, the datmo bags' ``/wheel_speeds``)
  and an IMU's yaw rate (:class:`DeadReckoning`).

The static mount ``base → laser`` is the chain of static transforms from the base
frame down to the laser frame (the scan's ``frame_id``), from ``/tf_static`` or from
``/tf`` transforms whose value never changes. ``laser_offset`` (``--laser-offset``)
overrides it. The IMU yaw rate is ``sensor_msgs/Imu`` ``angular_velocity.z`` (the IMU's
z axis is taken to be parallel to the laser's).

Frame names are compared without a leading ``/`` (ROS 1 tf_prefix style). Stamps are
header stamps (s); ``barc/Encoder`` has no header, so the bag record time is used.

Writing (:func:`write_scan_bag_with_odometry`) puts scans, ``/odom``, ``/tf`` (odom →
base), ``/tf_static`` (base → laser, latched) and ``/imu`` into one bag in time order.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.odometry import ImuTrack, OdometryInput, OdometryTrack
from dynslam2d.io.rosbag import (
    LASERSCAN,
    laserscan_message,
    list_topics,
    open_bag_writer,
    read_topic_messages,
    ros_time_to_stamp,
)
from dynslam2d.types import Pose2D, Scan, wrap_angle

__all__ = [
    "ENCODER",
    "IMU",
    "ODOMETRY",
    "TFMESSAGE",
    "DeadReckoning",
    "TfTree",
    "imu_message",
    "odometry_candidates",
    "odometry_message",
    "read_bag_odometry",
    "transform_message",
    "write_scan_bag_with_odometry",
]

ODOMETRY = "nav_msgs/msg/Odometry"
TFMESSAGE = "tf2_msgs/msg/TFMessage"
IMU = "sensor_msgs/msg/Imu"
ENCODER = "barc/msg/Encoder"
#: Topic names never taken for odometry in ``auto`` mode (ground truth is not odometry).
_NOT_ODOMETRY_WORDS = ("truth", "ground", "mocap", "gt")
#: Two static-mount sources disagreeing by more than this (m) are reported.
_MOUNT_DISAGREE_M = 0.01


@dataclass(frozen=True)
class DeadReckoning:
    """Dead reckoning from wheel speeds and an IMU yaw rate (the datmo bags' BARC cars).

    Model, per interval ``[t_k, t_{k+1}]`` between wheel-speed samples:
    ``v = wheel_radius · mean(wheel speeds of `wheels`)`` (trapezoid of the two ends),
    ``ω`` = the mean IMU yaw rate over the interval (minus ``gyro_bias``), and
    ``θ_{k+1} = θ_k + ω·Δt``, ``p_{k+1} = p_k + v·Δt·(cos, sin)(θ_k + ω·Δt/2)`` (midpoint
    heading). The body is assumed not to slip sideways.

    Attributes:
        wheel_radius: m per radian of wheel rotation (``/wheel_speeds`` holds rad/s).
        wheels: which Encoder fields to average: the undriven front wheels by default
            (the driven rear wheels spin under acceleration).
        gyro_bias: yaw-rate bias subtracted from the IMU, rad/s; None = estimate it as the
            mean yaw rate during the longest stretch with every wheel at zero (at least
            ``min_still_s`` long; 0.1 s trimmed at both ends), else 0.
    """

    wheel_radius: float = 0.0312
    wheels: tuple[str, ...] = ("FL", "FR")
    gyro_bias: float | None = None
    min_still_s: float = 0.5


def _frame(name: str) -> str:
    return str(name).lstrip("/")


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


class TfTree:
    """Planar transforms collected from ``/tf`` and ``/tf_static``, by (parent, child).

    An edge is *static* when it came from ``/tf_static`` or when every value it took on
    ``/tf`` is the same (static_transform_publisher on ROS 1 republishes on /tf).
    """

    def __init__(self) -> None:
        self._edges: dict[tuple[str, str], list[tuple[float, float, float, float]]] = {}
        self._static: set[tuple[str, str]] = set()
        self.parent: dict[str, str] = {}
        self.conflicts: list[str] = []

    def add(self, msg: Any, static: bool) -> None:
        for tr in msg.transforms:
            parent, child = _frame(tr.header.frame_id), _frame(tr.child_frame_id)
            if not parent or not child:
                continue
            known = self.parent.get(child)
            if known is not None and known != parent:
                note = f"frame {child} has two parents ({known}, {parent}); kept {known}"
                if note not in self.conflicts:
                    self.conflicts.append(note)
                continue
            self.parent[child] = parent
            t = tr.transform
            stamp = ros_time_to_stamp(tr.header.stamp.sec, tr.header.stamp.nanosec)
            self._edges.setdefault((parent, child), []).append(
                (stamp, float(t.translation.x), float(t.translation.y), _yaw(t.rotation)))
            if static:
                self._static.add((parent, child))

    @property
    def frames(self) -> set[str]:
        return set(self.parent) | set(self.parent.values())

    def is_static(self, parent: str, child: str) -> bool:
        if (parent, child) in self._static:
            return True
        vals = np.array(self._edges[(parent, child)])[:, 1:]
        return bool(np.all(np.ptp(vals, axis=0) < 1e-9)) if vals.shape[0] else True

    def value(self, parent: str, child: str) -> Pose2D:
        """The (last) value of a static edge."""
        _, x, y, yaw = self._edges[(parent, child)][-1]
        return Pose2D(x, y, yaw)

    def static_chain(self, ancestor: str, frame: str) -> Pose2D | None:
        """``ancestor → frame`` composed from static edges only, or None if there is no
        such all-static path (``frame`` is not below ``ancestor``)."""
        pose = Pose2D()
        f = frame
        while f != ancestor:
            p = self.parent.get(f)
            if p is None or not self.is_static(p, f):
                return None
            pose = self.value(p, f).compose(pose)
            f = p
        return pose

    def moving_edge_above(self, frame: str) -> tuple[str, str, Pose2D] | None:
        """Walk up from ``frame`` through static edges; return the first moving edge
        ``(parent, child, child → frame static mount)``, or None."""
        mount = Pose2D()
        f = frame
        seen = set()
        while f in self.parent and f not in seen:
            seen.add(f)
            p = self.parent[f]
            if not self.is_static(p, f):
                return p, f, mount
            mount = self.value(p, f).compose(mount)
            f = p
        return None

    def track(self, parent: str, child: str, source: str) -> OdometryTrack:
        arr = np.array(self._edges[(parent, child)], dtype=np.float64)
        return OdometryTrack(arr[:, 0], arr[:, 1:], parent, child, source=source)


def _is_ground_truth_name(topic: str) -> bool:
    """True for topic names that look like ground truth (never taken as odometry in auto mode)."""
    low = topic.lower()
    tokens = set(re.split(r"[/_\-]", low))
    return "truth" in low or "mocap" in low or bool(tokens & {"gt", "ground"})


def _describe(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in topics.items()) or "none"


def _short(msgtype: str) -> str:
    return msgtype.replace("/msg/", "/")


def _pick(candidates: list[str], preferred: tuple[str, ...]) -> tuple[str | None, str | None]:
    """(chosen topic, a note when several were possible)."""
    if not candidates:
        return None, None
    for name in preferred:
        for c in candidates:
            if c.strip("/") == name.strip("/"):
                chosen = c
                break
        else:
            continue
        break
    else:
        chosen = sorted(candidates)[0]
    note = None
    if len(candidates) > 1:
        others = ", ".join(c for c in sorted(candidates) if c != chosen)
        note = f"several candidates; using {chosen} (others: {others}; name one with the option)"
    return chosen, note


def _resolve(requested: str, topics: dict[str, str]) -> str | None:
    if requested in topics:
        return requested
    alt = requested[1:] if requested.startswith("/") else "/" + requested
    return alt if alt in topics else None


@dataclass
class _Plan:
    kinds: list[str] | None = None  # candidates in order: "topic" | "tf" | "wheels"
    odom_topic: str | None = None
    wheel_topic: str | None = None
    imu_topic: str | None = None
    explicit_odom: bool = False
    explicit_imu: bool = False
    notes: list[str] | None = None


def _plan(path: Path, topics: dict[str, str], odom: str, imu: str) -> _Plan:
    notes: list[str] = []
    plan = _Plan(notes=notes)
    odo_topics = [t for t, m in topics.items() if m == ODOMETRY]
    imu_topics = [t for t, m in topics.items() if m == IMU]
    wheel_topics = [t for t, m in topics.items() if m == ENCODER]
    has_tf = any(m == TFMESSAGE and t.strip("/") == "tf" for t, m in topics.items())
    # -- IMU
    if imu not in ("auto", "none"):
        name = _resolve(imu, topics)
        if name is None or topics[name] != IMU:
            what = "does not exist" if name is None else f"is {_short(topics[name])}, not sensor_msgs/Imu"
            raise DynSlamError(
                f"{path}: --imu {imu}: topic {what}; IMU topics: {', '.join(imu_topics) or 'none'}")
        plan.imu_topic, plan.explicit_imu = name, True
    elif imu == "auto":
        plan.imu_topic, note = _pick(imu_topics, ("/imu/data", "/imu"))
        if note:
            notes.append(f"IMU: {note} (--imu)")
    # -- odometry
    plan.kinds = []
    if odom == "none":
        return plan
    if odom == "auto":
        usable = [t for t in odo_topics if not _is_ground_truth_name(t)]
        if usable:
            plan.odom_topic, note = _pick(usable, ("/odom", "/odometry"))
            plan.kinds.append("topic")
            if note:
                notes.append(f"odometry: {note} (--odom)")
        if has_tf:
            plan.kinds.append("tf")
        if wheel_topics and plan.imu_topic:
            plan.wheel_topic = _pick(wheel_topics, ("/wheel_speeds",))[0]
            plan.kinds.append("wheels")
        elif wheel_topics:
            notes.append(f"odometry: wheel speeds on {', '.join(wheel_topics)} are not used: dead reckoning "
                         f"needs an IMU yaw rate{' (--imu none)' if imu == 'none' else ''}")
        return plan
    plan.explicit_odom = True
    if odom.strip("/") == "tf":
        if not has_tf:
            raise DynSlamError(f"{path}: --odom tf: the bag has no /tf topic; topics: {_describe(topics)}")
        plan.kinds.append("tf")
        return plan
    name = _resolve(odom, topics)
    if name is None or topics[name] not in (ODOMETRY, ENCODER, TFMESSAGE):
        what = "does not exist" if name is None else f"is {_short(topics[name])}"
        cands = {t: m for t, m in topics.items() if m in (ODOMETRY, ENCODER, TFMESSAGE)}
        raise DynSlamError(
            f"{path}: --odom {odom}: topic {what}; odometry needs nav_msgs/Odometry, tf (tf2_msgs/TFMessage) "
            f"or barc/Encoder wheel speeds; candidates: {_describe({t: _short(m) for t, m in cands.items()})}")
    if topics[name] == TFMESSAGE:
        plan.kinds.append("tf")
    elif topics[name] == ENCODER:
        plan.kinds.append("wheels")
        plan.wheel_topic = name
        if plan.imu_topic is None:
            raise DynSlamError(f"{path}: --odom {odom}: wheel-speed dead reckoning needs an IMU yaw rate, "
                               f"and "
                               f"{'--imu none was given' if imu == 'none' else 'the bag has no sensor_msgs/Imu topic'}")
    else:
        plan.kinds.append("topic")
        plan.odom_topic = name
    return plan


def odometry_candidates(path: str | os.PathLike[str], topics: dict[str, str], odom: str = "auto",
                        imu: str = "auto") -> dict[str, object]:
    """What :func:`read_bag_odometry` would try on a bag holding ``topics`` (name → type), from the
    names alone (no message read; for ``dynslam2d info``'s bag overview).

    Returns ``odometry``: the sources in the order tried (``"/odom (nav_msgs/Odometry)"``, ``"tf"``,
    ``"wheel speeds /wheel_speeds + IMU"``; empty = laser only), ``imu``: the IMU topic or None, and
    ``notes``. Whether TF gives odometry depends on the laser's frame (a moving transform above it),
    known only once a scan topic is read. Raises DynSlamError as :func:`read_bag_odometry` does for an
    explicitly named topic that is missing or of the wrong type.
    """
    plan = _plan(Path(path), topics, odom, imu)
    tried: list[str] = []
    for kind in plan.kinds or []:
        if kind == "topic" and plan.odom_topic:
            tried.append(f"{plan.odom_topic} ({_short(topics[plan.odom_topic])})")
        elif kind == "tf":
            tried.append("tf")
        elif kind == "wheels" and plan.wheel_topic:
            tried.append(f"wheel speeds {plan.wheel_topic} + IMU")
    return {"odometry": tried, "imu": plan.imu_topic, "notes": list(plan.notes or [])}


def _dead_reckon(wheels: list[tuple[float, Any]], imu: ImuTrack, model: DeadReckoning,
                 source: str, path: Path) -> OdometryTrack:
    t = np.array([w[0] for w in wheels], dtype=np.float64)
    try:
        speeds = np.array([[float(getattr(w[1], f)) for f in model.wheels] for w in wheels])
    except AttributeError as err:
        raise DynSlamError(f"{path}: wheel speeds: {err}; expected fields {', '.join(model.wheels)}") from None
    order = np.argsort(t, kind="stable")
    t, speeds = t[order], speeds[order]
    v = model.wheel_radius * np.mean(speeds, axis=1)
    bias = model.gyro_bias
    if bias is None:
        still = np.all(speeds == 0.0, axis=1)
        bias = 0.0
        if still.any():
            # the longest run of standing still, bracketed by wheel samples
            best = (0.0, 0, 0)
            k = 0
            n = still.shape[0]
            while k < n:
                if still[k]:
                    j = k
                    while j + 1 < n and still[j + 1]:
                        j += 1
                    if t[j] - t[k] > best[0]:
                        best = (t[j] - t[k], k, j)
                    k = j + 1
                else:
                    k += 1
            if best[0] >= model.min_still_s:
                # trimmed by 0.1 s at both ends: the wheels may start turning between two samples
                sel = (imu.stamps >= t[best[1]] + 0.1) & (imu.stamps <= t[best[2]] - 0.1)
                if np.count_nonzero(sel) >= 5:
                    bias = float(np.mean(imu.yaw_rate[sel]))
    n = t.shape[0]
    poses = np.zeros((n, 3))
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (imu.yaw_rate[1:] + imu.yaw_rate[:-1]) * np.diff(imu.stamps))))
    # integral of the IMU yaw rate (trapezoid), evaluated at the wheel stamps (held flat outside)
    heading = np.interp(t, imu.stamps, cum) - bias * (t - t[0])
    heading -= heading[0]
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        vm = 0.5 * (v[k] + v[k + 1])
        mid = 0.5 * (heading[k] + heading[k + 1])
        poses[k + 1, 0] = poses[k, 0] + vm * dt * math.cos(mid)
        poses[k + 1, 1] = poses[k, 1] + vm * dt * math.sin(mid)
    poses[:, 2] = wrap_angle(heading)
    return OdometryTrack(t, poses, "odom", "base_link", source=source)


def read_bag_odometry(
    path: str | os.PathLike[str],
    laser_frame: str | None,
    *,
    odom: str = "auto",
    imu: str = "auto",
    laser_offset: Pose2D | None = None,
    dead_reckoning: DeadReckoning | None = None,
    topics: dict[str, str] | None = None,
) -> OdometryInput:
    """Odometry, laser mount and IMU of a bag, as chosen by ``odom`` / ``imu``.

    Args:
        path: the bag (ROS 1, ROS 2 folder, bare MCAP/db3).
        laser_frame: the scans' ``frame_id`` (the TF child frame of the laser).
        odom: "auto" (a nav_msgs/Odometry topic, else TF, else wheel speeds + IMU; ground-
            truth-looking topic names are skipped), "none", "tf", or a topic name
            (nav_msgs/Odometry, tf2_msgs/TFMessage or barc/Encoder).
        imu: "auto" (the bag's sensor_msgs/Imu topic, /imu/data preferred), "none", or a topic.
        laser_offset: base → laser transform to use instead of TF (m, rad).
        dead_reckoning: parameters of the wheel-speed model.
        topics: the bag's topics and their types (:func:`~dynslam2d.io.rosbag.list_topics`) when the caller
            has them already (a :class:`~dynslam2d.io.rosbag.RosbagSource`'s ``meta.extra["topics"]``): the bag
            is then opened once here instead of twice.

    Raises:
        DynSlamError: an explicitly named topic that is missing or of the wrong type; TF
            asked for but without the laser frame or without a moving transform above it;
            odometry whose samples are all non-finite. In ``auto`` mode such problems
            become warnings in the result and the next source (or none) is used.
    """
    p = Path(path)
    topics = list_topics(p) if topics is None else topics
    plan = _plan(p, topics, odom, imu)
    out = OdometryInput(explicit=plan.explicit_odom, explicit_imu=plan.explicit_imu)
    out.warnings.extend(plan.notes or [])
    kinds = plan.kinds or []
    wanted: set[str] = set()
    if kinds or laser_offset is not None:
        wanted |= {t for t, m in topics.items() if m == TFMESSAGE and t.strip("/") in ("tf", "tf_static")}
    if "topic" in kinds and plan.odom_topic:
        wanted.add(plan.odom_topic)
    if "wheels" in kinds and plan.wheel_topic:
        wanted.add(plan.wheel_topic)
    if plan.imu_topic:
        wanted.add(plan.imu_topic)
    if not wanted:
        return out
    tree = TfTree()
    odo_rows: list[tuple[float, float, float, float]] = []
    odo_frames: tuple[str, str] | None = None
    odo_bad: list[int] = []
    imu_rows: list[tuple[float, float]] = []
    imu_bad: list[int] = []
    wheels: list[tuple[float, Any]] = []
    for topic, msgtype, index, bag_t, msg in read_topic_messages(p, sorted(wanted)):
        if msgtype == TFMESSAGE:
            tree.add(msg, static=topic.strip("/") == "tf_static")
        elif topic == plan.odom_topic and msgtype == ODOMETRY:
            pose = msg.pose.pose
            row = (ros_time_to_stamp(msg.header.stamp.sec, msg.header.stamp.nanosec),
                   float(pose.position.x), float(pose.position.y), _yaw(pose.orientation))
            if not all(math.isfinite(v) for v in row):
                odo_bad.append(index)
            odo_rows.append(row)
            if odo_frames is None:
                odo_frames = (_frame(msg.header.frame_id), _frame(msg.child_frame_id))
        elif topic == plan.wheel_topic and msgtype == ENCODER:
            wheels.append((bag_t, msg))
        elif topic == plan.imu_topic and msgtype == IMU:
            w = float(msg.angular_velocity.z)
            if not math.isfinite(w):
                imu_bad.append(index)
            imu_rows.append((ros_time_to_stamp(msg.header.stamp.sec, msg.header.stamp.nanosec), w))
    for c in tree.conflicts:
        out.warnings.append(f"TF: {c}")
    laser = _frame(laser_frame) if laser_frame else None

    # -- IMU
    if plan.imu_topic and imu_rows:
        arr = np.array(imu_rows)
        if imu_bad:
            out.warnings.append(f"IMU {plan.imu_topic}: {len(imu_bad)} non-finite yaw rates dropped "
                                f"(first at message index {imu_bad[0]})")
        try:
            out.imu = ImuTrack(arr[:, 0], arr[:, 1], source=f"{plan.imu_topic} (sensor_msgs/Imu)")
        except DynSlamError as err:
            if plan.explicit_imu:
                raise DynSlamError(f"{p}: {err}") from None
            out.warnings.append(f"IMU: {err}; no yaw rate")
    elif plan.imu_topic and plan.explicit_imu:
        raise DynSlamError(f"{p}: --imu {plan.imu_topic}: the topic holds no messages")

    # -- odometry: the first candidate that works
    failures: list[str] = []
    base_frame: str | None = None
    for kind in kinds:
        try:
            if kind == "topic":
                desc = f"{plan.odom_topic} (nav_msgs/Odometry)"
                if not odo_rows:
                    raise DynSlamError(f"{desc} holds no messages")
                arr = np.array(odo_rows)
                frames = odo_frames or ("odom", "base_link")
                track = OdometryTrack(arr[:, 0], arr[:, 1:], frames[0], frames[1], source=desc)
                if odo_bad:
                    out.warnings.append(f"odometry {plan.odom_topic}: {len(odo_bad)} messages with NaN/inf dropped "
                                        f"(first at message index {odo_bad[0]})")
                base_frame = frames[1] or "base_link"
            elif kind == "tf":
                if laser is None or laser not in tree.frames:
                    frames_s = ", ".join(sorted(tree.frames)) or "none"
                    raise DynSlamError(f"TF has no frame {laser_frame!r} (the scans' frame_id); TF frames: {frames_s}")
                found = tree.moving_edge_above(laser)
                if found is None:
                    raise DynSlamError(f"TF has no moving transform above {laser!r} (no odom → base_link)")
                parent, child, mount = found
                desc = f"tf {parent}→{child}"
                track = tree.track(parent, child, desc)
                out.mount, out.mount_source = mount, f"tf ({child}→{laser})"
                base_frame = None
            else:
                desc = f"dead reckoning: {plan.wheel_topic} (barc/Encoder) + {plan.imu_topic} yaw rate"
                if not wheels:
                    raise DynSlamError(f"{plan.wheel_topic} holds no messages")
                if out.imu is None:
                    raise DynSlamError(f"{desc}: no usable IMU yaw rate")
                model = dead_reckoning or DeadReckoning()
                track = _dead_reckon(wheels, out.imu, model, desc, p)
                desc = f"{desc} (wheel radius {model.wheel_radius:g} m)"
                base_frame = "base_link"
        except DynSlamError as err:
            if plan.explicit_odom:
                raise DynSlamError(f"{p}: {err}") from None
            failures.append(str(err))
            continue
        out.track, out.description = track, desc
        break
    if out.track is None and failures:
        out.warnings.append("odometry: " + "; ".join(failures) + "; continuing without odometry (laser only)")

    # -- the laser mount, for odometry given in a base frame
    if out.track is not None and base_frame is not None:
        chain = tree.static_chain(base_frame, laser) if laser else None
        if chain is not None:
            out.mount, out.mount_source = chain, f"tf_static ({base_frame}→{laser})"
        elif laser_offset is None:
            out.mount, out.mount_source = Pose2D(), "identity (no TF)"
            out.warnings.append(
                f"odometry: no static transform {base_frame}→{laser_frame} in TF; the laser is taken to sit at "
                f"the {base_frame} origin (give --laser-offset x,y,yaw)")
    if laser_offset is not None:
        if out.track is not None and out.mount_source.startswith("tf") and (
                math.hypot(out.mount.x - laser_offset.x, out.mount.y - laser_offset.y) > _MOUNT_DISAGREE_M):
            out.warnings.append(
                f"--laser-offset ({laser_offset.x:g}, {laser_offset.y:g}, {laser_offset.theta:g}) overrides TF "
                f"{out.mount_source} ({out.mount.x:g}, {out.mount.y:g}, {out.mount.theta:g})")
        out.mount, out.mount_source = laser_offset, "--laser-offset"
    if out.imu is not None:
        imu_desc = f"IMU {plan.imu_topic}"
        out.description = imu_desc if out.description is None else f"{out.description}; {imu_desc}"
    return out


# --------------------------------------------------------------------------- writing


def _quat(bag: Any, yaw: float) -> Any:
    return bag.msg_class("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def _vec3(bag: Any, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return bag.msg_class("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def transform_message(bag: Any, stamp: float, parent: str, child: str, pose: Pose2D, seq: int = 0) -> Any:
    """``tf2_msgs/TFMessage`` with one planar transform ``parent → child`` (child's pose in parent)."""
    transform = bag.msg_class("geometry_msgs/msg/Transform")(
        translation=_vec3(bag, pose.x, pose.y), rotation=_quat(bag, pose.theta))
    ts = bag.msg_class("geometry_msgs/msg/TransformStamped")(
        header=bag.header(stamp, parent, seq), child_frame_id=child, transform=transform)
    return bag.msg_class(TFMESSAGE)(transforms=[ts])


def odometry_message(bag: Any, stamp: float, frame: str, child: str, pose: np.ndarray,
                     twist: tuple[float, float] = (0.0, 0.0), seq: int = 0) -> Any:
    """``nav_msgs/Odometry``: ``child`` at ``pose`` (x, y, yaw) in ``frame``; twist = (v m/s, ω rad/s)."""
    point = bag.msg_class("geometry_msgs/msg/Point")(x=float(pose[0]), y=float(pose[1]), z=0.0)
    pwc = bag.msg_class("geometry_msgs/msg/PoseWithCovariance")(
        pose=bag.msg_class("geometry_msgs/msg/Pose")(position=point, orientation=_quat(bag, float(pose[2]))),
        covariance=np.zeros(36, dtype=np.float64))
    twc = bag.msg_class("geometry_msgs/msg/TwistWithCovariance")(
        twist=bag.msg_class("geometry_msgs/msg/Twist")(linear=_vec3(bag, twist[0]),
                                                       angular=_vec3(bag, 0.0, 0.0, twist[1])),
        covariance=np.zeros(36, dtype=np.float64))
    return bag.msg_class(ODOMETRY)(header=bag.header(stamp, frame, seq), child_frame_id=child, pose=pwc, twist=twc)


def imu_message(bag: Any, stamp: float, frame: str, yaw_rate: float, seq: int = 0) -> Any:
    """``sensor_msgs/Imu`` with only ``angular_velocity.z`` = ``yaw_rate`` rad/s (no orientation)."""
    no_orientation = np.zeros(9, dtype=np.float64)
    no_orientation[0] = -1.0  # REP 145 / sensor_msgs/Imu: orientation not provided
    no_accel = np.zeros(9, dtype=np.float64)
    no_accel[0] = -1.0
    return bag.msg_class(IMU)(
        header=bag.header(stamp, frame, seq),
        orientation=bag.msg_class("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=no_orientation,
        angular_velocity=_vec3(bag, 0.0, 0.0, yaw_rate),
        angular_velocity_covariance=np.zeros(9, dtype=np.float64),
        linear_acceleration=_vec3(bag),
        linear_acceleration_covariance=no_accel,
    )


def write_scan_bag_with_odometry(
    path: str | os.PathLike[str],
    scans: Iterable[Scan],
    track: OdometryTrack,
    mount: Pose2D,
    *,
    twist: np.ndarray | None = None,
    imu: ImuTrack | None = None,
    imu_frame: str = "imu_link",
    storage: str | None = None,
    topic: str = "/scan",
    odom_topic: str = "/odom",
    imu_topic: str = "/imu",
) -> Path:
    """Write scans (LaserScan on ``topic``) with ``track`` as ``/odom`` (nav_msgs/Odometry,
    ``track.frame_id`` → ``track.child_frame_id``) and ``/tf`` (the same transform), the mount
    as ``/tf_static`` (``child_frame_id`` → the scans' frame id, latched, once at the first
    stamp) and ``imu`` as ``/imu`` (sensor_msgs/Imu, yaw rate in angular_velocity.z, no
    orientation). Messages are written in stamp order; layout as :func:`open_bag_writer`.
    ``twist`` (n, 2): forward speed m/s and yaw rate rad/s per odometry sample (default 0).
    """
    scans = list(scans)
    if not scans:
        raise DynSlamError(f"{path}: no scans to write")
    laser_frame = scans[0].frame_id
    events: list[tuple[float, int, int, int]] = []  # stamp, kind order, kind, index
    events += [(float(s.stamp), 3, 0, i) for i, s in enumerate(scans)]
    events += [(float(t), 1, 1, i) for i, t in enumerate(track.stamps)]
    if imu is not None:
        events += [(float(t), 2, 2, i) for i, t in enumerate(imu.stamps)]
    events.sort()
    first = min(e[0] for e in events)
    tw = np.zeros((len(track), 2)) if twist is None else np.asarray(twist, dtype=np.float64).reshape(-1, 2)
    final = Path(path)
    with open_bag_writer(final, storage=storage) as bag:
        bag.add_topic(topic, LASERSCAN)
        bag.add_topic(odom_topic, ODOMETRY)
        bag.add_topic("/tf", TFMESSAGE)
        bag.add_topic("/tf_static", TFMESSAGE, latched=True)
        if imu is not None:
            bag.add_topic(imu_topic, IMU)
        bag.write("/tf_static", transform_message(bag, first, track.child_frame_id, laser_frame, mount, 0), first)
        for stamp, _, kind, i in events:
            if kind == 0:
                bag.write(topic, laserscan_message(bag, scans[i], seq=i), stamp)
            elif kind == 1:
                pose = track.poses[i]
                bag.write(odom_topic, odometry_message(bag, stamp, track.frame_id, track.child_frame_id, pose,
                                                        (float(tw[i, 0]), float(tw[i, 1])), i), stamp)
                bag.write("/tf", transform_message(bag, stamp, track.frame_id, track.child_frame_id,
                                             Pose2D.from_array(pose), i), stamp)
            else:
                assert imu is not None
                bag.write(imu_topic, imu_message(bag, stamp, imu_frame, float(imu.yaw_rate[i]), i), stamp)
    return final
