"""Why the laser-only ego path on the datmo bags is short: offset, timing or scale?

Prints three tables (docs/slam.md, "Odometry and IMU" quotes them):

1. **Path lengths** over the scan time span: motion capture (``/ego_pose``) at 120 Hz for
   the body origin and for the laser point (0.12 m behind it), the laser point sampled
   at the scan stamps, wheel/IMU dead reckoning (:mod:`dynslam2d.io.odombag`) and
   laser-only SLAM; plus the SLAM/mocap ratio of the distance covered over 0.4 s windows
   (5 scans; per-scan jitter adds length to the raw sum), the similarity-fit scale and
   the ATE (``dynslam2d.eval.trajectory.ate``, association within 10 ms, SE(2) aligned).
2. **Range scale**: every scan registered with the motion-capture laser poses (no SLAM),
   ranges multiplied by k; the number of 5 cm cells hit by static points (the red car
   removed) is smallest — the map is crispest — at the lidar's true range scale. A time
   shift of the scans against motion capture is searched as well.
3. **SLAM with ranges × k** for the k table 2 finds: the same figures as table 1.
4. **The full pipeline with wheel + IMU odometry and ``--range-scale auto``** against laser only
   (ranges × 1, and ranges × the same estimated k): estimated k, distance over 0.4 s windows / mocap, ATE.

Not a test; needs ../shared/data. ``--quick`` skips tables 2 and 3; ``--range-scale-only`` prints table 4 only.

    python benchmarks/datmo_odometry.py [--quick] [--scale 1.05] [--range-scale-only]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

DATMO = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "dynamic" / "datmo"
BAGS = ("intersection", "overtake_ego", "overtake_red", "overtakes", "parallel")
LASER = (-0.12, 0.0, 0.0)  # laser pose in the /ego_pose body frame (datmo's launch file)


def _length(xy: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) if len(xy) > 1 else 0.0


def _similarity_scale(ref: np.ndarray, est: np.ndarray) -> float:
    """Scale s of the least-squares similarity ref ≈ s·R·est + t (Umeyama 1991)."""
    a = ref - ref.mean(axis=0)
    b = est - est.mean(axis=0)
    u, d, vt = np.linalg.svd(a.T @ b / len(a))
    sign = np.ones(2)
    if np.linalg.det(u @ vt) < 0:
        sign[-1] = -1
    return float((d * sign).sum() / (b ** 2).sum(axis=1).mean())


class _Mocap:
    """Laser-point poses from /ego_pose (and the red car's positions)."""

    def __init__(self, bag: Path) -> None:
        from dynslam2d.io.odometry import compose_mount
        from dynslam2d.io.rosbag import read_pose_topic
        from dynslam2d.types import Pose2D

        ego = read_pose_topic(bag, "/ego_pose")
        self.red = read_pose_topic(bag, "/red_pose")
        self.t = ego.stamps
        self.body = np.column_stack((ego.xy, np.unwrap(ego.yaw)))
        self.laser = compose_mount(self.body, Pose2D(*LASER))
        self.laser[:, 2] = self.body[:, 2] + LASER[2]  # unwrapped heading

    def laser_at(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, self.t, self.laser[:, j]) for j in range(3)])

    def red_at(self, t: float) -> np.ndarray:
        return np.array([np.interp(t, self.red.stamps, self.red.xy[:, j]) for j in range(2)])


def _window_ratio_and_ate(mocap: _Mocap, st: np.ndarray, est: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(distance over 0.4 s windows (5 scans) / mocap's where mocap moved, ATE RMSE m, mocap laser poses at ``st``)."""
    from dynslam2d.eval.trajectory import ate
    from dynslam2d.io.trajectory import Trajectory

    ref = mocap.laser_at(st)
    k = 5
    d_ref = np.hypot(*(ref[k:, :2] - ref[:-k, :2]).T)
    d_est = np.hypot(*(est[k:, :2] - est[:-k, :2]).T)
    moving = d_ref > 0.1
    a = ate(Trajectory(mocap.t, mocap.laser), Trajectory(st, est))
    return float(d_est[moving].sum() / d_ref[moving].sum()), float(a.trans.rmse), ref


def _pipeline_row(bag: Path, mocap: _Mocap, odom: str, scale: float | str) -> tuple[float, float, float | None]:
    """Full default pipeline with ``--odom odom --imu odom --laser-offset LASER --range-scale scale``:
    (distance over 0.4 s windows / mocap, ATE RMSE m, the range scale used)."""
    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run
    from dynslam2d.types import Pose2D

    src = open_source(bag, odom=odom, imu=odom, laser_offset=Pose2D(*LASER))
    result = run(src, Config(laser={"range_scale": scale}))
    ratio, rmse, _ = _window_ratio_and_ate(mocap, result.trajectory.stamps, result.trajectory.poses)
    used = (src.meta.extra.get("range_scale") or {}).get("used")
    return ratio, rmse, used


def _range_scale_table(bags: list[tuple[str, Path]]) -> None:
    rows = []
    for name, bag in bags:
        mocap = _Mocap(bag)
        r_odo, a_odo, k = _pipeline_row(bag, mocap, "auto", "auto")
        r_l1, a_l1, _ = _pipeline_row(bag, mocap, "none", 1.0)
        r_lk, a_lk, _ = _pipeline_row(bag, mocap, "none", float(k))
        r_o1, a_o1, _ = _pipeline_row(bag, mocap, "auto", 1.0)
        rows.append([name, f"{k:.3f}", f"{r_l1:.3f} / {a_l1:.3f}", f"{r_o1:.3f} / {a_o1:.3f}",
                     f"{r_lk:.3f} / {a_lk:.3f}", f"**{r_odo:.3f} / {a_odo:.3f}**"])
    print("Table 4: full pipeline; distance over 0.4 s windows / mocap and ATE RMSE m")
    _table(("bag", "range scale k (auto, from wheel + IMU)", "laser only, × 1", "wheel + IMU, × 1",
            "laser only, × k", "wheel + IMU, --range-scale auto"), rows)


def _slam_row(bag: Path, mocap: _Mocap, scale: float = 1.0) -> list[str]:
    """Laser-only SLAM (ranges × scale): length, 0.4 s window ratio, similarity scale, ATE."""
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run

    src = open_source(bag, odom="none", imu="none")
    if scale != 1.0:
        scans = [s.with_ranges(s.ranges * scale) for s in src]

        class _List:
            meta = src.meta

            def __iter__(self):  # type: ignore[no-untyped-def]
                return iter(scans)

            def __len__(self) -> int:
                return len(scans)

        result = run(_List())
    else:
        result = run(src)
    est = result.trajectory.poses
    ratio, rmse, ref = _window_ratio_and_ate(mocap, result.trajectory.stamps, est)
    return [f"{_length(est[:, :2]):.3f}", f"{ratio:.3f}", f"{_similarity_scale(ref[:, :2], est[:, :2]):.3f}",
            f"{rmse:.3f}"]


def _crispness(scans: list, mocap: _Mocap, k: float, dt: float) -> int:
    """Number of 5 cm cells hit by the static points of all scans placed with mocap poses."""
    from dynslam2d.types import Pose2D

    cells = []
    for s in scans:
        pose = Pose2D(*mocap.laser_at(np.array([s.stamp + dt]))[0])
        m = s.valid_mask(min_range=0.3)
        a, r = s.angles[m], s.ranges[m] * k
        w = pose.transform_points(np.column_stack((r * np.cos(a), r * np.sin(a))))
        w = w[np.hypot(*(w - mocap.red_at(s.stamp + dt)).T) > 0.5]  # drop the red car
        cells.append(np.floor(w / 0.05).astype(np.int64))
    return int(np.unique(np.vstack(cells), axis=0).shape[0])


def _table(head: tuple[str, ...], rows: list[list[str]]) -> None:
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="table 1 only")
    ap.add_argument("--scale", type=float, default=None, help="range scale for table 3 (default: table 2's median)")
    ap.add_argument("--range-scale-only", action="store_true", help="table 4 only")
    args = ap.parse_args()
    if args.range_scale_only:
        _range_scale_table([(n, DATMO / f"{n}.bag") for n in BAGS if (DATMO / f"{n}.bag").exists()])
        return
    from dynslam2d.inputs import open_source
    from dynslam2d.io.odombag import read_bag_odometry
    from dynslam2d.io.odometry import compose_mount
    from dynslam2d.types import Pose2D

    mount = Pose2D(*LASER)
    rows1, rows2, best_k = [], [], []
    bags = [(n, DATMO / f"{n}.bag") for n in BAGS if (DATMO / f"{n}.bag").exists()]
    for name, bag in bags:
        scans = list(open_source(bag, odom="none", imu="none"))
        st = np.array([s.stamp for s in scans])
        mocap = _Mocap(bag)
        keep = (mocap.t >= st[0]) & (mocap.t <= st[-1])
        ref = mocap.laser_at(st)
        info = read_bag_odometry(bag, scans[0].frame_id, laser_offset=mount)
        base, ok = info.track.at(st)
        dr = compose_mount(base[ok], mount)
        yaw_ref = float(ref[-1, 2] - ref[0, 2])
        sel = (info.imu.stamps >= st[0]) & (info.imu.stamps <= st[-1])
        w, t = info.imu.yaw_rate[sel], info.imu.stamps[sel]
        yaw_imu = float(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(t)))
        rows1.append([name, f"{_length(mocap.body[keep, :2]):.3f}", f"{_length(mocap.laser[keep, :2]):.3f}",
                      f"{_length(ref[:, :2]):.3f}", f"{_length(dr[:, :2]):.3f}",
                      f"{_length(dr[:, :2]) / _length(ref[ok, :2]):.3f}",
                      f"{yaw_imu / yaw_ref:.3f}" if abs(yaw_ref) > 1.0 else "—",
                      *_slam_row(bag, mocap)])
        if not args.quick:
            grid = {(dt, k): _crispness(scans, mocap, k, dt)
                    for dt in (-0.04, 0.0, 0.04) for k in (0.98, 1.0, 1.02, 1.04, 1.06, 1.08, 1.10)}
            (dt, k) = min(grid, key=grid.get)
            best_k.append(k)
            rows2.append([name, f"{k:.2f}", f"{dt:+.2f}", str(grid[(0.0, 1.0)]), str(grid[(dt, k)])])
    print("Table 1: path lengths (m) over the scans' time span, laser-only SLAM vs motion capture")
    _table(("bag", "mocap body 120 Hz", "mocap laser 120 Hz", "mocap laser @scans", "wheel+IMU dead reckoning",
            "DR / mocap", "IMU Δyaw / mocap", "SLAM", "SLAM / mocap (0.4 s windows)", "similarity scale", "ATE m"),
           rows1)
    if args.quick:
        return
    print("Table 2: scans placed with motion-capture poses, ranges × k: 5 cm cells hit (fewer = crisper)")
    _table(("bag", "best k", "best time shift s", "cells at k=1, shift 0", "cells at best"), rows2)
    scale = args.scale if args.scale is not None else float(np.median(best_k))
    rows3 = [[name, *_slam_row(bag, _Mocap(bag), scale)] for name, bag in bags]
    print(f"Table 3: laser-only SLAM with ranges × {scale:.2f}")
    _table(("bag", "SLAM length", "SLAM / mocap (0.4 s windows)", "similarity scale", "ATE m"), rows3)
    _range_scale_table(bags)


if __name__ == "__main__":
    main()
