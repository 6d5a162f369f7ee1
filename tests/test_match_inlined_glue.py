"""The match stage's per-scan glue of pass match32 (issue 13 item 1) gives what the plain code gave: ``Pose2D``'s
slot-writing ``__init__`` against the frozen dataclass's generated one, the processor's inlined motion model and
jump test against the helpers they replace, the cached ``no_drop`` views, and ``match_multires``' copy of its start
for every kind of start it may be given."""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle
from collections.abc import Sequence

import numpy as np
import pytest
from conftest import paper_room_scan, paper_room_slam

import dynslam2d.slam.matcher as mt
import dynslam2d.slam.processor as pr
from dynslam2d.types import Pose2D, Scan, Track, wrap_angle


@dataclasses.dataclass(frozen=True, slots=True)
class _GeneratedPose:
    """Pose2D's fields with the dataclass's own generated ``__init__`` (what Pose2D had before)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


@pytest.mark.parametrize("args,kwargs", [((), {}), ((1.5,), {}), ((1.5, -2.0), {}), ((1.5, -2.0, 3.0), {}),
                                         ((), {"theta": 0.25}), ((1.0,), {"y": 2.0, "theta": -0.0}),
                                         ((np.float64(0.1), 2, np.nan), {})])
def test_pose_init_stores_what_the_generated_init_stored(args: tuple, kwargs: dict) -> None:
    p, q = Pose2D(*args, **kwargs), _GeneratedPose(*args, **kwargs)
    for name in ("x", "y", "theta"):
        a, b = getattr(p, name), getattr(q, name)
        assert type(a) is type(b) and (a is b or a == b or (a != a and b != b))
    assert repr(p).replace("Pose2D", "") == repr(q).replace("_GeneratedPose", "")
    if not any(isinstance(v, float) and math.isnan(v) for v in (*args, *kwargs.values())):
        assert p == Pose2D(*args, **kwargs) and hash(p) == hash(Pose2D(*args, **kwargs))
        assert hash(p) == hash(q)  # (the same field tuple)
    assert pickle.loads(pickle.dumps(p)) == p or math.isnan(p.theta)
    assert copy.deepcopy(p).x == p.x and dataclasses.replace(p, y=7.0).y == 7.0


def test_pose_stays_frozen_and_checks_its_arguments() -> None:
    p = Pose2D(1.0, 2.0, 3.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.x = 5.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        Pose2D(1.0, 2.0, 3.0, 4.0)  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        Pose2D(z=1.0)  # type: ignore[call-arg]
    assert [f.name for f in dataclasses.fields(Pose2D)] == ["x", "y", "theta"]


def test_the_inlined_motion_model_is_the_helpers_arithmetic() -> None:
    """``_prior``'s constant-velocity pose and ``_model_rates``' angular rate against ``_compose`` and
    ``float(wrap_angle(...))`` over poses that wrap and do not."""
    slam, _ = paper_room_slam()
    rng = np.random.default_rng(3)
    for _ in range(200):
        p0 = Pose2D(*rng.normal(0.0, 5.0, 2), float(rng.uniform(-math.pi, math.pi)))
        p1 = Pose2D(*rng.normal(0.0, 5.0, 2), float(rng.uniform(-4.0, 4.0)))
        t0, t1 = float(rng.uniform(0.0, 10.0)), float(rng.uniform(10.0, 11.0))
        slam._history.clear()
        slam._history.extend([(t0, p0), (t1, p1)])
        v = slam._model_rates()
        c, s_ = math.cos(p1.theta), math.sin(p1.theta)
        dx, dy = p1.x - p0.x, p1.y - p0.y
        dt = t1 - t0
        want = ((c * dx + s_ * dy) / dt, (-s_ * dx + c * dy) / dt, float(wrap_angle(p1.theta - p0.theta)) / dt)
        assert np.array([v]).tobytes() == np.array([want]).tobytes()
        slam._last_pose, slam._last_stamp, slam._state = p1, t1, pr.STATE_TRACKING
        stamp = t1 + float(rng.uniform(0.01, 0.2))
        scan = paper_room_scan(Pose2D(), stamp=stamp)
        prior = slam._prior(scan, p1, False)
        d = stamp - t1
        ref = pr._compose(p1, v[0] * d, v[1] * d, v[2] * d)
        assert (prior.pose.x, prior.pose.y, prior.pose.theta) == (ref.x, ref.y, ref.theta)
        assert np.array([prior.pose.theta]).tobytes() == np.array([ref.theta]).tobytes()


def test_the_inlined_jump_test_is_between(monkeypatch: pytest.MonkeyPatch) -> None:
    """A matcher that returns chosen poses: the match is refused as a jump exactly when ``_between`` of the start
    and the wrapped pose exceeds the limits (the inline arithmetic is ``_between``'s)."""
    slam, first = paper_room_slam()
    rng = np.random.default_rng(5)
    start = Pose2D(0.01, -0.02, 0.015)
    scan = paper_room_scan(first.compose(start), stamp=0.1)
    c = slam.config
    c.max_jump_distance, c.max_jump_angle = 0.3, 0.3  # (both limits met by some of the poses below)
    refused = 0
    for _ in range(60):
        got = np.array([start.x + rng.normal(0.0, 0.15), start.y + rng.normal(0.0, 0.15),
                        start.theta + rng.normal(0.0, 0.3)])
        monkeypatch.setattr(pr, "match_multires", lambda *a, g=got, **k: g.copy())
        monkeypatch.setattr(pr, "match_fit_at", lambda *a, g=got, **k: (g.copy(), None, None, None))
        res = slam.match(scan, predicted=start, commit=False)
        dx, dy, dth = pr._between(res.start, Pose2D(got[0], got[1], pr._wrap(float(got[2]))))
        assert (res.reason == pr.REJECT_JUMP) == (math.hypot(dx, dy) > c.max_jump_distance
                                                  or abs(dth) > c.max_jump_angle)
        refused += res.reason == pr.REJECT_JUMP
    assert 10 < refused < 50


def test_no_drop_views_are_all_false_shared_and_survive_growth(monkeypatch) -> None:
    # (a fresh cache: earlier tests may have filled the shared one's 64 entries with other beam counts)
    monkeypatch.setattr(mt, "_NO_DROP_VIEWS", {})
    monkeypatch.setattr(mt, "_NO_DROP", np.zeros(mt._NO_DROP.shape[0], dtype=np.bool_))
    a = mt.no_drop(361)
    assert a.shape == (361,) and a.dtype == np.bool_ and not a.any() and a.flags.c_contiguous
    assert mt.no_drop(361) is a
    big = mt.no_drop(mt._NO_DROP.shape[0] + 10)  # (the buffer grows; the earlier view stays valid and False)
    assert big.shape == (mt._NO_DROP.shape[0],) and not big.any()
    assert not a.any() and mt.no_drop(361) is a and mt.no_drop(0).shape == (0,)


def test_match_multires_start_copies() -> None:
    """The start as a float64 array (copied), a read-only one, a strided view, a float32 array and a list give the
    same pose bits, never the start's own array, which stays as it was."""
    slam, first = paper_room_slam()
    scan = paper_room_scan(first.compose(Pose2D(0.05, -0.03, 0.02)), stamp=0.1)
    pts = slam.scan_points(scan)[0]
    levels, c = slam.map.levels, slam.config
    base = np.array([0.01, 0.02, 0.0])
    ro = base.copy()
    ro.flags.writeable = False
    strided = np.array([0.01, 9.0, 0.02, 9.0, 0.0])[::2]
    starts = [base, ro, strided, base.astype(np.float32), base.tolist(), np.array(base, dtype=np.float64, order="F")]
    outs = []
    for s in starts:
        before = np.array(s, dtype=np.float64).tobytes()
        fit: list = []
        out = mt.match_multires(levels, pts, s, c.iterations_coarse, c.iterations_finest, False, True,
                                c.lm_lambda_init, c.lm_lambda_max, c.max_rotation_step, c.max_translation_step,
                                fit=fit, free_thresh=0.45)
        assert out is not s and out.dtype == np.float64 and out.flags.writeable
        assert np.array(s, dtype=np.float64).tobytes() == before
        assert fit  # (the one-call path)
        outs.append(out.tobytes())
    want = mt.match_multires(levels, pts, base.astype(np.float32).astype(np.float64), c.iterations_coarse,
                             c.iterations_finest, False, True, c.lm_lambda_init, c.lm_lambda_max,
                             c.max_rotation_step, c.max_translation_step).tobytes()
    assert outs[3] == want and all(o == outs[0] for o in outs[:3] + outs[4:])
    empty = mt.match_multires(levels, pts[:0], base, 4, 6)
    assert empty is not base and empty.tobytes() == base.tobytes()


def test_a_scans_trig_is_kept_by_its_first_call_and_shared_by_its_copies() -> None:
    r = np.linspace(1.0, 5.0, 90)
    s = Scan(stamp=1.0, angle_min=-1.2, angle_increment=0.02, ranges=r, range_min=0.1, range_max=30.0)
    t = s.trig()
    assert s.trig() is t and s._trig is t
    np.testing.assert_array_equal(t[0], np.cos(s.angles))
    np.testing.assert_array_equal(t[1], np.sin(s.angles))
    drop = np.zeros(90, dtype=bool)
    drop[::3] = True
    assert s.without(drop).trig() is t
    assert s.with_odometry(Pose2D()).trig() is t
    other = Scan(stamp=1.0, angle_min=-1.0, angle_increment=0.02, ranges=r[:50], range_min=0.1, range_max=30.0)
    assert other._trig is None and other.trig()[0].shape == (50,)  # (another geometry: its own arrays)
    np.testing.assert_array_equal(other.trig()[0], np.cos(other.angles))


def test_pose_compose_and_inverse_wrap_as_wrap_angle() -> None:
    rng = np.random.default_rng(11)
    for _ in range(300):
        a = Pose2D(*rng.normal(0.0, 3.0, 2), float(rng.uniform(-7.0, 7.0)))
        b = Pose2D(*rng.normal(0.0, 3.0, 2), float(rng.uniform(-7.0, 7.0)))
        assert a.compose(b).theta == float(wrap_angle(a.theta + b.theta))
        assert a.inverse().theta == float(wrap_angle(-a.theta))
        assert np.array([a.compose(b).theta]).tobytes() == np.array([float(wrap_angle(a.theta + b.theta))]).tobytes()


def test_step_result_fields_keep_the_order_process_passes_them_in() -> None:
    """``Pipeline.process`` builds its StepResult positionally: the field order it assumes, and a real step's fields
    holding what their names say."""
    from dynslam2d.pipeline import Pipeline, StepResult

    assert [f.name for f in dataclasses.fields(StepResult)] == [
        "index", "stamp", "pose", "score", "map_updated", "rejected", "skipped", "reason", "tracks", "removed",
        "removed_by", "timings", "degeneracy", "degenerate", "support_points", "support_spread", "low_support",
        "pose_source", "slam_state", "body"]
    pipe = Pipeline()
    first = Pose2D(0.3, -0.2, 0.1)
    for k in range(3):
        scan = paper_room_scan(first.compose(Pose2D(0.05 * k, 0.0, 0.0)), stamp=0.1 * k)
        step = pipe.process(scan)
    assert step.index == 2 and step.stamp == scan.stamp and isinstance(step.pose, Pose2D)
    assert isinstance(step.score, float) and 0.0 < step.score <= 1.0
    assert isinstance(step.map_updated, bool) and step.rejected is False and step.skipped is False
    # (the tracker's reports: a sequence of Track, built when read — TrackReports, passes trk70 / trk90)
    assert step.reason is None and isinstance(step.tracks, Sequence) and all(isinstance(t, Track) for t in step.tracks)
    assert step.removed.dtype == np.bool_ and step.removed_by.dtype == np.int64
    assert step.removed.shape == step.removed_by.shape == step.body.shape == scan.ranges.shape
    assert set(step.timings) == {"match", "track", "filter", "map_update", "loops", "total"}
    assert isinstance(step.degeneracy, float) and isinstance(step.degenerate, bool)
    assert isinstance(step.support_points, int) and step.support_points > 0 and step.support_spread > 0.0
    assert step.low_support is False and step.pose_source == "scan" and step.slam_state == "tracking"
