"""Simulated 2D LiDAR scenes with exact ground truth.

Quick use::

    from dynslam2d.sim import simulate, SimSource, SCENARIOS
    sim = simulate("paper", duration=10)       # scans + ground truth
    gt = sim.ground_truth
    gt.poses            # (n, 3) laser poses, world frame
    gt.poses_in("first")  # same, in the first-scan frame (SLAM's map frame)
    gt.labels           # (n, beams) int16: -1 none, 0 static, k mover k
    gt.mover_rows()     # structured rows: stamp,id,kind,x,y,heading,length,width,vx,vy,hits
    gt.static_map(0.05) # GridMap of the walls
    src = SimSource("crowd", seed=3)  # a ScanSource for the pipeline

See :mod:`dynslam2d.sim.simulation` for the frames and
:mod:`dynslam2d.sim.scenarios` for the registered scenes.
"""

from dynslam2d.sim.movers import (
    Circle,
    Keyframes,
    Mover,
    MoverState,
    Rect,
    loop_path,
    ping_pong,
    random_waypoints,
    square_loop,
    timeline,
)
from dynslam2d.sim.overview import plot_overview
from dynslam2d.sim.robot import ScriptedRobot, oscillating_in_place, waypoint_path
from dynslam2d.sim.scenarios import SCENARIOS, Scenario, ScenarioSpec, build_scenario, paper_room
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.simulation import MOVER_ROW_FIELDS, GroundTruth, SimSource, Simulation, simulate
from dynslam2d.sim.world import (
    LABEL_NONE,
    LABEL_STATIC,
    World,
    cast_rays,
    point_segment_distance,
    polyline_segments,
    rect_corners,
    rect_segments,
)

__all__ = [
    "LABEL_NONE",
    "LABEL_STATIC",
    "MOVER_ROW_FIELDS",
    "SCENARIOS",
    "Circle",
    "GroundTruth",
    "Keyframes",
    "LidarModel",
    "Mover",
    "MoverState",
    "Rect",
    "Scenario",
    "ScenarioSpec",
    "ScriptedRobot",
    "SimSource",
    "Simulation",
    "World",
    "build_scenario",
    "cast_rays",
    "loop_path",
    "oscillating_in_place",
    "paper_room",
    "ping_pong",
    "plot_overview",
    "point_segment_distance",
    "polyline_segments",
    "random_waypoints",
    "rect_corners",
    "rect_segments",
    "simulate",
    "square_loop",
    "timeline",
    "waypoint_path",
]
