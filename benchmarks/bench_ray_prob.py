"""The ray kernel's probability (``raycast._prob_fast``) against the plain form on every float32 (not run by pytest).

Pass map30 replaced the ray kernel's probability memo by ``_prob_fast``: float32(1 / (1 + exp(−v))) of float64
log-odds ``v``, computed branch-free in a vectorised loop, or NaN where it cannot guarantee the bits of the plain
form ``np.float32(1.0 / (1.0 + math.exp(-v)))`` (its error bound in its docstring), which the kernel then
computes. This checks the bound's claim exhaustively where the map's values live: for every float32 ``x`` with
|x| ≤ ``--max`` (2.29e9 values for 700), on five float64 values — ``x`` itself (an occupied update at the cap), and
the four the walk forms from a stored float32 log-odds: ``x + l_free`` (a free update), ``x + l_occ`` (an occupied
one), ``(x − l_free) + l_occ`` (an occupied update undoing this scan's free one) and ``x − l_free`` (the same at
the cap), with the configuration's ``l_free`` / ``l_occ`` (default
``SlamConfig``, or ``--factors FREE OCC``). Every log-odds a map of these settings stores is such an ``x`` (the
cap keeps it below ``cap + l_occ``; the free side reaches −700 after ≈ 1 700 free updates of one cell), so every
probability the kernel writes is one of these values. Printed per family: values, how many the fast form answered,
how many of those differ from the plain form (must be 0), how many it left to the plain form, and how many would
differ without its interval test (rounding its own float64 value instead: what the test is for).

    PYTHONPATH=src taskset -c 0 python benchmarks/bench_ray_prob.py
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from dynslam2d.jitbox import njit
from dynslam2d.slam.raycast import _prob_fast


@njit(cache=True)
def _count(x32, add0, add1, counts):  # pragma: no cover - numba
    """For v = (float64(x) + add0) + add1 over the float32 array ``x32``: counts += [values, answered,
    answered and different from the plain form, asked]."""
    for i in range(x32.shape[0]):
        v = (np.float64(x32[i]) + add0) + add1
        plain = np.float32(1.0 / (1.0 + math.exp(-v)))
        fast = _prob_fast(v)
        counts[0] += 1
        if fast == fast:
            counts[1] += 1
            if fast != plain:
                counts[2] += 1
        else:
            counts[3] += 1
    return counts


@njit(cache=True)
def _count_raw(x32, add0, add1, q_fast):  # pragma: no cover - numba
    """Values of the family where q_fast's float32 rounding differs from the plain form (q_fast: the fast form's
    float64 sigmoid without the interval test, compiled by the caller)."""
    n = 0
    for i in range(x32.shape[0]):
        v = (np.float64(x32[i]) + add0) + add1
        if abs(v) <= 700.0:
            n += np.float32(q_fast(v)) != np.float32(1.0 / (1.0 + math.exp(-v)))
    return n


def _q_fast():
    """The fast form's float64 sigmoid before its interval test (``_prob_fast``'s source up to ``q``)."""
    import inspect

    import dynslam2d.slam.raycast as rc

    src = inspect.getsource(rc._prob_fast.py_func)
    head = src[src.index("def _prob_fast"):src.index("    a = np.float32(")]
    head = head.replace("def _prob_fast(v):", "def _q(v):")
    ns = dict(vars(rc))
    exec(head + "    return q\n", ns)  # noqa: S102 - the kernel's own source, cut short
    return njit(ns["_q"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--max", type=float, default=700.0, help="largest |x| checked (default 700: the fast range)")
    ap.add_argument("--factors", type=float, nargs=2, default=None, metavar=("FREE", "OCC"),
                    help="update factors (default: SlamConfig's)")
    ap.add_argument("--chunk", type=int, default=1 << 24)
    ap.add_argument("--raw", action="store_true", help="also count the differences without the interval test")
    a = ap.parse_args()
    from dynslam2d.slam.config import SlamConfig

    c = SlamConfig()
    if a.factors is not None:
        c = SlamConfig(update_factor_free=a.factors[0], update_factor_occupied=a.factors[1])
    l_free, l_occ = c.logodds_free, c.logodds_occupied
    top = int(np.array(a.max, np.float32).view(np.int32))  # (bits of the largest positive float32 ≤ max)
    if float(np.array(top, np.int32).view(np.float32)) > a.max:
        top -= 1
    families = {"x": (0.0, 0.0), "x + l_free": (l_free, 0.0), "x + l_occ": (l_occ, 0.0),
                "(x - l_free) + l_occ": (-l_free, l_occ), "x - l_free": (-l_free, 0.0)}
    q_fast = _q_fast() if a.raw else None
    print(f"every float32 x with |x| <= {a.max:g} ({2 * (top + 1):,} values, ±0 both), l_free {l_free!r}, "
          f"l_occ {l_occ!r}")
    for name, (add0, add1) in families.items():
        counts = np.zeros(4, np.int64)
        raw = 0
        t0 = time.perf_counter()
        for sign in (0, 1 << 31):
            for start in range(0, top + 1, a.chunk):
                bits = np.arange(start, min(start + a.chunk, top + 1), dtype=np.uint32) | np.uint32(sign)
                x = bits.view(np.float32)
                _count(x, add0, add1, counts)
                if q_fast is not None:
                    raw += _count_raw(x, add0, add1, q_fast)
        dt = time.perf_counter() - t0
        line = (f"  v = {name:<22} values {counts[0]:>13,}  answered {counts[1]:>13,}  differing {counts[2]}  "
                f"asked {counts[3]:>9,} ({counts[3] / counts[0]:.3%})")
        if q_fast is not None:
            line += f"  differing without the interval test {raw:,}"
        print(line + f"  ({dt:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
