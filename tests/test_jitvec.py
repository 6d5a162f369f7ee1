"""dynslam2d.jitvec: each lane operation gives the bits of numba's scalar operation on that lane (pass det39)."""

from __future__ import annotations

import numpy as np

from dynslam2d.jitbox import njit
from dynslam2d.jitvec import (
    vadd,
    vdiv,
    vget,
    vload,
    vmax,
    vmin,
    vmul,
    vneg,
    vset,
    vsplat,
    vstore,
    vsub,
    vwhere,
    vwhere_lt,
)


@njit
def _lanes(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Every operation of a, b (lanes of four, 4-aligned blocks) into rows of the result; c, d for the selects."""
    n = a.shape[0]
    out = np.empty((10, n))
    w = np.empty(4)
    for q in range(0, n, 4):
        va = vset(a[q], a[q + 1], a[q + 2], a[q + 3])
        vb = vload(b, q)
        vc = vload(c, q)
        vd = vload(d, q)
        res = (vadd(va, vb), vsub(va, vb), vmul(va, vb), vdiv(va, vb), vneg(va), vmin(va, vb), vmax(va, vb),
               vwhere_lt(va, vb, vc, vd), vwhere(vc, va, vb), vsplat(a[q + 2]))
        for r in range(10):
            vstore(w, 0, res[r])
            for j in range(4):
                out[r, q + j] = vget(res[r], j) if r % 2 else w[j]
    return out


@njit
def _scalars(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    n = a.shape[0]
    out = np.empty((10, n))
    for i in range(n):
        x = a[i]
        y = b[i]
        out[0, i] = x + y
        out[1, i] = x - y
        out[2, i] = x * y
        out[3, i] = x / y if y != 0.0 else np.divide(x, y)
        out[4, i] = -x
        out[5, i] = min(x, y)
        out[6, i] = max(x, y)
        out[7, i] = c[i] if x < y else d[i]
        out[8, i] = x if c[i] != 0.0 else y
        out[9, i] = a[i - i % 4 + 2]
    return out


def test_lane_operations_are_the_scalar_ones_bit_for_bit() -> None:
    """Random values and every pairing of the special ones (±0, ±inf, NaN, equal values): numba's min / max keep
    the first argument unless the second compares below / above it, which decides the sign of a zero result and
    whether a NaN passes; the lane forms must do the same."""
    special = [0.0, -0.0, np.inf, -np.inf, np.nan, 1.5, -1.5, 5e-324]
    pa, pb = np.meshgrid(special, special)
    rng = np.random.default_rng(3)
    a = np.concatenate([pa.ravel(), rng.normal(0, 10, 256)])
    b = np.concatenate([pb.ravel(), rng.normal(0, 10, 256)])
    c = np.concatenate([np.tile([0.0, 1.0, -0.0, 2.0], 16), rng.integers(0, 2, 256).astype(float)])
    d = rng.normal(0, 1, a.shape[0])
    with np.errstate(all="ignore"):
        got = _lanes(a, b, c, d)
        want = _scalars(a, b, c, d)
    for r in range(10):
        assert got[r].tobytes() == want[r].tobytes(), r
