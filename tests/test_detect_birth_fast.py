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
    ref = _Track(id=a["tid"], x=_NO_STATE, P=_NO_STATE, born=a["t"], last_hit=a["t"], birth_xy=a["birth_xy"], g=a["g"],
                 gi=a["gi"], beams=a["beams"], free=a["free"], past=a["past"])
    assert type(fast) is _Track
    names = [f.name for f in dataclasses.fields(_Track)]
    assert len(names) == len(_Track.__slots__) and len(names) > 30
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


def test_scan_detection_points_are_its_rows_of_the_scan_array() -> None:
    """A scan detection given the scan's points and its first row reads its own rows (a view of them); given only its
    own points, that array itself; a point set assigned later replaces them."""
    pts = np.arange(20.0).reshape(10, 2)
    fits, lohi, rel = np.zeros((3, 12)), np.zeros((3, 4)), np.zeros((3, 2, 2), dtype=bool)
    d = ScanDetection(np.arange(4), pts, "rect", 4, 0.0, fits, lohi, rel, None, 1, 3)
    assert d.points.tolist() == pts[3:7].tolist() and np.shares_memory(d.points, pts)
    own = np.ones((2, 2))
    e = ScanDetection(np.arange(2), own, "rect", 2, 0.0, fits, lohi, rel, None, 0)
    assert e.points is own
    d.points = own
    assert d.points is own
    assert d.__reduce__()[1][1] is own  # (a copy is a Detection with these points)


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
        now = x + rng.choice([0.0, 0.0667, 0.3, 0.55, 0.8, 2.0])
        got = [id(r) for r in mem._refs(now)]
        assert got == [id(r) for r in _refs_loop(mem, now)]
        stamps = [r.stamp for r in mem._buf]
        ties += len(set(stamps)) < len(stamps)
    assert ties > 1000  # repeated stamps were exercised


def test_scan_detections_are_the_constructors_detections() -> None:
    """``scan_detections`` gives, slot for slot, the detections that ``ScanDetection(...)`` makes one by one (the
    shared arrays themselves, the beams as views of the scan's beams with the same values), with and without the map
    evidence; the axis angle and the map evidence are Python floats of the fit row and the evidence column (0.0
    without a map)."""
    from dynslam2d.detect.layout import F_THETA, KIND_NAMES
    from dynslam2d.detect.measure import scan_detections

    rng = np.random.default_rng(3)
    npts = rng.integers(1, 9, size=12)
    starts = np.concatenate(([0], np.cumsum(npts)[:-1]))
    beams = np.arange(int(npts.sum())) * 3
    pts = rng.normal(size=(beams.shape[0], 2))
    kinds = rng.integers(0, len(KIND_NAMES), size=12).astype(np.int8)
    fits, lohi, rel = rng.normal(size=(12, 12)), rng.normal(size=(12, 4)), rng.random((12, 2, 2)) < 0.5
    test = object()  # (a scan's free-space test: shared by every detection)
    for mev in (rng.random((3, 12)), None):
        got = scan_detections(beams, pts, starts.tolist(), npts.tolist(), kinds.tolist(), test, fits, lohi, rel, mev)
        assert len(got) == 12
        for j, d in enumerate(got):
            a0, n = int(starts[j]), int(npts[j])
            want = ScanDetection(beams[a0:a0 + n], pts, KIND_NAMES[int(kinds[j])], n, test, fits, lohi, rel, mev, j,
                                 a0)
            assert type(d) is ScanDetection
            for name in ScanDetection.__slots__ + ("kind", "theta", "n_points", "map_structure", "map_free",
                                                   "map_unknown", "person"):
                g, w = getattr(d, name), getattr(want, name)
                assert g is w or g == w, name
            assert np.shares_memory(d.beams, beams) and d.beams.tolist() == want.beams.tolist()
            assert d.points.tolist() == want.points.tolist() and d.centroid.tolist() == want.centroid.tolist()
            ev = [d.map_structure, d.map_free, d.map_unknown]
            assert type(d.theta) is float and d.theta == fits[j, F_THETA]
            assert all(type(v) is float for v in ev)
            assert ev == (mev[:, j].tolist() if mev is not None else [0.0, 0.0, 0.0])
