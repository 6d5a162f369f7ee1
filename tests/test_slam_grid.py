"""Log-odds grid levels: ray integration (Kohlbrecher et al. 2011, §IV-A), Bresenham, growth, export."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import scan_rays

from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.grid import GridLevel, MultiResMap, decode_probs, encode_probs
from dynslam2d.slam.raycast import bresenham_free_cells
from dynslam2d.types import Pose2D, Scan

L_FREE = math.log(0.4 / 0.6)
L_OCC = math.log(0.9 / 0.1)


def cell(level: GridLevel, i: int, j: int) -> float:
    """Log-odds of the cell with absolute index (i, j)."""
    return float(level.logodds[j - level.j0, i - level.i0])


def touched(level: GridLevel) -> set[tuple[int, int]]:
    rows, cols = np.nonzero(level.uidx > 0)
    return {(int(c) + level.i0, int(r) + level.j0) for r, c in zip(rows, cols)}


# --------------------------------------------------------------------------- Bresenham

@pytest.mark.parametrize(
    ("end", "expected"),
    [
        # hand-worked with the reference variant: error starts at |Δa|//2, endpoint excluded
        ((5, 2), [(0, 0), (1, 0), (2, 1), (3, 1), (4, 2)]),
        ((2, 5), [(0, 0), (0, 1), (1, 2), (1, 3), (2, 4)]),
        ((-4, -4), [(0, 0), (-1, -1), (-2, -2), (-3, -3)]),  # tie |Δx| = |Δy| → x major
        ((3, -1), [(0, 0), (1, 0), (2, -1)]),
        ((-5, 1), [(0, 0), (-1, 0), (-2, 0), (-3, 1), (-4, 1)]),
        ((0, -3), [(0, 0), (0, -1), (0, -2)]),
        ((1, 1), [(0, 0)]),
    ],
)
def test_bresenham_matches_reference_variant(end, expected) -> None:
    got = [tuple(int(v) for v in c) for c in bresenham_free_cells(0, 0, end[0], end[1])]
    assert got == expected


def test_bresenham_cells_hug_the_line() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        x0, y0, x1, y1 = (int(v) for v in rng.integers(-40, 40, 4))
        cells = bresenham_free_cells(x0, y0, x1, y1)
        n = max(abs(x1 - x0), abs(y1 - y0))
        assert len(cells) == n
        if n == 0:
            continue
        # consecutive cells are 8-neighbours, the last one is an 8-neighbour of the endpoint
        path = np.vstack((cells, [[x1, y1]]))
        assert np.all(np.abs(np.diff(path, axis=0)).max(axis=1) == 1)
        # every cell is within half a cell of the ideal line (minor-axis distance)
        d = np.array([x1 - x0, y1 - y0], dtype=float)
        rel = cells - [x0, y0]
        if abs(d[0]) >= abs(d[1]):
            dev = rel[:, 1] - rel[:, 0] * d[1] / d[0]
        else:
            dev = rel[:, 0] - rel[:, 1] * d[0] / d[1]
        assert np.all(np.abs(dev) <= 0.5 + 1e-9)


# --------------------------------------------------------------------------- integration

def _level_1m() -> GridLevel:
    lv = GridLevel(1.0, growth_margin_cells=2)
    lv.ensure(-10, -10, 10, 10)
    return lv


def test_ray_integration_hand_worked_example() -> None:
    lv = _level_1m()
    ends = np.array([[5.0, 0.0], [3.0, 0.0], [5.0, 2.0]])
    n = lv.integrate(np.zeros(2), ends, np.ones(3, bool), L_FREE, L_OCC, 50.0)
    assert n == 3
    free = {(0, 0), (1, 0), (2, 0), (4, 0), (2, 1), (3, 1), (4, 2)}
    occ = {(3, 0), (5, 0), (5, 2)}
    assert touched(lv) == free | occ
    for c in free:  # crossed by up to three rays, but one free update per scan
        assert cell(lv, *c) == pytest.approx(L_FREE, abs=1e-6)
    for c in occ:  # (3, 0) was crossed (free) by the ray to (5, 0): the free update is undone
        assert cell(lv, *c) == pytest.approx(L_OCC, abs=1e-6)
    # probability cache follows the log-odds
    j, i = 0 - lv.j0, 5 - lv.i0
    assert decode_probs(lv.prob)[j, i] == pytest.approx(0.9, abs=1e-6)
    assert decode_probs(lv.prob)[0 - lv.j0, 1 - lv.i0] == pytest.approx(0.4, abs=1e-6)

    # a second scan adds exactly one more observation per cell
    lv.integrate(np.zeros(2), ends[::-1].copy(), np.ones(3, bool), L_FREE, L_OCC, 50.0)
    assert cell(lv, 1, 0) == pytest.approx(2 * L_FREE, abs=1e-5)
    assert cell(lv, 3, 0) == pytest.approx(2 * L_OCC, abs=1e-5)


def test_integration_is_order_independent_and_occupied_wins() -> None:
    rng = np.random.default_rng(0)
    ends = rng.uniform(-8, 8, (60, 2))
    a, b = _level_1m(), _level_1m()
    a.integrate(np.array([0.3, -0.2]), ends, np.ones(60, bool), L_FREE, L_OCC, 50.0)
    perm = rng.permutation(60)
    b.integrate(np.array([0.3, -0.2]), ends[perm], np.ones(60, bool), L_FREE, L_OCC, 50.0)
    np.testing.assert_array_equal(a.logodds, b.logodds)
    # set semantics: every endpoint cell has +l_occ, every other traversed cell +l_free
    end_cells = {tuple(c) for c in np.floor(ends + 0.5).astype(int)}
    for c in touched(a):
        expect = L_OCC if c in end_cells else L_FREE
        assert cell(a, *c) == pytest.approx(expect, abs=1e-6)


def test_clearing_rays_mark_free_including_endpoint() -> None:
    lv = _level_1m()
    lv.integrate(np.zeros(2), np.array([[0.0, 4.0]]), np.zeros(1, bool), L_FREE, L_OCC, 50.0)
    assert touched(lv) == {(0, 0), (0, 1), (0, 2), (0, 3), (0, 4)}
    assert cell(lv, 0, 4) == pytest.approx(L_FREE, abs=1e-6)


def test_occupied_cap() -> None:
    lv = _level_1m()
    for _ in range(30):
        lv.integrate(np.zeros(2), np.array([[3.0, 0.0]]), np.ones(1, bool), L_FREE, L_OCC, 5.0)
    # hits are added while l < 5: 0, 2.2, 4.4 → 6.6, then no more
    assert cell(lv, 3, 0) == pytest.approx(3 * L_OCC, abs=1e-5)
    assert cell(lv, 1, 0) == pytest.approx(30 * L_FREE, abs=1e-4)  # free side unbounded


def _reference_rays(lv: GridLevel, sx: int, sy: int, ex, ey, hit, stop, free_idx: int, occ_idx: int,
                    cap: float) -> None:
    """The reference's update (OccGridMapBase::updateByScan) written plainly, cell by cell, on the Bresenham cells
    of :func:`bresenham_free_cells`: a free update at most once per cell per scan, occupied winning and undoing
    this scan's free update, the cap on the occupied side, the probability cache from the float64 log-odds,
    the last ``stop`` cells of a ray without free update."""
    h, w = lv.shape

    def free(x, y):
        if lv.uidx[y, x] < free_idx:
            v = float(lv.logodds[y, x]) + L_FREE
            lv.logodds[y, x] = v
            lv.prob[y, x] = encode_probs(1.0 / (1.0 + math.exp(-v)))
            lv.uidx[y, x] = free_idx

    for k in range(len(ex)):
        x1, y1 = int(ex[k]), int(ey[k])
        if (x1, y1) == (sx, sy) or not (0 <= x1 < w and 0 <= y1 < h):
            continue
        cells = bresenham_free_cells(sx, sy, x1, y1)
        major = max(abs(x1 - sx), abs(y1 - sy))
        skip = 0
        if stop is not None and stop[k] > 1.0:
            skip = min(int((stop[k] - 1.0) * major / math.hypot(x1 - sx, y1 - sy)), major - 1)
        for x, y in cells[: major - skip].tolist():
            free(x, y)
        if hit[k]:
            u = lv.uidx[y1, x1]
            if u < occ_idx:
                v = float(lv.logodds[y1, x1])
                if u == free_idx:
                    v -= L_FREE
                if v < cap:
                    v += L_OCC
                lv.logodds[y1, x1] = v
                lv.prob[y1, x1] = encode_probs(1.0 / (1.0 + math.exp(-v)))
                lv.uidx[y1, x1] = occ_idx
        else:
            free(x1, y1)


@pytest.mark.parametrize("with_stop", [False, True])
def test_ray_kernels_equal_the_plain_reference_update(with_stop: bool) -> None:
    """GridLevel.integrate and MultiResMap.integrate (the flat-index walk of slam/raycast.py) write every level
    bit for bit as the plain cell-by-cell reference update: repeated scans (free-then-occupied in one scan, the
    cap reached), clearing rays, with and without the grazing stop, on maps of 1, 3 (one kernel call) and 4 levels."""
    rng = np.random.default_rng(11)
    for n_levels in (1, 3, 4):
        hmap = MultiResMap(0.1, n_levels, L_FREE, L_OCC, cap=6.0, grazing_cells=1.5 if with_stop else 0.0)
        for lv in hmap.levels:  # (large enough for every scan below: no growth)
            m = int(6.0 / lv.resolution) + 2
            lv.ensure(-m, -m, m, m)
        ref = [GridLevel(lv.resolution) for lv in hmap.levels]
        for scan in range(8):
            pose = Pose2D(*rng.uniform(-0.5, 0.5, 2), float(rng.uniform(-3, 3)))
            a = np.linspace(-2.5, 2.5, 250)
            rr = rng.choice([1.5, 2.0, 3.0], a.shape[0]) + rng.normal(0.0, 0.02, a.shape[0])
            hits = np.column_stack((rr * np.cos(a), rr * np.sin(a)))
            clear = hits[::9] * 1.4 if scan % 2 else None
            before = [(lv.i0, lv.j0, lv.logodds.copy(), lv.prob.copy(), lv.uidx.copy(), lv.update_counter)
                      for lv in hmap.levels]
            hmap.integrate(pose, hits, clear)
            ends, hit, stop = scan_rays(pose, hits, clear, hmap.grazing_cells, hmap.min_sin)
            for lv, rl, (i0, j0, lo, pr, ui, cnt) in zip(hmap.levels, ref, before):
                assert (lv.i0, lv.j0) == (i0, j0)  # (the map does not grow: the reference reads the same cells)
                rl.logodds, rl.prob, rl.uidx, rl.i0, rl.j0 = lo, pr, ui, i0, j0
                r = lv.resolution
                cells = np.floor(ends / r + 0.5).astype(np.int64)
                _reference_rays(rl, int(math.floor(pose.x / r + 0.5)) - i0, int(math.floor(pose.y / r + 0.5)) - j0,
                                cells[:, 0] - i0, cells[:, 1] - j0, hit, stop, cnt + 1, cnt + 2, hmap.cap)
                assert np.array_equal(lv.logodds, rl.logodds) and np.array_equal(lv.prob, rl.prob)
                assert np.array_equal(lv.uidx, rl.uidx)
        assert hmap.levels[0].logodds.max() > 6.0  # the cap was reached
        assert (hmap.levels[0].logodds < 0).sum() > 100


# --------------------------------------------------------------------------- growth

def test_growth_keeps_content_in_every_direction() -> None:
    lv = GridLevel(0.1, growth_margin_cells=3)
    lv.integrate(np.zeros(2), np.array([[1.0, 0.3], [-0.4, 0.8], [0.2, -0.9]]), np.ones(3, bool),
                 L_FREE, L_OCC, 50.0)
    before = {c: cell(lv, *c) for c in touched(lv)}
    shape0 = lv.shape
    # scans far out in +x, −x, +y, −y (rays start there, so they do not cross the first scan)
    for origin in ([30.0, 0.0], [-30.0, 0.0], [0.0, 25.0], [0.0, -25.0], [20.0, 20.0]):
        o = np.array(origin)
        lv.integrate(o, o + np.array([[0.5, 0.5]]), np.ones(1, bool), L_FREE, L_OCC, 50.0)
    assert lv.n_grows >= 5
    assert lv.shape[0] > shape0[0] + 400 and lv.shape[1] > shape0[1] + 500
    for c, v in before.items():
        assert cell(lv, *c) == v
    assert cell(lv, 305, 5) == pytest.approx(L_OCC, abs=1e-6)  # endpoint of the +x scan
    assert cell(lv, -295, 5) == pytest.approx(L_OCC, abs=1e-6)


def test_ensure_is_noop_inside_and_world_coords_are_stable() -> None:
    lv = GridLevel(0.05, growth_margin_cells=4)
    assert lv.ensure(0, 0, 10, 10)
    assert not lv.ensure(2, 3, 9, 9)
    m_before = lv.world_to_map(np.array([[0.25, -0.1]]))
    w_before = lv.map_to_world(m_before)
    lv.ensure(-100, -100, 0, 0)
    np.testing.assert_allclose(lv.map_to_world(lv.world_to_map(np.array([[0.25, -0.1]]))), w_before)
    # world origin is the centre of absolute cell (0, 0): integer map coordinate after the shift
    m0 = lv.world_to_map(np.zeros((1, 2)))[0]
    np.testing.assert_allclose(m0, [-lv.i0, -lv.j0])


# --------------------------------------------------------------------------- levels / export

def _scan(ranges: np.ndarray, stamp: float = 0.0) -> Scan:
    n = ranges.shape[0]
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=ranges,
                range_min=0.05, range_max=20.0)


def test_levels_are_updated_from_the_scan_not_downsampled() -> None:
    m = MultiResMap(0.05, 3, L_FREE, L_OCC)
    m.integrate(Pose2D(), np.array([[2.0, 0.0], [0.0, 1.5]]))
    for k, lv in enumerate(m.levels):
        assert lv.resolution == pytest.approx(0.05 * 2**k)
        i = int(math.floor(2.0 / lv.resolution + 0.5))
        assert cell(lv, i, 0) == pytest.approx(L_OCC, abs=1e-6)
        assert cell(lv, i - 1, 0) == pytest.approx(L_FREE, abs=1e-6)
    # a coarse cell holds one observation, not the sum/average of its fine cells
    assert cell(m.levels[2], 5, 0) == pytest.approx(L_FREE, abs=1e-6)


def test_gridmap_export_nan_unknown_and_origin() -> None:
    slam = HectorSlam(SlamConfig(map_resolution=0.1, map_levels=2))
    ranges = np.full(90, 2.0)
    ranges[::2] = np.inf  # no return: never traced
    slam.process(_scan(ranges))
    gm = slam.gridmap()
    lo, origin = slam.logodds()
    assert gm.prob.shape == lo.shape
    assert gm.origin == origin
    assert np.isnan(gm.prob).any() and np.isfinite(gm.prob).any()
    # the laser sits at world (0, 0): its cell is free; a point 2 m ahead (+x) is occupied
    c, r = gm.world_to_cell(np.array([[0.0, 0.0], [2.0, 0.0]])).T
    assert gm.prob[r[0], c[0]] < 0.5
    known = np.isfinite(gm.prob)
    np.testing.assert_allclose(gm.prob[known], 1 / (1 + np.exp(-lo[known].astype(float))), rtol=1e-6)
    assert np.all(lo[~known] == 0)
    # cell (0, 0)'s lower-left corner: world = corner + (col + 0.5)·r for cell centres
    xs = gm.cell_centers()[0][0]
    assert np.min(np.abs(xs - 0.0)) < 1e-9  # the map origin is a cell centre
    assert slam.memory_bytes == sum(lv.nbytes for lv in slam.map.levels) > 0


def test_clear_no_return_option() -> None:
    ranges = np.full(180, np.inf)
    ranges[:40] = 3.0
    on = HectorSlam(SlamConfig(clear_no_return_dist=2.0))
    off = HectorSlam(SlamConfig())
    on.process(_scan(ranges))
    off.process(_scan(ranges))
    # beam 120 (angle ≈ +π/3) has no return: cleared to 2 m with the option, untouched without
    a = -math.pi + 120 * 2 * math.pi / 180
    p = np.array([[1.5 * math.cos(a), 1.5 * math.sin(a)]])
    g_on, g_off = on.gridmap(), off.gridmap()
    c, r = g_on.world_to_cell(p)[0]
    assert g_on.prob[r, c] < 0.5
    c, r = g_off.world_to_cell(p)[0]
    inside = 0 <= r < g_off.prob.shape[0] and 0 <= c < g_off.prob.shape[1]
    assert not inside or np.isnan(g_off.prob[r, c])


def test_grazing_stop_keeps_walls_that_rays_run_along() -> None:
    """stop-and-go's corridor walls are seen only at grazing incidence from the room: with Hector's update
    (every cell before the endpoint free) the rays running along them clear wall cells other rays hit;
    the incidence-scaled free-space stop (slam.grazing_stop_cells, docs/maps.md) keeps them, and leaves
    the map unchanged where rays meet surfaces head-on."""
    from dynslam2d.eval.maps import map_metrics
    from dynslam2d.sim.simulation import simulate
    from dynslam2d.slam.grid import grazing_stop

    sim = simulate("stop-and-go", duration=15.0)
    gt = sim.ground_truth
    maps = {}
    for g in (0.0, 1.0):
        m = MultiResMap(0.05, 1, -0.405, 2.197, grazing_cells=g)
        for i, scan in enumerate(sim.scans[::2]):
            i *= 2
            keep = (gt.labels[i] == 0) & np.isfinite(scan.ranges)
            m.integrate(gt.pose(i), scan.points(keep))
        maps[g] = map_metrics(m.to_gridmap(), gt.static_map(0.05))
    assert maps[0.0].recall < 0.97  # grazing rays cleared wall cells
    assert maps[1.0].recall > maps[0.0].recall + 0.01
    assert maps[1.0].precision >= maps[0.0].precision - 0.002
    assert HectorSlam(SlamConfig(grazing_stop_cells=1.0)).map.grazing_cells == 1.0  # the option reaches the map
    assert HectorSlam(SlamConfig()).map.grazing_cells == 0.0  # default: Hector's update
    # normal incidence: the stop is grazing_cells (1 cell = the endpoint the reference never frees)
    wall = np.column_stack((np.full(21, 3.0), np.linspace(-0.2, 0.2, 21)))
    assert np.allclose(grazing_stop(wall, 1.0, math.sin(math.radians(5.0))), 1.0, atol=0.01)


@pytest.mark.parametrize("seed", range(4))
def test_ray_ends_equal_the_pose_transform_and_numpy_extremes(seed: int) -> None:
    """raycast.ray_ends gives MultiResMap.integrate the ends Pose2D.transform_points computes (bit for bit), the
    hit flags (hits first, then clearing ends) and numpy's min / max of each row, NaN included."""
    from dynslam2d.slam.raycast import ray_ends

    rng = np.random.default_rng(seed)
    hits = rng.normal(0.0, 8.0, (int(rng.integers(1, 300)), 2))
    clear = rng.normal(0.0, 8.0, (int(rng.integers(0, 50)), 2))[:, ::-1]  # (a non-contiguous view)
    pose = Pose2D(float(rng.uniform(-30, 30)), float(rng.uniform(-30, 30)), float(rng.uniform(-math.pi, math.pi)))
    ends, hit, box = ray_ends(hits, clear, math.cos(pose.theta), math.sin(pose.theta), pose.x, pose.y)
    want = pose.transform_points(np.vstack((hits, clear)))
    assert np.array_equal(ends, want.T) and ends.flags.c_contiguous
    assert hit.tolist() == [True] * hits.shape[0] + [False] * clear.shape[0]
    assert box.tolist() == [*want.min(axis=0).tolist(), *want.max(axis=0).tolist()]
    hits[hits.shape[0] // 2, 1] = np.nan  # (NaN in both rows after the rotation)
    box = ray_ends(hits, clear, math.cos(pose.theta), math.sin(pose.theta), pose.x, pose.y)[2]
    want = pose.transform_points(np.vstack((hits, clear)))
    assert np.isnan(box).all() and np.isnan(want.min(axis=0)).all() and np.isnan(want.max(axis=0)).all()


@pytest.mark.parametrize("seed", range(6))
def test_growth_writes_every_cell_once_with_the_old_content_and_the_fill(seed: int) -> None:
    """Pass rest18: ``GridLevel._grow`` writes the old arrays into their place and the fill values (probability 0.5,
    update index 0, log-odds 0) into the strips around them in an uninitialised array; every array equals the
    earlier fill-then-copy growth exactly, whichever sides grow. The allocator is handed memory full of garbage of
    the arrays' sizes first, so that a strip left unwritten shows."""
    rng = np.random.default_rng(seed)
    lv = GridLevel(0.05)
    lv._grow((-7, 3, 13, 19))  # (from empty: every cell the fill)
    assert np.all(decode_probs(lv.prob) == np.float32(0.5)) and np.all(lv.uidx == 0) and np.all(lv.logodds == 0.0)
    for _ in range(8):
        h, w = lv.shape
        lv.prob[...] = encode_probs(rng.random((h, w), dtype=np.float32))
        lv.uidx[...] = rng.integers(0, 1000, (h, w), dtype=np.int32)
        lv.logodds[...] = rng.normal(0.0, 3.0, (h, w)).astype(np.float32)
        grow = rng.integers(0, 4, 4) * rng.integers(0, 2, 4)  # (some sides, by 0-3 cells; sometimes none)
        b = (lv.i0 - int(grow[0]), lv.j0 - int(grow[1]), lv.i0 + w + int(grow[2]), lv.j0 + h + int(grow[3]))
        want = {}
        for name, fill, dtype in (("prob", 0, np.uint32), ("uidx", 0, np.int32), ("logodds", 0.0, np.float32)):
            ref = np.full((b[3] - b[1], b[2] - b[0]), fill, dtype=dtype)
            ref[lv.j0 - b[1]:lv.j0 - b[1] + h, lv.i0 - b[0]:lv.i0 - b[0] + w] = getattr(lv, name)
            want[name] = ref
        junk = [np.full(a.shape, v, dtype=a.dtype) for a, v in ((want["prob"], 0x7FC00000), (want["uidx"], 7),
                                                                  (want["logodds"], 9.0))]
        del junk
        lv._grow(b)
        assert (lv.i0, lv.j0) == b[:2]
        for name, ref in want.items():
            got = getattr(lv, name)
            assert got.dtype == ref.dtype and got.shape == ref.shape
            assert np.array_equal(got, ref), name
