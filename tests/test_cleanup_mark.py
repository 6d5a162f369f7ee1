"""The clean-up counter's ray marking (two loops, vectorised) and its bit-scan of the marked cells against the
one-loop walk, cell for cell (docs/speed.md, pass cln96)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.cleanup import _count_scan


def _walk(ox: float, oy: float, ex: float, ey: float, core: float, h: int, w: int) -> set[tuple[int, int]]:
    """The cells (row, col) of an h × w array the segment passes: the walk of one cell per step of the major axis
    where the segment runs within ``core`` of the cell centre (the counting rule of ``_count_scan``)."""
    dx, dy = ex - ox, ey - oy
    x_major = abs(dx) >= abs(dy)
    if x_major:
        a0, a1 = math.floor(ox + 0.5), math.floor(ex + 0.5)
        slope, m0, n0 = (dy / dx if dx != 0.0 else 0.0), ox, oy
    else:
        a0, a1 = math.floor(oy + 0.5), math.floor(ey + 0.5)
        slope, m0, n0 = dx / dy, oy, ox
    step = 1 if a1 >= a0 else -1
    out = set()
    for a in range(a0, a1 + step, step):
        b = n0 + slope * (float(a) - m0)
        ib = math.floor(b + 0.5)
        if abs(b - ib) <= core:
            x, y = (a, ib) if x_major else (ib, a)
            if 0 <= x < w and 0 <= y < h:
                out.add((y, x))
    return out


def test_passes_match_the_one_loop_walk() -> None:
    rng = np.random.default_rng(7)
    h, w, core = 37, 53, 0.35
    for trial in range(60):
        # the laser inside the array or outside it (the box clipped), rays in every direction, some leaving it
        ox, oy = rng.uniform(-10, w + 10), rng.uniform(-10, h + 10)
        if trial % 3 == 0:
            ox, oy = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
        n = int(rng.integers(1, 40))
        ang = rng.uniform(-np.pi, np.pi, n)
        ang[: n // 4] = rng.choice([0.0, np.pi / 2, np.pi, -np.pi / 2, np.pi / 4], n // 4)  # axis and diagonal rays
        length = rng.uniform(0.0, 70.0, n)
        cx, cy = ox + length * np.cos(ang), oy + length * np.sin(ang)
        counts = np.zeros((h, w, 3), dtype=np.uint16)
        last = np.zeros((h, w), dtype=np.uint16)
        _count_scan(counts, last, 1, ox, oy, np.zeros(0), np.zeros(0), cx, cy, core)
        want = np.zeros((h, w), dtype=np.uint16)
        for k in range(n):
            for y, x in _walk(ox, oy, float(cx[k]), float(cy[k]), core, h, w):
                want[y, x] = 1
        assert np.array_equal(counts[:, :, 1], want), trial
        assert np.array_equal(last, want * 2), trial  # a pass of scan 1 is touch 2


def test_hit_cells_get_no_pass_and_dense_rows() -> None:
    # a fan of rays from the middle marks whole words of the scratch (8 cells in a row), a few of them hit
    h, w, core = 40, 40, 0.5
    ox, oy = 20.0, 20.0
    ang = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    cx, cy = ox + 18.0 * np.cos(ang), oy + 18.0 * np.sin(ang)
    hx, hy = np.array([22.0, 25.0, 30.0]), np.array([20.0, 20.0, 20.0])
    counts = np.zeros((h, w, 3), dtype=np.uint16)
    last = np.zeros((h, w), dtype=np.uint16)
    _count_scan(counts, last, 1, ox, oy, hx, hy, cx, cy, core)
    want = np.zeros((h, w), dtype=np.uint16)
    for k in range(ang.size):
        for y, x in _walk(ox, oy, float(cx[k]), float(cy[k]), core, h, w):
            want[y, x] = 1
    want[20, [22, 25, 30]] = 0
    assert np.array_equal(counts[:, :, 1], want)
    assert counts[20, [22, 25, 30], 0].tolist() == [1, 1, 1]
