"""Direct decoding of ROS 1 ``sensor_msgs/LaserScan`` messages from their serialized bytes.

rosbags' generic deserializer builds a message object (with a header object and a time
object) per message; :func:`laserscan_ros1` reads the same fields straight from the ROS 1
wire format (little-endian, strings and arrays prefixed by a uint32 length; the ROS wiki's
"ROS/Message_serialization") with one ``struct`` call for the seven float32 fields and
``numpy.frombuffer`` for the ranges and intensities: the values rosbags gives, bit for bit
(``tests/test_io_rosraw.py``). It applies only to connections whose message definition has
the standard LaserScan MD5 sum (:func:`is_ros1_laserscan`); callers fall back to rosbags
for anything else and for a message whose bytes do not parse exactly.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

#: MD5 sum of the ROS 1 sensor_msgs/LaserScan definition (``rosmsg md5 sensor_msgs/LaserScan``): a connection
#: with it serializes the fields in the order :func:`laserscan_ros1` reads.
LASERSCAN_MD5 = "90c7ef2dc6895d81024acba2ac42f369"

_HEADER = struct.Struct("<3I")  # header.seq, header.stamp.secs, header.stamp.nsecs
_U32 = struct.Struct("<I")
# angle_min, angle_max, angle_increment, time_increment, scan_time, range_min, range_max
_FLOATS = struct.Struct("<7f")
_F32 = np.dtype("<f4")


@dataclass(frozen=True, slots=True)
class RawLaserScan:
    """The fields of one LaserScan message that :class:`dynslam2d.types.Scan` takes.

    ``sec``/``nanosec``: header stamp (ROS time); angles in rad, times in s, ranges in m, as float32 values
    (the floats as Python floats, the arrays as float32 views of the message bytes).
    """

    sec: int
    nanosec: int
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    intensities: np.ndarray


def is_ros1_laserscan(connection: Any) -> bool:
    """Whether ``connection`` (a rosbags ``Connection``) is a ROS 1 LaserScan connection with the standard
    definition, so that :func:`laserscan_ros1` decodes its messages."""
    return connection.digest == LASERSCAN_MD5 and type(connection.ext).__name__ == "ConnectionExtRosbag1"


def laserscan_ros1(raw: bytes | memoryview) -> RawLaserScan | None:
    """The fields of a serialized ROS 1 LaserScan, or None when the bytes do not hold exactly one message
    (a truncated or padded message: the caller's generic decoder then reports it)."""
    try:
        n = len(raw)
        _, sec, nsec = _HEADER.unpack_from(raw, 0)
        (k,) = _U32.unpack_from(raw, 12)
        pos = 16 + k
        if pos > n:
            return None
        frame_id = bytes(raw[16:pos]).decode()
        f = _FLOATS.unpack_from(raw, pos)
        pos += 28
        (nr,) = _U32.unpack_from(raw, pos)
        pos += 4
        if pos + 4 * nr > n:
            return None
        ranges = np.frombuffer(raw, dtype=_F32, count=nr, offset=pos)
        pos += 4 * nr
        (ni,) = _U32.unpack_from(raw, pos)
        pos += 4
        if pos + 4 * ni != n:
            return None
        inten = np.frombuffer(raw, dtype=_F32, count=ni, offset=pos)
    except (struct.error, UnicodeDecodeError, ValueError):
        return None
    return RawLaserScan(sec, nsec, frame_id, f[0], f[1], f[2], f[3], f[4], f[5], f[6], ranges, inten)


__all__ = ["LASERSCAN_MD5", "RawLaserScan", "is_ros1_laserscan", "laserscan_ros1"]
