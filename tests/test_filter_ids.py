"""The pipeline's one-kernel exclusion (filter.filter_scan_ids, filter.observed_boxes_kernel) gives bit for bit what
the per-track numpy path gave: filter_scan with centres p + v·dt and ids looked up, and each box grown to the
points of its own beams (pipeline._observed_rows)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.filter import FilterConfig, filter_scan, filter_scan_ids
from dynslam2d.pipeline import _box_rows, _observed_rows
from dynslam2d.sim import simulate
from dynslam2d.types import Box, Pose2D, Scan, Track


def _track(tid: int, box: Box, v: tuple[float, float], beams: np.ndarray | None) -> Track:
    return Track(id=tid, state="confirmed", stamp=0.0, box=box, velocity=np.array(v, dtype=np.float64),
                 covariance=np.eye(4), age=1.0, hits=3, misses=0, kind="rect", in_m=True, m_reason="test",
                 beams=beams, n_points=0 if beams is None else len(beams))


def _reference_grown(t: Track, scan: Scan, pose: Pose2D) -> Box:
    """The per-track numpy version the kernel replaced (paper §2.2: the box fitted to this scan's cluster)."""
    if t.beams is None or not len(t.beams):
        return t.box
    r = scan.ranges[t.beams]
    cos_a, sin_a = scan.trig()
    ok = np.isfinite(r)
    if not ok.any():
        return t.box
    with np.errstate(invalid="ignore"):
        xy = pose.transform_points(np.column_stack((r * cos_a[t.beams], r * sin_a[t.beams])))
    pts = xy[ok]
    b = t.box
    c, s_ = math.cos(b.theta), math.sin(b.theta)
    d = pts - np.array([b.px, b.py])
    u = d[:, 0] * c + d[:, 1] * s_
    v = -d[:, 0] * s_ + d[:, 1] * c
    u0, u1 = min(-0.5 * b.length, float(u.min())), max(0.5 * b.length, float(u.max()))
    v0, v1 = min(-0.5 * b.width, float(v.min())), max(0.5 * b.width, float(v.max()))
    du, dv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    return Box(b.px + c * du - s_ * dv, b.py + s_ * du + c * dv, b.theta, u1 - u0, v1 - v0)


def _scene() -> tuple[Scan, Pose2D, list[Track]]:
    scan = simulate("paper", duration=0.5).scans[3]
    ranges = scan.ranges.copy()
    ranges[205] = np.nan  # a beam without a return among a track's beams
    scan = scan.with_ranges(ranges)
    pose = Pose2D(0.4, -0.2, 0.3)
    valid = scan.valid_mask()
    pts = np.full((scan.n_beams, 2), np.nan)
    pts[valid] = pose.transform_points(scan.points(valid))
    tracks = []
    for k, (i, th, size) in enumerate(((40, 0.2, (0.3, 0.2)), (200, 1.0, (1.2, 0.4)), (500, -2.0, (0.6, 0.6)))):
        beams = np.arange(i - 6, i + 7)
        cx, cy = np.nanmean(pts[beams], axis=0)
        tracks.append(_track(10 + k, Box(float(cx) + 0.03, float(cy) - 0.02, th, *size), (0.5 * k, -0.3), beams))
    tracks.append(_track(20, Box(3.0, 3.0, 0.5, 0.5, 0.4), (0.0, 0.0), None))  # coasting: no beams
    tracks.append(_track(21, Box(-3.0, 1.0, 0.1, 0.5, 0.4), (0.2, 0.1), np.array([205])))  # only a NaN return
    return scan, pose, tracks


def test_observed_rows_equal_the_per_track_boxes_bit_for_bit() -> None:
    scan, pose, tracks = _scene()
    rows, ids = _observed_rows(tracks, scan, pose)
    np.testing.assert_array_equal(ids, [t.id for t in tracks])
    for t, row in zip(tracks, rows):
        ref = _reference_grown(t, scan, pose)
        assert row[:5].tolist() == [ref.px, ref.py, ref.theta, ref.length, ref.width]
        assert row[5:].tolist() == t.velocity.tolist()
    # the three tracks with finite returns grew (their boxes were placed off their points), the others did not
    grown = [r[3] * r[4] > t.box.length * t.box.width for t, r in zip(tracks, rows)]
    assert grown == [True, True, True, False, False]


@pytest.mark.parametrize("cfg", [FilterConfig(), FilterConfig(speed_margin_time=0.1),
                                 FilterConfig(default_shape="square", max_half_extent=0.5),
                                 FilterConfig(mode="adaptive"), FilterConfig(mode="fixed", expected_objects=5),
                                 FilterConfig(mode="none")], ids=lambda c: f"{c.mode}-{c.default_shape}")
def test_filter_scan_ids_equals_filter_scan(cfg: FilterConfig) -> None:
    scan, pose, tracks = _scene()
    dt = 0.07
    rows, ids = _box_rows(tracks)
    removed, by = filter_scan_ids(cfg, scan, pose, rows, ids, dt)
    centres = np.array([t.box.center + t.velocity * dt for t in tracks])
    ref, obj = filter_scan(cfg, scan, pose, centres, np.array([t.box.theta for t in tracks]),
                           np.array([t.box.length for t in tracks]), np.array([t.box.width for t in tracks]),
                           np.array([t.speed for t in tracks]))
    np.testing.assert_array_equal(removed, ref)
    np.testing.assert_array_equal(by, np.where(obj >= 0, ids[np.clip(obj, 0, None)], -1))
    if cfg.mode != "none":
        assert removed.sum() >= 20  # the boxes sit on scan points
        assert {10, 11, 12} <= set(by[removed].tolist())
    else:
        assert not removed.any()


def test_no_tracks_remove_nothing() -> None:
    scan, pose, _ = _scene()
    rows, ids = _observed_rows([], scan, pose)
    assert rows.shape == (0, 7)
    removed, by = filter_scan_ids(FilterConfig(), scan, pose, rows, ids)
    assert not removed.any() and (by == -1).all() and removed.shape == scan.ranges.shape


@pytest.mark.parametrize("square", [False, True])
@pytest.mark.parametrize("cap", [None, 0.45])
def test_box_extents_kernel_equals_half_extents(square: bool, cap: float | None) -> None:
    from dynslam2d.filter import _box_extents_kernel, half_extents

    rng = np.random.default_rng(3)
    rows = rng.normal(0.0, 0.6, (40, 7))
    rows[3, 3] = np.nan
    rows[7, 4] = np.nan
    rows[9, 3:5] = np.nan
    cfg = FilterConfig(default_shape="square" if square else "rectangle", max_half_extent=cap, margin=0.15)
    got = _box_extents_kernel(rows, square, 0.15, math.inf if cap is None else cap)
    ref = half_extents(cfg, rows[:, 3], rows[:, 4])
    np.testing.assert_array_equal(got, ref)  # NaN where numpy gives NaN, the same floats elsewhere
    assert np.isnan(got[9]).all() and (cap is None or np.nanmax(got) == cap)
