"""The tracker's fast paths of pass trk13 (docs/speed.md): a birth's track record without the dataclass ``__init__``,
and a scan detection's points made when read."""

from __future__ import annotations

import dataclasses

import numpy as np

from dynslam2d.detect.measure import ScanDetection
from dynslam2d.detect.tracker import _NO_STATE, _new_track, _Track


def _args() -> dict:
    return dict(tid=7, t=1.25, birth_xy=np.array([1.0, 2.0]), g=(0.1, 1.0, 0.5, 0.0, 0.0, 0.0),
                gi=(0, True, True, False), beams=np.arange(3), free=[0.3], past=[(1.25, None)])


def test_new_track_sets_every_field_as_the_dataclass_does() -> None:
    """Every field of ``_new_track``'s record is the dataclass's for the same arguments (same value and type; the given
    objects themselves; fresh lists for the defaults): a field added to ``_Track`` without its line in ``_new_track``
    fails here (an unset slot raises, a different default differs)."""
    a = _args()
    fast = _new_track(**a)
    # (the counters: tentative, one hit, no miss, M of N 1 / 1, not flagged updated; the last hit at the birth's stamp;
    # rows of the tracker's counter table once _add_row gives the track its row, pass cnt36)
    ref = _Track(id=a["tid"], x=_NO_STATE, P=_NO_STATE, born=a["t"], birth_xy=a["birth_xy"], g=a["g"], gi=a["gi"],
                 ci=np.array([0, 1, 0, 1, 1, 0, 0, -1]), cl=(a["t"],), beams=a["beams"], free=a["free"], past=a["past"])
    assert type(fast) is _Track
    names = [f.name for f in dataclasses.fields(_Track)]
    assert len(names) == len(_Track.__slots__) and len(names) >= 29  # (person: a property, pass trk71)
    for name in names:
        got, want = getattr(fast, name), getattr(ref, name)
        assert type(got) is type(want), name
        if isinstance(want, np.ndarray):
            assert got is want or (got.dtype == want.dtype and np.array_equal(got, want)), name
        else:
            assert got == want, name
    # the lists given are the track's own (the riding and map-evidence windows are rows of the tracker's arrays since
    # pass trk26: no list default is left to share between tracks)
    assert fast.free is a["free"] and fast.past is a["past"] and fast.birth_xy is a["birth_xy"]


def _arrays(off: int = 0):
    """A scan's arrays (ScanArrays) of three detections, starts ``off`` + (0, 4, 6): 3 + 4 + 2 rows of 10 beams / points
    (the first three before them: another detection's)."""
    from dynslam2d.detect.measure import ScanArrays

    pts = np.arange(20.0).reshape(10, 2)
    fits, lohi, rel = np.arange(36.0).reshape(3, 12), np.zeros((3, 4)), np.zeros((3, 2, 2), dtype=bool)
    starts, npts = np.array([3, 7, 9]) + off, np.array([4, 2, 1])
    return ScanArrays(np.arange(10) * 2, pts, off, starts, npts, np.array([2, 0, 1], dtype=np.int8), fits, lohi, rel,
                      None)


def test_scan_detection_points_are_its_rows_of_the_scan_array() -> None:
    """A scan detection reads its own rows of the scan's points and beams (views of them), from its first row
    ``starts[j] − off`` (``off``: the merged pairs' arrays start after the scan's points), and copies to a plain
    Detection holding those points."""
    for off in (0, 57):
        s = _arrays(off)
        d = ScanDetection(s, 1, 0.25)
        assert d.points.tolist() == s.pts[7:9].tolist() and np.shares_memory(d.points, s.pts)
        assert d.beams.tolist() == [14, 16] and np.shares_memory(d.beams, s.beams)
        assert d.n_points == 2 and type(d.n_points) is int and d.kind == "point" and d.person is False
        assert d.free_fraction == 0.25 and d.theta == 12.0 and d.map_free == 0.0
        c = d.__reduce__()[1]
        assert c[1].tolist() == s.pts[7:9].tolist()  # (a copy is a Detection with these points)


def _refs_loop(mem, now: float) -> list:
    """FreeSpaceMemory._refs as first written: a Python loop keeping the first smallest deviation per age."""
    out: list = []
    ages = [now - b.stamp for b in mem._buf]
    for a in mem.ref_ages:
        j, best = 0, abs(ages[0] - a)
        for i in range(1, len(ages)):
            d = abs(ages[i] - a)
            if d < best:
                j, best = i, d
        if ages[j] > 0.0 and mem._buf[j] not in out:
            out.append(mem._buf[j])
    return out


def test_reference_choice_is_the_first_nearest_age_also_with_repeated_stamps() -> None:
    """The memory's reference scans (the first buffered scan nearest each reference age) are those of the plain loop
    on buffers with repeated stamps (ties: the earlier scan), gaps, and reads at, between and after the stamps."""
    import random

    from dynslam2d.detect.freespace import FreeSpaceMemory, _Ref

    rng = random.Random(13)
    ties = 0
    for _ in range(3000):
        mem = FreeSpaceMemory((0.3, 0.8, rng.choice([0.05, 0.5, 1.0])))
        x = rng.random()
        for _ in range(rng.randint(1, 30)):
            x += rng.choice([0.0, 0.0, 0.0667, 0.1, 0.25, 0.5])
            mem._buf.append(_Ref(x, None, None, 0.0, 0.0, False, 0.0, None))
            mem._stamps.append(x)  # (the memory's stamps list, kept with its buffer by add)
        now = x + rng.choice([0.0, 0.0667, 0.3, 0.55, 0.8, 2.0])
        got = [id(r) for r in mem._refs(now)]
        assert got == [id(r) for r in _refs_loop(mem, now)]
        stamps = [r.stamp for r in mem._buf]
        ties += len(set(stamps)) < len(stamps)
    assert ties > 1000  # repeated stamps were exercised


def test_scan_detections_are_the_constructors_detections() -> None:
    """``scan_detections`` gives, slot for slot, the detections that ``ScanDetection(...)`` makes one by one (the
    shared arrays themselves), with and without the map evidence; each reads the values of its row: the beams and
    points as views of the scan's, the kind, point count, axis angle and map evidence as Python values (0.0 without a
    map)."""
    from dynslam2d.detect.layout import F_THETA, KIND_NAMES
    from dynslam2d.detect.measure import ScanArrays, scan_detections

    rng = np.random.default_rng(3)
    npts = rng.integers(1, 9, size=12)
    starts = np.concatenate(([0], np.cumsum(npts)[:-1]))
    beams = np.arange(int(npts.sum())) * 3
    pts = rng.normal(size=(beams.shape[0], 2))
    kinds = rng.integers(0, len(KIND_NAMES), size=12).astype(np.int8)
    fits, lohi, rel = rng.normal(size=(12, 12)), rng.normal(size=(12, 4)), rng.random((12, 2, 2)) < 0.5
    test = object()  # (a scan's free-space test: shared by every detection)
    for mev in (rng.random((3, 12)), None):
        arrays = ScanArrays(beams, pts, 0, starts, npts, kinds, fits, lohi, rel, mev)
        got = scan_detections(arrays, test)
        assert len(got) == 12
        for j, d in enumerate(got):
            a0, n = int(starts[j]), int(npts[j])
            want = ScanDetection(arrays, j, test)
            assert type(d) is ScanDetection
            for name in ScanDetection.__slots__ + ("person",):
                g, w = getattr(d, name), getattr(want, name)
                assert g is w or g == w, name
            assert d._s is arrays and d.person is False and d._ff is test
            assert np.shares_memory(d.beams, beams) and d.beams.tolist() == beams[a0:a0 + n].tolist()
            assert np.shares_memory(d.points, pts) and d.points.tolist() == pts[a0:a0 + n].tolist()
            assert d.centroid.tolist() == fits[j, 10:12].tolist() and d.lo.tolist() == lohi[j, :2].tolist()
            assert d.kind == KIND_NAMES[int(kinds[j])] and d.n_points == n and type(d.n_points) is int
            ev = [d.map_structure, d.map_free, d.map_unknown]
            assert type(d.theta) is float and d.theta == fits[j, F_THETA]
            assert all(type(v) is float for v in ev)
            assert ev == (mev[:, j].tolist() if mev is not None else [0.0, 0.0, 0.0])


def test_merged_pairs_of_legs_read_their_rows_of_the_merged_arrays() -> None:
    """A merged pair of legs (Tracker._merge_legs) reads, from the merge's arrays, what it was given one by one before
    pass det32: the kind "point", axis angle 0, the legs' point counts summed, the first leg's beams and points then
    the second's, and the point-weighted map evidence (na·e_a + nb·e_b) / n of its legs bit for bit; the other
    detections keep theirs. On two people standing / walking on legs seen from a moving laser, the map evidence given
    as random fractions (the tracker has no map here)."""
    from test_detect_people import RATE, render, scene

    from dynslam2d.detect import DetectConfig, Tracker
    from dynslam2d.types import Pose2D

    rng = np.random.default_rng(5)
    seen = []

    class Check(Tracker):
        def _merge_legs(self, dets, *args):
            args, mev = args[:9], rng.random((3, len(dets)))  # (the arrays; the map evidence given instead of None)
            before = [(d.kind, d.theta, d.n_points, d.beams.tolist(), d.points.tolist()) for d in dets]
            out = super()._merge_legs(dets, *args, mev)
            new = out[0]
            kept = [d for d in new if not d.person]
            for d in kept:  # (the kept detections, unchanged)
                j = dets.index(d)
                assert (d.kind, d.theta, d.n_points, d.beams.tolist(), d.points.tolist()) == before[j]
            for d in new[len(kept):]:
                assert d.person and type(d) is ScanDetection
                da, db = d._ff
                a, b = dets.index(da), dets.index(db)
                na, nb = before[a][2], before[b][2]
                n = na + nb
                assert d.kind == "point" and d.theta == 0.0 and d.n_points == n
                assert d.beams.tolist() == before[a][3] + before[b][3]
                assert d.points.tolist() == before[a][4] + before[b][4]
                ev = [d.map_structure, d.map_free, d.map_unknown]
                ea, eb = mev[:, a].tolist(), mev[:, b].tolist()
                assert ev == [(na * x + nb * y) / n for x, y in zip(ea, eb)]
                seen.append(d)
            return out

    tr = Check(DetectConfig())
    for i in range(int(6.0 * RATE)):
        pose = Pose2D(0.2 * i / RATE, 0.0, 0.0)
        tr.update(render(pose, i / RATE, *scene(i / RATE, 2.0, 1.2), i)[0], pose)
    assert len(seen) > 20
