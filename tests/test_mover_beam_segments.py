"""Pass rep149: the movers' beams handed to the filter as places in the scan's detection arrays.

A track updated by a detection holds that detection's beams: the update's kernel writes the detection's first point
and point count into the track's counter row (``C_BS``, ``C_BN``), ``report_rows`` reads them out with the counters,
and ``TrackReports.mover_pack`` hands the filter's kernel those places in the detection arrays (the scan's clusters'
beams, then the merged persons') instead of a concatenation. A birth's, a revival's or a fragment host's beams are no
single segment: ``C_BN`` −1 there, and the movers' beams are concatenated as before.

Checked scan by scan: each mover's beams read from its places (as ``filter._grow_boxes`` reads them) are its track's
``beams`` — on a person made of two merged legs (places after the split point), on sim:crowd and sim:stop-and-go (many
movers, fragments) — and the pipeline removes the same beams as with the concatenation on every scan."""

from __future__ import annotations

import numpy as np
import pytest
from test_detect_people import RATE, render, scene

import dynslam2d.pipeline as pl
from dynslam2d.detect.kernels_update import C_BN, C_BS
from dynslam2d.detect.trackreport import TrackReports
from dynslam2d.inputs import open_source
from dynslam2d.types import Pose2D


def _places(packed: np.ndarray, beams: np.ndarray, more: np.ndarray) -> list[list[int]]:
    """Each mover's beams, place ``q`` read as ``filter._grow_boxes`` reads it."""
    k = (packed.shape[0] - 1) // 4
    n0 = int(packed[4 * k])
    return [[int(beams[q]) if q < n0 else int(more[q - n0]) for q in range(s, s + c)]
            for s, c in zip(packed[2 * k:3 * k].tolist(), packed[3 * k:4 * k].tolist())]


def _checked_pipeline(monkeypatch) -> tuple[pl.Pipeline, dict]:
    """A pipeline whose every ``mover_pack`` is checked against the movers' tracks and against the concatenation
    (``_mover_pack_copy``), and whose filter kernel's results are compared with those of the concatenation's pack."""
    seen = {"fast": 0, "copy": 0, "after_split": 0, "movers": 0}
    orig_pack, orig_copy, orig_ex = TrackReports.mover_pack, TrackReports._mover_pack_copy, pl.mover_exclusions
    p = pl.Pipeline()
    last: list = []

    def copy(self, idx, mids):
        seen["copy"] += 1
        return orig_copy(self, idx, mids)

    def pack(self, idx):
        out = orig_pack(self, idx)
        packed, beams, more, mids = out
        k = len(idx)
        live = {t.id: t for t in p.tracker._tracks}
        want = [live[tid].beams.tolist() if tid in self._updated else [] for tid in mids]
        assert _places(packed, beams, more) == want
        ref = orig_copy(self, idx, list(mids))
        assert _places(*ref[:3]) == want and ref[0][:2 * k].tolist() == packed[:2 * k].tolist()
        n0 = int(packed[4 * k])
        seen["after_split"] += sum(c > 0 and s >= n0 for s, c in zip(packed[2 * k:3 * k].tolist(),
                                                                      packed[3 * k:4 * k].tolist()))
        seen["fast"] += ref[0].tobytes() != packed.tobytes()
        seen["movers"] += k
        last[:] = [ref]
        return out

    def exclusions(config, scan, pose, boxes, states, packed, beams, more):
        got = orig_ex(config, scan, pose, boxes, states, packed, beams, more)
        want = orig_ex(config, scan, pose, boxes, states, *last[0][:3])
        for a, b in zip(got, want):
            assert type(a) is type(b) and (a.tobytes() == b.tobytes() if isinstance(a, np.ndarray) else a == b)
        return got

    monkeypatch.setattr(TrackReports, "mover_pack", pack)
    monkeypatch.setattr(TrackReports, "_mover_pack_copy", copy)
    monkeypatch.setattr(pl, "mover_exclusions", exclusions)
    return p, seen


def test_a_walking_person_of_two_merged_legs_is_excluded_by_its_places(monkeypatch) -> None:
    """Two people's legs (tests/test_detect_people.py's scene): the walker, a merged pair of legs in M, has its beams
    after the split point (the persons' arrays)."""
    p, seen = _checked_pipeline(monkeypatch)
    for i in range(int(7.0 * RATE)):
        t = i / RATE
        circles, ids = scene(t, 3.0, 1.2)
        p.process(render(Pose2D(0.0, 0.0, 0.0), t, circles, ids, i)[0])
    assert p.tracker.stats.merged_leg_pairs > 20 and seen["after_split"] > 5 and seen["fast"] > 5, seen


@pytest.mark.parametrize(("scene_name", "seed"), [("sim:crowd", 3), ("sim:stop-and-go", 2)])
def test_crowd_and_stop_and_go_movers_from_their_places(scene_name: str, seed: int, monkeypatch) -> None:
    """Many movers, fragments joined to their hosts (C_BN −1: the concatenation), every scan checked."""
    p, seen = _checked_pipeline(monkeypatch)
    for scan in open_source(scene_name, seed=seed, duration=12.0):
        p.process(scan)
    assert seen["fast"] > 40 and seen["movers"] > 100, (scene_name, seen)


def test_every_updated_track_row_holds_its_beams_or_minus_one() -> None:
    """After each scan, every live track updated in it: its row's ``C_BS``, ``C_BN`` are the places of its beams in the
    scan's detection arrays, or ``C_BN`` is −1 (a birth, a revival or a fragment's host: both occur)."""
    p = pl.Pipeline()
    seg = minus = 0
    frags = births = 0
    for scan in open_source("sim:crowd", seed=3, duration=12.0):
        f0, b0 = p.tracker.stats.merged_fragments, p.tracker.stats.tracks_born
        p.process(scan)
        trk = p.tracker
        frags += trk.stats.merged_fragments > f0
        births += trk.stats.tracks_born > b0
        dets = trk.last_detections
        if not dets:
            continue
        a, b = dets[0]._s, dets[-1]._s
        n0 = b.off if b.off else a.beams.shape[0]
        for k in trk._tracks:
            if k.id not in trk._updated:
                continue
            s, c = trk._CI[k.row, C_BS].item(), trk._CI[k.row, C_BN].item()
            if c < 0:
                assert c == -1
                minus += 1
                continue
            got = [int(a.beams[q]) if q < n0 else int(b.beams[q - n0]) for q in range(s, s + c)]
            assert got == k.beams.tolist()
            seg += 1
    assert seg > 500 and minus > 10 and frags > 0 and births > 0, (seg, minus, frags, births)
