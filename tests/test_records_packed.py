"""The run loop's packed records (pass pip92): ``TrackRows.add_tracks`` and ``PackedGrowArray.add_raw`` store the
bytes the NumPy way stores (``extend_records`` of ``pipeline._track_records``, a structured row assignment), across
the waiting bytes' flushes, reads in between, and the values ``struct`` refuses."""

from __future__ import annotations

import math

import numpy as np
import pytest

import dynslam2d.pipeline as pl
from dynslam2d import records
from dynslam2d.detect.trackreport import TrackReports
from dynslam2d.records import PackedGrowArray, TrackRows
from dynslam2d.types import Box, Track


def _track(rng: np.random.Generator, tid: int, state: str) -> Track:
    b = Box(*rng.normal(size=5).tolist())
    return Track(tid, state, 0.0, b, rng.normal(size=2), np.eye(4), 1.0, 3, 0, "person", bool(rng.random() < 0.5),
                 "", np.zeros(0, dtype=np.int64), 0, bool(rng.random() < 0.3))


def test_add_tracks_stores_what_extend_records_stores():
    rng = np.random.default_rng(5)
    a, b = TrackRows(), TrackRows()
    b._rows._chunk = 75 * 7  # (flushed every few scans, mid-scan too)
    fell_back = 0
    for scan in range(300):
        states = ["tentative", "confirmed", "coasting", "deleted"] + (["odd"] if scan == 40 else [])
        tracks = [_track(rng, int(rng.integers(1, 999)), states[int(rng.integers(0, len(states)))])
                  for _ in range(int(rng.integers(0, 9)))]
        if scan == 41 and tracks:
            tracks[0] = _track(rng, 7, "odd")  # (a code added by the NumPy way earlier: packed now)
        if scan == 12:
            tracks.append(Track(3, "confirmed", 0.0, Box(None, 1.0, 0.0, 1.0, 1.0), np.array([math.nan, -0.0]),  # type: ignore[arg-type]
                                np.eye(4), 1.0, 1, 0, "box", np.bool_(True), "", np.zeros(0, dtype=np.int64), 0, 0))
        stamp = 0.05 * scan
        a.extend_records(pl._track_records(stamp, tracks, a))
        if tracks and not b.add_tracks(stamp, tracks):
            fell_back += 1
            b.extend_records(pl._track_records(stamp, tracks, b))
        if scan % 50 == 7:
            assert len(a) == len(b)  # (a read between scans settles the waiting bytes)
    assert fell_back >= 1
    assert len(a) == len(b) and a.array().tobytes() == b.array().tobytes() and a.state_names() == b.state_names()
    assert [r[2] for r in a] == [r[2] for r in b] and np.array_equal(a.remembered(), b.remembered())


def test_packed_scan_rows_equal_structured_assignment():
    rows = [(0.1 * i, (1.0 * i, -2.5, math.pi), 0.5 + i, (i % 2 == 0, False, i % 3 == 0), True, False, i % 5 == 0,
             math.nan if i % 4 else 1e-3 * i) for i in range(700)]
    g = PackedGrowArray(pl._SCAN_RECORD, capacity=4, chunk=54 * 100)
    stored = []
    for i, r in enumerate(rows):
        st, (x, y, th), sc, (f0, f1, f2), lo, dg, lost, deg = r
        g.add_raw(pl._PACK_SCAN(st, x, y, th, sc, f0, f1, f2, lo, dg, lost, deg))
        stored.append(r)
        if i == 333:
            g.append(rows[0])  # (a NumPy row after waiting bytes keeps the order)
            stored.append(rows[0])
    a = np.zeros(len(stored), dtype=pl._SCAN_RECORD)
    for i, r in enumerate(stored):
        a[i] = r
    assert len(g) == len(stored) and g.view().tobytes() == a.tobytes() and g.nbytes >= a.nbytes


def _reports(rng: np.random.Generator, t: float, n: int, snames: tuple[str, ...] | None = None) -> TrackReports:
    """Reports of ``n`` live tracks as ``Tracker._report`` makes them (random columns)."""
    boxes, xo = rng.normal(size=(n, 5)), rng.normal(size=(n, 4))
    nst = 3 if snames is None else len(snames)
    # (kinds, states, hits, misses, the beam segments' first points and counts: −1, not a segment, as report_rows
    # gives a newborn track's)
    ints = [[0] * n, [int(rng.integers(0, nst)) for _ in range(n)], [1] * n, [0] * n, [0] * n, [-1] * n]
    in_m = tuple(bool(rng.random() < 0.5) for _ in range(n))
    cols = (tuple(int(rng.integers(1, 999)) for _ in range(n)), (0.0,) * n, in_m, ("",) * n,
            tuple(bool(rng.random() < 0.5) for _ in range(n)), (np.zeros(0, dtype=np.int64),) * n)
    r = TrackReports(t, boxes, xo, np.zeros((n, 4, 4)), ints, cols, frozenset())
    if snames is not None:
        r._snames = snames
    return r


def test_add_rows_stores_what_extend_records_stores(monkeypatch: pytest.MonkeyPatch):
    """The run loop's record of the tracker's reports from their columns (``TrackReports.add_rows`` →
    ``TrackRows.add_columns``, pass rec105): the bytes ``extend_records`` stores for ``_track_records``' rows,
    across the waiting columns' settling (a small chunk), reads in between, rows added as bytes between them (a list
    of ``Track``), the fallbacks (dormant reports, a state name not coded yet) and a state code table not the
    tracker's."""
    monkeypatch.setattr(records, "_COLUMN_CHUNK", 23)
    rng = np.random.default_rng(11)
    a, b = TrackRows(), TrackRows()
    used = fell_back = 0
    for scan in range(300):
        stamp = 0.05 * scan
        n = int(rng.integers(0, 9))
        tracks: object
        if scan in (30, 31):  # (a name the rows have not coded: the reports' order codes it, then a mapped table)
            tracks = _reports(rng, stamp, n + 1, ("tentative", "odd", "confirmed", "coasting"))
        elif scan % 37 == 5:
            tracks = [_track(rng, int(rng.integers(1, 999)), "confirmed") for _ in range(n)]
        else:
            tracks = _reports(rng, stamp, n)
            if scan % 41 == 2:
                tracks.extend([_track(rng, 5, "coasting")])
        a.extend_records(pl._track_records(stamp, tracks, a))  # type: ignore[arg-type]
        if tracks:
            if type(tracks) is TrackReports and tracks.add_rows(stamp, b):
                used += 1
            elif not (type(tracks) is list and b.add_tracks(stamp, tracks)):
                fell_back += 1
                b.extend_records(pl._track_records(stamp, tracks, b))  # type: ignore[arg-type]
        if scan % 50 == 7:
            assert len(a) == len(b) and a[-1] == b[-1]  # (a read between scans settles the waiting columns)
    assert used > 200 and fell_back >= 8
    assert len(a) == len(b) and a.array().tobytes() == b.array().tobytes() and a.state_names() == b.state_names()
    assert list(a) == list(b) and np.array_equal(a.remembered(), b.remembered())


def test_add_columns_refuses_without_adding():
    """A value the C calls refuse (an id beyond int64, a ``None`` stamp or flag, a strided box array, a negative
    code) adds nothing; ints as flags are stored as their truth, remembered as ``operator.and_`` with in M."""
    rows = TrackRows()
    boxes, xv = np.arange(10.0).reshape(2, 5), np.arange(8.0).reshape(2, 4)
    assert rows.add_columns(1.0, (1, 2), [1, 2], boxes, xv, (2, 0), (1, 3))
    assert not rows.add_columns(2.0, (1, 2**63), [1, 1], boxes, xv, (1, 1), (0, 0))
    assert not rows.add_columns(None, (1, 2), [1, 1], boxes, xv, (1, 1), (0, 0))  # type: ignore[arg-type]
    assert not rows.add_columns(2.0, (1, 2), [1, 1], boxes, xv, (None, 1), (0, 0))  # type: ignore[arg-type]
    assert not rows.add_columns(2.0, (1, 2), [1, -1], boxes, xv, (1, 1), (0, 0))
    assert not rows.add_columns(2.0, (1, 2), [1, 1], np.asfortranarray(boxes), xv, (1, 1), (0, 0))
    ref = TrackRows()
    ref.extend_records([(1.0, 1, 1, *range(5), 2.0, 3.0, True, False), (1.0, 2, 2, *range(5, 10), 6.0, 7.0, False,
                                                                       False)])
    assert len(rows) == 2 and rows.array().tobytes() == ref.array().tobytes()


def test_run_writes_the_records_each_scan_would_write():
    """``pipeline.run`` writes its records ``RECORD_BATCH`` scans at a time (pass rec110): the scan rows, removed
    bits, track rows and stage timings are those written one scan at a time as each scan's result came out of
    ``Pipeline.process`` (an observer called every scan), 100 scans of sim:crowd — the last 4 after the last whole
    batch — with tracks on most of them."""
    from itertools import islice

    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source

    full = open_source("sim:crowd", None)

    class First:
        meta = full.meta

        def __iter__(self):  # type: ignore[no-untyped-def]
            return islice(iter(full), 100)

    class EachScan:
        def __init__(self) -> None:
            self.ref = pl._RunRecords()
            self.n_tracks = 0

        def on_scan(self, scan, step, pipeline) -> None:  # type: ignore[no-untyped-def]
            self.ref.add([step])
            self.n_tracks += len(step.tracks)

        def on_finish(self, result, pipeline) -> None:  # type: ignore[no-untyped-def]
            pass

    obs = EachScan()
    res = pl.run(First(), Config(), observers=[obs])
    ref = obs.ref
    assert pl.RECORD_BATCH > 1 and res.n_scans == 100 and 100 % pl.RECORD_BATCH and obs.n_tracks > 200
    assert res.scores.tobytes() == ref.per_scan.view()["score"].tobytes()
    assert res.trajectory.poses.tobytes() == ref.per_scan.view()["pose"].tobytes()
    assert len(res.removed_rows) == 100 and res.removed_rows.stack().tobytes() == ref.removed.stack().tobytes()
    assert res.removed_rows.total_set == ref.removed.total_set > 0
    assert res.track_rows.array().tobytes() == ref.tracks.array().tobytes()
    assert res.track_rows.state_names() == ref.tracks.state_names()
    want = ref.stages.arrays()
    assert list(res.timings_ms) == list(want) and all(res.timings_ms[k].tobytes() == want[k].tobytes() for k in want)
