"""Kümmerle et al. (2009) relation files (``*.relations``) and matching them to scans.

One relation per line, 8 numbers: ``t1 t2 x y z roll pitch yaw``. ``(x, y, yaw)``
(m, m, rad) is the pose at time ``t2`` expressed in the robot frame at ``t1``,
i.e. ``x_t1⁻¹ ⊕ x_t2`` (:meth:`dynslam2d.types.Pose2D.between`); ``z``, ``roll``
and ``pitch`` are 0 in every published 2D file and are not kept. ``t1``/``t2``
are the ``ipc_timestamp`` of laser scans in the original log (s). Some lines
have ``t2 < t1``. Blank lines and ``#`` comments are skipped; the file may be
gzipped.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.carmen import read_text
from dynslam2d.stamps import nearest_sorted

#: Default stamp-matching tolerance, s (relation stamps are written with 6 decimals).
DEFAULT_MATCH_TOL = 1e-3


@dataclass(frozen=True, slots=True)
class Relations:
    """Relative-pose ground truth, as (n,) float64 arrays in file order.

    Attributes:
        t1, t2: stamps of the two scans, s.
        dx, dy: translation of the t2 pose in the t1 robot frame, m.
        dyaw: rotation of the t2 pose relative to the t1 pose, rad.
        line: 1-based line number of each relation (int64).
        origin: the file read.
    """

    t1: np.ndarray
    t2: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dyaw: np.ndarray
    line: np.ndarray
    origin: str = ""

    def __len__(self) -> int:
        return int(self.t1.shape[0])


def read_relations(path: str | os.PathLike[str]) -> Relations:
    """Read a ``*.relations`` file (plain or gzipped).

    Raises DynSlamError naming the file and the 1-based line for a line that does
    not hold exactly 8 finite numbers, and for a file without relations.
    """
    p, text = read_text(path)
    rows: list[tuple[float, ...]] = []
    lines: list[int] = []
    for index, raw in enumerate(text.split("\n")):
        fields = raw.split()
        if not fields or fields[0].startswith("#"):
            continue
        lineno = index + 1
        if len(fields) != 8:
            raise DynSlamError(
                f"{p}:{lineno}: a relation needs 8 numbers (t1 t2 x y z roll pitch yaw), found {len(fields)} fields"
            )
        try:
            values = tuple(float(f) for f in fields)
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise DynSlamError(f"{p}:{lineno}: non-numeric field {bad!r} in relation") from None
        if not all(math.isfinite(v) for v in values):
            raise DynSlamError(f"{p}:{lineno}: relation holds a non-finite number")
        rows.append(values)
        lines.append(lineno)
    if not rows:
        raise DynSlamError(f"{p}: no relations in file")
    a = np.asarray(rows, dtype=np.float64)
    if looks_like_tum(a):
        raise DynSlamError(
            f"{p}: looks like a TUM trajectory (stamp x y z qx qy qz qw with unit quaternions), not relations "
            f"(t1 t2 x y z roll pitch yaw); pass the relations file"
        )
    return Relations(
        t1=a[:, 0].copy(),
        t2=a[:, 1].copy(),
        dx=a[:, 2].copy(),
        dy=a[:, 3].copy(),
        dyaw=a[:, 7].copy(),
        line=np.asarray(lines, dtype=np.int64),
        origin=str(p),
    )


def looks_like_tum(a: np.ndarray) -> bool:
    """True if (n, 8) rows read as relations are a TUM trajectory instead.

    In TUM rows the last four numbers are a unit quaternion; in relations they are
    ``z roll pitch yaw`` (z, roll, pitch ~0), whose norm is 1 only where |yaw| happens
    to be ~1 rad. A TUM file also has its stamps in column 1 only: t2 (column 2) is not
    ≥ t1 everywhere. Both must hold.
    """
    if a.shape[0] < 2:
        return False
    unit = np.abs(np.linalg.norm(a[:, 4:8], axis=1) - 1.0) < 1e-3
    return bool(unit.all() and not np.all(a[:, 1] >= a[:, 0]))


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def match_relation_stamps(
    relations: Relations, scan_stamps: np.ndarray, tol: float = DEFAULT_MATCH_TOL
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Match relation stamps to scans: ``(i1, i2, ok)``.

    Args:
        relations: from :func:`read_relations`.
        scan_stamps: (m,) non-decreasing scan stamps, s (e.g. of a CarmenSource).
        tol: largest accepted |relation stamp − scan stamp|, s (inclusive).
    Returns:
        ``i1``, ``i2``: (n,) int64 indices of the scans nearest to ``t1`` / ``t2``
        (always valid indices); ``ok``: (n,) bool, True where both are within ``tol``.
        Use only ``i1[ok]``, ``i2[ok]``.
    """
    s = np.asarray(scan_stamps, dtype=np.float64)
    if s.ndim != 1 or s.shape[0] == 0:
        raise DynSlamError("match_relation_stamps: scan stamps must be a non-empty 1-D array")
    if not np.all(np.isfinite(s)) or np.any(np.diff(s) < 0.0):
        raise DynSlamError("match_relation_stamps: scan stamps must be finite and sorted (non-decreasing)")
    if not (math.isfinite(tol) and tol >= 0.0):
        raise DynSlamError(f"match_relation_stamps: tol must be a non-negative number of seconds, got {tol}")
    i1 = nearest_sorted(s, relations.t1)[0]
    i2 = nearest_sorted(s, relations.t2)[0]
    ok = (np.abs(s[i1] - relations.t1) <= tol) & (np.abs(s[i2] - relations.t2) <= tol)
    return i1, i2, ok
