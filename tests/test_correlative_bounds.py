"""Correlative search with the caller's acceptance bounds (``min_score``, ``min_margin``): the loop closer's one
search must give the candidates of a plain search followed by a runner-up search (slam/correlative.py)."""

from __future__ import annotations

import math

import numpy as np
from conftest import paper_room_slam_points

from dynslam2d.slam import HectorSlam
from dynslam2d.slam.correlative import correlative_search


def _level_and_points() -> tuple[HectorSlam, np.ndarray]:
    return paper_room_slam_points()


def _starts(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    return [np.array([rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi)])
            for _ in range(n)]


def test_min_score_gives_the_plain_search_or_none() -> None:
    slam, pts = _level_and_points()
    rng = np.random.default_rng(3)
    kept = refused = 0
    for level in (1, 2):
        lv = slam.map.levels[level]
        for start in _starts(rng, 12):
            for lin, ang in ((0.6, 0.3), (1.5, math.pi)):
                plain = correlative_search(lv, pts, start, lin, ang, None, 180, 4, 0.0, 0.0)
                assert plain is not None
                for t in (0.2, plain.score, math.nextafter(plain.score, 2.0), 0.55, 0.8):
                    got = correlative_search(lv, pts, start, lin, ang, None, 180, 4, 0.0, 0.0, min_score=t)
                    if plain.score < t:
                        assert got is None
                        refused += 1
                    else:
                        assert got is not None and got.score == plain.score
                        np.testing.assert_array_equal(got.pose, plain.pose)
                        kept += 1
    assert kept > 20 and refused > 20


def test_min_margin_stops_only_searches_that_lose_the_margin() -> None:
    slam, pts = _level_and_points()
    rng = np.random.default_rng(5)
    lost = won = 0
    lv = slam.map.levels[2]
    for start in _starts(rng, 16):
        for wrap in (False, True):
            kw = dict(runner_up_distance=0.6, runner_up_angle=0.25, runner_up_wrap=wrap)
            plain = correlative_search(lv, pts, start, 1.5, math.pi, None, 180, 4, 0.0, 0.0, **kw)
            margin = plain.score - (plain.runner_up or 0.0)
            for m in (0.0, 0.05, margin, math.nextafter(margin, 1.0), 0.15, 0.3):
                got = correlative_search(lv, pts, start, 1.5, math.pi, None, 180, 4, 0.0, 0.0, **kw,
                                         min_score=0.0, min_margin=m)
                assert got is not None and got.score == plain.score
                np.testing.assert_array_equal(got.pose, plain.pose)
                if margin >= m:  # accepted: the runner-up exactly as without the bound
                    assert got.runner_up == plain.runner_up
                    np.testing.assert_array_equal(got.runner_up_pose, plain.runner_up_pose)
                    won += 1
                else:  # refused either way; the early runner-up is no better than the real one
                    assert got.score - (got.runner_up or 0.0) < m
                    assert got.runner_up <= plain.runner_up
                    lost += 1
    assert won > 10 and lost > 10


def test_min_score_near_the_maps_lower_edge() -> None:
    """Points read at negative cell indices (the map's lower edges): the search runs without the pruning there
    and still gives the plain search's pose."""
    slam, pts = _level_and_points()
    lv = slam.map.levels[2]
    lo = lv.pose_to_world(np.array([2.0, 2.0, 0.0]))  # 2 cells inside the lower-left corner
    n = 0
    for th in np.linspace(-math.pi, math.pi, 9):
        start = np.array([lo[0], lo[1], th])
        plain = correlative_search(lv, pts, start, 1.0, 0.4, None, 180, 4, 0.0, 0.0)
        if plain is None:
            continue
        got = correlative_search(lv, pts, start, 1.0, 0.4, None, 180, 4, 0.0, 0.0, min_score=plain.score)
        assert got is not None and got.score == plain.score
        np.testing.assert_array_equal(got.pose, plain.pose)
        n += 1
    assert n > 5



def test_accept_turn_refuses_only_searches_the_caller_refuses() -> None:
    """``accept_turn`` (the far search's rotation limit): the search either gives the plain search's result bit for
    bit, or refuses one the caller refuses too — below ``min_score``, margin below ``min_margin``, or a best pose
    turned from the start by more than ``accept_turn`` (less one rotation step: the search's grid). The limits are
    set at and around each search's own best score, margin and turn, so that a pre-check refusing a little too
    much (a higher score or margin, fewer rotations) fails."""
    slam, pts = _level_and_points()
    rng = np.random.default_rng(17)
    same = refused = passed_inside = refused_outside = 0
    for level in (1, 2):
        lv = slam.map.levels[level]
        # the scan was taken 0.1 rad turned from the map's first pose: starts near that heading and anywhere
        starts = _starts(rng, 6) + [np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5),
                                              0.1 + rng.uniform(-0.8, 0.8)]) for _ in range(6)]
        for start in starts:
            ru = dict(runner_up_distance=0.6, runner_up_angle=0.25, runner_up_wrap=True)
            free = correlative_search(lv, pts, start, 1.5, math.pi, None, 180, 4, 0.0, 0.0, **ru)
            margin = free.score - (free.runner_up or 0.0)
            turn = abs(math.remainder(free.pose[2] - start[2], math.tau))
            step = 2.0 * math.pi / (free.n_rotations - 1)
            for min_score in (free.score - 0.1, free.score, math.nextafter(free.score, 2.0)):
                for min_margin in (0.0, margin - 0.02, margin, math.nextafter(margin, 1.0)):
                    kw = dict(**ru, min_score=min_score, min_margin=min_margin)
                    plain = correlative_search(lv, pts, start, 1.5, math.pi, None, 180, 4, 0.0, 0.0, **kw)
                    ok = plain is not None and plain.score - (plain.runner_up or 0.0) >= min_margin
                    for accept in (turn - step, turn, turn + step, 0.5, 0.9):
                        got = correlative_search(lv, pts, start, 1.5, math.pi, None, 180, 4, 0.0, 0.0, **kw,
                                                 accept_turn=accept)
                        if got is not None:
                            assert plain is not None and got.score == plain.score
                            assert got.runner_up == plain.runner_up
                            np.testing.assert_array_equal(got.pose, plain.pose)
                            np.testing.assert_array_equal(got.runner_up_pose, plain.runner_up_pose)
                            same += 1
                            passed_inside += ok and turn <= accept
                        else:
                            refused += 1
                            if ok:  # a pose the caller accepts on score and margin: only when it turns too far
                                assert turn > accept - 1e-9
                                refused_outside += 1
    assert same > 100 and refused > 100 and passed_inside > 30 and refused_outside > 10
