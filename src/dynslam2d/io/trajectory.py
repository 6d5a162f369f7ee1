"""Planar trajectories on disk (TUM format).

A :class:`~dynslam2d.trajectory.Trajectory` (the core type, re-exported here so
``from dynslam2d.io.trajectory import Trajectory`` keeps working) is stored in the
TUM format that ``evo`` reads (MichaelGrupp/evo, ``evo/tools/file_interface.py``):
one pose per line, ``timestamp tx ty tz qx qy qz qw``, whitespace-separated, ``#`` comments.
A planar pose is written with ``tz = 0`` and the quaternion of a pure yaw
rotation, ``(qx, qy, qz, qw) = (0, 0, sin(yaw/2), cos(yaw/2))``. Numbers are
written with Python's shortest round-trip representation, so a Unix stamp
(~1.1e9 s) keeps every bit (well below 1 µs) and reading back gives exactly the
floats that were written (the yaw to ~1e-16 rad through the quaternion).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.atomic import atomic_path
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import wrap_angle

#: Default tolerance on |z|, m, above which a TUM pose is "not planar".
PLANAR_Z_TOL_M = 1e-3
#: Default tolerance on the tilt (roll/pitch: angle between the pose's z axis and
#: the map's z axis), rad, above which a TUM pose is "not planar".
PLANAR_TILT_TOL_RAD = 1e-3
#: Accepted deviation of a TUM quaternion's norm from 1 (files written with few
#: decimals are slightly off; anything further is not a rotation).
QUATERNION_NORM_TOL = 1e-3

__all__ = ["PLANAR_TILT_TOL_RAD", "PLANAR_Z_TOL_M", "QUATERNION_NORM_TOL", "Trajectory", "read_tum", "write_tum"]


def _fmt(v: float) -> str:
    # Shortest repr that round-trips exactly (a float64 has ~17 significant digits,
    # so a 1.1e9 s stamp keeps ~1e-7 s, positions keep far below 1e-6 m).
    return repr(float(v))


def write_tum(
    path: str | os.PathLike[str], traj: Trajectory, *, comment: str | None = None
) -> Path:
    """Write ``traj`` as a TUM file at ``path``, atomically; return the path.

    One line per pose, ``stamp x y 0 0 0 sin(yaw/2) cos(yaw/2)``, in the
    trajectory's order. ``comment`` (may span several lines) is written first as
    ``#`` lines. The file appears under ``path`` only when complete.
    """
    lines: list[str] = []
    if comment:
        lines.extend("# " + c for c in comment.splitlines())
    half = 0.5 * traj.yaw
    qz = np.sin(half)
    qw = np.cos(half)
    for t, (x, y, _), z, w in zip(traj.stamps, traj.poses, qz, qw):
        lines.append(f"{_fmt(t)} {_fmt(x)} {_fmt(y)} 0.0 0.0 0.0 {_fmt(z)} {_fmt(w)}")
    text = "\n".join(lines) + "\n" if lines else ""
    final = Path(path)
    try:
        with atomic_path(final) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as e:
        raise DynSlamError(f"{final}: cannot write trajectory: {e}") from e
    return final


def read_tum(
    path: str | os.PathLike[str],
    *,
    max_z: float = PLANAR_Z_TOL_M,
    max_tilt: float = PLANAR_TILT_TOL_RAD,
    frame: str = "map",
) -> Trajectory:
    """Read a TUM trajectory of planar poses.

    Strict: every non-blank, non-``#`` line must hold exactly 8 finite numbers
    ``timestamp tx ty tz qx qy qz qw``; the quaternion must have norm 1 (±1e-3;
    it is normalised); the pose must be planar: ``|tz| <= max_z`` (m) and tilt
    ``<= max_tilt`` (rad), where tilt is the angle between the pose's z axis and
    the frame's z axis, ``2·asin(sqrt(qx² + qy²))``. Yaw is
    ``atan2(2(qw·qz + qx·qy), 1 − 2(qy² + qz²))``, wrapped to [-π, π).

    Raises:
        DynSlamError: naming the file and the 1-based line number, for any
            violation; for a missing/unreadable file; for a file with no pose.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DynSlamError(f"{p}: trajectory file not found") from None
    except IsADirectoryError:
        raise DynSlamError(f"{p}: is a directory, expected a TUM trajectory file") from None
    except UnicodeDecodeError as e:
        raise DynSlamError(f"{p}: not a text file ({e.reason} at byte {e.start})") from None
    except OSError as e:
        raise DynSlamError(f"{p}: cannot read trajectory: {e.strerror or e}") from None

    stamps: list[float] = []
    poses: list[tuple[float, float, float]] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != 8:
            raise DynSlamError(
                f"{p}:{lineno}: expected 8 fields 'timestamp tx ty tz qx qy qz qw', got {len(fields)}"
            )
        try:
            t, x, y, z, qx, qy, qz, qw = (float(f) for f in fields)
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise DynSlamError(f"{p}:{lineno}: field {bad!r} is not a number") from None
        vals = (t, x, y, z, qx, qy, qz, qw)
        if not all(math.isfinite(v) for v in vals):
            raise DynSlamError(f"{p}:{lineno}: non-finite value in {line!r}")
        norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        if abs(norm - 1.0) > QUATERNION_NORM_TOL:
            raise DynSlamError(
                f"{p}:{lineno}: quaternion (qx qy qz qw) = ({qx} {qy} {qz} {qw}) has norm {norm:.6g}, not 1"
            )
        qx, qy, qz, qw = qx / norm, qy / norm, qz / norm, qw / norm
        if abs(z) > max_z:
            raise DynSlamError(
                f"{p}:{lineno}: pose is not planar: z = {z} m exceeds the tolerance {max_z} m"
            )
        tilt = 2.0 * math.asin(min(1.0, math.sqrt(qx * qx + qy * qy)))
        if tilt > max_tilt:
            raise DynSlamError(
                f"{p}:{lineno}: pose is not planar: roll/pitch tilt {tilt:.6g} rad exceeds "
                f"the tolerance {max_tilt} rad"
            )
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        stamps.append(t)
        poses.append((x, y, float(wrap_angle(yaw))))
    if not stamps:
        raise DynSlamError(f"{p}: no poses (the file is empty or holds only comments)")
    return Trajectory(np.array(stamps), np.array(poses), frame)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
