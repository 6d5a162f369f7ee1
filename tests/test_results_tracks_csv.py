"""tracks.csv written column-wise from TrackRows is the text the per-row csv.writer gave."""

from __future__ import annotations

import csv
import io
from types import SimpleNamespace

import numpy as np

from dynslam2d.pipeline import TRACK_CSV_COLUMNS
from dynslam2d.records import TrackRows
from dynslam2d.results import tracks_csv


def _per_row_csv(rows: TrackRows) -> str:
    """The former tracks_csv: one tuple and one csv.writer row per track row."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TRACK_CSV_COLUMNS)
    for row, rem in zip(rows, rows.remembered().tolist()):
        stamp, tid, state, x, y, th, ln, wd, vx, vy, in_m = row
        w.writerow([repr(stamp), tid, state, f"{x:.4f}", f"{y:.4f}", f"{th:.4f}", f"{ln:.3f}", f"{wd:.3f}",
                    f"{vx:.4f}", f"{vy:.4f}", int(in_m), int(rem)])
    return buf.getvalue()


def _rows(extra_state: str | None = None) -> TrackRows:
    rng = np.random.default_rng(3)
    tr = TrackRows()
    for i in range(500):
        state = ("tentative", "confirmed", "coasting")[i % 3]
        tr.append((1394219504.6599405 + i * 0.0371, int(rng.integers(1, 50)), state,
                   *(rng.normal(size=7) * 10.0 ** rng.integers(-6, 4)).tolist(), bool(i % 2)), remembered=i % 5 == 0)
    for v in (float("nan"), float("inf"), -float("inf"), -0.0, 1e-300, -0.00005, 0.00005, 2.5e-5):
        tr.append((v, 7, "deleted", v, v, v, v, v, v, v, True), remembered=True)
    if extra_state is not None:
        tr.append((1.0, 8, extra_state, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, False))
    return tr


def test_column_wise_text_is_the_per_row_text():
    rows = _rows()
    text = tracks_csv(SimpleNamespace(track_rows=rows))
    assert text == _per_row_csv(rows)
    assert text.count("\n") == len(rows) + 1 and "nan" in text and "-0.0000" in text


def test_a_state_name_that_needs_quoting_keeps_the_csv_writer():
    rows = _rows('odd, "quoted"')
    text = tracks_csv(SimpleNamespace(track_rows=rows))
    assert text == _per_row_csv(rows)
    assert '"odd, ""quoted"""' in text
