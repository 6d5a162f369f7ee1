"""CPU cost of the vacated-footprints trace (docs/maps.md, "Vacated footprints"; not run by pytest).

Runs the default pipeline over each input and times ``Pipeline._evidence_view`` (the per-scan trace of the
beams through the map, the outlines' growth and the yielding view) with ``time.thread_time``, against the
whole run's thread time (the clean-up pass included):

    python benchmarks/bench_vacate.py sim:paper sim:parking ../shared/data/mit-csail/mit-csail.clf
    python benchmarks/bench_vacate.py ../shared/data/dynamic/leg_tracker/negative_2.bag --topic /right_scan
"""

from __future__ import annotations

import argparse
import time

from dynslam2d.config import Config
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import Pipeline, run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--topic", default=None, help="scan topic of the recordings (ignored by sim: inputs)")
    args = ap.parse_args()
    acc = [0.0, 0]
    orig = Pipeline._evidence_view

    def timed(self, scan, pose):
        t = time.thread_time()
        v = orig(self, scan, pose)
        acc[0] += time.thread_time() - t
        acc[1] += 1
        return v

    Pipeline._evidence_view = timed
    for inp in args.inputs:
        acc[0], acc[1] = 0.0, 0
        t0 = time.thread_time()
        run(open_source(inp, args.topic), Config())
        tot = time.thread_time() - t0
        n = max(acc[1], 1)
        name = f"{inp} {args.topic}" if args.topic and not inp.startswith("sim:") else inp
        print(f"{name}: trace {1e3 * acc[0] / n:.2f} ms/scan, run {1e3 * tot / n:.2f} ms/scan "
              f"({100 * acc[0] / tot:.0f} %)", flush=True)


if __name__ == "__main__":
    main()
