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

Since pass vac77 the form is the library's (:func:`dynslam2d.vacated.seen_through_inverse`, forced on every call);
the set-up / enumeration stage timings of the scratch form print 0. The bitmap is rebuilt whole here when the map
changed (its cost printed); in the library every map writer would
keep it (docs/speed.md, pass vac73). At every call of :func:`dynslam2d.vacated.vacated_scan_kernel` inside a
pipeline run this prints the walk and the inverse form's times (warm, best of 3, and first-called in alternating
order, before anything else reads the map), checks that both give the same cells with the same multiplicity (sorted
codes) on every call, and what a per-scan choice between the two would cost.

``PYTHONPATH=src taskset -c 0 python benchmarks/bench_vacated_inverse.py sim:paper negative_2/right --data DATA``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_vacated_walk import _best, _geometry, _walk_stats  # noqa: E402

from dynslam2d.jitbox import njit  # noqa: E402
from dynslam2d.vacated import _CELLS_PER_BEAM, seen_through_inverse  # noqa: E402


@njit(cache=False)
def _bitmap(logodds, occ_thr, bits):  # pragma: no cover
    """bits[r, c >> 6] bit c & 63 set where logodds[r, c] ≥ occ_thr (the walk's comparison)."""
    h, w = logodds.shape
    bits[:] = 0
    for r in range(h):
        for c in range(w):
            if logodds[r, c] >= occ_thr:
                bits[r, c >> 6] |= np.uint64(1) << np.uint64(c & 63)


def _inverse(logodds, i0, j0, ox, oy, cx, cy, clear, core, occ_thr, depth, bits, ang0, inc, th, out_r,
             out_c, stage=2):
    """The walk's seen-through cells (with repeats), found from the bitmap ``bits``: the library's form
    (:func:`dynslam2d.vacated.seen_through_inverse`, pass vac77; forced, ratio 0). ``stage`` < 2 (the scratch form's
    set-up / enumeration stages, pass vac73) is not timed any more: 0 returned."""
    if stage < 2:
        return 0
    nb = cx.shape[0]
    iw = np.empty((2 * _CELLS_PER_BEAM + 3) * nb, np.int64)
    return seen_through_inverse(logodds, i0, j0, ox, oy, cx, cy, clear, core, occ_thr, depth, bits, ang0, inc, th,
                                out_r, out_c, iw, np.empty(2 * nb), 0.0)


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
