"""Robust SLAM on the scenes built to break it (not run by pytest; numbers in docs/slam.md).

For ``sim:long-corridor`` (only the side walls in range for > 12 m stretches) and
``sim:occlusion`` (a person stands against and pushes through the sensor), the full
pipeline (``dynslam2d.pipeline.run``, default configuration) runs

  * laser only, and
  * with noisy wheel odometry attached to every scan (``Scan.with_odometry``): each step's
    ground-truth motion plus Gaussian noise of ``--odom-noise`` × the step length
    (default 2 %) in x, y and 0.1 × that in θ (rad per m),

and prints ATE RMSE (SE(2)-aligned), the largest heading error, path length against ground
truth, and the pose-confidence block of summary.json (degenerate share and longest stretch,
low-support share, lost events). ``--legacy`` adds a run with the guards of issue 10 switched
off (no motion prior / gating / too-close and narrow-view checks): today's behaviour.

    python benchmarks/bench_robust.py [--scenes long-corridor occlusion] [--odom-noise 0.02] [--legacy]
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def noisy_odometry(gt: np.ndarray, sigma: float, seed: int = 1) -> list:
    """Odometry poses (first frame) from ground-truth laser poses ``gt`` (n, 3): every step's motion
    plus N(0, (sigma·step)²) in x, y and N(0, (0.1·sigma·step)²) in θ."""
    from dynslam2d.types import Pose2D

    rng = np.random.default_rng(seed)
    out = [Pose2D(*gt[0])]
    for i in range(1, gt.shape[0]):
        d = Pose2D(*gt[i - 1]).between(Pose2D(*gt[i]))
        n = rng.normal(0.0, sigma * math.hypot(d.x, d.y) + 1e-6, 3)
        out.append(out[-1].compose(Pose2D(d.x + n[0], d.y + n[1], d.theta + 0.1 * n[2])))
    return out


class _Source:
    def __init__(self, scans, meta) -> None:
        self._scans, self.meta = scans, meta

    def __iter__(self):
        return iter(self._scans)


def _path(xy: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(xy[:, :2], axis=0).T)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["long-corridor", "occlusion"])
    ap.add_argument("--odom-noise", type=float, default=0.02)
    ap.add_argument("--legacy", action="store_true")
    args = ap.parse_args()

    from dynslam2d.config import Config, with_overrides
    from dynslam2d.eval.trajectory import ate
    from dynslam2d.io.trajectory import Trajectory
    from dynslam2d.pipeline import run
    from dynslam2d.sim import SimSource
    from dynslam2d.types import wrap_angle

    legacy = {"slam": {"motion_prior": False, "too_close_fraction": 1.0, "min_sector": 0.0,
                       "max_linear_accel": 1e6, "max_angular_accel": 1e6, "prior_weight": 0.0}}
    for name in args.scenes:
        src = SimSource(name)
        sim = src.simulation
        gt = sim.ground_truth.poses_in("first")
        stamps = sim.ground_truth.stamps
        odom = noisy_odometry(gt, args.odom_noise)
        bare = [s.with_odometry(None, None) for s in sim.scans]  # simulated scans carry odometry + IMU
        variants = [("laser only", bare, Config()),
                    (f"odometry ({100 * args.odom_noise:.0f} % noise)",
                     [s.with_odometry(o) for s, o in zip(sim.scans, odom)], Config())]
        if args.legacy:
            variants.append(("laser only, guards off", bare, with_overrides(Config(), legacy)))
        print(f"\n== sim:{name}: {len(gt)} scans, ground-truth path {_path(gt):.2f} m ==")
        for label, scans, cfg in variants:
            res = run(_Source(scans, src.meta), cfg)
            est = res.trajectory.poses
            a = ate(Trajectory(stamps, gt), res.trajectory)
            head = float(np.degrees(np.abs(wrap_angle(est[:, 2] - gt[:, 2])).max()))
            gl, el = _path(gt), _path(est)
            rel = f"{100 * (el / gl - 1):+.2f} %" if gl > 1.0 else "—"
            pc = res.summary()["pose_confidence"]
            print(f"{label:28s} ATE {a.rmse:.4f} m, max heading error {head:.1f}°, path {el:.2f} m ({rel}); "
                  f"degenerate {100 * pc['degenerate_share']:.0f} % (longest {pc['longest_degenerate_s']:.1f} s), "
                  f"low support {100 * pc['low_support_share']:.1f} %, lost {pc['lost_events']}×; "
                  f"reasons {res.reasons}")


if __name__ == "__main__":
    main()
