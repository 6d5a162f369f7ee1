"""The free-space reference made in the segmentation's kernel call (docs/speed.md, pass trk60) is the one
``FreeSpaceMemory.make_ref`` makes, bit for bit, and every scan's reference keeps arrays of its own."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.detect.segment import segment_points
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D

_FIELDS = ("stamp", "angle_min", "increment", "full", "reach")


def _same_ref(got, want) -> None:
    assert got.ranges.dtype == want.ranges.dtype and got.ranges.tobytes() == want.ranges.tobytes()
    assert got.par.dtype == want.par.dtype and got.par.tobytes() == want.par.tobytes()
    for f in _FIELDS:
        g, w = getattr(got, f), getattr(want, f)
        assert type(g) is type(w) and g == w, f
    assert got.pose is want.pose


def test_segmentation_reference_is_make_ref_bit_for_bit() -> None:
    """segment_points' ``r``, ``par`` and ``ref_of`` give make_ref's reference for full and partial scans, masks with
    holes and no valid beam, and poses whose θ wraps (±π, beyond 2π, negative zero)."""
    cfg = DetectConfig()
    rng = np.random.default_rng(7)
    thetas = [0.0, -0.0, math.pi, -math.pi, 2.9, -3.1, 7.5, -12.25, math.nextafter(math.pi, 0.0),
              math.nextafter(-math.pi, 0.0), 1e-300]
    cases = 0
    for sim in (simulate("crowd", duration=0.5), simulate("crowd", duration=0.5, fov=math.radians(190.0))):
        for scan in sim.scans[:4]:
            for th in thetas:
                pose = Pose2D(float(rng.uniform(-20, 20)), float(rng.uniform(-20, 20)), th)
                for holes in (0, 5, -1):
                    valid = scan.valid_mask() & (scan.ranges > 0.0)
                    if holes > 0:
                        valid[::holes] = False
                    elif holes < 0:
                        valid[:] = False
                    out = segment_points(scan, cfg.segment, valid, float(pose.x), float(pose.y), pose.theta,
                                         ref=True)
                    _same_ref(FreeSpaceMemory.ref_of(scan, pose, out[6], out[7]),
                              FreeSpaceMemory.make_ref(scan, pose, valid))
                    cases += 1
        # without ``ref`` no arrays are made
        out = segment_points(scan, cfg.segment, valid, 0.0, 0.0, 0.0)
        assert out[6].shape == (0,) and out[7].shape == (0,)
    assert cases == 2 * 4 * len(thetas) * 3


def test_tracker_references_are_make_refs_of_their_scans() -> None:
    """Over a tracker run, the references the free-space memory holds (one per scan, up to ``max_age`` old) and the
    scan's own (``_cur_ref``) are make_ref's of their scans when checked after the run: a reference's arrays are its
    own (a buffer reused across scans would turn the older references into the newest). The scan's mask, which the
    tracker reads without a copy, is unchanged by it."""
    sim = simulate("crowd", duration=3.0)
    tr = Tracker(DetectConfig())
    made = {}
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    for scan, pose in zip(sim.scans, poses):
        mask = scan.valid_mask()
        tr.update(scan, pose)
        assert scan.valid_view().tobytes() == mask.tobytes()  # (the tracker reads the scan's own mask, never writes it)
        valid = scan.valid_mask() & (scan.ranges > 0.0)
        made[float(scan.stamp)] = (scan, pose, valid)
        if tr.last_detections:
            assert tr._cur_ref is tr._free._buf[-1]
    buf = list(tr._free._buf)
    assert len(buf) > 10 and len({id(b.ranges) for b in buf}) == len(buf)
    assert len({b.ranges.tobytes() for b in buf}) > 1
    for b in buf:
        _same_ref(b, FreeSpaceMemory.make_ref(*made[b.stamp]))
