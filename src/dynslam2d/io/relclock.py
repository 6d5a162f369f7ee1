"""Clock mapping for Kümmerle relation files whose stamps are on another clock than a log.

The Freiburg 079 relations (Kümmerle et al. 2009) are stamped with the ``ipc_timestamp`` of
the original recording, while the GMapping-corrected log that carries the full scan rate
(``freiburg-079-corrected.log.gz``) only keeps the *logger* time (both stamp fields hold the
logger-relative time). The sub-sampled FLIRTLib copy of the same run (``fr079.flirtlib.log``)
writes both clocks on every ``ROBOTLASER1`` / ``FLASER`` record, so the offset
ipc − logger is known at its scans; it drifts (1211.00 … 1211.51 s over the run) and is
interpolated linearly in logger time in between (held constant outside the pairs' span).
docs/slam.md, "Loop closure", describes how relations are scored with it.

Only the two stamp fields of each laser record are read: the pose fields of these logs are
SLAM-corrected poses, never odometry.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.carmen import read_text

_LASER = ("FLASER", "ROBOTLASER1")


@dataclass(frozen=True, slots=True)
class ClockMap:
    """ipc = logger + offset(logger), offset interpolated between known (logger, ipc) pairs.

    Attributes:
        logger: (n,) sorted logger stamps of the pairs, s.
        offset: (n,) ipc − logger at those stamps, s.
        origin: the file the pairs came from.
    """

    logger: np.ndarray
    offset: np.ndarray
    origin: str = ""

    def to_ipc(self, logger_stamps: np.ndarray) -> np.ndarray:
        """(m,) logger stamps, s → (m,) ipc stamps, s."""
        t = np.asarray(logger_stamps, dtype=np.float64)
        return t + np.interp(t, self.logger, self.offset)


def read_clock_pairs(path: str | os.PathLike[str]) -> ClockMap:
    """The (logger, ipc) pairs of every laser record of a CARMEN log (plain or gzipped).

    The last three fields of ``FLASER`` and ``ROBOTLASER1`` records are
    ``ipc_timestamp ipc_hostname logger_timestamp``.

    Raises:
        DynSlamError: no laser record, a stamp that is not a finite number (naming the line),
            or a log whose two clocks are the same on every record (no mapping to learn).
    """
    p, text = read_text(path)
    logger: list[float] = []
    ipc: list[float] = []
    for index, raw in enumerate(text.split("\n")):
        fields = raw.split(maxsplit=1)
        if not fields or fields[0] not in _LASER:
            continue
        f = raw.split()
        try:
            a, b = float(f[-3]), float(f[-1])
        except (ValueError, IndexError):
            raise DynSlamError(f"{p}:{index + 1}: {fields[0]} record without numeric ipc/logger stamps") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise DynSlamError(f"{p}:{index + 1}: {fields[0]} record with a non-finite stamp")
        ipc.append(a)
        logger.append(b)
    if not logger:
        raise DynSlamError(f"{p}: no FLASER / ROBOTLASER1 records, so no clock pairs; pass the log that has both "
                           f"clocks")
    lg = np.asarray(logger)
    off = np.asarray(ipc) - lg
    if np.all(np.abs(off) < 1e-9):
        raise DynSlamError(f"{p}: ipc and logger stamps are equal on every record; this log cannot map the clocks")
    order = np.argsort(lg, kind="stable")
    return ClockMap(lg[order], off[order], str(p))
