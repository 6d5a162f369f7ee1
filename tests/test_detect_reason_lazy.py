"""Pass trk136: a moving track's reason in M ("in M: speed S m/s, moved D m since birth") is stored as its three floats
(speed, displacement since birth) and formatted only when read (``_Track.reason``, the reports' ``m_reason``).

The texts read — at report time through the track, and one scan later through the reports built then — are those the
former code formatted in ``_manage`` / ``_dynamic`` at that scan: the speed from the state's velocity (Python's
``math.hypot``, as ``manage_scan`` gives it), the distance NumPy's ``np.hypot`` of the state's centre less its birth
centre, both with two decimals."""

from __future__ import annotations

import math

import numpy as np

import dynslam2d.pipeline as pl
from dynslam2d.detect.trackmanage import TrackManage
from dynslam2d.detect.trackreport import TrackReport, TrackReports
from dynslam2d.detect.tracktable import _Track, moved_reason
from dynslam2d.inputs import open_source


def _former_text(k: _Track) -> str:
    """The moving reason as the former code formatted it from the track's state in its scan."""
    x, b = k.x, k.birth_xy
    return (f"in M: speed {math.hypot(x.item(2), x.item(3)):.2f} m/s, moved "
            f"{float(np.hypot(x[0] - b[0], x[1] - b[1])):.2f} m since birth")


def test_moving_reasons_read_now_and_a_scan_later_are_the_former_texts(monkeypatch) -> None:
    pending: list[tuple[TrackReports, dict[int, str]]] = []
    orig, orig_manage = TrackReport._report, TrackManage._manage
    seen = {"stored": 0, "texts": 0, "later": 0}
    want: dict[int, str] = {}
    stored: dict[int, tuple] = {}  # (each track's stored floats and their text as of the scan that stored them)

    def spy_manage(self, t, updated):
        orig_manage(self, t, updated)
        want.clear()
        for k in self._tracks:
            r = k._reason
            if r.__class__ is str:
                assert k.reason is r
                stored.pop(k.id, None)
                continue
            assert len(r) == 3 and all(type(v) is float for v in r)
            if k.id in updated:  # (stored in this scan, from its state now)
                assert k.in_m
                text = _former_text(k)
                stored[k.id] = (r, text)
                seen["stored"] += 1
            else:  # (a track without detection keeps its last update's reason)
                assert stored[k.id][0] is r
                text = stored[k.id][1]
            assert k.reason == moved_reason(*r) == text
            want[k.id] = text

    def spy(self, t, updated):
        out = orig(self, t, updated)
        for k in self._tracks:  # (the texts stored in _manage, unchanged up to the report)
            if k.id in want:
                assert k.reason == want[k.id]
        pending.append((out, dict(want)))
        return out

    monkeypatch.setattr(TrackManage, "_manage", spy_manage)
    monkeypatch.setattr(TrackReport, "_report", spy)
    p = pl.Pipeline()
    for scan in open_source("sim:crowd", seed=5, duration=12.0):
        p.process(scan)
        # the previous scan's reports, built only now (its tracks have moved on since)
        for reps, want in pending[:-1]:
            for r in reps[:reps.n_live]:
                assert type(r.m_reason) is str
                if r.id in want:
                    assert r.m_reason == want[r.id]
                    seen["later"] += 1
                seen["texts"] += 1
        del pending[:-1]
    assert seen["stored"] > 50 and seen["later"] > 50 and seen["texts"] > 200, seen


def test_a_stored_text_is_read_as_it_is() -> None:
    k = object.__new__(_Track)
    k.reason = "not in M: tentative track"
    assert k._reason == k.reason == "not in M: tentative track"
    k._reason = (1.234, 3.0, -4.0)
    assert k.reason == "in M: speed 1.23 m/s, moved 5.00 m since birth"
