"""Memory pass mem39 (issue 13 item 3): a level's log-odds grown into zeroed memory with only the old array's
non-zero cells copied (the untouched pages take no memory), with the values of before."""

from __future__ import annotations

import numpy as np

import dynslam2d.slam.grid as grid_module
from dynslam2d.slam.grid import GridLevel, encode_probs


def _filled_grow(level: GridLevel, b: tuple[int, int, int, int]) -> dict[str, np.ndarray]:
    """The arrays a growth to bounds ``b`` must give: each old array in its place, its fill value around it."""
    h, w = level.shape
    out = {}
    for name, fill, dtype in (("prob", 0, np.uint32), ("uidx", 0, np.int32), ("logodds", 0.0, np.float32)):
        new = np.full((b[3] - b[1], b[2] - b[0]), fill, dtype=dtype)
        r0, c0 = level.j0 - b[1], level.i0 - b[0]
        new[r0:r0 + h, c0:c0 + w] = getattr(level, name)
        out[name] = new
    return out


def test_grown_level_keeps_every_log_odds_bit_and_fills_zeros() -> None:
    rng = np.random.default_rng(5)
    lv = GridLevel(0.05, growth_margin_cells=7)
    lv.ensure(0, 0, 40, 30)
    h, w = lv.shape
    seen = rng.random((h, w)) < 0.3
    lv.logodds[seen] = rng.normal(0.0, 3.0, int(seen.sum())).astype(np.float32)
    lv.logodds[3, 4] = -0.0  # (a cell whose bits are not zero although it compares equal to 0.0)
    lv.uidx[seen] = rng.integers(0, 99, int(seen.sum()))
    lv.prob[seen] = encode_probs(rng.random(int(seen.sum())).astype(np.float32))
    for bounds in ((-30, -5, 45, 30), (0, 0, 400, 33), (-200, -300, 900, 700)):  # (the last one past _ZEROED_BYTES)
        b = lv._grown_bounds(*bounds)
        assert b is not None
        want = _filled_grow(lv, b)
        lv.ensure(*bounds)
        for name, arr in want.items():
            got = getattr(lv, name)
            assert got.dtype == arr.dtype and got.shape == arr.shape
            assert np.array_equal(got.view(np.uint8), arr.view(np.uint8)), name  # bit for bit
        assert np.signbit(lv.logodds).sum() == np.signbit(want["logodds"]).sum() > 0
    assert lv.logodds.nbytes >= grid_module._ZEROED_BYTES
