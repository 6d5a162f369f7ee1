"""The vacated-footprint trace skips map blocks without long-occupied cells (docs/speed.md, pass vac2): the same
seen-through cells as the full walk, on maps and segments where the skipping matters, and a block summary that the
map's integrations keep a superset of the exact one."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.mapevidence import BLOCK, BLOCK_FAR, MapView, block_summary, seen_through_structure_kernel
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.grid import MultiResMap
from dynslam2d.types import Pose2D, Scan
from dynslam2d.vacated import _NO_BLOCKS, _NO_ENDS, _NO_HIT, VacatedTrace, vacated_scan_kernel

OCC = 6.0


def _walk(lo, i0, j0, ox, oy, cx, cy, clear, depth, blocks):
    cap = 64 * cx.shape[0]
    out_r = np.empty(cap, dtype=np.int64)
    out_c = np.empty(cap, dtype=np.int64)
    n = seen_through_structure_kernel(lo, i0, j0, ox, oy, cx, cy, clear, 0.4, OCC, out_r, out_c, depth, blocks)
    return out_r[:n].copy(), out_c[:n].copy()


def _random_map(rng: np.random.Generator) -> np.ndarray:
    """Free floor (sizes not multiples of BLOCK: partial edge blocks) with long-occupied specks, lines and cells
    just at and just below the threshold, in some blocks only."""
    h, w = rng.integers(30, 160, size=2)
    lo = np.full((h, w), -1.0, dtype=np.float32)
    for _ in range(rng.integers(1, 6)):
        r, c = rng.integers(0, h), rng.integers(0, w)
        if rng.random() < 0.5:
            lo[r, c:c + rng.integers(1, 30)] = 8.0
        else:
            lo[r:r + rng.integers(1, 30), c] = 8.0
    lo[rng.random(lo.shape) < 0.003] = np.float32(OCC)  # exactly at the threshold: long-occupied
    lo[rng.random(lo.shape) < 0.01] = np.float32(5.999)  # just below: not
    lo[0, rng.integers(0, w)] = 9.0  # on the map's edges
    lo[h - 1, rng.integers(0, w)] = 9.0
    lo[rng.integers(0, h), w - 1] = 9.0
    return lo


def test_skipping_blocks_gives_the_cells_of_the_full_walk_and_a_wrong_skip_is_seen() -> None:
    rng = np.random.default_rng(3)
    found = wrong_seen = 0
    for _ in range(150):
        lo = _random_map(rng)
        h, w = lo.shape
        i0, j0 = (int(v) for v in rng.integers(-200, 200, size=2))
        # the laser inside the grid, near an edge or outside it (segments entering and leaving the grid)
        ox = i0 + rng.uniform(-20.0, w + 20.0)
        oy = j0 + rng.uniform(-20.0, h + 20.0)
        n = int(rng.integers(3, 400))
        ang = np.sort(rng.uniform(-math.pi, math.pi, n))
        rr = rng.uniform(0.0, 1.3 * max(h, w), n)
        rr[rng.random(n) < 0.1] = rng.uniform(0.0, 3.0)  # a few very short segments
        cx = ox + rr * np.cos(ang)
        cy = oy + rr * np.sin(ang)
        clear = rng.random(n) < 0.95
        depth = float(rng.choice([0.0, rng.uniform(0.0, 20.0)]))
        exact = block_summary(lo, OCC)
        full = _walk(lo, i0, j0, ox, oy, cx, cy, clear, depth, _NO_BLOCKS)
        skip = _walk(lo, i0, j0, ox, oy, cx, cy, clear, depth, exact)
        assert np.array_equal(full[0], skip[0]) and np.array_equal(full[1], skip[1])
        # a summary with smaller distances in places (as the map updates leave it) gives the same cells too
        loose = np.where(rng.random(exact.shape) < 0.3, rng.integers(0, BLOCK_FAR + 1, exact.shape), exact)
        loose = np.minimum(loose, exact).astype(np.uint8)
        assert all(np.array_equal(a, b) for a, b in zip(full, _walk(lo, i0, j0, ox, oy, cx, cy, clear, depth, loose)))
        if full[0].shape[0]:
            found += 1
            # the test would see a wrong skip: a seen-through cell's block and its neighbours called far from any
            # long-occupied cell lose it (unless the beam's other cells near long-occupied ones span it)
            wrong = exact.copy()
            r, c = full[0][0] // BLOCK, full[1][0] // BLOCK
            wrong[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] = BLOCK_FAR
            cut = _walk(lo, i0, j0, ox, oy, cx, cy, clear, depth, wrong)
            wrong_seen += not (np.array_equal(full[0], cut[0]) and np.array_equal(full[1], cut[1]))
    assert found > 50
    assert wrong_seen > 0.6 * found


def test_block_summary() -> None:
    lo = np.zeros((17, 9), dtype=np.float32)
    lo[16, 8] = OCC
    lo[3, 3] = 5.9
    s = block_summary(lo, OCC)
    assert s.shape == (3, 2) and s.tolist() == [[2, 2], [1, 1], [1, 0]]
    lo = np.zeros((200, 90), dtype=np.float32)
    lo[5, 5] = 7.0
    s = block_summary(lo, OCC)
    assert s[0, 0] == 0 and s[3, 5] == 5 and s[20, 1] == BLOCK_FAR and s[7, 0] == 7


def _ranges(px: float, py: float, a: np.ndarray, box: bool, xmax: float) -> np.ndarray:
    """Ranges from (px, py) along angles ``a`` to a room (x −10…``xmax``, y −8…8) and, with ``box``, a 4 × 2 m box
    at x 2…6, y −1…1 (slab method)."""
    d = np.stack((np.cos(a), np.sin(a)), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(d[:, 0] > 0, (xmax - px) / d[:, 0], (-10.0 - px) / d[:, 0])
        ty = np.where(d[:, 1] > 0, (8.0 - py) / d[:, 1], (-8.0 - py) / d[:, 1])
        r = np.minimum(tx, ty)
        if box:
            lo = (np.array([2.0, -1.0]) - (px, py)) / d
            hi = (np.array([6.0, 1.0]) - (px, py)) / d
            tn = np.minimum(lo, hi).max(axis=1)
            tf = np.maximum(lo, hi).min(axis=1)
            r = np.where((tn <= tf) & (tn > 0.0), np.minimum(r, tn), r)
    return r


def test_the_summary_kept_by_the_map_updates_gives_the_full_walk_and_stays_a_superset() -> None:
    """A room with a box mapped from several poses, then the box gone (scans see through its outline), the robot
    the far wall moving away so that the map grows; a trace with the summary against the full walk on every scan."""
    rng = np.random.default_rng(11)
    hmap = MultiResMap(0.05, 3, -0.4, 2.2, growth_margin=1.0)
    clean = CleanConfig()
    trace = VacatedTrace(clean, occupied_logodds=OCC, min_cells=4, max_extent=6.0, min_depth_m=1.0, min_extent=3.0,
                         min_share=0.2, scans=1)
    n = 540
    a = -math.pi + np.arange(n) * (2 * math.pi / n)
    seen = rebuilt = 0
    for step in range(36):
        box = step < 14
        px, py = -6.0 + 0.3 * step + rng.normal(0.0, 0.02), -4.0 + 0.2 * (step % 9)
        r = _ranges(px, py, a, box, 10.0 + max(step - 20, 0)) + rng.normal(0.0, 0.01, n)
        r[rng.random(n) < 0.05] = np.nan
        scan = Scan(stamp=float(step), angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=r, range_min=0.05,
                    range_max=30.0)
        pose = Pose2D(px, py, 0.0)
        lv = hmap.levels[0]
        if not lv.empty:
            view = MapView.of_level(lv)
            if trace._res != view.resolution or trace._beams != n:
                trace._prepare(view.resolution, n)
            blocks, rebuild, ends, hit = trace._summary(view)
            rebuilt += rebuild
            cos_a, sin_a = scan.trig()
            valid = scan.valid_view()
            args = (r, cos_a, sin_a, valid, px, py, 0.0, view.logodds, view.i0, view.j0, trace.params, trace._work,
                    trace._window)
            nc, k, out = vacated_scan_kernel(*args, blocks, rebuild, ends, hit)
            out = out.copy()
            assert (blocks <= block_summary(view.logodds, OCC)).all()  # distances that only err low
            nc0, k0, out0 = vacated_scan_kernel(*args, _NO_BLOCKS, False, _NO_ENDS, _NO_HIT)
            assert (nc, k) == (nc0, k0) and np.array_equal(out, out0)
            seen += nc > 0
        ok = np.isfinite(r)
        pts = np.stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])), axis=1)
        if step % 5 != 4:  # (some scans do not update the map)
            hmap.integrate(pose, pts)
    assert seen >= 5  # the box's outline was seen through
    assert 2 <= rebuilt < 20  # the first scan and the growths; otherwise kept up to date
