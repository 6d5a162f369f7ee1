"""The movers' exclusion visits only each box's beam window (filter._windowed_exclusion, pass mov128): bit for bit
the per-beam pass over every box (`_every_beam` below, filter._region_of per beam), on the simulator's scans, with
overlapping boxes (nearest centre wins), a box around the sensor, NaN / infinite extents, and beam angles shifted
by 2π or reversed. filter_scan_ids' non-default modes use the windowed pass too."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.filter import _region_of, _windowed_exclusion
from dynslam2d.jitbox import njit
from dynslam2d.sim import simulate


@njit(cache=True)
def _every_beam(ranges, cos_a, sin_a, valid, pc, ps, px, py, c, th, ha, hb, ids, removed,
                removed_by):  # pragma: no cover
    """The reference: every valid beam's point (Scan.points, Pose2D.transform_points' operations) tested against
    every box by filter._region_of (the library's per-beam pass before pass mov128)."""
    ct = np.cos(th)
    st = np.sin(th)
    for i in range(ranges.shape[0]):
        if not valid[i]:
            continue
        r = ranges[i]
        lx = r * cos_a[i]
        ly = r * sin_a[i]
        j = _region_of(pc * lx - ps * ly + px, ps * lx + pc * ly + py, c, ct, st, ha, hb)
        if j >= 0:
            removed_by[i] = ids[j]
            removed[i] = True


def _both(ranges: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray, valid: np.ndarray, pose: tuple[float, float, float],
          c: np.ndarray, th: np.ndarray, ext: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = ranges.shape[0]
    pc, ps, px, py = math.cos(pose[2]), math.sin(pose[2]), pose[0], pose[1]
    ref, ref_by = np.zeros(n, dtype=bool), np.full(n, -1, dtype=np.int64)
    _every_beam(ranges, cos_a, sin_a, valid, pc, ps, px, py, c, th, ext[:, 0].copy(), ext[:, 1].copy(), ids, ref,
                ref_by)
    got, got_by = np.zeros(n, dtype=bool), np.full(n, -1, dtype=np.int64)
    count = _windowed_exclusion(ranges, cos_a, sin_a, valid, pc, ps, px, py, c, th, ext, ids, got, got_by)
    np.testing.assert_array_equal(got, ref)
    assert count == int(np.count_nonzero(ref))
    np.testing.assert_array_equal(got_by, ref_by)
    return ref, ref_by


@pytest.mark.parametrize("variant", ["as simulated", "angles + 2π", "reversed"])
def test_windowed_exclusion_equals_every_beam(variant: str) -> None:
    sim = simulate("crowd", duration=1.0)
    rng = np.random.default_rng(7)
    hits = 0
    owners: set[int] = set()
    for scan in sim.scans[::5]:
        angles = scan.angles
        ranges = scan.ranges.copy()
        if variant == "angles + 2π":
            angles = angles + 2.0 * math.pi
        elif variant == "reversed":
            angles, ranges = angles[::-1].copy(), ranges[::-1].copy()
        cos_a, sin_a = np.cos(angles), np.sin(angles)
        valid = np.isfinite(ranges)
        pose = (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), float(rng.uniform(-4, 4)))
        pc, ps = math.cos(pose[2]), math.sin(pose[2])
        idx = rng.choice(np.flatnonzero(valid), 9)
        lx, ly = ranges[idx] * cos_a[idx], ranges[idx] * sin_a[idx]
        c = np.column_stack((pc * lx - ps * ly + pose[0], ps * lx + pc * ly + pose[1]))
        c[1] = c[0] + 0.05  # overlapping boxes: the nearer centre wins
        c[2] = pose[:2]  # a box around the sensor: every beam is a candidate
        th = rng.uniform(-4, 4, 9)
        ext = np.abs(rng.normal(0.4, 0.3, (9, 2)))
        ext[3, 0] = np.nan  # holds no point
        ext[4, 1] = np.inf  # a strip through the scene
        ext[2] = (2.5, 2.5)  # (large enough to hold returns)
        ids = np.arange(100, 109, dtype=np.int64)
        removed, by = _both(ranges, cos_a, sin_a, valid, pose, c, th, ext, ids)
        hits += int(removed.sum())
        owners |= set(by[removed].tolist())
    assert hits > 100
    assert {100, 101, 102, 104} <= owners and 103 not in owners


def test_windowed_exclusion_without_a_window() -> None:
    """Beams that are not a0 + i·inc, or a negative range: every beam against every box, the same results."""
    rng = np.random.default_rng(3)
    angles = np.sort(rng.uniform(-3, 3, 300))
    ranges = rng.uniform(0.5, 6, 300)
    ranges[::7] *= -1.0
    valid = np.ones(300, dtype=bool)
    c = rng.uniform(-4, 4, (6, 2))
    removed, _ = _both(ranges, np.cos(angles), np.sin(angles), valid, (0.1, 0.2, 0.3), c, rng.uniform(-3, 3, 6),
                       np.full((6, 2), 1.5), np.arange(6, dtype=np.int64))
    assert removed.any()


def test_windowed_exclusion_ties_and_overflowing_distances() -> None:
    """A beam held by several boxes goes to the nearer centre, the lower index on a tie, whichever box comes first
    (the held box's distance is computed again, pass mov133); a point whose squared distance overflows to inf is in
    no box (inf < inf is False), as in the every-beam reference."""
    n = 360
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    ranges = np.full(n, 3.0)
    ranges[10:20] = 1e200  # (a strip box holds them; their squared distance overflows)
    valid = np.ones(n, dtype=bool)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    pose = (0.2, -0.1, 0.4)
    pc, ps = math.cos(pose[2]), math.sin(pose[2])
    p = np.column_stack((pc * 3.0 * cos_a - ps * 3.0 * sin_a + pose[0], ps * 3.0 * cos_a + pc * 3.0 * sin_a + pose[1]))
    c = np.array([p[100] + 0.3, p[100], p[100], p[100] - 0.2, p[200] + 0.1, p[200], [0.0, 0.0]])
    th = np.zeros(7)
    ext = np.array([[1.0, 1.0], [0.6, 0.6], [0.6, 0.6], [0.9, 0.9], [0.8, 0.8], [0.4, 0.4], [np.inf, np.inf]])
    ids = np.array([7, 3, 9, 1, 5, 2, 8], dtype=np.int64)
    removed, by = _both(ranges, cos_a, sin_a, valid, pose, c, th, ext, ids)
    assert by[100] == 3  # (boxes 1 and 2 tie at distance 0: the lower index, not box 0 nor 3)
    assert by[200] == 2  # (box 5 comes after box 4 and is nearer)
    assert not removed[10:20].any() and removed[30]  # (inf distance: no box; finite: the strip box 6)
    assert set(by[removed].tolist()) >= {1, 3, 7, 2, 5, 8}


@pytest.mark.parametrize("negative_valid", [False, True])
def test_windowed_exclusion_negative_ranges_valid_or_not(negative_valid: bool) -> None:
    """Uniform beams with negative ranges (the real bags' scans hold them outside their valid interval): only a
    valid negative range turns the window off (pass flt137); an invalid one is tested in no box either way. A box
    behind the sensor holds the negative beams' points: when they are valid, the reference removes them and so must
    the windowed pass (a window that ignored them would not); when not, neither removes them."""
    n = 360
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    ranges = np.full(n, 3.0)
    ranges[40:50] = -2.0  # (points at angle + π: behind their beams)
    valid = np.ones(n, dtype=bool)
    if not negative_valid:
        valid[40:50] = False
    pose = (0.3, -0.2, 0.7)
    pc, ps = math.cos(pose[2]), math.sin(pose[2])
    q = 45
    lx, ly = -2.0 * cos_a[q], -2.0 * sin_a[q]
    behind = (pc * lx - ps * ly + pose[0], ps * lx + pc * ly + pose[1])
    lx, ly = 3.0 * cos_a[q + 180], 3.0 * sin_a[q + 180]
    ahead = (pc * lx - ps * ly + pose[0], ps * lx + pc * ly + pose[1])
    c = np.array([behind, ahead, [9.0, 9.0]])
    ext = np.array([[0.3, 0.3], [0.3, 0.3], [0.5, 0.5]])
    removed, by = _both(ranges, cos_a, sin_a, valid, pose, c, np.zeros(3), ext, np.array([4, 5, 6], dtype=np.int64))
    assert removed[40:50].any() == negative_valid
    assert (by == 5).any() and not (by == 6).any()
