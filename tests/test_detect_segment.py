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


def _links_reference(scan: Scan, cfg: SegmentConfig, wrap: bool) -> list[bool]:
    """Paper Eq. 1 per pair of consecutive valid beams, straight from the formula (law of cosines gap against the
    clamped Borges–Aldon threshold, trigonometry computed for every pair)."""
    idx = np.flatnonzero(scan.valid_mask() & (scan.ranges > 0.0))
    n, m, lam = scan.n_beams, idx.shape[0], math.radians(cfg.lambda_deg)
    out = []
    for j in range(m if wrap else m - 1):
        a, b = int(idx[j]), int(idx[(j + 1) % m])
        if (b - a - 1 if b > a else b + n - a - 1) > cfg.max_skip_beams:
            out.append(False)
            continue
        ra, rb = scan.ranges[a], scan.ranges[b]
        dphi = abs(scan.angles[b] - scan.angles[a])
        dphi = 2.0 * math.pi - dphi if dphi > math.pi else dphi
        gap2 = max(ra * ra + rb * rb - 2.0 * ra * rb * math.cos(dphi), 0.0)
        thr = cfg.d_max if dphi >= lam else min(max(ra * math.sin(dphi) / math.sin(lam - dphi)
                                                    + 3.0 * cfg.sigma_r, cfg.d_min), cfg.d_max)
        out.append(bool(gap2 < thr * thr))
    return out


@pytest.mark.parametrize("full", [True, False])
def test_cached_trigonometry_gives_the_links_of_the_formula(full: bool) -> None:
    """The segmentation reads the adjacent beams' trigonometry from a per-geometry cache and computes it only for
    pairs across dropped beams: every cluster boundary is where the formula puts a break, on the first scan of a
    geometry (cache filled) and on the next ones (cache read), and with the tracker's pre-checked mask."""
    rng = np.random.default_rng(7)
    cfg = SegmentConfig()
    for trial in range(4):
        r = np.repeat(rng.uniform(0.5, 12.0, 72), 10) + rng.normal(0.0, 0.02, 720)
        r[rng.random(720) < 0.06] = np.inf  # dropped beams: links across 1-3 of them use their own angles
        scan = full_scan(r, stamp=float(trial)) if full else fan_scan(r)
        wrap = full and is_full_circle(scan)
        links = _links_reference(scan, cfg, wrap)
        valid = scan.valid_mask() & (scan.ranges > 0.0)
        for seg in (segment_scan(scan, cfg), segment_scan(scan, cfg, valid, checked=True)):
            idx = np.flatnonzero(valid)
            pos = {int(b): j for j, b in enumerate(idx)}
            for c in range(seg.n_clusters):
                members = seg.cluster(c)
                for a, b in zip(members[:-1], members[1:]):
                    assert links[pos[int(a)]], (trial, a, b)  # linked inside a cluster
                assert not links[pos[int(members[-1])] % len(links)] or (not wrap and pos[int(members[-1])] ==
                                                                          len(idx) - 1)
            assert 5 < seg.n_clusters < 200 and seg.wrapped == wrap
