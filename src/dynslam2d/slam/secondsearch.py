"""The second far loop search: after the final optimisation and the keyframe re-match (docs/slam.md, "Intel: where
the error is").

During the run the far search looks for a keyframe's place in older submaps only while no loop was found for
``far_after`` m, and around the pose the graph estimated *then*. A part of the run that the front end tied to the
rest only through a stretch where it lost the map (a wing visited at the start, its return much later) can stay
metres and a radian off: when the robot comes back, the loops it is already closing elsewhere keep the far search
off, and the local search's window cannot cover the error. After the final optimisation (and the re-match) the
graph's poses are much better, and the graph says which pairs it does not tie yet: a keyframe and an older submap
whose every path along the graph (keyframe chain and accepted loops) crosses a weak front-end match.

So every stored place (every ``place_every``-th keyframe, on the ``search_every`` grid) is searched once more with
the far search's machinery — the place descriptor ranking, the all-rotation correlative search on ``far_level``,
the uncertainty gates, the verification by ``far_partners`` consistent partners (spanning ``second_partner_span``)
— but only against the submaps that every path along the graph to the keyframe reaches across a weak or
low-scoring front-end match (:func:`ties`; ``second_searches`` of them per keyframe). Pairs the loops and the
well-supported chain already tie are not searched: on a log without weak matches (MIT CSAIL) the pass searches
nothing. A pair that already has a loop edge gets no second one. The graph is optimised once after the round (after
every verified loop with ``second_optimise_each``: then each search starts from a slightly different graph, which
made the Intel result less stable); a next round (``second_rounds``) searches only from the keyframes whose far
candidates could not be verified, and ``second_rematch`` re-matches the keyframes after a round that added loops.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from dynslam2d.slam.rematch import rematch_keyframes

if TYPE_CHECKING:
    from dynslam2d.slam.loops import LoopCloser


def ties(closer: LoopCloser) -> np.ndarray:
    """(n_nodes,) int: a label per node, equal for the nodes that a path along the graph (accepted loops, re-match
    edges, keyframe edges) connects without crossing a keyframe edge across a weak front-end match or a match score
    below ``weak_score``: nodes with different labels are the pairs the loops do not tie yet (connected components
    of the graph without those edges)."""
    from scipy.sparse import coo_matrix

    from dynslam2d.lazyscipy import connected_components

    c = closer.config
    g = closer.graph
    n = g.n_nodes
    weak = np.asarray(closer.kf_weak, dtype=bool)
    with np.errstate(invalid="ignore"):
        weak = weak | (np.asarray(closer.kf_score, dtype=np.float64) < c.weak_score)
    ii, jj = [], []
    seen: set[int] = set()
    for e in g.edges:
        front = not e.loop and e.j == e.i + 1 and e.j not in seen  # the front end's edge (the first one into j)
        if front:
            seen.add(e.j)
        if e.active and not (front and weak[e.j]):
            ii.append(e.i)
            jj.append(e.j)
    m = coo_matrix((np.ones(len(ii)), (ii, jj)), shape=(n, n)).tocsr()
    return connected_components(m, directed=False)[1]


def untied(closer: LoopCloser, node: int) -> np.ndarray:
    """(n_nodes,) bool: the nodes whose every path along the graph to ``node`` crosses a weak or low-scoring front-end
    match (:func:`ties`)."""
    labels = ties(closer)
    return labels != labels[node]


def second_search(closer: LoopCloser, nodes: set[int] | None = None) -> tuple[int, int, set[int]]:
    """One round of the second far search over every ``search_every``-th stored place of ``closer`` (module
    docstring), or over ``nodes`` only. Loops are accepted as they are verified (the graph optimised after each if
    ``second_optimise_each``); pending candidates are tried on the keyframes after them. Does not run the final
    optimisation. Returns (far searches made, loop edges accepted, the keyframes whose far candidates were not
    verified)."""
    c = closer.config
    n = len(closer.keyframes)
    searches0 = closer.stats["far_searches"]
    loops0 = closer.stats["loops_accepted"]
    closer._pending = []
    cache0 = closer._cache_size
    closer._cache_size = max(cache0, c.second_cache)
    closer._second = {(e.i, e.j) for e in closer.graph.edges if e.loop}
    closer._second_tried = []
    # queries must be stored places: the returns of older keyframes that a new descriptor would need are gone
    step = math.lcm(c.search_every, c.place_every) if closer._places is not None else c.search_every
    labels: np.ndarray | None = None
    n_loops = 0.0
    k = c.submap_keyframes
    anchors = np.arange(n // k, dtype=np.int64) * k + k // 2  # every submap's anchor, last node and its path (m)
    last = anchors - k // 2 + k - 1
    last_path = np.array([closer.keyframes[int(j)].path for j in last], dtype=np.float64)
    for node in range(c.submap_keyframes, n):
        if closer._pending:
            closer._pending_far(node)
        if node % step if nodes is None else node not in nodes:
            continue
        pts = closer._query(closer.keyframes[node])
        if pts is None:
            continue
        if labels is None or closer.stats["loops_accepted"] != n_loops:  # new loops tie more pairs
            labels, n_loops = ties(closer), closer.stats["loops_accepted"]
        allowed = labels != labels[node]
        # an untied submap the far search would consider at all (finished, far enough along the path): else the
        # graph uncertainty and the place ranking of this keyframe are not worth computing
        n_sub = (node + 1) // k
        path = closer.keyframes[node].path
        if n_sub and np.any(allowed[anchors[:n_sub]] & (last[:n_sub] < node)
                            & (path - last_path[:n_sub] >= c.min_path_gap)):
            closer._far_search(node, closer._estimate(node), pts, set(), allowed, c.second_searches)
    closer._pending = []
    failed = {cand.node for cand in closer._second_tried if not cand.accepted}
    closer._second = closer._second_tried = None
    closer._cache_size = cache0
    while len(closer._cache) > cache0:
        closer._cache.popitem(last=False)
    return int(closer.stats["far_searches"] - searches0), int(closer.stats["loops_accepted"] - loops0), failed


def run_second_search(closer: LoopCloser) -> None:
    """Up to ``second_rounds`` rounds of :func:`second_search`, each followed by a full optimisation, while a round
    adds loops: the first over every stored place, the next ones only from the keyframes whose far candidates the
    round before could not verify (the graph the new loops corrected may verify them); counters in ``closer.stats``
    (``second_searches``, ``second_loops``, ``second_rounds``, ``second_ms``)."""
    t0 = time.perf_counter()
    nodes: set[int] | None = None
    for _ in range(closer.config.second_rounds):
        searches, loops, nodes = second_search(closer, nodes)
        closer.stats["second_searches"] += searches
        closer.stats["second_loops"] += loops
        closer.stats["second_rounds"] += 1
        if not loops:
            break
        closer._optimise(final=True)
        if closer.config.second_rematch:
            # the keyframes the new loops moved, matched again against their predecessors (slam/rematch.py)
            edges, checked = rematch_keyframes(closer)
            closer.stats["rematch_edges"] += edges
            closer.stats["rematch_checked"] += checked
            if edges:
                closer._optimise(final=True)
        if not nodes:
            break
    closer.stats["second_ms"] += (time.perf_counter() - t0) * 1e3
