"""dynslam2d.jitvec: each lane operation gives the bits of numba's scalar operation on that lane (pass det39)."""

from __future__ import annotations

import numpy as np

from dynslam2d.jitbox import njit
from dynslam2d.jitvec import (
    vabs,
    vadd,
    vall,
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


@njit
def _abs_all(a: np.ndarray, flags: np.ndarray) -> tuple:
    n = a.shape[0]
    ab = np.empty(n)
    for q in range(0, n, 4):
        v = vabs(vload(a, q))
        for j in range(4):
            ab[q + j] = vget(v, j)
    k = flags.shape[0] // 4
    every = np.empty(k, dtype=np.bool_)
    for r in range(k):
        every[r] = vall(vload(flags, 4 * r))
    return ab, every


@njit
def _abs_scalar(a: np.ndarray) -> np.ndarray:
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        out[i] = abs(a[i])
    return out


def test_lane_abs_and_all_lanes_set() -> None:
    """Pass det40: ``vabs`` gives numba's ``abs`` of each lane bit for bit (±0, ±inf, NaN, subnormals, random);
    ``vall`` is True exactly when no lane of a flag vector is 0.0 (all 16 patterns of 0.0 / 1.0, and −0.0 counts as
    0.0, a NaN lane as set, as ``vwhere`` reads them)."""
    rng = np.random.default_rng(40)
    a = np.concatenate([[0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324], rng.normal(0, 10, 248)])
    pats = [[(p >> j) & 1 for j in range(4)] for p in range(16)]
    flags = np.array(pats + [[1.0, -0.0, 1.0, 1.0], [1.0, np.nan, 1.0, 1.0], [2.0, -1.0, 0.5, 1e-300]],
                     dtype=float)
    ab, every = _abs_all(a, flags.ravel())
    assert ab.tobytes() == _abs_scalar(a).tobytes()
    assert every.tolist() == [bool(np.all((f != 0.0) | np.isnan(f))) for f in flags]
    assert every.tolist()[:16] == [p == 15 for p in range(16)]
