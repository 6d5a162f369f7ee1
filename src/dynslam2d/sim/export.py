"""Write a simulated run to disk: the scans as a bag, the ground truth, an overview PNG.

This is what ``dynslam2d simulate SCENARIO --out DIR`` produces; the folder then
serves both as an input (``scans.mcap``) and as ``--gt DIR`` for evaluation.
Ground truth is written in the first-scan frame (see
:mod:`dynslam2d.io.groundtruth`).
"""

from __future__ import annotations

import os
from pathlib import Path

from dynslam2d.io.groundtruth import write_ground_truth_folder
from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.io.trajectory import Trajectory
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
    bag = write_scan_bag(
        out / SCAN_BAG_NAMES[storage], sim.scans, topic=topic, storage="sqlite3" if storage == "sqlite3" else None
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
    files = write_ground_truth_folder(
        out,
        trajectory=Trajectory(stamps=gt.stamps.copy(), poses=gt.poses_in("first")),
        static_map=gt.static_map(map_resolution, frame="first"),
        labels=gt.labels,
        mover_rows=gt.mover_rows(frame="first"),
        info=info,
    )
    overview = plot_overview(sim, out / "overview.png")
    paths = {p.name: p for p in files}
    paths["scans"] = bag
    paths["overview.png"] = Path(overview)
    return paths
