"""The match stage's per-scan Python of pass mat127 (issue 13 item 1) gives what the plain code gave: ``_prior``'s
inlined odometry path against ``Pose2D.between`` / ``compose`` (every bit, poses that wrap and do not), the odometry
information from the increment's three floats, ``MatchResult`` built positionally (the field order it relies on) and
the shared read-only zero Hessian of an unmatched result."""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam

import dynslam2d.slam.processor as pr
from dynslam2d.types import Pose2D


def _bits(*v: float) -> tuple[bytes, ...]:
    return tuple(struct.pack("<d", float(a)) for a in v)


def _pose(rng: np.random.Generator, wide: bool) -> Pose2D:
    th = float(rng.uniform(-4.0, 4.0)) if wide else float(rng.uniform(-math.pi, math.pi))
    return Pose2D(*(float(a) for a in rng.normal(0.0, 20.0, 2)), th)


def test_odometry_prior_is_between_then_compose() -> None:
    slam, _ = paper_room_slam()
    slam.config.odometry_prior = "all"
    slam._sigma2 = 0.37
    rng = np.random.default_rng(11)
    scan0 = paper_room_scan(Pose2D(), stamp=1.05)
    n_wrap = 0
    for k in range(400):
        last, last_odom = _pose(rng, k % 2 == 0), _pose(rng, k % 3 == 0)
        step = Pose2D(*(float(a) for a in rng.normal(0.0, 0.3, 2)), float(rng.normal(0.0, 1.5)))
        odom = last_odom.compose(step) if k % 4 else Pose2D(last_odom.x + 0.1, last_odom.y, -last_odom.theta)
        slam._last_pose, slam._last_odom, slam._last_stamp = last, last_odom, 1.0
        scan = dataclasses.replace(scan0, odom=odom)
        prior = slam._prior(scan, last, False)
        delta = last_odom.between(odom)
        want = last.compose(delta)
        assert prior.kind == "odometry" and prior.gate is True
        assert _bits(prior.pose.x, prior.pose.y, prior.pose.theta) == _bits(want.x, want.y, want.theta)
        assert type(prior.pose.theta) is type(want.theta)
        assert _bits(*prior.delta) == _bits(delta.x, delta.y, delta.theta)
        n_wrap += abs(last.theta + delta.theta) > math.pi
        # the odometry information from the increment's floats: the Pose2D's values
        c = slam.config
        d, a = math.hypot(delta.x, delta.y), abs(delta.theta)
        var_xy = c.odometry_noise_floor_xy**2 + (c.odometry_noise_translation * d) ** 2
        var_th = c.odometry_noise_floor_theta**2 + (c.odometry_noise_rotation * a) ** 2
        info = slam._odometry_information(prior)
        assert info.tobytes() == (0.37 * np.diag([1.0 / var_xy, 1.0 / var_xy, 1.0 / var_th])).tobytes()
    assert n_wrap > 40


def test_match_result_fields_in_the_order_match_builds_them() -> None:
    names = [f.name for f in dataclasses.fields(pr.MatchResult)]
    assert names == ["pose", "start", "_covariance", "hessian", "score", "n_points", "free_fraction",
                     "used_correlative", "rejected", "reason", "skipped", "time_gap", "first", "match_ms", "points",
                     "clear_points", "degeneracy", "degenerate", "support_points", "support_spread", "low_support",
                     "prior", "pose_source", "state", "sigma2", "_covariance_of"]
    defaults = {f.name: f.default for f in dataclasses.fields(pr.MatchResult)
                if f.default is not dataclasses.MISSING}
    assert defaults["pose_source"] == pr.SOURCE_SCAN and math.isnan(defaults["sigma2"])
    assert math.isnan(defaults["degeneracy"]) and defaults["_covariance_of"] is None


@pytest.mark.parametrize("case", ["first", "skipped", "matched"])
def test_match_results_as_the_keyword_form_built_them(case: str) -> None:
    """A first scan, a scan with too few points and a matched one: every field but the timing as the keyword
    construction's defaults and the match's values give them; the unmatched Hessian zeros, shared and read-only."""
    if case == "first":
        from dynslam2d.slam import HectorSlam, SlamConfig
        slam = HectorSlam(SlamConfig())
    else:
        slam, first = paper_room_slam()
    scan = paper_room_scan(Pose2D(0.3, -0.4, 0.2) if case != "first" else Pose2D(), stamp=0.1)
    if case == "skipped":
        slam.config.min_points = 10_000
    res = slam.match(scan, commit=False)
    assert res.match_ms > 0.0
    if case == "matched":
        assert res.hessian is not pr._ZERO_HESSIAN and res.hessian.any() and res.score > 0.5
        assert res.pose_source == pr.SOURCE_SCAN and res.state == pr.STATE_TRACKING
        return
    assert res.hessian is pr._ZERO_HESSIAN and not res.hessian.any() and not res.hessian.flags.writeable
    assert res.first is (case == "first") and res.skipped is (case == "skipped")
    assert res.score == 0.0 and res.free_fraction == 0.0 and res.support_points == 0
    assert res.support_spread == 0.0 and math.isnan(res.degeneracy) and not res.degenerate
    assert res.n_points == res.points.shape[0] > 0 and res.clear_points.shape[1] == 2
    assert res.state == pr.STATE_TRACKING and not res.used_correlative and not res.time_gap
    if case == "first":
        assert res.pose_source == pr.SOURCE_SCAN and res.reason is None and not res.rejected
        assert res.covariance.tobytes() == np.zeros((3, 3)).tobytes() and math.isnan(res.sigma2)
    else:
        assert res.pose_source == pr.SOURCE_PREDICTION and res.reason == pr.SKIP_TOO_FEW_POINTS
        assert res.covariance.tobytes() == pr._NO_MATCH_COVARIANCE.tobytes()


@pytest.mark.parametrize("kind", ["kernel", "float32", "empty", "no_support"])
def test_match_fit_is_match_multires_with_its_fit_list(kind: str) -> None:
    """``match_fit`` returns ``match_multires``' pose and its ``fit`` list's items (every bit) from seeds around the
    paper room's pose, on the kernel path and the paths ``match_multires`` leaves the list empty on."""
    from conftest import paper_room_slam_points

    import dynslam2d.slam.matcher as mt

    slam, pts = paper_room_slam_points()
    if kind == "float32":
        pts = pts.astype(np.float32)
    elif kind == "empty":
        pts = pts[:0]
    c = slam.config
    sup = None if kind == "no_support" else c.support_probability
    sumsq = float((pts.astype(np.float64) ** 2).sum())
    rng = np.random.default_rng(2)
    levels = slam.map.levels
    for _ in range(12):
        seed = np.array([0.3, -0.4, 0.2]) + rng.normal(0.0, [0.1, 0.1, 0.08])
        args = (levels, pts, seed, c.iterations_coarse, c.iterations_finest, False, True, c.lm_lambda_init,
                c.lm_lambda_max, c.max_rotation_step, c.max_translation_step)
        fit: list = []
        want = mt.match_multires(*args, None, None, fit=fit, free_thresh=0.25, support_thresh=sup,
                                 degeneracy_threshold=c.degeneracy_threshold, sumsq=sumsq)
        p, f, free, s = mt.match_fit(*args, 0.25, sup, c.degeneracy_threshold, sumsq)
        assert p.tobytes() == want.tobytes()
        if kind in ("float32", "empty"):
            assert not fit and f is None and free is None and s is None
            continue
        wf = fit[0]
        assert f.hessian.tobytes() == wf.hessian.tobytes() and _bits(f.cost, f.score) == _bits(wf.cost, wf.score)
        assert f.n_inside == wf.n_inside and type(f.cost) is type(wf.cost) and f.degeneracy == wf.degeneracy
        assert _bits(free) == _bits(fit[1]) and type(free) is type(fit[1])
        assert s == (fit[2] if len(fit) > 2 else None)
        assert (s is None) is (kind == "no_support")
