"""Tests of the dynamic-point filter (paper Eq. 4–8, configurations 1–3 and ours)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from dynslam2d.filter import (
    FilterConfig,
    exclusion_mask,
    filter_active,
    filter_scan,
    filter_scan_points,
    half_extents,
    half_sides,
)
from dynslam2d.types import Pose2D, Scan


def _local_to_world(centre, heading, local):
    """Points given in an object's frame → world, via the object pose (independent oracle)."""
    return Pose2D(centre[0], centre[1], heading).transform_points(np.asarray(local, dtype=float))


# --- exclusion_mask: geometry -------------------------------------------------------------


def test_axis_aligned_square_boundary_inclusive():
    # Square of half-side 0.5 at (2, 1), heading 0.
    pts = np.array(
        [
            [2.0, 1.0],  # centre
            [2.5, 1.0],  # on the boundary (Eq. 7 uses ≤)
            [2.499, 1.499],  # just inside the corner
            [2.501, 1.0],  # just outside in x
            [2.0, 0.499],  # just outside in y (below)
            [2.0, 0.501],  # just inside in y
            [1.4, 1.0],  # outside left
        ]
    )
    removed, idx = exclusion_mask(pts, [[2.0, 1.0]], [0.0], [0.5])
    assert removed.tolist() == [True, True, True, False, False, True, False]
    assert idx.tolist() == [0, 0, 0, -1, -1, 0, -1]


@pytest.mark.parametrize("heading_deg", [30.0, 90.0, -60.0, 180.0])
def test_rotated_rectangle_removes_what_lies_inside(heading_deg):
    # A 2 m × 0.4 m rectangle (half-extents 1.0, 0.2) rotated by heading: points placed in
    # its own frame just inside / just outside each side must be removed / kept.
    th = math.radians(heading_deg)
    centre = (3.0, -1.0)
    local_in = [(0.99, 0.0), (-0.99, 0.0), (0.0, 0.19), (0.0, -0.19), (0.95, 0.15)]
    local_out = [(1.01, 0.0), (-1.01, 0.0), (0.0, 0.21), (0.0, -0.21), (0.3, 0.5)]
    pts = _local_to_world(centre, th, local_in + local_out)
    removed, idx = exclusion_mask(pts, [centre], [th], np.array([[1.0, 0.2]]))
    assert removed.tolist() == [True] * 5 + [False] * 5
    assert idx.tolist() == [0] * 5 + [-1] * 5


def test_eq5_interpretation_rotated_square_30deg():
    # Square of half-side 0.5 rotated by +30°. The corner region (0.45, 0.45) in the object's
    # frame lies inside; read literally (rotation block transposed, i.e. the square rotated by
    # −30°), the same world point would map to local ≈ (−0.16, 0.61) and be kept. So this
    # test fails for the transposed interpretation.
    th = math.radians(30.0)
    centre = (1.0, 2.0)
    p_in = _local_to_world(centre, th, [(0.45, 0.45)])
    p_out = _local_to_world(centre, th, [(0.0, 0.55), (0.55, 0.0)])
    removed, _ = exclusion_mask(np.vstack([p_in, p_out]), [centre], [th], [0.5])
    assert removed.tolist() == [True, False, False]
    # The literal transposed matrix would map p_in to R(θ)(s − p): outside the square.
    c, s = math.cos(th), math.sin(th)
    d = p_in[0] - np.array(centre)
    lit = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])
    assert np.max(np.abs(lit)) > 0.5


def test_square_rotated_90_equals_unrotated():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-2.0, 2.0, size=(500, 2))
    r0, _ = exclusion_mask(pts, [[0.2, -0.1]], [0.0], [0.7])
    r90, _ = exclusion_mask(pts, [[0.2, -0.1]], [math.pi / 2], [0.7])
    assert np.array_equal(r0, r90)
    assert 50 < r0.sum() < 450  # the test is not trivially all/none


def test_matches_bruteforce_on_random_points_and_objects():
    rng = np.random.default_rng(7)
    pts = rng.uniform(-6, 6, size=(800, 2))
    k = 5
    centres = rng.uniform(-4, 4, size=(k, 2))
    heads = rng.uniform(-math.pi, math.pi, size=k)
    ext = rng.uniform(0.2, 1.2, size=(k, 2))
    removed, idx = exclusion_mask(pts, centres, heads, ext)
    inside = np.zeros((800, k), dtype=bool)
    for j in range(k):
        loc = Pose2D(centres[j, 0], centres[j, 1], heads[j]).inverse().transform_points(pts)
        inside[:, j] = (np.abs(loc[:, 0]) <= ext[j, 0]) & (np.abs(loc[:, 1]) <= ext[j, 1])
    assert np.array_equal(removed, inside.any(axis=1))
    assert removed.sum() > 50
    for i in np.flatnonzero(removed):
        cand = np.flatnonzero(inside[i])
        d = np.hypot(*(pts[i] - centres[cand]).T)
        assert idx[i] == cand[np.argmin(d)]
    assert np.all(idx[~removed] == -1)


def test_several_objects_attribution():
    centres = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]])
    heads = np.array([0.0, math.radians(45), math.radians(-30)])
    sides = np.array([0.5, 0.8, 0.3])
    pts = np.array([[0.1, 0.1], [5.5, 0.0], [0.0, 5.2], [2.5, 2.5], [5.0, 0.75]])
    removed, idx = exclusion_mask(pts, centres, heads, sides)
    # (5, 0.75) is 0.75 from the centre along 90°: in the 45°-rotated frame that is
    # (0.53, 0.53), inside the half-side 0.8.
    assert idx.tolist() == [0, 1, 2, -1, 1]
    assert removed.tolist() == [True, True, True, False, True]


def test_overlapping_regions_attributed_to_nearest_centre():
    centres = np.array([[0.0, 0.0], [1.0, 0.0]])
    pts = np.array([[0.3, 0.0], [0.7, 0.0], [0.5, 0.0]])
    removed, idx = exclusion_mask(pts, centres, [0.0, 0.0], [1.0, 1.0])
    assert removed.all()
    assert idx.tolist() == [0, 1, 0]  # the tie at 0.5 goes to the lower index


def test_empty_inputs_and_no_objects():
    r, i = exclusion_mask(np.zeros((0, 2)), [[0.0, 0.0]], [0.0], [1.0])
    assert r.shape == (0,) and i.shape == (0,)
    pts = np.array([[0.0, 0.0], [1.0, 1.0]])
    r, i = exclusion_mask(pts, np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    assert r.tolist() == [False, False] and i.tolist() == [-1, -1]
    assert r.dtype == bool and i.dtype == np.int64


def test_nonfinite_points_are_kept():
    pts = np.array([[np.nan, np.nan], [0.0, 0.0], [np.inf, 0.0]])
    r, i = exclusion_mask(pts, [[0.0, 0.0]], [0.0], [100.0])
    assert r.tolist() == [False, True, False]
    assert i.tolist() == [-1, 0, -1]


def test_shape_errors():
    with pytest.raises(ValueError):
        exclusion_mask(np.zeros((3, 2)), [[0.0, 0.0]], [0.0, 1.0], [1.0])
    with pytest.raises(ValueError):
        exclusion_mask(np.zeros((3, 2)), [[0.0, 0.0]], [0.0], [1.0, 2.0])
    with pytest.raises(ValueError):
        exclusion_mask(np.zeros((3, 2)), [[0.0, 0.0]], [0.0], np.ones((1, 3)))


# --- configurations -----------------------------------------------------------------------


def test_config_defaults_and_validation():
    cfg = FilterConfig()
    assert cfg.mode == "box"
    assert cfg.fixed_d_ref * cfg.fixed_lambda / 2 == pytest.approx(1.5)
    assert cfg.expected_objects == 3 and cfg.adaptive_lambda == 1.0
    with pytest.raises(ValidationError):
        FilterConfig(mode="bogus")
    with pytest.raises(ValidationError):
        FilterConfig(margin=-0.1)
    with pytest.raises(ValidationError):
        FilterConfig(unknown_field=1)


def test_fixed_half_side_is_1_5_m_regardless_of_size():
    cfg = FilterConfig(mode="fixed")
    d = half_sides(cfg, [1.0, 2.0, 0.1], [1.0, 0.1, 0.1])
    assert d.tolist() == [1.5, 1.5, 1.5]


def test_adaptive_size_rule():
    cfg = FilterConfig(mode="adaptive")
    d = half_sides(cfg, [1.0, 2.0, 0.3], [1.0, 0.1, 0.8])
    assert d.tolist() == pytest.approx([0.5, 1.0, 0.4])  # max(w, l)·1.0/2 (Eq. 6)
    d2 = half_sides(FilterConfig(mode="adaptive", adaptive_lambda=1.5), [2.0], [0.1])
    assert d2.tolist() == pytest.approx([1.5])


def test_default_rectangle_and_square_with_margins():
    cfg = FilterConfig(mode="default", margin=0.2)
    ext = half_extents(cfg, [2.0, 1.0], [0.1, 1.0])
    np.testing.assert_allclose(ext, [[1.2, 0.25], [0.7, 0.7]])
    sq = FilterConfig(mode="default", default_shape="square", margin=0.15)
    assert half_sides(sq, [2.0], [0.1]).tolist() == pytest.approx([1.15])
    fast = FilterConfig(mode="default", margin=0.2, speed_margin_time=0.1)
    ext = half_extents(fast, [1.0, 1.0], [1.0, 1.0], speeds=[2.0, 0.0])
    np.testing.assert_allclose(ext, [[0.9, 0.9], [0.7, 0.7]])
    capped = FilterConfig(mode="default", margin=0.2, max_half_extent=1.0)
    np.testing.assert_allclose(half_extents(capped, [6.0], [0.5]), [[1.0, 0.45]])
    with pytest.raises(ValueError):
        half_sides(cfg, [1.0], [1.0])  # rectangle: no single half-side
    with pytest.raises(ValueError):
        half_sides(FilterConfig(mode="none"), [1.0], [1.0])


def _three_objects():
    centres = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]])
    heads = np.zeros(3)
    lengths = np.array([1.0, 1.0, 2.0])
    widths = np.array([1.0, 1.0, 0.1])
    return centres, heads, lengths, widths


def test_fixed_mode_count_rule():
    centres, heads, lengths, widths = _three_objects()
    pts = np.array([[1.2, 0.0], [4.0, 1.4], [0.0, 5.4], [2.0, 2.0]])
    cfg = FilterConfig(mode="fixed")
    assert filter_active(cfg, 3) and not filter_active(cfg, 2) and not filter_active(cfg, 4)
    removed, idx = filter_scan_points(cfg, pts, centres, heads, lengths, widths)
    assert removed.tolist() == [True, True, True, False]  # half-side 1.5 m around each
    assert idx.tolist() == [0, 1, 2, -1]
    # Two objects (one fewer than expected): nothing removed.
    removed, idx = filter_scan_points(cfg, pts, centres[:2], heads[:2], lengths[:2], widths[:2])
    assert not removed.any() and (idx == -1).all()
    # Four objects: nothing removed either.
    c4 = np.vstack([centres, [[10.0, 10.0]]])
    removed, _ = filter_scan_points(cfg, pts, c4, np.zeros(4), np.ones(4), np.ones(4))
    assert not removed.any()
    # With expected_objects = 2 the two-object case acts.
    removed, _ = filter_scan_points(
        FilterConfig(mode="fixed", expected_objects=2), pts, centres[:2], heads[:2], lengths[:2], widths[:2]
    )
    assert removed.tolist() == [True, True, False, False]


def test_adaptive_mode_removes_by_object_size():
    centres, heads, lengths, widths = _three_objects()
    # Object 0: half-side 0.5; object 2 (2 m × 0.1 m): half-side 1.0 (a square, Eq. 7).
    pts = np.array([[0.45, 0.0], [0.55, 0.0], [0.9, 4.9], [0.0, 5.1], [4.0, 0.6]])
    removed, idx = filter_scan_points(FilterConfig(mode="adaptive"), pts, centres, heads, lengths, widths)
    assert removed.tolist() == [True, False, True, False, False]
    assert idx.tolist() == [0, -1, 2, -1, -1]
    # Adaptive acts with any number of objects (no count rule).
    removed, _ = filter_scan_points(
        FilterConfig(mode="adaptive"), pts[:1], centres[:1], heads[:1], lengths[:1], widths[:1]
    )
    assert removed.tolist() == [True]


def test_none_mode_removes_nothing():
    centres, heads, lengths, widths = _three_objects()
    pts = centres.copy()
    removed, idx = filter_scan_points(FilterConfig(mode="none"), pts, centres, heads, lengths, widths)
    assert not removed.any() and (idx == -1).all()


def test_default_rectangle_follows_heading():
    # The 2 m × 0.1 m object rotated by 90°: its long side is along y.
    cfg = FilterConfig(mode="default", margin=0.2)
    centres = np.array([[0.0, 0.0]])
    pts = np.array([[0.0, 1.15], [0.0, 1.25], [0.2, 0.0], [0.3, 0.0]])
    removed, _ = filter_scan_points(cfg, pts, centres, [math.pi / 2], [2.0], [0.1])
    assert removed.tolist() == [True, False, True, False]
    # With heading 0 the same points are judged against the unrotated box.
    removed, _ = filter_scan_points(cfg, pts, centres, [0.0], [2.0], [0.1])
    assert removed.tolist() == [False, False, True, True]


def test_filter_scan_points_empty():
    cfg = FilterConfig(mode="adaptive")
    r, i = filter_scan_points(cfg, np.zeros((0, 2)), [[0.0, 0.0]], [0.0], [1.0], [1.0])
    assert r.shape == (0,) and i.shape == (0,)
    r, i = filter_scan_points(cfg, np.ones((4, 2)), np.zeros((0, 2)), [], [], [])
    assert r.tolist() == [False] * 4 and i.tolist() == [-1] * 4


def test_filter_scan_per_beam_in_map_frame():
    # 8 beams, 45° apart; the laser sits at (1, 0) in the map frame facing +y (θ = 90°).
    ranges = np.array([2.0, np.nan, 3.0, 0.05, 2.0, 2.0, 2.0, 2.0])
    scan = Scan(
        stamp=0.0, angle_min=0.0, angle_increment=math.pi / 4, ranges=ranges, range_min=0.1, range_max=10.0
    )
    pose = Pose2D(1.0, 0.0, math.pi / 2)
    # Beam 0 (along the laser's x = map +y) hits map (1, 2); beam 2 (laser +y = map −x) hits (−2, 0).
    centres = np.array([[1.0, 2.0], [-2.0, 0.0]])
    cfg = FilterConfig(mode="adaptive")
    removed, idx = filter_scan(cfg, scan, pose, centres, [0.0, 0.0], [0.4, 0.4], [0.4, 0.4])
    assert removed.tolist() == [True, False, True, False, False, False, False, False]
    assert idx.tolist() == [0, -1, 1, -1, -1, -1, -1, -1]
    # Beam 3 (0.05 m < range_min, no return) is never removed, even inside a region.
    r3, _ = filter_scan(cfg, scan, pose, [[1.0, 0.0]], [0.0], [1.0], [1.0])
    assert not r3[3] and not r3[1]
    # 'none' removes nothing.
    none = FilterConfig(mode="none")
    r, i = filter_scan(none, scan, pose, centres, [0.0, 0.0], [0.4, 0.4], [0.4, 0.4])
    assert not r.any() and (i == -1).all()
