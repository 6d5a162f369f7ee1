"""The match stage's pass mat132 (issue 13 item 1) gives what the plain code gave: ``match_fit`` (the one kernel path
``match_multires`` now goes through, the start and the prior given to ``match_pyramid`` as floats) against the level
loop, ``evaluate``, ``free_fraction`` and ``support_at`` at its pose (every bit, with and without a prior, starts of
every kind), ``match_multires``' fit list against ``match_fit``'s items, and the processor's first refine without the
per-scan caches (made only when a scan refines a second time)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam, paper_room_slam_points

import dynslam2d.slam.matcher as mt
import dynslam2d.slam.processor as pr
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.types import Pose2D, wrap_angle


def _bits(*v: float) -> tuple[bytes, ...]:
    return tuple(struct.pack("<d", float(a)) for a in v)


_INFO = np.array([[30.0, 2.0, 0.5], [2.0, 10.0, 0.1], [0.5, 0.1, 40.0]])


@pytest.mark.parametrize("start_kind", ["array", "list", "float32"])
@pytest.mark.parametrize("prior", [False, True])
def test_match_fit_equals_the_level_loop_and_the_evaluations_at_its_pose(start_kind: str, prior: bool) -> None:
    slam, pts = paper_room_slam_points()
    c = slam.config
    levels = slam.map.levels
    sumsq = float(np.einsum("ij,ij->", pts, pts))
    rng = np.random.default_rng(7)
    for _ in range(10):
        seed = np.array([0.3, -0.4, 0.2]) + rng.normal(0.0, [0.1, 0.1, 0.08])
        start = {"array": seed, "list": seed.tolist(), "float32": seed.astype(np.float32)}[start_kind]
        pw = seed + np.array([0.02, -0.01, 0.03]) if prior else None
        info = _INFO if prior else None
        args = (levels, pts, start, c.iterations_coarse, c.iterations_finest, False, True, c.lm_lambda_init,
                c.lm_lambda_max, c.max_rotation_step, c.max_translation_step)
        p, f, free, s = mt.match_fit(*args, 0.25, c.support_probability, c.degeneracy_threshold, sumsq, pw, info)
        want = mt._match_levels(*args, pw, info)  # the per-level loop from the start's float64 values
        assert p.tobytes() == want.tobytes()
        assert start_kind != "array" or p is not start
        ev = mt.evaluate(levels[0], pts, p)
        assert f.hessian.tobytes() == ev.hessian.tobytes() and _bits(f.cost, f.score) == _bits(ev.cost, ev.score)
        assert f.n_inside == ev.n_inside
        wp = np.array([p[0], p[1], wrap_angle(p[2])])
        assert _bits(free) == _bits(mt.free_fraction(levels[1], pts, wp, 0.25))
        assert s == mt.support_at(levels[0], pts, float(p[0]), float(p[1]), float(wp[2]), c.support_probability)
        d = f.degeneracy  # (its axis not normalised: unit_axis)
        assert (*d[:3], *mt.unit_axis(d[3], d[4]), *d[5:]) == mt.degeneracy_values(
            f.hessian, levels[0].resolution, pts, c.degeneracy_threshold, sumsq)
        # match_multires: the same pose, its list holding match_fit's items; without the list no evaluation
        fit: list = []
        got = mt.match_multires(*args, pw, info, fit=fit, free_thresh=0.25, support_thresh=c.support_probability,
                                degeneracy_threshold=c.degeneracy_threshold, sumsq=sumsq)
        assert got.tobytes() == p.tobytes() and len(fit) == 3
        assert fit[0].hessian.tobytes() == f.hessian.tobytes() and _bits(fit[1]) == _bits(free) and fit[2] == s
        assert mt.match_multires(*args, pw, info).tobytes() == p.tobytes()
        assert mt.match_fit(*args, 0.25, None, None, None, pw, info, False)[1:] == (None, None, None)


def test_match_fit_on_the_loops_paths_returns_no_fit() -> None:
    """Points the kernel does not take (float32, none) and a map of four levels: the loop's pose, no fit."""
    slam, pts = paper_room_slam_points()
    c = slam.config
    seed = np.array([0.3, -0.4, 0.2])
    for p_in in (pts.astype(np.float32), pts[:0]):
        args = (slam.map.levels, p_in, seed, 4, 6, False, True, 0.1, 1e4, 0.2, 2.0)
        p, f, free, s = mt.match_fit(*args, 0.25, c.support_probability, None, None)
        assert p.tobytes() == mt._match_levels(*args, None, None).tobytes() and (f, free, s) == (None, None, None)
        assert p is not seed
    deep = HectorSlam(SlamConfig(map_levels=4))
    first = Pose2D(0.3, -0.4, 0.2)
    deep.update_map(paper_room_scan(first), first, force=True)
    args = (deep.map.levels, pts, seed, 4, 6, False, True, 0.1, 1e4, 0.2, 2.0)
    p, f, _, _ = mt.match_fit(*args, 0.25, None, None, None)
    assert f is None and p.tobytes() == mt._match_levels(*args, None, None).tobytes()


def test_the_first_refine_makes_no_per_scan_caches_and_its_fit_is_the_results(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A tracked scan that neither searches nor recovers makes no per-scan caches, and its result holds the first
    refine's pose, Hessian, score and free fraction: ``match_fit`` from the result's start, bit for bit."""
    slam, first = paper_room_slam()
    made = []
    real = pr.HectorSlam._scan_context

    def counted(self, *a):  # noqa: ANN001, ANN002, ANN202
        made.append(1)
        return real(self, *a)

    monkeypatch.setattr(pr.HectorSlam, "_scan_context", counted)
    c = slam.config
    tracked = 0
    for k in range(1, 16):
        n_made, n_search = len(made), slam.pre_searches
        scan = paper_room_scan(first.compose(Pose2D(0.02 * k, 0.01 * k, 0.01 * k)), stamp=0.1 * k)
        res = slam.match(scan)
        if slam.pre_searches != n_search or res.rejected:
            continue
        tracked += 1
        assert len(made) == n_made  # (no search, no recovery: no caches)
        pts = res.points
        p, f, free, _ = mt.match_fit(slam.map.levels, pts, res.start.as_array(), c.iterations_coarse,
                                     c.iterations_finest, False, True, c.lm_lambda_init, c.lm_lambda_max,
                                     c.max_rotation_step, c.max_translation_step, pr.FREE_SPACE_PROB, None, None, None)
        assert _bits(res.pose.x, res.pose.y, res.pose.theta) == _bits(p[0], p[1], wrap_angle(p[2]))
        assert res.hessian.tobytes() == f.hessian.tobytes() and _bits(res.score) == _bits(f.score)
        assert _bits(res.free_fraction) == _bits(free)
    assert tracked >= 5 and len(made) == slam.pre_searches
