"""The front end's reuse of work within a scan (docs/speed.md, match pass 9): a refine's level-0 evaluation and
free fraction are reused at the pose that wins, whichever refine gave it, and the scan period's median is kept
from a sorted window instead of sorting on every scan — each the same values as computing them afresh."""

from __future__ import annotations

import math
import statistics

import numpy as np
from conftest import room_box_scan

from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.matcher import evaluate, free_fraction
from dynslam2d.slam.processor import FREE_SPACE_PROB, SOURCE_SCAN
from dynslam2d.slam.recovery import ScanPeriod
from dynslam2d.types import Pose2D


def test_match_fit_and_free_fraction_are_those_of_the_reported_pose() -> None:
    """With a correlative search on every scan, the winner is sometimes the first refine (the search's seed refines
    to a lower score): the score, Hessian and free fraction reported must still be those of the reported pose,
    bit for bit, as evaluating it afresh gives them."""
    slam = HectorSlam(SlamConfig(correlative_mode="always", constant_velocity=True))
    box = (7.0, 4.0, 1.2, 0.8)
    rng = np.random.default_rng(3)
    pose = Pose2D(2.0, 3.0, 0.1)
    checked = first_won = 0
    for k in range(40):
        # uneven steps (some large), so both the search's pose and the plain match win on some scans
        step = Pose2D(float(rng.uniform(0.0, 0.25)), float(rng.uniform(-0.05, 0.05)), float(rng.uniform(-0.12, 0.12)))
        pose = pose.compose(step)
        scan = room_box_scan(pose, box, 0.1 * k, seed=k)
        res = slam.match(scan)
        if not res.first and not res.skipped and res.pose_source == SOURCE_SCAN and res.reason is None:
            at = res.pose.as_array()
            fit = evaluate(slam.map.levels[0], res.points, at)
            assert res.score == fit.score
            np.testing.assert_array_equal(res.hessian, fit.hessian)
            assert res.free_fraction == free_fraction(slam.map.levels[1], res.points, at, FREE_SPACE_PROB)
            checked += 1
            first_won += not res.used_correlative
        if not res.rejected:
            slam.update_map(scan, res.pose)
    assert checked >= 30
    assert first_won >= 3  # the case a "latest refine only" reuse would miss is exercised


def test_scan_period_median_equals_the_median_of_the_window() -> None:
    """The kept-sorted window gives statistics.median of the last n positive finite gaps after every gap, with
    repeated values, evictions of duplicates and ignored gaps."""
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 31):
        sp = ScanPeriod(n)
        window: list[float] = []
        assert sp.median == 0.0
        for _ in range(300):
            u = rng.random()
            if u < 0.1:
                dt = float(rng.choice([0.0, -0.05, math.inf, math.nan]))
            elif u < 0.5:
                dt = float(rng.choice([0.1, 0.2, 0.1 + 1e-17, 0.3]))  # many equal values
            else:
                dt = float(rng.uniform(0.01, 1.0))
            sp.add(dt)
            if dt > 0.0 and math.isfinite(dt):
                window = (window + [dt])[-n:]
            expect = float(statistics.median(window)) if window else 0.0
            assert sp.median == expect
            assert sp.floor(0.05) == max(0.05, expect)


def test_a_search_seed_equal_to_the_start_is_not_refined_twice(monkeypatch) -> None:
    """A correlative search that returns the start itself: its refine is the first refine's (same map, points and
    seed), so the matcher runs once, and the scan's result is the one of the plain match."""
    from dynslam2d.slam import processor as proc_mod
    from dynslam2d.slam.correlative import CorrelativeResult

    def scans():
        pose = Pose2D(2.0, 3.0, 0.1)
        for k in range(6):
            pose = pose.compose(Pose2D(0.05, 0.0, 0.02))
            yield room_box_scan(pose, (7.0, 4.0, 1.2, 0.8), 0.1 * k, seed=k)

    plain = HectorSlam(SlamConfig(correlative_mode="never"))
    expect = [plain.process(s) for s in scans()]

    slam = HectorSlam(SlamConfig(correlative_mode="always"))
    calls = []
    real, real_fit = proc_mod.match_multires, proc_mod.match_fit_at
    monkeypatch.setattr(proc_mod, "correlative_search",
                        lambda level, pts, start, *a, **k: CorrelativeResult(np.array(start, dtype=np.float64), 1.0, 1))
    monkeypatch.setattr(proc_mod, "match_multires", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(proc_mod, "match_fit_at", lambda *a, **k: calls.append(1) or real_fit(*a, **k))
    for s, e in zip(scans(), expect, strict=True):
        n0 = len(calls)
        step = slam.process(s)
        assert step.pose == e.pose and step.score == e.score and step.map_updated == e.map_updated
        assert not step.used_correlative
        assert len(calls) - n0 == (0 if step.index == 0 else 1)  # (the first scan is not matched)


def test_constant_velocity_start_is_the_last_motion_over_its_time() -> None:
    """The constant-velocity start: the last accepted motion divided by its time, times the new gap, composed onto
    the last pose — the same floats as the array arithmetic (Δ / dt, then × dt′) it replaced."""
    slam = HectorSlam(SlamConfig(constant_velocity=True))
    box = (7.0, 4.0, 1.2, 0.8)
    poses = [Pose2D(2.0, 3.0, 0.1), Pose2D(2.13, 3.02, 0.14), Pose2D(2.27, 3.05, 0.19)]
    stamps = [0.0, 0.1, 0.23]
    for k, (p, t) in enumerate(zip(poses, stamps, strict=True)):
        prev, prev_t = slam.pose, slam._last_stamp
        step = slam.process(room_box_scan(p, box, t, seed=k))
        assert not step.rejected
        if k:
            d = prev.between(step.pose)
            v = np.array([d.x, d.y, d.theta]) / (t - prev_t)
            later = t + 0.07
            w = v * (later - t)
            expect = step.pose.compose(Pose2D(float(w[0]), float(w[1]), float(w[2])))
            assert slam.predict(later) == expect
            assert slam.predict(later) != step.pose  # (it moved)
