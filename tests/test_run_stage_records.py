"""run()'s per-scan records (pass front34): one timings row per scan, the tracks' rows written into their buffer,
BitRows.append's fast path — each against the form it replaced."""

from __future__ import annotations

import math

import numpy as np
import pytest

import dynslam2d.pipeline as pl
from dynslam2d.records import _TRACK_DTYPE, BitRows, GrowArray, TrackRows
from dynslam2d.sim import SimSource


def _old_timings(steps: list[dict[str, float]]) -> dict[str, np.ndarray]:
    """run()'s loop before front34: one GrowArray per stage, appended per scan."""
    timings: dict[str, GrowArray] = {}
    for t in steps:
        for k, v in t.items():
            arr = timings.get(k)
            if arr is None:
                arr = timings[k] = GrowArray(np.float64)
            arr.append(v)
    return {k: v.view().copy() for k, v in timings.items()}


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return list(a) == list(b) and all(a[k].dtype == b[k].dtype and a[k].tobytes() == b[k].tobytes() for k in a)


def test_stage_timings_rows_match_per_stage_arrays():
    st = pl._StageTimings()
    st.add({})
    st.add({"match": 1.0})  # (no stages on the first scan, then one)
    assert _same(st.arrays(), _old_timings([{}, {"match": 1.0}]))
    rng = np.random.default_rng(3)
    keys = ["match", "track", "filter", "map_update", "loops", "total"]
    steps = [dict(zip(keys, rng.exponential(size=6).tolist())) for _ in range(700)]  # (past the 256-row buffer)
    steps[5]["match"] = math.nan
    steps[6]["track"] = -0.0
    st = pl._StageTimings()
    assert st.arrays() == {}
    for t in steps:
        st.add(t)
    assert _same(st.arrays(), _old_timings(steps))
    # a scan with other stages (or another order): the old form's per-stage arrays, first-seen order
    odd = [{"match": 1.0, "extra": 2.0}, {"total": 3.0, "match": 4.0}, dict(zip(keys, [5.0] * 6)),
           dict(zip(reversed(keys), range(6)))]
    for cut in (0, 1, 300):
        seq = steps[:cut] + odd + steps[cut:cut + 20]
        st = pl._StageTimings()
        for t in seq:
            st.add(t)
        assert _same(st.arrays(), _old_timings(seq)), cut


def _old_append(rows: BitRows, row: object) -> None:
    """BitRows.append before front34."""
    r = np.asarray(row, dtype=bool).ravel()
    rows._start.append(len(rows._bits))
    rows._len.append(r.size)
    rows._bits.extend(np.packbits(r))
    rows.total_bits += r.size
    rows.total_set += int(np.count_nonzero(r))
    rows._widths.add(r.size)


def test_bitrows_append_fast_path_matches_old_form():
    rng = np.random.default_rng(7)
    inputs: list[object] = []
    for n in (720, 720, 1, 0, 13, 720, 5000):
        inputs.append(rng.random(n) < 0.3)
    inputs += [rng.random((4, 5)) < 0.5, [True, False, True], np.array([0, 2, 0, 1]), np.array([0.0, -0.0, 1.5]),
               (rng.random(40) < 0.5)[::2], np.ones(9, dtype=bool)]
    inputs += [rng.random(720) < 0.1 for _ in range(600)]  # (the packed bits' buffer grows)
    a, b = BitRows(), BitRows()
    for row in inputs:
        _old_append(a, row)
        b.append(row)
    assert type(b.total_set) is int and b.total_set == a.total_set and b.total_bits == a.total_bits
    assert b._widths == a._widths and b.uniform == a.uniform
    assert list(a._len) == list(b._len)
    kept = [i for i, row in enumerate(inputs) if np.asarray(row, dtype=bool).any()]  # (rows with a set bit keep bytes)
    assert [i for i, s in enumerate(b._start) if s >= 0] == kept and all(s == -1 for s in b._start if s < 0)
    assert b._bits.view().tobytes() == b"".join(a._bits.view()[a._start[i]:a._start[i] + (a._len[i] + 7) // 8]
                                                 .tobytes() for i in kept)
    assert len(a) == len(b) == len(inputs) and b.nbytes > 0
    for i in (0, 5, -1, -600, len(inputs) - 1):
        assert np.array_equal(b[i], np.asarray(inputs[i], dtype=bool).ravel()) and b[i].dtype == np.bool_
    assert all(np.array_equal(x, y) for x, y in zip(a, b)) and [len(r) for r in b[3:9]] == [len(r) for r in a[3:9]]
    u = BitRows()
    rows = [r for r in inputs if isinstance(r, np.ndarray) and r.shape == (720,)]
    rows[3:3] = [np.zeros(720, dtype=bool)] * 3  # (rows without a set bit between others)
    rows.append(np.zeros(720, dtype=bool))
    for r in rows:
        u.append(r)
    assert u.uniform and np.array_equal(u.stack(), np.array(rows)) and BitRows().stack().shape == (0, 0)
    z = BitRows()
    for _ in range(4):
        z.append(np.zeros(13, dtype=bool))
    assert np.array_equal(z.stack(), np.zeros((4, 13), dtype=bool)) and z.total_set == 0 and len(z._bits) == 0
    assert np.array_equal(z[-1], np.zeros(13, dtype=bool)) and z[-1].dtype == np.bool_


def test_extend_records_writes_the_rows_np_array_made():
    rng = np.random.default_rng(11)
    a, b = TrackRows(), TrackRows()
    for scan in range(400):  # (past the 1024-row buffer several times)
        k = int(rng.integers(0, 9))
        recs = [(0.05 * scan, int(rng.integers(1, 99)), int(rng.integers(0, 4)), *rng.normal(size=7).tolist(),
                 bool(rng.random() < 0.5), bool(rng.random() < 0.2)) for _ in range(k)]
        if scan == 3:
            recs.append((math.nan, 1, 0, math.inf, -0.0, 1e-300, 2.0, 3.0, np.float64(-0.25), 0.5, np.bool_(True),
                         False))
        if recs:
            a._rows.extend(np.array(recs, dtype=_TRACK_DTYPE))  # (extend_records before front34)
        b.extend_records(recs)
    assert len(a) == len(b) and a.array().tobytes() == b.array().tobytes()


@pytest.fixture(scope="module")
def sim_run() -> tuple[list, pl.RunResult]:
    src = SimSource("paper", duration=8.0)
    return list(src), pl.run(src)


def test_track_records_match_the_old_comprehension(sim_run):
    scans, _ = sim_run
    pipe = pl.Pipeline()
    a, b = TrackRows(), TrackRows()
    n_tracks = 0
    for scan in scans:
        step = pipe.process(scan)
        if not step.tracks:
            continue
        n_tracks += len(step.tracks)
        stamp, code, codes = step.stamp, a.code, a.state_codes
        a._rows.extend(np.array([
            (stamp, t.id, codes[t.state] if t.state in codes else code(t.state), bx.px, bx.py, bx.theta, bx.length,
             bx.width, float(vel[0]), float(vel[1]), bool(t.in_m), bool(t.remembered))
            for t in step.tracks for bx, vel in ((t.box, t.velocity),)], dtype=_TRACK_DTYPE))
        b.extend_records(pl._track_records(step.stamp, step.tracks, b))
    assert n_tracks > 50
    assert a.array().tobytes() == b.array().tobytes() and a.state_names() == b.state_names()


def test_run_records_every_stage_of_every_scan(sim_run):
    scans, res = sim_run
    assert list(res.timings_ms) == ["match", "track", "filter", "map_update", "loops", "total"]
    for v in res.timings_ms.values():
        assert v.dtype == np.float64 and v.shape == (len(scans),) and v.flags.c_contiguous and v.flags.owndata
    assert np.all(res.timings_ms["total"] >= res.timings_ms["match"])
    assert len(res.removed_rows) == len(scans) and len(res.track_rows) > 0
