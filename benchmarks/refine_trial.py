"""Trial of a point-to-line ICP refinement after the Hector match (issue 12; not run by pytest).

Every accepted scan-matched pose is refined by point-to-line ICP (Censi 2008, ``dynslam2d.slam.icp``)
against the points of the last ``--keyframes`` map updates (in the map frame, normals from each
keyframe's own ``k`` = 10 nearest neighbours), Cauchy weights at 3 cm, at most 10 Gauss–Newton steps,
correspondences within 0.3 m. The refinement is kept only if it converged, at least 30 % of the points
found a line, and it moved the pose less than 0.2 m / 0.1 rad; the refined pose is the one written into
the map. Only the points that reach the map (the scan the front end matched / integrated) take part.

It prints, for the SLAM alone (``HectorSlam``, laser only, no detection) with and without the
refinement: the Kümmerle relation error on MIT CSAIL and Freiburg 079 (scored as ``bench_loops.py``
does) and the ATE on simulated scenes, plus the share of scans refined and the time per scan.

    python benchmarks/refine_trial.py [--only csail fr079 sim] [--keyframes 5] [--no-icp]
        [--slam FIELD=VALUE ...]

``--slam`` sets ``SlamConfig`` fields for both runs (e.g. ``iterations_finest=20``); ``--no-icp`` runs
only the matcher without the refinement.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import deque
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from dynslam2d.eval.relations import relation_errors
from dynslam2d.eval.trajectory import Trajectory, ate
from dynslam2d.io.carmen import CarmenSource
from dynslam2d.io.relations import read_relations
from dynslam2d.sim import simulate
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam import processor as proc
from dynslam2d.slam.icp import LineCloud, line_cloud, register
from dynslam2d.types import Pose2D, Scan, wrap_angle

ROOT = Path(__file__).resolve().parents[1]


class IcpRefinedSlam(HectorSlam):
    """HectorSlam whose accepted scan matches are refined by point-to-line ICP against recent keyframes."""

    def __init__(self, config: SlamConfig, keyframes: int = 5) -> None:
        super().__init__(config)
        self._keyframes: deque[LineCloud] = deque(maxlen=keyframes)
        self._cloud: LineCloud | None = None
        self.tried = 0
        self.refined = 0

    def _integrate(self, pts: np.ndarray, clear: np.ndarray, pose: Pose2D) -> bool:
        ok = super()._integrate(pts, clear, pose)
        if ok:
            self._keyframes.append(line_cloud(pose.transform_points(pts), k=10))
            p = np.concatenate([c.points for c in self._keyframes])
            self._cloud = LineCloud(p, np.concatenate([c.normals for c in self._keyframes]),
                                    np.concatenate([c.usable for c in self._keyframes]), cKDTree(p))
        return ok

    def match(self, scan: Scan, predicted: Pose2D | None = None, commit: bool = True) -> proc.MatchResult:
        res = super().match(scan, predicted, commit=False)
        if not res.rejected and not res.first and res.pose_source == proc.SOURCE_SCAN and self._cloud is not None:
            self.tried += 1
            reg = register(self._cloud, res.points, res.pose.as_array(), max_iterations=10, max_distance=0.3,
                           kernel_scale=0.03)
            d = res.pose.between(Pose2D(*reg.pose))
            if reg.converged and reg.inliers >= 0.3 and math.hypot(d.x, d.y) < 0.2 and abs(d.theta) < 0.1:
                res.pose = Pose2D(float(reg.pose[0]), float(reg.pose[1]), float(wrap_angle(reg.pose[2])))
                self.refined += 1
        if commit:
            self._commit(scan, res)
        return res


def _run(slam: HectorSlam, scans: list[Scan]) -> tuple[np.ndarray, np.ndarray, float]:
    t = time.perf_counter()
    steps = [slam.process(s) for s in scans]
    ms = (time.perf_counter() - t) * 1e3 / max(len(scans), 1)
    return (np.array([s.stamp for s in steps]), np.array([[s.pose.x, s.pose.y, s.pose.theta] for s in steps]), ms)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", default=["csail", "fr079", "sim"])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--keyframes", type=int, default=5)
    ap.add_argument("--no-icp", action="store_true", help="only the matcher, without the ICP refinement")
    ap.add_argument("--slam", nargs="*", default=[], metavar="FIELD=VALUE", help="SlamConfig fields for both runs")
    a = ap.parse_args()
    fields = dict(kv.split("=", 1) for kv in a.slam)
    cfg = SlamConfig(use_odometry=False, **fields)  # laser only (--odom none); pydantic converts the strings
    if fields:
        print("slam:", fields, flush=True)

    def slams() -> list[tuple[str, HectorSlam]]:
        out: list[tuple[str, HectorSlam]] = [("Hector", HectorSlam(cfg))]
        return out if a.no_icp else [*out, ("Hector + ICP", IcpRefinedSlam(cfg, a.keyframes))]

    for name in a.only:
        if name in ("csail", "fr079"):
            if name == "csail":
                log, relf, tol, clock = "mit-csail/mit-csail.clf", "mit-csail/mit-csail.relations", 0.001, None
            else:
                log, relf, tol = "fr079/freiburg-079-corrected.log.gz", "fr079/fr079.relations", 0.1
                clock = "fr079/fr079.flirtlib.log"
            scans = list(CarmenSource(f"{a.data}/{log}"))
            rel = read_relations(f"{a.data}/{relf}")
            for label, slam in slams():
                st, po, ms = _run(slam, scans)
                if clock is not None:
                    from dynslam2d.io.relclock import read_clock_pairs

                    st = read_clock_pairs(f"{a.data}/{clock}").to_ipc(st)
                r = relation_errors(Trajectory(st, po), rel.t1, rel.t2, rel.dx, rel.dy, rel.dyaw, tol=tol)
                extra = f", refined {slam.refined} of {slam.tried}" if isinstance(slam, IcpRefinedSlam) else ""
                print(f"{name:8s} {label:13s} relations {r.trans_mean:.4f} ± {r.trans_std:.4f} m "
                      f"({r.n_used} scored), {ms:.2f} ms/scan{extra}", flush=True)
        elif name == "sim":
            for scen in ("static", "paper", "corridor"):
                sim = simulate(scen, seed=0, duration=30.0)
                gt = Trajectory(sim.ground_truth.stamps, sim.ground_truth.poses_in("first"))
                for label, slam in slams():
                    _, po, ms = _run(slam, sim.scans)
                    e = ate(gt, Trajectory(sim.ground_truth.stamps, po)).rmse
                    extra = f", refined {slam.refined} of {slam.tried}" if isinstance(slam, IcpRefinedSlam) else ""
                    print(f"sim:{scen:8s} {label:13s} ATE {e:.5f} m, {ms:.2f} ms/scan{extra}", flush=True)


if __name__ == "__main__":
    main()
