"""The far search's graph distances in one kernel (slam/graphdist.py) against SciPy's Dijkstra, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from dynslam2d.slam.graphdist import graph_distances


def _scipy(ij: np.ndarray, w: np.ndarray, n: int, node: int, limit0: float) -> tuple[np.ndarray, np.ndarray]:
    """What ``LoopCloser._uncertainty`` computed before the kernel (two CSR matrices, two ``dijkstra`` calls)."""
    out = []
    for col, limit in ((0, limit0), (1, np.inf)):
        if not ij.shape[0]:
            d = np.full(n, np.inf)
            d[node] = 0.0
        else:
            m = coo_matrix((w[:, col] + 1e-9, (ij[:, 0], ij[:, 1])), shape=(n, n)).tocsr()
            d = dijkstra(m, directed=False, indices=node, limit=limit)
        out.append(d)
    return out[0], out[1]


def _graph(rng: np.random.Generator, n: int, loops: int, isolated: int) -> tuple[np.ndarray, np.ndarray]:
    """A keyframe chain over the first n − isolated nodes plus random loop edges (unique (min, max) keys, as the loop
    closer's edge table), weights of very different scales, some zero."""
    keys = {(k, k + 1) for k in range(n - isolated - 1)}
    m = n - isolated
    loops = min(loops, m * (m - 1) // 2 - (m - 1))  # (no more loop edges than node pairs off the chain)
    while len(keys) < m - 1 + loops:
        a, b = sorted(rng.integers(0, n - isolated, 2).tolist())
        if a != b:
            keys.add((a, b))
    ij = np.array(sorted(keys, key=lambda _: rng.random()), dtype=np.int64).reshape(-1, 2)
    w = rng.random((ij.shape[0], 2)) * rng.choice([1e-3, 0.1, 3.0], (ij.shape[0], 2))
    w[rng.random(w.shape) < 0.1] = 0.0
    return ij, w


@pytest.mark.parametrize("seed", range(40))
def test_the_kernel_gives_scipys_distances_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 400))
    ij, w = _graph(rng, n, int(rng.integers(0, 30)), int(rng.integers(0, 3)) if n > 4 else 0)
    node = int(rng.integers(0, n))
    ref0, ref1 = _scipy(ij, w, n, node, np.inf)
    # limits: none, a few random ones, and each exactly at a reached distance (kept: SciPy keeps sums ≤ limit)
    finite = np.unique(ref0[np.isfinite(ref0)])
    limits = [np.inf, 0.0, float(rng.random())] + rng.choice(finite, min(5, finite.size)).tolist()
    for limit in limits:
        ref0, ref1 = _scipy(ij, w, n, node, limit)
        d = graph_distances(ij, w, n, node, limit)
        assert d.shape == (2, n)
        assert d[0].tobytes() == ref0.tobytes(), limit
        assert d[1].tobytes() == ref1.tobytes()
    if finite.size > 1:  # the limit at a distance keeps that node; just below it drops it (inf)
        lim = float(finite[1])
        on = graph_distances(ij, w, n, node, lim)[0]
        below = graph_distances(ij, w, n, node, float(np.nextafter(lim, -np.inf)))[0]
        assert np.count_nonzero(on == lim) >= 1 and np.count_nonzero(below == lim) == 0


def test_without_edges_only_the_source_is_reached() -> None:
    d = graph_distances(np.zeros((0, 2), dtype=np.int64), np.zeros((0, 2)), 5, 3, 2.0)
    assert d.tolist() == [[np.inf, np.inf, np.inf, 0.0, np.inf]] * 2


def test_a_shorter_path_through_more_edges_wins() -> None:
    # 0 – 1 direct at 1.0 and 0 – 2 – 1 at 0.25 + 0.25: the kernel must take the two-edge path (+ 1e-9 per edge)
    ij = np.array([[0, 1], [0, 2], [1, 2]], dtype=np.int64)
    w = np.array([[1.0, 0.1], [0.25, 0.5], [0.25, 0.5]])
    d = graph_distances(ij, w, 3, 0, np.inf)
    assert d[0, 1] == (0.0 + (0.25 + 1e-9)) + (0.25 + 1e-9)
    assert d[1, 1] == 0.0 + (0.1 + 1e-9)
