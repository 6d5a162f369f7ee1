"""Running a scenario: scans plus ground truth, and a ScanSource over them.

Frames
------
- **world frame (W)**: the scenario's own frame, in which walls, movers and the
  robot are defined. Ground truth is stored in W.
- **first-scan frame (F)**: the laser pose at the first scan, the frame SLAM
  output is expressed in (docs/architecture.md: "the map frame is the laser pose at the
  first scan"). ``T_FW = first_pose.inverse()``; every ground-truth accessor
  takes ``frame="world"`` or ``frame="first"``.

A scan is taken instantaneously at its stamp ``i / rate_hz`` (s since start).
Per-beam labels: -1 = no return, 0 = static structure, k ≥ 1 = mover id k.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.sim.movers import MoverState
from dynslam2d.sim.odometry import SIM_ODOMETRY, OdometryModel, SimOdometry, simulate_odometry
from dynslam2d.sim.scenarios import Scenario, build_scenario
from dynslam2d.sim.world import LABEL_NONE, cast_rays, rect_segments
from dynslam2d.types import Pose2D, Scan, SourceMeta, wrap_angle

#: Column names of :meth:`GroundTruth.mover_rows`, in order.
MOVER_ROW_FIELDS = ("stamp", "id", "kind", "x", "y", "heading", "length", "width", "vx", "vy", "hits")
_MOVER_ROW_DTYPE = np.dtype([
    ("stamp", "f8"), ("id", "i4"), ("kind", "U8"), ("x", "f8"), ("y", "f8"), ("heading", "f8"),
    ("length", "f8"), ("width", "f8"), ("vx", "f8"), ("vy", "f8"), ("hits", "i4"),
])
_FRAMES = ("world", "first")


@dataclass(eq=False)
class GroundTruth:
    """Everything true about a simulated run, world frame unless stated.

    Attributes:
        scenario: the simulated scenario (world, movers, robot, sensor).
        stamps: (n,) scan stamps, s.
        poses: (n, 3) laser poses ``x, y, theta`` in the world frame (m, rad).
        labels: (n, beams) int16 per-beam labels (-1 none, 0 static, k mover k).
        true_ranges: (n, beams) float32 noise-free distance to the first surface
            along each beam, m (``inf`` when the beam hits nothing at all, even
            beyond range_max).
        mover_ids: (k,) mover ids, in the order of the mover axis below.
        mover_states: (n, k, 6) ``x, y, heading, vx, vy, omega`` per scan and
            mover, world frame (m, rad, m/s, rad/s); velocities are exact.
    """

    scenario: Scenario
    stamps: np.ndarray
    poses: np.ndarray
    labels: np.ndarray
    true_ranges: np.ndarray
    mover_ids: np.ndarray
    mover_states: np.ndarray

    # ----------------------------------------------------------- frames and poses
    @property
    def n_scans(self) -> int:
        return int(self.stamps.shape[0])

    @property
    def first_pose(self) -> Pose2D:
        """Laser pose at the first scan, world frame."""
        return Pose2D.from_array(self.poses[0])

    def world_to_first(self) -> Pose2D:
        """``T_FW``: maps world-frame coordinates into the first-scan frame."""
        return self.first_pose.inverse()

    def frame_transform(self, frame: str) -> Pose2D:
        """The transform from world coordinates into ``frame``: identity for
        "world", ``T_FW`` for "first" (DynSlamError for anything else)."""
        if frame not in _FRAMES:
            raise DynSlamError(f"ground truth: unknown frame {frame!r}; use one of {', '.join(_FRAMES)}")
        return Pose2D() if frame == "world" else self.world_to_first()

    def pose(self, i: int, frame: str = "world") -> Pose2D:
        """Laser pose of scan ``i`` in ``frame`` ("world" or "first")."""
        return self.frame_transform(frame).compose(Pose2D.from_array(self.poses[i]))

    def poses_in(self, frame: str = "world") -> np.ndarray:
        """(n, 3) laser poses in ``frame``: "world", or "first" (``T_FW ⊕ pose_i``,
        so the first row is (0, 0, 0)) — the frame SLAM output is in."""
        t = self.frame_transform(frame)
        xy = t.transform_points(self.poses[:, :2])
        return np.column_stack((xy, wrap_angle(self.poses[:, 2] + t.theta)))

    # ----------------------------------------------------------- movers
    @property
    def movers(self) -> tuple:
        """The scenario's :class:`~dynslam2d.sim.movers.Mover` objects (id, name, shape)."""
        return self.scenario.movers

    @property
    def mover_hits(self) -> np.ndarray:
        """(n, k) int number of beams that hit each mover in each scan."""
        return (self.labels[:, :, None] == self.mover_ids[None, None, :]).sum(axis=1).astype(np.int32)

    def mover_states_in(self, frame: str = "world") -> np.ndarray:
        """(n, k, 6) mover states ``x, y, heading, vx, vy, omega`` in ``frame``."""
        t = self.frame_transform(frame)
        out = self.mover_states.copy()
        if frame == "world" or out.size == 0:
            return out
        c, s = math.cos(t.theta), math.sin(t.theta)
        x, y, vx, vy = (self.mover_states[..., j] for j in (0, 1, 3, 4))
        out[..., 0] = c * x - s * y + t.x
        out[..., 1] = s * x + c * y + t.y
        out[..., 2] = wrap_angle(self.mover_states[..., 2] + t.theta)
        out[..., 3] = c * vx - s * vy
        out[..., 4] = s * vx + c * vy
        return out

    def states_at(self, i: int, frame: str = "world") -> list[MoverState]:
        """Mover states at scan ``i`` in ``frame``."""
        st = self.mover_states_in(frame)[i]
        return [
            MoverState(int(m.id), m.kind, *map(float, st[j, :3]), float(m.shape.length), float(m.shape.width),
                       *map(float, st[j, 3:6]))
            for j, m in enumerate(self.movers)
        ]

    def mover_rows(self, frame: str = "world") -> np.ndarray:
        """All mover states flattened to one row per (scan, mover): a structured
        array with fields :data:`MOVER_ROW_FIELDS` = stamp (s), id, kind ("rect" or
        "circle"), x, y (m), heading (rad), length, width (m; a circle's diameter),
        vx, vy (m/s), hits (beams that hit it in that scan), in ``frame``."""
        n, k = self.n_scans, len(self.movers)
        rows = np.zeros(n * k, dtype=_MOVER_ROW_DTYPE)
        if k == 0:
            return rows
        st = self.mover_states_in(frame)
        rows["stamp"] = np.repeat(self.stamps, k)
        rows["id"] = np.tile(self.mover_ids, n)
        rows["kind"] = np.tile([m.kind for m in self.movers], n)
        rows["x"], rows["y"], rows["heading"] = (st[..., j].ravel() for j in range(3))
        rows["length"] = np.tile([m.shape.length for m in self.movers], n)
        rows["width"] = np.tile([m.shape.width for m in self.movers], n)
        rows["vx"], rows["vy"] = st[..., 3].ravel(), st[..., 4].ravel()
        rows["hits"] = self.mover_hits.ravel()
        return rows

    # ----------------------------------------------------------- static map
    def static_map(self, resolution: float = 0.05, frame: str = "world", margin: float = 0.5) -> GridMap:
        """The static world rasterised at ``resolution`` m in ``frame`` (see
        :meth:`~dynslam2d.sim.world.World.static_map`: 1 on static segments, 0 free
        inside the building, NaN outside it and inside solid obstacles)."""
        world = self.scenario.world
        if frame != "world":
            world = world.transformed(self.frame_transform(frame))
        return world.static_map(resolution, margin)


@dataclass(eq=False)
class Simulation:
    """A finished run: the scans (in time order) and their ground truth.

    ``odometry`` is the simulated wheel odometry and IMU (:mod:`dynslam2d.sim.odometry`);
    every scan carries its noisy ``odom`` and ``yaw_rate``.
    """

    scenario: Scenario
    scans: list[Scan]
    ground_truth: GroundTruth
    odometry: SimOdometry | None = None

    def __len__(self) -> int:
        return len(self.scans)

    def source(self) -> SimSource:
        """A :class:`SimSource` over this run (its scans and ground truth, no re-simulation)."""
        src = SimSource(self.scenario, odometry_model=None if self.odometry is None else self.odometry.model)
        src._simulation = self
        return src


def _sample_motion(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps (n,), laser poses (n, 3), mover states (n, k, 6) for a scenario."""
    stamps = scenario.stamps
    poses = scenario.robot.sample(stamps)
    if scenario.movers:
        states = np.stack([m.trajectory.sample(stamps) for m in scenario.movers], axis=1)
    else:
        states = np.zeros((stamps.shape[0], 0, 6))
    return stamps, poses, states


def _iter_scans(scenario: Scenario) -> Iterator[tuple[Scan, np.ndarray, np.ndarray]]:
    """Yield ``(scan, labels, true_ranges)`` per scan, deterministically from the seed."""
    stamps, poses, states = _sample_motion(scenario)
    lidar = scenario.lidar
    rng = np.random.default_rng([scenario.seed, 0])
    beam_angles = lidar.angles
    static = scenario.world.segments
    rect_idx = [j for j, m in enumerate(scenario.movers) if m.kind == "rect"]
    circ_idx = [j for j, m in enumerate(scenario.movers) if m.kind == "circle"]
    seg_ids = np.concatenate((
        np.zeros(static.shape[0], dtype=np.int32),
        np.repeat(np.array([scenario.movers[j].id for j in rect_idx], dtype=np.int32), 4),
    ))
    circ_ids = np.array([scenario.movers[j].id for j in circ_idx], dtype=np.int32)
    radii = np.array([scenario.movers[j].shape.radius for j in circ_idx], dtype=np.float64)
    for i in range(stamps.shape[0]):
        st = states[i]
        segs = [static] + [
            rect_segments(st[j, 0], st[j, 1], st[j, 2], scenario.movers[j].shape.length,
                          scenario.movers[j].shape.width)
            for j in rect_idx
        ]
        circles = np.column_stack((st[circ_idx, 0], st[circ_idx, 1], radii)) if circ_idx else np.zeros((0, 3))
        x, y, th = poses[i]
        dist, ids = cast_rays((x, y), th + beam_angles, np.vstack(segs), seg_ids, circles, circ_ids)
        ranges, valid = lidar.measure(dist, rng)
        labels = np.where(valid, ids, LABEL_NONE).astype(np.int16)
        yield lidar.make_scan(stamps[i], ranges), labels, dist


def _resolve(name_or_scenario: str | Scenario, seed: int | None, duration: float | None,
             sensor: dict[str, float | int | None]) -> Scenario:
    if isinstance(name_or_scenario, Scenario):
        sc = name_or_scenario
        if seed is not None or duration is not None:
            sc = dataclasses.replace(sc, seed=sc.seed if seed is None else int(seed),
                                     duration=sc.duration if duration is None else float(duration))
        changes = {k: v for k, v in sensor.items() if v is not None}
        if changes:
            try:
                sc = dataclasses.replace(sc, lidar=dataclasses.replace(sc.lidar, **changes))
            except ValueError as exc:
                raise DynSlamError(f"scenario {sc.name!r}: invalid sensor settings: {exc}") from exc
        return sc
    return build_scenario(str(name_or_scenario), seed=seed, duration=duration, **sensor)


def _scenario_odometry(scenario: Scenario, model: OdometryModel | None) -> SimOdometry:
    """The scenario's simulated odometry + IMU over its scan stamps (seeded by its seed)."""
    stamps = scenario.stamps
    last = float(stamps[-1]) if stamps.shape[0] else 0.0
    return simulate_odometry(scenario.robot, last, scenario.seed, model)


def simulate(
    name_or_scenario: str | Scenario,
    seed: int | None = None,
    duration: float | None = None,
    *,
    odometry_model: OdometryModel | None = None,
    **sensor: float | int | None,
) -> Simulation:
    """Run a scenario (registry name or :class:`Scenario`) to the end.

    ``sensor`` overrides LiDAR settings: beams, fov (rad), rate_hz (Hz),
    noise_sigma, dropout, range_min, range_max (m). Same seed → identical scans.
    ``odometry_model`` sets the odometry/IMU noise and laser mount (default
    :class:`~dynslam2d.sim.odometry.OdometryModel`); scans carry ``odom`` and ``yaw_rate``.
    """
    scenario = _resolve(name_or_scenario, seed, duration, sensor)
    odometry = _scenario_odometry(scenario, odometry_model)
    stamps, poses, states = _sample_motion(scenario)
    n, nb = stamps.shape[0], scenario.lidar.beams
    scans: list[Scan] = []
    labels = np.empty((n, nb), dtype=np.int16)
    true_ranges = np.empty((n, nb), dtype=np.float32)
    for i, (scan, lab, dist) in enumerate(_iter_scans(scenario)):
        scans.append(odometry.attach(scan))
        labels[i] = lab
        true_ranges[i] = dist
    gt = GroundTruth(scenario, stamps, poses, labels, true_ranges,
                     np.array([m.id for m in scenario.movers], dtype=np.int32), states)
    return Simulation(scenario, scans, gt, odometry)


class SimSource:
    """A :class:`~dynslam2d.types.ScanSource` over a simulated scenario.

    Scans are generated lazily while iterating (iterating twice gives identical
    scans); :attr:`ground_truth` runs the whole simulation once, on first use.
    ``meta.format == "sim"``, ``meta.origin == "sim:<name>"``, count known.
    Every scan carries the simulated noisy ``odom`` (laser pose in the odometry frame)
    and IMU ``yaw_rate``; ``meta.odometry == "sim"``, ``meta.extra["odometry"]`` describes
    the model, :attr:`odometry` holds the tracks.
    """

    def __init__(self, name_or_scenario: str | Scenario, seed: int | None = None, duration: float | None = None,
                 *, odometry_model: OdometryModel | None = None, **sensor: float | int | None) -> None:
        self.scenario = _resolve(name_or_scenario, seed, duration, sensor)
        self.odometry: SimOdometry = _scenario_odometry(self.scenario, odometry_model)
        lidar = self.scenario.lidar
        self.meta = SourceMeta(
            format="sim",
            origin=f"sim:{self.scenario.name}",
            topic=None,
            count=self.scenario.n_scans,
            beams=lidar.beams,
            fov=lidar.fov,
            rate_hz=lidar.rate_hz,
            frame_id=lidar.frame_id,
            range_min=lidar.range_min,
            range_max=lidar.range_max,
            extra={"seed": self.scenario.seed, "duration": self.scenario.duration,
                   "description": self.scenario.description},
            odometry=SIM_ODOMETRY,
        )
        m = self.odometry.model
        self.meta.extra["odometry"] = {
            "source": SIM_ODOMETRY, "imu": "sim", "mount": [m.mount.x, m.mount.y, m.mount.theta],
            "mount_source": "simulator", "rate_hz": m.rate_hz, "imu_rate_hz": m.imu_rate_hz,
        }
        self._simulation: Simulation | None = None

    def __iter__(self) -> Iterator[Scan]:
        if self._simulation is not None:
            return iter(self._simulation.scans)
        return (self.odometry.attach(scan) for scan, _, _ in _iter_scans(self.scenario))

    def __len__(self) -> int:
        return self.scenario.n_scans

    @property
    def simulation(self) -> Simulation:
        """The full run (computed once, then cached)."""
        if self._simulation is None:
            self._simulation = simulate(self.scenario, odometry_model=self.odometry.model)
        return self._simulation

    @property
    def ground_truth(self) -> GroundTruth:
        return self.simulation.ground_truth
