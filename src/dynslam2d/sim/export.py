"""Write a simulated run to disk: the scans as a bag, the ground truth, an overview PNG.

This is what ``dynslam2d simulate SCENARIO --out DIR`` produces; the folder then
serves both as an input (``scans.mcap``) and as ``--gt DIR`` for evaluation.
Ground truth is written in the first-scan frame (see
:mod:`dynslam2d.io.groundtruth`). The simulated odometry goes into the bag as
``/odom`` (nav_msgs/Odometry), ``/tf`` (odom → base_link), ``/tf_static``
(base_link → laser) and ``/imu`` (sensor_msgs/Imu yaw rate), and beside the ground
truth as ``odom.tum``: the noisy odometry's laser poses at the scan stamps,
re-anchored so the first is the origin (the frame of ``trajectory.tum``), so
``dynslam2d eval ate DIR/trajectory.tum DIR/odom.tum`` scores odometry alone.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from dynslam2d.io.groundtruth import write_ground_truth_folder
from dynslam2d.io.odombag import write_scan_bag_with_odometry
from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.io.trajectory import Trajectory, write_tum
from dynslam2d.sim.overview import plot_overview
from dynslam2d.sim.simulation import Simulation

#: Bag names by storage: a bare MCAP file is the most portable (rosbags, Foxglove, ros2 bag ≥ Iron).
SCAN_BAG_NAMES = {"mcap": "scans.mcap", "sqlite3": "scans_db3", "ros1": "scans.bag"}


def write_simulation(
    sim: Simulation,
    out_dir: str | os.PathLike[str],
    *,
    map_resolution: float = 0.05,
    storage: str = "mcap",
    topic: str = "/scan",
) -> dict[str, Path]:
    """Write ``sim`` into ``out_dir``; return the written paths by role.

    Args:
        map_resolution: cell side of the ground-truth map, m.
        storage: "mcap" (bare ``scans.mcap``), "sqlite3" (ROS 2 bag folder ``scans_db3``)
            or "ros1" (``scans.bag``).
    """
    if storage not in SCAN_BAG_NAMES:
        from dynslam2d.errors import DynSlamError

        raise DynSlamError(f"unknown bag storage {storage!r} (use one of {', '.join(SCAN_BAG_NAMES)})")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    gt = sim.ground_truth
    scenario = sim.scenario
    bag_storage = "sqlite3" if storage == "sqlite3" else None
    odo = sim.odometry
    if odo is None:
        bag = write_scan_bag(out / SCAN_BAG_NAMES[storage], sim.scans, topic=topic, storage=bag_storage)
    else:
        bag = write_scan_bag_with_odometry(
            out / SCAN_BAG_NAMES[storage], sim.scans, odo.track, odo.mount, twist=odo.twist, imu=odo.imu,
            imu_frame=odo.model.imu_frame, storage=bag_storage, topic=topic,
        )
    lidar = scenario.lidar
    info = {
        "scenario": scenario.name,
        "description": scenario.description,
        "seed": scenario.seed,
        "duration_s": float(scenario.duration),
        "scans": len(sim.scans),
        "frame": "first-scan laser frame (the SLAM map frame)",
        "world_to_first": [float(v) + 0.0 for v in gt.world_to_first().as_array()],
        "map_resolution_m": float(map_resolution),
        "sensor": {
            "beams": int(lidar.beams),
            "fov_rad": float(lidar.fov),
            "rate_hz": float(lidar.rate_hz),
            "range_min_m": float(lidar.range_min),
            "range_max_m": float(lidar.range_max),
            "frame_id": lidar.frame_id,
        },
        "movers": [{"id": int(m.id), "name": m.name, "kind": m.kind} for m in scenario.movers],
    }
    if odo is not None:
        info["odometry"] = {
            "topics": {"odom": "/odom", "tf": "/tf", "tf_static": "/tf_static", "imu": "/imu"},
            "mount_base_to_laser": [odo.mount.x, odo.mount.y, odo.mount.theta],
            "model": dataclasses.asdict(odo.model),
        }
    files = write_ground_truth_folder(
        out,
        trajectory=Trajectory(stamps=gt.stamps.copy(), poses=gt.poses_in("first")),
        static_map=gt.static_map(map_resolution, frame="first"),
        labels=gt.labels,
        mover_rows=gt.mover_rows(frame="first"),
        info=info,
    )
    if odo is not None:
        files = [*files, _write_odom_tum(sim, out / "odom.tum")]
    overview = plot_overview(sim, out / "overview.png")
    paths = {p.name: p for p in files}
    paths["scans"] = bag
    paths["overview.png"] = Path(overview)
    return paths


def _write_odom_tum(sim: Simulation, path: Path) -> Path:
    """The noisy odometry's laser poses at the scan stamps, first pose at the origin (TUM)."""
    assert sim.odometry is not None
    stamps = sim.ground_truth.stamps
    laser, _ = sim.odometry.laser_poses(stamps)
    first = laser[0]
    c, s = np.cos(-first[2]), np.sin(-first[2])
    d = laser - first
    rel = np.column_stack((c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]))
    rel[:, 2] = (rel[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return write_tum(path, Trajectory(stamps=stamps.copy(), poses=rel),
                     comment="simulated wheel odometry (noisy), laser poses re-anchored at the first scan")
