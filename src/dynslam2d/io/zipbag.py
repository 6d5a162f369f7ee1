"""A bag delivered inside a ``.zip`` archive (e.g. the leg_tracker benchmark bags).

The archive must hold exactly one bag file (ROS 1 ``.bag``, bare ``.mcap`` or
``.db3``), recognised by its first bytes like every other input, not by its name.
rosbags needs a seekable file on disk, so the bag is extracted into a private
temporary folder that is removed when the source is closed or garbage-collected
(and at interpreter exit at the latest).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Scan, SourceMeta

#: First bytes of a zip archive (local file header).
ZIP_MAGIC = b"PK\x03\x04"
#: First bytes of the single-file bag kinds a zip may hold.
_BAG_MAGICS = (b"#ROSBAG V2.0", b"\x89MCAP", b"SQLite format 3\x00")


def _bag_members(archive: zipfile.ZipFile) -> list[tuple[zipfile.ZipInfo, bytes]]:
    """(member, first bytes) of members whose content starts like a bag (directories and
    macOS resource forks skipped)."""
    found = []
    for info in archive.infolist():
        if info.is_dir() or info.filename.startswith("__MACOSX/"):
            continue
        with archive.open(info) as fh:
            head = fh.read(16)
        if head.startswith(_BAG_MAGICS):
            found.append((info, head))
    return found


def _extract_single_bag(path: Path, into: Path) -> tuple[Path, str]:
    """Extract the one bag of ``path`` into folder ``into``; return (file, member name)."""
    try:
        with zipfile.ZipFile(path) as archive:
            members = _bag_members(archive)
            if len(members) != 1:
                names = ", ".join(m.filename for m, _ in members)
                what = "no bag" if not members else f"{len(members)} bags ({names})"
                raise DynSlamError(
                    f"{path}: zip archive holds {what}; it must hold exactly one "
                    f"(unzip it and pass the bag itself)"
                )
            member, head = members[0]
            # The suffix tells rosbags the kind; the content was checked above.
            suffix = ".bag" if head.startswith(b"#ROSBAG") else ".mcap" if head.startswith(b"\x89MCAP") else ".db3"
            target = into / f"bag{suffix}"
            with archive.open(member) as src, target.open("wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
    except DynSlamError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, NotImplementedError) as err:
        raise DynSlamError(f"{path}: cannot read zip archive ({type(err).__name__}: {err})") from err
    return target, member.filename


class ExtractedBag:
    """The one bag of a zip archive, extracted into a temporary folder.

    ``path`` is the extracted file, ``member`` its name inside the archive,
    ``label`` = ``"<zip>:<member>"`` for messages. :meth:`close` (or leaving the
    ``with`` block) removes the folder; it is also removed when the object is
    garbage-collected.
    """

    def __init__(self, archive: str | os.PathLike[str]) -> None:
        self.archive = Path(archive)
        self._tmp = tempfile.TemporaryDirectory(prefix="dynslam2d-zip-")
        try:
            self.path, self.member = _extract_single_bag(self.archive, Path(self._tmp.name))
        except BaseException:
            self._tmp.cleanup()
            raise
        self.label = f"{self.archive}:{self.member}"

    def relabel(self, err: DynSlamError) -> DynSlamError:
        """The same error with the temporary path replaced by ``label``."""
        return DynSlamError(str(err).replace(str(self.path), self.label))

    def close(self) -> None:
        """Remove the extracted file (idempotent)."""
        self._tmp.cleanup()

    def __enter__(self) -> ExtractedBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextlib.contextmanager
def bag_file(path: str | os.PathLike[str]) -> Iterator[Path]:
    """``path`` itself, or, for a zip archive, its one bag extracted for the block's duration."""
    p = Path(path)
    if not is_zip(p):
        yield p
        return
    with ExtractedBag(p) as bag:
        try:
            yield bag.path
        except DynSlamError as err:
            raise bag.relabel(err) from err


def is_zip(path: Path) -> bool:
    """True if ``path`` is a file starting with the zip magic bytes."""
    try:
        with path.open("rb") as fh:
            return fh.read(4) == ZIP_MAGIC
    except OSError:
        return False


class ZipBagSource:
    """LaserScans of the one bag inside a zip archive (a :class:`ScanSource`).

    Same as :class:`~dynslam2d.io.rosbag.RosbagSource` on the extracted bag;
    ``meta.origin`` names the archive and member, ``meta.extra["archive"]`` the zip.
    Errors name ``<zip>:<member>`` instead of the temporary file. ``options`` go to
    ``RosbagSource`` unchanged.
    """

    def __init__(self, path: str | os.PathLike[str], topic: str | None = None, **options: Any) -> None:
        from dynslam2d.io.rosbag import RosbagSource

        self._bag = ExtractedBag(path)
        try:
            self._inner = RosbagSource(self._bag.path, topic=topic, **options)
        except DynSlamError as err:
            self._bag.close()
            raise self._bag.relabel(err) from err
        self.meta: SourceMeta = self._inner.meta
        self.meta.origin = self._bag.label
        self.meta.extra["archive"] = str(self._bag.archive)

    @property
    def path(self) -> Path:
        """The extracted bag (a temporary file), for readers of its other topics (odometry, TF)."""
        return self._bag.path

    def __len__(self) -> int:
        return len(self._inner)

    def __iter__(self) -> Iterator[Scan]:
        try:
            yield from self._inner
        except DynSlamError as err:
            raise self._bag.relabel(err) from err

    def close(self) -> None:
        """Remove the extracted bag now (it goes anyway when the source is collected)."""
        self._bag.close()
