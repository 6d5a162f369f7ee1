"""Pass front25: the scan matcher's per-scan Python gives the values of the forms it replaced, bit for bit."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.matcher import Degeneracy, degeneracy


def _degeneracy_before(hessian_cells: np.ndarray, resolution: float, pts_m: np.ndarray, threshold: float,
                       sumsq: float | None = None) -> Degeneracy:
    """``degeneracy`` as pass front23 left it (builtin max / min, the Hessian indexed entry by entry)."""
    n = pts_m.shape[0]
    if sumsq is None:
        sumsq = float(np.einsum("ij,ij->", pts_m, pts_m))
    rho = math.sqrt(sumsq / n) if n else 1.0
    rho = max(rho, 1e-3)
    h = hessian_cells.tolist()
    k = 1.0 / resolution
    a = h[0][0] * k * k
    b = 0.5 * (h[0][1] + h[1][0]) * k * k
    d = h[1][1] * k * k
    u = 0.5 * (h[0][2] + h[2][0]) * k
    v = 0.5 * (h[1][2] + h[2][1]) * k
    r = h[2][2]
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(d) and math.isfinite(u) and math.isfinite(v)
            and math.isfinite(r)) or not a + d > 0.0:
        return Degeneracy(0.0, 0.0, 0.0, np.array([1.0, 0.0]), rho, 0.0, True, True)
    if r > 1e-12 * (a + d):
        a2, b2, d2 = a - u * u / r, b - u * v / r, d - v * v / r
    else:
        a2, b2, d2 = a, b, d
    half_tr = 0.5 * (a2 + d2)
    disc = math.sqrt(max(0.25 * (a2 - d2) ** 2 + b2 * b2, 0.0))
    lam_max, lam_min = half_tr + disc, half_tr - disc
    if not lam_max > 0.0:
        return Degeneracy(0.0, 0.0, 0.0, np.array([1.0, 0.0]), rho, 0.0, True, True)
    if abs(b2) > 1e-300:
        ax, ay = lam_min - d2, b2
    elif a2 <= d2:
        ax, ay = 1.0, 0.0
    else:
        ax, ay = 0.0, 1.0
    nrm = math.hypot(ax, ay)
    axis = np.array([ax / nrm, ay / nrm]) if nrm > 0.0 else np.array([1.0, 0.0])
    t_ratio = max(lam_min, 0.0) / lam_max
    det = a * d - b * b
    s_rot = r - (u * (d * u - b * v) + v * (a * v - b * u)) / det if det > 1e-300 * (a * d + 1e-300) else 0.0
    r_ratio = max(s_rot, 0.0) / (rho * rho * lam_max)
    return Degeneracy(min(t_ratio, r_ratio), t_ratio, r_ratio, axis, rho, lam_max,
                      t_ratio < threshold, r_ratio < threshold)


def _bits(v: object) -> object:
    """Floats (and float arrays) as their IEEE bits, so that NaN == NaN and -0.0 != 0.0 in the comparison."""
    if isinstance(v, np.ndarray):
        return v.astype(np.float64).tobytes()
    if isinstance(v, float):
        return np.float64(v).tobytes()
    return v


def _same(a: Degeneracy, b: Degeneracy) -> bool:
    names = ("ratio", "translation_ratio", "rotation_ratio", "axis", "scale", "lam_max", "translation_degenerate",
             "rotation_degenerate")
    return all(type(getattr(a, k)) is type(getattr(b, k)) and _bits(getattr(a, k)) == _bits(getattr(b, k))
               for k in names)


def _outcome(f, *args):
    try:
        return f(*args)
    except ArithmeticError as e:
        return e


def test_degeneracy_equals_the_form_before_bit_for_bit():
    """Random Hessians (positive definite, indefinite, rank-deficient: a corridor, no rotation), special entries (0,
    -0.0, NaN, ±inf, huge, tiny), empty and NaN point sums, with and without the gate's sum: every field equal
    bit for bit (-0.0 and NaN included) to pass front23's form (or the same exception: an overflowing square)."""
    rng = np.random.default_rng(25)
    specials = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e-320, -1e-320, 1e300, -1e300, 1e-12, 1.0, -1.0]
    cases = []
    for _ in range(3000):
        kind = rng.integers(0, 6)
        a = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6, 6)
        if kind == 0:
            h = a @ a.T
        elif kind == 1:
            h = a
        elif kind == 2:  # a corridor: one translation direction unseen
            v = rng.normal(size=(3, 1))
            v[0] = 0.0
            h = v @ v.T * 1e4
        elif kind == 3:  # no rotation
            h = a @ a.T
            h[2, :] = 0.0
            h[:, 2] = 0.0
        elif kind == 4:  # special entries
            h = a @ a.T
            for _ in range(rng.integers(1, 4)):
                h[rng.integers(0, 3), rng.integers(0, 3)] = specials[rng.integers(0, len(specials))]
        else:  # exactly symmetric with b = 0 (the axis' branches)
            h = np.diag(rng.uniform(-1.0, 10.0, 3) * 10.0 ** rng.uniform(-3, 3))
        n = int(rng.integers(0, 40))
        pts = rng.normal(size=(n, 2)) * rng.uniform(0.0, 30.0)
        cases.append((h, float(rng.choice([0.05, 0.025, 0.1])), pts, float(rng.uniform(0.0, 0.2))))
    # signed zeros where max / min pick between equal values: every diagonal of {0, -0, 1, 2.5} with zero or -0
    # off-diagonal entries (a Hessian of a scan that sees nothing along some direction)
    vals = (0.0, -0.0, 1.0, 2.5)
    for d0 in vals:
        for d1 in vals:
            for d2 in vals:
                for off in (0.0, -0.0):
                    h = np.full((3, 3), off)
                    h[0, 0], h[1, 1], h[2, 2] = d0, d1, d2
                    cases.append((h, 0.05, rng.normal(size=(5, 2)), 0.1))
    for h, res, pts, thr in cases:
        sq = float(np.einsum("ij,ij->", pts, pts))
        for s in (None, sq, math.nan, 0.0):
            got, want = _outcome(degeneracy, h, res, pts, thr, s), _outcome(_degeneracy_before, h, res, pts, thr, s)
            if isinstance(want, Degeneracy):
                assert isinstance(got, Degeneracy) and _same(got, want)
            else:  # (Python's float ** raises on overflow in both forms)
                assert type(got) is type(want)
