"""Fast paths of the per-scan work give exactly what the plain computation gives (issue 9/13 speed work):
the LM matcher's one-pass trial step, the lazily computed match covariance, the reuse of the match's
scan points by the map update, the map's growth bounds, the ledger's cell count of a dropped record and its
block copy of an update's rows, the beam trigonometry shared by the scans of a laser and the body filter's
kept drop ranges."""

from __future__ import annotations

import math

import numpy as np
from conftest import paper_room_scan, paper_room_slam

from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.erasure import _LevelRecord
from dynslam2d.slam.grid import GridLevel
from dynslam2d.slam.matcher import _solve3, accumulate, covariance_world, match_level
from dynslam2d.types import Pose2D, Scan

scan_at = paper_room_scan


mapped = paper_room_slam


def lm_reference(prob, pts, pose, n_iter, lam0, lam_max, max_rot, max_trans):
    """The LM loop with a cost-only pass at every trial step and H, g recomputed at an accepted pose."""
    H, g, Hs, gs, d = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3)), np.zeros(3), np.zeros(3)
    x, y, th = pose
    cost, _, _ = accumulate(prob, pts, x, y, th, False, H, g)
    lam, steps = lam0, {"accepted": 0, "rejected": 0}
    for _ in range(n_iter):
        if H[0, 0] == 0.0 or H[1, 1] == 0.0:
            break
        A = H.copy()
        for a in range(3):
            A[a, a] += lam * A[a, a] + 1e-9
        if not _solve3(A, g.copy(), d):
            lam *= 10.0
            if lam > lam_max:
                break
            continue
        d[2] = min(max(d[2], -max_rot), max_rot)
        nt = math.sqrt(d[0] * d[0] + d[1] * d[1])
        if nt > max_trans:
            d[0] *= max_trans / nt
            d[1] *= max_trans / nt
        nx, ny, nth = x + d[0], y + d[1], th + d[2]
        new_cost, _, _ = accumulate(prob, pts, nx, ny, nth, False, Hs, gs)  # cost only (H, g thrown away)
        if new_cost < cost:
            x, y, th = nx, ny, nth
            cost, _, _ = accumulate(prob, pts, x, y, th, False, H, g)
            lam = max(lam * 0.1, 1e-7)
            steps["accepted"] += 1
            if nt < 1e-3 and abs(d[2]) < 1e-5:
                break
        else:
            steps["rejected"] += 1
            lam *= 10.0
            if lam > lam_max:
                break
    return np.array([x, y, th]), steps


def test_lm_one_pass_trial_step_equals_separate_cost_and_derivative_passes() -> None:
    slam, first = mapped()
    pts = slam.scan_points(scan_at(first.compose(Pose2D(0.12, -0.08, 0.05))))[0]
    seen = {"accepted": 0, "rejected": 0}
    for lv in slam.map.levels:
        pm = pts / lv.resolution
        for off in ((0.0, 0.0, 0.0), (1.5, -1.0, 0.08), (-2.0, 0.5, -0.12), (0.3, 0.3, 0.3)):
            start = lv.pose_to_map(np.array(off))
            want, steps = lm_reference(lv.prob, pm, start, 12, 0.1, 1e4, 0.2, 2.0)
            got, n_acc = match_level(lv.prob, pm, start, 12, False, True, 0.1, 1e4, 0.2, 2.0, start, np.zeros((3, 3)))
            np.testing.assert_array_equal(got, want)  # bit-identical, not merely close
            assert n_acc == steps["accepted"]
            for key in seen:
                seen[key] += steps[key]
    assert seen["accepted"] > 0 and seen["rejected"] > 0  # both branches of the trial step were taken


def test_match_covariance_is_computed_when_read_and_can_be_set() -> None:
    slam, first = mapped()
    res = slam.match(scan_at(first.compose(Pose2D(0.05, 0.0, 0.0)), stamp=0.1), commit=False)
    assert res._covariance is None  # not computed by the match itself
    want = covariance_world(res.hessian, res.sigma2, slam.map.resolution)
    np.testing.assert_array_equal(res.covariance, want)
    assert res._covariance_of is None and res.covariance is res.covariance  # computed once
    res.covariance = np.eye(3)
    np.testing.assert_array_equal(res.covariance, np.eye(3))


def test_map_update_reusing_the_match_points_writes_the_same_map() -> None:
    a, first = mapped()
    b, _ = mapped()
    scan = scan_at(first.compose(Pose2D(0.5, 0.2, 0.3)), stamp=0.1)
    ra, rb = a.match(scan), b.match(scan)
    assert ra.pose == rb.pose and a._last_points[0] is scan
    twin = scan.without(np.zeros(scan.n_beams, dtype=bool))  # an equal scan, another object: recomputed
    assert a.update_map(scan, ra.pose, force=True) and b.update_map(twin, rb.pose, force=True)
    for la, lb in zip(a.map.levels, b.map.levels):
        np.testing.assert_array_equal(la.logodds, lb.logodds)
        np.testing.assert_array_equal(la.uidx, lb.uidx)


def test_growth_bounds_from_the_extreme_ends_equal_the_extreme_cells() -> None:
    rng = np.random.default_rng(3)
    for res in (0.05, 0.1, 0.2):
        lv = GridLevel(res)
        ends = rng.uniform(-20.0, 20.0, (500, 2))
        ends[:20] = np.round(ends[:20] / res - 0.5) * res + 0.5 * res  # exactly on cell borders
        origin = rng.uniform(-1.0, 1.0, 2)
        cells = np.floor(ends / res + 0.5)
        s = np.floor(origin / res + 0.5)
        want = (int(min(s[0], cells[:, 0].min())), int(min(s[1], cells[:, 1].min())),
                int(max(s[0], cells[:, 0].max())), int(max(s[1], cells[:, 1].max())))
        assert lv.cell_bounds(origin, ends) == want


def test_dropped_ledger_record_counts_the_cells_folding_would() -> None:
    rng = np.random.default_rng(5)
    for cap, fold_first in ((10_000, False), (40, False), (40, True), (300, True)):
        a, b = _LevelRecord(cap), _LevelRecord(cap)
        for step in range(12):
            keys = np.unique(rng.integers(0, 120, rng.integers(1, 30))).astype(np.int64)
            n = keys.shape[0]
            rows = (keys, rng.normal(size=n), np.full(n, step - 1), np.full(n, step))
            a.append(*rows)
            b.append(*rows)
            if fold_first and step == 5:
                a.compact()
                b.compact()
        assert a.new_cells() == b.compact()
        assert a.new_cells() > 0 or cap == 40


def test_multires_integrate_equals_per_level_integration() -> None:
    """MultiResMap.integrate (bounds from the extreme ends, every level's end cells and rays in one kernel call)
    writes every level exactly as GridLevel.integrate does level by level, with and without the grazing stop and
    clearing rays, on maps of 2, 3, 4 (the fused kernel; 4: the loop closer's submaps, pass rest18) and 5 levels (the
    per-level loop)."""
    from conftest import scan_rays

    from dynslam2d.slam.grid import MultiResMap

    rng = np.random.default_rng(3)
    # 4 levels and fewer: one kernel call for all (integrate_levels); 5: level by level in Python
    for grazing, n_levels in ((0.0, 3), (1.5, 3), (0.0, 2), (1.5, 4), (0.0, 4), (1.5, 5)):
        fast = MultiResMap(0.05, n_levels, -0.4, 0.9, grazing_cells=grazing)
        plain = MultiResMap(0.05, n_levels, -0.4, 0.9, grazing_cells=grazing)
        pose = Pose2D(0.3, -0.2, 0.1)
        for step in range(6):
            pose = pose.compose(Pose2D(*rng.uniform(-0.4, 0.4, 2), float(rng.uniform(-0.3, 0.3))))
            a = np.linspace(-2.0, 2.0, 300)
            rr = rng.uniform(0.5, 4.0 + 3 * step, a.shape[0])  # later scans reach further: the levels grow
            hits = np.column_stack((rr * np.cos(a), rr * np.sin(a)))
            clear = hits[::7] * 1.3 if step % 2 else None
            fast.integrate(pose, hits, clear)
            ends, hit, stop = scan_rays(pose, hits, clear, grazing, plain.min_sin)
            for lv in plain.levels:
                lv.integrate(np.array([pose.x, pose.y]), ends, hit, plain.l_free, plain.l_occ, plain.cap, stop)
        for lf, lp in zip(fast.levels, plain.levels):
            assert (lf.i0, lf.j0, lf.shape, lf.update_counter) == (lp.i0, lp.j0, lp.shape, lp.update_counter)
            assert np.array_equal(lf.logodds, lp.logodds) and np.array_equal(lf.prob, lp.prob)
            assert np.array_equal(lf.uidx, lp.uidx)
            assert lf.n_grows > 1  # the growth path was exercised


def test_ledger_packed_level_cells_equal_the_per_level_sort() -> None:
    """EvidenceLedger._level_cells (one sort of (level, track, cell) packed into int64 by scan_cells) returns
    exactly the rows of the per-level lexsort / membership path: tracks sharing cells, cells an unowned point
    also hits (left out), points outside the level's array (read as 0 / −1), and the flat indices re-read
    the same values."""
    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam.erasure import EvidenceLedger
    from dynslam2d.slam.grid import MultiResMap
    from dynslam2d.slam.ledgerkernels import scan_cells

    rng = np.random.default_rng(5)
    hmap = MultiResMap(0.05, 3, -0.4, 0.9)
    a = np.linspace(-np.pi, np.pi, 400, endpoint=False)
    hmap.integrate(Pose2D(), np.column_stack((3.0 * np.cos(a), 3.0 * np.sin(a))))
    led = EvidenceLedger(MemoryConfig(), 0.1, 30.0)
    n_checked = n_outside = 0
    for trial in range(20):
        reach = 2.5 if trial % 2 else 12.0  # far points lie outside the level arrays: the per-level read path
        pts = rng.uniform(-reach, reach, (300, 2))
        pts[100:140] = pts[:40] + rng.normal(0.0, 0.02, (40, 2))  # unowned points near the tracks' points
        # as a scan at the identity pose: ranges and read-only cos / sin whose products are the points
        rr = np.hypot(pts[:, 0], pts[:, 1])
        cos_a, sin_a = pts[:, 0] / rr, pts[:, 1] / rr
        cos_a.flags.writeable = sin_a.flags.writeable = False
        pts = np.column_stack((rr * cos_a, rr * sin_a))
        mine_b = np.zeros(300, dtype=bool)
        mine_b[:100] = True
        mine_b[200:] = rng.random(100) < 0.5
        ids = rng.choice([3, 9, 11, 40], int(mine_b.sum()))
        flat: list = []
        uids = np.unique(ids)
        owner = np.full(300, -1, dtype=np.int64)
        owner[mine_b] = ids
        packed, params, _, _ = scan_cells(rr, cos_a, sin_a, np.ones(300, dtype=bool), np.zeros(300, dtype=bool),
                                          owner, uids, 0.0, np.inf, 1.0, 0.0, 0.0, 0.0,
                                          np.array([lv.resolution for lv in hmap.levels]))
        packed.sort()
        fast = led._level_cells(packed, params, uids, hmap, flat)
        plain = led._level_cells_plain(pts, mine_b, ids, hmap)
        assert fast is not None and len(fast) == len(plain) == 3
        for k, (f, p) in enumerate(zip(fast, plain)):
            for u, v in zip(f, p):
                assert u.dtype == v.dtype and np.array_equal(u, v)
            assert p[0].shape[0] > 0 and np.all(np.diff(p[0]) >= 0)
            if flat[k] is None:
                n_outside += 1
            else:
                lv = hmap.levels[k]
                assert np.array_equal(lv.logodds.ravel()[flat[k][0]].astype(np.float64), p[3])
            n_checked += 1
    assert n_outside > 0 and n_outside < n_checked  # both read paths ran


def test_ledger_keeps_each_tracks_valid_beams_as_the_per_track_gather() -> None:
    """before_update with keep_beams gathers every track's kept beams at once: per track the same beams (in
    order, int32) as ``t.beams[valid[t.beams]]``; a track with every beam removed or invalid gets no ledger."""
    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam.erasure import EvidenceLedger
    from dynslam2d.types import Box, Track

    slam, first = mapped()
    scan = scan_at(first, 1.0)
    n = scan.ranges.shape[0]
    ranges = scan.ranges.copy()
    ranges[50:60] = np.nan  # invalid beams inside track 4's beams
    scan = scan.with_ranges(ranges)
    removed = np.zeros(n, dtype=bool)
    removed[300:320] = True  # track 6: every beam removed

    def track(tid: int, beams: np.ndarray) -> Track:
        return Track(id=tid, state="confirmed", stamp=1.0, box=Box(1.0, 0.5, 0.0, 0.4, 0.4), velocity=np.zeros(2),
                     covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect", in_m=False, m_reason="",
                     beams=beams, n_points=int(beams.shape[0]))

    tracks = [track(4, np.arange(40, 80)), track(2, np.array([200, 150, 151, 400])), track(6, np.arange(300, 320)),
              track(9, np.arange(500, 503, dtype=np.int32))]
    led = EvidenceLedger(MemoryConfig(), slam.config.laser_min_dist, slam.config.laser_max_dist, keep_beams=True)
    pend = led.before_update(scan, first, tracks, removed, slam.map, index=17)
    assert pend is not None
    with np.errstate(invalid="ignore"):
        valid = (scan.valid_mask() & (scan.ranges > slam.config.laser_min_dist)
                 & (scan.ranges < slam.config.laser_max_dist) & ~removed)
    assert set(led._ledgers) == {4, 2, 9}
    for t in tracks:
        if t.id == 6:
            continue
        (idx, kb), = led._ledgers[t.id].beams
        want = t.beams[valid[t.beams]].astype(np.int32)
        assert idx == 17 and kb.dtype == np.int32 and np.array_equal(kb, want)
    assert led._ledgers[4].beams[0][1].shape[0] == 30


def test_ledger_beam_owner_in_one_assignment_equals_per_track_assignment() -> None:
    """The beams' owner track is set with one assignment when no beam is in two tracks, else per track in order
    (the later track wins): the pending rows equal those of the per-track owner and the per-level path."""
    from dynslam2d.detect.memoryconfig import MemoryConfig
    from dynslam2d.slam.erasure import EvidenceLedger
    from dynslam2d.types import Box, Track

    slam, first = mapped()
    scan = scan_at(first, 1.0)
    n = scan.ranges.shape[0]

    def track(tid: int, beams: np.ndarray) -> Track:
        return Track(id=tid, state="confirmed", stamp=1.0, box=Box(1.0, 0.5, 0.0, 0.4, 0.4), velocity=np.zeros(2),
                     covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect", in_m=False, m_reason="",
                     beams=beams, n_points=int(beams.shape[0]))

    for overlap in (False, True):
        tracks = [track(8, np.arange(100, 140)), track(3, np.arange(300, 330)),
                  track(5, np.arange(130, 150) if overlap else np.arange(140, 150))]
        led = EvidenceLedger(MemoryConfig(), slam.config.laser_min_dist, slam.config.laser_max_dist)
        removed = np.zeros(n, dtype=bool)
        pend = led.before_update(scan, first, tracks, removed, slam.map)
        owner = np.full(n, -1, dtype=np.int64)
        for t in tracks:
            owner[t.beams] = t.id
        with np.errstate(invalid="ignore"):
            valid = (scan.valid_mask() & (scan.ranges > slam.config.laser_min_dist)
                     & (scan.ranges < slam.config.laser_max_dist))
        idx = np.flatnonzero(valid)
        a = scan.angles[idx]
        r = scan.ranges[idx]
        pts = first.transform_points(np.column_stack((r * np.cos(a), r * np.sin(a))))
        mine_b = owner[idx] >= 0
        plain = led._level_cells_plain(pts, mine_b, owner[idx][mine_b], slam.map)
        for f, p in zip(pend.per_level, plain):
            for u, v in zip(f, p):
                assert np.array_equal(u, v)
        n5 = int((pend.per_level[0][0] == 5).sum())
        assert n5 > 0 and (int((pend.per_level[0][0] == 8).sum()) < 40 if overlap else True)


def test_scan_trig_is_shared_and_gives_the_per_scan_trigonometry() -> None:
    """Scan.trig computes the beams' cos / sin once per beam geometry (read-only, shared by the scans of a laser);
    points, the matcher's scan points and the clearing geometry are bit for bit what the per-scan cos / sin of
    the selected angles give."""
    from dynslam2d.slam.cleanup import CleanConfig, scan_clearing

    rng = np.random.default_rng(11)
    a, b = scan_at(Pose2D(0.2, 0.1, 0.3)), scan_at(Pose2D(-0.4, 0.3, -1.0), 0.1)
    ca, sa = a.trig()
    assert b.trig()[0] is ca and not ca.flags.writeable and not sa.flags.writeable
    other = Scan(stamp=0.0, angle_min=-1.0, angle_increment=0.01, ranges=np.full(200, 2.0), range_min=0.05,
                 range_max=20.0)
    assert other.trig()[0] is not ca and other.trig()[0].shape == (200,)
    for _ in range(20):
        m = a.valid_mask() & (rng.random(a.n_beams) < rng.random())
        ang = a.angles[m]
        want = np.column_stack((a.ranges[m] * np.cos(ang), a.ranges[m] * np.sin(ang)))
        assert np.array_equal(a.points(m), want)
    slam = HectorSlam(SlamConfig(clear_no_return_dist=2.0))
    pts, clear = slam.scan_points(a)
    noret = ~np.isfinite(a.ranges) | (a.ranges > a.range_max) | (a.ranges >= slam.config.laser_max_dist)
    assert np.array_equal(clear, np.column_stack((2.0 * np.cos(a.angles[noret]), 2.0 * np.sin(a.angles[noret]))))
    pose = Pose2D(0.3, -0.2, 0.7)
    with_angles = scan_clearing(a.ranges, a.angles, a.valid_mask(), pose, 0.05, CleanConfig())
    with_trig = scan_clearing(a.ranges, a.trig(), a.valid_mask(), pose, 0.05, CleanConfig())
    assert with_angles[0] == with_trig[0]
    for u, v in zip(with_angles[1:], with_trig[1:]):
        assert np.array_equal(u, v)


def test_ledger_rows_pushed_as_one_block_fold_as_pushed_row_by_row() -> None:
    """_LevelRecord.push_rows (an update's rows stacked once, one copy per record) folds to what push gives,
    and a record holding one update counts its cells without a sort as folding would, under the cap too."""
    rng = np.random.default_rng(8)
    for cap in (10_000, 30):
        a, b = _LevelRecord(cap), _LevelRecord(cap)
        for step in range(40):
            keys = np.unique(rng.integers(0, 200, rng.integers(1, 50))).astype(np.int64)
            n = keys.shape[0]
            delta, ub, ua = rng.normal(size=n), np.where(rng.random(n) < 0.8, step - 1, -1), np.full(n, step)
            rows = np.empty((4, n + 3), dtype=np.int64)  # with columns of other tracks around
            rows[:, :n] = np.stack((keys, ub, ua, delta.view(np.int64)))
            rows[:, n:] = -5
            if a.push(keys, delta, ub, ua):
                a.compact()
            if b.push_rows(rows, 0, n):
                b.compact()
        assert a.compact() == b.compact()
        for f in ("key", "delta", "pure", "last"):
            assert np.array_equal(getattr(a, f), getattr(b, f))
        one, ref = _LevelRecord(cap), _LevelRecord(cap)
        keys = np.arange(0, 90, 2, dtype=np.int64)
        for rec in (one, ref):
            rec.push(keys, np.ones(45), np.full(45, -1), np.zeros(45, dtype=np.int64))
        assert one.new_cells() == ref.compact() == min(45, cap)


def test_body_filter_keeps_drop_ranges_equal_to_a_fresh_computation() -> None:
    """BodyFilter.observe keeps its drop ranges while the body beams and their ranges stay the same: after every
    scan they equal the ranges computed from scratch from the body beams (edges included)."""
    from dynslam2d.config import Config
    from dynslam2d.detect.body import BodyFilter

    cfg = Config().detect.footprint
    body = BodyFilter(cfg)
    n = 360
    rng = np.random.default_rng(2)
    changes = 0
    prev = None
    for i in range(150):
        pose = Pose2D(0.02 * i, 0.01 * i, 0.03 * i)
        r = rng.uniform(2.0, 6.0, n)
        r[100:106] = 0.3 + rng.normal(0.0, 0.005, 6)  # a bumper fixed in the laser frame
        if i >= 90:
            r[200:203] = 0.5  # a second part seen from scan 90 on
        s = Scan(stamp=0.1 * i, angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=r, range_min=0.05,
                 range_max=20.0)
        body.mask(s)
        body.observe(s, pose)
        ref_r = np.where(body.body, body._ref, 0.0)
        grown = ref_r.copy()
        for d in range(1, int(cfg.auto_edge_beams) + 1):
            grown[d:] = np.maximum(grown[d:], ref_r[:-d])
            grown[:-d] = np.maximum(grown[:-d], ref_r[d:])
        edge = ~body.body & (grown > 0.0)
        want = ref_r.copy()
        want[edge] = grown[edge] + cfg.auto_tolerance
        assert np.array_equal(body.body_ranges, ref_r) and np.array_equal(body._drop_r, want)
        if prev is not None and not np.array_equal(prev, body.body):
            changes += 1
        prev = body.body.copy()
    assert body.body[100:106].all() and body.body[200:203].all() and changes >= 2


def test_single_pose_relative_and_compose_equal_the_vectorised_path() -> None:
    """relative / compose of one (3,) pose each (the keyframe path, scalar arithmetic without np.stack) give
    bit for bit what the (n, 3) path gives, including angles at ±π and wrap-around."""
    from dynslam2d.slam.posegraph import compose, relative

    rng = np.random.default_rng(11)
    a = np.column_stack((rng.normal(0, 30, 4000), rng.normal(0, 30, 4000), rng.uniform(-12, 12, 4000)))
    b = np.column_stack((rng.normal(0, 30, 4000), rng.normal(0, 30, 4000), rng.uniform(-12, 12, 4000)))
    a[:50, 2], b[:50, 2] = math.pi, -math.pi
    a[50:100, 2], b[50:100, 2] = np.nextafter(math.pi, 0.0), 0.0
    for f in (relative, compose):
        many = f(a, b)
        one = np.array([f(a[i], b[i]) for i in range(a.shape[0])])
        assert one.shape == many.shape and one.tobytes() == many.tobytes()
    assert not np.array_equal(relative(a, b), compose(a, b))


def test_pose_graph_diag_edges_built_when_read_equal_added_edges() -> None:
    """PoseGraph.add_diag_edge (the loop closer's keyframe edges, built when the edges are next read) gives the
    edges add_edge with diag_info gives, at the same indices, between loop edges added with add_edge; and the
    keyframe chain helper loops._chain equals relative and compose bit for bit."""
    from dynslam2d.slam.loops import _chain
    from dynslam2d.slam.posegraph import PoseGraph, compose, diag_info, relative

    rng = np.random.default_rng(3)
    a, b = PoseGraph(), PoseGraph()
    for g in (a, b):
        for _ in range(12):
            g.add_node(rng.normal(size=3) if g is a else a.poses[g.n_nodes])
    ka, kb = [], []
    for k in range(11):
        z = rng.normal(size=3).tolist()
        sxy, sth = float(rng.uniform(0.01, 1.0)), float(rng.uniform(0.001, 0.5))
        ka.append(a.add_edge(k, k + 1, z, diag_info(sxy, sth), robust=k % 3 == 0))
        kb.append(b.add_diag_edge(k, k + 1, list(z), sxy, sth, robust=k % 3 == 0))
        if k % 4 == 3:  # a loop edge in between: it lands after the keyframe edges before it
            ka.append(a.add_edge(0, k, z, np.eye(3), loop=True))
            kb.append(b.add_edge(0, k, z, np.eye(3), loop=True))
    assert ka == kb == list(range(len(a.edges)))
    assert len(b._pending) == 3  # (the keyframe edges after the last loop edge are still unbuilt)
    for ea, eb in zip(a.edges, b.edges, strict=True):
        assert (ea.i, ea.j, ea.loop, ea.robust, ea.active) == (eb.i, eb.j, eb.loop, eb.robust, eb.active)
        assert ea.z.tobytes() == eb.z.tobytes() and ea.info.tobytes() == eb.info.tobytes()
    for _ in range(2000):
        p, q, e = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3, 3)
        p[2], q[2], e[2] = rng.uniform(-7, 7, 3)
        z, x = _chain(p, q, e)
        assert np.array(z).tobytes() == relative(p, q).tobytes()
        assert np.array(x).tobytes() == compose(e, relative(p, q)).tobytes()


def test_keyframe_index_spread_equals_linspace_and_is_shared() -> None:
    """correlative.even_indices: evenly spread sub-sample indices (place returns, loop queries), once per size."""
    from dynslam2d.slam.correlative import even_indices as _even

    for n, k in ((121, 120), (600, 120), (1081, 360), (361, 360), (5000, 360)):
        idx = _even(n, k)
        assert np.array_equal(idx, np.linspace(0, n - 1, k).astype(np.int64)) and idx.dtype == np.int64
        assert idx[0] == 0 and idx[-1] == n - 1 and not idx.flags.writeable
        assert _even(n, k) is idx


def test_loop_closer_given_the_kept_scan_builds_the_same_keyframes() -> None:
    """LoopCloser.add with the caller's kept scan (the pipeline's, built for the map update) stores the same
    place returns, searches and loop candidates as when it builds the kept scan itself."""
    from dynslam2d.slam.loops import LoopCloser

    a, b = LoopCloser(), LoopCloser()
    rng = np.random.default_rng(4)
    for i in range(130):  # a loop around the room: keyframes, submaps and searches
        th = 2 * math.pi * i / 60
        pose = Pose2D(1.5 * math.cos(th), 1.5 * math.sin(th), th + 1.0)
        scan = scan_at(pose, 0.1 * i)
        removed = rng.random(scan.n_beams) < 0.05
        kept = scan.without(removed)
        a.add(scan.stamp, pose, scan, removed, i % 2 == 0, score=0.8)
        b.add(scan.stamp, pose, scan, removed, i % 2 == 0, score=0.8, kept=kept)
    assert len(a.keyframes) == len(b.keyframes) == 65
    assert a._place_pts.keys() == b._place_pts.keys()
    assert all(np.array_equal(a._place_returns(k), b._place_returns(k)) for k in a._place_pts)
    assert a.stats["searches"] == b.stats["searches"] > 0
    assert [(c.node, c.anchor, c.z.tobytes()) for c in a.candidates] == \
        [(c.node, c.anchor, c.z.tobytes()) for c in b.candidates]


def test_loop_closer_place_returns_are_those_of_the_keyframe_when_beams_are_dropped_later() -> None:
    """The place returns are computed only when a descriptor first needs them, but from the beams removed when the
    keyframe was added: beams the erasure marks removed afterwards (LoopCloser.drop_beams, which the re-rendered map
    and later submaps leave out) do not change them. Two closers fed the same keyframes, one of them told after
    each keyframe that half of its beams were erased: the same place returns and descriptors; the returns without
    the dropped beams differ from them."""
    from dynslam2d.slam.loops import LoopCloser

    a, b = LoopCloser(), LoopCloser()
    rng = np.random.default_rng(7)
    for i in range(50):
        th = 2 * math.pi * i / 60
        pose = Pose2D(1.5 * math.cos(th), 1.5 * math.sin(th), th + 1.0)
        scan = scan_at(pose, 0.1 * i)
        removed = rng.random(scan.n_beams) < 0.05
        for lc in (a, b):
            lc.add(scan.stamp, pose, scan, removed, True, score=0.8)
        b.drop_beams([(b.next_index - 1, np.arange(0, scan.n_beams, 2))])
    assert all(isinstance(v, tuple) for v in b._place_pts.values())  # nothing described yet: nothing computed
    k = max(b._place_pts)
    kf = b.keyframes[k]
    later = b._scan_points(kf.kept())[0]  # the keyframe's returns with the dropped beams left out
    assert later.shape[0] < 0.6 * a._scan_points(a.keyframes[k].kept())[0].shape[0]
    for node in sorted(a._place_pts):
        assert np.array_equal(a._place_returns(node), b._place_returns(node))
    a._place_flush()
    b._place_flush()
    assert len(a._places) == len(b._places) > 10
    for name in ("_cols", "_occ", "_count"):
        assert np.array_equal(getattr(a._places, name)[:len(a._places)], getattr(b._places, name)[:len(b._places)])
    # the returns of the beams kept after the drop are another point set (the test would see a lazy closer that
    # read the keyframe's current removed beams)
    from dynslam2d.slam.correlative import even_indices
    dropped = later[even_indices(later.shape[0], 120)] if later.shape[0] > 120 else later
    assert dropped.shape != a._place_returns(k).shape or not np.array_equal(dropped, a._place_returns(k))


def test_body_filter_skipping_empty_restarts_and_moved_beams_finds_the_same_body() -> None:
    """BodyFilter.observe skips the restart assignments when no beam restarts and tests the net motion only on
    beams not yet marked moved: its state after every scan equals the full-mask computation's, with beams that
    restart (a near object that comes and goes) and beams that become body beams; BodyFilter.mask, which keeps
    the drop ranges' limits until they change, drops what the drop ranges of that moment say."""
    from dynslam2d.config import Config
    from dynslam2d.detect.body import BodyFilter
    from dynslam2d.types import wrap_angle

    cfg = Config().detect.footprint
    body = BodyFilter(cfg)
    n = 360
    ref = {"ref": np.full(n, np.nan), "start": np.zeros((n, 3)), "same": np.zeros(n, np.int64),
           "seen": np.zeros(n, np.int64), "moved": np.zeros(n, bool)}
    rng = np.random.default_rng(5)
    restarts = drops = 0
    for i in range(160):
        pose = Pose2D(0.02 * i, 0.01 * i, 0.03 * i)
        r = rng.uniform(2.0, 6.0, n)
        r[100:106] = 0.3 + rng.normal(0.0, 0.005, 6)  # fixed in the laser frame: body beams
        r[150:160] = rng.choice([0.25, 0.4, 3.0], 10)  # near, jumping: restarts
        if i >= 90:
            r[200:203] = 0.45  # a second body part from scan 90 on: the drop ranges change after first use
        s = Scan(stamp=0.1 * i, angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=r, range_min=0.05,
                 range_max=20.0)
        want_drop = np.zeros(n, dtype=bool)
        if body.body.any():  # the mask from the drop ranges as they stand (kept limits must follow them)
            want_drop = s.valid_mask() & (body._drop_r > 0.0) & (r <= body._drop_r + cfg.auto_tolerance)
        drops += int(want_drop.sum())
        assert np.array_equal(body.mask(s), want_drop)
        body.observe(s, pose)
        # the full-mask computation (before this change)
        valid = s.valid_mask()
        near = valid & (r <= cfg.auto_max_range)
        same = near & (np.abs(r - ref["ref"]) <= cfg.auto_tolerance)
        ref["seen"] += valid
        ref["same"] += same
        restart = near & ~same & (ref["same"] < 0.5 * ref["seen"])
        restarts += int(restart.sum())
        ref["ref"][restart] = r[restart]
        ref["same"][restart] = 1
        ref["seen"][restart] = 1
        ref["start"][restart] = (pose.x, pose.y, pose.theta)
        ref["moved"][restart] = False
        idx = np.flatnonzero(same)
        st = ref["start"][idx]
        mv = np.hypot(pose.x - st[:, 0], pose.y - st[:, 1]) >= cfg.auto_min_travel
        tn = np.abs(wrap_angle(pose.theta - st[:, 2])) >= cfg.auto_min_turn
        ref["moved"][idx[mv & tn]] = True
        want = ref["moved"] & (ref["same"] >= cfg.auto_min_scans) & (ref["same"] >= cfg.auto_share * ref["seen"])
        assert np.array_equal(body.body, want) and np.array_equal(body._moved, ref["moved"])
        assert np.array_equal(body._ref, ref["ref"], equal_nan=True) and np.array_equal(body._start, ref["start"])
        assert np.array_equal(body._same, ref["same"]) and np.array_equal(body._seen, ref["seen"])
    assert restarts > 20 and drops > 100 and body.body[100:106].all() and body.body[200:203].all()


def test_scan_points_kernel_equals_the_masked_array_computation() -> None:
    """HectorSlam.scan_points' one kernel pass gives the gated returns and, with clear_no_return_dist, the
    clearing-ray ends of the masked array expressions it replaced (NaN, ±inf, beyond range_max, too close,
    beyond laser_max_dist, on the gates exactly), bit for bit and in beam order; so does the loop closer's
    keyframe points (LoopCloser._scan_points)."""
    n = 400
    rng = np.random.default_rng(11)
    r = rng.uniform(0.0, 35.0, n)
    r[::13] = np.nan
    r[5::17] = np.inf
    r[7::19] = -np.inf
    r[9::23] = 0.4  # laser_min_dist (excluded)
    r[11::29] = 25.0  # laser_max_dist: a "no return" for the clearing rays
    s = Scan(stamp=0.0, angle_min=-2.0, angle_increment=4.0 / n, ranges=r, range_min=0.1, range_max=30.0)
    for clear_dist in (0.0, 3.0):
        c = SlamConfig(laser_min_dist=0.4, laser_max_dist=25.0, clear_no_return_dist=clear_dist)
        pts, clear = HectorSlam(c).scan_points(s)
        cos_a, sin_a = s.trig()
        with np.errstate(invalid="ignore"):
            valid = s.valid_mask() & (r > c.laser_min_dist) & (r < c.laser_max_dist)
            noret = ~np.isfinite(r) | (r > s.range_max) | (r >= c.laser_max_dist)
        np.testing.assert_array_equal(pts, np.column_stack((r[valid] * cos_a[valid], r[valid] * sin_a[valid])))
        want = (np.column_stack((clear_dist * cos_a[noret], clear_dist * sin_a[noret])) if clear_dist > 0.0
                else np.zeros((0, 2)))
        np.testing.assert_array_equal(clear, want)
        assert pts.shape[0] > 100 and (clear_dist == 0.0 or clear.shape[0] > 50)
    # the loop closer's keyframe points: the same kernel without clearing rays, cut at submap_max_range
    from dynslam2d.slam.loopconfig import LoopConfig
    from dynslam2d.slam.loops import LoopCloser

    c = SlamConfig(laser_min_dist=0.4, laser_max_dist=25.0)
    closer = LoopCloser(LoopConfig(submap_max_range=12.0), c)
    pts, clear = closer._scan_points(s)
    with np.errstate(invalid="ignore"):
        valid = s.valid_mask() & (r > 0.4) & (r < 12.0)
    np.testing.assert_array_equal(pts, s.points(valid))
    assert clear.shape == (0, 2) and pts.shape[0] > 50
