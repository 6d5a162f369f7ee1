"""``EvidenceLedger.observe`` (slam/erasure.py; pass ledger16 unpacks each track's velocity) against a frozen copy
of pass ledger15's version, on random track sequences: births, ends (tentative and confirmed, with and without
pending rows), standing and moving tracks, tracks in and out of the removal set, ledgers started before and
after a track's first report, stays in the removal set, repeated ids in one scan's list. After every scan the
two ledgers' whole state must be the same (pass led26: once the ended ledgers that wait for their batch are packed
and the dropped ones counted; in between, all but those): each live track's standing box (in the dict's order),
every ledger's fields, the ended ledgers in order (the order of linked erasures) with their packed rows, the
oldest ended stamp and the counters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import EvidenceLedger
from dynslam2d.types import Box, Track


def _observe_ref(self: EvidenceLedger, tracks: list, removing: set, stamp: float) -> None:
    """``EvidenceLedger.observe`` as pass ledger15 left it (the specification)."""
    reach = self.config.link_margin + 0.5
    stand = self.config.stand_speed
    first = self._first
    ledgers = self._ledgers
    hypot = math.hypot
    for t in tracks:
        tid = t.id
        a = first.get(tid)
        out = tid not in removing
        if a is None:
            first[tid] = [er._box_key(t), stamp, stamp]
        elif out and hypot(*t.velocity.tolist()) < stand:
            b, f = t.box, a[0]
            if hypot(b.px - f[0], b.py - f[1]) <= reach:
                a[2] = stamp
            else:
                first[tid] = [er._box_key(t), stamp, stamp]
        if out:
            led = ledgers.get(tid)
            if led is not None:
                if led.m_start is not None:
                    led.m_start, led.skip, led.linked = None, False, False
                led.last_track = t
                led.last_seen = stamp
                if not led.confirmed and t.state != "tentative":
                    led.confirmed = True
    live = {t.id for t in tracks}
    if len(first) > len(live):
        self._first = {tid: b for tid, b in first.items() if tid in live}
    for tid in [i for i in ledgers if i not in live]:
        led = ledgers.pop(tid)
        if led.last_track is not None:
            led.last_box = er._box_key(led.last_track)
        if led.confirmed:
            led.pack()
            self._ended[tid] = led
            self._oldest_ended = min(self._oldest_ended, led.last_seen)
        else:
            self._drop(led)
    keep = self.config.ledger_keep_s
    if self._ended and stamp - self._oldest_ended > keep:
        for tid in [i for i, led in self._ended.items() if stamp - led.last_seen > keep]:
            self._drop(self._ended.pop(tid))
        self._oldest_ended = min((led.last_seen for led in self._ended.values()), default=math.inf)


class _DictLedger(EvidenceLedger):
    """The ledger with its standing boxes in a dict, ``{id: [box, t0, t1]}`` (pass ledger15's form; pass led32 keeps
    them in id-indexed arrays)."""

    _first = None  # (an attribute of the instance: shadows the property)

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self._first = {}

    def _first_of(self, tid: int):
        return self._first.get(tid)


def _track(tid: int, state: str, stamp: float, x: float, y: float, v: float, size: float) -> Track:
    vel = np.array([v, 0.0]) if tid % 2 else np.array([0.0, -v])
    return Track(id=tid, state=state, stamp=stamp, box=Box(x, y, 0.3, size, 0.5 * size), velocity=vel,
                 covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect", in_m=False,
                 m_reason="", beams=np.zeros(0, dtype=np.int64), n_points=0)


def _ledger_state(led, ended: bool = False) -> tuple:
    # (each entry's rows as they read: an ended ledger's are squeezed, with the batch it was packed in, pass mem41)
    ent = [(er._unsqueeze_rows(r, a, b).tobytes(), b - a, lv if type(lv) is int else tuple(lv))
           for r, a, b, lv in led.ent]
    # (an ended ledger's track is never read again: pass ldg47 lets it go when the track ends, the reference keeps it;
    # checked apart, _ended_tracks)
    return (led.id, led.first_box, led.first_t, led.last_box, led.last_seen, led.m_start, led.linked, led.confirmed,
            led.skip, None if ended else id(led.last_track), ent, led.recs is None, led.nb_rows, led.nb_chunks)


def _ended_tracks(led: EvidenceLedger) -> list:
    """The tracks the ended ledgers still hold."""
    return [v.last_track for v in led._ended.values() if v.last_track is not None]


def _state(led: EvidenceLedger, full: bool = True) -> tuple:
    """The ledger's whole state; without ``full``, only what does not wait for :meth:`EvidenceLedger._finish_ended`
    (the ended ledgers' ids and stamps, not their packed rows; not the counters)."""
    led._sync_sights()  # (pass glu121: the live ledgers' last sights written as they read)
    if not full:
        return (sorted(led._first.items()), [(k, _ledger_state(v)) for k, v in led._ledgers.items()],
                [(k, v.last_seen, v.last_box) for k, v in led._ended.items()], led._oldest_ended)
    return (sorted(led._first.items()), [(k, _ledger_state(v)) for k, v in led._ledgers.items()],
            [(k, _ledger_state(v, True)) for k, v in led._ended.items()], led._oldest_ended, dict(led.stats))


@pytest.mark.parametrize("seed", range(12))
def test_observe_keeps_the_same_state_as_pass_ledger15s(seed: int, monkeypatch) -> None:
    rng = np.random.default_rng(seed)
    if seed % 2:  # (batches of three: observe packs and counts them itself, often)
        monkeypatch.setattr(er, "_END_BATCH", 3)
    cfg = MemoryConfig(ledger_keep_s=float(rng.choice([0.5, 2.0, 600.0])), link_margin=0.5, stand_speed=0.25)
    new = EvidenceLedger(cfg, 0.1, 30.0)
    ref = _DictLedger(cfg, 0.1, 30.0)
    # (pass glu121: a ledger read only every seventh scan, so that its last sights are written from the call that
    # saw them when the track enters the removal set or ends, not when the state is read)
    lazy = EvidenceLedger(cfg, 0.1, 30.0)
    pool: dict[int, list] = {}  # id → [state, x, y, standing, size]
    next_id = 1
    stamp = 0.0
    stand = cfg.stand_speed
    reach = cfg.link_margin + 0.5
    removing: set[int] = set()
    blocks = [rng.integers(-50, 50, (5, 40)).astype(np.int64) for _ in range(4)]
    for b in blocks:
        b[4] = rng.integers(0, 3, 40)
    n_scans = 160
    seen_ended = 0
    for scan in range(n_scans):
        stamp += float(rng.choice([0.1, 0.1, 0.35]))
        for tid in [i for i in pool if rng.random() < 0.08]:  # ends
            del pool[tid]
        for _ in range(int(rng.integers(0, 4))):  # births
            x, y = rng.integers(-20, 20, 2) / 4
            pool[next_id] = ["tentative", float(x), float(y), bool(rng.random() < 0.6), float(rng.uniform(0.2, 2.0))]
            next_id += 1
        tracks = []
        for tid, p in pool.items():
            if p[0] == "tentative" and rng.random() < 0.3:
                p[0] = "confirmed"
            elif p[0] != "tentative" and rng.random() < 0.1:
                p[0] = "coasting" if p[0] == "confirmed" else "confirmed"
            if rng.random() < 0.05:
                p[3] = not p[3]
            # positions on a 0.25 m grid, speeds and steps exactly at the limits too (reach = 1 m, stand = 0.25 m/s:
            # both tests' boundaries are hit exactly)
            if p[3]:  # standing: at most the speed limit, mostly within reach of where it stood
                v = float(rng.choice([0.0, 0.125, stand]))
                step = float(rng.choice([0.0, 0.25, reach, reach, reach + 0.25]))
            else:
                v, step = float(rng.choice([stand + 0.125, 1.0])), float(rng.choice([0.0, 0.5, 2.0]))
            if rng.random() < 0.5:
                p[1] += step * float(rng.choice([-1.0, 1.0]))
            else:
                p[2] += step * float(rng.choice([-1.0, 1.0]))
            tracks.append(_track(tid, p[0], stamp, p[1], p[2], v, p[4]))
        rng.shuffle(tracks)
        if tracks and rng.random() < 0.1:
            tracks.append(tracks[int(rng.integers(len(tracks)))])  # (an id listed twice)
        # the removal set: mostly the same movers as before, some ids of ended tracks too
        removing = {i for i in removing if rng.random() < 0.85} | {t.id for t in tracks if rng.random() < 0.06}
        _observe_ref(ref, tracks, set(removing), stamp)
        new.observe(tracks, set(removing), stamp)
        lazy.observe(tracks, set(removing), stamp)
        # (pass led26: ended ledgers are packed and dropped ones counted in batches; at most _END_BATCH wait)
        assert len(new._to_pack) + len(new._to_count) < er._END_BATCH
        assert _state(new, False) == _state(ref, False), scan
        assert not _ended_tracks(new), scan  # (the reference's ended ledgers hold theirs)
        if rng.random() < 0.2 or scan == n_scans - 1:
            new._finish_ended()
            assert _state(new) == _state(ref), scan
        if scan % 7 == 6:
            assert _state(lazy, False) == _state(ref, False), scan
        # after observe: ledgers started (before_update / erase_entering), stays in the removal set, rows recorded
        for t in tracks:
            r = rng.random()
            u = float(rng.random())
            for x in (ref, new, lazy):
                led = x._ledgers.get(t.id)
                if led is None and r < 0.25:
                    x._ledgers[t.id] = led = x._new_ledger(t, t.stamp, 3)
                if led is None:
                    continue
                if t.id in removing and led.m_start is None and u < 0.5:  # (as erase_entering starts a stay)
                    led.m_start, led.skip, led.linked = (t.box.px, t.box.py), u < 0.2, u < 0.3
                if u < 0.4:
                    k = int(4 * u / 0.4) % 4
                    led.ent.append((blocks[k], 3 * k, 3 * k + 5 + k, 7))
                    led.nb_rows += 5 + k
                    led.nb_chunks += 1
        assert _state(new, False) == _state(ref, False), scan
        if rng.random() < 0.05:  # a ledger started before the track is first reported
            early = _track(next_id, "confirmed", stamp, 0.0, 0.0, 0.0, 1.0)
            ref._ledgers[next_id] = ref._new_ledger(early, stamp, 3)
            new._ledgers[next_id] = new._new_ledger(early, stamp, 3)
            lazy._ledgers[next_id] = lazy._new_ledger(early, stamp, 3)
        seen_ended = max(seen_ended, len(new._ended))
    assert new.stats["cells_recorded"] > 0 and seen_ended > 0  # (dropped ledgers counted, ended ones kept)
    assert _ended_tracks(ref)  # (the reference's ended ledgers do hold tracks: the test above can fail)
    lazy._finish_ended()
    assert _state(lazy) == _state(ref)


def test_an_ended_ledger_lets_its_track_and_the_scans_arrays_go() -> None:
    """Pass ldg47 (issue 13 item 3): a ledger whose track ended keeps its last box and stamp but not the track's
    last report, which held that scan's report arrays (velocity and covariance rows, the beams' batch) for
    ``ledger_keep_s``; nothing else refers to it, so the report and its arrays are freed when the track ends."""
    import gc
    import weakref

    led = EvidenceLedger(MemoryConfig(ledger_keep_s=600.0), 0.1, 30.0)
    t = _track(7, "confirmed", 0.0, 1.0, 0.5, 0.0, 0.4)
    cov = np.eye(4)[None].repeat(3, axis=0)  # (a scan's reports' covariances; a report's is its row: a view)
    t = Track(**{**{f: getattr(t, f) for f in Track.__dataclass_fields__}, "covariance": cov[1]})
    led._ledgers[7] = led._new_ledger(t, 0.0, 3)
    led.observe([t], set(), 0.0)
    led._sync_sights()  # (pass glu121: written when read)
    assert led._ledgers[7].last_track is t
    gone = weakref.ref(cov)
    del t, cov
    led.observe([], set(), 0.1)  # (it ends, confirmed: kept for linking)
    gc.collect()
    l7 = led._ended[7]
    assert l7.last_box == (1.0, 0.5, 0.2) and l7.last_seen == 0.0
    assert l7.last_track is None and gone() is None


def test_a_stay_that_erase_entering_starts_ends_when_the_track_is_out_of_the_set_again() -> None:
    """``erase_entering`` starts a stay (``m_start``, ``skip``, ``linked``) that ``observe`` keeps while the track is
    in the removal set and ends at its first report out of it; the track's last report out of the set gives the
    ended ledger's last box and stamp."""
    from dynslam2d.slam import HectorSlam, SlamConfig

    slam = HectorSlam(SlamConfig())
    led = EvidenceLedger(MemoryConfig(), 0.1, 30.0)
    led.observe([_track(7, "confirmed", 0.0, 1.0, 0.5, 0.0, 0.4)], set(), 0.0)
    led.erase_entering([_track(7, "confirmed", 0.1, 1.0, 0.5, 0.0, 0.4)], {7}, 0.1, slam.map)
    l7 = led._ledgers[7]
    assert l7.m_start == (1.0, 0.5) and l7.skip and l7.linked  # (it did not stand long enough: its stay skips)
    led.observe([_track(7, "confirmed", 0.2, 1.5, 0.5, 1.0, 0.4)], {7}, 0.2)
    assert l7.m_start == (1.0, 0.5) and l7.skip and l7.linked
    led.observe([_track(7, "confirmed", 0.3, 2.0, 0.5, 1.0, 0.4)], set(), 0.3)
    assert l7.m_start is None and not l7.skip and not l7.linked
    led.observe([], set(), 0.4)  # (it ends: its last report out of the set gives its last box and stamp)
    assert led._ended[7] is l7 and l7.last_box == (2.0, 0.5, 0.2) and l7.last_seen == 0.3


def test_before_update_records_only_the_tracks_with_beams_in_their_order() -> None:
    """``before_update`` hands the kernel the tracks that list beams (pass ledger16 collects them with
    comprehensions): tracks without beams (None, empty) change nothing — the block, the small array and the kept
    beams equal those of the tracks with beams alone — a track listing one beam is recorded, and ledgers start
    only for tracks that keep a beam, with their kept beams."""
    from conftest import paper_room_scan

    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.types import Pose2D

    slam = HectorSlam(SlamConfig())
    pose = Pose2D(0.3, -0.4, 0.2)
    scan = paper_room_scan(pose)
    slam.update_map(scan, Pose2D(), force=True)
    removed = np.zeros(scan.ranges.shape[0], dtype=bool)
    removed[300:320] = True  # (track 5's beams: it keeps none)

    def tr(tid: int, beams) -> Track:
        t = _track(tid, "confirmed", 0.0, 1.0, 0.5, 0.0, 0.4)
        return Track(**{**{f: getattr(t, f) for f in Track.__dataclass_fields__}, "beams": beams,
                        "n_points": 0 if beams is None else len(beams)})

    with_beams = [tr(9, np.arange(100, 160)), tr(4, np.array([200])), tr(5, np.arange(300, 320)),
                  tr(2, np.arange(400, 430))]
    mixed = [tr(1, None), with_beams[0], tr(3, np.zeros(0, dtype=np.int64)), *with_beams[1:], tr(8, None)]
    got, want = (EvidenceLedger(MemoryConfig(), 0.1, 30.0, keep_beams=True) for _ in range(2))
    p_got = got.before_update(scan, pose, mixed, removed, slam.map, 3)
    p_want = want.before_update(scan, pose, with_beams, removed, slam.map, 3)
    assert p_got.fused[0].shape[1] > 50 and np.array_equal(p_got.fused[0], p_want.fused[0])
    assert np.array_equal(p_got.fused[1], p_want.fused[1])
    assert 4 in p_got.fused[0][0] and 5 not in p_got.fused[0][0]  # (the one-beam track's cell, none of track 5)
    assert list(got._ledgers) == [9, 4, 2]
    assert [(i, b.tolist()) for i, b in got._ledgers[4].beams] == [(3, [200])]
    assert got._ledgers[9].beams[0][1].tolist() == list(range(100, 160))
    got.before_update(scan, pose, mixed, removed, slam.map, 5)  # (a second update: the beams in update order)
    assert [(i, b.tolist()) for i, b in got._ledgers[4].beams] == [(3, [200]), (5, [200])]
    assert [i for i, _ in got._ledgers[2].beams] == [3, 5] and len(got._ledgers[2].kb) == 8  # (four items each)
    assert EvidenceLedger(MemoryConfig(), 0.1, 30.0).before_update(scan, pose, mixed[2:3], removed, slam.map) is None


def test_new_ledger_sets_every_field_as_the_dataclass_does() -> None:
    """``EvidenceLedger._new_ledger`` sets the slots of a new ``_Ledger`` directly (pass led28): every field equals
    that of the dataclass ``__init__`` with the same arguments — the first box from the standing boxes when the
    track has one, else where it is —, and each ledger gets lists of its own."""
    rng = np.random.default_rng(3)
    cfg = MemoryConfig(max_ledger_cells=int(rng.integers(10, 5000)))
    led = EvidenceLedger(cfg, 0.1, 30.0)
    made = []
    for tid in range(1, 40):
        t = _track(tid, "tentative", 0.1 * tid, *rng.uniform(-5, 5, 2).tolist(), float(rng.uniform(0, 2)),
                   float(rng.uniform(0.1, 3)))
        if tid % 3:
            led._set_first(tid, (float(tid), -1.0, 0.25 * tid), 0.05 * tid, 0.1 * tid)
        n_lv = int(rng.integers(1, 5))
        got = led._new_ledger(t, t.stamp, n_lv)
        box, t0, _ = led._first.get(tid) or (er._box_key(t), t.stamp, t.stamp)
        want = er._Ledger(tid, box, t0, er._box_key(t), t.stamp, None, n_lv, cfg.max_ledger_cells)
        for f in er._Ledger.__dataclass_fields__:
            assert getattr(got, f) == getattr(want, f) and type(getattr(got, f)) is type(getattr(want, f)), f
        made.append(got)
    assert len({id(x.ent) for x in made}) == len({id(x.kb) for x in made}) == len(made)


@pytest.mark.parametrize("scene", ["sim:stop-and-go", "sim:crowd"])
def test_observe_with_the_tracker_rows_keeps_the_boxes_of_the_reports(scene: str) -> None:
    """In the pipeline, ``observe`` reads the live reports' centres and velocities from the tracker's state rows
    (pass led32: ``ledgerkernels.stand_marks``): at every scan those rows hold each live report's box centre and
    velocity, and the standing boxes are those of a ledger that reads the reports themselves (the kernel's other
    input) and of one with pass ledger15's dict form — new boxes, stays, moves and the dormant reports included."""
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    p = Pipeline()
    led = p.ledger
    plain = EvidenceLedger(led.config, led.laser_min_dist, led.laser_max_dist)
    ref = _DictLedger(led.config, led.laser_min_dist, led.laser_max_dist)
    seen = {"rows": 0, "other": 0, "stays": 0}
    observe = led.observe

    def checked(tracks, removing, stamp, states=None):
        X, rows = states
        n = rows.shape[0]
        assert n <= len(tracks)
        want = [(t.box.px, t.box.py, *t.velocity.tolist()) for t in tracks[:n]]
        assert X[rows].tolist() == [list(w) for w in want]
        seen["rows"] += n
        seen["other"] += len(tracks) - n
        observe(tracks, removing, stamp, states)
        plain.observe(tracks, removing, stamp)
        _observe_ref(ref, tracks, set(removing), stamp)
        got = led._first
        assert got == plain._first == dict(sorted(ref._first.items()))
        seen["stays"] += sum(b[2] > b[1] for b in got.values())

    led.observe = checked
    for scan in open_source(scene, seed=5, duration=12.0):
        p.process(scan)
    assert seen["rows"] > 100 and seen["stays"] > 50, seen


class _GrowingLedger(EvidenceLedger):
    """The ledger with pass led32's layout of the standing boxes: one row per id ever seen, never laid out again."""

    compact_ids = False


def test_standing_boxes_stay_bounded_over_many_ids_and_keep_the_results(monkeypatch) -> None:
    """Pass led34: the standing boxes' arrays hold rows for the live ids only. Over 3000 scans and ≈ 12000 track
    ids (births and ends, two ids that live through the whole run and so get pinned below the window, ended ids
    that come back — a revived dormant track keeps its id —, an id listed twice, removal sets with ids of ended
    tracks, reports with and without the tracker's state rows) the arrays stay within ``2 · _PIN_COST`` rows per
    id of the live set (about a thousand, where the growing layout ends with one per id ever seen), and after
    every scan the standing boxes, and :meth:`EvidenceLedger._first_of` of live, ended, unseen and negative ids,
    equal those of the growing layout and of pass ledger15's dict form. (Ids below ``_ROWS_FLAT`` are rows
    themselves: 256 here, so that the run lays the rows out by the live ids again and again.)"""
    monkeypatch.setattr(er, "_ROWS_FLAT", 256)
    rng = np.random.default_rng(34)
    cfg = MemoryConfig(link_margin=0.5, stand_speed=0.25)
    new = EvidenceLedger(cfg, 0.1, 30.0)
    grow = _GrowingLedger(cfg, 0.1, 30.0)
    ref = _DictLedger(cfg, 0.1, 30.0)
    pool: dict[int, list] = {1: [0.0, 0.0], 2: [5.0, 5.0]}  # id → [x, y] (ids 1, 2 never end)
    ended: list[int] = []
    next_id = 3
    stamp = 0.0
    removing: set[int] = set()
    prev: set[int] = set()
    most = 0
    pinned = revived = 0
    for scan in range(3000):
        stamp += 0.1
        for tid in [i for i in pool if i > 2 and rng.random() < 0.12]:
            del pool[tid]
            ended.append(tid)
        for _ in range(int(rng.integers(2, 7))):
            pool[next_id] = [float(rng.integers(-8, 8)) / 4, float(rng.integers(-8, 8)) / 4]
            next_id += 1
        if ended and rng.random() < 0.02:  # an ended id back (a revived dormant track keeps its id)
            tid = ended.pop(int(rng.integers(len(ended))))
            pool[tid] = [0.5, 0.5]
            revived += tid < new._s + new._P
        tracks = []
        for tid, p in pool.items():
            if rng.random() < 0.3:
                p[int(rng.integers(2))] += float(rng.choice([0.25, 1.0, 1.5]))
            v = float(rng.choice([0.0, 0.125, 0.25, 1.0]))
            tracks.append(_track(tid, "confirmed", stamp, p[0], p[1], v, 0.5))
        rng.shuffle(tracks)
        if rng.random() < 0.1:
            tracks.append(tracks[0])  # (an id listed twice)
        removing = {i for i in removing if rng.random() < 0.8} | {t.id for t in tracks if rng.random() < 0.05}
        if ended and rng.random() < 0.1:
            removing.add(ended[-1])
        states = None
        if rng.random() < 0.5:  # (the tracker's rows for the first reports, as the pipeline hands them over)
            nr = int(rng.integers(len(tracks) + 1))
            X = np.array([(t.box.px, t.box.py, *t.velocity.tolist()) for t in tracks[:nr]] or np.zeros((0, 4)))
            X = np.ascontiguousarray(X[::-1])
            states = (X, np.arange(nr - 1, -1, -1, dtype=np.int64))
        new.observe(tracks, set(removing), stamp, states)
        grow.observe(tracks, set(removing), stamp, states)
        _observe_ref(ref, tracks, set(removing), stamp)
        got = new._first
        assert got == grow._first == dict(sorted(ref._first.items())), scan
        for tid in (*rng.integers(-3, next_id + 3, 6).tolist(), *ended[-3:]):
            assert new._first_of(tid) == grow._first_of(tid), (scan, tid)
        live = {t.id for t in tracks}
        # (at most _PIN_COST rows per id of the live set and the reports, twice that for room)
        assert new._F.shape[0] == new._mark.shape[0] <= max(er._ROWS_FLAT, 2 * er._PIN_COST * len(prev | live)
                                                            + er._ROWS_ROOM), scan
        prev = live
        most = max(most, new._F.shape[0])
        pinned = max(pinned, new._P)
    assert next_id > 11000 and grow._F.shape[0] >= next_id  # (the growing layout: a row per id ever seen)
    assert most <= 2048, most
    assert pinned >= 2 and revived > 0  # (the long-lived ids were pinned; an id came back below the window)
    with pytest.raises(ValueError):
        new.observe([_track(-4, "confirmed", stamp, 0.0, 0.0, 0.0, 0.5)], set(), stamp + 0.1)

