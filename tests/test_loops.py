"""Loop closure (slam/loops.py) and the pose graph (slam/posegraph.py) on simulated scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.world import World, cast_rays, polyline_segments, rect_segments
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.loops import LoopCandidate, LoopCloser
from dynslam2d.slam.posegraph import PoseGraph, compose, diag_info, relative
from dynslam2d.types import Pose2D

LIDAR = LidarModel(beams=360, fov=2 * math.pi, rate_hz=10.0, range_min=0.1, range_max=20.0, noise_sigma=0.01)


def _block_loop_world() -> World:
    """A 2.4 m wide corridor around a 24 × 14 m block, with pillars, recesses and boxes that make
    every stretch look different."""
    outer = polyline_segments([(0, 0), (30, 0), (30, 20), (0, 20)], closed=True)
    inner = polyline_segments([(3, 3), (27, 3), (27, 17), (3, 17)], closed=True)
    feats = [rect_segments(x, y, 0.0, 0.4, 0.4) for x, y in ((6, 0.5), (13, 0.6), (22, 0.4), (29.4, 7),
                                                              (29.5, 14), (18, 19.5), (8, 19.4), (0.6, 12))]
    feats += [rect_segments(x, y, 0.5, 0.8, 0.3) for x, y in ((10, 2.6), (25, 2.7), (27.3, 10), (15, 17.3), (2.7, 6))]
    return World(np.vstack([outer, inner] + feats))


def _loop_path(step: float = 0.2, laps: float = 1.35) -> np.ndarray:
    """(n, 3) laser poses along the corridor's centre line, counter-clockwise, ``laps`` laps; at each
    corner the robot turns on the spot in 0.1 rad steps."""
    corners = np.array([(1.5, 1.5), (28.5, 1.5), (28.5, 18.5), (1.5, 18.5)])
    segs = [(corners[k], corners[(k + 1) % 4]) for k in range(4)]
    lap = sum(float(np.linalg.norm(b - a)) for a, b in segs)
    out = []
    s = 0.0
    prev = None
    while s < laps * lap:
        r = s % lap
        for a, b in segs:
            seg = float(np.linalg.norm(b - a))
            if r <= seg:
                d = (b - a) / seg
                heading = math.atan2(d[1], d[0])
                if prev is not None:
                    turn = math.remainder(heading - prev[2], 2 * math.pi)
                    for k in range(1, int(abs(turn) / 0.1) + 1):
                        out.append((prev[0], prev[1], prev[2] + math.copysign(0.1 * k, turn)))
                pos = a + d * r
                out.append((pos[0], pos[1], heading))
                prev = out[-1]
                break
            r -= seg
        s += step
    return np.array(out)


def _scans(world: World, poses: np.ndarray, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    scans = []
    for k, p in enumerate(poses):
        true, _ = cast_rays(p[:2], LIDAR.angles + p[2], world.segments, max_dist=LIDAR.range_max)
        r, _ = LIDAR.measure(true, rng)
        scans.append(LIDAR.make_scan(0.1 * k, r))
    return scans


def _drifted(gt: np.ndarray, rad_per_m: float) -> np.ndarray:
    """A front end that turns ``rad_per_m`` too much per metre: its poses drift away from ``gt``."""
    rel = relative(gt[:-1], gt[1:])
    rel[:, 2] += rad_per_m * np.hypot(rel[:, 0], rel[:, 1])
    out = [gt[0]]
    for z in rel:
        out.append(compose(out[-1], z))
    return np.array(out)


def _close(world: World, gt: np.ndarray, front: np.ndarray, config: LoopConfig | None = None) -> tuple:
    scans = _scans(world, gt)
    lc = LoopCloser(config or LoopConfig(), SlamConfig())
    for k, (s, p) in enumerate(zip(scans, front)):
        lc.add(s.stamp, Pose2D(*p), s, np.zeros(s.ranges.shape, bool), keyframe=k % 2 == 0)
    return lc, lc.finish()


@pytest.fixture(scope="module")
def block_loop() -> tuple:
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.0015)
    lc, res = _close(world, gt, front)
    return gt, front, lc, res


def test_loop_closure_pulls_the_drift_back(block_loop: tuple) -> None:
    gt, front, _lc, res = block_loop
    err_front = np.hypot(*(front[:, :2] - gt[:, :2]).T)
    err_opt = np.hypot(*(res.poses[:, :2] - gt[:, :2]).T)
    assert err_front.max() > 1.0  # the front end ends more than a metre off
    assert res.corrected and len(res.loops) >= 5
    assert err_opt.max() < 0.3 and err_opt.max() < err_front.max() / 8  # 2.6 m → 0.22 m
    # every accepted loop agrees with the ground truth: the keyframe seen from the anchor
    kf = res.keyframe_scans
    for i, j in res.loops:
        e = next(e for e in res.graph.edges if e.loop and e.active and (e.i, e.j) == (i, j))
        true = relative(gt[kf[i]], gt[kf[j]])
        assert math.hypot(*(e.z[:2] - true[:2])) < 0.1 and abs(e.z[2] - true[2]) < 0.02


def test_no_loop_closure_without_revisit() -> None:
    world = _block_loop_world()
    gt = _loop_path(laps=0.6)
    lc, res = _close(world, gt, _drifted(gt, 0.0015))
    assert not res.corrected and res.loops == []
    assert np.array_equal(res.poses, res.frontend)


def test_ambiguous_corridor_gives_no_loop() -> None:
    """Down and back a featureless corridor: every match along its axis scores the same, so the
    runner-up margin refuses them all."""
    # 200 m long: from the stretch driven (70 … 130 m) the end walls are beyond the 20 m range
    world = World(np.vstack([polyline_segments([(0, 0), (200, 0), (200, 2.4), (0, 2.4)], closed=True)]))
    out = [(70.0 + 0.2 * k, 1.2, 0.0) for k in range(300)] + [(130.0 - 0.2 * k, 1.2, math.pi) for k in range(300)]
    gt = np.array(out)
    lc, res = _close(world, gt, _drifted(gt, 0.0), LoopConfig(min_path_gap=4.0))
    assert lc.stats["searches"] > 20  # it did look
    assert res.loops == []


def test_pose_graph_matches_scipy_least_squares() -> None:
    from scipy.optimize import least_squares

    rng = np.random.default_rng(3)
    th = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    gt = np.stack([5 * np.cos(th), 5 * np.sin(th), th + np.pi / 2], 1)
    odo = relative(gt[:-1], gt[1:]) + rng.normal(0, [0.03, 0.03, 0.01], (59, 3))
    g = PoseGraph()
    p = [gt[0]]
    for z in odo:
        p.append(compose(p[-1], z))
    for q in p:
        g.add_node(q)
    for k, z in enumerate(odo):
        g.add_edge(k, k + 1, z, diag_info(0.03, 0.01))
    g.add_edge(0, 59, relative(gt[0], gt[59]), diag_info(0.02, 0.005), loop=True)
    g.add_edge(10, 50, relative(gt[10], gt[50]), diag_info(0.02, 0.005), loop=True)
    p0 = g.poses.copy()
    g.optimise(kernel="none", outlier_chi2=None)

    def res(x: np.ndarray) -> np.ndarray:
        P = np.vstack([p0[:1], x.reshape(-1, 3)])
        return np.concatenate([np.linalg.cholesky(e.info).T @ relative(e.z, relative(P[e.i], P[e.j]))
                               for e in g.edges])

    ref = np.vstack([p0[:1], least_squares(res, p0[1:].ravel()).x.reshape(-1, 3)])
    d = ref - g.poses
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    assert np.abs(d).max() < 1e-5
    assert np.abs(g.poses[:, :2] - gt[:, :2]).max() < np.abs(p0[:, :2] - gt[:, :2]).max() / 2


@pytest.mark.parametrize("kernel", ["dcs", "cauchy"])
def test_robust_kernel_shrugs_off_injected_false_loops(block_loop: tuple, kernel: str) -> None:
    """A tenth of the accepted loops replaced by wrong ones (1–3 m, 0.3 rad off): the optimised
    trajectory stays within 5 mm of the one with those loops simply left out; without a kernel it
    does not."""
    gt, front, lc, res = block_loop
    good = [e for e in res.graph.edges if e.loop and e.active]
    rng = np.random.default_rng(7)
    bad = set(rng.choice(len(good), size=max(1, len(good) // 10), replace=False).tolist())

    def optimised(kernel_name: str, outlier: float | None, wrong: bool) -> np.ndarray:
        g = PoseGraph()
        for p in front[res.keyframe_scans]:
            g.add_node(p)
        for e in res.graph.edges:
            if not e.loop:
                g.add_edge(e.i, e.j, e.z, e.info)
        r = np.random.default_rng(11)
        for k, e in enumerate(good):
            if k in bad:
                if not wrong:
                    continue
                z = e.z + np.array([r.uniform(1, 3) * r.choice([-1, 1]), r.uniform(1, 3), 0.3])
            else:
                z = e.z
            g.add_edge(e.i, e.j, z, e.info, loop=True)
        g.optimise(kernel_name, lc.config.kernel_scale if kernel_name == "dcs" else 1.0, 50, outlier)
        return g.poses

    reference = optimised(lc.config.kernel, lc.config.outlier_chi2, wrong=False)
    robust = optimised(kernel, lc.config.outlier_chi2, wrong=True)
    plain = optimised("none", None, wrong=True)
    d_robust = np.hypot(*(robust[:, :2] - reference[:, :2]).T).max()
    d_plain = np.hypot(*(plain[:, :2] - reference[:, :2]).T).max()
    assert d_robust < 0.005
    assert d_plain > 0.05


def test_map_check_keeps_optimised_poses_only_when_the_map_gets_sharper(block_loop: tuple) -> None:
    """The front end drifted 2.6 m: its map holds the start area twice, the optimised one once —
    lower total entropy, so the optimised poses are kept; the other way round they are refused."""
    from dynslam2d.pipeline import keep_optimised, map_entropy, render_map

    _gt, _front, _lc, res = block_loop
    saved = res.node_poses
    try:
        res.node_poses = res.frontend[res.keyframe_scans]
        _, lo_front = render_map(res, SlamConfig())
    finally:
        res.node_poses = saved
    _, lo_opt = render_map(res, SlamConfig())
    assert map_entropy(lo_opt) < 0.97 * map_entropy(lo_front)
    assert not keep_optimised(res, lo_opt, lo_front, LoopConfig())
    # a correction smaller than min_correction is not applied (here the largest one is 2.6 m)
    assert not keep_optimised(res, lo_front, lo_opt, LoopConfig(min_correction=5.0))
    assert res.stats["max_keyframe_correction_m"] > 1.0
    assert keep_optimised(res, lo_front, lo_opt, LoopConfig()) and res.corrected
    assert res.stats["map_entropy_optimised"] < res.stats["map_entropy_frontend"]


def test_re_rendered_map_leaves_out_beams_erased_after_the_fact() -> None:
    """A box stands in the corridor while the robot passes it the first time and is gone on the second
    lap; retroactive erasure hands the box's beams to the loop closer (``drop_beams``) once it has left.
    Loop closure keeps the optimised poses and re-renders the map from the keyframes: the box is not in
    it, while the same run without the dropped beams keeps it."""
    from dynslam2d.pipeline import render_map

    world = _block_loop_world()
    box = rect_segments(12.0, 1.0, 0.0, 0.8, 0.6)  # in the lower corridor, 0.5 m beside the path
    gt = _loop_path()
    front = _drifted(gt, 0.0015)
    rng = np.random.default_rng(0)
    scans, box_beams = [], []
    for k, p in enumerate(gt):
        there = k < len(gt) // 2
        segs = np.vstack([world.segments, box]) if there else world.segments
        true, _ = cast_rays(p[:2], LIDAR.angles + p[2], segs, max_dist=LIDAR.range_max)
        r, _ = LIDAR.measure(true, rng)
        scans.append(LIDAR.make_scan(0.1 * k, r))
        if there:
            only, _ = cast_rays(p[:2], LIDAR.angles + p[2], box, max_dist=LIDAR.range_max)
            box_beams.append((k, np.flatnonzero(np.isfinite(only) & (only == true))))

    def closed(drop: bool):
        lc = LoopCloser(LoopConfig(), SlamConfig())
        given = []
        for k, (s, p) in enumerate(zip(scans, front)):
            given.append(np.zeros(s.ranges.shape, bool))
            lc.add(s.stamp, Pose2D(*p), s, given[-1], keyframe=k % 2 == 0)
            if drop and k == len(gt) // 2:  # the box has gone: its evidence is erased
                assert lc.drop_beams(box_beams) > 100
        assert not any(g.any() for g in given)  # the caller's arrays (the pipeline's step results) stay as given
        return lc.finish()

    def box_cells(res) -> int:
        grid, _ = render_map(res, SlamConfig())
        xs = grid.origin[0] + (np.arange(grid.shape[1]) + 0.5) * grid.resolution
        ys = grid.origin[1] + (np.arange(grid.shape[0]) + 0.5) * grid.resolution
        X, Y = np.meshgrid(xs, ys)
        inside = (np.abs(X - 12.0) < 0.5) & (np.abs(Y - 1.0) < 0.4)
        return int((np.nan_to_num(grid.prob, nan=0.0)[inside] > 0.65).sum())

    res = closed(True)
    assert res.corrected  # the optimised poses are what gets rendered
    assert box_cells(res) == 0
    assert box_cells(closed(False)) > 10


@pytest.fixture(scope="module")
def far_loop() -> tuple:
    """A front end whose heading drifts 0.006 rad/m: 10 m off at the end, about 4 m and 0.5 rad off when it
    comes back to the start, beyond the local search's capped radius and windows (6 m, 3 m, 0.8 rad around
    the drifted estimate)."""
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.006)
    return world, gt, front, _close(world, gt, front)


def _true_loops(res, gt: np.ndarray) -> None:
    kf = res.keyframe_scans
    for e in res.graph.edges:
        if e.loop:
            true = relative(gt[kf[e.i]], gt[kf[e.j]])
            assert math.hypot(*(e.z[:2] - true[:2])) < 0.1 and abs(e.z[2] - true[2]) < 0.02


def test_far_search_closes_a_loop_the_fixed_window_misses(far_loop: tuple) -> None:
    world, gt, front, (lc, res) = far_loop
    err_front = np.hypot(*(front[:, :2] - gt[:, :2]).T)
    assert err_front.max() > 8.0
    # the local search alone (the window around the drifted estimate) finds nothing
    _lc0, res0 = _close(world, gt, front, LoopConfig(far_search=False))
    assert res0.loops == [] and not res0.corrected
    # the far search (radius from the uncertainty summed along the graph, every rotation) finds the start
    assert lc.stats["far_loops"] >= 3 and res.corrected and len(res.loops) >= 10
    _true_loops(res, gt)
    err_opt = np.hypot(*(res.poses[:, :2] - gt[:, :2]).T)
    assert err_opt.max() < 1.2  # 10.0 m → 0.94 m


def test_far_search_refuses_look_alike_places() -> None:
    """Less drift (0.004 rad/m): the corridor after one corner of the block looks like the corridor after
    another, turned by 90°, and such matches pass score and margin; the correction they imply (11 m, 1.3 rad)
    exceeds what the uncertainty allows, so every accepted loop is a true one and the map gets better."""
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.004)
    lc, res = _close(world, gt, front)
    _lc0, res0 = _close(world, gt, front, LoopConfig(far_search=False))
    assert lc.stats["far_searches"] > 20 and lc.stats["far_loops"] >= 3
    _true_loops(res, gt)
    err = np.hypot(*(res.poses[:, :2] - gt[:, :2]).T).max()
    err0 = np.hypot(*(res0.poses[:, :2] - gt[:, :2]).T).max()
    assert err < 0.8 and err < err0 / 2  # 1.45 m (local search only) → 0.63 m


def test_far_candidate_is_verified_on_the_keyframes_before_it(far_loop: tuple) -> None:
    """A far candidate is accepted only if the preceding keyframes, matched around the pose it implies for
    them, agree with it: the true one passes, the same one moved by 1.5 m and 0.4 rad does not."""
    _world, _gt, _front, (lc, res) = far_loop
    far = next(c for c in lc.candidates if c.far) if any(c.far for c in lc.candidates) else None
    e = far if far is not None else next(e for e in res.graph.edges if e.loop)
    node, anchor = (e.node, e.anchor) if far is not None else (e.j, e.i)
    s = anchor // lc.config.submap_keyframes
    z = np.array(e.z, dtype=np.float64)
    n_edges = len(lc.graph.edges)
    wrong = LoopCandidate(node, anchor, compose(z, np.array([1.5, 0.0, 0.4])), 0.8, 0.3, 200)
    lc._verify_far(wrong, s)
    assert len(lc.graph.edges) == n_edges and not wrong.accepted
    right = LoopCandidate(node, anchor, z, 0.8, 0.3, 200)
    lc._verify_far(right, s)
    assert right.accepted and len(lc.graph.edges) >= n_edges + 1 + lc.config.far_partners


def test_rematch_repairs_a_local_break_no_loop_spans() -> None:
    """A keyframe the front end put 0.6 m along the corridor and back (a look-alike match, as on Intel's
    scans 2433→2435): the loops correct the drift but not that keyframe; the re-match against its optimised
    predecessors' map does."""
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.0015)
    k = 120  # a keyframe on the first straight, far from the start where the loops are; the scan after it
    # (no keyframe) was tracked from it
    front[k:k + 2] = compose(front[k:k + 2], np.array([0.6, 0.0, 0.0]))
    errs = {}
    for on in (False, True, "reuse"):
        # "reuse": the local map kept for the following keyframes (rematch_reuse), in the frame of the keyframe it
        # was built for: the edge must still be the keyframe seen from the one before it
        cfg = LoopConfig(rematch=bool(on), rematch_reuse=20 if on == "reuse" else 0)
        _lc, res = _close(world, gt, front, cfg)
        assert res.corrected
        err = np.hypot(*(res.poses[:, :2] - gt[:, :2]).T)
        assert np.delete(err, [k, k + 1]).max() < 0.3
        # the broken scans relative to the keyframe before them (the loops leave ~0.17 m of drift there)
        rel = relative(res.poses[k - 2], res.poses[k:k + 2]) - relative(gt[k - 2], gt[k:k + 2])
        errs[on] = float(np.hypot(rel[:, 0], rel[:, 1]).max())
        if on:
            assert res.stats["rematch_edges"] >= 1
    assert errs[False] > 0.5  # without the re-match the broken keyframe stays 0.6 m off its neighbours
    assert errs[True] < 0.03 and errs["reuse"] < 0.03


def test_rematch_only_near_low_scores() -> None:
    """With the front end's match scores given, only keyframes near a low-scoring match are re-matched: the
    break of the test above is repaired when its scan scored low, checking a handful of keyframes; with every
    score high no keyframe is matched (the break stays: the cost of the selection) — unless, as by default, the
    0.6 m step out and back is taken as a front-end jump (``loop.jump_weak``, slam/jumps.py): then the edges
    across it are weak and the keyframes there are re-matched too."""
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.0015)
    k = 120
    front[k:k + 2] = compose(front[k:k + 2], np.array([0.6, 0.0, 0.0]))
    scans = _scans(world, gt)
    out = {}
    for low, jump_weak in ((True, False), (False, False), ("jump", True)):
        lc = LoopCloser(LoopConfig(jump_weak=jump_weak), SlamConfig())
        for i, (s, p) in enumerate(zip(scans, front)):
            score = 0.3 if low is True and i in (k, k + 1) else 0.9
            lc.add(s.stamp, Pose2D(*p), s, np.zeros(s.ranges.shape, bool), keyframe=i % 2 == 0, score=score)
        res = lc.finish()
        assert res.corrected
        rel = relative(res.poses[k - 2], res.poses[k:k + 2]) - relative(gt[k - 2], gt[k:k + 2])
        out[low] = (float(np.hypot(rel[:, 0], rel[:, 1]).max()), res.stats["rematch_checked"],
                    res.stats["rematch_edges"], len(res.keyframe_scans))
    err, checked, edges, n_kf = out[True]
    assert err < 0.03 and edges >= 1
    assert 1 <= checked <= 8 < n_kf // 10  # keyframes 60, 61 marked (± 2), not the whole run
    assert out[False][1] == 0 and out[False][0] > 0.5
    err, checked, edges, _ = out["jump"]
    assert err < 0.03 and edges >= 1 and 1 <= checked <= 8


@pytest.mark.parametrize("n", [2, 3, 4, 7])
def test_rematch_selection_grows_marks_by_the_neighbours_on_short_chains(n):
    # a chain shorter than the 2·neighbours + 1 window (np.convolve "same" returned the window's length then)
    from types import SimpleNamespace

    from dynslam2d.slam.rematch import selected

    graph = PoseGraph()
    for k in range(n):
        graph.add_node(np.array([float(k), 0.0, 0.0]))
    scores = [1.0] * n
    scores[1] = 0.1  # keyframe 1's incoming match was poor: it and its neighbours are re-matched
    closer = SimpleNamespace(config=LoopConfig(rematch_neighbours=2), graph=graph, keyframes=[None] * n,
                             kf_score=scores, kf_weak=[False] * n)
    sel = selected(closer)
    assert sel.shape == (n,)
    assert sel.tolist() == [k <= 3 for k in range(n)]
