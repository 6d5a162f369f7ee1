"""Breakpoint segmentation (paper Eq. 1): adaptive and fixed gaps, wrap-around, sizes, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import SegmentConfig, segment_scan
from dynslam2d.detect.segment import is_full_circle
from dynslam2d.types import Scan


def full_scan(ranges: np.ndarray, stamp: float = 0.0) -> Scan:
    n = ranges.shape[0]
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=ranges, range_min=0.1,
                range_max=20.0)


def fan_scan(ranges: np.ndarray, fov: float = 1.5 * math.pi) -> Scan:
    n = ranges.shape[0]
    return Scan(stamp=0.0, angle_min=-fov / 2, angle_increment=fov / (n - 1), ranges=ranges, range_min=0.1,
                range_max=20.0)


def test_two_objects_on_empty_background() -> None:
    r = np.full(720, np.inf)
    r[100:120] = 3.0
    r[200:230] = 5.0
    seg = segment_scan(full_scan(r))
    assert seg.n_clusters == 2
    assert [list(seg.cluster(c)) for c in range(2)] == [list(range(100, 120)), list(range(200, 230))]
    assert np.all(seg.labels[100:120] == 0) and np.all(seg.labels[200:230] == 1)
    assert np.all(seg.labels[:100] == -1)
    assert not seg.structure.any()


def test_range_step_breaks_cluster_adaptive_and_fixed() -> None:
    # a 0.4 m range step between two adjacent beams at 4 m
    r = np.full(720, np.inf)
    r[100:120] = 4.0
    r[120:140] = 4.4
    for cfg in (SegmentConfig(), SegmentConfig(mode="fixed", fixed_gap=0.2)):
        assert segment_scan(full_scan(r), cfg).n_clusters == 2
    # a 0.1 m step stays one cluster in both modes
    r[120:140] = 4.1
    for cfg in (SegmentConfig(), SegmentConfig(mode="fixed", fixed_gap=0.2)):
        assert segment_scan(full_scan(r), cfg).n_clusters == 1


def test_adaptive_threshold_grows_with_range_and_is_clamped() -> None:
    """Two points at the same range, separated by k beams of no return: linked iff the gap is
    below clip(r sinΔφ/sin(λ−Δφ) + 3σ, d_min, d_max) with the real Δφ."""
    cfg = SegmentConfig(max_skip_beams=10, d_max=5.0, d_min=0.0)
    n = 720
    inc = 2 * math.pi / n
    lam = math.radians(cfg.lambda_deg)
    for rng in (2.0, 8.0):
        for skip in (1, 4, 8):
            r = np.full(n, np.inf)
            r[100:110] = rng
            r[110 + skip:120 + skip] = rng
            dphi = (skip + 1) * inc
            gap = 2 * rng * math.sin(dphi / 2)
            thr = rng * math.sin(dphi) / math.sin(lam - dphi) + 3 * cfg.sigma_r
            expected = 1 if gap < thr else 2
            assert segment_scan(full_scan(r), cfg).n_clusters == expected, (rng, skip)
    # d_max clamps: with a 0.3 m cap the far pair (gap ≈ 0.63 m at 8 m, 8 skipped) splits
    r = np.full(n, np.inf)
    r[100:110] = 8.0
    r[119:129] = 8.0
    assert segment_scan(full_scan(r), SegmentConfig(max_skip_beams=10, d_max=0.3)).n_clusters == 2


def test_skip_limit_on_no_return_beams() -> None:
    r = np.full(720, np.inf)
    r[100:110] = 2.0
    r[112:122] = 2.0  # two dropped beams between
    assert segment_scan(full_scan(r), SegmentConfig(max_skip_beams=2)).n_clusters == 1
    assert segment_scan(full_scan(r), SegmentConfig(max_skip_beams=1)).n_clusters == 2


def test_wrap_around_joins_the_ends_of_a_360_scan_only() -> None:
    r = np.full(720, np.inf)
    r[:10] = 3.0
    r[-10:] = 3.0
    scan = full_scan(r)
    assert is_full_circle(scan)
    seg = segment_scan(scan)
    assert seg.wrapped and seg.n_clusters == 1
    assert list(seg.cluster(0)) == list(range(710, 720)) + list(range(10))
    assert segment_scan(scan, SegmentConfig(wrap_around="never")).n_clusters == 2
    fan = fan_scan(r)
    assert not is_full_circle(fan)
    assert segment_scan(fan).n_clusters == 2


def test_min_points_and_structure() -> None:
    r = np.full(720, np.inf)
    r[50:52] = 3.0  # 2 points: dropped with min_points 3
    r[100:600] = 5.0  # a long wall: too many points
    seg = segment_scan(full_scan(r), SegmentConfig(max_points=400))
    assert seg.n_clusters == 1 and seg.n_dropped == 1
    assert seg.structure.tolist() == [True]
    assert np.all(seg.labels[50:52] == -1)


@pytest.mark.parametrize("value", [np.inf, np.nan, 0.0, 30.0])
def test_scan_without_valid_returns(value: float) -> None:
    seg = segment_scan(full_scan(np.full(720, value)))
    assert seg.n_clusters == 0 and seg.beams.size == 0 and np.all(seg.labels == -1)


def test_single_closed_ring_is_one_cluster() -> None:
    seg = segment_scan(full_scan(np.full(360, 2.0)))
    assert seg.n_clusters == 1 and seg.sizes().tolist() == [360]
