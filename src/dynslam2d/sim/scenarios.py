"""The scenario registry: named scenes with a robot, movers and a LiDAR.

A :class:`Scenario` is everything needed to simulate: the static
:class:`~dynslam2d.sim.world.World`, the movers, the scripted robot, the sensor
model, a duration and a seed. All geometry is in the scenario's **world frame**
(m, rad); the first laser pose is generally not the world origin.

Registered scenes (``SCENARIOS``):

- ``paper``, ``paper-1``, ``paper-2``, ``paper-3`` — paper §3: a ≈10 m room, the
  robot oscillating in yaw at the centre, three boxes moving at > 0.5 m/s: a
  1×1 m box on a small square path, a 1×1 m box on a large square path, and a
  0.1×2 m bar back and forth on an L-shaped route. The room has a chamfered
  corner, an alcove, a door recess, wall pilasters, a pillar and a cabinet so
  scan matching is well constrained. The numbered variants stand in for the
  paper's three tests: different yaw amplitude/frequency, mover speeds,
  directions and phases.
- ``static`` — the same room, no movers; the robot yaws at up to ≈1 rad/s and
  shuttles a little.
- ``crowd`` — a 14×10 m hall, six people (discs, 0.4–0.5 m) on random-waypoint
  walks around a robot driving a rectangular circuit.
- ``drive`` — a robot driving at ≈1 m/s along a 24 m corridor with door
  recesses, through a doorway into a room and through a second doorway into
  another corridor (walls seen at grazing angles, a 270° laser); six people
  walk past, towards, across and ahead of it at 0.7–2.0 m/s, four stand still
  the whole time and one stands for 26 s (in view), then starts walking. Walking and
  standing people are movers (their beams carry their ids); whether a person
  walks at a scan is in the movers' exact velocities (``movers.csv``), which
  :mod:`dynslam2d.eval.motionclass` uses to split the removal metrics.
- ``corridor`` — a 30 m corridor with door recesses and a side room; people
  walking both ways, a cart shuttling, a person wandering in the side room;
  the robot drives along it.
- ``stop-and-go`` — a box arrives through a doorway and parks; a parked car
  waits, then leaves through the doorway and parks outside; a person walks
  back and forth with long stops at both ends.
- ``long-corridor`` — a 60 m corridor, 2.4 m wide, seen by a 6 m laser while the
  robot drives it at 1 m/s: for two stretches of more than 12 m only the two side
  walls are in range (the scan cannot tell where along the corridor it is); two
  people walk along it.
- ``occlusion`` — an office (the paper room) and a 240° laser on a robot yawing in
  place; a person walks up, stands pressed against the sensor for 1 s (over half
  the beams blocked or too close) and then pushes through it (5 scans see nothing
  but the person from inside).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.sim.movers import (
    Circle,
    Keyframes,
    Mover,
    Rect,
    ping_pong,
    random_waypoints,
    square_loop,
    timeline,
)
from dynslam2d.sim.robot import ScriptedRobot, oscillating_in_place, waypoint_path
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.world import World, polyline_segments, rect_corners, rect_segments


@dataclass(frozen=True, eq=False)
class Scenario:
    """A complete simulated scene.

    Attributes:
        name: registry name (or any label for a hand-built scene).
        description: one line for listings.
        world: static structure, world frame.
        movers: moving objects (ids 1..k, the per-beam labels of their hits).
        robot: scripted laser pose over time, world frame.
        lidar: the sensor model.
        duration: simulated time span, s; scans are taken at ``i / rate_hz``.
        seed: seed of every random draw (random walks, range noise, dropout).
    """

    name: str
    description: str
    world: World
    movers: tuple[Mover, ...]
    robot: ScriptedRobot
    lidar: LidarModel
    duration: float
    seed: int

    @property
    def n_scans(self) -> int:
        """Number of scans: one every ``1/rate_hz`` s from t = 0, while t < duration."""
        return max(1, int(math.ceil(self.duration * self.lidar.rate_hz - 1e-9)))

    @property
    def stamps(self) -> np.ndarray:
        """(n_scans,) scan stamps, s since the start."""
        return np.arange(self.n_scans) / self.lidar.rate_hz

    def mover(self, mover_id: int) -> Mover:
        """The mover with this id (DynSlamError if none)."""
        for m in self.movers:
            if m.id == mover_id:
                return m
        raise DynSlamError(f"scenario {self.name!r}: no mover with id {mover_id}")


@dataclass(frozen=True)
class ScenarioSpec:
    """A registry entry: ``spec(seed=None, duration=None) -> Scenario``."""

    builder: Callable[[int, float], Scenario]
    seed: int
    duration: float
    description: str

    def __call__(self, seed: int | None = None, duration: float | None = None) -> Scenario:
        return self.builder(self.seed if seed is None else int(seed),
                            self.duration if duration is None else float(duration))


# --------------------------------------------------------------------------- rooms

def _solid(cx: float, cy: float, length: float, width: float, heading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Outline segments and polygon of a solid rectangular obstacle."""
    return rect_segments(cx, cy, heading, length, width), rect_corners(cx, cy, heading, length, width)


def _build_world(outline: list[tuple[float, float]], solids: list[tuple[np.ndarray, np.ndarray]],
                 extra_segments: list[np.ndarray] | None = None,
                 extra_interior: list[list[tuple[float, float]]] | None = None) -> World:
    segs = [polyline_segments(outline, closed=True)] + [s for s, _ in solids] + list(extra_segments or [])
    interior = [np.asarray(outline)] + [np.asarray(p) for p in (extra_interior or [])]
    return World(np.vstack(segs), interior=interior, solids=[p for _, p in solids])


#: The paper room's outline (≈10×10 m, counter-clockwise): chamfered lower-left
#: corner, an alcove in the right wall, a door recess in the top wall.
_PAPER_OUTLINE = [
    (-4.0, -5.0), (5.0, -5.0), (5.0, 0.5), (5.8, 0.5), (5.8, 2.0), (5.0, 2.0), (5.0, 5.0),
    (1.5, 5.0), (1.5, 5.6), (0.3, 5.6), (0.3, 5.0), (-5.0, 5.0), (-5.0, -4.0),
]


def _pilasters() -> list[tuple[np.ndarray, np.ndarray]]:
    """Two 0.3 m wall pilasters (bottom wall at x≈0.15, left wall at y≈0.65)."""
    return [_solid(0.15, -4.85, 0.3, 0.3), _solid(-4.85, 0.65, 0.3, 0.3)]


def paper_room() -> World:
    """The static room of the ``paper`` scenes, world frame centred on the room."""
    solids = _pilasters() + [_solid(2.0, 2.2, 0.5, 0.5), _solid(-2.2, -2.4, 1.2, 0.6)]
    return _build_world(_PAPER_OUTLINE, solids)


def _lidar(**overrides: float) -> LidarModel:
    return dataclasses.replace(LidarModel(), **overrides)


# --------------------------------------------------------------------------- paper

@dataclass(frozen=True)
class _PaperVariant:
    yaw_amplitude: float  # rad
    yaw_period: float  # s
    speeds: tuple[float, float, float]  # small square, large square, L bar; m/s
    phases: tuple[float, float, float]  # fraction of each period travelled at t = 0
    clockwise: tuple[bool, bool] = (False, False)
    bar_pause: float = 0.0  # s at each end of the L
    sway: tuple[tuple[float, float], ...] = ()
    heading: float = 0.0  # robot's mean heading, rad (the first scan's frame differs from the world's)
    yaw_phase: float = 0.0  # rad


_PAPER_VARIANTS = {
    "paper": _PaperVariant(0.5, 8.0, (0.6, 0.8, 0.7), (0.0, 0.0, 0.0)),
    "paper-1": _PaperVariant(0.35, 10.0, (0.6, 0.7, 0.6), (0.1, 0.3, 0.0)),
    "paper-2": _PaperVariant(0.8, 5.0, (0.9, 1.2, 1.0), (0.25, 0.5, 0.3), (True, False), 0.0,
                             ((0.3, 0.2),), heading=0.3),
    "paper-3": _PaperVariant(0.6, 7.0, (0.7, 1.0, 0.8), (0.5, 0.75, 0.6), (False, True), 0.3,
                             heading=-0.4, yaw_phase=1.0),
}


def _paper_movers(v: _PaperVariant) -> tuple[Mover, ...]:
    """Paper §3 movers: 1×1 box on a small square, 1×1 box on a large square,
    0.1×2 bar (0.1 along x, 2 along y) back and forth on an L."""
    small = square_loop((-2.0, 2.0), 1.4, v.speeds[0], heading=0.0, phase=v.phases[0], clockwise=v.clockwise[0])
    large = square_loop((0.0, 0.0), 7.6, v.speeds[1], heading=0.0, phase=v.phases[1], clockwise=v.clockwise[1])
    bar = ping_pong([(1.0, -2.0), (2.7, -2.0), (2.7, -0.5)], v.speeds[2], heading=0.0, pause=v.bar_pause,
                    phase=v.phases[2])
    return (
        Mover(1, "box-small-square", Rect(1.0, 1.0), small),
        Mover(2, "box-large-square", Rect(1.0, 1.0), large),
        Mover(3, "bar-L-route", Rect(0.1, 2.0), bar),
    )


def _paper_builder(name: str) -> Callable[[int, float], Scenario]:
    v = _PAPER_VARIANTS[name]

    def build(seed: int, duration: float) -> Scenario:
        robot = oscillating_in_place(0.0, 0.0, v.heading, v.yaw_amplitude, v.yaw_period, phase=v.yaw_phase,
                                     sway=list(v.sway) or None)
        return Scenario(name, _PAPER_DESCRIPTIONS[name], paper_room(), _paper_movers(v), robot, _lidar(),
                        duration, seed)

    return build


_PAPER_DESCRIPTIONS = {
    "paper": "paper §3 scene: robot yawing ±0.5 rad in a 10 m room, 1×1 boxes on small/large squares, "
             "0.1×2 bar on an L",
    "paper-1": "paper scene, test 1: gentle yaw (±0.35 rad, 10 s), slower movers",
    "paper-2": "paper scene, test 2: fast yaw (±0.8 rad, 5 s), robot sways, fast movers, small loop clockwise",
    "paper-3": "paper scene, test 3: ±0.6 rad / 7 s yaw, large loop clockwise, bar pauses at the L ends",
}


# --------------------------------------------------------------------------- static

def _build_static(seed: int, duration: float) -> Scenario:
    # max yaw rate = A·2π/T = 1.25·2π/8 ≈ 0.98 rad/s
    robot = oscillating_in_place(0.0, 0.0, 0.0, 1.25, 8.0, sway=[(0.8, 0.4)], sway_speed=0.1)
    return Scenario("static", "paper room without movers; robot yaws up to ≈1 rad/s and shuttles 0.9 m",
                    paper_room(), (), robot, _lidar(), duration, seed)


# --------------------------------------------------------------------------- crowd

_HALL_OUTLINE = [
    (-7.0, -5.0), (-1.0, -5.0), (-1.0, -5.5), (0.5, -5.5), (0.5, -5.0), (7.0, -5.0), (7.0, 3.5),
    (5.5, 5.0), (-3.0, 5.0), (-3.0, 5.7), (-4.2, 5.7), (-4.2, 5.0), (-7.0, 5.0),
]


def _build_crowd(seed: int, duration: float) -> Scenario:
    rng = np.random.default_rng([seed, 11])
    solids = [_solid(5.6, 0.0, 0.4, 0.4), _solid(-5.6, 1.2, 0.4, 0.4), _solid(-5.6, -2.0, 0.8, 0.5, 0.4)]
    world = _build_world(_HALL_OUTLINE, solids)
    robot = waypoint_path([(-4.0, -2.5), (4.0, -2.5), (4.0, 2.5), (-4.0, 2.5)], speed=0.4, turn_rate=0.8,
                          wobble_amplitude=0.1, wobble_period=3.0)
    # walking areas never reach the robot's circuit (≥ 0.45 m clearance) nor the pillars
    regions = [(-3.2, 3.2, -1.7, 1.7)] * 3 + [(-6.4, 5.0, 3.2, 4.4)] * 2 + [(-6.4, 6.4, -4.4, -3.2)]
    movers = []
    for k, region in enumerate(regions, start=1):
        radius = float(rng.uniform(0.2, 0.25))
        walk = random_waypoints(rng, region, duration + 5.0, speed_range=(0.6, 1.4), pause_range=(0.0, 2.0))
        movers.append(Mover(k, f"person-{k}", Circle(radius), walk))
    return Scenario("crowd", "14×10 m hall, six people on random-waypoint walks, robot on a rectangular circuit",
                    world, tuple(movers), robot, _lidar(), duration, seed)


# --------------------------------------------------------------------------- corridor

_CORRIDOR_OUTLINE = [
    (0.0, -1.25), (8.0, -1.25), (8.0, -1.65), (9.0, -1.65), (9.0, -1.25), (22.5, -1.25), (22.5, -1.65),
    (23.5, -1.65), (23.5, -1.25), (30.0, -1.25), (30.0, 1.25), (18.2, 1.25), (18.2, 1.65), (17.0, 1.65),
    (17.0, 1.25), (14.0, 1.25), (14.0, 3.75), (11.0, 3.75), (11.0, 1.25), (5.2, 1.25), (5.2, 1.65),
    (4.0, 1.65), (4.0, 1.25), (0.0, 1.25),
]


def _build_corridor(seed: int, duration: float) -> Scenario:
    rng = np.random.default_rng([seed, 12])
    world = _build_world(_CORRIDOR_OUTLINE, [_solid(13.4, 3.2, 0.6, 0.6)])
    robot = waypoint_path([(1.0, -0.55), (29.0, -0.55)], speed=0.45, loop=False, wobble_amplitude=0.08,
                          wobble_period=2.5)
    movers = (
        Mover(1, "person-lane-1", Circle(0.22), ping_pong([(3.0, 0.45), (15.0, 0.45)], 1.2, heading=None,
                                                          phase=0.3)),
        Mover(2, "person-lane-2", Circle(0.22), ping_pong([(6.0, 0.85), (27.0, 0.85)], 0.9, heading=None,
                                                          phase=0.6)),
        Mover(3, "cart", Rect(1.0, 0.6), ping_pong([(17.0, 0.3), (28.0, 0.3)], 0.7, heading=None, pause=2.0)),
        Mover(4, "person-side-room", Circle(0.2),
              random_waypoints(rng, (11.4, 12.7, 1.8, 3.3), duration + 5.0, (0.5, 1.0), (0.5, 3.0))),
    )
    return Scenario("corridor", "30 m corridor with door recesses and a side room; two walkers, a cart, "
                    "a wanderer; robot drives its length", world, movers, robot, _lidar(), duration, seed)


# --------------------------------------------------------------------------- drive

#: Corridor A (x 0…24, y ±1.2) with door recesses, a doorway (y ±0.5, 0.15 m thick wall)
#: into room B (x 24.15…32, y −4…5), a doorway (x 28.9…30.1) into corridor C
#: (x 28.3…30.7, y 5.15…16). Counter-clockwise.
_DRIVE_OUTLINE = [
    (0.0, -1.2), (5.0, -1.2), (5.0, -1.5), (6.0, -1.5), (6.0, -1.2), (12.0, -1.2), (12.0, -1.8),
    (13.0, -1.8), (13.0, -1.2), (19.0, -1.2), (19.0, -1.5), (20.0, -1.5), (20.0, -1.2), (24.0, -1.2),
    (24.0, -0.5), (24.15, -0.5), (24.15, -4.0), (32.0, -4.0), (32.0, 5.0), (30.1, 5.0), (30.1, 5.15),
    (30.7, 5.15), (30.7, 16.0), (28.3, 16.0), (28.3, 5.15), (28.9, 5.15), (28.9, 5.0), (24.15, 5.0),
    (24.15, 0.5), (24.0, 0.5), (24.0, 1.2), (17.5, 1.2), (17.5, 1.5), (16.5, 1.5), (16.5, 1.2),
    (13.0, 1.2), (13.0, 1.8), (12.0, 1.8), (12.0, 1.2), (9.0, 1.2), (9.0, 1.5), (8.0, 1.5),
    (8.0, 1.2), (0.0, 1.2),
]

#: Radius of a simulated person (a disc at laser height), m.
_PERSON_RADIUS = 0.22


def _stand_then_shuttle(start: tuple[float, float], wait: float, route: list[tuple[float, float]],
                        speed: float, until: float) -> Keyframes:
    """Stand at ``start`` for ``wait`` s, then walk ``route`` back and forth at ``speed``
    m/s without stopping until at least ``until`` s (so it never stands again)."""
    steps: list[tuple] = [("wait", wait)]
    t, there = wait, True
    pts = [start, *route]
    while t <= until:
        leg = pts[1:] if there else pts[-2::-1]
        prev = pts[0] if there else pts[-1]
        for q in leg:
            steps.append(("go", q, speed))
            t += math.dist(prev, q) / speed
            prev = q
        there = not there
    return timeline(start, steps, heading=None)


def _build_drive(seed: int, duration: float) -> Scenario:
    solids = [_solid(25.0, 4.3, 1.2, 0.5), _solid(27.5, 2.5, 0.4, 0.4), _solid(30.55, 9.0, 0.3, 0.3),
              _solid(28.45, 13.0, 0.3, 0.3)]
    world = _build_world(_DRIVE_OUTLINE, solids)
    # ≈1 m/s; 0.8 rad/s turns in place at the waypoints; a slight yaw wobble of the platform
    robot = waypoint_path([(1.0, -0.2), (23.0, -0.2), (26.0, 0.0), (29.4, 3.0), (29.4, 14.5)], speed=1.0,
                          loop=False, wobble_amplitude=0.03, wobble_period=2.0)
    person = Circle(_PERSON_RADIUS)
    # phases put each walker where it passes the robot at a chosen place (checked in tests:
    # nobody comes within 0.5 m of the laser)
    movers = (
        Mover(1, "walker-oncoming", person, ping_pong([(2.0, 0.6), (23.0, 0.6)], 1.3, heading=None, phase=0.5)),
        Mover(2, "walker-overtaking", person, ping_pong([(0.5, -0.85), (18.0, -0.85)], 1.9, heading=None,
                                                        phase=0.83)),
        Mover(3, "walker-crossing", person, ping_pong([(12.5, -1.45), (12.5, 1.45)], 0.7, heading=None,
                                                      phase=0.16)),
        Mover(4, "walker-room-loop", person, ping_pong([(27.0, -3.2), (31.3, -3.2), (31.3, 4.3)], 1.0,
                                                       heading=None, phase=0.3)),
        Mover(5, "walker-room-across", person, ping_pong([(26.0, -2.4), (30.3, -2.4)], 1.5, heading=None)),
        Mover(6, "walker-corridor-c", person, ping_pong([(30.05, 15.5), (30.05, 6.0)], 2.0, heading=None)),
        Mover(7, "starts-walking", person, _stand_then_shuttle((30.6, -0.8), 26.0, [(27.0, -0.8)], 0.9,
                                                                duration + 5.0)),
        Mover(8, "standing-recess", person, timeline((17.0, 1.22), [])),
        Mover(9, "standing-corridor", person, timeline((21.0, -0.9), [])),
        Mover(10, "standing-room", person, timeline((26.0, 2.5), [])),
        Mover(11, "standing-corridor-c", person, timeline((28.6, 11.0), [])),
    )
    lidar = _lidar(beams=811, fov=math.radians(270.0), rate_hz=15.0, range_min=0.05, range_max=20.0)
    return Scenario("drive", "robot at 1 m/s through corridors, doorways and a room; six people walking "
                    "past/across at 0.7–2 m/s, four standing, one starting to walk", world, movers, robot,
                    lidar, duration, seed)


# --------------------------------------------------------------------------- stop-and-go

_STOPGO_OUTLINE = [
    (-4.0, -5.0), (5.0, -5.0), (5.0, -1.0), (14.0, -1.0), (14.0, 1.0), (5.0, 1.0), (5.0, 5.0),
    (1.5, 5.0), (1.5, 5.6), (0.3, 5.6), (0.3, 5.0), (-5.0, 5.0), (-5.0, -4.0),
]


def _build_stop_and_go(seed: int, duration: float) -> Scenario:
    solids = _pilasters() + [_solid(-0.2, 3.8, 0.4, 0.4), _solid(-2.2, -2.4, 1.2, 0.6)]
    world = _build_world(_STOPGO_OUTLINE, solids)
    robot = oscillating_in_place(-2.0, 0.0, 0.6, 0.5, 8.0)
    box = timeline((12.5, 0.0), [("wait", 5.0), ("go", (4.0, 0.0), 0.8), ("go", (1.5, -2.5), 0.8)], heading=0.0)
    car = timeline((2.0, 2.5), [("wait", 28.0), ("go", (4.0, 0.0), 0.7), ("go", (13.0, 0.0), 0.9)],
                   start_heading=0.0)
    person = ping_pong([(-3.5, -3.0), (-3.5, 3.0)], 1.0, heading=None, pause=4.0)
    movers = (
        Mover(1, "box-arriving", Rect(1.0, 1.0), box),
        Mover(2, "car-leaving", Rect(1.2, 0.8), car),
        Mover(3, "person-stop-and-go", Circle(0.25), person),
    )
    return Scenario("stop-and-go", "a box arrives and parks, a parked car leaves through the doorway, "
                    "a person walks with long stops", world, movers, robot, _lidar(), duration, seed)


# --------------------------------------------------------------------------- long corridor

#: 60 m × 2.4 m corridor: a side room and a door recess near the start, one door recess
#: half-way, plain walls elsewhere (counter-clockwise).
_LONG_CORRIDOR_OUTLINE = [
    (0.0, -1.2), (30.0, -1.2), (30.0, -1.7), (31.2, -1.7), (31.2, -1.2), (60.0, -1.2), (60.0, 1.2),
    (4.0, 1.2), (4.0, 1.6), (3.0, 1.6), (3.0, 1.2), (2.2, 1.2), (2.2, 3.2), (0.0, 3.2),
]
#: Range of the corridor laser, m: a short-range scanner sees only the side walls for
#: 30 − 4 − 2·6 = 14 m and 60 − 31.2 − 4 − 2·6 ≈ 12.8 m of the drive.
LONG_CORRIDOR_RANGE = 6.0


def _build_long_corridor(seed: int, duration: float) -> Scenario:
    world = _build_world(_LONG_CORRIDOR_OUTLINE, [_solid(1.0, 2.6, 0.5, 0.5)])
    robot = waypoint_path([(1.5, -0.4), (56.5, -0.4)], speed=1.0, loop=False, wobble_amplitude=0.03,
                          wobble_period=4.0)
    movers = (
        Mover(1, "person-oncoming", Circle(0.22), ping_pong([(55.0, 0.65), (6.0, 0.65)], 1.3, heading=None)),
        Mover(2, "person-ahead", Circle(0.22), ping_pong([(14.0, 0.55), (45.0, 0.55)], 0.9, heading=None,
                                                          phase=0.1)),
    )
    lidar = _lidar(range_max=LONG_CORRIDOR_RANGE)
    return Scenario("long-corridor", "60 m corridor, 6 m laser, robot at 1 m/s: >12 m stretches where only "
                    "the side walls are in range; two people", world, movers, robot, lidar, duration, seed)


# --------------------------------------------------------------------------- occlusion

#: Scenes where a mover touches or passes through the sensor on purpose (the occlusion event);
#: every other scene keeps movers clear of the robot.
SENSOR_CONTACT_SCENARIOS = frozenset({"occlusion"})
#: Where the occlusion robot stands (world frame, m) and the person's radius, m.
OCCLUSION_ROBOT = (-1.0, 0.0)
_OCCLUDER_RADIUS = 0.25


def _build_occlusion(seed: int, duration: float) -> Scenario:
    solids = _pilasters() + [_solid(2.0, 2.2, 0.5, 0.5), _solid(-2.2, -2.4, 1.2, 0.6)]
    world = _build_world(_PAPER_OUTLINE, solids)
    rx, ry = OCCLUSION_ROBOT
    robot = oscillating_in_place(rx, ry, 0.0, 0.4, 6.0)
    r = _OCCLUDER_RADIUS
    # stands 0.03 m from the sensor (blocks 2·asin(0.25/0.28) ≈ 126° of the 240° fan) for 1 s,
    # then pushes through it at 2 m/s: the sensor is inside the person for 2r / 2 m/s = 0.25 s
    person = timeline((3.0, 1.5), [("wait", 6.0), ("go", (rx + r + 0.03, ry), 1.0), ("wait", 1.0),
                                   ("go", (rx - r - 0.03, ry), 2.0), ("go", (-3.5, -1.2), 1.0)])
    movers = (Mover(1, "person-through-sensor", Circle(r), person),)
    lidar = _lidar(fov=math.radians(240.0), beams=720)
    return Scenario("occlusion", "office, 240° laser on a robot yawing in place; a person stands against "
                    "the sensor for 1 s and pushes through it", world, movers, robot, lidar, duration, seed)


# --------------------------------------------------------------------------- parking

#: A 22×15 m hall opening on the right into a garage bay with a ramp going down (y < −6)
#: where vehicles park out of sight; an alcove in the top wall.
_PARKING_OUTLINE = [
    (-11.0, -7.5), (11.0, -7.5), (11.0, -6.0), (13.0, -6.0), (13.0, -16.0), (19.0, -16.0), (19.0, 6.0),
    (11.0, 6.0), (11.0, 7.5), (6.0, 7.5), (6.0, 8.3), (4.0, 8.3), (4.0, 7.5), (-11.0, 7.5),
]


def _build_parking(seed: int, duration: float) -> Scenario:
    """Vehicles of four sizes park and leave, people walk and then stand, and the robot
    drives a 10×4 m loop past all of them about twice (issue 11, docs/maps.md)."""
    world = _build_world(_PARKING_OUTLINE, [_solid(-8.0, 3.2, 0.5, 0.5), _solid(8.0, -2.5, 0.5, 0.5)])
    robot = waypoint_path([(-5.0, -2.0), (5.0, -2.0), (5.0, 2.0), (-5.0, 2.0)], speed=0.6, turn_rate=0.8,
                          wobble_amplitude=0.05, wobble_period=3.0)
    car = timeline((-4.0, -5.0), [("wait", 45.0), ("go", (7.0, -5.0), 1.2), ("go", (16.0, -1.0), 1.2),
                                  ("go", (14.5, -13.5), 1.2)], start_heading=0.0)
    van = timeline((-8.5, 0.0), [("wait", 80.0), ("go", (-8.0, -4.6), 0.8), ("go", (7.0, -4.6), 1.2),
                                 ("go", (16.0, -1.0), 1.2), ("go", (17.5, -13.0), 1.2)], start_heading=math.pi / 2)
    small = timeline((16.0, -10.0), [("wait", 10.0), ("go", (16.0, -1.0), 1.0), ("go", (6.5, 5.0), 1.0),
                                     ("go", (2.0, 5.0), 0.8)], start_heading=math.pi / 2)
    cart = timeline((-6.0, 6.3), [("wait", 30.0), ("go", (-1.5, 6.3), 0.7)], start_heading=0.0)
    walker = timeline((-10.0, 4.6), [("go", (-3.0, 4.5), 1.1)], start_heading=0.0)
    stander = timeline((0.0, 0.0), [("wait", 50.0), ("go", (3.5, 0.5), 0.9), ("wait", 25.0),
                                    ("go", (-3.0, -0.5), 1.0)], start_heading=0.0)
    movers = (
        Mover(1, "car-leaving", Rect(4.0, 1.8), car),
        Mover(2, "van-leaving", Rect(5.0, 2.0), van),
        Mover(3, "small-car-arriving", Rect(2.6, 1.6), small),
        Mover(4, "cart-stop-go-stop", Rect(1.2, 0.8), cart),
        Mover(5, "person-walks-then-stands", Circle(0.25), walker),
        Mover(6, "person-stands-walks-stands", Circle(0.25), stander),
    )
    return Scenario("parking", "hall with a garage bay: a car and a van parked then leaving, a small car and a "
                    "cart arriving and parking, people who walk and then stand; robot loops past them",
                    world, movers, robot, _lidar(), duration, seed)


# --------------------------------------------------------------------------- registry

#: name → spec; ``SCENARIOS[name](seed=None, duration=None)`` builds the scene
#: with its fixed default seed and duration.
SCENARIOS: dict[str, ScenarioSpec] = {
    **{name: ScenarioSpec(_paper_builder(name), 1 + i, 60.0, _PAPER_DESCRIPTIONS[name])
       for i, name in enumerate(_PAPER_VARIANTS)},
    "static": ScenarioSpec(_build_static, 5, 40.0, "paper room without movers, robot yawing up to ≈1 rad/s"),
    "crowd": ScenarioSpec(_build_crowd, 6, 60.0, "six people on random walks around a robot on a circuit"),
    "drive": ScenarioSpec(_build_drive, 11, 45.0, "robot at 1 m/s through corridors and doors; people walking "
                          "past/across at 0.7–2 m/s, some standing"),
    "corridor": ScenarioSpec(_build_corridor, 7, 60.0, "30 m corridor, walkers, a cart, robot driving along"),
    "stop-and-go": ScenarioSpec(_build_stop_and_go, 8, 60.0, "objects parking and leaving; a person with stops"),
    "long-corridor": ScenarioSpec(_build_long_corridor, 9, 55.0,
                                  "60 m corridor, 6 m laser, only side walls in range for >12 m stretches"),
    "occlusion": ScenarioSpec(_build_occlusion, 10, 16.0, "a person stands against and pushes through the sensor"),
    "parking": ScenarioSpec(_build_parking, 9, 120.0, "vehicles park and leave, people walk then stand, robot loops"),
}


#: Longest simulated span, s: motion, mover states and labels are precomputed for every scan.
MAX_SIM_DURATION_S = 3600.0
#: Most beams (scans × beams per scan) one simulation holds as ground truth (6 bytes each).
MAX_SIM_BEAMS = 100_000_000


def build_scenario(
    name: str,
    seed: int | None = None,
    duration: float | None = None,
    beams: int | None = None,
    fov: float | None = None,
    rate_hz: float | None = None,
    noise_sigma: float | None = None,
    dropout: float | None = None,
    range_min: float | None = None,
    range_max: float | None = None,
) -> Scenario:
    """Build a registered scenario, overriding seed, duration (s) and sensor settings.

    ``fov`` is in rad, ``rate_hz`` in Hz, ``noise_sigma``/ranges in m. Unknown
    names raise :class:`DynSlamError` listing the available ones.
    """
    spec = SCENARIOS.get(name)
    if spec is None:
        raise DynSlamError(f"unknown scenario {name!r}; available: {', '.join(sorted(SCENARIOS))}")
    if duration is not None and not duration > 0:
        raise DynSlamError(f"scenario {name!r}: duration must be > 0 s, got {duration}")
    if duration is not None and not duration <= MAX_SIM_DURATION_S:
        raise DynSlamError(
            f"scenario {name!r}: --duration {duration:g} s is over the simulator's limit of {MAX_SIM_DURATION_S:g} s "
            f"(motion and ground truth are precomputed); simulate a shorter span"
        )
    scenario = spec(seed, duration)
    overrides = {k: v for k, v in dict(beams=beams, fov=fov, rate_hz=rate_hz, noise_sigma=noise_sigma,
                                       dropout=dropout, range_min=range_min, range_max=range_max).items()
                 if v is not None}
    if overrides:
        try:
            lidar = dataclasses.replace(scenario.lidar, **overrides)
        except ValueError as exc:
            raise DynSlamError(f"scenario {name!r}: invalid sensor settings: {exc}") from exc
        scenario = dataclasses.replace(scenario, lidar=lidar)
    beams_total = scenario.n_scans * scenario.lidar.beams
    if beams_total > MAX_SIM_BEAMS:
        raise DynSlamError(
            f"scenario {name!r}: {scenario.n_scans} scans × {scenario.lidar.beams} beams is over the simulator's "
            f"limit of {MAX_SIM_BEAMS:.0e} beams (ground truth is held in memory); shorten --duration or lower the rate"
        )
    return scenario
