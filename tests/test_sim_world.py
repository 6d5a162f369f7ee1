"""Simulator geometry: ray casting, trajectories, the beam model, static-map rasterisation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.sim.movers import Keyframes, ping_pong, random_waypoints, square_loop, timeline
from dynslam2d.sim.robot import oscillating_in_place, waypoint_path
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.world import (
    World,
    cast_rays,
    point_segment_distance,
    polyline_segments,
    rect_corners,
    rect_segments,
    sample_segments,
)

SQUARE_ROOM = polyline_segments([(-5, -5), (5, -5), (5, 5), (-5, 5)], closed=True)


# ---------------------------------------------------------------- ray casting

def test_rays_in_square_room_hit_walls_at_exact_distances():
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4, math.atan2(4.5, -6.0)])
    dist, ids = cast_rays((1.0, 0.5), angles, SQUARE_ROOM)
    expected = [4.0, 4.5, 6.0, 5.5, 4.0 * math.sqrt(2.0), math.hypot(4.5, 6.0)]  # the last one ends in a corner
    np.testing.assert_allclose(dist, expected, rtol=0, atol=1e-12)
    assert ids.tolist() == [0] * 6


def test_ray_vs_circle_matches_closed_form():
    # circle of radius 1 at (3, 0) seen from the origin: d(a) = 3 cos a − sqrt(1 − 9 sin² a)
    a = np.array([0.0, 0.1, -0.2, 0.3, 0.4])
    dist, ids = cast_rays((0.0, 0.0), a, np.zeros((0, 4)), circles=[[3.0, 0.0, 1.0]], circle_ids=[7])
    hit = np.abs(np.sin(a)) < 1.0 / 3.0
    exp = 3 * np.cos(a[hit]) - np.sqrt(1 - 9 * np.sin(a[hit]) ** 2)
    np.testing.assert_allclose(dist[hit], exp, atol=1e-12)
    assert ids[hit].tolist() == [7] * int(hit.sum())
    assert np.all(np.isinf(dist[~hit])) and np.all(ids[~hit] == -1)
    assert (~hit).sum() == 1  # a = 0.4 misses (sin 0.4 > 1/3)


def test_ray_vs_rotated_rectangle_uses_length_along_heading():
    # length 2 along heading π/2 (i.e. along world y), width 1 across → near face at x = 3 − 0.5
    segs = rect_segments(3.0, 0.0, math.pi / 2, 2.0, 1.0)
    d, ids = cast_rays((0.0, 0.0), np.array([0.0, math.atan2(0.9, 2.5), math.atan2(1.1, 2.5)]), segs,
                       np.full(4, 4))
    assert d[0] == pytest.approx(2.5, abs=1e-12)
    assert d[1] == pytest.approx(math.hypot(2.5, 0.9), abs=1e-12)  # still on the near face (|y| ≤ 1)
    assert np.isinf(d[2]) and ids[2] == -1  # passes above the corner (2.5, 1)
    assert ids[:2].tolist() == [4, 4]
    # from above, straight down onto the top face y = 1
    d_top, _ = cast_rays((3.2, 3.0), np.array([-math.pi / 2]), segs)
    assert d_top[0] == pytest.approx(2.0, abs=1e-12)
    # a unit square turned 45°: its near vertex at x = 4 − √2/2
    d45, _ = cast_rays((0.0, 0.0), np.array([0.0]), rect_segments(4.0, 0.0, math.pi / 4, 1.0, 1.0))
    assert d45[0] == pytest.approx(4.0 - math.sqrt(0.5), abs=1e-12)


def test_nearest_hit_wins_whatever_the_order():
    wall = np.array([[3.0, -1.0, 3.0, 1.0]])
    box = rect_segments(2.0, 0.0, 0.0, 0.5, 0.5)  # near face at x = 1.75
    for segs, ids in ((np.vstack((wall, box)), [0, 2, 2, 2, 2]), (np.vstack((box, wall)), [2, 2, 2, 2, 0])):
        d, lab = cast_rays((0.0, 0.0), np.array([0.0]), segs, ids)
        assert d[0] == pytest.approx(1.75) and lab[0] == 2
    # a circle in front of the box wins; behind the wall it is hidden
    d, lab = cast_rays((0.0, 0.0), np.array([0.0]), np.vstack((wall, box)), [0, 2, 2, 2, 2],
                       circles=[[1.0, 0.0, 0.2], [5.0, 0.0, 0.3]], circle_ids=[5, 6])
    assert d[0] == pytest.approx(0.8) and lab[0] == 5
    # overlapping collinear walls: still the nearest crossing
    d, lab = cast_rays((0.0, 0.0), np.array([0.0]), [[2.0, -1.0, 2.0, 1.0], [2.0, -2.0, 2.0, 0.5],
                                                      [1.0, -1.0, 1.0, -0.5]], [1, 2, 3])
    assert d[0] == pytest.approx(2.0) and lab[0] in (1, 2)


def test_max_dist_and_origin_behind_segment():
    d, lab = cast_rays((0.0, 0.0), np.array([0.0, math.pi]), [[3.0, -1.0, 3.0, 1.0]], max_dist=2.0)
    assert np.all(np.isinf(d)) and np.all(lab == -1)  # beyond max_dist, and behind the ray


def _brute_force(origin, angles, segs):
    out = []
    for a in angles:
        best = math.inf
        dx, dy = math.cos(a), math.sin(a)
        for x0, y0, x1, y1 in segs:
            ex, ey = x1 - x0, y1 - y0
            den = dx * ey - dy * ex
            if abs(den) < 1e-12:
                continue
            wx, wy = x0 - origin[0], y0 - origin[1]
            t = (wx * ey - wy * ex) / den
            u = (wx * dy - wy * dx) / den
            if t > 0 and 0 <= u <= 1:
                best = min(best, t)
        out.append(best)
    return np.array(out)


def test_kernel_matches_brute_force_on_random_scene():
    rng = np.random.default_rng(3)
    segs = rng.uniform(-6, 6, (35, 4))
    angles = rng.uniform(-math.pi, math.pi, 300)
    d, _ = cast_rays((0.3, -0.2), angles, segs)
    np.testing.assert_allclose(d, _brute_force((0.3, -0.2), angles, segs), atol=1e-9)
    assert np.isfinite(d).sum() > 100


# ---------------------------------------------------------------- trajectories

def test_square_loop_visits_corners_at_constant_speed():
    tr = square_loop((1.0, 2.0), 2.0, speed=0.5, heading=0.3)
    period = 8.0 / 0.5
    assert tr.period == pytest.approx(period)
    corners = tr.sample(np.array([0.0, 4.0, 8.0, 12.0, 16.0]))[:, :2]
    np.testing.assert_allclose(corners, [[0, 1], [2, 1], [2, 3], [0, 3], [0, 1]], atol=1e-12)
    s = tr.sample(np.linspace(0, 40, 801))
    np.testing.assert_allclose(np.hypot(s[:, 3], s[:, 4]), 0.5, atol=1e-12)
    np.testing.assert_allclose(s[:, 2], 0.3)
    # phase shifts along the loop: phase 0.25 starts at the second corner
    assert square_loop((1.0, 2.0), 2.0, 0.5, phase=0.25).sample(0.0)[:2] == pytest.approx([2.0, 1.0])


def test_heading_along_the_path_turns_at_corners_and_reversals():
    tr = square_loop((0.0, 0.0), 2.0, 1.0, heading=None)
    h = tr.sample(np.array([0.5, 2.5, 4.5, 6.5, 8.5]))[:, 2]
    np.testing.assert_allclose(np.cos(h), [1, 0, -1, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.sin(h), [0, 1, 0, -1, 0], atol=1e-12)
    pp = ping_pong([(0.0, 0.0), (2.0, 0.0)], 1.0, heading=None, pause=1.0)
    s = pp.sample(np.array([1.0, 2.5, 3.5, 6.5]))
    np.testing.assert_allclose(np.cos(s[:, 2]), [1, 1, -1, 1], atol=1e-12)  # faces back only once it leaves
    np.testing.assert_allclose(s[:, 3], [1, 0, -1, 1], atol=1e-12)


def test_keyframe_velocity_is_the_exact_slope():
    tr = Keyframes(np.array([0.0, 2.0, 2.0, 5.0]), np.array([[0, 0], [2, 1], [2, 1], [2, 4]]),
                   np.array([0.0, 0.0, 1.0, 1.0]))
    s = tr.sample(np.array([1.0, 2.5, 6.0, -1.0]))
    np.testing.assert_allclose(s[0], [1.0, 0.5, 0.0, 1.0, 0.5, 0.0])
    np.testing.assert_allclose(s[1], [2.0, 1.5, 1.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(s[2], [2.0, 4.0, 1.0, 0.0, 0.0, 0.0])  # held after the end
    np.testing.assert_allclose(s[3], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # held before the start


def test_ping_pong_l_route_reverses_and_dwells():
    tr = ping_pong([(0, 0), (2, 0), (2, 1)], speed=1.0, heading=0.0, pause=0.5)
    assert tr.period == pytest.approx(2 * 3.0 + 2 * 0.5)
    s = tr.sample(np.array([1.0, 2.5, 3.2, 3.6, 5.0]))
    np.testing.assert_allclose(s[:, :2], [[1, 0], [2, 0.5], [2, 1], [2, 0.9], [1.5, 0]], atol=1e-12)
    np.testing.assert_allclose(s[:, 3:5], [[1, 0], [0, 1], [0, 0], [0, -1], [-1, 0]], atol=1e-12)


def test_random_waypoints_stay_in_region_and_cover_duration():
    rng = np.random.default_rng(0)
    region = (-1.0, 2.0, 0.5, 1.5)
    tr = random_waypoints(rng, region, duration=30.0, speed_range=(0.5, 1.0), pause_range=(0.0, 1.0))
    assert tr.end_time > 30.0
    s = tr.sample(np.linspace(0, 30, 3001))
    assert s[:, 0].min() >= -1 and s[:, 0].max() <= 2 and s[:, 1].min() >= 0.5 and s[:, 1].max() <= 1.5
    sp = np.hypot(s[:, 3], s[:, 4])
    assert sp.max() <= 1.0 + 1e-9 and (sp == 0).mean() > 0.02 and (sp >= 0.5 - 1e-9).mean() > 0.5


def test_timeline_waits_then_drives_then_parks():
    tr = timeline((0.0, 0.0), [("wait", 2.0), ("go", (3.0, 4.0), 1.0)])
    s = tr.sample(np.array([1.0, 4.5, 10.0]))
    np.testing.assert_allclose(s[0, :2], [0, 0]) and np.testing.assert_allclose(s[0, 3:5], [0, 0])
    np.testing.assert_allclose(s[1, :2], [1.5, 2.0])
    np.testing.assert_allclose(s[1, 3:5], [0.6, 0.8])
    assert s[1, 2] == pytest.approx(math.atan2(4, 3))
    np.testing.assert_allclose(s[2, :5], [3.0, 4.0, math.atan2(4, 3), 0, 0])


def test_robot_oscillation_and_waypoint_turns():
    r = oscillating_in_place(1.0, 2.0, 0.5, amplitude=0.4, period=4.0)
    p = r.sample(np.array([0.0, 1.0, 3.0]))
    np.testing.assert_allclose(p, [[1, 2, 0.5], [1, 2, 0.9], [1, 2, 0.1]], atol=1e-12)
    assert r.yaw_rate(0.0) == pytest.approx(0.4 * 2 * math.pi / 4.0)
    w = waypoint_path([(0, 0), (2, 0), (2, 2)], speed=0.5, turn_rate=0.5, loop=True)
    t = np.linspace(0, 60, 6001)
    s = w.sample(t)
    # turns in place (no heading jump between consecutive samples) at ≤ turn_rate
    dh = np.abs(np.diff(np.unwrap(s[:, 2]))) / np.diff(t)
    assert dh.max() <= 0.5 + 1e-6
    assert w.sample(4.0)[:2] == pytest.approx([2.0, 0.0])


# ---------------------------------------------------------------- beam model

def test_beam_geometry_full_circle_and_partial_fan():
    full = LidarModel(beams=720)
    assert full.angle_increment == pytest.approx(2 * math.pi / 720) and full.angle_min == -math.pi
    fan = LidarModel(beams=1081, fov=math.radians(270))
    assert fan.angles[0] == pytest.approx(-math.radians(135)) and fan.angles[-1] == pytest.approx(math.radians(135))
    scan = fan.make_scan(1.5, np.full(1081, 2.0))
    assert scan.n_beams == 1081 and scan.angle_max == pytest.approx(math.radians(135))


def test_measured_noise_and_dropout_rates_match_configuration():
    rng = np.random.default_rng(1)
    true = rng.uniform(0.5, 10.0, 200_000)
    lid = LidarModel(beams=720, noise_sigma=0.02, dropout=0.15, range_min=0.1, range_max=20.0)
    r, valid = lid.measure(true, rng)
    err = r[valid] - true[valid]
    assert err.std() == pytest.approx(0.02, rel=0.02)
    assert abs(err.mean()) < 3 * 0.02 / math.sqrt(valid.sum())
    assert (~valid).mean() == pytest.approx(0.15, abs=0.005)
    assert np.all(np.isinf(r[~valid]))


def test_no_return_beyond_max_and_below_min_range():
    lid = LidarModel(beams=4, noise_sigma=0.0, range_min=0.2, range_max=5.0)
    r, valid = lid.measure(np.array([0.1, 1.0, 6.0, np.inf]), np.random.default_rng(0))
    assert valid.tolist() == [False, True, False, False]
    assert r[1] == 1.0 and np.all(np.isinf(r[[0, 2, 3]]))


# ---------------------------------------------------------------- static map

def test_static_map_marks_walls_without_gaps_and_free_inside():
    pillar = rect_corners(1.0, 1.0, 0.3, 0.8, 0.8)
    outline = np.array([(-5, -5), (5, -5), (5, 5), (-5, 5)], dtype=float)
    world = World(np.vstack((SQUARE_ROOM, polyline_segments(pillar, closed=True),
                             [[-3.0, -4.0, 2.3, 3.7]])),  # a slanted wall
                  interior=[outline], solids=[pillar])
    for res in (0.05, 0.1):
        g = world.static_map(res)
        pts = sample_segments(world.segments, res / 10)
        cells = g.world_to_cell(pts)
        assert np.all(g.prob[cells[:, 1], cells[:, 0]] == 1.0)
        occ = g.occupied()
        # occupied cells hug the segments (a cell's centre is within half a diagonal)
        xc, yc = g.cell_centers()
        centres = np.column_stack((xc[occ], yc[occ]))
        assert point_segment_distance(centres, world.segments).max() <= res * math.sqrt(0.5) + 1e-9
        c = g.world_to_cell(np.array([[-3.0, 2.0], [5.3, 0.0], [1.0, 1.0]]))
        assert g.prob[c[0, 1], c[0, 0]] == 0.0  # free floor
        assert np.isnan(g.prob[c[1, 1], c[1, 0]])  # outside the building
        assert np.isnan(g.prob[c[2, 1], c[2, 0]])  # inside the pillar
        # the wall x = 5 is exactly one cell thick along its length (no aliasing on grid lines)
        ys = np.arange(-4.0, 4.0, res)
        for dx, expect in ((0.0, 1.0), (res, None), (-res, 0.0)):
            cc = g.world_to_cell(np.column_stack((np.full(ys.shape, 5.0 + dx), ys)))
            vals = g.prob[cc[:, 1], cc[:, 0]]
            if expect is None:
                assert np.all(np.isnan(vals))
            else:
                assert np.all(vals == expect)
