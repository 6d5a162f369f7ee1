"""The kernels whose array allocations were written in the call forms other kernels use (docs/speed.md, "Cold
compile pass 5"): the same dtypes and values as before, for the manifest's argument types."""

from __future__ import annotations

import numpy as np

from dynslam2d.detect.kernels import merge_leg_pairs
from dynslam2d.filter import _box_extents_kernel


def test_merge_leg_pairs_keeps_int8_kinds_and_int64_indices():
    """Two legs (detections 0 and 2, two points each) merged into one person after detection 1: kinds int8, starts,
    counts and beams int64, the person's points appended after the scan's."""
    px = np.array([0.0, 0.2, 5.0, 1.0, 1.2])
    py = np.array([0.0, 0.1, 5.0, 0.0, 0.1])
    beams = np.array([10, 11, 12, 13, 14], dtype=np.int64)
    starts = np.array([0, 2, 3], dtype=np.int64)
    npts = np.array([2, 1, 2], dtype=np.int64)
    kinds = np.array([3, 1, 3], dtype=np.int8)
    fits = np.zeros((3, 8))
    fits[:, 0] = [0.1, 5.0, 1.1]
    fits[:, 1] = [0.05, 5.0, 0.05]
    lohi = np.zeros((3, 4))
    rel = np.zeros((3, 2, 2), dtype=np.bool_)
    out = merge_leg_pairs(np.array([0], dtype=np.int64), np.array([2], dtype=np.int64), px, py, beams, starts, npts,
                          kinds, fits, lohi, rel)
    ki, kinds2, _, _, _, starts2, npts2, px2, _, mbeams = out
    assert ki.tolist() == [1]
    assert kinds2.dtype == np.int8 and kinds2[0] == 1
    assert starts2.dtype == npts2.dtype == mbeams.dtype == np.int64
    assert starts2.tolist() == [2, 5] and npts2.tolist() == [1, 4]
    assert mbeams.tolist() == [10, 11, 13, 14] and px2[5:].tolist() == [0.0, 0.2, 1.0, 1.2]


def test_box_extents_kernel_gives_float64_half_extents():
    """(k, 2) float64 half-extents |l| / 2, |w| / 2 for square = False, no margin, no cap."""
    boxes = np.array([[0.0, 0.0, 0.0, 4.0, -2.0], [1.0, 1.0, 0.5, 1.0, 3.0]])
    out = _box_extents_kernel(boxes, False, 0.0, np.inf)
    assert out.dtype == np.float64 and out.shape == (2, 2)
    assert out.tolist() == [[2.0, 1.0], [0.5, 1.5]]
