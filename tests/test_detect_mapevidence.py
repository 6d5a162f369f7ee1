"""Static evidence from the map (Eq. 3 + the map's word) and the physical acceleration bound."""

from __future__ import annotations

import numpy as np
import pytest
from test_detect_tracker import render

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.mapevidence import MapView, map_evidence
from dynslam2d.types import Pose2D

RES = 0.05


def grid(value_path: float, value_rest: float = -2.0) -> MapView:
    """A map of the 16×12 m test room: ``value_rest`` everywhere, ``value_path`` on the band the box
    drives through (y 1.0…2.0), log-odds."""
    i0, j0 = -200, -150
    lo = np.full((300, 400), value_rest, dtype=np.float32)
    ys = (np.arange(300) + j0) * RES
    lo[(ys > 1.0) & (ys < 2.0), :] = value_path
    return MapView(lo, i0, j0, RES)


def run(view: MapView | None, robot_speed: float = 0.0, config: DetectConfig | None = None, duration: float = 4.0,
        jump_at: int | None = None):
    """A 0.8×0.5 box driving along +x at 0.8 m/s (optionally jumping 0.15 m ahead at scan ``jump_at``);
    the robot at (robot_speed·t, −2). Returns the box track per scan."""
    tr = Tracker(config)
    out = []
    shift = 0.0
    for i in range(int(duration * 20)):
        t = i / 20.0
        if jump_at is not None and i == jump_at:
            shift = 0.15
        pose = Pose2D(robot_speed * t, -2.0, 0.0)
        scan, lab = render(pose, [(-3.0 + 0.8 * t + shift, 1.5, 0.0, 0.8, 0.5)], t, seed=i)
        tracks = tr.update(scan, pose, view)
        box = [k for k in tracks if k.n_points and (lab[k.beams] == 1).mean() > 0.5]
        out.append(box[0] if box else None)
    return out


def test_map_evidence_flags() -> None:
    lo = np.zeros((10, 10), dtype=np.float32)
    lo[5, 5] = 4.0  # long-occupied
    lo[2, 2] = -1.0  # observed free, next to nothing occupied
    lo[7, 7] = -1.0
    lo[7, 8] = 2.2  # once hit, next to a free cell
    view = MapView(lo, 0, 0, 0.1)
    pts = np.array([[0.5, 0.5], [0.2, 0.2], [0.7, 0.7], [0.0, 0.9], [5.0, 5.0]])
    s, f, u = map_evidence(pts, view, occupied_logodds=3.0, free_logodds=-0.35, free_radius=1)
    assert s.tolist() == [True, False, False, False, False]
    assert f.tolist() == [False, True, False, False, False]
    assert u.tolist() == [False, False, False, True, True]


def test_map_decides_between_structure_and_motion() -> None:
    """The same moving box: free map -> in M; its path on long-occupied cells -> never in M (structure);
    never-observed cells and a moving laser -> never in M; never-observed cells and a motionless laser
    (whose map is not updated) -> in M; no map at all -> the kinematic test alone (in M)."""
    def in_m(out):
        return any(k is not None and k.in_m for k in out)

    assert in_m(run(grid(-2.0)))
    structure = run(grid(5.0))
    assert not in_m(structure)
    assert any(k is not None and "map cells" in k.m_reason for k in structure)
    assert not in_m(run(grid(0.0, 0.0), robot_speed=0.1))
    assert in_m(run(grid(0.0, 0.0), robot_speed=0.0))
    assert in_m(run(None))


@pytest.mark.parametrize("bound", [4.0, None])
def test_speed_respects_the_acceleration_bound(bound) -> None:
    cfg = DetectConfig()
    cfg.tracker.max_accel = bound
    out = run(None, config=cfg, jump_at=40)
    seq = [k for k in out[30:60] if k is not None]
    dv = max(float(np.hypot(*(b.velocity - a.velocity))) for a, b in zip(seq[:-1], seq[1:]) if a.id == b.id)
    if bound is None:
        assert dv > 0.5  # the jump shows up as a speed jump (control)
    else:
        assert dv <= bound / 20.0 + 1e-9


def test_a_laser_outside_the_grid_walking_away_reads_nothing_off_the_grid() -> None:
    """The vacated-footprint walk of a beam with no step inside the grid finds nothing (docs/speed.md, pass vac2: it
    read the rows beyond the map's end). The map is rows 5…14 of a larger array of long-occupied cells, so a read past
    its last row would find "long-occupied" cells outside the map."""
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel

    big = np.full((40, 30), 8.0, dtype=np.float32)
    lo = big[5:15]  # (C-contiguous: the rows after it are long-occupied memory)
    n = 7
    cx = 15.0 + np.linspace(-3.0, 3.0, n)  # the laser at column 15, row 22 (above the map's rows 0…9), beams going up
    cy = np.full(n, 35.0)
    out_r = np.zeros(64 * n, dtype=np.int64)
    out_c = np.zeros(64 * n, dtype=np.int64)
    got = seen_through_structure_kernel(lo, 0, 0, 15.0, 22.0, cx, cy, np.ones(n, dtype=np.bool_), 0.5, 6.0, out_r,
                                        out_c, 0.0)
    assert got == 0
    # the same beams from inside the map see through its long-occupied rows above the laser
    cy_in = np.full(n, 9.0)
    got_in = seen_through_structure_kernel(lo, 0, 0, 15.0, 1.0, cx, cy_in, np.ones(n, dtype=np.bool_), 0.5, 6.0, out_r,
                                           out_c, 0.0)
    assert got_in > 0 and out_r[:got_in].max() <= 9 and out_r[:got_in].min() >= 0


def _seen_through_plain(lo, i0, j0, ox, oy, cx, cy, clear, core, occ, depth):
    """The seen-through cells as the kernel's docstring states them, walked plainly: every step of each beam's major
    axis from the laser's cell to its end's, no window, no first pass; (row, column) in order."""
    import math

    h, w = lo.shape
    out = []
    for k in range(1, len(cx) - 1):
        if not (clear[k] and clear[k - 1] and clear[k + 1]):
            continue
        reach = math.sqrt(min((cx[j] - ox) ** 2 + (cy[j] - oy) ** 2 for j in (k - 1, k + 1, k))) - depth
        if not reach > 0.0:
            continue
        dx, dy = cx[k] - ox, cy[k] - oy
        x_major = abs(dx) >= abs(dy)
        if x_major:
            a0, a1, m0, n0 = math.floor(ox + 0.5), math.floor(cx[k] + 0.5), ox, oy
            slope = dy / dx if dx != 0.0 else 0.0
        else:
            a0, a1, m0, n0 = math.floor(oy + 0.5), math.floor(cy[k] + 0.5), oy, ox
            slope = dx / dy
        step = 1 if a1 >= a0 else -1
        for a in range(a0, a1 + step, step):
            b = n0 + slope * (a - m0)
            ib = math.floor(b + 0.5)
            x, y = (a, ib) if x_major else (ib, a)
            r, c = y - j0, x - i0
            if 0 <= r < h and 0 <= c < w and abs(b - ib) <= core and lo[r, c] >= occ and \
                    (x - ox) ** 2 + (y - oy) ** 2 <= reach * reach:
                out.append((r, c))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_seen_through_kernel_equals_the_plain_walk(seed) -> None:
    """seen_through_structure_kernel (branch-free first pass, windowed walk) gives the cells of the plain walk above,
    in the same order, on random maps of long-occupied blobs with beams in every direction (both major axes, both
    signs), some not clearing, the laser inside and outside the grid, with and without depth."""

    rng = np.random.default_rng(seed)
    h, w, i0, j0 = 60, 80, -30, 7
    lo = rng.normal(-1.0, 2.0, size=(h, w)).astype(np.float32)
    for _ in range(25):
        r, c = rng.integers(0, h - 4), rng.integers(0, w - 4)
        lo[r:r + rng.integers(1, 5), c:c + rng.integers(1, 5)] = rng.uniform(5.0, 12.0)
    total = 0
    for ox, oy, depth in ((i0 + 40.3, j0 + 30.6, 0.0), (i0 + 12.5, j0 + 44.1, 1.5), (i0 - 6.2, j0 + 20.0, 0.0)):
        n = 361
        ang = np.sort(rng.uniform(-np.pi, np.pi, n))
        rng_m = rng.uniform(2.0, 60.0, n)
        cx = ox + rng_m * np.cos(ang)
        cy = oy + rng_m * np.sin(ang)
        clear = rng.random(n) < 0.9
        total += _walk_matches_plain(lo, i0, j0, ox, oy, cx, cy, clear, 0.4, depth)
    assert total > 100


def _walk_matches_plain(lo, i0, j0, ox, oy, cx, cy, clear, core, depth) -> int:
    """Run the kernel, assert its cells equal the plain walk's (same order), return how many it found."""
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel

    n = cx.shape[0]
    out_r = np.zeros(64 * n, dtype=np.int64)
    out_c = np.zeros(64 * n, dtype=np.int64)
    got = seen_through_structure_kernel(lo, i0, j0, ox, oy, cx, cy, clear, core, 6.0, out_r, out_c, depth)
    want = _seen_through_plain(lo, i0, j0, ox, oy, cx, cy, clear, core, 6.0, depth)
    assert list(zip(out_r[:got].tolist(), out_c[:got].tolist())) == want
    return got


def _free_steps_plain(lo, i0, j0, ox, oy, occ, cap):
    """``_free_steps`` as its docstring states it, line by line: per octant (+x, −x, +y, −y; the minor coordinate
    growing, shrinking) the largest d ≤ cap whose lines 0 … d from the laser's cell hold no cell ≥ occ from the
    laser's minor cell − 2 to + line + 2 on that side; −1 everywhere with the laser off the grid."""
    import math

    h, w = lo.shape
    c, r = math.floor(ox + 0.5) - i0, math.floor(oy + 0.5) - j0
    if not (0 <= r < h and 0 <= c < w):
        return [-1] * 8
    out = []
    for q in range(4):
        sgn = 1 if q % 2 == 0 else -1
        for side in range(2):
            d = 0
            while d <= cap:
                lo_b, hi_b = (-2, d + 2) if side == 0 else (-d - 2, 2)
                cells = [(r + b, c + sgn * d) if q < 2 else (r + sgn * d, c + b) for b in range(lo_b, hi_b + 1)]
                if any(0 <= rr < h and 0 <= cc < w and lo[rr, cc] >= occ for rr, cc in cells):
                    break
                d += 1
            out.append(min(d - 1, cap))
    return out


@pytest.mark.parametrize("seed", [3, 4])
def test_free_steps_equal_their_definition(seed) -> None:
    """mapevidence._free_steps (the free square by rings, then each octant's lines from its edge on) gives the
    definition's value on random maps of a few blobs (cells exactly at the threshold among them), the laser inside,
    on the edge of and outside the grid, on cell boundaries, with caps from 0 to 64 (pass det38)."""
    import math

    from dynslam2d.detect.mapevidence import _free_steps

    rng = np.random.default_rng(seed)
    positive = 0
    for _ in range(150):
        h, w = (int(v) for v in rng.integers(3, 90, 2))
        lo = rng.normal(-1.0, 1.5, size=(h, w)).astype(np.float32)
        for _ in range(int(rng.integers(0, 8))):
            r, c = rng.integers(0, h), rng.integers(0, w)
            lo[r:r + rng.integers(1, 4), c:c + rng.integers(1, 4)] = rng.choice([6.0, 7.5])
        i0, j0 = (int(v) for v in rng.integers(-50, 50, 2))
        ox, oy = i0 + rng.uniform(-4.0, w + 4.0), j0 + rng.uniform(-4.0, h + 4.0)
        if rng.random() < 0.3:
            ox, oy = math.floor(ox) + 0.5, math.floor(oy) - 0.5
        cap = int(rng.choice([0, 1, 3, 10, 64]))
        out = np.empty(8, dtype=np.int64)
        _free_steps(lo, i0, j0, ox, oy, 6.0, cap, out)
        want = _free_steps_plain(lo, i0, j0, ox, oy, 6.0, cap)
        assert out.tolist() == want
        positive += sum(v > 2 for v in want)
    assert positive > 200


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_seen_through_kernel_equals_the_plain_walk_in_open_space(seed) -> None:
    """The walk's first pass starts after the steps _free_steps finds free (pass det38): on sparse maps (a few
    long-occupied blobs at all distances from the laser, cells exactly at the threshold among them) the cells are
    still the plain walk's, in the same order, with beams in every direction, the laser anywhere in a cell (on its
    boundaries too), near the grid's edges and outside it, with and without depth."""
    import math


    rng = np.random.default_rng(seed)
    h, w, i0, j0 = 90, 110, -40, 12
    total = 0
    for trial in range(12):
        lo = rng.normal(-1.0, 1.0, size=(h, w)).astype(np.float32)
        for _ in range(int(rng.integers(2, 12))):
            r, c = rng.integers(0, h - 3), rng.integers(0, w - 3)
            lo[r:r + rng.integers(1, 4), c:c + rng.integers(1, 4)] = rng.choice([6.0, 9.0])
        ox, oy = i0 + rng.uniform(0.0, w), j0 + rng.uniform(0.0, h)
        if trial % 4 == 1:
            ox, oy = math.floor(ox) + 0.5, math.floor(oy) + 0.5
        elif trial % 4 == 2:
            ox, oy = i0 + rng.uniform(-0.5, 2.0), j0 + h - rng.uniform(0.6, 2.0)
        elif trial == 11:
            ox = i0 - 7.3
        n = 541
        ang = np.sort(rng.uniform(-np.pi, np.pi, n))
        ang[::37] = np.round(ang[::37] / (np.pi / 4)) * (np.pi / 4)  # (diagonals and axes: slopes ±1 and 0)
        rng_m = rng.uniform(5.0, 140.0, n)
        cx, cy = ox + rng_m * np.cos(ang), oy + rng_m * np.sin(ang)
        clear = rng.random(n) < 0.95
        depth = (0.0, 3.0)[trial % 2]
        total += _walk_matches_plain(lo, i0, j0, ox, oy, cx, cy, clear, 0.5, depth)
    assert total > 100
