"""The batched numba kernels of the tracker agree with the per-object reference code.

``dynslam2d.detect.kernels`` replaces per-detection Python (classify_and_bound, measure, the
Kalman update, the free-space test, the fragment test) by one kernel call per scan; these tests
run both on real clusters of simulated scans and on edge cases, and require the same numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import DetectConfig, Tracker, fit_clusters, search_angles, segment_scan
from dynslam2d.detect.freespace import FreeSpaceMemory, FreeTest
from dynslam2d.detect.kernels import (
    _pairwise_sum,
    classify_batch,
    fit_params,
    fragment_hosts,
    gate_costs,
    kalman_update_batch,
    leg_pairs,
    mask_fractions,
    measure_batch,
    merge_leg_pairs,
    merge_legs,
    segment_means,
    world_points,
)
from dynslam2d.detect.layout import (
    F_HI1,
    F_HI2,
    F_LO1,
    F_LO2,
    F_THETA,
    FIT_CENTROID,
    FIT_CIRCLE,
    K_CIRCLE,
    K_POINT,
    K_RECT,
    KIND_CODES,
    KIND_NAMES,
    DetectionBatch,
)
from dynslam2d.detect.reference import classify_and_bound, measure
from dynslam2d.detect.segment import segment_points
from dynslam2d.detect.shapes import CRITERIA, _lu_solve3
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D, Scan


def test_kind_table_maps_codes_and_names_both_ways() -> None:
    assert KIND_NAMES[K_POINT] == "point" and KIND_NAMES[K_CIRCLE] == "circle" and KIND_NAMES[K_RECT] == "rect"
    assert all(KIND_NAMES[KIND_CODES[name]] == name for name in KIND_NAMES)
    assert sorted(KIND_CODES.values()) == list(range(len(KIND_NAMES)))


@pytest.fixture(scope="module")
def scenes() -> list[tuple]:
    """(scan, pose) pairs of two simulated scenes with movers, boxes and walls (720 beams)."""
    out = []
    for name in ("crowd", "paper"):
        sim = simulate(name, duration=1.5)
        poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
        out += list(zip(sim.scans[::3], poses[::3]))
    return out


def _clusters(scan, pose, cfg):
    seg = segment_scan(scan, cfg.segment)
    valid = scan.valid_mask() & (scan.ranges > 0.0)
    r = np.where(valid, scan.ranges, 0.0)
    allpts = pose.transform_points(np.column_stack((r * np.cos(scan.angles), r * np.sin(scan.angles))))
    pts = allpts[seg.beams]
    px, py = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
    fits = fit_clusters(px, py, seg.offsets, ~seg.structure, search_angles(cfg.fit.angle_step_deg),
                        CRITERIA[cfg.fit.criterion], cfg.fit.closeness_d0, cfg.fit.circle_min_points,
                        cfg.fit.coarse_stride)
    return seg, valid, allpts, pts, px, py, fits


def test_classify_and_measure_batches_match_the_reference(scenes) -> None:
    cfg = DetectConfig()
    p = fit_params(cfg.fit)
    n_kind = {K_POINT: 0, K_CIRCLE: 0, K_RECT: 0}
    n_rel = 0
    for scan, pose in scenes:
        seg, valid, allpts, pts, px, py, fits = _clusters(scan, pose, cfg)
        dphi = abs(scan.angle_increment)
        keep, kind, lohi, rel = classify_batch(px, py, seg.beams, seg.offsets, fits, seg.structure, pose.x, pose.y,
                                               scan.ranges, valid, np.ascontiguousarray(allpts[:, 0]),
                                               np.ascontiguousarray(allpts[:, 1]), seg.wrapped,
                                               cfg.segment.max_skip_beams, scan.range_max, dphi,
                                               cfg.segment.max_extent, p)
        dets, idx = [], []
        for c in range(seg.n_clusters):
            row = fits[c]
            expect_keep = not seg.structure[c] and max(row[F_HI1] - row[F_LO1],
                                                       row[F_HI2] - row[F_LO2]) <= cfg.segment.max_extent
            assert keep[c] == expect_keep
            if not expect_keep:
                continue
            a0, a1 = seg.offsets[c], seg.offsets[c + 1]
            det = classify_and_bound(seg.beams[a0:a1], pts[a0:a1], row, np.array([pose.x, pose.y]), scan.ranges,
                                     valid, allpts, seg.wrapped, cfg.segment.max_skip_beams, scan.range_max,
                                     cfg.fit, dphi)
            assert kind[c] == KIND_CODES[det.kind]
            np.testing.assert_allclose(lohi[c], [det.lo[0], det.lo[1], det.hi[0], det.hi[1]], rtol=0, atol=1e-12)
            np.testing.assert_array_equal(rel[c], det.rel)
            n_kind[int(kind[c])] += 1
            n_rel += int(rel[c].sum())
            dets.append(det)
            idx.append(c)
        if not dets:
            continue
        idx = np.array(idx)
        m = len(dets)
        starts, npts = seg.offsets[idx], np.diff(seg.offsets)[idx]
        batch = DetectionBatch(kind[idx], fits[idx, F_THETA].copy(), lohi[idx], rel[idx],
                               fits[idx, FIT_CENTROID].copy(), fits[idx, FIT_CIRCLE].copy(), px, py, starts, npts)
        # every detection three ways: defaults, with a track's sizes, with a track's radius
        rows = np.tile(np.arange(m), 3)
        sizes = np.vstack((np.zeros((m, 2)), np.tile([[0.9, 0.45]], (m, 1)), np.zeros((m, 2))))
        has = np.repeat([False, True, False], m)
        radius = np.repeat([-1.0, -1.0, 0.3], m)
        sigma = np.repeat([0.0, 0.05, 0.05], m)
        z, R, H, zm, Rm, size_obs, size_kind = measure_batch(rows, *batch, sizes, has, radius, sigma, p)
        for r, j in enumerate(rows):
            ref = measure(dets[j], sizes[r] if has[r] else None, radius[r] if radius[r] > 0 else None, cfg.fit,
                          size_sigma=sigma[r])
            for got, want in ((z[r], ref.z), (R[r], ref.R), (H[r], ref.H), (zm[r], ref.zm), (Rm[r], ref.Rm),
                              (size_obs[r], ref.size_obs)):
                np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
            np.testing.assert_array_equal(size_kind[r], ref.size_kind)
    # the scenes exercise every kind and real bounds
    assert min(n_kind.values()) >= 5, n_kind
    assert n_rel >= 20


def test_kalman_batch_matches_numpy_and_rejects_singular() -> None:
    rng = np.random.default_rng(3)
    n = 20
    X = rng.normal(size=(n, 4))
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(4)
    H = rng.normal(size=(n, 2, 4))
    zm = rng.normal(size=(n, 2))
    B = rng.normal(size=(n, 2, 2))
    Rm = B @ B.transpose(0, 2, 1) + 0.01 * np.eye(2)
    H[-1] = 0.0  # S = R = 0: singular, the row must be left alone
    Rm[-1] = 0.0
    Xn, Pn, ok = kalman_update_batch(X, P, H, zm, Rm)
    assert ok[:-1].all() and not ok[-1]
    np.testing.assert_array_equal(Xn[-1], X[-1])
    np.testing.assert_array_equal(Pn[-1], P[-1])
    for i in range(n - 1):
        S = H[i] @ P[i] @ H[i].T + Rm[i]
        K = P[i] @ H[i].T @ np.linalg.inv(S)
        x = X[i] + K @ (zm[i] - H[i] @ X[i])
        Pi = P[i] - K @ H[i] @ P[i]
        np.testing.assert_allclose(Xn[i], x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(Pn[i], 0.5 * (Pi + Pi.T), rtol=1e-10, atol=1e-10)


def _seen_through_numpy(ref, points: np.ndarray, margin: float) -> np.ndarray:
    """The vectorised numpy version of the free-space test (docs/tracking.md)."""
    local = ref.pose.inverse().transform_points(points)
    rho = np.hypot(local[:, 0], local[:, 1])
    phi = np.arctan2(local[:, 1], local[:, 0])
    m = ref.ranges.shape[0]
    idx = np.rint((phi - ref.angle_min) / ref.increment).astype(np.int64)
    if ref.full:
        idx %= m
        inside = np.ones(points.shape[0], dtype=bool)
    else:
        alt = np.rint((phi + 2.0 * math.pi - ref.angle_min) / ref.increment).astype(np.int64)
        idx = np.where((idx < 0) | (idx >= m), alt, idx)
        inside = (idx >= 1) & (idx < m - 1)
        idx = np.clip(idx, 0, m - 1)
    rmin = np.minimum(np.minimum(ref.ranges[idx], ref.ranges[(idx - 1) % m]), ref.ranges[(idx + 1) % m])
    beyond = np.where(np.isinf(rmin), rho < ref.reach - margin, rmin > rho + margin)
    return inside & beyond


@pytest.mark.parametrize("fov", [None, 4.0])
def test_free_space_kernel_matches_numpy(fov) -> None:
    sim = simulate("crowd", duration=1.0, fov=fov) if fov else simulate("crowd", duration=1.0)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    mem = FreeSpaceMemory()
    ref = mem.make_ref(sim.scans[0], poses[0], sim.scans[0].valid_mask())
    rng = np.random.default_rng(0)
    pts = rng.uniform(-8.0, 8.0, size=(5000, 2))
    got = np.zeros(pts.shape[0], dtype=bool)
    assert FreeTest((ref,), mem.margin).count(pts, got) == got.sum()  # (the runtime test, one reference)
    want = _seen_through_numpy(ref, pts, mem.margin)
    np.testing.assert_array_equal(got, want)
    assert 200 < got.sum() < 4800  # both answers occur


def test_free_space_references_and_flags_into_a_given_mask() -> None:
    """The reference scans are the buffered ones nearest each reference age (the first on ties, as np.argmin of the
    age differences), each once and only if older than now; the test kept for later (``test_at``, the references
    chosen now) gives the fraction ``seen_through`` gives now, also after the memory has gained and dropped scans."""
    sim = simulate("crowd", duration=1.0)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    mem = FreeSpaceMemory(ref_ages=(0.3, 0.8, 0.3))
    for scan, pose in zip(sim.scans[:20], poses[:20]):
        mem.add(scan, pose, scan.valid_mask())
    buf = list(mem._buf)
    stamps = np.array([b.stamp for b in buf])
    for now in (float(stamps[-1]), float(stamps[-1]) + 0.05, float(stamps[10]), 0.5 * (stamps[3] + stamps[4]) + 0.3):
        want = []
        ages = now - stamps
        for a in mem.ref_ages:
            j = int(np.argmin(np.abs(ages - a)))
            if ages[j] > 0.0 and buf[j] not in want:
                want.append(buf[j])
        assert mem._refs(now) == want
    assert len(mem._refs(float(stamps[-1]))) == 2  # the second age 0.3 picks the same scan: once
    rng = np.random.default_rng(6)
    pts = rng.uniform(-8.0, 8.0, size=(3000, 2))
    now = float(stamps[-1]) + 0.05
    base = mem.seen_through(pts, now)
    refs = mem._refs(now)
    assert len(refs) == 2
    # every reference in one kernel call: the OR of the per-reference numpy tests
    np.testing.assert_array_equal(base, _seen_through_numpy(refs[0], pts, mem.margin)
                                  | _seen_through_numpy(refs[1], pts, mem.margin))
    assert (base != _seen_through_numpy(refs[0], pts, mem.margin)).any()  # (the second reference adds points)
    test = mem.test_at(now)
    mem.clear()  # (the memory moves on — here it forgets every scan — the kept test does not)
    assert not mem.seen_through(pts, now).any()
    assert test.fraction(pts) == int(np.count_nonzero(base)) / 3000
    assert 100 < base.sum() < 2900


def test_free_test_with_references_of_different_beam_counts() -> None:
    """A kept test whose reference scans differ in beam count and fan (a full one and 400 of its 720 beams), in both
    orders and with a third reference (two kernel calls): its count and flags are the OR of the per-reference numpy
    tests, points already flagged stay and count too, and a single reference's count is that of its own mask."""
    sim = simulate("crowd", duration=0.5)
    full = sim.scans[3]
    s0 = sim.scans[0]
    part = Scan(s0.stamp, s0.angle_min + 100 * s0.angle_increment, s0.angle_increment, s0.ranges[100:500].copy(),
                s0.range_min, s0.range_max)  # (400 of the 720 beams: a partial fan)
    mem = FreeSpaceMemory()
    ra = mem.make_ref(full, Pose2D.from_array(sim.ground_truth.poses_in("first")[3]), full.valid_mask())
    rb = mem.make_ref(part, Pose2D(0.4, -0.3, 0.5), part.valid_mask())
    assert ra.full and not rb.full
    assert ra.ranges.shape[0] != rb.ranges.shape[0]
    rng = np.random.default_rng(8)
    pts = rng.uniform(-8.0, 8.0, size=(4000, 2))
    want = _seen_through_numpy(ra, pts, mem.margin) | _seen_through_numpy(rb, pts, mem.margin)
    rc = mem.make_ref(full, Pose2D(-1.0, 0.5, 2.0), full.valid_mask())
    want3 = want | _seen_through_numpy(rc, pts, mem.margin)
    assert want3.sum() > want.sum()
    assert FreeTest((ra, rb, rc), mem.margin).fraction(pts) == int(np.count_nonzero(want3)) / 4000
    assert FreeTest((), mem.margin).fraction(pts) == 0.0
    for refs in ((ra, rb), (rb, ra)):
        test = FreeTest(refs, mem.margin)
        free = np.zeros(4000, dtype=bool)
        free[:7] = True  # (flags already set stay and count)
        assert test.count(pts, free) == int(np.count_nonzero(want | (np.arange(4000) < 7)))
        np.testing.assert_array_equal(free[7:], want[7:])
        assert test.fraction(pts) == int(np.count_nonzero(want)) / 4000
    for ref in (ra, rb):
        assert mem.count_seen_by(ref, pts) == int(np.count_nonzero(_seen_through_numpy(ref, pts, mem.margin)))
    assert 100 < want.sum() < 3900


def test_fragment_hosts_match_the_per_track_test() -> None:
    rng = np.random.default_rng(5)
    tx, ty = rng.uniform(-3, 3, 6), rng.uniform(-3, 3, 6)
    th, s0, s1 = rng.uniform(0, math.pi, 6), rng.uniform(0.3, 1.5, 6), rng.uniform(0.3, 1.0, 6)
    clouds = [np.column_stack((tx[i % 6] + rng.normal(0, 0.3, 8), ty[i % 6] + rng.normal(0, 0.3, 8)))
              for i in range(30)]
    px = np.concatenate([c[:, 0] for c in clouds])
    py = np.concatenate([c[:, 1] for c in clouds])
    npts = np.full(30, 8, dtype=np.int64)
    start = np.arange(30, dtype=np.int64) * 8
    margin = 0.15
    got = fragment_hosts(px, py, start, npts, np.arange(30, dtype=np.int64), tx, ty, th, s0, s1, margin)
    for r, cloud in enumerate(clouds):
        best, best_d = -1, math.inf
        for i in range(6):
            c, s = math.cos(th[i]), math.sin(th[i])
            rel = cloud - [tx[i], ty[i]]
            u = np.abs(rel[:, 0] * c + rel[:, 1] * s) - 0.5 * s0[i]
            v = np.abs(-rel[:, 0] * s + rel[:, 1] * c) - 0.5 * s1[i]
            d = float(np.max(np.maximum(u, v)))
            if d < margin and d < best_d:
                best, best_d = i, d
        assert got[r] == best
    assert (got >= 0).sum() >= 5 and (got < 0).sum() >= 5


def test_pairwise_sum_and_segment_means_round_like_numpy() -> None:
    rng = np.random.default_rng(1)
    for n in (1, 7, 8, 9, 127, 128, 129, 300, 1000, 4099):
        x = rng.normal(size=n + 3) * 10.0 ** rng.integers(-3, 6, n + 3)
        assert _pairwise_sum(x, 3, n) == x[3:].sum()  # bit for bit
    off = np.array([0, 5, 5, 300, 1303], dtype=np.int64)
    v = rng.normal(size=1303)
    means = segment_means(v, off)
    assert means[1] == 0.0
    for c in (0, 2, 3):
        assert means[c] == v[off[c]:off[c + 1]].mean()


def test_mask_fractions_equal_segment_means_of_the_masks() -> None:
    """The tracker's per-detection fractions: the count over the length, bit for bit segment_means of 0 / 1."""
    rng = np.random.default_rng(3)
    off = np.array([0, 5, 5, 300, 301, 1303], dtype=np.int64)
    masks = rng.random((4, 1303)) < np.array([[0.02], [0.5], [0.9], [0.37]])
    got = mask_fractions(masks, off)
    assert got.shape == (4, 5) and (got[:, 1] == 0.0).all()
    for r in range(4):
        want = segment_means(masks[r].astype(np.float64), off)
        assert got[r].tobytes() == want.tobytes()
    assert 0.0 < got[0, 4] < got[3, 4] < got[1, 4] < got[2, 4] < 1.0


def test_world_points_are_the_pose_transform_bit_for_bit(scenes) -> None:
    """The kernel that maps the beams into the map frame gives the numpy arithmetic the tracker had (the same
    operations in the same order; invalid beams at the pose)."""
    cfg = DetectConfig()
    for scan, pose in scenes[:6]:
        seg = segment_scan(scan, cfg.segment)
        valid = scan.valid_mask() & (scan.ranges > 0.0)
        cos_a, sin_a = np.cos(scan.angles), np.sin(scan.angles)
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        r = np.where(valid, scan.ranges, 0.0)
        lx, ly = r * cos_a, r * sin_a
        ax, ay = c * lx - s * ly + pose.x, s * lx + c * ly + pose.y
        got = world_points(scan.ranges, valid, cos_a, sin_a, c, s, float(pose.x), float(pose.y), seg.beams)
        for g, w in zip(got, (ax, ay, ax[seg.beams], ay[seg.beams], np.column_stack((ax, ay))[seg.beams])):
            assert g.shape == w.shape and g.tobytes() == w.tobytes()
        assert (got[0][~valid] == pose.x).all()
        # the tracker's form (pass det25): the segmentation kernel also returns these points, in the same call
        both = segment_points(scan, cfg.segment, valid, float(pose.x), float(pose.y), pose.theta)
        for f in ("labels", "beams", "offsets", "structure"):
            g, w = getattr(both[0], f), getattr(seg, f)
            assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()
        assert (both[0].wrapped, both[0].n_dropped) == (seg.wrapped, seg.n_dropped)
        for g, w in zip(both[1:], got):
            assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()
    # a scan without a valid beam: no cluster, every beam at the pose
    scan, pose = scenes[0]
    none = np.zeros(scan.n_beams, dtype=bool)
    seg, ax, ay, px, py, pts, _, _ = segment_points(scan, cfg.segment, none, float(pose.x), float(pose.y), pose.theta)
    assert seg.n_clusters == 0 and px.shape == py.shape == (0,) and pts.shape == (0, 2)
    assert (ax == pose.x).all() and (ay == pose.y).all()


def _merge_numpy(first, second, px, py, beams, starts, npts, kinds, fits, lohi, rel):
    """The leg merge as the tracker's numpy code did it (pair by pair, concatenations)."""
    pairs = list(zip(first.tolist(), second.tolist()))
    drop = {j for pr in pairs for j in pr}
    ki = np.array([j for j in range(starts.shape[0]) if j not in drop], dtype=np.int64)
    m, n0 = len(pairs), px.shape[0]
    new_fits, new_lohi = np.zeros((m, fits.shape[1])), np.empty((m, 4))
    new_starts, new_npts, ext_px, ext_py, ext_b = [], [], [px], [py], []
    for r, (a, b) in enumerate(pairs):
        sa, sb = slice(starts[a], starts[a] + npts[a]), slice(starts[b], starts[b] + npts[b])
        pts = np.concatenate((np.column_stack((px[sa], py[sa])), np.column_stack((px[sb], py[sb]))))
        mid = 0.5 * (fits[a, FIT_CENTROID] + fits[b, FIT_CENTROID])
        new_fits[r, 6:8] = mid
        new_fits[r, FIT_CENTROID] = mid
        new_lohi[r, :2], new_lohi[r, 2:] = pts.min(axis=0), pts.max(axis=0)
        new_starts.append(n0)
        new_npts.append(pts.shape[0])
        ext_px.append(pts[:, 0])
        ext_py.append(pts[:, 1])
        ext_b.append(np.concatenate((beams[sa], beams[sb])))
        n0 += pts.shape[0]
    return (ki, np.concatenate((kinds[ki], np.zeros(m, dtype=kinds.dtype))), np.concatenate((fits[ki], new_fits)),
            np.concatenate((lohi[ki], new_lohi)), np.concatenate((rel[ki], np.zeros((m, 2, 2), dtype=bool))),
            np.concatenate((starts[ki], np.array(new_starts, dtype=np.int64))),
            np.concatenate((npts[ki], np.array(new_npts, dtype=np.int64))), np.concatenate(ext_px),
            np.concatenate(ext_py), np.concatenate(ext_b))


def test_merge_leg_pairs_matches_the_numpy_merge() -> None:
    """Legs of simulated people (small clusters in pairs) among larger clusters: the kernel's merged arrays are
    those of the pair-by-pair numpy merge, bit for bit."""
    rng = np.random.default_rng(4)
    sizes = rng.integers(2, 9, 24)
    sizes[::5] = 30  # some clusters too large to be legs
    offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
    centres = rng.uniform(-6.0, 6.0, (24, 2))
    centres[1::2] = centres[::2] + rng.uniform(-0.25, 0.25, (12, 2))  # leg pairs 0.1-0.35 m apart
    spread = np.where(sizes == 30, 1.0, 0.04)
    px = np.concatenate([centres[c, 0] + spread[c] * rng.normal(size=sizes[c]) for c in range(24)])
    py = np.concatenate([centres[c, 1] + spread[c] * rng.normal(size=sizes[c]) for c in range(24)])
    beams = rng.permutation(2 * px.shape[0])[:px.shape[0]].astype(np.int64)
    fits = fit_clusters(px, py, offsets, np.ones(24, dtype=bool), search_angles(1.0), CRITERIA["variance"], 0.01,
                        5, 5)
    lohi = np.column_stack((fits[:, F_LO1], fits[:, F_LO2], fits[:, F_HI1], fits[:, F_HI2]))
    rel = rng.random((24, 2, 2)) < 0.5
    kinds = rng.integers(0, 3, 24).astype(np.int8)
    starts, npts = offsets[:-1], offsets[1:] - offsets[:-1]
    first, second = leg_pairs(lohi, npts, fits, 0.35, 0.6)
    assert first.shape[0] >= 4
    got = merge_leg_pairs(first, second, px, py, beams, starts, npts, kinds, fits, lohi, rel)
    want = _merge_numpy(first, second, px, py, beams, starts, npts, kinds, fits, lohi, rel)
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()
    # the tracker's one-dispatch form: leg_pairs' pairs, then the same merged arrays, the persons' points (n, 2) and
    # their map evidence, the point-weighted means of the legs' columns (Tracker._merge_legs' former per-pair Python)
    mev = rng.random((3, 24))
    both = merge_legs(px, py, beams, starts, npts, kinds, fits, lohi, rel, mev, 0.35, 0.6)
    assert len(both) == 14 and both[0].tolist() == first.tolist() and both[1].tolist() == second.tolist()
    for g, w in zip(both[2:12], want):
        assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()
    n0 = px.shape[0]
    pts, mmev = both[12], both[13]
    assert pts.tobytes() == np.column_stack((want[7][n0:], want[8][n0:])).tobytes()
    nk = both[2].shape[0]
    assert mmev.shape == (3, nk + first.shape[0])
    for r, (a, b) in enumerate(zip(first.tolist(), second.tolist())):
        na, nb = npts.item(a), npts.item(b)
        for e in range(3):
            assert mmev[e, nk + r] == (na * mev.item(e, a) + nb * mev.item(e, b)) / (na + nb)
    # without a map: no evidence column
    assert merge_legs(px, py, beams, starts, npts, kinds, fits, lohi, rel, np.empty((3, 0)), 0.35, 0.6)[13].shape \
        == (3, 0)
    # no pair within reach: the argument arrays themselves come back, with empty pairs, indices, beams and points
    none = merge_legs(px, py, beams, starts, npts, kinds, fits, lohi, rel, mev, 0.35, 0.0)
    assert none[0].shape == none[1].shape == none[2].shape == none[11].shape == (0,) and none[12].shape == (0, 2)
    assert all(a is b for a, b in zip(none[3:11], (kinds, fits, lohi, rel, starts, npts, px, py)))
    assert none[13] is mev


def test_lu_solve3_matches_lapack_and_flags_singular() -> None:
    rng = np.random.default_rng(2)
    for _ in range(50):
        a = rng.normal(size=(3, 3))
        b = rng.normal(size=3)
        x = b.copy()
        det = _lu_solve3(a.copy(), x)
        np.testing.assert_allclose(det, np.linalg.det(a), rtol=1e-10)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    sing = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    x = np.ones(3)
    assert _lu_solve3(sing, x) == 0.0


def test_tracker_without_detections_or_tracks_is_cheap_and_consistent() -> None:
    """Empty scans take the no-cluster path: no kernel input is left over from an earlier scan."""
    sim = simulate("paper", duration=1.0)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    tr = Tracker()
    for s, p in zip(sim.scans[:10], poses[:10]):
        tr.update(s, p)
    n_before = tr.n_tracks
    assert n_before > 0
    empty = sim.scans[10].with_ranges(np.full(sim.scans[10].n_beams, np.nan))
    out = tr.update(empty, poses[10])
    assert tr.last_detections == [] and tr.stats.empty_scans == 1
    assert all(t.n_points == 0 for t in out) and len(out) == n_before


def test_gate_distance_test_is_hypots_also_at_the_limit() -> None:
    """gate_costs' near[i, j] is hypot(centroid − track) < gate_distance + reach[i] bit for bit: it decides most
    pairs from the squared distance, so pairs placed exactly on the limit and one ulp either side, NaN centroids and
    a negative / NaN / zero limit must still give hypot's answer (and d2, ok as computed from it)."""
    rng = np.random.default_rng(7)
    n = 6
    Xs = np.zeros((n, 4))
    Xs[:, 0] = rng.uniform(-30.0, 30.0, n)
    Xs[:, 1] = rng.uniform(-30.0, 30.0, n)
    Ps = np.tile(np.eye(4) * 0.3, (n, 1, 1))
    reach = np.array([0.4, 1.3, -5.0, np.nan, 0.0, 0.7])
    gd = 1.0
    cen = []
    for i in range(n):
        lim = gd + reach[i]
        for ang in rng.uniform(0.0, 2.0 * math.pi, 12):
            for d in (lim, np.nextafter(lim, 0.0), np.nextafter(lim, 10.0), lim * (1 - 1e-11), lim * (1 + 1e-11),
                      0.5 * lim, 2.0 * lim, 1e-3):
                cen.append((Xs[i, 0] + d * math.cos(ang), Xs[i, 1] + d * math.sin(ang)))
    cen.append((np.nan, 0.0))
    cen.append((np.inf, 0.0))
    centroid = np.array(cen)
    m = centroid.shape[0]
    R = np.tile(np.eye(2) * 0.01, (m, 1, 1))
    kind = np.full(m, K_POINT, dtype=np.int8)
    d2, near, ok = gate_costs(Xs, Ps, reach, np.zeros(n, dtype=bool), np.zeros(n), np.ones((n, 2)), centroid.copy(),
                              R, gd, 9.21, kind, np.zeros(m), np.zeros((m, 4)), np.zeros((m, 2, 2), dtype=bool),
                              centroid, np.zeros((m, 3)), np.zeros(1), np.zeros(1), np.zeros(m, dtype=np.int64),
                              np.ones(m, dtype=np.int64), fit_params(DetectConfig().fit))
    want = np.array([[math.hypot(centroid[j, 0] - Xs[i, 0], centroid[j, 1] - Xs[i, 1]) < gd + reach[i]
                      for j in range(m)] for i in range(n)])
    np.testing.assert_array_equal(near, want)
    assert 0 < want.sum() < want.size
    assert not near[2].any() and not near[3].any()  # (a negative and a NaN limit: never near)
    # the pairs placed on the limit and an ulp either side (left to hypot by the shortcut) give both answers
    on = np.array([[near[i, i * 96 + a * 8 + t] for a in range(12) for t in range(3)] for i in (0, 1, 4, 5)])
    assert on.any() and not on.all()
    assert near[0, 3:96:8].all() and not near[0, 4:96:8].any()  # 1e-11 relative inside / outside the limit
    np.testing.assert_array_equal(ok, np.isfinite(d2) & (d2 < 9.21) & want)


def test_reference_arrays_are_the_masked_ranges_and_the_inverse_pose() -> None:
    """FreeSpaceMemory.make_ref's ranges are np.where(valid, ranges, inf) and its parameter row holds
    Pose2D.inverse() bit for bit (with angle_min, increment, the full-circle flag and range_max)."""
    sim = simulate("crowd", duration=0.5)
    scan = sim.scans[2]
    valid = scan.valid_mask()
    valid[::5] = False
    for pose in (Pose2D(3.25, -1.5, 2.9), Pose2D(-0.1, 7.0, -3.1), Pose2D(0.0, 0.0, math.pi)):
        ref = FreeSpaceMemory.make_ref(scan, pose, valid)
        np.testing.assert_array_equal(ref.ranges, np.where(valid, scan.ranges, np.inf))
        inv = pose.inverse()
        want = np.array([inv.x, inv.y, inv.theta, scan.angle_min, scan.angle_increment, 1.0 if ref.full else 0.0,
                         scan.range_max])
        assert ref.par.tobytes() == want.tobytes()
        assert ref.pose is pose and ref.stamp == scan.stamp
