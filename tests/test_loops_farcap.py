"""The far search's place-distance caps (``loop.far_max_place_distance``, ``loop.far_best_place_distance``;
slam/loops.py ``_far_pick``): submaps whose places look too unlike the keyframe's are not searched."""

from __future__ import annotations

import math

import numpy as np
import pydantic
import pytest
from test_loops_place import _jumped_front_end

from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.loops import LoopCloser
from dynslam2d.types import Pose2D

_OFF = {"far_max_place_distance": 2.0}


@pytest.fixture(scope="module")
def jumped() -> tuple:
    """A lap and a bit around the cluttered block whose front end jumps 7 m at scan 250 (flagged weak):
    far searches run from 20 m of path on, and only a far search ties the keyframes after the jump back."""
    return _jumped_front_end()


class _Old(LoopCloser):
    """The far search's choice before the caps: the first ``count`` eligible submaps."""

    def _far_pick(self, node, elig, count):  # noqa: ANN001, ANN202
        return elig[:count]


def _run(data: tuple, cls: type = LoopCloser, **settings: object) -> tuple:
    """(closer, result, keyframe errors m, the run's far searches as (node, submap, place distance, best-ranked))."""
    gt, front, scans = data
    lc = cls(LoopConfig(**settings), SlamConfig())
    searched: list[tuple[int, int, float, bool]] = []
    pick, match = lc._far_pick, lc._match_at
    first: dict[int, int] = {}

    def watched_pick(node, elig, count):  # noqa: ANN001, ANN202
        if elig[:count]:
            first[node] = elig[0][2]
        return pick(node, elig, count)

    def watched_match(node, s, pts, pred, lin, ang, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        if ang == math.pi and lc._second is None:  # a far search during the run
            searched.append((node, s, lc._place_cover(node, s), first.get(node) == s))
        return match(node, s, pts, pred, lin, ang, *a, **k)

    lc._far_pick, lc._match_at = watched_pick, watched_match  # type: ignore[method-assign]
    for k, (s, p) in enumerate(zip(scans, front)):
        lc.add(s.stamp, Pose2D(*p), s, np.zeros(s.ranges.shape, bool), keyframe=k % 2 == 0, weak=k == 251)
    res = lc.finish()
    err = np.hypot(*(res.poses[res.keyframe_scans, :2] - gt[res.keyframe_scans, :2]).T)
    return lc, res, err, searched


@pytest.fixture(scope="module")
def uncapped(jumped: tuple) -> tuple:
    return _run(jumped, **_OFF)


def test_cap_off_is_the_search_before(jumped: tuple, uncapped: tuple) -> None:
    """``far_max_place_distance: 2`` searches every submap the ranking picks, as before the caps: the same far
    searches, loops and poses as the closer whose choice is the plain first ``far_searches``."""
    lc, res, err, searched = uncapped
    old, res_old, _err, searched_old = _run(jumped, _Old, **_OFF)
    assert lc.stats["far_skipped"] == 0 and lc.stats["far_searches"] == old.stats["far_searches"] >= 20
    assert searched == searched_old
    assert np.array_equal(res.poses, res_old.poses) and lc.stats["far_loops"] == old.stats["far_loops"] >= 3
    assert err.max() < 0.05
    # the run searched places both below and above the caps used below (else those tests could not fail)
    d = sorted(x[2] for x in searched)
    assert d[0] < d[len(d) // 2] < d[-1]


def test_submaps_above_the_cap_are_not_searched(jumped: tuple, uncapped: tuple) -> None:
    """With a cap at the median place distance of the uncapped run's far searches, no far search of the run reads a
    submap above it, and the ones skipped are counted."""
    _lc0, _res0, _err0, searched0 = uncapped
    cap = float(np.median([x[2] for x in searched0]))
    lc, _res, _err, searched = _run(jumped, far_max_place_distance=cap, far_best_place_distance=cap)
    assert searched and max(x[2] for x in searched) <= cap
    assert lc.stats["far_skipped"] >= 1


def test_the_best_ranked_submap_has_its_own_cap(jumped: tuple) -> None:
    """``far_max_place_distance: 0`` with ``far_best_place_distance: 2``: each keyframe searches only its
    best-ranked far submap — and that suffices here to tie the keyframes after the 7 m jump back (ranked by place,
    test_loops_place)."""
    lc, res, err, searched = _run(jumped, far_max_place_distance=0.0, far_best_place_distance=2.0)
    nodes = [x[0] for x in searched]
    assert searched and len(nodes) == len(set(nodes)) and all(x[3] for x in searched)
    assert lc.stats["far_skipped"] >= 1 and lc.stats["far_loops"] >= 3
    assert res.corrected and err.max() < 0.05


def test_default_caps_keep_the_far_loop(jumped: tuple, uncapped: tuple) -> None:
    """The default caps (0.66, the best-ranked 0.74) skip far searches here and still find the loop after the
    jump: the keyframes end as close to the truth as without the caps."""
    lc, res, err, searched = _run(jumped)
    c = lc.config
    assert (c.far_max_place_distance, c.far_best_place_distance) == (0.66, 0.74)
    assert all(x[2] <= (c.far_best_place_distance if x[3] else c.far_max_place_distance) for x in searched)
    assert lc.stats["far_loops"] >= 3 and res.corrected and err.max() < 0.05


@pytest.mark.parametrize("key,value", [("far_max_place_distance", -0.1), ("far_max_place_distance", 2.5),
                                       ("far_best_place_distance", 2.01)])
def test_caps_are_validated(key: str, value: float) -> None:
    with pytest.raises(pydantic.ValidationError):
        LoopConfig(**{key: value})
