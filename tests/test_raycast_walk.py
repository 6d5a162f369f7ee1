"""The ray kernel's walk (slam/raycast.py): minor offsets by multiply-shift (and division above its limit), the
probabilities written in batches after the walks by the fast exact form (or the plain one where it asks), the
prefetches — each against the plain cell-by-cell reference update."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.jitbox import njit
from dynslam2d.slam.grid import GridLevel, MultiResMap, decode_probs, encode_probs
from dynslam2d.slam.raycast import (
    _MAGIC_MAX,
    _MAGIC_SHIFT,
    _PREFETCH,
    _PROB_BATCH,
    _prob_fast,
    _write_probs,
    bresenham_free_cells,
    integrate_rays,
    integrate_rays_stop,
)
from dynslam2d.types import Pose2D

L_FREE = -0.4054651081081643
L_OCC = 2.1972245773362196


def _reference(lo, pr, ui, sx, sy, ex, ey, hit, stop, free_idx, occ_idx, cap) -> None:
    """OccGridMapBase::updateByScan cell by cell on the error-recurrence Bresenham cells of
    :func:`bresenham_free_cells` (float64 arrays of the level's values, updated in place)."""
    h, w = lo.shape

    def free(x, y):
        if ui[y, x] < free_idx:
            v = float(np.float32(lo[y, x])) + L_FREE
            lo[y, x] = np.float32(v)
            pr[y, x] = np.float32(1.0 / (1.0 + math.exp(-v)))
            ui[y, x] = free_idx

    for k in range(len(ex)):
        x1, y1 = int(ex[k]), int(ey[k])
        if (x1, y1) == (sx, sy) or not (0 <= x1 < w and 0 <= y1 < h):
            continue
        major = max(abs(x1 - sx), abs(y1 - sy))
        skip = 0
        if stop is not None and stop[k] > 1.0:
            skip = min(int((stop[k] - 1.0) * major / math.hypot(x1 - sx, y1 - sy)), major - 1)
        for x, y in bresenham_free_cells(sx, sy, x1, y1)[: major - skip].tolist():
            free(x, y)
        if hit[k]:
            u = ui[y1, x1]
            if u < occ_idx:
                v = float(np.float32(lo[y1, x1]))
                if u == free_idx:
                    v -= L_FREE
                if v < cap:
                    v += L_OCC
                lo[y1, x1] = np.float32(v)
                pr[y1, x1] = np.float32(1.0 / (1.0 + math.exp(-v)))
                ui[y1, x1] = occ_idx
        else:
            free(x1, y1)


def _check(h: int, w: int, sx: int, sy: int, ex, ey, hit, stop, scans: int, cap: float = 6.0) -> None:
    """Integrate the same rays ``scans`` times with the kernel and the reference; every array equal after each."""
    lo = np.zeros((h, w), np.float32)
    pr = np.zeros((h, w), np.uint32)  # (the cache's words: 0.5 everywhere)
    ui = np.full((h, w), -1, np.int32)
    rlo, rpr, rui = lo.astype(np.float64), decode_probs(pr).astype(np.float64), ui.astype(np.int64)
    ex, ey = np.asarray(ex, np.int64), np.asarray(ey, np.int64)
    for s in range(scans):
        fi, oi = 3 * s + 1, 3 * s + 2
        if stop is None:
            integrate_rays(lo, pr, ui, fi, oi, sx, sy, ex, ey, hit, L_FREE, L_OCC, cap)
        else:
            integrate_rays_stop(lo, pr, ui, fi, oi, sx, sy, ex, ey, hit, stop, L_FREE, L_OCC, cap)
        _reference(rlo, rpr, rui, sx, sy, ex, ey, hit, stop, fi, oi, cap)
        assert np.array_equal(lo, rlo.astype(np.float32))
        assert np.array_equal(decode_probs(pr).view(np.int32), rpr.astype(np.float32).view(np.int32))
        assert np.array_equal(ui, rui.astype(np.int32))


def test_multiply_shift_gives_the_bresenham_minor_offsets_below_the_limit() -> None:
    """(t · ceil(2^42 / M)) >> 42 == t // M for every major length M < _MAGIC_MAX and the walk's largest values of
    t = M // 2 + j · minor (j < M, minor ≤ M), where the multiply-shift's error is largest; it fails above the
    limit (so the kernel's division fallback is needed there)."""
    for m in list(range(1, 600)) + list(range(_MAGIC_MAX - 600, _MAGIC_MAX)):
        magic = ((1 << _MAGIC_SHIFT) + m - 1) // m
        top = m // 2 + (m - 1) * m
        t = np.concatenate((np.arange(max(top - 3 * m, 0), top + 1), np.arange(0, min(top, 3 * m) + 1)))
        t = t.astype(np.int64)
        assert np.array_equal((t * magic) >> _MAGIC_SHIFT, t // m), m
    bad = 0
    for m in range(1 << 15, (1 << 15) + 64):  # well above the limit, some values go wrong
        magic = ((1 << _MAGIC_SHIFT) + m - 1) // m
        t = np.arange(m * m - 4 * m, m * m, dtype=np.int64)
        bad += int(np.count_nonzero((t * magic) >> _MAGIC_SHIFT != t // m))
    assert bad > 0


@pytest.mark.parametrize("with_stop", [False, True])
def test_rays_sharing_cells_equal_the_reference(with_stop: bool) -> None:
    """Dense fans of rays in every octant (each ray shares a leading run of cells with the previous one), runs of
    equal ends, rays outside the array or ending in the start cell between them, clearing rays, the grazing stop,
    repeated scans (free then occupied, the cap): bit for bit the reference."""
    rng = np.random.default_rng(5)
    h, w, sx, sy = 90, 110, 47, 41
    a = np.sort(rng.uniform(-math.pi, math.pi, 700))
    r = rng.choice([8.0, 20.0, 35.0, 60.0], a.size) + rng.normal(0.0, 0.7, a.size)
    ex = np.floor(sx + r * np.cos(a) + 0.5).astype(np.int64)
    ey = np.floor(sy + r * np.sin(a) + 0.5).astype(np.int64)
    ex[rng.random(a.size) < 0.05] = sx  # some end in the start cell (skipped)
    ey[ex == sx] = sy
    ex = np.concatenate((ex, ex[100:160], ex[:40][::-1]))  # repeats and a reversed run
    ey = np.concatenate((ey, ey[100:160], ey[:40][::-1]))
    hit = rng.random(ex.size) < 0.85
    stop = rng.choice([0.0, 1.0, 2.5, 7.0], ex.size) if with_stop else None
    assert ((ex < 0) | (ex >= w) | (ey < 0) | (ey >= h)).any()  # (rays outside the array are among them)
    _check(h, w, sx, sy, ex, ey, hit, stop, scans=4)


def test_mirrored_rays_are_not_skipped_along() -> None:
    """Consecutive rays mirrored about the major axis have the same minor offsets at every step but lie on opposite
    sides (a different minor direction): the second ray's cells are its own (a walk that took the offsets' cells
    from the previous ray would not update them)."""
    h, w, sx, sy = 60, 60, 30, 30
    ex = [sx + 25, sx + 25, sx - 25, sx - 25, sx + 6, sx - 6, sx + 6, sx - 6, sx + 25, sx + 25]
    ey = [sy + 7, sy - 7, sy + 7, sy - 7, sy + 25, sy + 25, sy - 25, sy - 25, sy + 25, sy - 25]
    _check(h, w, sx, sy, ex, ey, np.ones(len(ex), bool), None, scans=2)


def test_repeated_rays_are_skipped_only_when_they_would_change_nothing() -> None:
    """A ray with the previous ray's end cell, kind and stop walks the same cells, all already updated this scan, so
    the kernel skips it (counting it as the previous one was); the same end as a clearing ray then a return, or
    with a shorter stop, does change cells and must be walked: bit for bit the reference, and the returned count
    includes the skipped repeats but not the rays outside the array."""
    h, w, sx, sy = 40, 50, 20, 18
    ex = [35, 35, 35, 35, 35, 60, 60, 20, 20, 5, 5, 5, 30, 30, 30]
    ey = [25, 25, 25, 25, 25, 10, 10, 18, 18, 3, 3, 3, 38, 38, 38]
    hit = np.array([True, True, False, False, True, True, True, True, True, False, True, True, True, True, True])
    # (35, 25): return ×2, clearing ×2 (changes nothing), return (changes nothing); (60, 10) outside; (20, 18) the
    # start cell; (5, 3): clearing then a return (the end turns occupied); (30, 38) with stops 9, 9, then 1
    stop = np.array([0.0] * 12 + [9.0, 9.0, 1.0])
    _check(h, w, sx, sy, ex, ey, hit, None, scans=3)
    _check(h, w, sx, sy, ex, ey, hit, stop, scans=3)
    lo = np.zeros((h, w), np.float32)
    pr = np.zeros((h, w), np.uint32)  # (the cache's words: 0.5 everywhere)
    ui = np.full((h, w), -1, np.int32)
    exa, eya = np.asarray(ex, np.int64), np.asarray(ey, np.int64)
    assert integrate_rays(lo, pr, ui, 1, 2, sx, sy, exa, eya, hit, L_FREE, L_OCC, 6.0) == 11
    assert ui[3, 5] == 2 and lo[3, 5] == np.float32(L_OCC)  # the return after the clearing ray was not skipped
    lo[:] = 0.0
    ui[:] = -1
    assert integrate_rays_stop(lo, pr, ui, 1, 2, sx, sy, exa, eya, hit, stop, L_FREE, L_OCC, 6.0) == 11
    cells = bresenham_free_cells(sx, sy, 30, 38)
    assert (ui[cells[:, 1], cells[:, 0]] == 1).all()  # stop 1 after stop 9: the ray's last cells made free too


def test_single_rays_of_every_length_around_the_prefetch_distance_equal_the_reference() -> None:
    """The free walk runs in two parts, the cells whose cell _PREFETCH steps on is still on the ray and the last ones:
    one ray at a time (no other ray's cells to hide a cell walked too far or left out), every major length from 1
    to 2·_PREFETCH + 3 in four octants, with and without a stop that leaves 0, 1, ... cells before the end
    unwalked, as a return and as a clearing ray: bit for bit the reference."""
    n = 2 * (2 * _PREFETCH + 4) + 1  # (every ray's end inside the array: a ray ending outside is skipped whole)
    h, w, sx, sy = n, n, n // 2, n // 2
    for major in range(1, 2 * _PREFETCH + 4):
        for dx, dy in ((major, major // 3), (-(major // 2), major), (-major, -(major // 5)), (major // 4, -major)):
            ex, ey = [sx + dx], [sy + dy]
            assert 0 <= ex[0] < w and 0 <= ey[0] < h
            length = math.hypot(dx, dy)
            for hit in (True, False):
                _check(h, w, sx, sy, ex, ey, np.array([hit]), None, scans=2)
                for skip in (1, 2, _PREFETCH - 1, _PREFETCH, _PREFETCH + 1):
                    stop = np.array([1.0 + (skip + 0.5) * length / major])
                    _check(h, w, sx, sy, ex, ey, np.array([hit]), stop, scans=2)


def test_rays_longer_than_the_multiply_shift_limit_equal_the_reference() -> None:
    """Rays with a major length at and above _MAGIC_MAX take the division path: cells and values as the
    reference, next to short rays in the same octant."""
    h, w, sx, sy = 40, _MAGIC_MAX + 300, 2, 20
    ex = np.array([w - 1, _MAGIC_MAX + 2, _MAGIC_MAX, _MAGIC_MAX - 1, 500, 501, w - 3, 30, w - 2])
    ey = np.array([39, 0, 21, 25, 33, 33, 5, 22, 20])
    hit = np.array([True, True, False, True, True, True, True, False, True])
    _check(h, w, sx, sy, ex, ey, hit, None, scans=2)


@njit(cache=True)
def _fast_all(v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - numba
    for i in range(v.shape[0]):
        out[i] = _prob_fast(v[i])


def _plain(v: np.ndarray) -> np.ndarray:
    """float32(1 / (1 + exp(−v))) element by element in Python floats (math.exp: the C library's exp, as the kernel's
    plain form), of float64 ``v``."""
    return np.array([1.0 / (1.0 + math.exp(-x)) if not x < -709.0 else 0.0 for x in v.tolist()]).astype(np.float32)


def test_fast_probability_has_the_plain_form_bits_or_asks_for_it() -> None:
    """``_prob_fast`` on the log-odds a simulated map reaches (its float32 values, and those plus the free, the
    occupied and the undo-then-occupied increments, as the walk forms them in float64), on random values
    over its whole range, and on its edges: wherever it answers (not NaN), the plain form's bits; it asks (NaN)
    for under 1 % of them, for nearly every value whose probability lies on a float32 rounding boundary (where
    rounding its own float64 value would give the wrong bits about half the time), for every value beyond ±700
    and for NaN."""
    rng = np.random.default_rng(4)
    hmap = MultiResMap(0.05, 3, L_FREE, L_OCC, cap=50.0)
    for s in range(30):
        pose = Pose2D(float(0.02 * s), float(-0.01 * s), float(0.05 * s))
        a = np.linspace(-2.5, 2.5, 400)
        rr = rng.choice([1.0, 2.0, 3.5], a.size) + rng.normal(0.0, 0.05, a.size)
        hmap.integrate(pose, np.column_stack((rr * np.cos(a), rr * np.sin(a))))
    lo = np.unique(np.concatenate([lv.logodds.ravel() for lv in hmap.levels])).astype(np.float64)
    assert lo.size > 200  # (the map's histories gave many values)
    v = np.concatenate((lo, lo + L_FREE, lo + L_OCC, (lo - L_FREE) + L_OCC,
                        rng.uniform(-700.0, 700.0, 20000), rng.uniform(-40.0, 40.0, 20000),
                        np.float32(rng.uniform(-120.0, 60.0, 20000)).astype(np.float64),
                        [0.0, -0.0, 700.0, -700.0, 1e-300, -1e-300, 17.0, 36.8, -87.3, -103.97]))
    out = np.empty(v.size, np.float32)
    _fast_all(v, out)
    answered = out == out
    assert np.array_equal(out[answered].view(np.int32), _plain(v[answered]).view(np.int32))
    assert np.count_nonzero(~answered) < 0.01 * v.size
    # values whose probability lies on a float32 rounding boundary (the midpoint of two neighbours) to about 1e-16:
    # the fast form's own float64 value (error ≈ 1e-11) rounds either way, so it must ask for nearly all of them
    p32 = np.float32(rng.uniform(0.001, 0.999, 3000))
    mid = (p32.astype(np.float64) + np.nextafter(p32, np.float32(1.0)).astype(np.float64)) / 2.0
    v = np.log(mid) - np.log1p(-mid)
    out = np.empty(v.size, np.float32)
    _fast_all(v, out)
    answered = out == out
    assert np.array_equal(out[answered].view(np.int32), _plain(v[answered]).view(np.int32))
    assert np.count_nonzero(answered) < 0.05 * v.size
    edge = np.array([700.0000000000001, -700.0000000000001, 745.0, -745.0, 1e308, -np.inf, np.inf, np.nan])
    out = np.empty(edge.size, np.float32)
    _fast_all(edge, out)
    assert np.isnan(out).all()


def test_probability_writes_keep_the_order_and_fall_back_to_the_plain_form() -> None:
    """``_write_probs``: every listed cell gets the plain form's value, a cell listed twice the later one, values
    the fast form asks about (beyond ±700, NaN) the plain form's (0, 1, NaN)."""
    rng = np.random.default_rng(6)
    n = 3000
    cells = rng.integers(0, 500, n).astype(np.uint64)  # (many cells listed more than once)
    vals = rng.uniform(-30.0, 30.0, n)
    vals[::97] = rng.choice([800.0, -800.0, np.nan], vals[::97].size)
    pr = encode_probs(np.full(500, 0.25, np.float32))
    _write_probs(pr, cells, vals, np.empty(n, np.float32), n)
    want = np.full(500, 0.25, np.float32)
    for f, p in zip(cells.tolist(), _plain(vals).tolist()):
        want[f] = p
    assert np.array_equal(decode_probs(pr).view(np.int32), want.view(np.int32))


def test_probability_batches_across_a_scan_equal_the_reference() -> None:
    """More cells updated in one call than one probability batch holds (``_PROB_BATCH``), with rays whose end
    cell lies on an earlier ray's path (a free update undone by an occupied one in a later batch): bit for bit
    the reference over three scans."""
    rng = np.random.default_rng(8)
    h, w, sx, sy = 160, 150, 70, 80
    a = np.sort(rng.uniform(-math.pi, math.pi, 900))
    r = rng.uniform(3.0, 70.0, a.size)
    ex = np.floor(sx + r * np.cos(a) + 0.5).astype(np.int64)
    ey = np.floor(sy + r * np.sin(a) + 0.5).astype(np.int64)
    hit = rng.random(a.size) < 0.9
    ui = np.full((h, w), -1, np.int32)
    integrate_rays(np.zeros((h, w), np.float32), np.zeros((h, w), np.uint32), ui, 1, 2, sx, sy, ex, ey, hit,
                   L_FREE, L_OCC, 6.0)
    assert np.count_nonzero(ui >= 1) > 3 * _PROB_BATCH
    _check(h, w, sx, sy, ex, ey, hit, None, scans=3)


def test_level_integrate_and_the_fused_call_agree_on_a_grown_map() -> None:
    """GridLevel.integrate (integrate_rays per level) and MultiResMap.integrate (every level in one call, growth
    bounds computed once) write the same cells while the map grows in every direction."""
    rng = np.random.default_rng(9)
    hmap = MultiResMap(0.1, 3, L_FREE, L_OCC, cap=5.0)
    ref = [GridLevel(lv.resolution, lv.growth_margin_cells) for lv in hmap.levels]
    for s in range(10):
        pose = Pose2D(float(3.0 * s * (-1) ** s), float(-2.0 * s), float(rng.uniform(-3, 3)))
        a = np.linspace(-3.0, 3.0, 200)
        rr = rng.uniform(0.5, 6.0, a.size)
        hits = np.column_stack((rr * np.cos(a), rr * np.sin(a)))
        hmap.integrate(pose, hits)
        c, sn = math.cos(pose.theta), math.sin(pose.theta)
        ends = np.column_stack((c * hits[:, 0] - sn * hits[:, 1] + pose.x, sn * hits[:, 0] + c * hits[:, 1] + pose.y))
        for lv in ref:
            lv.integrate(np.array([pose.x, pose.y]), ends, np.ones(a.size, bool), L_FREE, L_OCC, 5.0)
    for lv, rl in zip(hmap.levels, ref):
        assert (lv.i0, lv.j0, lv.shape) == (rl.i0, rl.j0, rl.shape)
        assert np.array_equal(lv.logodds, rl.logodds) and np.array_equal(lv.prob, rl.prob)
        assert np.array_equal(lv.uidx, rl.uidx)


def _levels_state(m: MultiResMap) -> list[tuple]:
    return [(lv.logodds.tobytes(), lv.prob.tobytes(), lv.uidx.tobytes(), lv.i0, lv.j0, lv.shape, lv.update_counter)
            for lv in m.levels]


@pytest.mark.parametrize("n_levels", [4, 3, 2])
def test_fused_scan_call_takes_the_growth_way_exactly_when_a_level_must_grow(
        n_levels: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """MultiResMap.integrate's one kernel call (ends, bounds, every level) integrates a scan only when every level
    holds its start cell and its ends' cells; otherwise it writes nothing and the Python way grows the levels
    (ray_ends called): scans ending on the array's edge cells, one cell past them, a start cell outside the array
    with every end inside, a NaN end, a map over its byte limit — every level bit for bit the per-level reference,
    the counters and errors as before."""
    from conftest import scan_rays

    import dynslam2d.slam.grid as grid
    from dynslam2d.slam.grid import MapTooLargeError

    calls = []
    real_ends = grid.ray_ends

    def counted(*a):
        calls.append(1)
        return real_ends(*a)

    monkeypatch.setattr(grid, "ray_ends", counted)
    fast = MultiResMap(0.05, n_levels, L_FREE, L_OCC, growth_margin=0.5)
    plain = MultiResMap(0.05, n_levels, L_FREE, L_OCC, growth_margin=0.5)
    a = np.linspace(-3.0, 3.0, 200)

    def scan(pose: Pose2D, rr: np.ndarray, a: np.ndarray = a) -> bool:
        """Integrate into both maps; True if the fused call integrated it (no ray_ends call)."""
        hits = np.column_stack((rr * np.cos(a), rr * np.sin(a)))
        n = len(calls)
        fast.integrate(pose, hits)
        ends, hit, _ = scan_rays(pose, hits, None, 0.0, plain.min_sin)
        for lv in plain.levels:
            lv.integrate(np.array([pose.x, pose.y]), ends, hit, plain.l_free, plain.l_occ, plain.cap)
        for f, p in zip(fast.levels, plain.levels):
            assert f.logodds.tobytes() == p.logodds.tobytes() and f.prob.tobytes() == p.prob.tobytes()
            assert f.uidx.tobytes() == p.uidx.tobytes() and (f.i0, f.j0, f.shape) == (p.i0, p.j0, p.shape)
        return len(calls) == n

    pose = Pose2D(0.0, 0.0, 0.0)
    assert not scan(pose, np.full(a.shape, 2.0))  # the first scan grows every level
    lv0 = fast.levels[0]
    # the array's last column, as a world x: a return on that cell's centre fits, one cell further does not
    x_edge = (lv0.i0 + lv0.shape[1] - 1) * lv0.resolution
    rr = np.full(a.shape, 1.0)
    rr[100] = x_edge / math.cos(a[100])  # (a[100] ≈ 0.015 rad: nearly along +x)
    counter = [lv.update_counter for lv in fast.levels]
    version = fast.version
    assert scan(pose, rr)
    assert [lv.update_counter for lv in fast.levels] == [c + 3 for c in counter] and fast.version == version + 1
    rr[100] = (x_edge + lv0.resolution) / math.cos(a[100])
    assert not scan(pose, rr)  # one cell past the edge: level 0 grows
    # every end inside the arrays, the start cell outside (the pose moved past the edge, the rays pointing back)
    lv0 = fast.levels[0]
    far = (lv0.i0 + lv0.shape[1] + 3) * lv0.resolution
    back = Pose2D(far, 0.0, math.pi)
    narrow = np.linspace(-0.3, 0.3, 50)
    ends_x = far - (far - 1.0) * np.cos(narrow)
    assert ends_x.max() < (lv0.i0 + lv0.shape[1] - 1) * lv0.resolution  # (every end inside level 0)
    assert not scan(back, np.full(narrow.shape, far - 1.0), narrow)
    assert scan(back, np.full(narrow.shape, far - 1.5), narrow)
    before = _levels_state(fast)
    bad = np.column_stack((np.cos(a), np.sin(a)))
    bad[7] = np.nan
    with pytest.raises(ValueError):
        fast.integrate(pose, bad)
    assert _levels_state(fast) == before
    fast.max_bytes = fast.memory_bytes - 1  # already over the limit: no scan is integrated, as before
    with pytest.raises(MapTooLargeError):
        fast.integrate(pose, np.column_stack((np.cos(a), np.sin(a))))
    assert _levels_state(fast) == before
    fast.max_bytes = fast.memory_bytes
    plain.max_bytes = None
    assert scan(pose, np.full(a.shape, 1.2))
    fast.levels[-1].release("prob")  # a level's arrays of different shapes: an error, nothing written
    before = _levels_state(fast)
    with pytest.raises(ValueError):
        fast.integrate(pose, np.column_stack((np.cos(a), np.sin(a))))
    assert _levels_state(fast) == before
