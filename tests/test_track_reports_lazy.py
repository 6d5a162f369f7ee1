"""Passes trk70 / trk90: ``Tracker.update`` returns a :class:`TrackReports` (the reports kept as ``report_rows``'
arrays and the live tracks' Python fields snapshotted at report time, a ``Track`` built when read), and the pipeline,
the filter and the erasure ledger read its columns, never building the movers.

* Every lazily built report equals, field by field and float for float, the report the eager loop built at report
  time — read one scan *later*, after the next ``update`` mutated the tracker's tracks — and every column the
  pipeline and the ledger read (records, ids, beams, states, stamps, box keys, in M, the movers' pack) is the
  objects' value.
* ``filter.mover_exclusions`` (one kernel from the columns) gives bit for bit what the object path gave: the movers'
  ``Track`` objects, ``pipeline._observed_rows`` and ``filter_scan_ids`` — in every filter mode.
* The erasure ledger fed the tracker's reports keeps the same state as one fed the same reports as plain ``Track``
  objects (``TrackReports.of_tracks``), scan after scan of a whole pipeline run."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import dynslam2d.pipeline as pl
from dynslam2d.config import Config
from dynslam2d.detect.kernels_update import report_rows
from dynslam2d.detect.layout import KIND_NAMES
from dynslam2d.detect.trackreport import TrackReport, TrackReports
from dynslam2d.detect.tracktable import STATE_NAMES
from dynslam2d.filter import filter_scan_ids, mover_beams
from dynslam2d.inputs import open_source
from dynslam2d.records import TrackRows
from dynslam2d.slam import erasure
from dynslam2d.types import Box, Track


def _eager(tracker, t: float, updated: set[int]) -> list[Track]:
    """The reports as the eager loop built them before pass trk70 (the reference: its values, at report time)."""
    tracks = tracker._tracks
    if not tracks:
        return []
    slow = 0.5 * tracker.config.tracker.v_min
    boxes, Xo, P, ints = report_rows(tracker._G, tracker._Gi, tracker._X, tracker._P, tracker._CI, tracker._rows(),
                                     slow)
    kinds, states, hits, misses = ints.tolist()[:4]
    out = []
    cols = boxes.T.tolist()
    for i, k in enumerate(tracks):
        beams = k.beams if k.id in updated else np.zeros(0, dtype=np.int64)
        out.append(Track(k.id, STATE_NAMES[states[i]], t, Box(*[c[i] for c in cols]), Xo[i, 2:].copy(),
                         P[i].copy(), t - k.born, hits[i], misses[i], KIND_NAMES[kinds[i]], k.in_m, k.reason,
                         beams.copy(), len(beams), k.remembered and k.in_m))
    return out


def _mover_segments(packed: np.ndarray, beams: np.ndarray, more: np.ndarray) -> list[np.ndarray]:
    """Each mover's beams of ``TrackReports.mover_pack``'s result, place by place as ``filter._grow_boxes`` reads
    them (place ``q``: ``beams[q]`` below the split point ``n0``, else ``more[q − n0]``)."""
    k = (packed.shape[0] - 1) // 4
    n0 = int(packed[4 * k])
    return [np.array([beams[q] if q < n0 else more[q - n0] for q in range(s, s + c)], dtype=np.int64)
            for s, c in zip(packed[2 * k:3 * k].tolist(), packed[3 * k:4 * k].tolist())]


def _same(a: Track, b: Track) -> None:
    for f in dataclasses.fields(Track):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            assert isinstance(vb, np.ndarray) and va.dtype == vb.dtype and va.shape == vb.shape, f.name
            assert va.tobytes() == vb.tobytes(), f.name
        elif isinstance(va, Box):
            assert dataclasses.astuple(va) == dataclasses.astuple(vb), f.name
            assert all(type(x) is float for x in dataclasses.astuple(va)), f.name
        else:
            assert type(va) is type(vb) and va == vb, (f.name, va, vb)


def _columns_are_the_objects(lazy: TrackReports) -> None:
    """Every column reader of ``lazy`` against the values of its built objects (read through the columns first)."""
    n = len(lazy)
    ids = list(lazy.ids)
    keys = [lazy.box_key(i) for i in range(n)]
    states = [lazy.state_of(i) for i in range(n)]
    stamps = [lazy.stamp_of(i) for i in range(n)]
    wb = lazy.with_beams()
    idx = lazy.moving_index()
    packed, beams, more, mids = lazy.mover_pack(idx)
    sights = [lazy.sight(i) for i in range(n)]
    tr_a, tr_b = TrackRows(), TrackRows()
    recs = pl._track_records(1.5, lazy, tr_a)
    objs = list(lazy)  # (built now)
    assert ids == [t.id for t in objs]
    assert keys == [erasure._box_key(t) for t in objs] and all(type(v) is float for k in keys for v in k)
    assert states == [t.state for t in objs] and stamps == [t.stamp for t in objs]
    assert recs == pl._track_records(1.5, objs, tr_b)
    assert [erasure._sight_key(s) for s in sights] == keys
    assert all(s is objs[i] or (type(s) is tuple and s[0] is lazy and s[1] == i) for i, s in enumerate(sights))
    mine = [i for i, t in enumerate(objs) if t.beams is not None and len(t.beams)]
    assert wb[0] == mine and wb[2] == [objs[i].id for i in mine]
    assert all(a is objs[i].beams for a, i in zip(wb[1], mine))
    assert idx == [i for i, t in enumerate(objs) if t.in_m]
    moving = [objs[i] for i in idx]
    rows, want_ids, own, ends = pl._track_rows(moving)
    k = len(idx)
    assert packed.dtype == np.int64 and packed.shape == (4 * k + 1,) and mids == want_ids.tolist()
    assert packed[:2 * k].tolist() == idx + want_ids.tolist()
    assert beams.dtype == np.int64 and more.dtype == np.int64
    # (each mover's beams, read from their places as the filter's kernel reads them, are its object's, in order)
    assert [b.tobytes() for b in _mover_segments(packed, beams, more)] == \
        [np.asarray(t.beams, dtype=np.int64).tobytes() if t.beams is not None else b"" for t in moving]
    assert mover_beams(packed, beams, more).tobytes() == \
        (np.concatenate(own) if own else np.zeros(0, dtype=np.int64)).astype(np.int64).tobytes()
    assert [e - s for s, e in zip([0, *ends], ends)] == packed[3 * k:4 * k].tolist()
    boxes, X = lazy.arrays
    assert np.concatenate((boxes[idx], X[idx, 2:]), axis=1).reshape(k, 7).tobytes() == rows.tobytes()


@pytest.mark.parametrize(("scene", "inline"), [("sim:crowd", True), ("sim:stop-and-go", True), ("sim:crowd", False)])
def test_lazy_reports_equal_the_eager_ones_read_a_scan_later(scene: str, inline: bool, monkeypatch) -> None:
    """(``inline``: the objects built in place, or by the constructors where ``_INLINE`` is off.)"""
    from dynslam2d.detect import trackreport

    monkeypatch.setattr(trackreport, "_INLINE", trackreport._INLINE and inline)
    pairs: list[tuple[TrackReports, list[Track], object]] = []
    orig = TrackReport._report

    def spy(self, t, updated):
        ref = _eager(self, t, updated)
        out = orig(self, t, updated)
        assert type(out) is TrackReports
        pairs.append((out, ref, self))
        return out

    monkeypatch.setattr(TrackReport, "_report", spy)
    p = pl.Pipeline()
    seen = {"reports": 0, "in_m": 0, "beams": 0, "changed": 0, "dormant": 0}
    for scan in open_source(scene, seed=5, duration=12.0):
        p.process(scan)
        # the previous scan's reports, read only now (the tracker's tracks moved on since)
        for lazy, ref, tracker in pairs[:-1]:
            live = {k.id: k for k in tracker._tracks}
            assert lazy.n_live == len(ref) and all(r is None for r in lazy._built)  # (nothing built them)
            _columns_are_the_objects(lazy)
            got = list(lazy)[:lazy.n_live]
            assert lazy[lazy.n_live:] == list(lazy)[lazy.n_live:]
            seen["dormant"] += len(lazy) - lazy.n_live
            for g, r in zip(got, ref):
                _same(g, r)
                assert not np.shares_memory(g.velocity, tracker._X) and not np.shares_memory(g.covariance, tracker._P)
                assert g is lazy[got.index(g)]  # (built once: the same object on every read)
                k = live.get(g.id)
                if k is not None and (k.in_m != g.in_m or k.reason != g.m_reason):
                    seen["changed"] += 1
                seen["reports"] += 1
                seen["in_m"] += g.in_m
                seen["beams"] += g.n_points > 0
        del pairs[:-1]
    assert seen["reports"] > 200 and seen["in_m"] > 20 and seen["beams"] > 100 and seen["changed"] > 0, seen


def test_of_tracks_keeps_the_objects_and_reads_their_values() -> None:
    """A plain list of ``Track`` wrapped for the column readers: its items are the given objects, every column their
    values (a state name the tracker does not use keeps its own code), and a ``TrackReports`` is returned as it is."""
    def track(tid: int, state: str, in_m: bool, beams) -> Track:
        return Track(tid, state, 2.5, Box(1.0 + tid, -0.5, 0.25, 0.8, 1.1), np.array([0.5, -0.25]), np.eye(4),
                     1.0, 3, 0, "rect", in_m, "r", beams, 0 if beams is None else len(beams), in_m)

    objs = [track(3, "confirmed", True, np.array([4, 5])), track(9, "parked", False, None),
            track(4, "tentative", True, np.zeros(0, dtype=np.int64))]
    reps = TrackReports.of_tracks(objs)
    assert TrackReports.of_tracks(reps) is reps and list(reps) == objs and all(a is b for a, b in zip(reps, objs))
    _columns_are_the_objects(reps)
    assert reps + [objs[0]] == [*objs, objs[0]] and [objs[1]] + reps == [objs[1], *objs]
    assert reps.sight(1) is objs[1] and reps.state_of(1) == "parked"


_MODES = {
    "box": {},
    "square-capped": {"default_shape": "square", "max_half_extent": 0.4, "margin": 0.3},
    "speed-margin": {"speed_margin_time": 0.1, "max_half_extent": None},
    "adaptive": {"mode": "adaptive"},
    "fixed": {"mode": "fixed", "expected_objects": 5},
}


@pytest.mark.parametrize("mode", list(_MODES))
def test_mover_exclusions_equal_the_object_path(mode: str, monkeypatch) -> None:
    """Each scan's movers: the rows, ids and removed beams of ``mover_exclusions`` are those of the movers' built
    ``Track`` objects through ``_observed_rows`` (kept rows: its ungrown copy) and ``filter_scan_ids`` at dt 0."""
    cfg = Config()
    for key, value in _MODES[mode].items():
        setattr(cfg.filter, key, value)
    packs: list[tuple[TrackReports, list[int]]] = []
    orig_pack, orig_ex = TrackReports.mover_pack, pl.mover_exclusions
    checked = {"scans": 0, "movers": 0, "removed": 0}

    def pack(self, idx):
        packs.append((self, list(idx)))
        return orig_pack(self, idx)

    def exclusions(config, scan, pose, boxes, states, packed, beams, more):
        got = orig_ex(config, scan, pose, boxes, states, packed, beams, more)
        reps, idx = packs.pop()
        moving = [reps[i] for i in idx]
        keep: list = []
        rows, ids = pl._observed_rows(moving, scan, pose, keep)
        removed, removed_by = filter_scan_ids(config, scan, pose, rows, ids, 0.0)
        assert got[0].tobytes() == keep[0][0].tobytes() and got[0].shape == (len(idx), 7)
        assert got[1].dtype == np.int64 and got[1].tobytes() == ids.tobytes()
        assert got[2].dtype == np.bool_ and got[2].tobytes() == removed.tobytes()
        assert got[3].dtype == np.int64 and got[3].tobytes() == removed_by.tobytes()
        checked["scans"] += 1
        checked["movers"] += len(idx)
        checked["removed"] += int(removed.sum())
        return got

    monkeypatch.setattr(TrackReports, "mover_pack", pack)
    monkeypatch.setattr(pl, "mover_exclusions", exclusions)
    p = pl.Pipeline(cfg)
    for scan in open_source("sim:crowd", seed=3, duration=8.0):
        p.process(scan)
    assert checked["scans"] > 40 and checked["movers"] > 80 and checked["removed"] > 200, checked


def _ledger_state(led: erasure.EvidenceLedger) -> tuple:
    led._sync_sights()  # (pass glu121: the live ledgers' last sights written as they read)

    def one(x) -> tuple:
        return (x.id, x.first_box, x.first_t, x.last_box, x.last_seen, x.m_start, x.linked, x.confirmed, x.skip,
                None if x.last_track is None else erasure._last_key(x), x.n_cells)

    return ([one(x) for x in led._ledgers.values()], [one(x) for x in led._ended.values()], dict(led.stats),
            led._F.tobytes(), sorted(led.erased_cells))


def test_the_ledger_from_the_columns_keeps_the_state_of_the_ledger_fed_objects(monkeypatch) -> None:
    """Two pipelines in lockstep on a scene where movers stop, stand and leave (ledgers started, confirmed, ended,
    linked, erased): one as it runs, the other with its tracker's reports handed on as plain ``Track`` objects (the
    pipeline and the ledger read them through ``TrackReports.of_tracks``). After every scan: the same removed
    beams, ledger state and map."""
    from dynslam2d.detect.tracker import Tracker

    class Plain(Tracker):
        def update(self, *a, **kw):
            return list(super().update(*a, **kw))

    a, b = pl.Pipeline(), pl.Pipeline()
    b.tracker = Plain(b.config.detect)
    erased = 0
    for scan in open_source("sim:stop-and-go", seed=2, duration=20.0):
        sa, sb = a.process(scan), b.process(scan)
        assert type(sa.tracks) is TrackReports and type(sb.tracks) is TrackReports
        assert sa.removed_by.tobytes() == sb.removed_by.tobytes()
        assert _ledger_state(a.ledger) == _ledger_state(b.ledger)
        erased += a.ledger.stats["cells_changed"]
    assert a.ledger.stats["erasures"] > 0 and erased > 0, a.ledger.stats
    assert a.gridmap().prob.tobytes() == b.gridmap().prob.tobytes()


def test_erase_entering_from_the_movers_rows_keeps_the_state_of_the_reports_path() -> None:
    """``EvidenceLedger.erase_entering`` given the pipeline's movers' ids and rows (pass trk97) and the same call
    reading the reports' columns (``movers`` None), two pipelines in lockstep on a scene where movers stop, stand and
    leave: after every scan the same ledger state and, at the end, the same map."""
    a, b = pl.Pipeline(), pl.Pipeline()
    orig = b.ledger.erase_entering
    calls = {"with movers": 0}

    def from_reports(tracks, removing, stamp, hmap, movers=None):
        calls["with movers"] += movers is not None
        return orig(tracks, removing, stamp, hmap)

    b.ledger.erase_entering = from_reports
    for scan in open_source("sim:stop-and-go", seed=2, duration=20.0):
        sa, sb = a.process(scan), b.process(scan)
        assert sa.removed_by.tobytes() == sb.removed_by.tobytes()
        assert _ledger_state(a.ledger) == _ledger_state(b.ledger)
    assert a.ledger.stats["erasures"] > 0 and calls["with movers"] > 20, (a.ledger.stats, calls)
    assert a.gridmap().prob.tobytes() == b.gridmap().prob.tobytes()


def test_mover_pack_makes_int64_beams_of_any_integer_beams() -> None:
    """The movers' beams concatenated as int64 whatever the integer type of each track's beams (pass mov133: the
    concatenation's own dtype instead of an astype after it), the running counts after each mover."""
    def track(tid: int, in_m: bool, beams) -> Track:
        return Track(tid, "confirmed", 2.5, Box(1.0 + tid, -0.5, 0.25, 0.8, 1.1), np.array([0.5, -0.25]), np.eye(4),
                     1.0, 3, 0, "rect", in_m, "r", beams, len(beams), in_m)

    objs = [track(3, True, np.array([4, 5], dtype=np.int32)), track(9, False, np.array([1], dtype=np.int64)),
            track(4, True, np.array([700, 2], dtype=np.int16)), track(6, True, np.zeros(0, dtype=np.int64))]
    reps = TrackReports.of_tracks(objs)
    packed, beams, more, mids = reps.mover_pack(reps.moving_index())
    assert beams.dtype == np.int64 and beams.tolist() == [4, 5, 700, 2] and more.shape == (0,)
    # (indices, ids, first places, counts, split point: the objects' beams are concatenated, pass rep149)
    assert packed.dtype == np.int64 and packed.tolist() == [0, 2, 3, 3, 4, 6, 0, 2, 4, 2, 2, 0, 4]
    assert mids == [3, 4, 6]


def test_a_run_builds_no_track_object(monkeypatch) -> None:
    """Pass cln147: the per-scan path (filter, erasure ledger, the run's records) reads the reports' columns only,
    so no tracker work is done lazily inside the filter stage's timing: ``pipeline.run`` over a scene whose movers
    enter M, stop and leave (filter and ledger at work) builds no ``Track`` of a live report."""
    built: list[int] = []
    build_many = TrackReports._build_many

    def counted(self, idx):
        built.append(len(idx))
        return build_many(self, idx)

    monkeypatch.setattr(TrackReports, "_build_many", counted)
    moving = [0]

    def observe(n: int, step) -> None:
        moving[0] += bool(step.removed.any())

    pl.run(open_source("sim:stop-and-go", seed=2, duration=20.0), progress=observe)
    assert moving[0] > 20, moving  # (the filter removed beams on many scans)
    assert sum(built) == 0, built
