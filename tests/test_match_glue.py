"""The match stage's trimmed per-scan glue (issue 13 item 1, pass glue4) gives what the plain code gave: the
no-match covariance copied when read, the refine fit reused at the wrapped pose exactly when the pose's bytes are
the refine's, and the scan's cached valid mask read without copies and never written."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam

import dynslam2d.slam.processor as pr
from dynslam2d.detect.body import BodyFilter
from dynslam2d.slam.matcher import LevelFit, evaluate
from dynslam2d.types import Pose2D, Scan


def test_an_unmatched_result_gets_its_own_copy_of_the_no_match_covariance() -> None:
    slam, _ = paper_room_slam()
    few = Scan(stamp=0.1, angle_min=-math.pi, angle_increment=2 * math.pi / 720, ranges=np.full(720, np.nan),
               range_min=0.1, range_max=30.0)
    res = slam.match(few, commit=False)
    assert res.skipped and res._covariance is None and res._covariance_of == ()  # not made by the match
    want = np.diag([1e6, 1e6, math.pi**2])
    np.testing.assert_array_equal(res.covariance, want)
    assert res.covariance is res.covariance and res._covariance_of is None  # copied once
    res.covariance[0, 0] = 5.0  # a caller may change its own
    np.testing.assert_array_equal(pr._NO_MATCH_COVARIANCE, want)
    np.testing.assert_array_equal(slam.match(few, commit=False).covariance, want)


@pytest.mark.parametrize("theta", [pr._wrap(0.01), 0.01, -0.0, 0.0, pr._wrap(-3.0), 3.5])
def test_the_refine_fit_is_reused_exactly_when_the_wrapped_pose_has_the_refines_bytes(
        theta: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """A matcher returning θ: the old lookup (``fits[Pose2D(x, y, wrap(θ)).as_array().tobytes()]``) found the
    refine's fit iff wrapping left θ's bits as they were (−0.0 wraps to +0.0: another key); otherwise the pose
    is evaluated again."""
    slam, first = paper_room_slam()
    start = Pose2D(0.02, 0.0, theta if abs(theta) < 1.0 else 0.0)
    scan = paper_room_scan(first.compose(start), stamp=0.1)
    mark = LevelFit(np.full((3, 3), 7.0), 3.0, 0.875, 11)

    def fake(levels, pts, seed, *a, fit=None, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        if fit is not None:
            fit[:] = [mark, 0.0, None]
        return np.array([0.02, 0.0, theta])

    monkeypatch.setattr(pr, "match_multires", fake)
    monkeypatch.setattr(pr, "match_fit_at", lambda levels, pts, x, y, th, *a: (np.array([0.02, 0.0, theta]), mark, 0.0,
                                                                                None))
    slam.config.max_jump_angle = 10.0  # (θ far from the start must not be refused as a jump)
    res = slam.match(scan, predicted=start, commit=False)
    assert res.reason != pr.REJECT_JUMP
    same = np.array([0.02, 0.0, pr._wrap(theta)]).tobytes() == np.array([0.02, 0.0, theta]).tobytes()
    if same:
        assert res.hessian is mark.hessian and res.score == 0.875
    else:
        want = evaluate(slam.map.levels[0], res.points, res.pose.as_array())
        assert res.hessian is not mark.hessian
        np.testing.assert_array_equal(res.hessian, want.hessian)
        assert res.score == want.score
    assert res.free_fraction == 0.0  # the refine's free fraction (taken at the wrapped pose) either way


def test_the_wrap_cases_cover_both_branches() -> None:
    """An angle the matcher wrapped keeps its bits when wrapped again (the usual case: the fit is reused); −0.0,
    θ beyond π and some unwrapped angles change them (another key: evaluated again)."""
    def keeps(t: float) -> bool:
        return np.array([pr._wrap(t)]).tobytes() == np.array([t]).tobytes()

    assert keeps(pr._wrap(0.01)) and keeps(0.0) and keeps(pr._wrap(-3.0))
    assert not keeps(0.01) and not keeps(-0.0) and not keeps(3.5)


def test_cached_valid_masks_are_read_not_copied_nor_written() -> None:
    """The gate, the body filter and the vacated trace read ``scan.valid_view()``, the scan's cached mask itself; the
    mask is the plain expression's (no errstate: NaN and ±inf compare without a floating-point error) and nobody
    writes it."""
    rng = np.random.default_rng(3)
    r = rng.uniform(0.0, 40.0, 720)
    r[::7], r[::11], r[::13] = np.nan, np.inf, -np.inf
    scan = Scan(stamp=0.0, angle_min=-math.pi, angle_increment=2 * math.pi / 720, ranges=r, range_min=0.1,
                range_max=30.0)
    with warnings.catch_warnings(), np.errstate(all="raise"):
        warnings.simplefilter("error")
        v = scan.valid_mask()
    np.testing.assert_array_equal(v, np.isfinite(r) & (r >= 0.1) & (r <= 30.0))
    cached = scan._valid
    assert scan.valid_view() is cached and scan.valid_mask() is not cached
    before = cached.copy()
    slam, _ = paper_room_slam()
    pts, clear, n_valid, n_close, _, _ = slam._gate(scan, True)
    fresh = Scan(stamp=0.0, angle_min=-math.pi, angle_increment=2 * math.pi / 720, ranges=r.copy(), range_min=0.1,
                 range_max=30.0)
    assert fresh._valid is None
    assert Scan(stamp=0.0, angle_min=-math.pi, angle_increment=2 * math.pi / 720, ranges=r.copy(), range_min=0.1,
                range_max=30.0).valid_view().sum() == before.sum()
    pts2, clear2, n_valid2, n_close2, _, _ = slam._gate(fresh, True)  # (computes the mask on the way)
    np.testing.assert_array_equal(pts, pts2)
    np.testing.assert_array_equal(clear, clear2)
    assert (n_valid, n_close) == (n_valid2, n_close2) == (int(before.sum()), n_close)
    from types import SimpleNamespace
    body = BodyFilter(SimpleNamespace(polygon=None, auto=True, auto_tolerance=0.05, auto_max_range=1.0,
                                      auto_min_travel=0.5, auto_min_turn=0.5, auto_min_scans=5, auto_share=0.9,
                                      auto_edge_beams=1))
    for k in range(3):
        body.mask(scan)
        body.observe(scan, Pose2D(0.1 * k, 0.0, 0.0))
    assert scan._valid is cached
    np.testing.assert_array_equal(cached, before)
