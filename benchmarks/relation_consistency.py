"""How well do the Kümmerle reference relations agree with the laser scans themselves? (not run by pytest)

For every relation whose two scans are ``--min-dt`` (default 0) to ``--max-dt`` (default 2) s apart,
the two raw scans (range gates as the SLAM uses them) are registered to each other by point-to-line ICP (Censi 2008,
``dynslam2d.slam.icp``), started from the estimated relative pose of a ``dynslam2d run``. It prints:

* the relation error of the estimate and of this direct scan-to-scan registration (an independent
  laser-only measurement of the same relative pose);
* how far the registration moved from the estimate;
* the median point-to-line residual of the second scan against the first at the estimate, at the
  registration's optimum and at the **reference** relative pose — a reference pose that leaves the
  two scans clearly worse aligned than the estimate does is not what the laser saw;
* where the registration ends when started at the reference pose (whether the reference sits in
  the same basin, away from its bottom);
* a bound: the relation error over *all* relations if every selected relation took the scan-to-scan
  registration's value and every other one were exact (0);
* with a clock log (fr079): the error of all relations by how far their ends' stamps are from the
  matched scans' (a clock mapping that picked wrong scans would show there).

    python benchmarks/relation_consistency.py csail RUN_DIR [--min-dt 2 --max-dt inf]
    python benchmarks/relation_consistency.py fr079 RUN_DIR

``RUN_DIR`` is the ``--out`` of ``dynslam2d run LOG --odom none`` (its ``trajectory.tum``); the logs
and relations are those of ``bench_loops.py``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from dynslam2d.eval.relations import nearest_sorted, relation_errors
from dynslam2d.io.carmen import CarmenSource
from dynslam2d.io.relations import read_relations
from dynslam2d.io.trajectory import read_tum
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.icp import line_cloud, register

ROOT = Path(__file__).resolve().parents[1]
#: name → (log, relations, clock log or None, stamp tolerance s)
LOGS = {
    "csail": ("mit-csail/mit-csail.clf", "mit-csail/mit-csail.relations", None, 0.001),
    "fr079": ("fr079/freiburg-079-corrected.log.gz", "fr079/fr079.relations", "fr079/fr079.flirtlib.log", 0.1),
}


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ ⊕ b of two (x, y, θ) poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], 2 * math.pi)])


def _residual(cloud, pts: np.ndarray, pose: np.ndarray, max_distance: float = 0.3) -> float:
    """Median |point-to-line residual| of ``pts`` at ``pose`` against ``cloud``, m."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    q = np.column_stack((c * pts[:, 0] - s * pts[:, 1] + pose[0], s * pts[:, 0] + c * pts[:, 1] + pose[1]))
    d, j = cloud.tree.query(q, distance_upper_bound=max_distance)
    ok = np.isfinite(d)
    ok[ok] = cloud.usable[j[ok]]
    if not ok.any():
        return math.nan
    r = np.einsum("ij,ij->i", cloud.normals[j[ok]], q[ok] - cloud.points[j[ok]])
    return float(np.median(np.abs(r)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", choices=list(LOGS))
    ap.add_argument("run", type=Path, help="output directory of dynslam2d run (trajectory.tum)")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--max-dt", type=float, default=2.0, help="relations shorter than this, s")
    ap.add_argument("--min-dt", type=float, default=0.0, help="and at least this long, s")
    a = ap.parse_args()
    log, relf, clock, tol = LOGS[a.log]
    traj = read_tum(a.run / "trajectory.tum")
    rel = read_relations(f"{a.data}/{relf}")
    stamps = traj.stamps
    if clock is not None:
        from dynslam2d.io.relclock import read_clock_pairs

        stamps = read_clock_pairs(f"{a.data}/{clock}").to_ipc(stamps)
    from dynslam2d.eval.trajectory import Trajectory

    full = relation_errors(Trajectory(stamps, traj.poses), rel.t1, rel.t2, rel.dx, rel.dy, rel.dyaw, tol=tol)
    slam = HectorSlam(SlamConfig())
    scan_pts = [slam.scan_points(s)[0] for s in CarmenSource(f"{a.data}/{log}")]
    if len(scan_pts) != len(stamps):
        raise SystemExit(f"{len(scan_pts)} scans in the log but {len(stamps)} poses in the trajectory")
    used = np.flatnonzero(full.used)
    e_all = full.trans_errors.copy()
    rows = []
    failed = 0
    for k, i in enumerate(used):
        if not a.min_dt <= abs(rel.t2[i] - rel.t1[i]) < a.max_dt:
            e_all[k] = 0.0
            continue
        k1 = int(nearest_sorted(stamps, np.array([rel.t1[i]]))[0][0])
        k2 = int(nearest_sorted(stamps, np.array([rel.t2[i]]))[0][0])
        est = _relative(traj.poses[k1], traj.poses[k2])
        ref = np.array([rel.dx[i], rel.dy[i], rel.dyaw[i]])
        cloud = line_cloud(scan_pts[k1])
        q = scan_pts[k2]
        reg = register(cloud, q, est, max_iterations=50, tol_translation=1e-5, tol_rotation=1e-5)
        from_ref = register(cloud, q, ref, max_iterations=50, tol_translation=1e-5, tol_rotation=1e-5)
        if not (reg.converged and reg.inliers >= 0.3 and math.hypot(*(reg.pose - est)[:2]) < 0.3):
            reg.pose = est  # no reliable registration (little overlap): keep the estimate
            failed += 1
        if not (from_ref.converged and from_ref.inliers >= 0.3):
            from_ref.pose = ref
        e_est = math.hypot(*(est - ref)[:2])
        e_reg = math.hypot(*(reg.pose - ref)[:2])
        e_all[k] = e_reg
        rows.append((e_est, e_reg, math.hypot(*(reg.pose - est)[:2]), _residual(cloud, q, est),
                     _residual(cloud, q, reg.pose), _residual(cloud, q, ref),
                     math.hypot(*(from_ref.pose - reg.pose)[:2])))
    R = np.array(rows)
    print(f"{a.log}: {full.n_used} relations scored, estimate {full.trans_mean:.4f} m; "
          f"{len(R)} of them {a.min_dt}–{a.max_dt} s long; scan-to-scan ICP failed (kept the estimate) on {failed}")
    print(f"  relation error of these: estimate {R[:, 0].mean():.4f} m, scan-to-scan ICP {R[:, 1].mean():.4f} m; "
          f"ICP − estimate {R[:, 2].mean():.4f} m (median {np.median(R[:, 2]):.4f})")
    print(f"  median point-to-line residual: at the estimate {np.nanmedian(R[:, 3]):.4f} m, at the ICP optimum "
          f"{np.nanmedian(R[:, 4]):.4f} m, at the reference {np.nanmedian(R[:, 5]):.4f} m")
    big = R[:, 0] > 0.03
    print(f"  where the estimate is > 3 cm from the reference ({big.sum()}): residual at the estimate "
          f"{np.nanmedian(R[big, 3]):.4f} m, at the reference {np.nanmedian(R[big, 5]):.4f} m; the reference aligns "
          f"the scans worse in {100 * np.mean(R[big, 5] > R[big, 3]):.0f} %")
    print(f"  ICP started at the reference ends {np.median(R[:, 6]):.4f} m (median) from ICP started at the estimate; "
          f"within 5 mm in {100 * np.mean(R[:, 6] < 0.005):.0f} %")
    if clock is not None:  # does the clock mapping pick wrong scans? error by the ends' stamp distance
        _, d1 = nearest_sorted(stamps, rel.t1[used])
        _, d2 = nearest_sorted(stamps, rel.t2[used])
        dmax = np.maximum(d1, d2)
        parts = []
        for lo, hi in ((0.0, 0.005), (0.005, 0.02), (0.02, 0.05), (0.05, tol + 1e-9)):
            m = (dmax >= lo) & (dmax < hi)
            parts.append(f"{1e3 * lo:.0f}–{1e3 * hi:.0f} ms: {full.trans_errors[m].mean():.4f} m ({m.sum()})")
        print("  all relations by the larger distance of their ends to the matched scan stamp: " + ", ".join(parts))
    print(f"  bound: these relations at the ICP value, all others exact → {e_all.mean():.4f} m over all {full.n_used}")


if __name__ == "__main__":
    main()
