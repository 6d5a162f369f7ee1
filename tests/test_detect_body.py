"""The robot's own body: footprint polygon (validation, dropping), automatic body beams, riding tracks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.config import Config, config_from_dict
from dynslam2d.detect.body import BodyFilter, convex_hull, points_in_polygon, polygon_problem
from dynslam2d.detect.config import FootprintConfig
from dynslam2d.errors import DynSlamError
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import cast_rays, rect_segments
from dynslam2d.sim.world import transform_segments
from dynslam2d.types import Pose2D, Scan

N = 720
FOV = math.radians(270.0)
ANGLES = -0.5 * FOV + np.arange(N) * FOV / (N - 1)
ROOM = np.vstack([rect_segments(0.0, 0.0, 0.0, 14.0, 10.0), rect_segments(2.0, 2.5, 0.4, 1.0, 0.6),
                  rect_segments(-3.0, -2.0, 0.0, 0.6, 0.6)])
# a bumper and a mast seen by the laser, in the LASER frame (they move with the robot)
BODY = np.vstack([rect_segments(-0.25, 0.3, 0.0, 0.3, 0.06), rect_segments(-0.3, -0.28, 0.0, 0.08, 0.08)])


def drive(n_scans: int = 120, rate: float = 10.0, config: Config | None = None):
    """A robot driving a curve at ≈0.8 m/s in a room; the laser sees BODY; yields (scan, pose, body labels)."""
    pipe = Pipeline(config)
    steps = []
    for i in range(n_scans):
        t = i / rate
        pose = Pose2D(-4.0 + 0.8 * t, -1.0 + 1.5 * math.sin(0.25 * t), 0.4 * math.sin(0.25 * t))
        segs = np.vstack([ROOM, transform_segments(BODY, pose)])
        ids = np.concatenate([np.zeros(ROOM.shape[0], dtype=np.int32), np.ones(BODY.shape[0], dtype=np.int32)])
        dist, lab = cast_rays((pose.x, pose.y), pose.theta + ANGLES, segs, ids, np.zeros((0, 3)),
                              np.zeros(0, dtype=np.int32))
        r = dist + np.random.default_rng(i).normal(0.0, 0.01, dist.shape)
        scan = Scan(stamp=t, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]), ranges=r,
                    range_min=0.05, range_max=20.0)
        steps.append((pipe.process(scan), lab, scan))
    return pipe, steps


@pytest.mark.parametrize("polygon, why", [
    ([(0, 0), (1, 1), (1, 0), (0, 1)], "not simple"),
    ([(0, 0), (1, 0), (2, 0)], "no area"),
    ([(0, 0), (1, 0)], "at least 3"),
])
def test_bad_footprint_is_a_one_line_error(polygon, why) -> None:
    assert why in polygon_problem(polygon)
    with pytest.raises(DynSlamError) as err:
        config_from_dict({"detect": {"footprint": {"polygon": polygon}}}, origin="robot.yaml")
    msg = str(err.value)
    assert "\n" not in msg and "robot.yaml" in msg and "footprint" in msg and why in msg
    with pytest.raises(DynSlamError):
        BodyFilter(FootprintConfig.model_construct(polygon=polygon, auto=False))


def test_polygon_helpers() -> None:
    square = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    assert polygon_problem(square) is None
    inside = points_in_polygon(np.array([[0, 0], [0.9, -0.9], [1.1, 0], [np.nan, 0]]), np.array(square))
    assert inside.tolist() == [True, True, False, False]
    hull = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]]))
    assert hull.shape == (4, 2)


def test_footprint_returns_are_dropped_before_everything() -> None:
    cfg = Config()
    cfg.detect.footprint = FootprintConfig(polygon=[(-0.5, -0.45), (0.05, -0.45), (0.05, 0.45), (-0.5, 0.45)],
                                           auto=False)
    pipe, steps = drive(40, config=cfg)
    for step, lab, _ in steps:
        assert np.array_equal(step.body, lab == 1)  # exactly the body's returns, nothing else
        assert not step.removed[lab == 1].any()
    assert pipe.body.report()["footprint_dropped_returns"] == sum(int((lab == 1).sum()) for _, lab, _ in steps)


def test_body_is_found_automatically_and_never_follows_the_robot() -> None:
    pipe, steps = drive(120)
    body_beams = np.flatnonzero(steps[-1][1] == 1)
    found = pipe.body.body
    assert found[body_beams].mean() > 0.8  # most body beams found
    assert not found[steps[-1][1] == 0].any()  # no wall beam taken for the body
    later = [(s, lab) for s, lab, _ in steps[60:]]
    assert np.mean([s.body[lab == 1].mean() for s, lab in later]) > 0.9
    # no track in M anywhere near the robot once the body is found (before that, only a footprint polygon
    # protects: a car keeping pace alongside looks exactly like a bumper for a while, datmo's parallel bag)
    first = next(i for i, (s, lab, _) in enumerate(steps) if s.body[lab == 1].mean() > 0.5)
    assert first <= 40
    for step, _lab, _ in steps[first:]:
        for t in step.tracks:
            if t.in_m:
                assert math.hypot(t.box.px - step.pose.x, t.box.py - step.pose.y) > 1.0
    rep = pipe.body.report(Scan(stamp=0.0, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]),
                                ranges=np.ones(N), range_min=0.05, range_max=20.0))
    poly = np.array(rep["suggested_footprint"])
    assert polygon_problem(poly) is None
    last_scan, last_lab = steps[-1][2], steps[-1][1]
    seen = last_scan.points(last_lab == 1)  # the body's returns, laser frame
    assert points_in_polygon(seen, poly).mean() > 0.9


def test_without_the_body_filter_the_body_rides_with_the_robot() -> None:
    """Control: with the automatic detection off the body's returns are tracked; the riding test keeps
    them out of M (they are fixed in the laser frame while the laser moves)."""
    cfg = Config()
    cfg.detect.footprint.auto = False
    pipe, steps = drive(80, config=cfg)
    riding = [t for step, lab, _ in steps for t in step.tracks if t.n_points and (lab[t.beams] == 1).all()]
    assert riding, "the body's returns are tracked"
    assert any("laser frame" in t.m_reason for t in riding)
    assert not any(t.in_m for t in riding)


def _body_scans(n_scans: int, move: bool) -> tuple[list[Scan], np.ndarray]:
    """The scans of :func:`drive` (or of a laser standing still at its start) and the last scan's body labels."""
    scans, lab = [], None
    for i in range(n_scans):
        t = i / 10.0
        tt = t if move else 0.0
        pose = Pose2D(-4.0 + 0.8 * tt, -1.0 + 1.5 * math.sin(0.25 * tt), 0.4 * math.sin(0.25 * tt))
        segs = np.vstack([ROOM, transform_segments(BODY, pose)])
        ids = np.concatenate([np.zeros(ROOM.shape[0], dtype=np.int32), np.ones(BODY.shape[0], dtype=np.int32)])
        dist, lab = cast_rays((pose.x, pose.y), pose.theta + ANGLES, segs, ids, np.zeros((0, 3)),
                              np.zeros(0, dtype=np.int32))
        r = dist + np.random.default_rng(i).normal(0.0, 0.01, dist.shape)
        scans.append(Scan(stamp=100.0 + t, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]),
                          ranges=r, range_min=0.05, range_max=20.0))
    return scans, lab


def test_info_finds_the_body_in_a_bag_and_suggests_a_footprint(tmp_path, capsys) -> None:
    """`dynslam2d info` on a bag of a driving robot whose laser sees a bumper and a mast: the body beams (and
    no wall beam) are reported with a footprint that holds the body's returns; from a motionless laser it
    says why it cannot tell (and finds nothing)."""
    import json

    from conftest import run_cli

    from dynslam2d.io.rosbag import write_scan_bag

    scans, lab = _body_scans(120, move=True)
    bag = write_scan_bag(tmp_path / "drive.mcap", scans)
    code, out, _ = run_cli(capsys, "info", str(bag), "--json")
    assert code == 0
    body = json.loads(out)["body"]
    found = np.zeros(N, dtype=bool)
    found[body["auto_body_beam_indices"]] = True
    assert found[lab == 1].mean() > 0.8 and not found[lab == 0].any()
    assert body["enough_motion"] and body["scans_used"] == 120
    lo, hi = body["body_range_m"]
    assert 0.2 < lo <= hi < 0.6  # the bumper and mast lie 0.25-0.45 m from the laser
    poly = np.array(body["suggested_footprint"])
    assert polygon_problem(poly) is None
    assert points_in_polygon(scans[-1].points(lab == 1), poly).mean() > 0.9
    code, out, _ = run_cli(capsys, "info", str(bag))
    assert code == 0 and "robot body" in out and "suggested" in out
    still, _ = _body_scans(60, move=False)
    bag2 = write_scan_bag(tmp_path / "still.mcap", still)
    code, out, _ = run_cli(capsys, "info", str(bag2), "--json")
    body2 = json.loads(out)["body"]
    assert body2["auto_body_beams"] == 0 and not body2["enough_motion"]
    code, out, _ = run_cli(capsys, "info", str(bag2))
    assert "cannot tell its body from a wall" in " ".join(out.split())
    code, out, _ = run_cli(capsys, "info", str(bag), "--json", "--body-scans", "0")
    assert "body" not in json.loads(out)


def test_the_first_mask_is_the_scans_valid_mask_written_in_the_drop_pass() -> None:
    """Pass rest18: ``mask`` on a scan without its valid mask yet has ``_drop_body`` write it (finite and within
    [range_min, range_max], both limits included) and the scan keeps it; a scan holding its mask keeps that one; the
    drops equal the array expressions' on both paths."""
    rng = np.random.default_rng(3)
    lo, hi = 0.1, 8.0
    r = rng.uniform(0.0, 9.0, 400)
    r[:12] = [np.nan, np.inf, -np.inf, lo, hi, np.nextafter(lo, 0.0), np.nextafter(hi, 9.0), 0.0, -1.0,
              np.nextafter(lo, 1.0), np.nextafter(hi, 0.0), 0.3]
    body = BodyFilter(FootprintConfig())
    drop_r = np.where(rng.random(400) < 0.3, rng.uniform(0.0, 5.0, 400), 0.0)
    drop_r[3] = drop_r[4] = drop_r[9] = drop_r[11] = 10.0  # (beams at and next to the limits are body beams)
    tol = float(FootprintConfig().auto_tolerance)
    for cached in (False, True):
        scan = Scan(stamp=1.0, angle_min=-1.0, angle_increment=0.005, ranges=r.copy(), range_min=lo, range_max=hi)
        held = scan.valid_view() if cached else None
        body.mask(scan)  # (the first call makes the per-beam state: then the drop ranges are set)
        body._drop_r = drop_r.copy()
        scan = Scan(stamp=1.0, angle_min=-1.0, angle_increment=0.005, ranges=r.copy(), range_min=lo, range_max=hi)
        if cached:
            held = scan.valid_view()
        assert scan.has_valid_mask() is cached
        drop = body.mask(scan)
        want = np.isfinite(r) & (r >= lo) & (r <= hi)
        assert scan.has_valid_mask()
        np.testing.assert_array_equal(scan.valid_view(), want)
        assert want[3] and want[4] and not want[5] and not want[6]  # (both limits inside, one ulp out outside)
        if cached:
            assert scan.valid_view() is held
        np.testing.assert_array_equal(drop, want & (drop_r > 0.0) & (r <= drop_r + tol))
        assert drop[3] and drop[4] and not drop[5] and not drop[6]


@pytest.mark.parametrize("polygon, auto", [(None, True), ([(-0.4, -0.1), (0.1, -0.1), (0.1, 0.45), (-0.4, 0.45)], True),
                                           ([(-0.4, -0.1), (0.1, -0.1), (0.1, 0.45), (-0.4, 0.45)], False)])
def test_apply_is_mask_then_without(polygon, auto) -> None:
    """Pass bdy122: ``apply`` writes the filtered scan in ``_drop_body``'s pass; its drop mask, ranges (NaN where
    dropped) and valid mask equal ``mask`` + ``Scan.without`` bit for bit on the driving robot's scans (body beams
    found after a few seconds; with a footprint every scan drops), and the scan itself comes back when
    nothing is dropped. The filters' state and counts stay equal."""
    cfg = FootprintConfig.model_construct(**{**FootprintConfig().model_dump(), "polygon": polygon, "auto": auto})
    _, steps = drive(120)
    a, b = BodyFilter(cfg), BodyFilter(cfg)
    same = dropped = 0
    for res, _, scan in steps:
        s1 = Scan(stamp=scan.stamp, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
                  ranges=scan.ranges.copy(), range_min=scan.range_min, range_max=scan.range_max)
        s2 = Scan(stamp=scan.stamp, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
                  ranges=scan.ranges.copy(), range_min=scan.range_min, range_max=scan.range_max)
        d1, out = a.apply(s1)
        d2 = b.mask(s2)
        np.testing.assert_array_equal(d1, d2)
        if not d2.any():
            assert out is s1
            same += 1
        else:
            want = s2.without(d2)
            assert np.array_equal(out.ranges, want.ranges, equal_nan=True)
            np.testing.assert_array_equal(out.valid_view(), want.valid_view())
            np.testing.assert_array_equal(out.valid_view(), out.valid_mask(out.range_min, out.range_max))
            assert out.stamp == s1.stamp and out.angle_min == s1.angle_min and out.trig()[0] is s1.trig()[0]
            dropped += 1
        a.observe(s1, res.pose)
        b.observe(s2, res.pose)
    assert dropped > 30 and (same > 10 if polygon is None else same == 0)  # (the footprint holds body returns)
    np.testing.assert_array_equal(a.body, b.body)
    assert a.report(steps[-1][2]) == b.report(steps[-1][2])
