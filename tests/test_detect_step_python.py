"""Pass det81: the detection step's Python per scan — the free-space memory's reference, test and add as one call
(``FreeSpaceMemory.step``), the segmentation's geometry arguments kept per tracker and ``Tracker.last_segmentation``
made when read — give what the separate calls gave."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.detect.segment import segment_scan, segmentation_of
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D, Scan

_FIELDS = ("stamp", "angle_min", "increment", "full", "reach")


def _same_ref(got, want) -> None:
    assert got.ranges.tobytes() == want.ranges.tobytes() and got.par.tobytes() == want.par.tobytes()
    for f in _FIELDS:
        g, w = getattr(got, f), getattr(want, f)
        assert type(g) is type(w) and g == w, f
    assert got.pose is want.pose


def test_step_is_ref_of_test_at_and_add() -> None:
    """``step`` returns ``ref_of``'s reference and ``test_at``'s test made before the scan is added (or None), and
    leaves the buffer, its stamps and its count of stamps that go back as ``add`` does: stamps that repeat, go back
    and drop out of the memory, with and without a test asked for."""
    rng = np.random.default_rng(81)
    pose = Pose2D(1.0, -2.0, 0.5)
    for case in range(12):
        a = FreeSpaceMemory(ref_ages=((0.3, 0.8), (0.25, 0.5, 1.0))[case % 2], max_age=(0.6, 1.5, 3.0)[case % 3])
        b = FreeSpaceMemory(ref_ages=a.ref_ages, max_age=a.max_age)
        t = 10.0
        for i in range(120):
            t += float(rng.choice([0.0, 0.05, 0.1, 0.25, -0.3 if case % 4 == 1 else 0.1]))
            scan = Scan(stamp=t, angle_min=-1.0, angle_increment=0.1, ranges=rng.uniform(0.5, 5.0, 21),
                        range_min=0.1, range_max=10.0)
            valid = scan.valid_mask()
            made = FreeSpaceMemory.make_ref(scan, pose, valid)
            want_test = bool(i % 3)
            ref, test = a.step(scan, pose, made.ranges, made.par, want_test)
            ref_b = b.ref_of(scan, pose, made.ranges, made.par)
            test_b = b.test_at(float(scan.stamp)) if want_test else None
            b.add(scan, pose, valid, ref_b)
            _same_ref(ref, ref_b)
            assert (test is None) == (test_b is None)
            if test is not None:
                assert type(test) is type(test_b) and test.margin == test_b.margin
                assert len(test.refs) == len(test_b.refs) > 0
                for x, y in zip(test.refs, test_b.refs):
                    assert x.stamp == y.stamp and x.ranges is y.ranges
            assert a._stamps == b._stamps and a._descents == b._descents
            assert [x.stamp for x in a._buf] == a._stamps and a._buf[-1] is ref


def test_last_segmentation_of_two_geometries_in_turn() -> None:
    """One tracker fed scans of two beam geometries in turn (a full circle and a 190° field of view): the
    segmentation it keeps, read when asked for, is ``segment_scan``'s of each scan (the geometry arguments kept for
    one geometry are never used for the other), the same object on a second read; a segmentation assigned is kept."""
    full = simulate("crowd", duration=1.0).scans
    part = simulate("crowd", duration=1.0, fov=math.radians(190.0)).scans
    assert full[0].ranges.shape != part[0].ranges.shape or full[0].angle_min != part[0].angle_min
    cfg = DetectConfig()
    tr = Tracker(cfg)
    pose = Pose2D(0.0, 0.0, 0.0)
    checked = 0
    for i in range(min(len(full), len(part))):
        for scan in (full[i], part[i]) if i % 2 else (part[i], full[i]):
            tr.update(scan, pose)
            if (i + checked) % 3 == 0:
                continue  # (some scans' segmentations never read)
            got = tr.last_segmentation
            assert tr.last_segmentation is got
            want = segment_scan(scan, cfg.segment, scan.valid_mask() & (scan.ranges > 0.0))
            for f in ("labels", "beams", "offsets", "structure"):
                g, w = getattr(got, f), getattr(want, f)
                assert g.dtype == w.dtype and g.tobytes() == w.tobytes(), f
            assert got.wrapped == want.wrapped and got.n_dropped == want.n_dropped
            checked += 1
    assert checked > 10
    tr.last_segmentation = None
    assert tr.last_segmentation is None


def test_segmentation_of_gives_the_kernels_labels_and_structure_at_the_size_limit() -> None:
    """``segmentation_of`` (pass det109: ``detect_scan`` returns neither labels nor structure) makes, from a
    segmentation's beams and offsets, the labels and structure flags the segmentation kernel made, bit for bit, with
    ``max_points`` set to each cluster size of the scans in turn, so that clusters of exactly the limit (not
    structure) and of one point more (structure) both occur."""
    scans = simulate("crowd", duration=1.0).scans[::5]
    cfg = DetectConfig().segment
    at_limit = over = 0
    for scan in scans:
        valid = scan.valid_mask() & (scan.ranges > 0.0)
        sizes = np.diff(segment_scan(scan, cfg, valid).offsets)
        for limit in sorted(set(sizes.tolist()))[:6]:
            cfg.max_points = limit
            want = segment_scan(scan, cfg, valid)
            got = segmentation_of(want.beams, want.offsets, scan.ranges.shape[0], limit, want.wrapped, want.n_dropped)
            for f in ("labels", "beams", "offsets", "structure"):
                g, w = getattr(got, f), getattr(want, f)
                assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes(), f
            assert got.wrapped == want.wrapped and got.n_dropped == want.n_dropped
            at_limit += int(np.count_nonzero(np.diff(want.offsets) == limit))
            over += int(np.count_nonzero(want.structure))
    assert at_limit > 20 and over > 20
