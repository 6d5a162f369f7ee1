"""Record a run as a ROS bag that RViz and Foxglove replay (issue 6, "ROS outputs without ROS").

:class:`BagRecorder` is a :class:`~dynslam2d.pipeline.RunObserver`: hand it to
:func:`dynslam2d.pipeline.run` and it writes, for every scan, in the bag's time
order and with the scan's own stamp as header stamp and bag time:

============== ================================ =============================================
topic          type                             content
============== ================================ =============================================
/scan          sensor_msgs/LaserScan            the input scan, unchanged (laser frame)
/scan_filtered sensor_msgs/LaserScan            the same scan with every beam the filter
                                                removed set to +inf ("no return", REP 117)
/slam_pose     geometry_msgs/PoseStamped        the laser pose, frame ``map``
/tf            tf2_msgs/TFMessage               ``map`` → the scan's frame id (the laser)
/tracks        visualization_msgs/MarkerArray   per live track: an oriented box (LINE_STRIP),
                                                its id (TEXT_VIEW_FACING), its velocity
                                                (ARROW); DELETE markers once a track is gone
/map           nav_msgs/OccupancyGrid           the finest map level every ``map_period`` s
                                                of scan time and once at the end (latched)
============== ================================ =============================================

Frames follow REP 105 loosely: SLAM here has no odometry, so ``map`` → laser is
published directly (a pose is the laser's pose in the map frame, docs/architecture.md).
``/map`` follows map_server: ``data`` row-major from cell (0, 0) at
``info.origin`` (the lower-left corner of the map, identity orientation), rows
going +y, values −1 unknown and ``round(100·p)`` for occupancy probability p.

Markers keep their namespace and id per track (namespaces ``boxes``, ``ids``,
``velocity``; marker id = track id), so a viewer updates them in place; a track
that disappears gets one DELETE per namespace at the first scan without it.
Colour: red for tracks in the dynamic set M, blue otherwise; tentative tracks
half transparent.

The bag is written through :func:`~dynslam2d.io.rosbag.open_bag_writer`, so it
appears at its path only when complete: use the recorder as a context manager
around :func:`run` so that a failed run leaves nothing behind (see
:class:`BagRecorder`).
"""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io.rosbag import LASERSCAN, BagWriter, laserscan_message, open_bag_writer
from dynslam2d.types import Pose2D, Scan, Track

if TYPE_CHECKING:
    from dynslam2d.pipeline import Pipeline, RunResult, StepResult

__all__ = [
    "BagRecorder",
    "MARKER_NAMESPACES",
    "TOPICS",
    "filtered_scan",
    "occupancy_data",
    "occupancy_grid_message",
    "pose_stamped_message",
    "tf_message",
    "track_markers_message",
]

#: Topic → message type of everything :class:`BagRecorder` writes.
TOPICS: dict[str, str] = {
    "/scan": LASERSCAN,
    "/scan_filtered": LASERSCAN,
    "/map": "nav_msgs/msg/OccupancyGrid",
    "/slam_pose": "geometry_msgs/msg/PoseStamped",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tracks": "visualization_msgs/msg/MarkerArray",
}

#: Marker namespaces, one marker per track in each (marker id = track id).
MARKER_NAMESPACES = ("boxes", "ids", "velocity")

# visualization_msgs/Marker constants (same values in ROS 1 and ROS 2).
_ARROW, _LINE_STRIP, _TEXT = 0, 4, 9
_ADD, _DELETE = 0, 2

_RED = (0.9, 0.15, 0.1)  # in M
_BLUE = (0.1, 0.45, 0.9)  # not in M


# --------------------------------------------------------------------------- message helpers


def _blank(bag: BagWriter, msgtype: str) -> Any:
    """A message of ``msgtype`` with every field zero / empty (quaternions: identity)."""
    return bag.msg_class(msgtype)(**_blank_fields(bag, msgtype))


def _blank_fields(bag: BagWriter, msgtype: str) -> dict[str, Any]:
    """Keyword arguments for a zero / empty ``msgtype`` message (fresh objects).

    Built from the bag's typestore field definitions, so fields that differ between
    ROS 1 and ROS 2 (e.g. Marker.texture, Header.seq) are filled without naming them.
    """
    from rosbags.interfaces import Nodetype

    bag.msg_class(msgtype)
    fielddefs = bag.typestore.fielddefs[msgtype][1]
    kwargs: dict[str, Any] = {}
    for name, (kind, spec) in fielddefs:
        if kind == Nodetype.BASE:
            base = spec[0]
            kwargs[name] = "" if base == "string" else (False if base == "bool" else 0)
        elif kind == Nodetype.NAME:
            kwargs[name] = _blank(bag, spec)
        else:  # ARRAY / SEQUENCE
            (sub_kind, sub_spec), length = spec
            n = length if kind == Nodetype.ARRAY else 0
            if sub_kind == Nodetype.BASE and sub_spec[0] != "string":
                kwargs[name] = np.zeros(n, dtype=_NUMPY[sub_spec[0]])
            elif sub_kind == Nodetype.BASE:
                kwargs[name] = [""] * n
            else:
                kwargs[name] = [_blank(bag, sub_spec) for _ in range(n)]
    if msgtype == "geometry_msgs/msg/Quaternion":
        kwargs["w"] = 1.0
    return kwargs


_NUMPY = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
    "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
    "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64,
}


def _quaternion(bag: BagWriter, yaw: float) -> Any:
    """Rotation about +z by ``yaw`` rad as ``geometry_msgs/Quaternion``."""
    return bag.msg_class("geometry_msgs/msg/Quaternion")(
        x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw)
    )


def _point(bag: BagWriter, x: float, y: float, z: float = 0.0) -> Any:
    return bag.msg_class("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=float(z))


def _pose(bag: BagWriter, pose: Pose2D) -> Any:
    return bag.msg_class("geometry_msgs/msg/Pose")(
        position=_point(bag, pose.x, pose.y), orientation=_quaternion(bag, pose.theta)
    )


def filtered_scan(scan: Scan, removed: np.ndarray) -> Scan:
    """``scan`` with the ``removed`` beams set to +inf ("no return", REP 117); others unchanged."""
    removed = np.asarray(removed, dtype=bool)
    if removed.shape != scan.ranges.shape:
        raise ValueError(f"removed mask has {removed.shape[0]} beams, the scan {scan.ranges.shape[0]}")
    if not removed.any():
        return scan
    return scan.with_ranges(np.where(removed, np.inf, scan.ranges))


def occupancy_data(grid: GridMap) -> np.ndarray:
    """(H·W,) int8 ``OccupancyGrid.data``: −1 unknown (NaN), else ``round(100·p)`` in 0 … 100.

    Row-major from cell (0, 0), rows going +y: the order of ``GridMap.prob`` (row 0 at the
    bottom) and of ROS map_server's ``/map``.
    """
    prob = np.asarray(grid.prob, dtype=np.float64)
    known = np.isfinite(prob)
    out = np.full(prob.shape, -1, dtype=np.int8)
    out[known] = np.clip(np.rint(100.0 * prob[known]), 0, 100).astype(np.int8)
    return out.reshape(-1)


def occupancy_grid_message(bag: BagWriter, grid: GridMap, stamp: float, frame_id: str = "map",
                           seq: int = 0) -> Any:
    """``nav_msgs/OccupancyGrid`` of ``grid`` (origin = pose of the lower-left corner of cell (0, 0))."""
    h, w = grid.shape
    info = bag.msg_class("nav_msgs/msg/MapMetaData")(
        map_load_time=bag.time(stamp),
        resolution=float(grid.resolution),
        width=int(w),
        height=int(h),
        origin=_pose(bag, Pose2D(grid.origin[0], grid.origin[1], 0.0)),
    )
    return bag.msg_class("nav_msgs/msg/OccupancyGrid")(
        header=bag.header(stamp, frame_id, seq), info=info, data=occupancy_data(grid)
    )


def pose_stamped_message(bag: BagWriter, pose: Pose2D, stamp: float, frame_id: str = "map",
                         seq: int = 0) -> Any:
    """``geometry_msgs/PoseStamped`` of a planar pose (z = 0, rotation about +z)."""
    return bag.msg_class("geometry_msgs/msg/PoseStamped")(
        header=bag.header(stamp, frame_id, seq), pose=_pose(bag, pose)
    )


def tf_message(bag: BagWriter, pose: Pose2D, stamp: float, parent: str, child: str) -> Any:
    """``tf2_msgs/TFMessage`` holding one transform ``parent`` → ``child`` = ``pose``.

    (The pose of the child frame's origin in the parent frame, as tf defines it.)
    """
    vec = bag.msg_class("geometry_msgs/msg/Vector3")(x=float(pose.x), y=float(pose.y), z=0.0)
    transform = bag.msg_class("geometry_msgs/msg/Transform")(
        translation=vec, rotation=_quaternion(bag, pose.theta)
    )
    ts = bag.msg_class("geometry_msgs/msg/TransformStamped")(
        header=bag.header(stamp, parent), child_frame_id=child, transform=transform
    )
    return bag.msg_class("tf2_msgs/msg/TFMessage")(transforms=[ts])


def _marker(bag: BagWriter, base: dict[str, Any], header: Any, ns: str, mid: int, mtype: int,
            action: int) -> Any:
    """A Marker from ``base`` (fields of :func:`_blank_fields`; the fields this module sets are
    made fresh, the others — lifetime, texture, mesh … — are shared, read-only, between markers)."""
    return bag.msg_class("visualization_msgs/msg/Marker")(**{
        **base,
        "header": header, "ns": ns, "id": int(mid), "type": mtype, "action": action,
        "pose": _pose(bag, Pose2D()), "scale": bag.msg_class("geometry_msgs/msg/Vector3")(x=0.0, y=0.0, z=0.0),
        "color": _color(bag, (0.0, 0.0, 0.0), 0.0), "points": [], "text": "",
    })


def _color(bag: BagWriter, rgb: tuple[float, float, float], alpha: float) -> Any:
    return bag.msg_class("std_msgs/msg/ColorRGBA")(r=rgb[0], g=rgb[1], b=rgb[2], a=alpha)


def track_markers_message(bag: BagWriter, tracks: list[Track], gone: list[int], stamp: float,
                          frame_id: str = "map", arrow_time: float = 1.0) -> Any:
    """``visualization_msgs/MarkerArray`` for one scan.

    Per track in ``tracks`` (map frame), in namespaces :data:`MARKER_NAMESPACES` with
    marker id = track id, action ADD:

    * ``boxes``: LINE_STRIP through the box corners, closed (5 points, z = 0), width 0.05 m;
    * ``ids``: TEXT_VIEW_FACING with the track id, 0.4 m high, at the box centre, z = 0.5 m;
    * ``velocity``: ARROW from the centre to ``centre + velocity·arrow_time`` (m, z = 0).

    Then, per id in ``gone``, one DELETE in each namespace. Lifetime 0 (until deleted).
    """
    header = bag.header(stamp, frame_id)
    base = _blank_fields(bag, "visualization_msgs/msg/Marker")
    markers: list[Any] = []
    vec3 = bag.msg_class("geometry_msgs/msg/Vector3")
    for t in tracks:
        rgb = _RED if t.in_m else _BLUE
        alpha = 0.5 if t.state == "tentative" else 1.0
        color = _color(bag, rgb, alpha)
        box = _marker(bag, base, header, "boxes", t.id, _LINE_STRIP, _ADD)
        corners = t.box.corners()
        box.points = [_point(bag, x, y) for x, y in np.vstack([corners, corners[:1]])]
        box.scale = vec3(x=0.05, y=0.0, z=0.0)
        box.color = color
        label = _marker(bag, base, header, "ids", t.id, _TEXT, _ADD)
        label.pose = _pose(bag, Pose2D(t.box.px, t.box.py, 0.0))
        label.pose.position.z = 0.5
        label.scale = vec3(x=0.0, y=0.0, z=0.4)
        label.color = color
        label.text = str(t.id)
        arrow = _marker(bag, base, header, "velocity", t.id, _ARROW, _ADD)
        vx, vy = float(t.velocity[0]), float(t.velocity[1])
        arrow.points = [_point(bag, t.box.px, t.box.py),
                        _point(bag, t.box.px + vx * arrow_time, t.box.py + vy * arrow_time)]
        arrow.scale = vec3(x=0.05, y=0.12, z=0.12)  # shaft diameter, head diameter, head length
        arrow.color = color
        markers.extend((box, label, arrow))
    for tid in gone:
        for ns in MARKER_NAMESPACES:
            markers.append(_marker(bag, base, header, ns, tid, _ARROW, _DELETE))
    return bag.msg_class("visualization_msgs/msg/MarkerArray")(markers=markers)


# --------------------------------------------------------------------------- the observer


class BagRecorder:
    """Writes a run into a ROS bag, scan by scan (a :class:`~dynslam2d.pipeline.RunObserver`).

    Args:
        path: output. ``*.bag`` → ROS 1 bag; ``*.mcap`` / ``*.db3`` → one bare ROS 2
            storage file; anything else → a ROS 2 bag folder (``metadata.yaml`` + storage),
            MCAP unless ``storage="sqlite3"`` (the rules of
            :func:`~dynslam2d.io.rosbag.write_scan_bag`). An existing ``path`` is replaced.
        storage: "mcap" or "sqlite3" for ROS 2 output, None = from the path (default MCAP).
        map_period: write ``/map`` whenever this much scan time (s) passed since the last
            one (the first at the first scan with a non-empty map); 0 = every scan; None =
            only at the end. The final map (``RunResult.grid``) is always written at the end,
            stamped with the last scan's stamp.
        map_frame: the fixed frame of ``/map``, ``/slam_pose``, ``/tracks`` and the parent of
            ``/tf``.
        arrow_time: velocity arrows are ``velocity · arrow_time`` long, s.

    Use it as a context manager around :func:`~dynslam2d.pipeline.run`::

        with BagRecorder("out.mcap") as rec:
            result = run(source, config, observers=[rec])

    ``on_finish`` completes the bag (it appears at ``path`` then); leaving the ``with``
    block by an exception first discards it, so nothing is left at ``path``. The bag is
    created at construction (a bad path or storage raises :class:`DynSlamError` at once).

    Attributes:
        counts: messages written per topic so far.
    """

    def __init__(self, path: str | os.PathLike[str], storage: str | None = None,
                 map_period: float | None = 1.0, *, map_frame: str = "map",
                 arrow_time: float = 1.0) -> None:
        if map_period is not None and not (math.isfinite(map_period) and map_period >= 0):
            raise DynSlamError(f"{path}: map period must be a number of seconds >= 0, got {map_period}")
        self.path = Path(path)
        self.map_period = map_period
        self.map_frame = map_frame
        self.arrow_time = float(arrow_time)
        self._stack = contextlib.ExitStack()
        self._bag: BagWriter = self._stack.enter_context(open_bag_writer(self.path, storage=storage))
        self._closed = False
        for topic, msgtype in TOPICS.items():
            self._bag.add_topic(topic, msgtype, latched=topic == "/map")
        self._live_ids: set[int] = set()
        self._last_map_stamp: float | None = None
        self._last_map_index: int | None = None
        self._last_stamp: float | None = None
        self._last_index = -1

    @property
    def counts(self) -> dict[str, int]:
        return dict(self._bag.counts)

    # ---- RunObserver
    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None:
        """Write /scan, /scan_filtered, /tf, /slam_pose, /tracks (and /map when due) for one scan."""
        self._check_open()
        bag, stamp, index = self._bag, scan.stamp, step.index
        laser = scan.frame_id or "laser"
        try:
            bag.write("/scan", laserscan_message(bag, scan, seq=index), stamp)
            bag.write("/scan_filtered", laserscan_message(bag, filtered_scan(scan, step.removed), seq=index),
                      stamp)
            bag.write("/tf", tf_message(bag, step.pose, stamp, self.map_frame, laser), stamp)
            bag.write("/slam_pose", pose_stamped_message(bag, step.pose, stamp, self.map_frame, index), stamp)
            ids = {t.id for t in step.tracks}
            gone = sorted(self._live_ids - ids)
            bag.write("/tracks", track_markers_message(bag, step.tracks, gone, stamp, self.map_frame,
                                                       self.arrow_time), stamp)
            self._live_ids = ids
        except (ValueError, OverflowError) as err:
            raise DynSlamError(f"{self.path}: scan {index} (stamp {stamp}): {err}") from err
        self._last_stamp, self._last_index = stamp, index
        if self.map_period is not None and (
            self._last_map_stamp is None or stamp - self._last_map_stamp >= self.map_period
        ):
            grid = pipeline.gridmap()
            if grid.prob.size:
                self._write_map(grid, stamp, index)

    def on_finish(self, result: RunResult, pipeline: Pipeline) -> None:
        """Write the final map (unless it was just written for the last scan) and complete the bag."""
        self._check_open()
        if (self._last_stamp is not None and self._last_map_index != self._last_index
                and result.grid.prob.size):
            self._write_map(result.grid, self._last_stamp, self._last_index)
        self.close()

    # ---- lifetime
    def close(self) -> Path:
        """Complete the bag (idempotent); it appears at :attr:`path`. Returns the path."""
        if not self._closed:
            self._closed = True
            self._stack.close()
        return self.path

    def abort(self) -> None:
        """Discard the bag (idempotent after close): nothing is left at :attr:`path`."""
        if not self._closed:
            self._closed = True
            with contextlib.suppress(_Abort):
                self._stack.__exit__(_Abort, _Abort(), None)

    def __enter__(self) -> BagRecorder:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def _check_open(self) -> None:
        if self._closed:
            raise DynSlamError(f"{self.path}: bag already closed")

    def _write_map(self, grid: GridMap, stamp: float, index: int) -> None:
        self._bag.write("/map", occupancy_grid_message(self._bag, grid, stamp, self.map_frame, index), stamp)
        self._last_map_stamp, self._last_map_index = stamp, index


class _Abort(Exception):
    """Thrown into the bag writer's context to make it discard the bag."""
