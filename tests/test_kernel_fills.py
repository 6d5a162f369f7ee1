"""The map-side kernels without numba's slice fills (pass cmp149): the same values, less code to compile."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from dynslam2d import vacated
from dynslam2d.slam import cleanup, correlative, ledgerkernels
from dynslam2d.slam.cleanup import _scan_geometry
from dynslam2d.types import Scan


def test_scan_geometry_of_invalid_beams_is_the_laser_cell() -> None:
    """Every output element is written by the loops: an invalid beam's ends are the laser's cell, not kept, not
    clearing (the former ``a[:] = 0`` fills), a valid one's end the map-frame point in cell units."""
    rng = np.random.default_rng(3)
    n = 181
    scan = Scan(stamp=0.0, angle_min=-math.pi / 2, angle_increment=math.pi / (n - 1),
                ranges=rng.uniform(0.5, 9.0, n), range_min=0.05, range_max=40.0)
    cos_a, sin_a = scan.trig()
    valid = rng.random(n) > 0.3
    removed = rng.random(n) > 0.8
    px, py, th, res = 1.25, -2.5, 0.4, 0.05
    ex, ey, cx, cy, kept, clear = _scan_geometry(scan.ranges, cos_a, sin_a, valid, removed, px, py, th, res, 0.1,
                                                 1.0, 0.2)
    ox, oy = px / res, py / res
    bad = ~valid
    for a, o in ((ex, ox), (ey, oy), (cx, ox), (cy, oy)):
        assert np.array_equal(a[bad], np.full(bad.sum(), o))
    assert not kept[bad].any() and not clear[bad].any()
    assert np.array_equal(kept[valid], ~removed[valid])
    lx = scan.ranges * cos_a
    ly = scan.ranges * sin_a
    wx = (px + math.cos(th) * lx - math.sin(th) * ly) / res
    assert np.allclose(ex[valid], wx[valid], rtol=0, atol=1e-9)
    assert clear[valid].sum() > 0.9 * valid.sum()  # (ranges ≥ 0.5 m, margins ≤ 0.25 m: nearly all clear)


@pytest.mark.parametrize("func", [
    cleanup._scan_geometry, cleanup._add_scan, ledgerkernels.beam_owners, ledgerkernels.scan_cells,
    ledgerkernels.unpack_cells, ledgerkernels.record_cells, ledgerkernels.level_rows, correlative.branch_and_bound,
    vacated.seen_through_inverse, vacated.vacated_scan_kernel,
], ids=lambda f: f.py_func.__name__)
def test_cold_start_kernels_have_no_slice_fills(func: object) -> None:
    """``a[:] = v`` on a fresh array lowers numba's slice assignment (≈ 300 LLVM instructions, twice an element
    loop's) and ``np.zeros`` compiles two helpers per dtype: neither in these kernels of a cold run."""
    code = [line.split("#")[0] for line in inspect.getsource(func.py_func).splitlines()]  # type: ignore[attr-defined]
    src = "\n".join(code)
    assert "[:] = " not in src
    assert "np.zeros(" not in src
