"""Intel sub-sampled log: the whole pipeline in stamp order (what ``dynslam2d run`` reads) or in file order
(not run by pytest).

``intel-lab.flirtlib.log`` has 97 backward steps of its ipc stamps in file order, and the reader sorts the
scans by stamp. The stamps jitter by a large part of the 0.6 s scan period (relations put scans 0.006 s
apart 0.33 m apart), so sorting swaps neighbouring scans: the robot seems to step back and forth. This
script feeds the pipeline the scans in either order (in file order the stamps are raised to the previous
one + 0.01 s for processing only) and scores the poses at the scans' original stamps::

    python benchmarks/bench_intel_order.py --order stamp|file [--config FILE] [--data ../shared/data]

It prints the relation error (``--tol 0.05``, as ``dynslam2d eval relations``) of the final trajectory and,
when loop closure replaced it, of the front end's, with the loop-closure counters. Only the laser is used
(the pose fields of the log are corrected poses, never read).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import yaml

from dynslam2d.config import Config
from dynslam2d.eval.relations import relation_errors_from
from dynslam2d.io.carmen import CarmenSource
from dynslam2d.io.relations import read_relations
from dynslam2d.pipeline import run
from dynslam2d.trajectory import Trajectory

ROOT = Path(__file__).resolve().parents[1]


class _ListSource:
    """The scans of a list, with the meta of the log they came from."""

    def __init__(self, scans: list, meta: object) -> None:
        self.scans = scans
        self.meta = meta

    def __iter__(self):
        return iter(self.scans)

    def __len__(self) -> int:
        return len(self.scans)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--order", choices=["stamp", "file"], default="stamp")
    ap.add_argument("--config", default=None, help="a dynslam2d config YAML (as for dynslam2d run --config)")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    a = ap.parse_args()
    cfg = Config(**(yaml.safe_load(Path(a.config).read_text()) or {})) if a.config else Config()
    src = CarmenSource(f"{a.data}/intel/intel-lab.flirtlib.log")
    scans = list(src)
    stamps = np.array([s.stamp for s in scans])
    if a.order == "file":
        order = np.argsort([r.line for r in src.records()], kind="stable")
    else:
        order = np.arange(len(scans))
    fed, last = [], -math.inf
    for k in order:
        s = scans[k]
        t = max(s.stamp, last + 0.01)  # non-decreasing stamps for processing only
        last = t
        fed.append(s.with_ranges(s.ranges, stamp=t))
    t0 = time.perf_counter()
    res = run(_ListSource(fed, src.meta), cfg)
    wall = time.perf_counter() - t0
    rel = read_relations(f"{a.data}/intel/intel.relations")
    for name, traj in (("final", res.trajectory), ("front end", res.frontend_trajectory)):
        if traj is None:
            continue
        r = relation_errors_from(Trajectory(stamps[order], traj.poses), rel, tol=0.05)
        print(f"{a.order} order, {name}: translation {r.trans.mean:.3f} ± {r.trans.std:.3f} m, rotation "
              f"{math.degrees(r.rot.mean):.2f} ± {math.degrees(r.rot.std):.2f}°, {int(r.used.sum())} relations")
    if res.loop is not None:
        s = res.loop.stats
        print(f"loops accepted {s.get('loops_accepted')}, optimised kept {bool(s.get('kept_optimised'))}, "
              f"map entropy front end {s.get('map_entropy_frontend')} / optimised {s.get('map_entropy_optimised')}")
    print(f"wall {wall:.1f} s")


if __name__ == "__main__":
    main()
