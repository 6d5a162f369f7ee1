"""Reference trajectories from what users have: TUM files or pose topics in bags.

A motion-capture or odometry topic gives the pose of a body frame; SLAM estimates
the laser pose. ``sensor_offset`` (the laser's pose in the body frame, m and rad)
bridges the two: laser = body ⊕ offset. For the datmo bags the laser sits at
(−0.12, 0, 0) in the ``/ego_pose`` frame.
"""

from __future__ import annotations

import os

import numpy as np

from dynslam2d.io.sources import sniff_format
from dynslam2d.io.trajectory import Trajectory, read_tum
from dynslam2d.types import Pose2D, wrap_angle


def pose_topic_trajectory(
    path: str | os.PathLike[str], topic: str, sensor_offset: Pose2D = Pose2D()
) -> Trajectory:
    """The sensor trajectory implied by a pose topic: body pose ⊕ ``sensor_offset`` per message."""
    from dynslam2d.io.rosbag import read_pose_topic

    track = read_pose_topic(path, topic)
    c, s = np.cos(track.yaw), np.sin(track.yaw)
    ox, oy, oth = sensor_offset.x, sensor_offset.y, sensor_offset.theta
    poses = np.column_stack(
        (track.xy[:, 0] + c * ox - s * oy, track.xy[:, 1] + s * ox + c * oy, wrap_angle(track.yaw + oth))
    )
    order = np.argsort(track.stamps, kind="stable")
    return Trajectory(stamps=track.stamps[order], poses=poses[order], frame=track.frame_id or "map")


def load_reference(
    path: str | os.PathLike[str], topic: str | None = None, sensor_offset: Pose2D = Pose2D()
) -> Trajectory:
    """A reference trajectory from a TUM file, or from ``topic`` of a bag (ROS 1/2, MCAP)."""
    from dynslam2d.errors import DynSlamError

    p = os.fspath(path)
    if os.path.isfile(p) and not p.endswith((".bag", ".mcap", ".db3")):
        try:
            fmt = sniff_format(p)
        except DynSlamError:
            fmt = "text"
        if fmt not in ("ros1-bag", "mcap", "ros2-bag"):
            return read_tum(p)
    if topic is None:
        raise DynSlamError(f"{p}: a bag as reference needs --ref-topic (e.g. /ego_pose)")
    return pose_topic_trajectory(p, topic, sensor_offset)
