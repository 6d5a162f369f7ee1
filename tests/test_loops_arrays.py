"""The loop closer's array forms of its per-keyframe bookkeeping give what the per-item Python gave, bit for bit:
the place descriptor's points of several keyframes (loops._place_points) and the edge weights the far search sums
(loops._EdgeTable)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.loops import _EdgeTable, _place_points


def test_place_points_equal_the_per_keyframe_expression_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    for _ in range(100):
        k = int(rng.integers(1, 12))
        rel = rng.normal(0.0, 3.0, (k, 3))
        pts = [rng.normal(0.0, 5.0, (int(rng.integers(0, 120)), 2)).astype(np.float32) for _ in range(k)]
        parts = []
        for (x, y, th), q in zip(rel, pts):
            ct, st = math.cos(th), math.sin(th)
            parts.append(np.c_[x + ct * q[:, 0] - st * q[:, 1], y + st * q[:, 0] + ct * q[:, 1]])
        ref = np.vstack(parts)
        got = _place_points(rel, pts)
        assert got.dtype == np.float64 and got.shape == ref.shape
        assert np.array_equal(ref.view(np.uint64), got.view(np.uint64))
    # the products are float32 (a float64 product would differ in the last bits for most points)
    q = np.array([[1.1, 2.3]], dtype=np.float32)
    assert _place_points(np.array([[0.0, 0.0, 0.3]]), [q])[0, 0] == 0.0 + np.float32(math.cos(0.3)) * q[0, 0] - (
        np.float32(math.sin(0.3)) * q[0, 1])
    assert _place_points(np.zeros((0, 3)), []).shape == (0, 2)


def test_edge_table_keeps_the_dicts_order_values_and_minima() -> None:
    table = _EdgeTable()
    sigma: dict[tuple[int, int], float] = {}
    turn: dict[tuple[int, int], float] = {}
    rng = np.random.default_rng(2)
    for n in range(1, 200):  # more edges than the first capacity: the arrays grow
        s, t = float(rng.uniform(0.01, 0.1)), float(rng.uniform(0.0, 0.05))
        table.set((n - 1, n), s, t)
        sigma[(n - 1, n)], turn[(n - 1, n)] = s, t
        if n % 7 == 0:  # a loop, sometimes onto an existing chain edge (the smaller weight stays, per column)
            key = (n - 1, n) if n % 14 == 0 else (n // 2, n)
            s, t = 0.05, float(rng.uniform(0.0, 0.05))
            table.set(key, s, t, keep_min=True)
            sigma[key] = min(sigma.get(key, math.inf), s)
            turn[key] = min(turn.get(key, math.inf), t)
    ij, w = table.arrays()
    assert len(table) == len(sigma) == ij.shape[0]
    assert ij.tolist() == [list(k) for k in sigma]
    assert w[:, 0].tolist() == list(sigma.values()) and w[:, 1].tolist() == list(turn.values())
