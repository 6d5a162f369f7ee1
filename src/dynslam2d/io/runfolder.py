"""Reading back what ``dynslam2d run`` wrote: the removal mask, the tracks, the trajectory.

Files (see :mod:`dynslam2d.results`): ``kept_mask.npz`` (``stamps`` (n,) s,
``removed`` (n, beams) bool), ``tracks.csv`` (one row per scan and live track,
columns ``stamp, id, state, x, y, heading, length, width, vx, vy, in_M``, map frame,
m / rad / m/s) and ``trajectory.tum`` (laser pose in the map frame per scan).
Every problem raises :class:`DynSlamError` naming the file.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.trajectory import Trajectory, read_tum

KEPT_MASK = "kept_mask.npz"
TRACKS_CSV = "tracks.csv"
TRAJECTORY = "trajectory.tum"

#: dtype of :func:`read_tracks` rows (tracks.csv columns).
TRACK_DTYPE = np.dtype([
    ("stamp", "f8"), ("id", "i8"), ("state", "U12"), ("x", "f8"), ("y", "f8"), ("heading", "f8"),
    ("length", "f8"), ("width", "f8"), ("vx", "f8"), ("vy", "f8"), ("in_M", "?"),
])


@dataclass(frozen=True, eq=False)
class RemovedMask:
    """``kept_mask.npz``: ``stamps`` (n,) scan stamps in s, ``removed`` (n, beams) bool."""

    stamps: np.ndarray
    removed: np.ndarray


def _need(run_dir: Path, name: str) -> Path:
    if not run_dir.is_dir():
        raise DynSlamError(f"{run_dir}: results folder not found (write one with 'dynslam2d run')")
    path = run_dir / name
    if not path.is_file():
        raise DynSlamError(f"{run_dir}: not a complete results folder ({name} is missing; write one with 'dynslam2d "
                           f"run')")
    return path


def read_removed_mask(run_dir: str | os.PathLike[str]) -> RemovedMask:
    """Read ``kept_mask.npz`` of a results folder."""
    path = _need(Path(run_dir), KEPT_MASK)
    try:
        with np.load(path) as npz:
            stamps = np.asarray(npz["stamps"], dtype=np.float64).reshape(-1)
            removed = np.asarray(npz["removed"], dtype=bool)
    except (OSError, ValueError, KeyError) as err:
        raise DynSlamError(f"{path}: cannot read the removal mask ({err})") from err
    if removed.ndim != 2 or removed.shape[0] != stamps.shape[0]:
        raise DynSlamError(f"{path}: removed has shape {removed.shape} for {stamps.shape[0]} stamps")
    return RemovedMask(stamps, removed)


def read_tracks(run_dir: str | os.PathLike[str]) -> np.ndarray:
    """Read ``tracks.csv`` of a results folder as a structured array (:data:`TRACK_DTYPE`)."""
    path = _need(Path(run_dir), TRACKS_CSV)
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    names = list(TRACK_DTYPE.names or ())
    # tracks.csv of this version ends with a column "remembered" (track memory); older ones do not
    if not rows or rows[0] not in (names, names + ["remembered"]):
        raise DynSlamError(f"{path}: header is not {','.join(names)}[,remembered]")
    width = len(rows[0])
    out = np.zeros(len(rows) - 1, dtype=TRACK_DTYPE)
    for i, row in enumerate(rows[1:]):
        if len(row) != width:
            raise DynSlamError(f"{path}:{i + 2}: {len(row)} fields, expected {width}")
        try:
            out[i] = (float(row[0]), int(row[1]), row[2], *map(float, row[3:10]), row[10] == "1")
        except ValueError as err:
            raise DynSlamError(f"{path}:{i + 2}: malformed value ({err})") from err
    return out


def read_run_trajectory(run_dir: str | os.PathLike[str]) -> Trajectory:
    """Read ``trajectory.tum`` of a results folder (laser pose in the map frame)."""
    return read_tum(_need(Path(run_dir), TRAJECTORY))


__all__ = ["RemovedMask", "TRACK_DTYPE", "read_removed_mask", "read_run_trajectory", "read_tracks"]
