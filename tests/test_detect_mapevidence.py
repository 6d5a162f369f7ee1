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
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel

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
        out_r = np.zeros(64 * n, dtype=np.int64)
        out_c = np.zeros(64 * n, dtype=np.int64)
        got = seen_through_structure_kernel(lo, i0, j0, ox, oy, cx, cy, clear, 0.4, 6.0, out_r, out_c, depth)
        want = _seen_through_plain(lo, i0, j0, ox, oy, cx, cy, clear, 0.4, 6.0, depth)
        assert list(zip(out_r[:got].tolist(), out_c[:got].tolist())) == want
        total += got
    assert total > 100
