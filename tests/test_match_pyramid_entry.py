"""Pass mat146 (issue 13 item 1): ``match_fit_at`` calls ``match_pyramid``'s compiled entry point (no type resolution
by numba's dispatcher) for probability caches of the usual type, remembered by the identity of the last three caches;
caches of another layout or type go through the dispatcher. The iterations no longer sum Σ M and n_inside (``keep``
off): the evaluation pass at the result gives them, the same bits as ``evaluate`` (tests/test_match_level0_rows.py)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_room_slam_points

import dynslam2d.slam.matcher as mt
from dynslam2d.jitbox import AOT


class _Levels:
    """Stand-ins of the map's levels with other probability caches (the same values), geometry stamps kept."""

    def __init__(self, lv: object, prob: np.ndarray) -> None:
        self.__dict__.update({k: getattr(lv, k) for k in ("resolution", "i0", "j0", "logodds", "geometry_stamp")})
        self.prob = prob


def _fit(levels: list, pts: np.ndarray, slam: object, start: tuple[float, float, float], **kw: object) -> tuple:
    c = slam.config
    args = dict(lam0=c.lm_lambda_init, lam_max=c.lm_lambda_max, max_rot=c.max_rotation_step,
                max_trans=c.max_translation_step)
    args.update(kw)
    p, f, free, sup = mt.match_fit_at(
        levels, pts, *start, c.iterations_coarse, c.iterations_finest, False, True, args["lam0"], args["lam_max"],
        args["max_rot"], args["max_trans"], 0.25, c.support_probability, c.degeneracy_threshold, 1234.5)
    return p.tobytes(), f.hessian.tobytes(), f.cost, f.score, f.n_inside, f.degeneracy, free, sup


@pytest.mark.skipif(AOT is not None, reason="numba's dispatcher only (the AOT kernels have no entry points)")
def test_usual_caches_take_the_entry_point_and_others_the_dispatcher_with_the_same_results() -> None:
    slam, pts = paper_room_slam_points()
    levels = slam.map.levels
    starts = [(0.3, -0.4, 0.2), (0.42, -0.31, 0.27), (0.2, -0.5, 0.1)]
    want = [_fit(levels, pts, slam, s) for s in starts]
    last = mt._PYRAMID_LAST
    assert last[0]() is levels[0].prob and last[1]() is levels[1].prob and last[2]() is levels[2].prob
    assert type(last[3]) is type(len) and last[3] is mt._PYRAMID_STD[0]  # the compiled entry point, remembered
    assert [_fit(levels, pts, slam, s) for s in starts] == want  # (through the entry point: the same results)
    # caches of other layouts / types (the same probabilities): the dispatcher, the same results; read as C-order
    # uint32 caches by the entry point (without the type test) they would give other poses
    for make in (np.asfortranarray, lambda a: a[::-1][::-1], lambda a: np.require(a, requirements="C").copy()):
        other = [_Levels(lv, make(lv.prob)) for lv in levels]
        if make is np.asfortranarray:  # (a square level is C- and F-contiguous at once only when 1 wide)
            assert not other[0].prob.flags.c_contiguous
        got = [_fit(other, pts, slam, s) for s in starts]
        assert got == want
        usual = all(o.prob.flags.c_contiguous for o in other)
        assert (mt._PYRAMID_LAST[3] is mt._PYRAMID_STD[0]) == usual
        assert mt._PYRAMID_LAST[0]() is other[0].prob
    ro = [_Levels(lv, lv.prob.copy()) for lv in levels]
    for o in ro:
        o.prob.flags.writeable = False
    assert [_fit(ro, pts, slam, s) for s in starts] == want
    assert mt._PYRAMID_LAST[3] is mt.match_pyramid  # (read-only caches: the dispatcher's own specialisation)


def test_numbers_of_other_types_give_the_same_results() -> None:
    """An int or a NumPy scalar where the entry point takes a float64: the same values as Python floats."""
    slam, pts = paper_room_slam_points()
    levels = slam.map.levels
    s = (0.3, -0.4, 0.2)
    want = _fit(levels, pts, slam, s, max_trans=2.0, lam_max=1e4)
    assert _fit(levels, pts, slam, s, max_trans=2, lam_max=10000) == want
    assert _fit(levels, pts, slam, tuple(np.float64(v) for v in s), max_trans=np.float64(2.0), lam_max=1e4) == want


def test_the_evaluation_sums_at_the_result_without_the_iterations_keeping_them() -> None:
    """Σ M (score · n) and n_inside come from the evaluation pass: equal to ``evaluate`` at the returned pose, and
    non-zero (the iterations without ``keep`` return 0 for both)."""
    slam, pts = paper_room_slam_points()
    levels = slam.map.levels
    for s in [(0.3, -0.4, 0.2), (0.1, -0.2, 0.3)]:
        pb, _, cost, score, n_in, _, _, _ = _fit(levels, pts, slam, s)
        ev = mt.evaluate(levels[0], pts, np.frombuffer(pb))
        assert (cost, score, n_in) == (ev.cost, ev.score, ev.n_inside)
        assert score > 0.3 and n_in > 0.9 * pts.shape[0]


def test_the_remembered_caches_do_not_keep_a_dropped_map_alive() -> None:
    """The last caches are remembered weakly: a map's probability caches (a loop closure's submap, a grown level's
    old arrays) are freed as soon as nothing else holds them, not kept until the next match (≈ 3 MiB more at MIT
    CSAIL's memory peak with strong references, session 47)."""
    import gc
    import weakref

    slam, pts = paper_room_slam_points()
    copies = [_Levels(lv, lv.prob.copy()) for lv in slam.map.levels]
    probe = weakref.ref(copies[0].prob)
    want = _fit(slam.map.levels, pts, slam, (0.3, -0.4, 0.2))
    assert _fit(copies, pts, slam, (0.3, -0.4, 0.2)) == want
    assert mt._PYRAMID_LAST[0]() is copies[0].prob
    del copies
    gc.collect()
    assert probe() is None  # (freed although it was the last cache matched)
    assert mt._PYRAMID_LAST[0]() is None
    assert _fit(slam.map.levels, pts, slam, (0.3, -0.4, 0.2)) == want  # (a dead reference: the caches tested again)
