"""Simulated scenarios: registry, ground truth against geometry, determinism, the ScanSource."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.sim import (
    MOVER_ROW_FIELDS,
    SCENARIOS,
    SimSource,
    build_scenario,
    plot_overview,
    point_segment_distance,
    rect_segments,
    simulate,
)
from dynslam2d.sim.world import sample_segments
from dynslam2d.types import Pose2D, ScanSource, wrap_angle


@pytest.fixture(scope="module")
def paper_short():
    return simulate("paper", duration=4.0)


@pytest.fixture(scope="module")
def crowd_short():
    return simulate("crowd", duration=4.0)


def test_every_registered_scenario_builds_and_runs_briefly():
    assert {"paper", "paper-1", "paper-2", "paper-3", "static", "crowd", "corridor", "stop-and-go"} <= set(SCENARIOS)
    for name in SCENARIOS:
        sim = simulate(name, duration=0.5)
        sc = sim.scenario
        n = round(0.5 * sc.lidar.rate_hz)
        assert len(sim.scans) == n == sim.ground_truth.n_scans
        gt = sim.ground_truth
        assert gt.labels.shape == (n, sc.lidar.beams) and gt.labels.dtype == np.int16
        for scan, lab in zip(sim.scans, gt.labels):
            assert np.array_equal(scan.valid_mask(), lab >= 0)
            assert np.all(np.isinf(scan.ranges[lab < 0]))
        assert (gt.labels >= 0).mean() > 0.5, name  # the scenes are mostly enclosed
        np.testing.assert_allclose(np.diff(gt.stamps), 1.0 / sc.lidar.rate_hz)


def test_unknown_scenario_lists_the_available_ones():
    with pytest.raises(DynSlamError, match="unknown scenario 'nope'.*paper.*stop-and-go"):
        build_scenario("nope")
    with pytest.raises(DynSlamError):
        SimSource("nope")
    with pytest.raises(DynSlamError, match="sensor"):
        build_scenario("paper", beams=1)


def test_overrides_change_the_sensor_and_duration():
    sc = build_scenario("paper", duration=2.0, beams=360, fov=math.radians(270), rate_hz=10, noise_sigma=0.02)
    assert sc.n_scans == 20 and sc.lidar.beams == 360 and sc.lidar.noise_sigma == 0.02
    scan = simulate(sc).scans[0]
    assert scan.n_beams == 360 and scan.angles[0] == pytest.approx(-math.radians(135))


def _mover_outline(mover, state) -> np.ndarray:
    x, y, h = state[:3]
    return rect_segments(x, y, h, mover.shape.length, mover.shape.width)


def _check_labels_against_geometry(sim, tol):
    gt = sim.ground_truth
    static = gt.scenario.world.segments
    checked_movers = 0
    for i, scan in enumerate(sim.scans):
        lab = gt.labels[i]
        pts = Pose2D.from_array(gt.poses[i]).transform_points(scan.points(lab >= 0))
        lv = lab[lab >= 0]
        st = pts[lv == 0]
        assert point_segment_distance(st, static).max() < tol
        for j, m in enumerate(gt.movers):
            p = pts[lv == m.id]
            if p.shape[0] == 0:
                continue
            checked_movers += 1
            s = gt.mover_states[i, j]
            if m.kind == "circle":
                d = np.abs(np.hypot(p[:, 0] - s[0], p[:, 1] - s[1]) - m.shape.radius)
            else:
                d = point_segment_distance(p, _mover_outline(m, s))
            assert d.max() < tol, (m.name, i)
            # and not explained by the static structure
            assert np.median(point_segment_distance(p, static)) > tol
    return checked_movers


def test_labels_agree_with_geometry_paper(paper_short):
    sigma = paper_short.scenario.lidar.noise_sigma
    assert _check_labels_against_geometry(paper_short, 6 * sigma) > 100


def test_labels_agree_with_geometry_crowd(crowd_short):
    sigma = crowd_short.scenario.lidar.noise_sigma
    assert _check_labels_against_geometry(crowd_short, 6 * sigma) > 50


def test_measured_range_noise_matches_sigma(paper_short):
    gt = paper_short.ground_truth
    r = np.stack([s.ranges for s in paper_short.scans])
    ok = gt.labels >= 0
    err = r[ok] - gt.true_ranges[ok].astype(np.float64)
    # true ranges are stored as float32 (≈ 1e-6 m rounding, negligible against σ = 0.01)
    assert err.std() == pytest.approx(paper_short.scenario.lidar.noise_sigma, rel=0.03)
    assert abs(err.mean()) < 1e-3


def test_dropout_rate_matches_configuration():
    sim = simulate("paper", duration=2.0, dropout=0.2)
    lab = sim.ground_truth.labels
    assert (lab == -1).mean() == pytest.approx(0.2, abs=0.01)  # the room is closed: no other misses
    assert (simulate("paper", duration=2.0).ground_truth.labels == -1).mean() == 0.0


def test_same_seed_same_data_other_seed_differs():
    a = simulate("crowd", duration=1.0)
    b = simulate("crowd", duration=1.0)
    c = simulate("crowd", duration=1.0, seed=99)
    assert all(x.same_as(y) for x, y in zip(a.scans, b.scans))
    assert np.array_equal(a.ground_truth.mover_states, b.ground_truth.mover_states)
    assert not np.array_equal(a.ground_truth.mover_states, c.ground_truth.mover_states)
    assert not any(x.same_as(y) for x, y in zip(a.scans, c.scans))
    # for a scripted scene the seed only changes the noise
    p1, p2 = simulate("paper", duration=0.5, seed=1), simulate("paper", duration=0.5, seed=2)
    assert np.array_equal(p1.ground_truth.mover_states, p2.ground_truth.mover_states)
    assert not np.array_equal(p1.scans[0].ranges, p2.scans[0].ranges)


def test_paper_movers_sizes_and_speeds():
    for name in ("paper", "paper-1", "paper-2", "paper-3"):
        sim = simulate(name, beams=16)  # full duration, few beams: mover ground truth is what matters
        gt = sim.ground_truth
        sizes = sorted((m.shape.length, m.shape.width) for m in gt.movers)
        assert sizes == [(0.1, 2.0), (1.0, 1.0), (1.0, 1.0)]
        assert all(m.kind == "rect" for m in gt.movers)
        assert sim.scenario.duration >= 60.0
        speed = np.hypot(gt.mover_states[..., 3], gt.mover_states[..., 4])
        assert (speed > 0.5).mean(axis=0).min() > 0.9, name


def test_paper_variants_differ_in_robot_and_mover_motion():
    stamps = np.arange(0, 60, 0.05)
    yaw = {n: build_scenario(n).robot.sample(stamps)[:, 2] for n in ("paper", "paper-1", "paper-2", "paper-3")}
    spans = {n: np.ptp(np.unwrap(y)) for n, y in yaw.items()}
    assert len({round(s, 2) for s in spans.values()}) == 4
    pos = {n: build_scenario(n).movers[1].trajectory.sample(stamps)[:, :2] for n in yaw}
    assert not np.allclose(pos["paper"], pos["paper-2"]) and not np.allclose(pos["paper-1"], pos["paper-3"])


@pytest.mark.parametrize("name", ["paper-2", "crowd", "stop-and-go", "corridor"])
def test_mover_velocity_equals_finite_difference_of_positions(name):
    sc = build_scenario(name)
    t = np.arange(0.0, sc.duration, 0.01)
    for m in sc.movers:
        s = m.trajectory.sample(t)
        fd = (s[2:, :2] - s[:-2, :2]) / 0.02
        err = np.hypot(*(fd - s[1:-1, 3:5]).T)
        # exact except across the instants where the velocity changes
        assert (err < 1e-6).mean() > 0.95, m.name
        assert np.median(err) < 1e-9


def test_ground_truth_velocity_matches_positions_at_scan_rate(paper_short):
    gt = paper_short.ground_truth
    dt = np.diff(gt.stamps)[:, None, None]
    fd = (gt.mover_states[2:, :, :2] - gt.mover_states[:-2, :, :2]) / (2 * dt[:1])
    err = np.linalg.norm(fd - gt.mover_states[1:-1, :, 3:5], axis=-1)
    assert (err < 1e-6).mean() > 0.9


def test_robot_never_inside_a_mover_and_movers_clear_static_structure():
    import dataclasses

    from dynslam2d.sim.scenarios import SENSOR_CONTACT_SCENARIOS

    for name in SCENARIOS:
        sc = build_scenario(name)
        if name in SENSOR_CONTACT_SCENARIOS:  # the person walks through the sensor on purpose
            sc = dataclasses.replace(sc, movers=())
        t = sc.stamps
        robot = sc.robot.sample(t)[:, :2]
        static = sc.world.segments
        for m in sc.movers:
            s = m.trajectory.sample(t)
            if m.kind == "circle":
                assert np.hypot(*(robot - s[:, :2]).T).min() > m.shape.radius + 0.3, (name, m.name)
                outline = (s[:, None, :2] + m.shape.radius *
                           np.stack([np.cos(np.linspace(0, 2 * np.pi, 24)), np.sin(np.linspace(0, 2 * np.pi, 24))],
                                    axis=1)[None]).reshape(-1, 2)
            else:
                c, sn = np.cos(s[:, 2]), np.sin(s[:, 2])
                dx, dy = robot[:, 0] - s[:, 0], robot[:, 1] - s[:, 1]
                lx, ly = c * dx + sn * dy, -sn * dx + c * dy  # robot in the mover's frame
                outside = np.maximum(np.abs(lx) - m.shape.length / 2, np.abs(ly) - m.shape.width / 2)
                assert outside.min() > 0.3, (name, m.name)
                outline = np.vstack([sample_segments(rect_segments(*row[:3], m.shape.length, m.shape.width), 0.1)
                                     for row in s[::5]])
            assert point_segment_distance(outline, static).min() > 0.05, (name, m.name)


def test_static_scenario_yaw_rate_and_no_movers():
    sc = build_scenario("static")
    rate = np.abs(sc.robot.yaw_rate(sc.stamps))
    assert 0.8 < rate.max() <= 1.1
    assert not sc.movers
    xy = sc.robot.sample(sc.stamps)[:, :2]
    assert 0.3 < np.ptp(xy[:, 0]) < 1.5  # moves a little
    sim = simulate(sc, duration=1.0)
    assert sim.ground_truth.labels.max() == 0


def test_crowd_people_are_discs_of_human_size():
    sc = build_scenario("crowd")
    assert len(sc.movers) >= 5
    for m in sc.movers:
        assert m.kind == "circle" and 0.4 <= 2 * m.shape.radius <= 0.5
    xy = sc.robot.sample(sc.stamps)[:, :2]
    assert np.hypot(*np.ptp(xy, axis=0)) > 5.0  # the robot drives


def test_stop_and_go_has_parked_and_moving_phases():
    sc = build_scenario("stop-and-go")
    t = sc.stamps
    speed = {m.name: np.hypot(*m.trajectory.sample(t)[:, 3:5].T) for m in sc.movers}
    box, car, person = speed["box-arriving"], speed["car-leaving"], speed["person-stop-and-go"]
    assert np.all(box[t < 5.0] == 0) and np.all(box[t > 21.0] == 0) and box[(t > 6) & (t < 19)].min() > 0.5
    assert np.all(car[t < 28.0] == 0) and car[(t > 29) & (t < 40)].min() > 0.5 and np.all(car[t > 47] == 0)
    assert 0.2 < (person == 0).mean() < 0.8


def test_static_map_has_occupied_cells_on_walls(paper_short):
    gt = paper_short.ground_truth
    for frame in ("world", "first"):
        g = gt.static_map(0.05, frame=frame)
        walls = gt.scenario.world.segments
        if frame == "first":
            walls = np.column_stack((gt.world_to_first().transform_points(walls[:, :2]),
                                     gt.world_to_first().transform_points(walls[:, 2:])))
        pts = sample_segments(walls, 0.01)
        c = g.world_to_cell(pts)
        assert np.all(g.prob[c[:, 1], c[:, 0]] == 1.0)
        robot = g.world_to_cell(gt.poses_in(frame)[:1, :2])
        assert g.prob[robot[0, 1], robot[0, 0]] == 0.0
        free_area = (g.prob == 0.0).sum() * 0.05**2
        assert 95.0 < free_area < 101.0  # ≈ 10×10 m room + alcove + recess − chamfer − furniture
        assert np.isnan(g.prob).sum() * 0.05**2 > 10.0  # outside the building
    # the laser sees what the map holds: static hits land on occupied cells (±1 cell)
    g = gt.static_map(0.05)
    lab = gt.labels[0]
    pts = Pose2D.from_array(gt.poses[0]).transform_points(paper_short.scans[0].points(lab >= 0))[lab[lab >= 0] == 0]
    c = g.world_to_cell(pts)
    occ = g.occupied()
    near = np.zeros(len(c), dtype=bool)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            near |= occ[c[:, 1] + dy, c[:, 0] + dx]
    assert near.all()


def test_first_frame_poses_and_mover_rows():
    sim = simulate("paper-2", duration=2.0)  # its first laser heading is 0.3 rad, not the world's
    gt = sim.ground_truth
    first = gt.poses_in("first")
    assert gt.first_pose.theta == pytest.approx(0.3)
    np.testing.assert_allclose(first[0], 0.0, atol=1e-12)
    for i in (5, 30):
        rel = gt.first_pose.between(gt.pose(i))
        np.testing.assert_allclose(first[i], rel.as_array(), atol=1e-12)
        assert gt.pose(i, "first").as_array() == pytest.approx(rel.as_array())
    rows = gt.mover_rows()
    assert rows.dtype.names == MOVER_ROW_FIELDS and rows.shape == (gt.n_scans * 3,)
    k = 3 * 7 + 1  # scan 7, second mover
    assert rows["stamp"][k] == gt.stamps[7] and rows["id"][k] == gt.mover_ids[1] and rows["kind"][k] == "rect"
    np.testing.assert_allclose([rows["x"][k], rows["vx"][k]], gt.mover_states[7, 1, [0, 3]])
    assert rows["hits"].sum() == (gt.labels > 0).sum()
    rf = gt.mover_rows("first")
    np.testing.assert_allclose(np.hypot(rf["vx"], rf["vy"]), np.hypot(rows["vx"], rows["vy"]), atol=1e-12)
    back = gt.first_pose.transform_points(np.column_stack((rf["x"], rf["y"])))
    np.testing.assert_allclose(back, np.column_stack((rows["x"], rows["y"])), atol=1e-12)
    v_back = Pose2D(0.0, 0.0, gt.first_pose.theta).transform_points(np.column_stack((rf["vx"], rf["vy"])))
    np.testing.assert_allclose(v_back, np.column_stack((rows["vx"], rows["vy"])), atol=1e-12)
    np.testing.assert_allclose(rf["heading"], np.asarray(wrap_angle(rows["heading"] - 0.3)), atol=1e-12)
    st = gt.states_at(7, "first")[1]
    assert (st.x, st.y, st.vx) == pytest.approx((rf["x"][k], rf["y"][k], rf["vx"][k]))
    with pytest.raises(DynSlamError, match="frame"):
        gt.poses_in("map")


def test_sim_source_is_a_scan_source_replaying_the_simulation():
    src = SimSource("corridor", duration=1.0)
    assert isinstance(src, ScanSource)
    assert src.meta.format == "sim" and src.meta.origin == "sim:corridor" and src.meta.count == len(src) == 20
    assert src.meta.beams == 720 and src.meta.rate_hz == 20.0
    first = list(src)
    again = list(src)
    ref = simulate("corridor", duration=1.0)
    assert len(first) == 20
    assert all(a.same_as(b) and a.same_as(c) for a, b, c in zip(first, again, ref.scans))
    gt = src.ground_truth
    assert np.array_equal(gt.labels, ref.ground_truth.labels)
    assert all(a.same_as(b) for a, b in zip(src, ref.scans))


def test_plot_overview_writes_a_png(tmp_path, crowd_short):
    out = plot_overview(crowd_short, tmp_path / "ov" / "crowd.png")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert [p.name for p in out.parent.iterdir()] == ["crowd.png"]  # no temporary left behind
    plot_overview(crowd_short, tmp_path / "first.png", scan_index=-1, frame="first")
    with pytest.raises(IndexError):
        plot_overview(crowd_short, tmp_path / "bad.png", scan_index=10_000)
    assert not (tmp_path / "bad.png").exists()
