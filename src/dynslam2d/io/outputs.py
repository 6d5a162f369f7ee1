"""Where a command may write: checked before any work, never over a user's data.

Rules (docs/reliability.md):

* an output location is checked before the first scan: its nearest existing
  ancestor must be a folder the process can create entries in (a probe folder is
  created and removed), so ``/proc/foo``, ``file/sub`` or a read-only parent fail
  at once;
* a results folder is marked by ``run.json`` (:data:`MARKER`), written when the
  folder is created (status ``"incomplete"``) and rewritten LAST when every file is
  complete (status ``"complete"``). A non-empty folder without that marker belongs
  to the user and is never written into; a marked folder is replaced only with
  ``force`` and then as a whole: the new results go into a fresh sibling folder
  that is swapped in at the end, so no file of the earlier run survives;
* a bag output (``--write-bag``) never replaces an input, and replaces an existing
  path only with ``force`` and only if it is a bag dynslam2d wrote (it holds the
  ``/slam_pose`` and ``/scan_filtered`` topics). Leftover ``.part`` folders of an
  interrupted bag write are removed before the next write to the same path.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dynslam2d import __version__
from dynslam2d.errors import DynSlamError

#: File that marks a folder as a dynslam2d results folder (written last).
MARKER = "run.json"
#: Topics only a bag written by dynslam2d's BagRecorder holds together.
_OWN_BAG_TOPICS = frozenset({"/slam_pose", "/scan_filtered"})


def _abs(path: str | os.PathLike[str]) -> Path:
    return Path(os.path.abspath(os.fspath(path)))


def same_or_inside(path: str | os.PathLike[str], container: str | os.PathLike[str]) -> bool:
    """True if ``path`` is ``container`` (same file, or same resolved path) or lies inside it."""
    p, c = Path(path), Path(container)
    try:
        if p.exists() and c.exists() and os.path.samefile(p, c):
            return True
    except OSError:
        pass
    rp, rc = p.resolve(), c.resolve()
    return rp == rc or rc in rp.parents


def check_writable_location(path: str | os.PathLike[str], option: str) -> None:
    """Raise DynSlamError unless ``path`` (not existing yet) can be created.

    The nearest existing ancestor must be a folder in which an entry can be created;
    this is probed by creating and removing a temporary folder there.
    """
    p = _abs(path)
    anc = p.parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise DynSlamError(f"{option} {path}: {anc} is a file, not a folder; choose another location")
    try:
        probe = tempfile.mkdtemp(prefix=".dynslam2d-probe-", dir=anc)
        os.rmdir(probe)
    except OSError as exc:
        raise DynSlamError(
            f"{option} {path}: cannot write in {anc} ({exc.strerror or exc}); choose another location"
        ) from None


def read_marker(folder: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The content of ``folder/run.json`` if it is a dynslam2d marker, else None."""
    f = Path(folder) / MARKER
    try:
        data = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if isinstance(data, dict) and data.get("tool") == "dynslam2d":
        return data
    return None


def write_marker(folder: str | os.PathLike[str], status: str, **info: Any) -> Path:
    """Write ``folder/run.json`` atomically: tool, version, ``status`` and ``info``."""
    from dynslam2d.io.atomic import write_text_atomic

    data = {"tool": "dynslam2d", "version": __version__, "status": status,
            "written": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"), **info}
    return write_text_atomic(Path(folder) / MARKER, json.dumps(data, indent=2, default=str) + "\n")


@dataclass
class ResultsFolder:
    """A results folder being written: ``work`` is where files go, ``final`` where they end up.

    Create with :func:`plan_results_folder`; call :meth:`start` before the first scan,
    :meth:`finish` after the marker says "complete" (swaps ``work`` in when replacing),
    or :meth:`discard` on an error (removes what this run created, nothing else).
    """

    final: Path
    work: Path
    replace: bool
    existed_empty: bool
    created: list[Path] = field(default_factory=list)

    def start(self, **info: Any) -> None:
        """Create the folder (and missing parents) and mark it as an incomplete run."""
        if self.replace:
            self.work = Path(tempfile.mkdtemp(prefix=f".{self.final.name}.staging-", dir=_abs(self.final).parent))
            write_marker(self.work, "incomplete", **info)
            return
        missing = []
        d = _abs(self.work)
        while not d.exists():
            missing.append(d)
            d = d.parent
        try:
            self.work.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DynSlamError(f"--out {self.final}: cannot create the folder ({exc.strerror or exc})") from None
        self.created = list(reversed(missing))
        write_marker(self.work, "incomplete", **info)

    def finish(self) -> Path:
        """Move the results to ``final`` (swapping out an earlier results folder); return it."""
        if not self.replace:
            return self.final
        old = Path(tempfile.mkdtemp(prefix=f".{self.final.name}.old-", dir=self.final.parent))
        os.replace(self.final, old / "previous")
        os.replace(self.work, self.final)
        shutil.rmtree(old, ignore_errors=True)
        self.work = self.final
        self.replace = False
        return self.final

    def keep_partial(self) -> Path:
        """After an interrupt: where the partial results stay; return that folder.

        Written in place, they stay at ``final``. When an earlier complete results folder
        was being replaced, that one is kept and the partial results are moved beside it
        to ``<final>.incomplete-<UTC time>`` (a marked results folder, like any other).
        """
        if not self.replace:
            return self.final
        stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%d-%H%M%S")
        target = _abs(self.final).parent / f"{self.final.name}.incomplete-{stamp}"
        os.replace(self.work, target)
        self.work = target
        self.replace = False
        return target

    def discard(self) -> None:
        """Remove what this run wrote: the folders it created, or its files in an empty folder it was given."""
        if self.replace or self.created:
            top = self.work if self.replace else self.created[0]
            shutil.rmtree(top, ignore_errors=True)
        elif self.existed_empty:
            for entry in list(self.work.iterdir()) if self.work.is_dir() else []:
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    entry.unlink(missing_ok=True)


def plan_results_folder(
    out: str | os.PathLike[str], force: bool = False, inputs: Iterable[str | os.PathLike[str]] = ()
) -> ResultsFolder:
    """Decide where a results folder is written; raise DynSlamError if ``out`` must not be touched.

    * missing ``out``: created (its location is probed first);
    * an empty folder: written into;
    * a folder marked by ``run.json``: replaced as a whole with ``force`` (written into a
      fresh sibling, swapped at the end), refused otherwise;
    * anything else (a file, a device, a non-empty folder without the marker): refused.
    An input (recording, ground truth, configuration) inside ``out`` is never replaced.
    """
    p = Path(out)
    if p.name in ("", ".", "..") or str(p) in (".", ".."):
        p = _abs(p)
    if p.exists() or p.is_symlink():
        if not p.is_dir():
            raise DynSlamError(f"--out {out}: exists and is not a folder; give the path of a new or empty folder")
        try:
            entries = next(os.scandir(p), None)
        except OSError as exc:
            raise DynSlamError(f"--out {out}: cannot read the folder ({exc.strerror or exc})") from None
        if entries is None:
            check_writable_location(p / "x", "--out")
            return ResultsFolder(p, p, replace=False, existed_empty=True)
        if read_marker(p) is None:
            raise DynSlamError(
                f"--out {out}: folder is not empty and is not a dynslam2d results folder (no {MARKER}); "
                f"nothing was written, choose a new or empty folder"
            )
        if not force:
            raise DynSlamError(
                f"--out {out}: holds the results of an earlier run; use --force to replace them, or choose another "
                f"folder"
            )
        for inp in inputs:
            if same_or_inside(inp, p):
                raise DynSlamError(f"--out {out}: contains the input {inp}; choose another folder")
        check_writable_location(p, "--out")
        # The staging folder is created by start(), beside the earlier results.
        return ResultsFolder(p, _abs(p).parent / f".{p.name}.staging", replace=True, existed_empty=False)
    check_writable_location(p, "--out")
    return ResultsFolder(p, p, replace=False, existed_empty=False)


def is_own_bag(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is a bag (file or ROS 2 folder) that dynslam2d's BagRecorder wrote."""
    try:
        from rosbags.highlevel import AnyReader

        with AnyReader([Path(path)]) as reader:
            topics = {c.topic for c in reader.connections}
    except Exception:  # anything unreadable is not ours
        return False
    return _OWN_BAG_TOPICS <= topics


def stale_parts(path: str | os.PathLike[str]) -> list[Path]:
    """Leftover temporary folders of an interrupted atomic write of ``path`` (``.<name>.*.part``)."""
    p = _abs(path)
    if not p.parent.is_dir():
        return []
    return sorted(d for d in p.parent.glob(f".{p.name}.*.part") if d.is_dir() and not d.is_symlink())


def check_bag_target(
    path: str | os.PathLike[str],
    force: bool = False,
    inputs: Iterable[str | os.PathLike[str]] = (),
    out: str | os.PathLike[str] | None = None,
) -> None:
    """Raise DynSlamError unless a bag may be written at ``path`` (rules in the module docstring)."""
    p = Path(path)
    if p.name in ("", ".", ".."):
        raise DynSlamError(f"--write-bag {path}: give a file or new folder name, e.g. out.mcap")
    for inp in inputs:
        if same_or_inside(inp, p):
            raise DynSlamError(f"--write-bag {path}: is the input {inp}; an input is never written over")
    if out is not None and same_or_inside(out, p):
        raise DynSlamError(f"--write-bag {path}: is the --out folder or contains it; choose another name")
    if p.exists() or p.is_symlink():
        if not force:
            raise DynSlamError(
                f"--write-bag {path}: exists already; use --force to replace a bag dynslam2d wrote, or choose another "
                f"name"
            )
        if not is_own_bag(p):
            raise DynSlamError(f"--write-bag {path}: exists and is not a bag written by dynslam2d; it is not replaced")
        check_writable_location(p, "--write-bag")
    else:
        check_writable_location(p, "--write-bag")


def clean_stale_parts(path: str | os.PathLike[str]) -> int:
    """Remove leftover ``.part`` folders of earlier interrupted writes of ``path``; return how many."""
    parts = stale_parts(path)
    for d in parts:
        shutil.rmtree(d, ignore_errors=True)
    return len(parts)


__all__ = [
    "MARKER", "ResultsFolder", "check_bag_target", "check_writable_location", "clean_stale_parts",
    "is_own_bag", "plan_results_folder", "read_marker", "same_or_inside", "stale_parts", "write_marker",
]
