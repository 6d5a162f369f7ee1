"""The "drive" scene (robot at 1 m/s through corridors and doorways, people walking and
standing) and the removal metrics split into walking / standing / stopped movers."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.eval.motionclass import (
    STANDING,
    STATIC,
    STOPPED,
    WALKING,
    beam_classes,
    mover_classes,
    removal_by_motion,
)
from dynslam2d.results import evaluate, ground_truth_for
from dynslam2d.sim import SCENARIOS, build_scenario, point_segment_distance, simulate
from dynslam2d.types import Pose2D


@pytest.fixture(scope="module")
def drive():
    return simulate("drive", duration=32.0)


def test_drive_is_registered_short_and_deterministic():
    assert "drive" in SCENARIOS and SCENARIOS["drive"].duration <= 60.0
    a, b = simulate("drive", duration=1.0), simulate("drive", duration=1.0)
    assert all(x.same_as(y) for x, y in zip(a.scans, b.scans))
    c = simulate("drive", duration=1.0, seed=123)
    assert not np.array_equal(a.scans[0].ranges, c.scans[0].ranges)  # the seed drives the range noise
    lidar = a.scenario.lidar
    assert lidar.fov == pytest.approx(np.radians(270.0)) and not lidar.full_circle


def test_drive_robot_and_people_move_as_specified():
    sc = build_scenario("drive")
    t = np.arange(0.0, sc.duration, 0.02)
    robot = sc.robot.sample(t)
    base = sc.robot.base.sample(t)
    speed = np.hypot(base[:, 3], base[:, 4])
    driving = speed > 0
    assert np.allclose(speed[driving], 1.0) and driving.mean() > 0.8  # ≈1 m/s, turns in place
    assert np.hypot(*(robot[-1, :2] - robot[0, :2])) > 25.0
    walking_speeds, standing = set(), []
    for m in sc.movers:
        st = m.trajectory.sample(t)
        v = np.round(np.hypot(st[:, 3], st[:, 4]), 6)
        walking_speeds |= set(v[v > 0].tolist())
        if not (v > 0).any():
            standing.append(m.id)
        # nobody walks into the laser or through a wall
        assert np.hypot(st[:, 0] - robot[:, 0], st[:, 1] - robot[:, 1]).min() > 0.45, m.name
        assert point_segment_distance(st[:, :2], sc.world.segments).min() >= m.shape.radius - 1e-9, m.name
    assert min(walking_speeds) >= 0.7 and max(walking_speeds) <= 2.0
    assert len(walking_speeds) >= 5 and len(standing) >= 3
    starter = next(m for m in sc.movers if m.name == "starts-walking")
    v = np.hypot(*starter.trajectory.sample(t)[:, 3:5].T)
    assert (v[t < 26.0] == 0).all() and (v[t > 26.0] > 0).all()  # stands, then walks without stopping


def test_drive_labels_agree_with_geometry(drive):
    gt = drive.ground_truth
    tol = 6 * drive.scenario.lidar.noise_sigma
    static = gt.scenario.world.segments
    hits = {m.id: 0 for m in gt.movers}
    for i in range(0, len(drive.scans), 3):
        lab = gt.labels[i]
        pts = Pose2D.from_array(gt.poses[i]).transform_points(drive.scans[i].points(lab >= 0))
        lv = lab[lab >= 0]
        assert point_segment_distance(pts[lv == 0], static).max() < tol
        for j, m in enumerate(gt.movers):
            p = pts[lv == m.id]
            if p.shape[0]:
                s = gt.mover_states[i, j]
                assert np.abs(np.hypot(p[:, 0] - s[0], p[:, 1] - s[1]) - m.shape.radius).max() < tol, m.name
                hits[m.id] += p.shape[0]
    seen = {m.name for m in gt.movers if hits[m.id] > 0}
    # within 32 s the robot has passed every corridor-A person and entered the room
    assert {"walker-oncoming", "walker-overtaking", "walker-crossing", "standing-recess",
            "standing-corridor", "starts-walking"} <= seen


def test_mover_classes_walking_standing_stopped():
    rows = np.zeros(8, dtype=[("stamp", "f8"), ("id", "i4"), ("vx", "f8"), ("vy", "f8")])
    # mover 1: still, moving, still (stopped), mover 4: always still
    rows["stamp"] = [0.0, 0.0, 0.1, 0.1, 0.2, 0.2, 0.3, 0.3]
    rows["id"] = [1, 4] * 4
    rows["vx"] = [0.0, 0.0, 0.8, 0.0, 0.0, 0.0, 0.0, 0.01]
    ids, cls = mover_classes(rows, np.array([0.0, 0.1, 0.2, 0.3]))
    assert ids.tolist() == [1, 4]
    assert cls[:, 0].tolist() == [STANDING, WALKING, STOPPED, STOPPED]
    assert cls[:, 1].tolist() == [STANDING] * 4  # 0.01 m/s is below the threshold
    labels = np.array([[-1, 0, 1, 4]] * 4)
    beams = beam_classes(labels, ids, cls)
    assert beams[1].tolist() == [-1, STATIC, WALKING, STANDING]
    removed = np.zeros((4, 4), dtype=bool)
    removed[1, 2] = removed[2, 2] = removed[0, 1] = True
    m = removal_by_motion(removed, labels, np.array([0.0, 0.1, 0.2, 0.3]), rows)
    assert (m.walking_recall, m.standing_removed_share, m.stopped_removed_share) == (1.0, 0.0, 0.5)
    assert m.static_removed_share == 0.25 and (m.n_walking, m.n_standing, m.n_stopped, m.n_static) == (1, 5, 2, 4)


def test_drive_removal_split_by_motion_class(drive):
    """A mask that removes exactly the walking people and half the standing people's beams
    is scored 1.0 / 0.5 / 0 static, through the same evaluate() that metrics.json uses."""
    source = drive.source()
    gt = ground_truth_for(source, None, 0.05)
    ids, cls = mover_classes(gt.movers, gt.stamps)
    beams = beam_classes(gt.labels, ids, cls)
    assert (beams == WALKING).sum() > 1000 and (beams == STANDING).sum() > 500
    assert (beams == STOPPED).sum() == 0  # nobody in "drive" stands after walking
    starter = next(m.id for m in drive.scenario.movers if m.name == "starts-walking")
    on_starter = gt.labels == starter
    before, after = on_starter & (gt.stamps[:, None] < 25.9), on_starter & (gt.stamps[:, None] > 26.1)
    assert before.sum() > 100 and after.sum() > 100  # seen standing, then seen walking
    assert set(np.unique(beams[before])) == {STANDING} and set(np.unique(beams[after])) == {WALKING}
    removed = beams == WALKING
    standing_idx = np.argwhere(beams == STANDING)
    removed[tuple(standing_idx[::2].T)] = True
    out = evaluate(gt.trajectory, gt.static_map, gt, removed, gt.stamps)
    mc = out["removal_by_motion"]
    assert mc["walking_recall"] == 1.0 and mc["static_removed_share"] == 0.0
    assert mc["n_removed_standing"] == (len(standing_idx) + 1) // 2
    assert out["removal"]["recall"] < 1.0  # the unsplit recall counts standing people as movers
    from dynslam2d.io.runfolder import TRACK_DTYPE

    none_in_m = evaluate(gt.trajectory, gt.static_map, gt, removed, gt.stamps, np.zeros(0, dtype=TRACK_DTYPE))
    assert none_in_m["time_to_m"]["seen_walking"] >= 5 and none_in_m["time_to_m"]["reached"] == 0


def test_time_to_m_from_the_first_scan_a_mover_is_seen_walking():
    from dynslam2d.eval.motionclass import time_to_m
    from dynslam2d.io.runfolder import TRACK_DTYPE

    stamps = np.round(np.arange(10) * 0.1, 10)
    rows = np.zeros(20, dtype=[("stamp", "f8"), ("id", "i4"), ("x", "f8"), ("y", "f8"), ("vx", "f8"),
                               ("vy", "f8"), ("hits", "i4")])
    rows["stamp"] = np.repeat(stamps, 2)
    rows["id"] = [1, 2] * 10
    # mover 1 stands until 0.3 s, walks from 0.3 s (seen throughout); mover 2 walks, unseen until 0.5 s
    rows["vx"] = [0.0 if (t < 0.25 and k == 1) else 1.0 for t in stamps for k in (1, 2)]
    rows["x"] = [max(t - 0.3, 0.0) if k == 1 else 5.0 + t for t in stamps for k in (1, 2)]
    rows["hits"] = [10 if k == 1 else (0 if t < 0.45 else 8) for t in stamps for k in (1, 2)]
    tracks = []
    for t in stamps:
        if t >= 0.55:  # a track in M over mover 1 from 0.6 s, in a map frame shifted by (−1, 0)
            tracks.append((t, 7, "confirmed", max(t - 0.3, 0.0) - 1.0 + 0.2, 0.1, 0, 0.4, 0.4, 1, 0, True))
        tracks.append((t, 8, "confirmed", 5.0 + t - 1.0, 0.0, 0, 0.4, 0.4, 1, 0, False))  # over mover 2, not in M
    tracks = np.array(tracks, dtype=TRACK_DTYPE)
    r = time_to_m(rows, tracks, transform=Pose2D(1.0, 0.0, 0.0))
    by_id = {m.id: m for m in r.movers}
    assert by_id[1].onset == pytest.approx(0.3) and by_id[1].reached == pytest.approx(0.6)
    assert by_id[1].delay == pytest.approx(0.3)
    assert by_id[2].onset == pytest.approx(0.5) and by_id[2].reached is None
    assert (r.seen_walking, r.reached, r.within_half_second) == (2, 1, 0.5)
    assert time_to_m(rows, tracks).reached == 0  # without the frame transform the track is 1 m off
