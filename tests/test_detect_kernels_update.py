"""The update step's kernels (detect/kernels_update.py) against the plain Python they replace: ``py_hypot`` against
``math.hypot`` bit for bit, ``accel_bound`` against ``Tracker._bound_acceleration``'s former per-row loop."""

from __future__ import annotations

import math
import struct

import numpy as np

from dynslam2d.detect.kernels import accel_candidates
from dynslam2d.detect.kernels_update import accel_bound, hypot_rows


def _bits(values) -> list[int]:
    """The IEEE bit patterns of floats (so −0.0 ≠ 0.0 and a NaN equals a NaN of the same bits)."""
    return [struct.unpack("<q", struct.pack("<d", v))[0] for v in values]


def test_py_hypot_is_math_hypot_bit_for_bit() -> None:
    """Random pairs over every scale (one coordinate up to 1e16 times the other, where the last bits of the
    correction decide), velocities like the tracker's, and the edge values: zeros of both signs, subnormals (the
    DBL_MIN scaling), the largest doubles, infinities and NaNs in every combination. A libm hypot, or the square
    root of the plain sum of squares, differs from math.hypot on this many pairs (checked below)."""
    rng = np.random.default_rng(7)
    n = 400_000
    xs, ys = [], []
    for scale in (1e-300, 1e-9, 1e-3, 1.0, 3.0, 1e3, 1e150, 1e300):
        a = rng.normal(size=n) * scale
        b = a * rng.choice([1e-16, 1e-8, 1e-3, 0.1, 1.0, 0.5, 7.0], n) * rng.normal(size=n)
        xs.append(a)
        ys.append(b)
    # velocity changes of the acceleration bound: m/s, near a few limits
    v = rng.uniform(-3.0, 3.0, (n, 2))
    xs.append(v[:, 0])
    ys.append(v[:, 1])
    edge = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-310, 1.7976931348623157e308,
            -1.7976931348623157e308, math.inf, -math.inf, math.nan, 1.0, -2.5, 3e-320]
    ea, eb = np.meshgrid(np.array(edge), np.array(edge))
    xs.append(ea.ravel())
    ys.append(eb.ravel())
    a = np.concatenate(xs)
    b = np.concatenate(ys)
    got = hypot_rows(a, b)
    want = list(map(math.hypot, a.tolist(), b.tolist()))
    assert _bits(got.tolist()) == _bits(want)
    # (the test can fail: the naive form differs from math.hypot on these pairs)
    with np.errstate(over="ignore", invalid="ignore"):
        naive = np.sqrt(a * a + b * b)
    assert sum(x != y for x, y in zip(naive.tolist(), want) if x == x and y == y) > 1000


def _bound_python(X_prior: np.ndarray, X_new: np.ndarray, hits: list[int], lim: float, after: int) -> int:
    """``Tracker._bound_acceleration``'s loop before the kernel (main at 0c1213a), on its own."""
    near = accel_candidates(X_prior, X_new, (0.999 * lim) ** 2)
    nb = 0
    for r, (pvx, pvy), (nvx, nvy) in zip(near.tolist(), X_prior.take(near, axis=0)[:, 2:].tolist(),
                                              X_new.take(near, axis=0)[:, 2:].tolist()):
        if hits[r] < after:
            continue
        dvx = nvx - pvx
        dvy = nvy - pvy
        d = math.hypot(dvx, dvy)
        if d > lim:
            X_new[r, 2] = pvx + dvx * lim / d
            X_new[r, 3] = pvy + dvy * lim / d
            nb += 1
    return nb


def test_accel_bound_is_the_former_per_row_loop() -> None:
    """Random updates (velocity changes spread around the limit, some exactly on it or on the candidate filter's
    0.999 of it, young tracks skipped): the bounded states' bytes and the count equal the Python loop's."""
    rng = np.random.default_rng(11)
    bounded = 0
    for _ in range(3000):
        n = int(rng.integers(1, 40))
        lim = float(rng.choice([0.05, 0.25, 0.4 * 0.1, 1.5]))
        Xp = rng.normal(size=(n, 4))
        ang = rng.uniform(-math.pi, math.pi, n)
        mag = lim * rng.choice([0.5, 0.999, 0.9995, 1.0, 1.0000001, 1.2, 5.0], n) * rng.uniform(0.999, 1.001, n)
        Xn = Xp + rng.normal(scale=0.05, size=(n, 4))
        Xn[:, 2] = Xp[:, 2] + mag * np.cos(ang)
        Xn[:, 3] = Xp[:, 3] + mag * np.sin(ang)
        exact = rng.random(n) < 0.1  # (a change of exactly lim along an axis)
        Xn[exact, 2] = Xp[exact, 2] + lim
        Xn[exact, 3] = Xp[exact, 3]
        hits = rng.integers(1, 6, n).tolist()
        after = int(rng.integers(1, 5))
        want = Xn.copy()
        nb_want = _bound_python(Xp, want, hits, lim, after)
        got = Xn.copy()
        near = accel_candidates(Xp, got, (0.999 * lim) ** 2)
        rows = [r for r in near.tolist() if hits[r] >= after]
        nb = accel_bound(Xp, got, np.array(rows, dtype=np.int64), lim) if rows else 0
        assert nb == nb_want
        assert got.tobytes() == want.tobytes()
        bounded += nb
    assert bounded > 5000


def test_manage_speed_rows_is_manage_rows_with_python_speeds() -> None:
    """``manage_speed_rows`` gives ``manage_rows``' outcomes and σ with the speeds Python's math.hypot gives (the
    values ``Tracker._manage`` handed to ``manage_rows`` before), bit for bit, on random rows in a shuffled order:
    non-finite covariances, speeds at rest and below 1e-9, velocities whose libm hypot differs from math.hypot."""
    from dynslam2d.detect.kernels import manage_rows
    from dynslam2d.detect.kernels_update import manage_speed_rows

    rng = np.random.default_rng(5)
    n = 6000
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) * rng.uniform(0.01, 2.0, size=(n, 1, 1))
    P[5::101, 1, 2] = np.nan
    P[7::103, 0, 0] = np.inf
    X = rng.normal(size=(n, 4)) * rng.choice([1e-12, 1e-3, 1.0, 30.0], size=(n, 1))
    X[::17, 2:] = 0.0
    rows = rng.permutation(n)
    speeds = list(map(math.hypot, X[rows, 2].tolist(), X[rows, 3].tolist()))
    assert any(s != float(h) for s, h in zip(speeds, np.hypot(X[rows, 2], X[rows, 3])))  # (libm's differs here)
    bad0, sig0 = manage_rows(P, X, rows, np.array(speeds), 1.5)
    bad, sig, speed = manage_speed_rows(P, X, rows, 1.5)
    assert _bits(speed.tolist()) == _bits(speeds)
    assert bad.tolist() == bad0.tolist() and sig.tobytes() == sig0.tobytes()
    assert 0 < bad.sum() < n
