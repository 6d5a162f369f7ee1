"""Speed with odometry on (issue 10: "speed stays within 10 % of today's").

One line per call: the median SLAM time per scan on MIT CSAIL with its FLASER odometry attached
(the first 800 scans, the first 50 left out) and the wall time per scan of the full default
pipeline on datmo ``overtakes.bag`` with wheel + IMU odometry (scans read beforehand). Run it
alternately with two source trees and compare medians (the machine is shared; single runs vary
by 2×):

    for i in 1 2 3 4 5 6; do
      PYTHONPATH=OLD/src python benchmarks/bench_odometry_speed.py old
      PYTHONPATH=NEW/src python benchmarks/bench_odometry_speed.py new
    done

Not a test; needs ../shared/data.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


class _Listed:
    """Scans read beforehand, so reading the file is not timed."""

    def __init__(self, source: object) -> None:
        self.meta = source.meta  # type: ignore[attr-defined]
        self.scans = list(source)  # type: ignore[call-overload]

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.scans)

    def __len__(self) -> int:
        return len(self.scans)


def main() -> None:
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run
    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.types import Pose2D

    label = sys.argv[1] if len(sys.argv) > 1 else "this"
    scans = list(open_source(DATA / "mit-csail" / "mit-csail.clf", odom="auto"))[:800]
    slam = HectorSlam(SlamConfig())
    ms = []
    for s in scans:
        t0 = time.perf_counter()
        slam.process(s)
        ms.append((time.perf_counter() - t0) * 1e3)
    bag = _Listed(open_source(DATA / "dynamic" / "datmo" / "overtakes.bag", laser_offset=Pose2D(-0.12, 0.0, 0.0)))
    res = run(bag)
    print(f"{label}: MIT CSAIL + FLASER odometry, SLAM median {np.median(ms[50:]):.3f} ms/scan; "
          f"datmo overtakes + wheel/IMU, pipeline {1e3 * res.wall_time_s / len(bag):.3f} ms/scan")


if __name__ == "__main__":
    main()
