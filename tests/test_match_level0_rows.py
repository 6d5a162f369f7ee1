"""Pass mat140 (issue 13 item 1): ``match_pyramid``'s evaluation at its result reads level 0's points as rows from
its iterations (no second division of the points), and ``match_fit_at`` hands on the kernel's Python floats and
ints without converting them: the same bits and the same types as ``evaluate`` / the conversions gave."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from conftest import paper_room_slam_points

import dynslam2d.slam.matcher as mt
from dynslam2d.types import wrap_angle


def _bits(*v: float) -> tuple[bytes, ...]:
    return tuple(struct.pack("<d", float(a)) for a in v)


@pytest.mark.parametrize("it_finest", [0, 1, None])
def test_the_evaluation_at_the_result_is_evaluates_with_the_same_types(it_finest: int | None) -> None:
    slam, pts = paper_room_slam_points()
    c = slam.config
    levels = slam.map.levels
    sumsq = float(np.einsum("ij,ij->", pts, pts))
    fin = c.iterations_finest if it_finest is None else it_finest
    rng = np.random.default_rng(11)
    for _ in range(12):
        sx, sy, sth = (np.array([0.3, -0.4, 0.2]) + rng.normal(0.0, [0.15, 0.15, 0.1])).tolist()
        p, f, free, sup = mt.match_fit_at(
            levels, pts, sx, sy, sth, c.iterations_coarse, fin, False, True, c.lm_lambda_init, c.lm_lambda_max,
            c.max_rotation_step, c.max_translation_step, 0.25, c.support_probability, c.degeneracy_threshold, sumsq)
        ev = mt.evaluate(levels[0], pts, p)  # level 0's H, cost and score at the result, from pts / res made anew
        assert f.hessian.tobytes() == ev.hessian.tobytes()
        assert _bits(f.cost, f.score) == _bits(ev.cost, ev.score) and f.n_inside == ev.n_inside
        assert type(f.cost) is float and type(f.score) is float and type(f.n_inside) is int
        wp = np.array([p[0], p[1], wrap_angle(p[2])])
        assert type(free) is float and _bits(free) == _bits(mt.free_fraction(levels[1], pts, wp, 0.25))
        assert type(sup[0]) is int and type(sup[1]) is float
        assert sup == mt.support_at(levels[0], pts, float(p[0]), float(p[1]), float(wp[2]), c.support_probability)
