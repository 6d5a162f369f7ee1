"""A bag with several LaserScan topics, described in one pass (``dynslam2d info BAG`` without ``--topic``).

``dynslam2d run`` maps one LaserScan topic and needs ``--topic`` when a bag holds several; ``info``
then describes every one of them so the user can choose: :func:`describe_bag` reads the scans of all
LaserScan topics in a single pass over the bag (:func:`~dynslam2d.io.rosbag.read_scan_topics`) and
keeps one :class:`~dynslam2d.io.summary.SummaryAccumulator` per topic, so the figures per topic are
the ones ``info --topic T`` prints. The other topics are listed with their role (odometry, TF, IMU,
poses, wheel speeds) and what ``--odom auto`` / ``--imu auto`` would try
(:func:`~dynslam2d.io.odombag.odometry_candidates`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

from dynslam2d.io.rosbag import LASERSCAN, POSE_MSGTYPES, read_scan_topics, topic_counts
from dynslam2d.io.summary import SourceSummary, SummaryAccumulator
from dynslam2d.types import Scan, SourceMeta

__all__ = ["BagOverview", "describe_bag", "laserscan_topics", "topic_role"]

#: Message types named by :func:`topic_role` (ROS 2 spelling, as rosbags gives them).
_ROLES = {
    "nav_msgs/msg/Odometry": "odometry",
    "tf2_msgs/msg/TFMessage": "TF",
    "sensor_msgs/msg/Imu": "IMU",
    "barc/msg/Encoder": "wheel speeds",
    LASERSCAN: "laser scans",
}


def topic_role(topic: str, msgtype: str) -> str:
    """What a topic is to the pipeline: "laser scans", "odometry", "TF" (``/tf_static``: "static TF"),
    "IMU", "wheel speeds", "poses" (a reference trajectory for ``eval``), or "" for anything else."""
    role = _ROLES.get(msgtype, "poses" if msgtype in POSE_MSGTYPES else "")
    return "static TF" if role == "TF" and topic.strip("/") == "tf_static" else role


def laserscan_topics(path: str | os.PathLike[str]) -> list[str]:
    """The LaserScan topics of a bag (ROS 1, ROS 2 folder, MCAP, db3, or a zip holding one), sorted."""
    from dynslam2d.io.zipbag import bag_file

    with bag_file(path) as bag:
        return [t for t, (m, _) in topic_counts(bag).items() if m == LASERSCAN]


@dataclass(slots=True)
class BagOverview:
    """Every topic of a bag and a :class:`SourceSummary` of each LaserScan topic.

    Attributes:
        format: "ros1-bag", "ros2-bag", "mcap" or "zip".
        origin: the path described.
        topics: every topic → (message type, message count from the bag's index).
        scans: LaserScan topic → its summary (stamps in s, angles in rad, ranges in m), in topic order.
            ``extra["skipped_scans"]``: scans whose stamp did not increase (dropped here; ``run`` stops at
            the first unless ``--skip-bad``); ``extra["skipped_messages"]``: undecodable messages passed
            over (``--skip-bad`` only).
        odometry: what ``--odom`` / ``--imu`` would try (:func:`~dynslam2d.io.odombag.odometry_candidates`).
        first_scans: LaserScan topic → its first ``keep_first`` scans (for the robot-body search);
            left out of :meth:`as_dict`.
    """

    format: str
    origin: str
    topics: dict[str, tuple[str, int]]
    scans: dict[str, SourceSummary]
    odometry: dict[str, object]
    first_scans: dict[str, list[Scan]] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: ``topics`` as {name: {type, messages, role}}, ``scans`` as {name: summary dict}."""
        return {
            "format": self.format,
            "origin": self.origin,
            "topics": {t: {"type": m, "messages": n, "role": topic_role(t, m)} for t, (m, n) in self.topics.items()},
            "scans": {t: s.as_dict() for t, s in self.scans.items()},
            "odometry": self.odometry,
        }


def describe_bag(
    path: str | os.PathLike[str],
    *,
    keep_first: int = 0,
    skip_bad: bool = False,
    odom: str = "auto",
    imu: str = "auto",
    progress: Callable[[int], None] | None = None,
) -> BagOverview:
    """Read every LaserScan topic of a bag once and summarise each (module docstring).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, a bare ``.mcap`` / ``.db3``, or a ``.zip`` holding one.
        keep_first: keep each topic's first scans, at most this many (:attr:`BagOverview.first_scans`).
        skip_bad: pass over undecodable messages (counted per topic) instead of raising.
        odom, imu: the ``--odom`` / ``--imu`` modes whose candidates are reported.
        progress: called with the number of scans read so far (all topics), every 100 scans.
    Raises:
        DynSlamError: unreadable or corrupt bag, a message that is no valid LaserScan (without
            ``skip_bad``), or an explicitly named ``odom`` / ``imu`` topic the bag lacks.
    """
    from dynslam2d.io.odombag import odometry_candidates
    from dynslam2d.io.sources import sniff_format
    from dynslam2d.io.zipbag import bag_file

    fmt = sniff_format(path)
    origin = os.fspath(path)
    with bag_file(path) as bag:
        inner_fmt = sniff_format(bag)
        topics = topic_counts(bag)
        names = [t for t, (m, _) in topics.items() if m == LASERSCAN]
        odometry = odometry_candidates(bag, {t: m for t, (m, _) in topics.items()}, odom, imu)
        acc = {t: SummaryAccumulator() for t in names}
        extra: dict[str, dict[str, object]] = {t: {} for t in names}
        first: dict[str, list[Scan]] = {t: [] for t in names}

        def bad(topic: str, index: int) -> None:
            count = extra[topic]
            count["skipped_messages"] = int(count.get("skipped_messages", 0)) + 1  # type: ignore[call-overload]

        total = 0
        for topic, _, scan in read_scan_topics(bag, names, on_bad=bad if skip_bad else None):
            a = acc[topic]
            if a.n and not scan.stamp > a.last:  # what CheckedSource refuses without --skip-bad
                extra[topic]["skipped_scans"] = int(extra[topic].get("skipped_scans", 0)) + 1  # type: ignore[call-overload]
                continue
            a.add(scan)
            if len(first[topic]) < keep_first:
                first[topic].append(scan)
            total += 1
            if progress is not None and total % 100 == 0:
                progress(total)
    if progress is not None:
        progress(total)
    summaries = {
        t: acc[t].result(SourceMeta(format=inner_fmt, origin=origin, topic=t, count=topics[t][1], extra=extra[t]))
        for t in names
    }
    return BagOverview(format=fmt, origin=origin, topics=topics, scans=summaries, odometry=odometry,
                       first_scans=first)

