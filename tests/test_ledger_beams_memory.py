"""The evidence ledger's kept beams (``_Ledger.kb`` / ``kbc``, slam/erasure.py; pass kb35, issue 13 item 3): a
ledger whose track lives through a long run holds its own beams, not every map update's whole kept-beam array
(pass led34's layout held one of those per update for as long as the track lived), and the beams read when the
track is erased — and so the loop closer's keyframes and the outputs — are those of pass led34's layout."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.slam import erasure as er
from dynslam2d.slam.erasure import EvidenceLedger
from dynslam2d.types import Box, Track


class _Led34(EvidenceLedger):
    """Pass led34's kept beams: references to every update's whole array, never copied."""

    kb_sweep = 0


def _track(tid: int, stamp: float, x: float, y: float, beams: np.ndarray) -> Track:
    return Track(id=tid, state="confirmed", stamp=stamp, box=Box(x, y, 0.3, 0.5, 0.4), velocity=np.zeros(2),
                 covariance=np.eye(4), age=1.0, hits=1, misses=0, kind="rect", in_m=False, m_reason="",
                 beams=beams, n_points=len(beams))


def _retained(led: er._Ledger) -> int:
    """Bytes of the arrays a ledger's kept beams hold alive (each distinct array once)."""
    kb = led.kb
    arrays = {id(kb[q + 1]): kb[q + 1] for q in range(0, len(kb), 4)}
    for m, cat in led.kbc or ():
        arrays[id(m)], arrays[id(cat)] = m, cat
    return sum(a.nbytes for a in arrays.values())


def test_a_track_living_through_a_long_run_holds_only_its_own_beams() -> None:
    """2000 map updates with kept beams: track 9 lives through all of them (its beams change a little every
    scan), eight other tracks are born and end around it, some scans keep none of track 9's beams (all removed),
    ledgers of ended confirmed tracks are packed. After every scan track 9's ledger holds at most its own beams
    (4 bytes each), 24 bytes per update and the whole arrays of the last ``2 · kb_sweep`` updates; pass led34's
    layout holds one whole array per update (about six times as much here) and fails that bound; no live ledger holds
    more than the last ``2 · kb_sweep`` updates' whole arrays. The (scan index,
    beams) of every ledger, live and ended, equal pass led34's after every scan, and erasing track 9 at the end
    hands the loop closer the same beams in the same order."""
    from conftest import paper_room_scan

    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.types import Pose2D

    rng = np.random.default_rng(35)
    slam = HectorSlam(SlamConfig())
    pose = Pose2D(0.3, -0.4, 0.2)
    scan = paper_room_scan(pose)
    slam.update_map(scan, Pose2D(), force=True)
    n_b = scan.ranges.shape[0]
    got, want = EvidenceLedger(MemoryConfig(), 0.1, 30.0, keep_beams=True), _Led34(MemoryConfig(), 0.1, 30.0,
                                                                                  keep_beams=True)
    others: dict[int, tuple[int, int]] = {}  # id → (first beam, last scan)
    next_id = 10
    own = entries = 0
    worst_old = 0
    compacted = False
    for i in range(2000):
        stamp = 0.1 * i
        while len(others) < 8:
            others[next_id] = (int(rng.integers(200, n_b - 60)), i + int(rng.integers(5, 300)))
            next_id += 1
        b9 = np.arange(100, 160 + int(rng.integers(-10, 10)))
        tracks = [_track(9, stamp, 1.0, 0.5, b9)]
        tracks += [_track(tid, stamp, 2.0, 1.0, np.arange(f, f + 40)) for tid, (f, _) in others.items()]
        removed = np.zeros(n_b, dtype=bool)
        if i % 97 == 5:
            removed[90:180] = True  # (track 9 keeps no beam at this update)
        for led in (got, want):
            led.observe(tracks, set(), stamp)
            led.before_update(scan, pose, tracks, removed, slam.map, i)
        l9, w9 = got._ledgers[9], want._ledgers[9]
        if not removed[100]:
            own += int(w9.kb[-1] - w9.kb[-2])
            entries += 1
        bound = 4 * own + 24 * entries + 2 * got.kb_sweep * max(a.nbytes for a in w9.kb[1::4]) + 2048
        assert _retained(l9) <= bound, (i, _retained(l9), bound)
        assert len(l9.kb) <= 4 * 2 * got.kb_sweep
        compacted |= l9.kbc is not None
        # (pass led36: the chunks' rows as int32, 12 bytes an entry)
        assert all(m.dtype == np.int32 and m.nbytes == 12 * m.shape[0] for m, _ in l9.kbc or ())
        worst_old = max(worst_old, _retained(w9) - bound)
        if i % 50 == 0 or i == 1999:
            # no live ledger holds an older update's whole array than two sweeps
            held = {id(led.kb[q]) for led in got._ledgers.values() for q in range(1, len(led.kb), 4)}
            assert len(held) <= 2 * got.kb_sweep + 1, (i, len(held))
            for tid, w in want._ledgers.items():
                g = got._ledgers[tid]
                assert [(s, b.tolist()) for s, b in g.beams] == [(s, b.tolist()) for s, b in w.beams], (i, tid)
            assert list(got._ended) == list(want._ended)
            for tid, w in want._ended.items():
                assert [(s, b.tolist()) for s, b in got._ended[tid].beams] == [(s, b.tolist()) for s, b in w.beams]
        others = {tid: v for tid, v in others.items() if v[1] > i}
    held_old = {id(led.kb[q]) for led in want._ledgers.values() for q in range(1, len(led.kb), 4)}
    assert len(held_old) > 1900  # (pass led34's layout: one array per update)
    assert compacted and worst_old > 0 and _retained(want._ledgers[9]) > 4 * _retained(got._ledgers[9])
    assert any(led.kbc is not None for led in got._ended.values())
    for led in (got, want):
        led._erase(led._ledgers[9], slam.map)
    assert len(got.erased_beams) == entries == len(want.erased_beams)
    assert all(s == t and a.dtype == b.dtype and np.array_equal(a, b)
               for (s, a), (t, b) in zip(got.erased_beams, want.erased_beams))
    assert got._ledgers[9].kb == [] and got._ledgers[9].kbc is None


@pytest.mark.parametrize("sweep", [1, 3])
def test_the_pipeline_erases_the_same_beams_with_the_sweep(monkeypatch, sweep: int) -> None:
    """sim:stop-and-go with the loop closer (the ledger keeps beams): with a sweep every ``sweep`` map updates (so
    that the copies run all the time) the loop closer is handed the same beams in the same order as with pass
    led34's layout, and every keyframe's removed beams, the front end's map and the erased cells are the same."""
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    def run(k: int) -> tuple:
        monkeypatch.setattr(EvidenceLedger, "kb_sweep", k)
        p = Pipeline()
        assert p.loops is not None and p.ledger.keep_beams
        handed: list = []
        drop = p.loops.drop_beams

        def record(items):
            handed.extend((s, np.array(b)) for s, b in items)
            return drop(items)

        p.loops.drop_beams = record
        for scan in open_source("sim:stop-and-go", seed=3, duration=40.0):
            p.process(scan)
        kfs = [(kf.scan_index, kf.removed.tolist()) for kf in p.loops.keyframes]
        lv = p.slam.map.levels[0]
        return handed, kfs, lv.logodds.copy(), sorted(p.ledger.erased_cells)

    h1, k1, m1, e1 = run(sweep)
    h0, k0, m0, e0 = run(0)
    assert h0 and len(h1) == len(h0)
    assert all(s == t and np.array_equal(a, b) for (s, a), (t, b) in zip(h1, h0))
    assert k1 == k0 and e1 == e0 and m1.tobytes() == m0.tobytes()
