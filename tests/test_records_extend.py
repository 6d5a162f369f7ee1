"""TrackRows.extend_records stores what TrackRows.append stores (the run loop's one write per scan)."""

from __future__ import annotations

import numpy as np

from dynslam2d.records import TrackRows


def test_extend_records_equals_appends():
    rng = np.random.default_rng(5)
    rows = [(100.0 + 0.1 * i, i % 7, ("tentative", "confirmed", "coasting", "odd")[i % 4],
             *rng.normal(size=7).tolist(), bool(i % 2)) for i in range(40)]
    rows.append((float("nan"), 3, "confirmed", float("inf"), -0.0, np.float64(1.5), 1e-300, 2.0,
                 np.float64(-0.25), 0.5, np.bool_(True)))
    remembered = [i % 3 == 0 for i in range(len(rows))]
    a, b = TrackRows(), TrackRows()
    for r, m in zip(rows, remembered):
        a.append(r, remembered=m)
    for lo, hi in ((0, 1), (1, 17), (17, 17), (17, len(rows))):  # scans with one, many and no tracks
        b.extend_records([(r[0], r[1], b.code(r[2]), *r[3:10], bool(r[10]), m)
                          for r, m in zip(rows[lo:hi], remembered[lo:hi])])
    assert a.array().tobytes() == b.array().tobytes()
    assert a.state_names() == b.state_names() and b.state_codes["odd"] == 4
    assert repr(list(a)) == repr(list(b)) and len(b) == len(rows)  # (NaN != NaN: compare the text)
