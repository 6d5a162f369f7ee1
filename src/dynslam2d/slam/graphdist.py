"""Shortest-path sums over the loop closer's pose graph (the far search's uncertainty radius, slam/loops.py).

One kernel call gives, from one node, the summed edge weights along the shortest paths of an undirected graph for two
weights per edge (Dijkstra 1959, a binary heap with repeated entries instead of a decrease-key). It replaces two
``scipy.sparse.csgraph.dijkstra`` calls on a CSR matrix built per call (≈ 1 ms per far search in the pipeline, most of
it SciPy's matrix construction and argument checks) with the same values: with non-negative weights any correct
Dijkstra returns, per node, the smallest left-to-right float64 sum over all paths (rounding is monotone, so the
settled value of a node is ``d[u] + w`` of the best predecessor, whatever the order of the relaxations), and a
node whose sum exceeds the limit is ``inf``, as SciPy's ``limit`` (a relaxation is kept only when ``≤ limit``).
"""

from __future__ import annotations

import numpy as np

from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle


@njit(cache=True)
def graph_distances(ij: np.ndarray, w: np.ndarray, n: int, source: int, limit0: float) -> np.ndarray:
    """(2, n) float64: row k the shortest-path sums of weight column k of ``w`` (m, 2) from node ``source`` over the
    undirected edges ``ij`` (m, 2) int64 (node indices < ``n``), each weight + 1e-9 (what the loop closer gave SciPy,
    which drops zero weights); row 0 only up to ``limit0`` (beyond it ``inf``), row 1 without a limit.
    Unreachable nodes are ``inf``."""
    m = ij.shape[0]
    # adjacency in CSR form, both directions of every edge
    deg = np.empty(n + 1, dtype=np.int64)
    deg[:] = 0
    for e in range(m):
        deg[ij[e, 0] + 1] += 1
        deg[ij[e, 1] + 1] += 1
    for v in range(n):
        deg[v + 1] += deg[v]
    nbr = np.empty(2 * m, dtype=np.int64)
    eid = np.empty(2 * m, dtype=np.int64)
    fill = deg[:n].copy()
    for e in range(m):
        a, b = ij[e, 0], ij[e, 1]
        nbr[fill[a]] = b
        eid[fill[a]] = e
        fill[a] += 1
        nbr[fill[b]] = a
        eid[fill[b]] = e
        fill[b] += 1
    out = np.empty((2, n))
    hv = np.empty(2 * m + 1)  # heap of (value, node); a node may sit in it more than once (stale entries skipped)
    hn = np.empty(2 * m + 1, dtype=np.int64)
    done = np.empty(n, dtype=np.bool_)
    done[:] = False
    for col in range(2):
        limit = limit0 if col == 0 else np.inf
        d = out[col]
        for v in range(n):
            d[v] = np.inf
            done[v] = False
        d[source] = 0.0
        hv[0] = 0.0
        hn[0] = source
        size = 1
        while size > 0:
            val = hv[0]
            u = hn[0]
            size -= 1
            if size > 0:  # the last entry sifted down from the root
                lv, ln = hv[size], hn[size]
                i = 0
                while True:
                    c = 2 * i + 1
                    if c >= size:
                        break
                    if c + 1 < size and hv[c + 1] < hv[c]:
                        c += 1
                    if hv[c] < lv:
                        hv[i] = hv[c]
                        hn[i] = hn[c]
                        i = c
                    else:
                        break
                hv[i] = lv
                hn[i] = ln
            if done[u] or val > d[u]:
                continue
            done[u] = True
            for k in range(deg[u], deg[u + 1]):
                v = nbr[k]
                if done[v]:
                    continue
                nv = val + (w[eid[k], col] + 1e-9)
                if nv <= limit and nv < d[v]:
                    d[v] = nv
                    i = size  # sift up
                    size += 1
                    while i > 0:
                        p = (i - 1) // 2
                        if hv[p] > nv:
                            hv[i] = hv[p]
                            hn[i] = hn[p]
                            i = p
                        else:
                            break
                    hv[i] = nv
                    hn[i] = v
    return out
