"""ROS bags: read ``sensor_msgs/LaserScan`` (and ground-truth poses), write scan bags.

Reading and writing go through the pure-Python ``rosbags`` library (>= 0.11, no ROS
install needed; https://gitlab.com/ternaris/rosbags). Supported inputs:

* ROS 1 ``.bag`` files (format ``"ros1-bag"``);
* ROS 2 bag folders (``metadata.yaml`` + sqlite3 ``.db3`` or ``.mcap`` storage,
  format ``"ros2-bag"``), and a bare ``.db3`` file (``"ros2-bag"``);
* a bare ``.mcap`` file, no ``metadata.yaml`` needed (format ``"mcap"``). rosbags
  0.11 reads a standalone ``.mcap``/``.db3`` directly: MCAP carries its schemas and
  message counts in its own summary section, and rosbags' sqlite3 files carry the
  message definitions in their tables.

The kind of a file is decided by its first bytes, not its name, so a ROS 1 bag
called ``run.log`` still reads. Every failure (missing path, corrupt or truncated
bag, a message that contradicts itself) raises :class:`DynSlamError` naming the
file, and for message-level problems the topic and the 0-based message index.

Time: a ROS time ``(sec, nanosec)`` becomes the float ``sec + nanosec·1e-9`` s
(:func:`ros_time_to_stamp`); :func:`stamp_to_ros_time` is its inverse, exact for
every stamp that came from a ROS time (so read → write → read keeps stamps
bit-identical). Stamps are quantised to 1 ns on writing.

LaserScan stores its scalar fields and ranges as float32: a :class:`Scan` read
from a bag round-trips exactly; any other Scan is rounded to float32 on writing
(ranges beyond the float32 range become ±inf).
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.atomic import atomic_path
from dynslam2d.io.rosraw import RawLaserScan, is_ros1_laserscan, laserscan_ros1
from dynslam2d.types import Pose2D, Scan, SourceMeta

__all__ = [
    "LASERSCAN",
    "POSE_MSGTYPES",
    "BagWriter",
    "PoseTrack",
    "RosbagSource",
    "laserscan_message",
    "list_topics",
    "open_bag_writer",
    "read_pose_topic",
    "read_scan_topics",
    "read_topic_messages",
    "ros_time_to_stamp",
    "stamp_to_ros_time",
    "topic_counts",
    "write_scan_bag",
]

#: The LaserScan type name as rosbags spells it (ROS 1 names are normalised to ROS 2 style).
LASERSCAN = "sensor_msgs/msg/LaserScan"

#: Message types :func:`read_pose_topic` understands.
POSE_MSGTYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/TransformStamped",
)

_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"

#: Storage plugins the writer offers for ROS 2 output.
_STORAGES = ("mcap", "sqlite3")
_STORAGE_SUFFIX = {"mcap": ".mcap", "sqlite3": ".db3"}
_ROSBAG2_VERSION = 9  # newest metadata version rosbags writes (ROS 2 Jazzy and later)


# --------------------------------------------------------------------------- time


def ros_time_to_stamp(sec: int, nanosec: int) -> float:
    """ROS time (s, ns) → float seconds ``sec + nanosec·1e-9``."""
    return int(sec) + int(nanosec) * 1e-9


def stamp_to_ros_time(stamp: float) -> tuple[int, int]:
    """Float seconds → ROS time ``(sec, nanosec)`` with ``0 <= nanosec < 1e9``.

    Rounds to the nearest nanosecond; ``ros_time_to_stamp(*stamp_to_ros_time(t)) == t``
    holds exactly for every ``t`` produced by :func:`ros_time_to_stamp`.
    """
    if not math.isfinite(stamp):
        raise ValueError(f"stamp {stamp} is not finite")
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)  # stamp - sec is exact (both in one binade)
    if nanosec >= 1_000_000_000:
        sec += 1
        nanosec -= 1_000_000_000
    return int(sec), int(nanosec)


def _stamp_ns(stamp: float) -> int:
    sec, nsec = stamp_to_ros_time(stamp)
    return sec * 1_000_000_000 + nsec


# --------------------------------------------------------------------------- opening


@dataclass(frozen=True, slots=True)
class _BagInput:
    """What a path holds: the ``SourceMeta.format`` name, the ROS 2 storage, the path to open."""

    format: str  # "ros1-bag" | "ros2-bag" | "mcap"
    storage: str | None  # "mcap" | "sqlite3" | None (ROS 1)
    path: Path  # file or folder handed to rosbags
    kind: str  # "ros1" | "ros2-dir" | "mcap-file" | "sqlite3-file"


def _head(path: Path, n: int = 16) -> bytes:
    try:
        with path.open("rb") as fh:
            return fh.read(n)
    except OSError as err:
        raise DynSlamError(f"{path}: cannot read ({err.strerror or err})") from err


def _classify(path: Path) -> _BagInput:
    """Decide what ``path`` is by its content; raise DynSlamError if it is no bag."""
    if not path.exists():
        raise DynSlamError(f"{path}: no such file or folder")
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            has_mcap = any(path.glob("*.mcap*"))
            return _BagInput("ros2-bag", "mcap" if has_mcap else "sqlite3", path, "ros2-dir")
        storage_files = sorted([*path.glob("*.mcap"), *path.glob("*.db3")])
        if len(storage_files) == 1:
            # A bag folder that lost its metadata.yaml: its one storage file still reads.
            return _classify(storage_files[0])
        raise DynSlamError(
            f"{path}: folder is not a ROS 2 bag (no metadata.yaml"
            + (f", and {len(storage_files)} storage files)" if storage_files else ")")
        )
    head = _head(path)
    if not head:
        raise DynSlamError(f"{path}: file is empty")
    if head.startswith(_ROS1_MAGIC):
        return _BagInput("ros1-bag", None, path, "ros1")
    if head.startswith(_MCAP_MAGIC):
        return _BagInput("mcap", "mcap", path, "mcap-file")
    if head.startswith(_SQLITE_MAGIC):
        return _BagInput("ros2-bag", "sqlite3", path, "sqlite3-file")
    raise DynSlamError(
        f"{path}: not a ROS bag (expected a ROS 1 .bag, a ROS 2 bag folder, an .mcap or a .db3 file)"
    )


def _make_reader(inp: _BagInput, scratch: Path) -> Any:
    """An unopened ``rosbags.highlevel.AnyReader`` for ``inp``.

    AnyReader picks ROS 1 vs ROS 2 and the ROS 2 storage plugin from the file name's
    suffix. When the suffix disagrees with the content (``run.log`` holding a ROS 1 bag),
    the reader opens a symlink with the right suffix, created in ``scratch``.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    # Old ROS 2 bags carry no message definitions; LaserScan/poses are the same in every distro.
    default = None if inp.kind == "ros1" else get_typestore(Stores.ROS2_HUMBLE)
    path = inp.path
    expected = {"ros1": ".bag", "mcap-file": ".mcap", "sqlite3-file": ".db3"}.get(inp.kind)
    if inp.kind == "ros2-dir":
        if path.suffix == ".bag":  # a bag folder named *.bag would be taken for ROS 1
            link = scratch / "bag"
            link.symlink_to(path.resolve(), target_is_directory=True)
            path = link
    elif path.suffix != expected:
        link = scratch / f"bag{expected}"
        link.symlink_to(path.resolve())
        path = link
    return AnyReader([path], default_typestore=default)


@contextlib.contextmanager
def _open_bag(path: Path) -> Iterator[tuple[Any, _BagInput]]:
    """Open a bag for reading; every rosbags failure becomes a DynSlamError naming ``path``."""
    inp = _classify(path)
    with tempfile.TemporaryDirectory(prefix="dynslam2d-bag-") as scratch:
        try:
            reader = _make_reader(inp, Path(scratch))
            reader.open()
        except DynSlamError:
            raise
        except Exception as err:  # rosbags raises many types (ReaderError, struct.error, apsw, …)
            hint = "; if it was cut short, 'rosbag reindex' may repair it" if inp.kind == "ros1" else ""
            raise DynSlamError(f"{path}: cannot open {inp.format} ({type(err).__name__}: {_short(err)}){hint}") from err
        try:
            yield reader, inp
        finally:
            with contextlib.suppress(Exception):
                reader.close()


def _topic_types(reader: Any) -> dict[str, str]:
    return {name: (info.msgtype or "?") for name, info in sorted(reader.topics.items())}


def _resolve_topic(requested: str, available: dict[str, str]) -> str | None:
    """Match a topic name, tolerating a missing/extra leading slash (ROS 1 bags have both)."""
    if requested in available:
        return requested
    alt = requested[1:] if requested.startswith("/") else "/" + requested
    return alt if alt in available else None


def _describe(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in topics.items()) or "none"


def _iter_raw(
    reader: Any,
    path: Path,
    topic: str,
    connections: list[Any],
    *,
    start_ns: int | None = None,
    first_index: int = 0,
    on_bad: Callable[[int], None] | None = None,
    raw_scans: bool = False,
) -> Iterator[tuple[int, int, Any]]:
    """Yield (index, bag time ns, deserialised message) of ``topic`` in the bag's time order.

    ``start_ns`` skips messages recorded before that bag time; ``first_index`` is then
    the index of the first message yielded (used in error messages only). A message
    that cannot be decoded raises DynSlamError, or, with ``on_bad``, is passed over
    after calling ``on_bad(index)``. ``raw_scans``: messages of ROS 1 LaserScan connections
    come as :class:`~dynslam2d.io.rosraw.RawLaserScan` (decoded straight from their bytes,
    the same values; :func:`_scan_from_msg` takes both).
    """
    it = reader.messages(connections=connections, start=start_ns)
    direct = {c.id for c in connections if is_ros1_laserscan(c)} if raw_scans else set()
    index = first_index
    while True:
        try:
            conn, t_ns, raw = next(it)
        except StopIteration:
            return
        except Exception as err:
            hint = "; try 'rosbag reindex' on it" if path.suffix == ".bag" or _is_ros1(path) else ""
            raise DynSlamError(
                f"{path}: cannot read message index {index} of topic {topic} "
                f"({type(err).__name__}: {_short(err)}); the bag looks corrupt or truncated{hint}"
            ) from err
        msg = laserscan_ros1(raw) if conn.id in direct else None
        if msg is None:  # (a message the direct decoder does not parse exactly: rosbags reports it)
            msg = _decode(reader, raw, conn.msgtype, path, topic, index, skip=on_bad is not None,
                          hint="use --skip-bad to drop such messages")
        if msg is None:
            on_bad(index)  # type: ignore[misc]
            index += 1
            continue
        yield index, t_ns, msg
        index += 1


def _decode(reader: Any, raw: bytes, msgtype: str, path: Path, topic: str, index: int, *, skip: bool,
            hint: str) -> Any | None:
    """Deserialise one message; a message that cannot be decoded gives None with ``skip`` (the caller counts
    it), else a DynSlamError naming ``path``, ``topic`` and ``index``, ending with ``hint``."""
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as err:
        if skip:
            return None
        raise DynSlamError(
            f"{path}: cannot decode message index {index} of topic {topic} ({type(err).__name__}: {_short(err)}); "
            f"{hint}"
        ) from err


def _short(err: BaseException, limit: int = 160) -> str:
    """An exception's text on one line, at most ``limit`` characters."""
    text = " ".join(str(err).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _is_ros1(path: Path) -> bool:
    try:
        with path.open("rb") as fh:
            return fh.read(13) == b"#ROSBAG V2.0\n"
    except OSError:
        return False


def list_topics(path: str | os.PathLike[str]) -> dict[str, str]:
    """Topics of a bag and their message types (ROS 2 spelling, e.g. ``sensor_msgs/msg/LaserScan``)."""
    p = Path(path)
    with _open_bag(p) as (reader, _):
        return _topic_types(reader)


def read_topic_messages(path: str | os.PathLike[str], topics: Iterable[str], *,
                        on_bad: Callable[[str, int], None] | None = None,
                        decode_hint: str = "the bag looks corrupt or truncated",
                        ) -> Iterator[tuple[str, str, int, float, Any]]:
    """Yield ``(topic, msgtype, index, bag time s, message)`` of several topics in one pass.

    Messages come in the bag's time order; ``index`` counts per topic from 0. Topics
    the bag does not hold are ignored (callers check :func:`list_topics` first). Used by
    the odometry readers (:mod:`dynslam2d.io.odombag`) to read /odom, /tf, /tf_static and
    an IMU together, and by :func:`read_scan_topics`. A message that cannot be decoded
    raises DynSlamError (ending with ``decode_hint``), or, with ``on_bad``, is passed over after
    ``on_bad(topic, index)``.
    """
    p = Path(path)
    with _open_bag(p) as (reader, _):
        available = _topic_types(reader)
        names = [n for n in (_resolve_topic(t, available) for t in topics) if n is not None]
        if not names:
            return
        connections = [c for n in dict.fromkeys(names) for c in reader.topics[n].connections]
        counts: dict[str, int] = {}
        it = reader.messages(connections=connections)
        while True:
            try:
                conn, t_ns, raw = next(it)
            except StopIteration:
                return
            except Exception as err:
                raise DynSlamError(
                    f"{p}: cannot read a message of {', '.join(names)} ({type(err).__name__}: {_short(err)}); "
                    f"the bag looks corrupt or truncated"
                ) from err
            index = counts.get(conn.topic, 0)
            counts[conn.topic] = index + 1
            msg = _decode(reader, raw, conn.msgtype, p, conn.topic, index, skip=on_bad is not None,
                          hint=decode_hint)
            if msg is None:
                on_bad(conn.topic, index)  # type: ignore[misc]
                continue
            yield conn.topic, conn.msgtype, index, t_ns * 1e-9, msg


def topic_counts(path: str | os.PathLike[str]) -> dict[str, tuple[str, int]]:
    """Every topic of a bag → (message type, message count from the bag's index)."""
    p = Path(path)
    with _open_bag(p) as (reader, _):
        return {name: (info.msgtype or "?", int(info.msgcount)) for name, info in sorted(reader.topics.items())}


def read_scan_topics(path: str | os.PathLike[str], topics: Iterable[str], *,
                     on_bad: Callable[[str, int], None] | None = None) -> Iterator[tuple[str, int, Scan]]:
    """Yield ``(topic, index, Scan)`` of several LaserScan topics in one pass, in the bag's time order.

    ``index`` counts each topic's messages from 0. A message that cannot be decoded or is no
    valid LaserScan raises DynSlamError naming topic and index, or, with ``on_bad``, is
    passed over after ``on_bad(topic, index)`` (``--skip-bad``).
    """
    p = Path(path)
    for topic, _, index, _, msg in read_topic_messages(p, topics, on_bad=on_bad,
                                                       decode_hint="use --skip-bad to drop such messages"):
        try:
            scan = _scan_from_msg(msg, p, topic, index)
        except DynSlamError as err:
            if on_bad is None:
                raise DynSlamError(f"{err}; use --skip-bad to drop such messages") from err
            on_bad(topic, index)
            continue
        yield topic, index, scan


# --------------------------------------------------------------------------- scans


def _scan_from_msg(msg: Any, path: Path, topic: str, index: int) -> Scan:
    """LaserScan message (rosbags' or a :class:`~dynslam2d.io.rosraw.RawLaserScan`) → Scan (every field kept;
    empty intensities → None)."""
    try:
        if type(msg) is RawLaserScan:
            stamp, frame_id = ros_time_to_stamp(msg.sec, msg.nanosec), msg.frame_id
        else:
            stamp = ros_time_to_stamp(msg.header.stamp.sec, msg.header.stamp.nanosec)
            frame_id = msg.header.frame_id
        intensities = msg.intensities if len(msg.intensities) else None
        return Scan(
            stamp=stamp,
            angle_min=float(msg.angle_min),
            angle_increment=float(msg.angle_increment),
            ranges=msg.ranges,
            range_min=float(msg.range_min),
            range_max=float(msg.range_max),
            frame_id=str(frame_id),
            intensities=intensities,
            angle_max=float(msg.angle_max),
            time_increment=float(msg.time_increment),
            scan_time=float(msg.scan_time),
        )
    except DynSlamError as err:
        raise DynSlamError(f"{path}: topic {topic}, message index {index}: {err}") from err
    except (AttributeError, TypeError, ValueError, OverflowError) as err:
        # The connection declares LaserScan but its message definition is another one.
        raise DynSlamError(
            f"{path}: topic {topic}, message index {index}: not a valid sensor_msgs/LaserScan "
            f"({type(err).__name__}: {_short(err)}); the bag's message definition for this topic is wrong"
        ) from err


class RosbagSource:
    """LaserScans of one topic of a ROS 1/ROS 2/MCAP bag, as a :class:`ScanSource`.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, a bare ``.mcap`` or ``.db3`` file.
        topic: the LaserScan topic; may be omitted when the bag has exactly one. A
            missing/extra leading ``/`` is tolerated (``scan`` finds ``/scan``).
        skip_bad: pass over messages that cannot be decoded or are no valid LaserScan,
            counting them in ``meta.extra["skipped_messages"]``, instead of raising.

    Scans come in the bag's time order (record time), each with ``stamp`` =
    ``header.stamp``. ``meta`` is filled on construction from the bag index and the
    first message: ``count`` (the topic's message count), ``beams``, ``fov``,
    ``range_min``/``range_max``, ``frame_id`` and ``rate_hz`` = (count − 1) / (header
    stamp span) for ROS 1 (first and last message), (count − 1) / (bag record span)
    of the whole bag for ROS 2 and MCAP (their indexes give no per-topic span
    cheaply). ``meta.extra`` holds ``storage``, ``topics`` (all topics →
    types) and ``scan_time`` (s, first message). Iterating opens the bag again.

    Raises:
        DynSlamError: unreadable/corrupt bag, no LaserScan topic, several LaserScan
            topics and no ``topic``, a ``topic`` that is not a LaserScan topic, or a
            message that contradicts itself (named by its index) while iterating.
    """

    def __init__(self, path: str | os.PathLike[str], topic: str | None = None, skip_bad: bool = False) -> None:
        self.path = Path(path)
        self.skip_bad = skip_bad
        self.skipped_messages = 0
        with _open_bag(self.path) as (reader, inp):
            topics = _topic_types(reader)
            self.topic = self._choose_topic(topics, topic)
            info = reader.topics[self.topic]
            count = int(info.msgcount)
            first: Scan | None = None
            on_bad = (lambda i: None) if skip_bad else None
            for index, _, msg in _iter_raw(reader, self.path, self.topic, info.connections, on_bad=on_bad):
                try:
                    first = _scan_from_msg(msg, self.path, self.topic, index)
                except DynSlamError:
                    if not skip_bad:
                        raise
                    continue
                break
            rate = None
            if first is not None and count > 1:
                span: float | None
                if inp.kind == "ros1":
                    last = self._last_ros1_stamp(reader, info.connections)
                    span = None if last is None else last - first.stamp
                else:
                    # rosbags reports end_time as last record time + 1 ns
                    span = (reader.end_time - 1 - reader.start_time) * 1e-9
                if span is not None and span > 0:
                    rate = (count - 1) / span
        self.meta = SourceMeta(
            format=inp.format,
            origin=str(self.path),
            topic=self.topic,
            count=count,
            beams=None if first is None else first.n_beams,
            fov=None if first is None else first.fov,
            rate_hz=rate,
            frame_id=None if first is None else first.frame_id,
            range_min=None if first is None else first.range_min,
            range_max=None if first is None else first.range_max,
            extra={
                "storage": inp.storage,
                "topics": topics,
                "scan_time": None if first is None else first.scan_time,
            },
        )

    def _choose_topic(self, topics: dict[str, str], topic: str | None) -> str:
        scans = {t: m for t, m in topics.items() if m == LASERSCAN}
        if not scans:
            raise DynSlamError(
                f"{self.path}: no sensor_msgs/LaserScan topic; the bag has: {_describe(topics)}"
            )
        if topic is None:
            if len(scans) > 1:
                raise DynSlamError(
                    f"{self.path}: {len(scans)} LaserScan topics ({', '.join(scans)}); choose one with --topic "
                    f"(e.g. --topic {next(iter(scans))}); 'dynslam2d info {self.path}' describes each"
                )
            return next(iter(scans))
        if not topic.strip():
            raise DynSlamError(
                f"{self.path}: --topic is empty; give one of the LaserScan topics: {', '.join(scans)}"
            )
        name = _resolve_topic(topic, topics)
        if name is None or topics[name] != LASERSCAN:
            what = "does not exist" if name is None else f"is {topics[name]}, not a LaserScan"
            raise DynSlamError(
                f"{self.path}: topic {topic} {what}; LaserScan topics: {', '.join(scans)}"
            )
        return name

    def _last_ros1_stamp(self, reader: Any, connections: list[Any]) -> float | None:
        """Header stamp of the topic's last message, found through the ROS 1 index."""
        owner = reader.readers[0]
        times = [owner.indexes[c.id][-1].time for c in connections if owner.indexes.get(c.id)]
        if not times:
            return None
        n_before = sum(1 for c in connections for e in owner.indexes.get(c.id, []) if e.time < max(times))
        last = None
        for _, _, msg in _iter_raw(
            reader, self.path, self.topic, connections, start_ns=max(times), first_index=n_before
        ):
            last = ros_time_to_stamp(msg.header.stamp.sec, msg.header.stamp.nanosec)
        return last

    def __len__(self) -> int:
        return int(self.meta.count or 0)

    def __iter__(self) -> Iterator[Scan]:
        with _open_bag(self.path) as (reader, _):
            info = reader.topics.get(self.topic)
            if info is None:  # the file changed since construction
                raise DynSlamError(f"{self.path}: topic {self.topic} is gone")
            self.skipped_messages = 0
            on_bad = self._count_bad if self.skip_bad else None
            for index, _, msg in _iter_raw(reader, self.path, self.topic, info.connections, on_bad=on_bad,
                                           raw_scans=True):
                try:
                    scan = _scan_from_msg(msg, self.path, self.topic, index)
                except DynSlamError:
                    if not self.skip_bad:
                        raise
                    self._count_bad(index)
                    continue
                yield scan

    def _count_bad(self, index: int) -> None:
        """--skip-bad: one malformed message passed over (counted in ``meta.extra``)."""
        self.skipped_messages += 1
        self.meta.extra["skipped_messages"] = self.skipped_messages


# --------------------------------------------------------------------------- poses


@dataclass(frozen=True, slots=True, eq=False)
class PoseTrack:
    """A planar trajectory read from a pose topic (e.g. motion-capture ground truth).

    Attributes:
        stamps: (n,) header stamps, s, in the bag's time order.
        xy: (n, 2) positions, m, in ``frame_id``.
        yaw: (n,) heading about +z, rad in [-pi, pi] (from the orientation quaternion).
        frame_id: the frame the poses are expressed in (header.frame_id of the first message).
    """

    stamps: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    frame_id: str

    def __post_init__(self) -> None:
        stamps = np.ascontiguousarray(self.stamps, dtype=np.float64).reshape(-1)
        xy = np.ascontiguousarray(self.xy, dtype=np.float64).reshape(-1, 2)
        yaw = np.ascontiguousarray(self.yaw, dtype=np.float64).reshape(-1)
        if not (stamps.shape[0] == xy.shape[0] == yaw.shape[0]):
            raise DynSlamError(
                f"PoseTrack: {stamps.shape[0]} stamps, {xy.shape[0]} positions, {yaw.shape[0]} yaws"
            )
        object.__setattr__(self, "stamps", stamps)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "yaw", yaw)

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    def pose(self, i: int) -> Pose2D:
        """The i-th pose as a :class:`Pose2D` (x, y m; theta rad)."""
        return Pose2D(float(self.xy[i, 0]), float(self.xy[i, 1]), float(self.yaw[i]))


def _yaw_from_quaternion(x: np.ndarray, y: np.ndarray, z: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotation about +z of a unit quaternion (ZYX Euler yaw), rad."""
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _pose_of(msg: Any, msgtype: str) -> tuple[Any, Any, Any]:
    """(header, position, orientation) of a supported pose message."""
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return msg.header, msg.pose.position, msg.pose.orientation
    if msgtype in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        return msg.header, msg.pose.pose.position, msg.pose.pose.orientation
    # geometry_msgs/msg/TransformStamped
    return msg.header, msg.transform.translation, msg.transform.rotation


def read_pose_topic(path: str | os.PathLike[str], topic: str) -> PoseTrack:
    """Read a pose topic as a planar :class:`PoseTrack` (x, y, yaw; z/roll/pitch dropped).

    Supports ``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped``,
    ``TransformStamped`` and ``nav_msgs/Odometry``. Stamps are the header stamps, in
    the bag's time order. A topic with no messages gives an empty track.

    Raises:
        DynSlamError: unreadable bag, or ``topic`` missing / not a pose type (the
            message lists the pose topics the bag has).
    """
    p = Path(path)
    with _open_bag(p) as (reader, _):
        topics = _topic_types(reader)
        poses = {t: m for t, m in topics.items() if m in POSE_MSGTYPES}
        name = _resolve_topic(topic, topics)
        if name is None or topics[name] not in POSE_MSGTYPES:
            what = "does not exist" if name is None else f"is {topics[name]}, not a pose type"
            raise DynSlamError(
                f"{p}: topic {topic} {what}; pose topics: {_describe(poses)}"
            )
        msgtype = topics[name]
        n = int(reader.topics[name].msgcount)
        stamps = np.empty(n)
        vals = np.empty((n, 6))  # x, y, qx, qy, qz, qw
        frame_id = ""
        count = 0
        for index, _, msg in _iter_raw(reader, p, name, reader.topics[name].connections):
            header, pos, q = _pose_of(msg, msgtype)
            if index == 0:
                frame_id = str(header.frame_id)
            if count == n:  # index disagreed with the content; grow
                stamps = np.resize(stamps, 2 * n + 1)
                vals = np.resize(vals, (2 * n + 1, 6))
                n = 2 * n + 1
            stamps[count] = ros_time_to_stamp(header.stamp.sec, header.stamp.nanosec)
            vals[count] = (pos.x, pos.y, q.x, q.y, q.z, q.w)
            count += 1
    stamps, vals = stamps[:count], vals[:count]
    yaw = _yaw_from_quaternion(vals[:, 2], vals[:, 3], vals[:, 4], vals[:, 5])
    return PoseTrack(stamps=stamps, xy=vals[:, :2], yaw=yaw, frame_id=frame_id)


# --------------------------------------------------------------------------- writing


@dataclass(frozen=True, slots=True)
class _Layout:
    ros1: bool
    storage: str | None  # ROS 2 storage plugin
    bare_file: bool  # ROS 2 storage file without its folder (.mcap / .db3)


def _writer_layout(path: Path, storage: str | None) -> _Layout:
    """Decide the output layout from the path's suffix and ``storage``."""
    suffix = path.suffix.lower()
    if storage is not None and storage not in _STORAGES:
        raise DynSlamError(f"{path}: unknown bag storage {storage!r} (choose mcap or sqlite3)")
    if suffix == ".bag":
        if storage is not None:
            raise DynSlamError(f"{path}: a .bag path writes a ROS 1 bag; storage={storage!r} does not apply")
        return _Layout(ros1=True, storage=None, bare_file=False)
    for name, ext in _STORAGE_SUFFIX.items():
        if suffix == ext:
            if storage is not None and storage != name:
                raise DynSlamError(f"{path}: a {ext} path is a {name} file; storage={storage!r} contradicts it")
            return _Layout(ros1=False, storage=name, bare_file=True)
    return _Layout(ros1=False, storage=storage or "mcap", bare_file=False)


def _nested_type_names(fielddef: Any) -> list[str]:
    """Message type names a rosbags field definition refers to."""
    names: list[str] = []

    def walk(node: Any) -> None:
        if isinstance(node, tuple):
            if len(node) == 2 and getattr(node[0], "name", None) == "NAME" and isinstance(node[1], str):
                names.append(node[1])
                return
            for item in node:
                walk(item)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(fielddef[1])
    return names


def _latched_qos() -> Any:
    """The QoS a latched ROS 2 publisher offers: reliable, transient-local, keep-last 1."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)  # rmw's "default" = no deadline / lifespan / lease
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL,
        deadline=never,
        lifespan=never,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False,
    )


class BagWriter:
    """Writes ROS messages of any type into an open bag; made by :func:`open_bag_writer`.

    Messages are built from this bag's typestore (ROS 1 Noetic for ``.bag``, ROS 2
    Humble otherwise) with :meth:`msg_class`, :meth:`header` and :meth:`time`, and
    written with :meth:`write`. One connection per topic, created on first use (or
    explicitly with :meth:`add_topic` so that an empty topic still appears).
    """

    def __init__(self, raw: Any, ros1: bool, typestore: Any, path: Path) -> None:
        self._raw = raw
        self.ros1 = ros1
        self.typestore = typestore
        self.path = path
        self._connections: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self.counts: dict[str, int] = {}

    def msg_class(self, msgtype: str) -> Any:
        """The message class for ``msgtype`` (ROS 2 spelling). Types missing from the
        ROS 1 Noetic store (e.g. ``tf2_msgs/msg/TFMessage``) are added from ROS 2 Humble."""
        if msgtype not in self.typestore.types:
            from rosbags.typesys import Stores, get_typestore

            donor = get_typestore(Stores.ROS2_HUMBLE)
            if msgtype not in donor.fielddefs:
                raise DynSlamError(f"{self.path}: unknown message type {msgtype}")
            missing: dict[str, Any] = {}
            todo = [msgtype]
            while todo:  # the type and every nested type this store lacks
                name = todo.pop()
                if name in missing or name in self.typestore.fielddefs:
                    continue
                missing[name] = donor.fielddefs[name]
                todo.extend(_nested_type_names(donor.fielddefs[name]))
            self.typestore.register(missing)
        return self.typestore.types[msgtype]

    def time(self, stamp: float) -> Any:
        """``builtin_interfaces/Time`` for a stamp in s."""
        sec, nsec = stamp_to_ros_time(stamp)
        return self.msg_class("builtin_interfaces/msg/Time")(sec=sec, nanosec=nsec)

    def header(self, stamp: float, frame_id: str, seq: int = 0) -> Any:
        """``std_msgs/Header`` (ROS 1 headers also carry ``seq``)."""
        cls = self.msg_class("std_msgs/msg/Header")
        if self.ros1:
            return cls(seq=int(seq) & 0xFFFFFFFF, stamp=self.time(stamp), frame_id=frame_id)
        return cls(stamp=self.time(stamp), frame_id=frame_id)

    def add_topic(self, topic: str, msgtype: str, *, latched: bool = False) -> None:
        """Declare ``topic`` with ``msgtype`` (idempotent; a second type is an error).

        ``latched=True`` marks the topic as latched so that a replay hands its last
        message to late subscribers (e.g. ``/map``): ROS 1 → ``latching=1`` in the
        connection header; ROS 2 → an offered QoS profile reliable / transient-local /
        keep-last 1 (stored in metadata.yaml and in the MCAP channel / sqlite3 topic
        table, where ``ros2 bag play`` reads it).
        """
        if topic in self._connections:
            if self._types[topic] != msgtype:
                raise DynSlamError(
                    f"{self.path}: topic {topic} already holds {self._types[topic]}, cannot add {msgtype}"
                )
            return
        self.msg_class(msgtype)
        extra: dict[str, Any] = {}
        if latched:
            extra = {"latching": 1} if self.ros1 else {"offered_qos_profiles": [_latched_qos()]}
        try:
            conn = self._raw.add_connection(topic, msgtype, typestore=self.typestore, **extra)
        except Exception as err:
            raise DynSlamError(f"{self.path}: cannot add topic {topic} ({err})") from err
        self._connections[topic] = conn
        self._types[topic] = msgtype
        self.counts[topic] = 0

    def write(self, topic: str, msg: Any, stamp: float) -> None:
        """Serialise ``msg`` and record it on ``topic`` at bag time ``stamp`` (s, >= 0)."""
        msgtype = type(msg).__msgtype__
        self.add_topic(topic, msgtype)
        if not (math.isfinite(stamp) and stamp >= 0):
            raise DynSlamError(
                f"{self.path}: topic {topic} message {self.counts[topic]}: "
                f"stamp {stamp} is not a valid bag time (finite, >= 0)"
            )
        try:
            if self.ros1:
                data = self.typestore.serialize_ros1(msg, msgtype)
            else:
                data = self.typestore.serialize_cdr(msg, msgtype)
            self._raw.write(self._connections[topic], _stamp_ns(stamp), data)
        except Exception as err:
            raise DynSlamError(
                f"{self.path}: cannot write message {self.counts[topic]} on {topic} "
                f"({type(err).__name__}: {err})"
            ) from err
        self.counts[topic] += 1


@contextlib.contextmanager
def open_bag_writer(path: str | os.PathLike[str], *, storage: str | None = None) -> Iterator[BagWriter]:
    """Open a new bag for writing; it appears at ``path`` only if the block completes.

    Layout by ``path``: ``*.bag`` → ROS 1 bag file; ``*.mcap`` / ``*.db3`` → a bare
    ROS 2 storage file (MCAP / sqlite3) with no ``metadata.yaml`` — the single file
    Foxglove, ``ros2 bag`` (Iron and later) and rosbags >= 0.11 open directly;
    anything else → a ROS 2 bag folder (``metadata.yaml`` + one storage file) with
    ``storage`` "mcap" (default) or "sqlite3". An existing ``path`` is replaced.
    Goes through :func:`atomic_path`; on any exception nothing is left at ``path``.
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    final = Path(path)
    layout = _writer_layout(final, storage)
    with atomic_path(final, directory=not layout.ros1 and not layout.bare_file) as tmp:
        target = tmp.with_name(tmp.name + ".bagdir") if layout.bare_file else tmp
        try:
            if layout.ros1:
                raw = Writer1(target)
                typestore = get_typestore(Stores.ROS1_NOETIC)
            else:
                plugin = StoragePlugin.MCAP if layout.storage == "mcap" else StoragePlugin.SQLITE3
                raw = Writer2(target, version=_ROSBAG2_VERSION, storage_plugin=plugin)
                typestore = get_typestore(Stores.ROS2_HUMBLE)
            raw.open()
        except Exception as err:
            raise DynSlamError(f"{final}: cannot create bag ({type(err).__name__}: {err})") from err
        writer = BagWriter(raw, layout.ros1, typestore, final)
        try:
            yield writer
        except BaseException:
            with contextlib.suppress(Exception):
                raw.abort()
            raise
        try:
            raw.close()
        except Exception as err:
            with contextlib.suppress(Exception):
                raw.abort()
            raise DynSlamError(f"{final}: cannot finish bag ({type(err).__name__}: {err})") from err
        if layout.bare_file:
            # rosbags names the storage file after its folder: <folder>/<folder name><ext>.
            os.replace(target / (target.name + _STORAGE_SUFFIX[layout.storage or "mcap"]), tmp)


def laserscan_message(bag: BagWriter, scan: Scan, seq: int = 0) -> Any:
    """Scan → ``sensor_msgs/LaserScan`` in ``bag``'s typestore (float32 fields and arrays).

    ``seq`` goes into the ROS 1 header (ignored for ROS 2). Empty intensities are
    written for ``scan.intensities is None``.
    """
    cls = bag.msg_class(LASERSCAN)
    with np.errstate(over="ignore"):
        ranges = np.asarray(scan.ranges, dtype=np.float32)
        inten = (
            np.zeros(0, dtype=np.float32)
            if scan.intensities is None
            else np.asarray(scan.intensities, dtype=np.float32)
        )
    return cls(
        header=bag.header(scan.stamp, scan.frame_id, seq),
        angle_min=float(scan.angle_min),
        angle_max=float(scan.angle_max if scan.angle_max is not None else scan.angle_min),
        angle_increment=float(scan.angle_increment),
        time_increment=float(scan.time_increment),
        scan_time=float(scan.scan_time),
        range_min=float(scan.range_min),
        range_max=float(scan.range_max),
        ranges=ranges,
        intensities=inten,
    )


def write_scan_bag(
    path: str | os.PathLike[str],
    scans: Iterable[Scan],
    topic: str = "/scan",
    storage: str | None = None,
) -> Path:
    """Write scans as ``sensor_msgs/LaserScan`` on ``topic``; return the final path.

    The layout follows :func:`open_bag_writer` (``.bag`` → ROS 1; ``.mcap``/``.db3``
    → one bare ROS 2 storage file; otherwise a ROS 2 bag folder, MCAP unless
    ``storage="sqlite3"``). Each message's bag time is its scan stamp; ROS 1
    headers get ``seq`` = scan index. Fields are stored as float32 (LaserScan's
    type), so :class:`RosbagSource` reads back exactly what a bag gave. The bag
    appears only once complete: if ``scans`` raises, nothing is left at ``path``.

    Raises:
        DynSlamError: bad path/storage combination, a stamp < 0, or a value the
            message cannot hold (named by scan index).
    """
    final = Path(path)
    with open_bag_writer(final, storage=storage) as bag:
        bag.add_topic(topic, LASERSCAN)
        for index, scan in enumerate(scans):
            try:
                msg = laserscan_message(bag, scan, seq=index)
            except (ValueError, OverflowError) as err:
                raise DynSlamError(f"{final}: scan {index} (stamp {scan.stamp}): {err}") from err
            bag.write(topic, msg, scan.stamp)
    return final
