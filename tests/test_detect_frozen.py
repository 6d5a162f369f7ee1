"""The tracker's cheap bookkeeping (issue 9 speed): fast report constructors, bounded history, reports
that own their arrays — each checked against the plain construction or on a simulated moving box."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
from conftest import room_box_scan

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.frozen import fast_init
from dynslam2d.types import Box, Pose2D, Scan, Track

N = 360


def _fields(obj: object) -> list:
    return [getattr(obj, f.name) for f in dataclasses.fields(obj)]


def test_fast_init_builds_the_same_frozen_objects_as_the_class() -> None:
    make_box, make_track = fast_init(Box), fast_init(Track)
    assert make_box is not Box and make_track is not Track  # both qualify for the fast path
    b = make_box(1.0, -2.0, 0.3, 0.8, 0.5)
    ref = Box(1.0, -2.0, 0.3, 0.8, 0.5)
    assert type(b) is Box and b == ref and hash(b) == hash(ref)
    args = (7, "confirmed", 2.5, b, np.array([0.1, 0.2]), np.eye(4), 1.5, 9, 0, "rect", True, "in M", np.arange(3),
            3)
    t, tref = make_track(*args), Track(*args)
    assert type(t) is Track and all(a is c for a, c in zip(_fields(t), _fields(tref)))  # every field, in order
    assert t.remembered is False  # the field's default
    assert make_track(*args, remembered=True).remembered is True
    assert make_track(**{f.name: v for f, v in zip(dataclasses.fields(Track), args)}).hits == 9  # keywords
    with pytest.raises(dataclasses.FrozenInstanceError):
        t.hits = 3  # type: ignore[misc]
    with pytest.raises(TypeError):
        make_box(1.0, 2.0)  # missing fields are an error, as with the class
    # built on a twin class of the same slots, then re-classed: nothing of the twin is left on the object
    for obj, ref_obj in ((b, ref), (t, tref)):
        assert obj.__class__ is type(ref_obj) and not hasattr(obj, "__dict__")
        c = pickle.loads(pickle.dumps(obj))
        assert type(c) is type(ref_obj) and all(
            np.array_equal(u, w) for u, w in zip(_fields(c), _fields(ref_obj)))


def test_fast_init_falls_back_to_the_class_where_slots_cannot_be_set_directly() -> None:
    @dataclasses.dataclass(frozen=True)
    class NoSlots:
        a: int

    @dataclasses.dataclass(frozen=True, slots=True)
    class PostInit:
        a: int

        def __post_init__(self) -> None:
            pass

    @dataclasses.dataclass(slots=True)
    class Factory:
        a: list = dataclasses.field(default_factory=list)

    for cls in (NoSlots, PostInit, Factory):
        assert fast_init(cls) is cls


def _scan(pose: Pose2D, box_x: float, stamp: float, seed: int) -> Scan:
    return room_box_scan(pose, (box_x, 1.5, 0.8, 0.5), stamp, seed, N)


def test_history_is_bounded_and_reports_own_their_arrays() -> None:
    """A box driven past the laser for 60 updates: each track keeps at most ``confirm_window`` history entries
    (the M-of-N rule reads no more), and a report's covariance / velocity are not the tracker's arrays (writing
    into a report leaves the next step unchanged)."""
    cfg = DetectConfig()
    tr = Tracker(cfg)
    pose = Pose2D(0.0, -2.0, 0.0)
    out = []
    for i in range(60):
        out = tr.update(_scan(pose, -3.0 + 0.05 * i, i / 15.0, i), pose)
    box = [t for t in out if t.in_m]
    assert len(box) == 1 and box[0].hits >= 50
    assert all(k.hist_hits <= k.hist_n <= cfg.tracker.confirm_window for k in tr._tracks)
    k = next(k for k in tr._tracks if k.id == box[0].id)
    assert not np.shares_memory(box[0].covariance, k.P) and not np.shares_memory(box[0].velocity, k.x)
    cov_before = k.P.copy()
    box[0].covariance[:] = 1e6  # a caller scribbling on its report
    box[0].velocity[:] = 99.0
    assert np.array_equal(k.P, cov_before) and float(np.hypot(k.x[2], k.x[3])) < 1.0


def test_report_built_in_place_is_the_constructors_report(monkeypatch) -> None:
    """``Tracker._report`` builds the live tracks' reports in its loop (``trackreport._INLINE``): on every step of a
    box driven past the laser (clutter tracks born, confirmed, coasting and deleted around it), the same reports as
    the loop that calls the ``fast_init`` constructors — every field, floats and arrays bit for bit, the same types,
    no attribute of the twin classes left — and the reports are frozen."""
    from dynslam2d.detect import trackreport

    assert trackreport._INLINE  # the in-place form is the one the tracker runs
    tr = Tracker(DetectConfig())
    pose = Pose2D(0.0, -2.0, 0.0)
    orig = tr._report
    steps = 0

    def both(t, updated):
        nonlocal steps
        got = list(orig(t, updated))  # (the reports are built when read: read each at once, pass trk90)
        monkeypatch.setattr(trackreport, "_INLINE", False)
        want = list(orig(t, updated))
        monkeypatch.setattr(trackreport, "_INLINE", True)
        assert len(got) == len(want)
        for a, b in zip(got, want):
            assert type(a) is Track and type(a.box) is Box and not hasattr(a, "__dict__")
            fa, fb = _fields(a), _fields(b)
            assert [type(v) for v in fa] == [type(v) for v in fb]
            for u, w in zip(fa, fb):
                if isinstance(u, np.ndarray):
                    assert u.dtype == w.dtype and u.shape == w.shape and u.tobytes() == w.tobytes()
                else:
                    assert u == w
        for a in got:
            with pytest.raises(dataclasses.FrozenInstanceError):
                a.box.px = 0.0  # type: ignore[misc]
        steps += bool(got)
        return got

    tr._report = both
    coasted = updated = 0
    for i in range(60):
        # (every 7th scan the box is outside the room: its track coasts, reported without beams)
        out = tr.update(_scan(pose, 50.0 if i % 7 == 6 else -3.0 + 0.05 * i, i / 15.0, i), pose)
        coasted += sum(t.n_points == 0 for t in out)
        updated += sum(t.n_points > 0 for t in out)
    assert steps >= 50 and coasted >= 5 and updated >= 40
