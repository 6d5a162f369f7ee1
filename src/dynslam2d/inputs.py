"""Open any input of the pipeline: a simulated scenario or a recording.

:func:`open_source` is the one entry point for "where do the scans come from":
``sim:<scenario>`` runs the simulator (:mod:`dynslam2d.sim`); anything else is a
recording read by :func:`dynslam2d.io.sources.open_recording` (format sniffing,
pipes, zipped bags). It sits above both ``io`` and ``sim`` (docs/architecture.md
"Layers"), so neither of them needs to know the other.
"""

from __future__ import annotations

import os

from dynslam2d.io.sources import SIM_PREFIX, CheckedSource, checked_source, open_recording
from dynslam2d.types import Pose2D, ScanSource

__all__ = ["open_source"]


def open_source(
    path: str | os.PathLike[str],
    topic: str | None = None,
    *,
    seed: int | None = None,
    duration: float | None = None,
    skip_bad: bool = False,
    odom: str = "auto",
    imu: str = "auto",
    laser_offset: Pose2D | None = None,
) -> CheckedSource:
    """Open a scan source: a simulated scenario or a recording whose format is sniffed.

    Args:
        path: ``sim:<scenario>`` (a scenario of :mod:`dynslam2d.sim`), or anything
            :func:`~dynslam2d.io.sources.open_recording` reads: a ROS 1 ``.bag``, a ROS 2 bag
            folder, a bare ``.mcap``, a CARMEN log, a ``.zip`` holding one bag, or a pipe /
            FIFO / ``/dev/stdin`` holding one of these.
        seed, duration: simulator seed and length in s (``sim:`` sources only).
        topic, skip_bad, odom, imu, laser_offset: as for
            :func:`~dynslam2d.io.sources.open_recording`. For ``sim:`` the topic is ignored,
            ``odom`` / ``imu`` are "auto" or "none" (the simulated odometry / IMU) and a
            ``laser_offset`` is an error (the mount is in the simulator's odometry model).
    Returns:
        A :class:`~dynslam2d.io.sources.CheckedSource` (iterable of Scan, ``meta``,
        ``len()`` where known).
    """
    text = os.fspath(path)
    if not text.startswith(SIM_PREFIX):
        return open_recording(path, topic, skip_bad=skip_bad, odom=odom, imu=imu, laser_offset=laser_offset)
    from dynslam2d.sim import SimSource  # imported on use: the simulator is not needed to read files

    inner: ScanSource = SimSource(text[len(SIM_PREFIX) :], seed=seed, duration=duration)
    return checked_source(inner, "sim", skip_bad=skip_bad, odom=odom, imu=imu, laser_offset=laser_offset)
