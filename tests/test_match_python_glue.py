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
