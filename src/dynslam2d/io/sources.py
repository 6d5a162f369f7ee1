"""Open anything that holds laser scans: format sniffing and stream checks.

:func:`open_source` looks at what ``path`` is (a ``sim:<scenario>`` name, a ROS 2
bag folder, or a file whose first bytes say ROS 1 bag, MCAP, gzip or CARMEN
text) and returns a :class:`ScanSource`. Every source is wrapped in
:class:`CheckedSource`, which enforces what all later stages rely on: stamps
strictly increase, and the input is not empty.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterator

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Scan, ScanSource, SourceMeta

SIM_PREFIX = "sim:"

_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP"
_GZIP_MAGIC = b"\x1f\x8b"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_ZIP_MAGIC = b"PK\x03\x04"  # a zip archive holding one bag (io/zipbag.py)
_CARMEN_RECORDS = (b"FLASER", b"ROBOTLASER1", b"RLASER", b"ODOM", b"PARAM", b"VERTEX2", b"NEFF")


def sniff_format(path: str | os.PathLike[str]) -> str:
    """Name the format of ``path``: "sim", "ros2-bag", "ros1-bag", "mcap", "carmen" or "zip"
    (an archive holding one bag, see :mod:`dynslam2d.io.zipbag`).

    Decided by content (magic bytes, a bag folder's metadata.yaml), not by the file
    name alone. Raises DynSlamError for missing paths and unknown content.
    """
    text = os.fspath(path)
    if text.startswith(SIM_PREFIX):
        return "sim"
    p = Path(text)
    if not p.exists():
        raise DynSlamError(f"{p}: no such file or folder")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "ros2-bag"
        raise DynSlamError(f"{p}: folder is not a ROS 2 bag (no metadata.yaml inside)")
    try:
        with p.open("rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise DynSlamError(f"{p}: cannot read ({exc.strerror})") from exc
    if not head:
        raise DynSlamError(f"{p}: file is empty")
    if head.startswith(_ROS1_MAGIC):
        return "ros1-bag"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    if head.startswith(_SQLITE_MAGIC):
        return "ros2-bag"  # a bare .db3 (rosbags reads it with or without metadata.yaml)
    if head.startswith(_GZIP_MAGIC):
        return "carmen"
    if head.startswith(_ZIP_MAGIC):
        return "zip"
    for line in head.splitlines():
        word = line.strip().split(b" ", 1)[0]
        if word in _CARMEN_RECORDS:
            return "carmen"
    raise DynSlamError(
        f"{p}: unknown format (expected a ROS 1 .bag, a ROS 2 bag folder, an .mcap file, "
        f"a CARMEN log, a .zip holding one bag, or sim:<scenario>)"
    )


class CheckedSource:
    """Wraps a source; enforces strictly increasing stamps and a non-empty input.

    A scan whose stamp does not increase raises DynSlamError naming the source and
    the scan index, unless ``skip_bad`` is set: then it is skipped and counted in
    ``skipped`` (and ``meta.extra["skipped_scans"]``).
    """

    def __init__(self, inner: ScanSource, skip_bad: bool = False) -> None:
        self.inner = inner
        self.meta: SourceMeta = inner.meta
        self.skip_bad = skip_bad
        self.skipped = 0

    def __len__(self) -> int:
        if self.meta.count is None:
            raise TypeError(f"{self.meta.origin}: scan count is not known before reading")
        return self.meta.count

    def __iter__(self) -> Iterator[Scan]:
        self.skipped = 0
        last: float | None = None
        n = 0
        for index, scan in enumerate(self.inner):
            if last is not None and not scan.stamp > last:
                what = "repeats" if scan.stamp == last else "goes backwards"
                if not self.skip_bad:
                    raise DynSlamError(
                        f"{self.meta.origin}: scan {index} stamp {scan.stamp:.6f} {what} "
                        f"(previous {last:.6f}); use --skip-bad to drop such scans"
                    )
                self.skipped += 1
                self.meta.extra["skipped_scans"] = self.skipped
                continue
            last = scan.stamp
            n += 1
            yield scan
        if n == 0:
            raise DynSlamError(f"{self.meta.origin}: holds no usable laser scans")


def open_source(
    path: str | os.PathLike[str],
    topic: str | None = None,
    *,
    seed: int | None = None,
    duration: float | None = None,
    skip_bad: bool = False,
) -> CheckedSource:
    """Open a scan source by sniffing its format.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 or MCAP), a bare ``.mcap``,
            a CARMEN log (``.clf``/``.log``, optionally gzipped), a ``.zip`` holding exactly
            one bag (extracted to a temporary folder, removed with the source), or
            ``sim:<scenario>``.
        topic: the LaserScan topic (bags with several); ignored for other formats.
        seed, duration: simulator seed and length in s (``sim:`` sources only).
        skip_bad: skip malformed records and non-increasing stamps (counted) instead of
            stopping with an error.
    Returns:
        A :class:`CheckedSource` (iterable of Scan, ``meta``, ``len()`` where known).
    """
    fmt = sniff_format(path)
    text = os.fspath(path)
    inner: ScanSource
    if fmt == "sim":
        from dynslam2d.sim import SimSource

        inner = SimSource(text[len(SIM_PREFIX) :], seed=seed, duration=duration)
    elif fmt == "zip":
        from dynslam2d.io.zipbag import ZipBagSource

        inner = ZipBagSource(text, topic=topic)
    elif fmt == "carmen":
        from dynslam2d.io.carmen import CarmenSource

        inner = CarmenSource(text, skip_bad=skip_bad)
    else:
        from dynslam2d.io.rosbag import RosbagSource

        inner = RosbagSource(text, topic=topic)
    return CheckedSource(inner, skip_bad=skip_bad)
