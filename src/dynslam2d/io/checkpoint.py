"""Checkpoints of a long run: what an interrupted run leaves behind.

:class:`Checkpointer` is a :class:`~dynslam2d.pipeline.RunObserver`. Every
``every_s`` seconds of wall time and/or every ``every_scans`` scans it writes,
atomically, into the results folder:

* ``trajectory.tum`` — every pose so far (laser in the map frame);
* ``map.yaml`` + ``map.pgm`` — the current finest map level;
* ``summary.json`` and ``run.json`` with ``"status": "incomplete"`` and the scan count.

A run killed even with SIGKILL therefore leaves its trajectory and map up to the last
checkpoint; a complete run overwrites all of them and rewrites ``run.json`` last with
``"status": "complete"`` (docs/reliability.md). The observer keeps 32 bytes per scan.
"""

from __future__ import annotations

import json
import os
import time
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.io.atomic import write_text_atomic
from dynslam2d.io.mapfile import write_map
from dynslam2d.io.outputs import write_marker
from dynslam2d.io.trajectory import Trajectory, write_tum

#: Default wall time between checkpoints, s.
DEFAULT_CHECKPOINT_S = 60.0


class Checkpointer:
    """Writes the trajectory and map so far into ``folder`` now and then (see module docstring).

    Args:
        folder: the results folder being written.
        every_s: wall time between checkpoints, s (0 = no time-based checkpoints).
        every_scans: scans between checkpoints (0 = no count-based checkpoints).
        info: extra keys for summary.json / run.json (e.g. the input).
        clock: monotonic clock, s (tests replace it).
    """

    def __init__(self, folder: str | os.PathLike[str], every_s: float = DEFAULT_CHECKPOINT_S,
                 every_scans: int = 0, info: dict[str, Any] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.folder = Path(folder)
        self.every_s = float(every_s)
        self.every_scans = int(every_scans)
        self.info = dict(info or {})
        self._clock = clock
        self._last_t = clock()
        self._last_n = 0
        #: the scans' stamps (s) and laser poses (x, y m, theta rad, map frame; three a scan), float64: an
        #: ``array.append`` a scan costs less than a NumPy item assignment (docs/speed.md, pass cln113)
        self._stamps = array("d")
        self._poses = array("d")
        self._pipeline: Any = None
        self.written = 0

    @property
    def n_scans(self) -> int:
        """Scans seen so far."""
        return len(self._stamps)

    def on_scan(self, scan: Any, step: Any, pipeline: Any) -> None:
        self._stamps.append(step.stamp)
        pose = step.pose
        self._poses.extend((pose.x, pose.y, pose.theta))
        self._pipeline = pipeline
        n = self.n_scans
        due = (self.every_scans > 0 and n - self._last_n >= self.every_scans) or (
            self.every_s > 0 and self._clock() - self._last_t >= self.every_s
        )
        if due:
            self.write()

    def on_finish(self, result: Any, pipeline: Any) -> None:
        """Let go of the pipeline: the complete results replace the checkpoint, and holding it would keep the
        front end's maps, tracker and ledgers alive while the results and figures are written (docs/speed.md)."""
        self._pipeline = None

    def write(self) -> None:
        """Write a checkpoint now (trajectory, map, summary.json and run.json marked incomplete)."""
        n = self.n_scans
        self.folder.mkdir(parents=True, exist_ok=True)
        write_tum(self.folder / "trajectory.tum", Trajectory(np.array(self._stamps, dtype=np.float64),
                                                            np.array(self._poses, dtype=np.float64).reshape(-1, 3)),
                  comment=f"laser pose in the map frame; INCOMPLETE run, first {n} scans")
        if self._pipeline is not None:
            grid = self._pipeline.gridmap()
            if grid.prob.size:
                write_map(self.folder / "map.yaml", grid)
        summary = {"status": "incomplete", "scans": n, **self.info}
        write_text_atomic(self.folder / "summary.json", json.dumps(summary, indent=2, default=str) + "\n")
        write_marker(self.folder, "incomplete", scans=n, **self.info)
        self._last_t, self._last_n = self._clock(), n
        self.written += 1


__all__ = ["Checkpointer", "DEFAULT_CHECKPOINT_S"]
