"""The place descriptors' bearings read from the kept points' column views (pass neg46): the same images, bit for
bit, as the row-mask form they replaced (``pts[m, 1]``, ``pts[m, 0]``), on clouds with points out of range,
non-finite points and inputs in other layouts."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.placedesc import polar_descriptor, polar_descriptors


def _row_mask_form(points: np.ndarray, rings: int, sectors: int, max_range: float) -> np.ndarray:
    """polar_descriptor as it was before pass neg46 (the kept points' coordinates as ``pts[m, k]``)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros((rings, sectors), dtype=np.float32)
    if pts.shape[0] == 0:
        return out
    r = np.hypot(pts[:, 0], pts[:, 1])
    m = np.isfinite(r) & (r < max_range)
    if not m.any():
        return out
    ri = np.minimum((r[m] * (rings / max_range)).astype(np.int64), rings - 1)
    a = np.arctan2(pts[m, 1], pts[m, 0])
    si = np.floor((a + math.pi) * (sectors / (2.0 * math.pi))).astype(np.int64) % sectors
    out[ri, si] = 1.0
    return out


def _clouds(rng: np.random.Generator) -> list[np.ndarray]:
    """Point sets (m, laser frame) as the loop closer makes them and in other layouts: float64 and float32, a
    Fortran-ordered and a strided one, points beyond the range, on the axes, NaN and inf, an empty set."""
    out: list[np.ndarray] = []
    for k in range(30):
        n = int(rng.integers(1, 400))
        p = rng.normal(0.0, 6.0, (n, 2))
        p[rng.random(n) < 0.05] = np.nan
        p[rng.random(n) < 0.03, int(rng.integers(2))] = np.inf
        p[rng.random(n) < 0.05, int(rng.integers(2))] = 0.0  # on an axis: bearings at ±π/2, 0, π
        out.append(p.astype(np.float32) if k % 3 == 0 else p)
    wide = rng.normal(0.0, 4.0, (300, 4))
    out += [np.asfortranarray(rng.normal(0.0, 5.0, (200, 2))), wide[:, 1:3], np.zeros((0, 2))]
    return out


def test_descriptors_equal_the_row_mask_form_bit_for_bit() -> None:
    rng = np.random.default_rng(46)
    clouds = _clouds(rng)
    ref = [_row_mask_form(p, 20, 60, 15.0) for p in clouds]
    assert sum(int(d.sum()) for d in ref) > 1000  # (the images are not empty)
    for p, d in zip(clouds, ref):
        assert polar_descriptor(p, 20, 60, 15.0).tobytes() == d.tobytes()
    batch = polar_descriptors(clouds, 20, 60, 15.0)
    for i, d in enumerate(ref):
        assert batch[i].tobytes() == d.tobytes(), i
    # another grid, a range that cuts most points
    batch = polar_descriptors(clouds, 7, 33, 3.0)
    for i, p in enumerate(clouds):
        assert batch[i].tobytes() == _row_mask_form(p, 7, 33, 3.0).tobytes(), i
