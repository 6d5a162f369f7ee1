"""Hand-annotated people in leg_tracker benchmark bags (``leg_tracker/Person``).

The leg_tracker benchmark bags (Leigh et al., ICRA 2015) carry, beside the laser
scans, one ``leg_tracker/Person`` message per annotated person and scan on
``/ground_truth_people_tracks``: ``geometry_msgs/Pose pose`` and ``uint32 id``,
**no header**, the position **in the scan's own frame** (m). Each annotation is
recorded halfway between the scan it annotates and the next one, so it belongs to
the last scan *recorded* before it — by bag record time, not header stamp (the
two clocks differ in these bags). docs/real.md describes the recordings.

The message type is registered from the bag's own message definition where the
bag carries one (ROS 1 bags always do); :func:`register_person_type` adds it to a
typestore for writing such bags.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Scan

PERSON_MSGTYPE = "leg_tracker/msg/Person"
#: ``leg_tracker/msg/Person.msg``.
PERSON_MSGDEF = "geometry_msgs/Pose pose\nuint32 id\n"
#: The topic the benchmark bags use.
PEOPLE_TOPIC = "/ground_truth_people_tracks"


def register_person_type(typestore: Any) -> None:
    """Add ``leg_tracker/msg/Person`` to a rosbags typestore (no-op if present)."""
    if PERSON_MSGTYPE in typestore.types:
        return
    from rosbags.typesys import get_types_from_msg

    typestore.register(get_types_from_msg(PERSON_MSGDEF, PERSON_MSGTYPE))


@dataclass(frozen=True, eq=False)
class AnnotatedScans:
    """Scans of one topic and the people annotated on them.

    Attributes:
        scans: the LaserScans in record order (``stamp`` = header stamp, s).
        record_times: (n,) bag record time of each scan, s.
        scan_index: (m,) index into ``scans`` of the scan each annotation belongs to.
        ids: (m,) person id of each annotation.
        xy: (m, 2) annotated position in that scan's laser frame, m.
        n_dropped: annotations recorded before the first scan (no scan to belong to).
        origin: the bag (and topics) read, for messages.
    """

    scans: list[Scan]
    record_times: np.ndarray
    scan_index: np.ndarray
    ids: np.ndarray
    xy: np.ndarray
    n_dropped: int
    origin: str

    @property
    def stamps(self) -> np.ndarray:
        """(n,) header stamps of the scans, s."""
        return np.array([s.stamp for s in self.scans], dtype=np.float64)


def _person_fields(msg: Any, where: str) -> tuple[int, float, float]:
    try:
        pid = int(msg.id)
        x, y = float(msg.pose.position.x), float(msg.pose.position.y)
    except (AttributeError, TypeError, ValueError) as err:
        raise DynSlamError(f"{where}: not a leg_tracker/Person (pose + id) message ({err})") from err
    if not (math.isfinite(x) and math.isfinite(y)):
        raise DynSlamError(f"{where}: position ({x}, {y}) is not finite")
    return pid, x, y


def read_people_annotations(
    path: str | os.PathLike[str],
    scan_topic: str | None = None,
    people_topic: str = PEOPLE_TOPIC,
) -> AnnotatedScans:
    """Read the scans of ``scan_topic`` and the Person annotations of ``people_topic``.

    ``path`` is a bag (or a zip holding one bag). ``scan_topic`` may be omitted when
    the bag has one LaserScan topic.

    Raises:
        DynSlamError: unreadable bag; no / ambiguous LaserScan topic; ``people_topic``
            missing or not ``leg_tracker/Person``; a malformed Person message (named
            by its index); no annotation at all.
    """
    from dynslam2d.io.rosbag import (
        RosbagSource,
        _describe,
        _open_bag,
        _resolve_topic,
        _scan_from_msg,
        _topic_types,
    )
    from dynslam2d.io.zipbag import bag_file

    with bag_file(path) as bag:
        topic = RosbagSource(bag, topic=scan_topic).topic
        with _open_bag(Path(bag)) as (reader, _):
            topics = _topic_types(reader)
            name = _resolve_topic(people_topic, topics)
            if name is None:
                raise DynSlamError(
                    f"{bag}: no {people_topic} topic ({PERSON_MSGTYPE} annotations); "
                    f"the bag has: {_describe(topics)}"
                )
            if topics[name] != PERSON_MSGTYPE:
                raise DynSlamError(
                    f"{bag}: topic {name} is {topics[name]}, not {PERSON_MSGTYPE} (pose + id, no header)"
                )
            conns = list(reader.topics[topic].connections) + list(reader.topics[name].connections)
            scans: list[Scan] = []
            record: list[float] = []
            scan_index: list[int] = []
            ids: list[int] = []
            xy: list[tuple[float, float]] = []
            dropped = 0
            scan_conns = {c.id for c in reader.topics[topic].connections}
            counts = {topic: 0, name: 0}
            for conn, t_ns, raw in reader.messages(connections=conns):
                which = topic if conn.id in scan_conns else name
                index = counts[which]
                counts[which] += 1
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as err:
                    raise DynSlamError(
                        f"{bag}: cannot read message index {index} of topic {which} "
                        f"({type(err).__name__}: {err}); the bag looks corrupt or truncated"
                    ) from err
                if which == topic:
                    scans.append(_scan_from_msg(msg, Path(bag), topic, index))
                    record.append(t_ns * 1e-9)
                    continue
                pid, x, y = _person_fields(msg, f"{bag}: topic {name}, message index {index}")
                if not scans:
                    dropped += 1
                    continue
                scan_index.append(len(scans) - 1)
                ids.append(pid)
                xy.append((x, y))
    if not ids:
        raise DynSlamError(f"{path}: topic {people_topic} holds no annotation after the first scan of {topic}")
    return AnnotatedScans(
        scans=scans,
        record_times=np.asarray(record, dtype=np.float64),
        scan_index=np.asarray(scan_index, dtype=np.int64),
        ids=np.asarray(ids, dtype=np.int64),
        xy=np.asarray(xy, dtype=np.float64).reshape(-1, 2),
        n_dropped=dropped,
        origin=f"{path} ({topic}, {name})",
    )


__all__ = ["PEOPLE_TOPIC", "PERSON_MSGDEF", "PERSON_MSGTYPE", "AnnotatedScans", "read_people_annotations",
           "register_person_type"]
