"""Why MIT CSAIL's own odometry does not bring the relation error below 0.028 m.

Prints (docs/slam.md, "MIT CSAIL with its odometry" quotes it):

1. The Kümmerle et al. 2009 relation error of full ``dynslam2d run`` pipelines: laser only, the
   log's FLASER odometry as the default prior (seed + degenerate directions), and
   ``slam.odometry_prior: all`` (the odometry's noise model on every direction, gated).
2. How the reference relations relate to the log's odometry: the share of relations whose
   reference translation equals the odometry's to < 1 mm, and the laser-only error on those and
   on the rest.
3. An upper bound for any odometry fusion: per relation, the laser-only relative pose replaced
   by (or mixed with) the odometry's whenever the two agree within a gate.

Not a test; needs ../shared/data.

    python benchmarks/csail_odometry.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

CSAIL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mit-csail"


def _relative_errors(stamps: np.ndarray, poses: np.ndarray, rel: object) -> np.ndarray:
    """(n, 3) error of the relative pose x_t1⁻¹ ⊕ x_t2 against each relation (frame of t1)."""
    i1 = np.searchsorted(stamps, rel.t1 - 1e-3)  # type: ignore[attr-defined]
    i2 = np.searchsorted(stamps, rel.t2 - 1e-3)  # type: ignore[attr-defined]
    a, b = poses[i1], poses[i2]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    ex = c * dx + s * dy - rel.dx  # type: ignore[attr-defined]
    ey = -s * dx + c * dy - rel.dy  # type: ignore[attr-defined]
    et = np.angle(np.exp(1j * (b[:, 2] - a[:, 2] - rel.dyaw)))  # type: ignore[attr-defined]
    return np.column_stack((ex, ey, et))


def main() -> None:
    from dynslam2d.config import Config
    from dynslam2d.eval.relations import relation_errors
    from dynslam2d.inputs import open_source
    from dynslam2d.io.relations import read_relations
    from dynslam2d.pipeline import run

    log, relf = CSAIL / "mit-csail.clf", CSAIL / "mit-csail.relations"
    rel = read_relations(relf)
    runs = {}
    for name, odom, slam in (("laser only (--odom none)", "none", {}),
                             ("FLASER odometry, default prior (--odom auto)", "auto", {}),
                             ("FLASER odometry, slam.odometry_prior: all", "auto", {"odometry_prior": "all"})):
        src = open_source(log, odom=odom)
        res = run(src, Config(slam=slam))
        r = relation_errors(res.trajectory, rel.t1, rel.t2, rel.dx, rel.dy, rel.dyaw)
        runs[name] = res.trajectory
        print(f"| {name} | {r.trans_mean:.4f} ± {r.trans_std:.4f} | {r.rot_deg_mean:.3f} ± {r.rot_deg_std:.3f} |")
    scans = list(open_source(log, odom="auto"))
    stamps = np.array([s.stamp for s in scans])
    odo = np.array([s.odom.as_array() for s in scans])
    laser = runs["laser only (--odom none)"]
    e_odo = _relative_errors(stamps, odo, rel)
    e_las = _relative_errors(laser.stamps, laser.poses, rel)
    t_odo, t_las = np.hypot(*e_odo[:, :2].T), np.hypot(*e_las[:, :2].T)
    exact = t_odo < 1e-3
    print(f"\nrelations whose reference translation equals the odometry's to < 1 mm: {exact.sum()} of {exact.size} "
          f"({100 * exact.mean():.1f} %); laser-only error there {t_las[exact].mean():.4f} m, "
          f"elsewhere {t_las[~exact].mean():.4f} m; odometry error median {np.median(t_odo):.4f} m, "
          f"mean {t_odo.mean():.3f} m")
    gap = np.hypot(*(e_odo[:, :2] - e_las[:, :2]).T)
    print("\nper-relation fusion bound (laser-only relation moved by w towards the odometry's where they agree "
          "within the gate):")
    print("| gate m | w | mean translation error m |")
    print("|---|---|---|")
    for g in (0.05, 0.1, 0.2):
        for w in (0.3, 0.5, 1.0):
            f = e_las[:, :2] + ((gap < g) * w)[:, None] * (e_odo[:, :2] - e_las[:, :2])
            print(f"| {g} | {w} | {np.hypot(*f.T).mean():.4f} |")


if __name__ == "__main__":
    main()
