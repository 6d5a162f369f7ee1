"""eval people: a leg_tracker-style annotated bag generated from the simulator, with a
results folder written by hand, so every number is known exactly."""

from __future__ import annotations

import csv
import json
import math
import sys

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.cli import main
from dynslam2d.errors import DynSlamError
from dynslam2d.eval.people import PeopleParams, evaluate_people
from dynslam2d.io.annotations import PERSON_MSGTYPE, read_people_annotations, register_person_type
from dynslam2d.io.rosbag import LASERSCAN, laserscan_message, open_bag_writer
from dynslam2d.io.trajectory import Trajectory, write_tum
from dynslam2d.pipeline import TRACK_COLUMNS
from dynslam2d.sim import Circle, Mover, Scenario, simulate, timeline, waypoint_path
from dynslam2d.sim.scenarios import _build_world
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.types import Pose2D

HEADER0, RECORD0, DT = 1000.0, 5000.0, 0.1  # header and record clocks differ, as in the real bags
UNANNOTATED = range(20, 25)  # scans nobody annotated
T_START, T_M = 3.0, 4.5  # the "starter" walks from 3 s; a track in M covers it from 4.5 s


@pytest.fixture(scope="module")
def sim():
    world = _build_world([(-6.0, -4.0), (6.0, -4.0), (6.0, 4.5), (-6.0, 4.5)], [])
    movers = (
        Mover(1, "walker", Circle(0.22), timeline((-4.0, 1.5), [("go", (4.0, 1.5), 1.0)])),
        Mover(2, "stander", Circle(0.22), timeline((0.0, 3.2), [])),
        Mover(3, "starter", Circle(0.22), timeline((-2.0, -0.3), [("wait", T_START), ("go", (5.0, -0.3), 1.2)])),
    )
    robot = waypoint_path([(-3.0, -2.0), (3.0, -2.0)], speed=0.5, loop=False)
    lidar = LidarModel(beams=360, rate_hz=1 / DT)
    return simulate(Scenario("people-test", "", world, movers, robot, lidar, 7.0, 3))


def _header(i: int) -> float:
    return HEADER0 + i * DT


def _annotations(sim):
    """(scan index, id, x, y in the laser frame) for every scan a person is seen in."""
    gt = sim.ground_truth
    out = []
    for i in range(gt.n_scans):
        if i in UNANNOTATED:
            continue
        inv = Pose2D.from_array(gt.poses[i]).inverse()
        for j, m in enumerate(gt.movers):
            if (gt.labels[i] == m.id).any():
                x, y = inv.transform_points(gt.mover_states[i, j, None, :2])[0]
                out.append((i, m.id, x, y))
    return out


def _write_bag(path, sim, people=None, people_type=PERSON_MSGTYPE, bad_index=None):
    anns = _annotations(sim) if people is None else people
    with open_bag_writer(path) as bag:
        register_person_type(bag.typestore)
        bag.add_topic("/scan", LASERSCAN)
        if people_type is not None:
            bag.add_topic("/ground_truth_people_tracks", people_type)
        cls = bag.msg_class(PERSON_MSGTYPE)
        geo = bag.typestore.types

        def pose(x, y):
            return geo["geometry_msgs/msg/Pose"](
                position=geo["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=geo["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=0.0))

        if people_type == PERSON_MSGTYPE:  # one annotation recorded before the first scan: dropped
            bag.write("/ground_truth_people_tracks", cls(pose=pose(1.0, 0.0), id=9), RECORD0 - 0.01)
        k = 0
        for i, scan in enumerate(sim.scans):
            bag.write("/scan", laserscan_message(bag, scan.with_ranges(scan.ranges, stamp=_header(i)), seq=i),
                      RECORD0 + i * DT)
            if people_type is None:
                continue
            for n, (_si, pid, x, y) in enumerate([a for a in anns if a[0] == i]):
                if people_type != PERSON_MSGTYPE:
                    msg = bag.msg_class(people_type)(header=bag.header(_header(i), "laser"), pose=pose(x, y))
                else:
                    if k == bad_index:
                        x = math.nan
                    msg = cls(pose=pose(x, y), id=pid)
                # halfway between this scan and the next, by record time
                bag.write("/ground_truth_people_tracks", msg, RECORD0 + (i + 0.5) * DT + 1e-4 * n)
                k += 1
    return path


def _removed_mask(sim):
    gt = sim.ground_truth
    lab = gt.labels
    n = lab.shape[0]
    even = (np.arange(n) % 2 == 0)[:, None]
    late = (gt.stamps >= 4.0)[:, None]
    removed = ((lab == 1) & even) | ((lab == 3) & late)
    static_cols = np.flatnonzero(lab[0] == 0)[:5]
    for i in (0, 1, 2, 21):  # 21 is not annotated: it counts only in removed_share_all
        removed[i, np.flatnonzero(lab[i] == 0)[:5]] = True
    assert static_cols.size == 5
    return removed


def _write_run(run, sim, removed, shift=0.0):
    gt = sim.ground_truth
    run.mkdir()
    stamps = np.array([_header(i) for i in range(gt.n_scans)]) + shift
    np.savez_compressed(run / "kept_mask.npz", stamps=stamps, removed=removed)
    write_tum(run / "trajectory.tum", Trajectory(stamps=stamps, poses=gt.poses))
    with (run / "tracks.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TRACK_COLUMNS)
        for i in range(gt.n_scans):
            wx, wy = gt.mover_states[i, 0, :2]
            sx, sy = gt.mover_states[i, 2, :2]
            # near the walker, not in M; then in M, far from everyone
            w.writerow([repr(float(stamps[i])), 1, "confirmed", wx, wy, 0, 0.4, 0.4, 1.0, 0.0, 0])
            w.writerow([repr(float(stamps[i])), 2, "confirmed", 10.0, 10.0, 0, 1, 1, 1.0, 0.0, 1])
            if gt.stamps[i] >= T_M - 1e-9:
                w.writerow([repr(float(stamps[i])), 3, "confirmed", sx + 0.3, sy - 0.2, 0, 0.4, 0.4, 1.2, 0.0, 1])
    return run


@pytest.fixture(scope="module")
def case(sim, tmp_path_factory):
    d = tmp_path_factory.mktemp("people")
    bag = _write_bag(d / "annotated.bag", sim)
    removed = _removed_mask(sim)
    run = _write_run(d / "run", sim, removed)
    return bag, run, removed


def test_annotations_go_to_the_last_scan_recorded_before_them(sim, case):
    ann = read_people_annotations(case[0])
    expected = _annotations(sim)
    assert ann.n_dropped == 1 and len(ann.scans) == len(sim.scans)
    assert ann.scan_index.tolist() == [a[0] for a in expected]
    assert ann.ids.tolist() == [a[1] for a in expected]
    np.testing.assert_allclose(ann.xy, [a[2:] for a in expected])
    np.testing.assert_allclose(ann.stamps, [_header(i) for i in range(len(sim.scans))])
    np.testing.assert_allclose(ann.record_times, RECORD0 + DT * np.arange(len(sim.scans)))


def test_people_metrics_are_exact(sim, case):
    bag, run, removed = case
    gt = sim.ground_truth
    m = evaluate_people(bag, run)
    lab = gt.labels
    annotated = np.ones(gt.n_scans, dtype=bool)
    annotated[list(UNANNOTATED)] = False
    beams = {pid: int((lab[annotated] == pid).sum()) for pid in (1, 2, 3)}
    removed_of = {pid: int((removed[annotated] & (lab[annotated] == pid)).sum()) for pid in (1, 2, 3)}
    assert removed_of[1] > 100 and removed_of[3] > 100 and beams[2] > 100
    per = {r.id: r for r in m.per_person}
    # person beams are exactly the simulator's labelled beams (nothing else within 0.35 m)
    for pid in (1, 2, 3):
        assert (per[pid].beams, per[pid].removed) == (beams[pid], removed_of[pid])
    assert m.person_beams == sum(beams.values()) and m.recall == sum(removed_of.values()) / m.person_beams
    # walking: the walker always, the starter from about 3 s; standing: the stander, the starter before
    assert m.walking_removed == removed_of[1] + removed_of[3] and m.standing_removed == 0
    starter_after = int((lab[annotated & (gt.stamps >= T_START + 0.5)] == 3).sum())
    starter_around = int((lab[annotated & (gt.stamps >= T_START - 0.5)] == 3).sum())
    assert beams[1] + starter_after <= m.walking_beams <= beams[1] + starter_around
    assert m.walking_beams + m.standing_beams + m.unknown_beams == m.person_beams
    assert m.walking_recall == m.walking_removed / m.walking_beams
    # non-person beams: the annotated scans' static beams; 5 removed in each of scans 0, 1, 2
    assert m.non_person_beams == int((lab[annotated] == 0).sum()) and m.non_person_removed == 15
    assert m.removed_share_all == pytest.approx(removed.sum() / (lab >= 0).sum())
    assert (m.scans, m.scans_annotated, m.people, m.walking_people) == (gt.n_scans, int(annotated.sum()), 3, 2)
    # time to M: the starter's track joins M at 4.5 s; the walker's track never does
    assert per[2].first_motion is None and per[1].reached_m is None
    assert per[1].first_motion == pytest.approx(HEADER0)
    assert HEADER0 + T_START - 0.3 <= per[3].first_motion <= HEADER0 + T_START
    assert per[3].reached_m == pytest.approx(HEADER0 + T_M)
    assert per[3].time_to_m == pytest.approx(HEADER0 + T_M - per[3].first_motion)
    assert m.people_reached_m == 1 and m.median_time_to_m == per[3].time_to_m


def test_a_tighter_radius_or_scan_frame_changes_what_counts(case):
    bag, run, _ = case
    tight = evaluate_people(bag, run, params=PeopleParams(radius=0.15))
    assert tight.person_beams < evaluate_people(bag, run).person_beams
    # the robot drives at 0.5 m/s: in its own frame even the stander moves
    scan_frame = evaluate_people(bag, run, params=PeopleParams(motion_frame="scan"))
    assert scan_frame.walking_people == 3


def test_cli_eval_people_json(case, capsys):
    bag, run, _ = case
    old, sys.argv = sys.argv, ["dynslam2d", "eval", "people", str(bag), str(run), "--json"]
    try:
        with pytest.raises(SystemExit) as exc:
            main()
    finally:
        sys.argv = old
    out = capsys.readouterr().out
    assert exc.value.code in (0, None)
    data = json.loads(out)
    assert data["non_person_removed"] == 15 and data["people"] == 3
    assert data["walking_recall"] == evaluate_people(bag, run).walking_recall


def test_wrong_or_malformed_annotation_bags_are_one_line_errors(sim, tmp_path):
    no_people = _write_bag(tmp_path / "plain.bag", sim, people_type=None)
    with pytest.raises(DynSlamError, match=r"plain.bag: no /ground_truth_people_tracks topic \(leg_tracker/msg/Person"):
        read_people_annotations(no_people)
    wrong = _write_bag(tmp_path / "wrong.bag", sim, people_type="geometry_msgs/msg/PoseStamped")
    with pytest.raises(DynSlamError, match="is geometry_msgs/msg/PoseStamped, not leg_tracker/msg/Person"):
        read_people_annotations(wrong)
    nan = _write_bag(tmp_path / "nan.bag", sim, bad_index=7)
    with pytest.raises(DynSlamError, match=r"nan.bag: topic /ground_truth_people_tracks, message index 8: "
                                           r"position \(nan, .*\) is not finite") as e:
        read_people_annotations(nan)
    assert "\n" not in str(e.value)


def test_a_run_of_another_bag_or_an_incomplete_folder_is_refused(sim, case, tmp_path):
    bag, _, removed = case
    other = _write_run(tmp_path / "other", sim, removed, shift=0.05)
    with pytest.raises(DynSlamError, match="no scan of .* has a stamp in the run"):
        evaluate_people(bag, other)
    (other / "trajectory.tum").unlink()
    with pytest.raises(DynSlamError, match="trajectory.tum is missing"):
        evaluate_people(bag, other)


def test_real_person_following_bag(tmp_path):
    """The real annotated bag, with a run folder that removes exactly the beams near the
    annotation in every other scan: recall 0.5 ± rounding, nothing else removed."""
    archive = shared_file("dynamic/leg_tracker/person_following_outdoor_1.bag.zip")
    ann = read_people_annotations(archive)
    assert len(ann.scans) == 7170 and ann.ids.shape[0] == 6179 and set(ann.ids.tolist()) == {2}
    n, beams = len(ann.scans), ann.scans[0].n_beams
    removed = np.zeros((n, beams), dtype=bool)
    for k in range(0, ann.ids.shape[0], 2):
        s = ann.scans[ann.scan_index[k]]
        with np.errstate(invalid="ignore"):
            px, py = s.ranges * np.cos(s.angles), s.ranges * np.sin(s.angles)
            near = np.hypot(px - ann.xy[k, 0], py - ann.xy[k, 1]) <= 0.35
        removed[ann.scan_index[k]] = near & s.valid_mask()
    run = tmp_path / "run"
    run.mkdir()
    stamps = ann.stamps
    np.savez_compressed(run / "kept_mask.npz", stamps=stamps, removed=removed)
    write_tum(run / "trajectory.tum", Trajectory(stamps=stamps, poses=np.zeros((n, 3))))
    (run / "tracks.csv").write_text(",".join(TRACK_COLUMNS) + "\n")
    m = evaluate_people(archive, run)
    assert m.non_person_removed == 0 and m.person_removed == int(removed.sum())
    assert 0.4 < m.recall < 0.6 and m.people == 1 and m.scans_annotated == 6179
