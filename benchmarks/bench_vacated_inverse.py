"""The vacated walk turned inside out: the long-occupied cells tested against the beams (pass vac73; not library code).

:func:`dynslam2d.detect.mapevidence.seen_through_structure_kernel` walks every clearing ray cell by cell (≈ 46 000
first-pass map reads a scan on sim:paper) to find the few long-occupied cells (log-odds ≥ the tracker's
``map_occupied_logodds``) it passes. The map holds only ≈ 800–1 800 such cells. This form enumerates them from a
bitmap (one bit a cell, uint64 words along each row) and tests each against the few beams whose direction can pass
within ``core`` ≤ 0.5 cells of its centre, with the walk's own per-step arithmetic, so it finds the same cells:

* the walk records cell (a, ib) (a on the beam's major axis) at step a when ``ib = floor(b + 0.5)`` with
  ``b = n0 + slope · (a − m0)``, ``|b − ib| ≤ core``, a inside the beam's walked range and the cell within the reach:
  the test below is that, term for term (the first pass only bounds the second; ``_free_steps``' skip only leaves
  out steps with no long-occupied cell);
* the point (a, b) of the ray is then within 0.5 of the cell's centre, so the beam's direction is within
  asin(core / d) ≤ 1.003 core / d (d ≥ 4) of the cell's direction seen from the laser at distance d, found with an
  atan2 approximation good to 1.2e-5 rad (+ 8e-6 rad for the rounding of the beams' directions, ~1e-13 rad); for
  d < 4 every beam is tested. The beams' angles
  are ``angle_min + k · increment`` (a scan's beams are uniform).

The bitmap is rebuilt whole here when the map changed (its cost printed); in the library every map writer would
keep it (docs/speed.md, pass vac73). At every call of :func:`dynslam2d.vacated.vacated_scan_kernel` inside a
pipeline run this prints the walk and the inverse form's times (warm, best of 3, and first-called in alternating
order, before anything else reads the map), checks that both give the same cells with the same multiplicity (sorted
codes) on every call, and what a per-scan choice between the two would cost.

``PYTHONPATH=src taskset -c 0 python benchmarks/bench_vacated_inverse.py sim:paper negative_2/right --data DATA``
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_vacated_walk import _beam_axis, _beam_reach, _best, _geometry, _walk_stats  # noqa: E402

from dynslam2d.jitbox import njit  # noqa: E402


@njit(cache=False)
def _bitmap(logodds, occ_thr, bits):  # pragma: no cover
    """bits[r, c >> 6] bit c & 63 set where logodds[r, c] ≥ occ_thr (the walk's comparison)."""
    h, w = logodds.shape
    bits[:] = 0
    for r in range(h):
        for c in range(w):
            if logodds[r, c] >= occ_thr:
                bits[r, c >> 6] |= np.uint64(1) << np.uint64(c & 63)


#: de Bruijn sequence and table: the index of a word's lowest set bit from one multiplication
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_DB_TABLE = np.array([0, 1, 48, 2, 57, 49, 28, 3, 61, 58, 50, 42, 38, 29, 17, 4, 62, 55, 59, 36, 53, 51, 43, 22, 45, 39,
                      33, 30, 24, 18, 12, 5, 63, 47, 56, 27, 60, 41, 37, 16, 54, 35, 52, 21, 44, 32, 23, 11, 46, 26, 40,
                      15, 34, 20, 31, 10, 25, 14, 19, 9, 13, 8, 7, 6], dtype=np.int64)


@njit(cache=False, inline="always")
def _atan2_approx(y, x):  # pragma: no cover
    """atan2(y, x) within 1.2e-5 rad (a degree-9 odd polynomial on the octant, |z| ≤ 1; Abramowitz & Stegun
    4.4.49's form), in (−π, π]."""
    ax = abs(x)
    ay = abs(y)
    if ax >= ay:
        z = ay / ax if ax > 0.0 else 0.0
    else:
        z = ax / ay
    z2 = z * z
    t = z * (0.9998660 + z2 * (-0.3302995 + z2 * (0.1801410 + z2 * (-0.0851330 + z2 * 0.0208351))))
    if ax < ay:
        t = 0.5 * math.pi - t
    if x < 0.0:
        t = math.pi - t
    return -t if y < 0.0 else t


@njit(cache=False)
def _inverse(logodds, i0, j0, ox, oy, cx, cy, clear, core, occ_thr, depth, bits, ang0, inc, th, out_r,
             out_c, stage=2):  # pragma: no cover
    """The walk's seen-through cells (with repeats), found from the bitmap ``bits`` (module docstring)."""
    h, w = logodds.shape
    nb = cx.shape[0]
    # every beam's walk: axis, slope, walked major range [alo, ahi], reach²
    xm = np.zeros(nb, np.bool_)
    sl = np.empty(nb)
    alo = np.empty(nb, np.int64)
    ahi = np.empty(nb, np.int64)
    rr2 = np.full(nb, -1.0)  # (−1: no walk, so the distance test below fails for it)
    rmax = -1.0
    for k in range(1, nb - 1):
        reach = _beam_reach(k, ox, oy, cx, cy, clear, depth)
        if not reach > 0.0:
            continue
        x_major, slope, _, _, _, _, _, _, _, start, step, cnt = _beam_axis(k, ox, oy, cx, cy, i0, j0, h, w, reach)
        lo, hi = (start, start + cnt - 1) if step == 1 else (start - cnt + 1, start)
        if cnt <= 0:
            continue
        xm[k] = x_major
        sl[k] = slope
        alo[k] = lo
        ahi[k] = hi
        rr2[k] = reach * reach
        rmax = max(rmax, reach)
    n = 0
    if rmax < 0.0 or stage == 0:
        return 0
    cap = out_r.shape[0]
    # the rows / columns within the largest reach (+1) of the laser
    r_lo = max(int(math.floor(oy - rmax)) - 1 - j0, 0)
    r_hi = min(int(math.ceil(oy + rmax)) + 1 - j0, h - 1)
    c_lo = max(int(math.floor(ox - rmax)) - 1 - i0, 0)
    c_hi = min(int(math.ceil(ox + rmax)) + 1 - i0, w - 1)
    two_pi = 2.0 * math.pi
    inv_2pi = 1.0 / two_pi
    inv_inc = 1.0 / inc
    inv_abs = abs(inv_inc)
    turn = two_pi * inv_inc  # (beams a turn; floor / ceil with hw ≥ 1 beam absorb this product's rounding)
    for r in range(r_lo, r_hi + 1):
        for wd in range(c_lo >> 6, (c_hi >> 6) + 1):
            word = bits[r, wd]
            while word != 0:
                low = word & (~word + np.uint64(1))
                word ^= low
                c = (wd << 6) + _DB_TABLE[(low * _DEBRUIJN) >> np.uint64(58)]
                if c < c_lo or c > c_hi or logodds[r, c] < occ_thr:
                    continue
                if stage == 1:
                    n += 1
                    continue
                x = c + i0
                y = r + j0
                ddx = x - ox
                ddy = y - oy
                d2 = ddx * ddx + ddy * ddy
                d = math.sqrt(d2)
                if d > rmax + 1.0:
                    continue
                if d < 4.0:
                    k_lo, k_hi = 1, nb - 2
                    shifts = 0
                else:
                    # (asin(core / d) ≤ 1.003 core / d for d ≥ 4 and core ≤ 0.5; the approximation's 1.2e-5 rad and
                    # more than the beams' directions' rounding: 2e-5 rad)
                    phi = _atan2_approx(ddy, ddx) - th - ang0
                    phi -= two_pi * math.floor(phi * inv_2pi)  # [0, 2π)
                    hw = (1.003 * core / d + 2e-5) * inv_abs
                    kc = phi * inv_inc
                    shifts = 1
                for sh in range(-1 if shifts else 0, 2 if shifts else 1):
                    if shifts:
                        kk = kc + sh * turn
                        k_lo = max(int(math.floor(kk - hw)), 1)
                        k_hi = min(int(math.ceil(kk + hw)), nb - 2)
                    for k in range(k_lo, k_hi + 1):
                        # (the walk's last test first: (a − m0)² + (ib − n0)² is this sum in either axis order)
                        if not d2 <= rr2[k]:
                            continue
                        if xm[k]:
                            a, ibc, m0, n0 = x, y, ox, oy
                        else:
                            a, ibc, m0, n0 = y, x, oy, ox
                        if a < alo[k] or a > ahi[k]:
                            continue
                        b = n0 + sl[k] * (a - m0)
                        ib = int(math.floor(b + 0.5))
                        if ib != ibc or abs(b - ib) > core:
                            continue
                        if n < cap:
                            out_r[n] = r
                            out_c[n] = c
                            n += 1
    return n


#: Calls left out of the statistics (the first compiles the scratch kernels)
_SKIP = 5


def run(name: str, data: Path) -> None:
    import dynslam2d.pipeline as pl
    import dynslam2d.vacated as vac
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel as seen
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    kernel = vac.vacated_scan_kernel
    rows: list[tuple] = []
    st: dict = {"key": None, "builds": [], "scan": None}

    def _rebuild(logodds, params, key):
        bits = np.zeros((logodds.shape[0], (logodds.shape[1] + 63) >> 6), np.uint64)
        st["builds"].append(_best(lambda: _bitmap(logodds, params[5], bits), 1)[0])
        st.update(key=key, copy=logodds.copy(), bits=bits)

    def wrapped(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work, window):
        res = float(params[0])
        ox, oy = px / res, py / res
        geo = _geometry(ranges, cos_a, sin_a, valid, px, py, th, res, params[1], params[2], params[3])
        cx, cy, clear = geo
        key = (id(logodds), logodds.shape, i0, j0)
        if st["key"] != key:  # (a grown map: a bitmap of its shape before the first-called pair)
            _rebuild(logodds, params, key)
        sc = st["scan"]
        ang0, inc = float(sc.angle_min), float(sc.angle_increment)
        outs = [np.empty(64 * ranges.shape[0], np.int64) for _ in range(4)]

        def walk():
            return seen(logodds, i0, j0, ox, oy, cx, cy, clear, params[4], params[5], outs[0], outs[1], params[6])

        def inv():
            return _inverse(logodds, i0, j0, ox, oy, cx, cy, clear, params[4], params[5], params[6], st["bits"],
                            ang0, inc, th, outs[2], outs[3])

        # first-called: the one that runs first alternates from call to call
        order = (walk, inv) if len(rows) % 2 == 0 else (inv, walk)
        first = {}
        for f in order:
            t0 = time.perf_counter_ns()
            f()
            first[f] = (time.perf_counter_ns() - t0) / 1e3
        # (the change test reads the whole map: after the first-called pair, which may have read a stale bitmap of the
        # same shape — its time is the same; the warm pair and the check below read the current one)
        if not np.array_equal(st["copy"], logodds):
            _rebuild(logodds, params, key)
        r = kernel(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work, window)
        tw, n0 = _best(walk)
        ti, n1 = _best(inv)
        t_setup, _ = _best(lambda: _inverse(logodds, i0, j0, ox, oy, cx, cy, clear, params[4], params[5], params[6],
                                            st["bits"], ang0, inc, th, outs[2], outs[3], 0))
        t_enum, cells = _best(lambda: _inverse(logodds, i0, j0, ox, oy, cx, cy, clear, params[4], params[5],
                                               params[6], st["bits"], ang0, inc, th, outs[2], outs[3], 1))
        ti, n1 = _best(inv)
        w = logodds.shape[1]
        same = n0 == n1 and np.array_equal(np.sort(outs[0][:n0] * w + outs[1][:n0]),
                                           np.sort(outs[2][:n1] * w + outs[3][:n1]))
        _, fp = _walk_stats(ox, oy, cx, cy, clear, params[6])
        rows.append((first[walk], first[inv], tw, ti, n0, cells, same, len(rows) % 2 == 0, t_setup, t_enum, fp))
        return r

    vac.vacated_scan_kernel = wrapped
    try:
        pipe = pl.Pipeline()
        for s in scans:
            st["scan"] = s
            pipe.process(s)
    finally:
        vac.vacated_scan_kernel = kernel
    a = np.array(rows, dtype=float)
    print(f"{name}: {len(rows)} calls, the same cells (with repeats) on {int(a[:, 6].sum())}; statistics without the "
          f"first {_SKIP} calls (the inverse form's compile)")
    a = a[_SKIP:]
    for i, lab in zip((0, 1, 2, 3, 8, 9, 4, 5), ("walk first-called", "inverse first-called", "walk warm",
                                                  "inverse warm", "inverse: beams' set-up", "+ cells enumerated",
                                                  "seen-through hits", "long-occupied in reach")):
        print(f"  {lab:24s} median {np.median(a[:, i]):9.2f}  mean {a[:, i].mean():9.2f}")
    for lab, m in (("walk ran first", a[:, 7] == 1), ("inverse ran first", a[:, 7] == 0)):
        print(f"  {lab:24s} first-called medians: walk {np.median(a[m, 0]):.2f}, inverse {np.median(a[m, 1]):.2f}")
    print(f"  per-call ratio inverse / walk, medians: first-called {np.median(a[:, 1] / a[:, 0]):.3f}, "
          f"warm {np.median(a[:, 3] / a[:, 2]):.3f}")
    # a per-scan choice between both forms (both exact): the inverse where the walk's first pass has more than R
    # cells per long-occupied cell within the reach (both counts known before either form runs)
    wm = np.median(a[:, 0])
    for rr in (10, 20, 40, 80):
        pick = np.where(a[:, 10] > rr * a[:, 5], a[:, 1], a[:, 0])
        print(f"  choice at R = {rr:2d}: inverse on {np.mean(a[:, 10] > rr * a[:, 5]):5.1%} of calls, first-called "
              f"median {np.median(pick):.2f} (x{np.median(pick) / wm:.3f} of the walk), "
              f"mean x{pick.mean() / a[:, 0].mean():.3f}")
    b = st["builds"][1:]  # (the first compiles the scratch builder)
    spread = np.median(b) * (len(b) + 1) / len(rows)
    print(f"  bitmap rebuilt whole {len(b) + 1} times, median {np.median(b):.1f} µs, {spread:.1f} µs a scan"
          " at the median (the library would keep it by its writers instead; docs/speed.md pass vac73)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="+", help=", ".join(sorted(INPUTS)) + " or a built-in scene (sim:NAME)")
    ap.add_argument("--data", type=Path, default=Path("data"))
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data)


if __name__ == "__main__":
    main()
