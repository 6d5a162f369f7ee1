"""The match stage's pass match5 (issue 13 item 1) gives what the plain code gave: the support taken inside the
matcher's kernel call equals ``support_at`` at the wrapped result pose (θ across ±π, dense scans with a stride,
every pyramid depth), the processor uses it only while the result holds that same pose, and ``ScanPeriod``'s
streamlined running median equals the earlier implementation over windows that wrap."""

from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam

import dynslam2d.slam.processor as pr
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.matcher import match_multires, support_at
from dynslam2d.slam.recovery import ScanPeriod
from dynslam2d.types import Pose2D, wrap_angle

_THRESH = SlamConfig().support_probability


def _mapped_near_pi(levels: int) -> tuple[HectorSlam, Pose2D, Pose2D]:
    """A map of three paper-room scans whose map frame is turned so that the laser's θ is just below π: matches
    there end on either side of ±π. Returns (slam, the room pose of the first scan, its map pose)."""
    slam = HectorSlam(SlamConfig(map_levels=levels))
    first = Pose2D(0.3, -0.4, 0.2)
    base = Pose2D(0.0, 0.0, math.pi - 0.01)
    for d in (Pose2D(), Pose2D(0.3, 0.1, 0.1), Pose2D(-0.2, 0.3, -0.15)):
        slam.update_map(paper_room_scan(first.compose(d)), base.compose(d), force=True)
    return slam, first, base


@pytest.mark.parametrize("levels", [1, 2, 3])
def test_the_kernels_support_equals_support_at_the_wrapped_result(levels: int) -> None:
    slam, first, base = _mapped_near_pi(levels)
    lv = slam.map.levels
    signs: set[bool] = set()
    supports: set[tuple[int, float]] = set()
    strides: set[int] = set()
    for d in (Pose2D(0.05, -0.03, 0.02), Pose2D(-0.04, 0.02, -0.03), Pose2D(0.1, 0.05, 0.0)):
        pts = slam.scan_points(paper_room_scan(first.compose(d)))[0]
        for dense in (False, True):
            p = np.ascontiguousarray(np.repeat(pts, 3, axis=0)) if dense else pts  # 3×: a stride of 2 or more
            strides.add(max(1, p.shape[0] // 240))
            want_map = base.compose(d)
            for off in (0.0, 0.015, -0.015, 2.0 * math.pi):  # (2π: a start θ beyond π)
                start = np.array([want_map.x + 0.02, want_map.y - 0.01, want_map.theta + off])
                for swapped in (False, True):
                    fit: list = []
                    got = match_multires(lv, p, start, 4, 6, swapped, True, fit=fit, free_thresh=0.45,
                                         support_thresh=_THRESH)
                    th = float(wrap_angle(got[2]))
                    want = support_at(lv[0], p, float(got[0]), float(got[1]), th, _THRESH)
                    assert fit[2] == want  # the same count and spread, bit for bit
                    assert isinstance(fit[2][0], int) and isinstance(fit[2][1], float)
                    signs.add(th > 0.0)
                    supports.add(want)
                    plain: list = []  # without support_thresh the fit is the two items as before
                    match_multires(lv, p, start, 4, 6, swapped, True, fit=plain, free_thresh=0.45)
                    assert len(plain) == 2 and plain[1] == fit[1]
    assert signs == {True, False}  # results on both sides of ±π
    assert len(supports) > 3 and all(n > 0 for n, _ in supports)
    assert len(strides) == 2


def test_the_processor_takes_the_matchers_support_exactly_while_the_pose_is_the_matched_one(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Tracked scans: the result's support is support_at's at its pose, without calling support_at (the matcher's
    value); a result whose pose is not the one _match_against_map gave it is computed again."""
    calls = []
    real = pr.support_at

    def counted(*a, **k):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(pr, "support_at", counted)
    slam, first = paper_room_slam()
    n = 0
    for i, d in enumerate((Pose2D(0.02, 0.0, 0.01), Pose2D(0.05, -0.02, 0.03), Pose2D(0.08, 0.01, -0.02))):
        res = slam.match(paper_room_scan(first.compose(d), stamp=0.1 * (i + 1)), predicted=first.between(
            first.compose(d)), commit=False)
        assert res.reason is None and res.pose_source == pr.SOURCE_SCAN
        want = real(slam.map.levels[0], res.points, res.pose.x, res.pose.y, res.pose.theta, _THRESH)
        assert (res.support_points, res.support_spread) == want and want[0] > 0
        n += 1
    assert n == 3 and calls == []  # every support came from the matcher's kernel call
    # the guard: the stored support is used only for that result and that pose object
    res = slam.match(paper_room_scan(first.compose(Pose2D(0.02, 0.0, 0.01)), stamp=0.5), commit=False)
    fake = (123456, 9.0)
    slam._support_of = (res, res.pose, fake)
    slam._support(res, res.points, res.pose)
    assert (res.support_points, res.support_spread) == fake
    for of in ((res, Pose2D(res.pose.x, res.pose.y, res.pose.theta), fake), (object(), res.pose, fake)):
        slam._support_of = of
        slam._support(res, res.points, res.pose)
        assert (res.support_points, res.support_spread) == real(slam.map.levels[0], res.points, res.pose.x,
                                                                res.pose.y, res.pose.theta, _THRESH)
    assert len(calls) == 2


class _OldScanPeriod:
    """ScanPeriod before pass match5 (the reference)."""

    def __init__(self, n: int = 31) -> None:
        self._gaps: deque[float] = deque(maxlen=n)
        self._sorted: list[float] = []
        self.median = 0.0

    def add(self, dt: float) -> None:
        if dt > 0.0 and math.isfinite(dt):
            gaps, srt = self._gaps, self._sorted
            if len(gaps) == gaps.maxlen:
                del srt[bisect.bisect_left(srt, gaps[0])]
            gaps.append(dt)
            bisect.insort(srt, dt)
            n = len(srt)
            i = n // 2
            self.median = float(srt[i] if n % 2 else (srt[i - 1] + srt[i]) / 2)


@pytest.mark.parametrize("n", [1, 2, 4, 7, 31])
def test_scan_period_equals_the_earlier_implementation(n: int) -> None:
    rng = np.random.default_rng(11)
    new, old = ScanPeriod(n), _OldScanPeriod(n)
    for k in range(400):  # (windows of up to 31 wrap many times)
        u = rng.random()
        if u < 0.1:
            dt = float(rng.choice([0.0, -0.05, -0.0, math.inf, -math.inf, math.nan]))
        elif u < 0.4:
            dt = float(rng.choice([0.025, 0.05, 0.025 + 1e-17, 0.1]))  # equal values, evicted and inserted
        elif u < 0.5:
            dt = np.float64(rng.uniform(0.001, 0.5))  # (a NumPy float: the median is a Python float still)
        else:
            dt = float(rng.uniform(0.001, 0.5))
        new.add(dt)
        old.add(dt)
        assert new.median == old.median and type(new.median) is float, k
        assert new.floor(0.03) == max(0.03, old.median)


@pytest.mark.parametrize("weak", [False, True])
def test_the_motion_gate_judges_only_weak_matches(weak: bool) -> None:
    """A gate far tighter than the scans' motion: a well-supported match is kept without the gate's deviation and
    limits being computed; with every match weak (support threshold out of reach), the same scan is refused."""
    slam, first = paper_room_slam()
    c = slam.config
    c.gate_distance, c.gate_angle, c.max_linear_accel, c.max_angular_accel = 1e-9, 1e-9, 1e-9, 1e-9
    if weak:
        c.support_min_points = 10**6
    limits = []
    real = slam._gate_limits
    slam._gate_limits = lambda dt: limits.append(dt) or real(dt)
    reasons = []
    for i in range(1, 6):
        d = Pose2D(0.02 * i + 0.003 * i * i, 0.004 * i, 0.01 * i)  # (accelerating: beyond the motion model)
        res = slam.match(paper_room_scan(first.compose(d), stamp=0.1 * i))
        reasons.append(res.reason)
        assert res.low_support == weak
    if weak:
        assert pr.PREDICT_UNSUPPORTED in reasons and len(limits) >= 1
    else:
        assert reasons == [None] * 5 and limits == []
