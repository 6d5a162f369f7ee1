"""Atomic writes: a file or folder appears under its final name only when complete.

Every writer in dynslam2d goes through :func:`atomic_path`: it yields a temporary
path in the same directory (so the final rename is atomic on POSIX), renames it
over the final name on success and removes it on any exception, including
KeyboardInterrupt. An interrupted run never leaves a half-written file under the
final name.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike[str], *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``final``; move it to ``final`` on success.

    Args:
        final: the path the result must end up at. Its parent is created if missing.
        directory: the writer produces a folder (e.g. a ROS 2 bag) rather than a file.
            The yielded path does not exist yet, so writers that insist on creating
            their own folder (rosbags) can do so.

    An existing ``final`` is replaced only once the new content is complete.
    """
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp_dir = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent))
    tmp = tmp_dir / final.name
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"writer produced nothing at {tmp}")
        if directory and final.exists():
            # os.replace cannot replace a non-empty directory: move the old one aside first.
            old = tmp_dir / (final.name + ".old")
            os.replace(final, old)
        os.replace(tmp, final)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


def write_text_atomic(final: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``final`` atomically; return the final path."""
    with atomic_path(final) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(final)


def write_bytes_atomic(final: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``final`` atomically; return the final path."""
    with atomic_path(final) as tmp:
        tmp.write_bytes(data)
    return Path(final)
