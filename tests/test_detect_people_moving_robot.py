"""People seen from a driving robot (issue 9): a person who starts walking enters M within 0.5 s, and a
person who walks up to a wall does not carry M onto the wall (simulated scenes, exact labels)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dynslam2d.config import Config
from dynslam2d.detect import Tracker
from dynslam2d.detect.mapevidence import MapView
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import Circle, LidarModel, Mover, Scenario, World, cast_rays, polyline_segments, simulate, timeline
from dynslam2d.sim.robot import waypoint_path
from dynslam2d.sim.world import rect_corners
from dynslam2d.types import Pose2D, Scan

RATE = 15.0  # Hz, as sim:drive
VANISH = 2.3  # s, when the walker of the wall test is gone (at x = 5.6, 0.18 m from the wall)

#: a 30 × 4 m corridor closed at both ends (counter-clockwise)
_OUTLINE = [(0.0, -2.0), (30.0, -2.0), (30.0, 2.0), (0.0, 2.0)]


def _world() -> World:
    return World(polyline_segments(_OUTLINE, closed=True), interior=[np.asarray(_OUTLINE)])


def _lidar() -> LidarModel:
    return dataclasses.replace(LidarModel(), beams=811, fov=math.radians(270.0), rate_hz=RATE, range_min=0.05,
                               range_max=20.0)


def _run(scenario: Scenario, config: Config) -> tuple[list, object]:
    sim = simulate(scenario)
    pipe = Pipeline(config)
    return [pipe.process(s) for s in sim.scans], sim.ground_truth


def _starter(start: tuple[float, float] = (10.0, 1.0), goal: tuple[float, float] = (1.0, 1.0), wait: float = 4.0,
             duration: float = 8.0) -> Scenario:
    """The robot drives along the corridor at 1 m/s; a person stands at ``start`` until ``wait``, then walks
    to ``goal`` at 0.9 m/s."""
    robot = waypoint_path([(1.0, -1.0), (29.0, -1.0)], speed=1.0, loop=False, wobble_amplitude=0.03,
                          wobble_period=2.0)
    walker = timeline(start, [("wait", wait), ("go", goal, 0.9)])
    return Scenario("starter", "a person starts walking while the robot drives", _world(),
                    (Mover(1, "starts-walking", Circle(0.22), walker),), robot, _lidar(), duration, 5)


def _time_to_m(steps: list, gt: object, onset: float) -> float:
    """Seconds from ``onset`` to the first scan where a track in M has its centre within 0.5 m of mover 1
    (track centres are in the first scan's frame, the ground truth in the world frame)."""
    to_world = gt.first_pose  # first-scan frame → world
    for i, step in enumerate(steps):
        if step.stamp < onset - 1e-9:
            continue
        mx, my = gt.mover_states[i, 0, :2]
        for t in step.tracks:
            if t.in_m:
                x, y = to_world.transform_points(np.array([[t.box.px, t.box.py]]))[0]
                if math.hypot(x - mx, y - my) <= 0.5:
                    return step.stamp - onset
    return math.inf


@pytest.mark.parametrize("start, goal, wait", [((9.0, 1.2), (20.0, 1.2), 4.0), ((12.0, 0.5), (12.0, -1.8), 3.0)])
def test_person_who_starts_walking_before_a_driving_robot_enters_m_within_half_a_second(
        start: tuple[float, float], goal: tuple[float, float], wait: float) -> None:
    """A person stood in the robot's view (its track was born where it stood), then walks ahead of the robot,
    or across the corridor in front of it. Measured 0.33 s to M for both. Without the person's faster way in
    (0.15 m since birth on map evidence, the free-space memory where the map has not seen the place) it takes
    0.6 / 0.67 s. Never in M while standing."""
    sc = _starter(start, goal, wait, duration=wait + 2.0)
    steps, gt = _run(sc, Config())
    delay = _time_to_m(steps, gt, wait)
    assert delay <= 0.5, delay
    lab = gt.labels
    assert not any((s.removed & (lab[i] == 1)).any() for i, s in enumerate(steps) if s.stamp < wait)
    old = Config()
    old.detect.tracker.person_min_displacement = old.detect.tracker.min_displacement
    old.detect.tracker.person_free_min = 1.0
    steps_old, _ = _run(sc, old)
    assert _time_to_m(steps_old, gt, wait) > 0.5


def _wall_scans(vanish: float, duration: float) -> tuple[list, list]:
    """A motionless laser at the origin facing +x; a person (r 0.22 m) walking along y = 0.4 at 2 m/s from x = 1
    towards a 1.5 m wall piece across x = 6 (short enough to be a candidate mover) who is gone from ``vanish``
    on (stepped out of the laser's plane). The wall returns only from ``vanish`` on (before, its surface was
    too dark or glossy for the laser), so that no track of its own holds it: the same situation as a wall
    whose pieces keep changing shape behind a walker. Returns scans and per-beam labels (1 = person, 0 = wall)."""
    n = 541
    fov = math.radians(270.0)
    angles = -0.5 * fov + np.arange(n) * fov / (n - 1)
    wall = polyline_segments([(6.0, -0.75), (6.0, 0.75)])
    scans, labels = [], []
    for i in range(int(duration * RATE)):
        t = i / RATE
        circles = np.zeros((0, 3)) if t >= vanish else np.array([[1.0 + 2.0 * t, 0.0, 0.22]])
        segs = wall if t >= vanish else np.zeros((0, 4))
        dist, lab = cast_rays((0.0, 0.0), angles, segs, np.zeros(segs.shape[0], dtype=np.int32), circles,
                              np.ones(circles.shape[0], dtype=np.int32))
        r = dist + np.random.default_rng(i).normal(0.0, 0.01, dist.shape)
        scans.append(Scan(stamp=t, angle_min=float(angles[0]), angle_increment=float(angles[1] - angles[0]), ranges=r,
                          range_min=0.05, range_max=20.0))
        labels.append(lab)
    return scans, labels


def _wall_map() -> MapView:
    """The map a laser has after a while in front of the wall: the wall's cells long occupied (log-odds 7),
    the room in front of it observed free (−2). 5 cm cells, x −1…8, y −3…3."""
    res = 0.05
    i0, j0 = -20, -60
    lo = np.full((121, 181), -2.0, dtype=np.float32)
    col = int(round(6.0 / res)) - i0
    lo[int(round(-0.8 / res)) - j0:int(round(0.8 / res)) - j0 + 1, col - 1:col + 2] = 7.0
    lo[:, col + 2:] = 0.0  # behind the wall: never seen
    return MapView(lo, i0, j0, res)


def _wall_run(config: Config) -> tuple[int, float]:
    """(static beams removed by tracks in M after the person vanished, largest box side in M then, m)."""
    tracker = Tracker(config.detect)
    view = _wall_map()
    scans, labels = _wall_scans(vanish=VANISH, duration=3.5)
    removed, largest = 0, 0.0
    for scan, lab in zip(scans, labels):
        tracks = tracker.update(scan, Pose2D(0.0, 0.0, 0.0), view)
        if scan.stamp < VANISH:
            continue
        for t in tracks:
            if t.in_m:
                largest = max(largest, t.box.length, t.box.width)
                removed += int((lab[t.beams] == 0).sum())
    return removed, largest


def test_track_in_m_does_not_take_a_wall_when_its_person_vanishes_next_to_it() -> None:
    """The person walks up to a short wall the map knows as long-occupied and vanishes; the wall's cluster lies
    within the person's gate. Updating the person's track with it would carry M onto the wall (sim:drive: a
    walker at a corridor's end took the end wall, 3400 static beams removed). The detection is refused and the
    track leaves M: no wall beam is ever in M. With the refusal off (merge_size_jump huge) the clutter rule's claims
    alone keep the wall's cluster from the track when that rule is on (the wall piece is a dormant track's object,
    or a kept place of structure, docs/real.md "Fewer clutter tracks"); with both off (the clutter rule is off by
    default) the track takes the wall and stays in M."""
    removed, largest = _wall_run(Config())
    assert removed == 0 and largest < 1.0, (removed, largest)
    no_veto = Config()
    no_veto.detect.tracker.merge_size_jump = 100.0
    claims = no_veto.model_copy(deep=True)
    claims.detect.tracker.structure_retire_updates = 2
    claims.detect.tracker.structure_birth_min = 0.5
    removed_c, largest_c = _wall_run(claims)
    assert removed_c == 0 and largest_c < 1.0, (removed_c, largest_c)
    off = no_veto
    assert off.detect.tracker.structure_retire_updates == 0 and off.detect.tracker.structure_birth_min > 1.0
    removed_off, largest_off = _wall_run(off)
    assert removed_off > 20 and largest_off > 1.0, (removed_off, largest_off)


def _wall_hugger() -> Scenario:
    """The robot drives along the corridor at 1 m/s; a person walks towards it at 1.5 m/s 0.13 m from the left
    wall, which the laser sees at a grazing angle beside the person."""
    robot = waypoint_path([(1.0, -1.0), (29.0, -1.0)], speed=1.0, loop=False, wobble_amplitude=0.03,
                          wobble_period=2.0)
    walker = timeline((16.0, 1.65), [("go", (3.0, 1.65), 1.5)])
    return Scenario("wall-hugger", "a person walks along a wall towards the robot", _world(),
                    (Mover(1, "walker", Circle(0.22), walker),), robot, _lidar(), 6.0, 3)


def test_wall_beside_a_walker_stays_in_the_scan() -> None:
    """The exclusion box of a walker in M reaches 0.2 m past the person (range noise, box-fit error), over the
    wall it passes 0.13 m from. Beams in it that are not the walker's own and land on long-occupied map cells
    stay with filter.spare_structure: 232 wall beams removed instead of 687 (the rest lie on cells the map has not
    yet seen often enough: grazing, and hidden behind the walker), and the walker's beams are removed as
    before (0.986)."""
    on = Config()
    on.filter.spare_structure = True
    steps, gt = _run(_wall_hugger(), on)
    off = Config()
    assert not off.filter.spare_structure  # off by default (docs/tracking.md)
    steps_off, _ = _run(_wall_hugger(), off)
    lab = gt.labels
    rem, rem_off = np.array([s.removed for s in steps]), np.array([s.removed for s in steps_off])
    static, walker = lab == 0, lab == 1
    assert rem_off[static].sum() > 100  # the plain box takes a strip of the wall
    assert rem[static].sum() < 0.5 * rem_off[static].sum(), (rem[static].sum(), rem_off[static].sum())
    assert rem[walker].mean() >= rem_off[walker].mean() - 0.02 and rem[walker].mean() > 0.8


def _cluttered_starter() -> Scenario:
    """The starter scene (a person stands at (9, 1.2) until 4 s, then walks ahead of the robot) with eight
    0.4 m boxes along the corridor's walls: small static clusters that are candidate movers (clutter)."""
    boxes = [rect_corners(x, y, 0.0, 0.4, 0.4) for x in (4.0, 7.0, 11.0, 14.0) for y in (-1.7, 1.7)]
    segs = np.vstack([polyline_segments(_OUTLINE, closed=True)] + [polyline_segments(b, closed=True)
                                                                     for b in boxes])
    world = World(segs, interior=[np.asarray(_OUTLINE)], solids=[np.asarray(b) for b in boxes])
    robot = waypoint_path([(1.0, -1.0), (29.0, -1.0)], speed=1.0, loop=False, wobble_amplitude=0.03,
                          wobble_period=2.0)
    walker = timeline((9.0, 1.2), [("wait", 4.0), ("go", (20.0, 1.2), 0.9)])
    return Scenario("cluttered-starter", "boxes along the walls; a person starts walking", world,
                    (Mover(1, "starts-walking", Circle(0.22), walker),), robot, _lidar(), 6.0, 5)


def test_clutter_on_map_structure_is_retired_and_a_walker_still_enters_m_fast() -> None:
    """Clutter retirement, off by default (tracker.structure_retire_updates, structure_birth_min; docs/real.md
    "Fewer clutter tracks"): the boxes along the walls become long-occupied map cells, and the still tracks on
    them are retired (dormant) or never born, so the tracker carries far fewer live tracks per scan than with the
    rule off (measured: 524 against 1172 live tracks summed over the 6 s' scans); the walking person still enters M
    within 0.5 s of starting to walk (0.40 s; 0.33 s with the rule off: the standing person's track is retired once
    the map holds the cells it stands on, and the walker's revived track needs its own updates)."""
    sc = _cluttered_starter()
    on = Config()
    on.detect.tracker.structure_retire_updates = 2
    on.detect.tracker.structure_birth_min = 0.5
    off = Config()
    assert off.detect.tracker.structure_retire_updates == 0 and off.detect.tracker.structure_birth_min > 1.0
    sim = simulate(sc)
    runs = {}
    for name, cfg in (("on", on), ("off", off)):
        pipe = Pipeline(cfg)
        steps, live = [], 0
        for scan in sim.scans:
            steps.append(pipe.process(scan))
            live += pipe.tracker.n_tracks
        runs[name] = (steps, live, pipe.tracker.stats)
    (steps, live, st), (steps_off, live_off, st_off) = runs["on"], runs["off"]
    assert st.deleted_structure > 0 and st.unborn_structure > 0 and st_off.deleted_structure == 0
    assert live < 0.55 * live_off, (live, live_off)
    gt = sim.ground_truth
    assert _time_to_m(steps, gt, 4.0) <= 0.5
    assert _time_to_m(steps_off, gt, 4.0) <= 0.5
