"""Open a recording of laser scans: format sniffing and stream checks.

:func:`open_recording` looks at what ``path`` is (a ROS 2 bag folder, or a file
whose first bytes say ROS 1 bag, MCAP, gzip or CARMEN text) and returns a
:class:`ScanSource`. Every source is wrapped in :class:`CheckedSource`, which
enforces what all later stages rely on: stamps strictly increase, and the input
is not empty. Opening any input, simulated scenarios (``sim:<scenario>``)
included, is :func:`dynslam2d.inputs.open_source`, one layer up
(docs/architecture.md "Layers"); ``open_source`` is still reachable from here.
"""

from __future__ import annotations

import contextlib
import os
import select
import stat
import tempfile
import time
import weakref
from collections.abc import Iterator
from pathlib import Path

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceMeta

SIM_PREFIX = "sim:"

_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP"
_GZIP_MAGIC = b"\x1f\x8b"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_ZIP_MAGIC = b"PK\x03\x04"  # a zip archive holding one bag (io/zipbag.py)
_CARMEN_RECORDS = (b"FLASER", b"ROBOTLASER1", b"RLASER", b"ODOM", b"PARAM", b"VERTEX2", b"NEFF")

#: How long to wait for the first byte from a pipe / FIFO before giving up, s.
STREAM_WAIT_S = 30.0
#: Largest stream (pipe, FIFO, /dev/stdin) copied to a temporary file, bytes.
MAX_STREAM_BYTES = 4 * 2**30


def is_stream(path: str | os.PathLike[str]) -> bool:
    """True for an existing path that is neither a regular file nor a folder (pipe, FIFO, device)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def spool_stream(
    path: str | os.PathLike[str], wait_s: float | None = None, max_bytes: int | None = None
) -> Path:
    """Copy a pipe / FIFO / ``/dev/stdin`` into a temporary file and return its path.

    Format sniffing reads the first bytes of a file and then reopens it; a pipe can be
    read only once, so it is copied first (nothing is lost, gzip included). A FIFO with
    no writer would block forever: if no byte arrives within ``wait_s`` seconds, a
    DynSlamError says so. More than ``max_bytes`` bytes is refused. Defaults:
    :data:`STREAM_WAIT_S`, :data:`MAX_STREAM_BYTES`. The caller removes
    the file (:func:`open_source` does when the source is garbage-collected).
    """
    name = os.fspath(path)
    wait_s = STREAM_WAIT_S if wait_s is None else wait_s
    max_bytes = MAX_STREAM_BYTES if max_bytes is None else max_bytes
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise DynSlamError(f"{name}: cannot open ({exc.strerror or exc})") from None
    tmp = None
    try:
        deadline = time.monotonic() + wait_s
        first = b""
        while not first:
            left = deadline - time.monotonic()
            ready, _, _ = select.select([fd], [], [], max(0.0, min(left, 0.2)))
            if ready:
                try:
                    first = os.read(fd, 1 << 16)
                except BlockingIOError:
                    first = b""
                if not first and _writer_gone(fd):
                    raise DynSlamError(f"{name}: the stream ended before any data; nothing to read")
            if not first and time.monotonic() >= deadline:
                raise DynSlamError(
                    f"{name}: no data within {wait_s:g} s (a FIFO with no writer?); start the writer first or pass a "
                    f"file"
                )
        os.set_blocking(fd, True)
        out = tempfile.NamedTemporaryFile(prefix="dynslam2d-stream-", delete=False)
        tmp = Path(out.name)
        total = 0
        with out:
            chunk = first
            while chunk:
                total += len(chunk)
                if total > max_bytes:
                    raise DynSlamError(
                        f"{name}: stream larger than {max_bytes / 2**30:g} GiB; save it to a file and pass the file"
                    )
                out.write(chunk)
                chunk = os.read(fd, 1 << 20)
        return tmp
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
    finally:
        os.close(fd)


def _writer_gone(fd: int) -> bool:
    """After a 0-byte read on a readable descriptor: has a writer been there and left (EOF)?

    On Linux a FIFO that never had a writer does not poll readable, so a readable
    descriptor with no data means end of stream.
    """
    return True


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
            dropped = {k: self.meta.extra.get(k) for k in ("skipped_lines", "skipped_messages", "skipped_scans")}
            why = ", ".join(f"{v} {k.replace('skipped_', '')} skipped" for k, v in dropped.items() if v)
            raise DynSlamError(f"{self.meta.origin}: holds no usable laser scans" + (f" ({why})" if why else ""))


def open_recording(
    path: str | os.PathLike[str],
    topic: str | None = None,
    *,
    skip_bad: bool = False,
    odom: str = "auto",
    imu: str = "auto",
    laser_offset: Pose2D | None = None,
) -> CheckedSource:
    """Open a recorded scan source by sniffing its format.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 or MCAP), a bare ``.mcap``,
            a CARMEN log (``.clf``/``.log``, optionally gzipped), or a ``.zip`` holding exactly
            one bag (extracted to a temporary folder, removed with the source).
            ``sim:<scenario>`` is not a recording: :func:`dynslam2d.inputs.open_source` opens it.
        topic: the LaserScan topic (bags with several); ignored for other formats.
        skip_bad: skip malformed records and non-increasing stamps (counted) instead of
            stopping with an error.
        odom, imu: where ``Scan.odom`` / ``Scan.yaw_rate`` come from: "auto" (what the
            recording has), "none" (laser only), or a topic / record name
            (:mod:`dynslam2d.io.odomsource`); ``meta.odometry`` says what was used.
        laser_offset: the base → laser transform (m, rad) when the recording has no TF.
    Returns:
        A :class:`CheckedSource` (iterable of Scan, ``meta``, ``len()`` where known).

    A pipe, FIFO or ``/dev/stdin`` is first copied to a temporary file
    (:func:`spool_stream`), so sniffing loses nothing; ``meta.origin`` names the stream.
    """
    spooled: Path | None = None
    origin = os.fspath(path)
    if not origin.startswith(SIM_PREFIX) and is_stream(path):
        spooled = spool_stream(path)
        path = spooled
    try:
        source = _open(path, topic, skip_bad=skip_bad, origin=origin if spooled is not None else None,
                       odom=odom, imu=imu, laser_offset=laser_offset)
    except BaseException as exc:
        if spooled is not None:
            spooled.unlink(missing_ok=True)
            if isinstance(exc, DynSlamError):  # name the stream the user gave, not the copy
                raise DynSlamError(str(exc).replace(str(spooled), origin)) from None
        raise
    if spooled is not None:
        source.meta.origin = origin
        source.meta.extra["spooled_from"] = origin
        weakref.finalize(source, _unlink, str(spooled))
    return source


def checked_source(
    inner: ScanSource, fmt: str, *, skip_bad: bool = False, odom: str = "auto", imu: str = "auto",
    laser_offset: Pose2D | None = None,
) -> CheckedSource:
    """``inner`` (a source of format ``fmt``, as :func:`sniff_format` names it) with its
    odometry / IMU input attached (:func:`dynslam2d.io.odomsource.attach_odometry`) and the
    stream checks of :class:`CheckedSource`; the last step of opening any source."""
    from dynslam2d.io.odomsource import attach_odometry

    inner = attach_odometry(inner, fmt, odom=odom, imu=imu, laser_offset=laser_offset)
    return CheckedSource(inner, skip_bad=skip_bad)


def __getattr__(name: str) -> object:
    # ``dynslam2d.io.sources.open_source`` keeps working for existing code; it lives one layer
    # up (it opens ``sim:`` scenarios too), so it is imported on first use, not at module level.
    if name == "open_source":
        from dynslam2d.inputs import open_source

        return open_source
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _unlink(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def _open(
    path: str | os.PathLike[str], topic: str | None, *, skip_bad: bool,
    origin: str | None = None, odom: str = "auto", imu: str = "auto", laser_offset: Pose2D | None = None,
) -> CheckedSource:
    fmt = sniff_format(path)
    text = os.fspath(path)
    inner: ScanSource
    if fmt == "sim":
        raise DynSlamError(
            f"{text}: a simulated scenario, not a recording; open it with dynslam2d.inputs.open_source"
        )
    if fmt == "zip":
        from dynslam2d.io.zipbag import ZipBagSource

        inner = ZipBagSource(text, topic=topic, skip_bad=skip_bad)
    elif fmt == "carmen":
        from dynslam2d.io.carmen import CarmenSource

        inner = CarmenSource(text, skip_bad=skip_bad, origin=origin)
    else:
        from dynslam2d.io.rosbag import RosbagSource

        inner = RosbagSource(text, topic=topic, skip_bad=skip_bad)
    return checked_source(inner, fmt, skip_bad=skip_bad, odom=odom, imu=imu, laser_offset=laser_offset)
