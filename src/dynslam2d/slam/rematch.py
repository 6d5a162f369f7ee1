"""Re-matching of keyframes against the map of their optimised predecessors (after the loop closure).

A loop only corrects the keyframe chain as a whole between the keyframes it ties; a local break of the
front end (a scan that slid along a corridor, or jumped to a look-alike and back, with no loop right there)
stays in the chain. After the final optimisation each keyframe ``b`` is matched once more, in order,
against a local map rendered from the ``rematch_window`` keyframes before it at their current (optimised,
and already re-matched) poses: correlative search around the chain's pose, then Gauss–Newton, the same
acceptance as a loop (score, margin over the runner-up, support). Where the match disagrees with the
chain by more than ``rematch_min_shift`` / ``rematch_min_turn`` it becomes an edge (b−1, b) under the
robust kernel, and the keyframes from ``b`` on are moved with it so that the next local maps are built from
the repaired poses; the graph is optimised again afterwards. See docs/slam.md, "Intel: where the error is".

Only keyframes near where a break can be are matched (:func:`selected`, unless ``rematch_all``): within
``rematch_neighbours`` keyframes of an edge across a weak or low-scoring front-end match (or one without a
score), or of an edge the optimisation bent away from the front end's relative pose. A keyframe left out is
one whose match would not have changed anything unless the front end broke there without noticing.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from dynslam2d.slam.correlative import correlative_search
from dynslam2d.slam.grid import MultiResMap
from dynslam2d.slam.matcher import match_multires, support
from dynslam2d.slam.posegraph import compose, diag_info, relative
from dynslam2d.types import Pose2D

if TYPE_CHECKING:
    from dynslam2d.slam.config import SlamConfig
    from dynslam2d.slam.grid import GridLevel
    from dynslam2d.slam.loopconfig import LoopConfig
    from dynslam2d.slam.loops import LoopCloser


def refine_supported(levels: list[GridLevel], pts: np.ndarray, seed: np.ndarray, max_shift: float, c: LoopConfig,
                     sc: SlamConfig) -> tuple[np.ndarray, int] | None:
    """A correlative match ``seed`` (x, y, θ in the levels' frame, m / rad) of points ``pts`` (laser frame, m)
    refined by Gauss–Newton on ``levels``, and its supporting point count; None when the refinement is not
    finite, moves more than ``max_shift`` m from the seed, or the support (count, share of ``pts``, angular
    spread) is below the loop acceptance's minimums (``loop.min_support``, ``min_support_share``,
    ``min_spread``). Shared by the loop search (:mod:`dynslam2d.slam.loops`) and the re-match."""
    p = match_multires(levels, pts, seed, sc.iterations_coarse, sc.iterations_finest, False,
                       sc.step_mode == "lm", sc.lm_lambda_init, sc.lm_lambda_max, sc.max_rotation_step,
                       sc.max_translation_step)
    if not np.all(np.isfinite(p)) or math.hypot(p[0] - seed[0], p[1] - seed[1]) > max_shift:
        return None
    n_sup, spread = support(levels[0], pts, p, sc.support_probability)
    if n_sup < c.min_support or n_sup < c.min_support_share * pts.shape[0] or spread < c.min_spread:
        return None
    return p, n_sup

def _local_map(closer: LoopCloser, poses: np.ndarray, first: int, last: int, anchor: np.ndarray,
               grid: MultiResMap | None = None) -> MultiResMap:
    """Grid of keyframes first … last (inclusive) at ``poses`` (n, 3; world, m / rad), in ``anchor``'s frame
    (added to ``grid`` if given)."""
    sc = closer.slam
    c = closer.config
    if grid is None:
        grid = MultiResMap(sc.map_resolution, max(c.search_level + 1, 2), sc.logodds_free, sc.logodds_occupied,
                           sc.occupied_logodds_cap, sc.map_growth_margin)
    for k in range(first, last + 1):
        pts, _ = closer._points(closer.keyframes[k])
        if pts.shape[0]:
            rel = relative(anchor, poses[k])
            grid.integrate(Pose2D(float(rel[0]), float(rel[1]), float(rel[2])), pts)
    return grid


def _match(closer: LoopCloser, grid: MultiResMap, pts: np.ndarray, pred: np.ndarray) -> np.ndarray | None:
    """Keyframe points ``pts`` (laser frame, m) matched in ``grid`` around ``pred`` (grid frame): the refined
    pose, or None when score, margin or support fail the loop acceptance (LoopConfig)."""
    c = closer.config
    sc = closer.slam
    lvl = grid.levels[min(c.search_level, len(grid.levels) - 1)]
    cr = correlative_search(lvl, pts, pred, c.rematch_linear_window, c.rematch_angular_window, None,
                            c.search_points, sc.correlative_max_height, 0.0, 0.0,
                            runner_up_distance=c.runner_up_distance, runner_up_angle=c.runner_up_angle)
    if cr is None or cr.score < c.min_score or cr.score - (cr.runner_up or 0.0) < c.min_margin:
        return None
    refined = refine_supported(grid.levels[: max(c.search_level + 1, 2)], pts, cr.pose, 2 * lvl.resolution, c, sc)
    return None if refined is None else np.asarray(refined[0], dtype=np.float64)


def selected(closer: LoopCloser) -> np.ndarray:
    """(n,) bool: keyframes to re-match. Marked: the edge into a keyframe spans a weak front-end match or a
    match score below ``rematch_score`` (or none given), or the optimised relative pose of the keyframe to the one
    before it differs from the front end's edge by more than ``rematch_bend_shift`` m / ``rematch_bend_turn`` rad
    (the loops bent the chain there); selected: within ``rematch_neighbours`` keyframes of a marked one."""
    c = closer.config
    g = closer.graph
    n = len(closer.keyframes)
    if c.rematch_all:
        return np.ones(n, dtype=bool)
    score = np.asarray(closer.kf_score, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        mark = np.asarray(closer.kf_weak, dtype=bool) | ~(score >= c.rematch_score)  # NaN (no score) marks
    mark[0] = False
    for e in g.edges:
        if e.loop or e.j != e.i + 1 or not e.active:
            continue
        d = relative(e.z, relative(g.poses[e.i], g.poses[e.j]))
        if math.hypot(d[0], d[1]) > c.rematch_bend_shift or abs(d[2]) > c.rematch_bend_turn:
            mark[e.j] = True
    sel = mark.copy()
    for s in range(1, min(c.rematch_neighbours, n - 1) + 1):  # grow by the neighbours on either side
        sel[s:] |= mark[:-s]
        sel[:-s] |= mark[s:]
    return sel


def rematch_keyframes(closer: LoopCloser) -> tuple[int, int]:
    """Re-match the :func:`selected` keyframes, in order, against their predecessors' map at the graph's current
    poses and add an edge (b−1, b) for each that disagrees with the chain (module docstring). Does not optimise.
    Returns (edges added, keyframes matched)."""
    c = closer.config
    g = closer.graph
    n = len(closer.keyframes)
    if n < 2:
        return 0, 0
    sel = selected(closer)
    work = g.poses.copy()
    info = diag_info(c.loop_sigma_xy, c.loop_sigma_theta)
    chain = {e.i: k for k, e in enumerate(g.edges) if not e.loop and e.j == e.i + 1}
    added = 0
    checked = 0
    w = c.rematch_window
    # the local map: keyframes lo … last in the frame whose pose (world) is ``frame``; kept for the next keyframe
    # while it holds at most rematch_window + rematch_reuse keyframes (a repair moves only keyframes after ``last``)
    grid: MultiResMap | None = None
    lo = last = -1
    frame = work[0]
    for b in range(1, n):
        if not sel[b]:
            continue
        pts, _ = closer._points(closer.keyframes[b])
        if pts.shape[0] < c.min_support:
            continue
        anchor = work[b - 1]
        checked += 1
        first = max(0, b - w)
        if c.rematch_reuse and grid is not None and lo >= b - w - c.rematch_reuse and last + 1 >= first:
            grid = _local_map(closer, work, last + 1, b - 1, frame, grid)
        else:
            frame = anchor.copy()
            lo = first
            grid = _local_map(closer, work, first, b - 1, frame)
        last = b - 1
        pred = relative(frame, work[b])
        zf = _match(closer, grid, pts, pred)
        if zf is None:
            continue
        d = relative(pred, zf)
        z = relative(anchor, compose(frame, zf))  # keyframe b seen from b − 1
        if math.hypot(d[0], d[1]) < c.rematch_min_shift and abs(d[2]) < c.rematch_min_turn:
            continue
        g.add_edge(b - 1, b, z, info, robust=not c.rematch_replace)
        k = chain.get(b - 1)
        if k is not None:
            if c.rematch_replace:
                g.edges[k].active = False
            else:
                g.edges[k].robust = True
        added += 1
        # keyframes b … n−1 follow the repaired pose rigidly (the next local maps are built from them)
        new_b = compose(anchor, z)
        work[b:] = compose(new_b, relative(work[b], work[b:]))
    return added, checked
