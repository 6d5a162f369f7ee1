"""Where the vacated-footprint kernel's time goes, and two exact cheaper forms of its ray walk (pass det31).

Runs the pipeline over each input and, at every call of :func:`dynslam2d.vacated.vacated_scan_kernel`, times in
situ: the call itself, the same call repeated (warm), a call with no beams (the fixed cost), the clearing geometry
alone (:func:`dynslam2d.slam.cleanup._scan_geometry`) and the seen-through walk alone
(:func:`dynslam2d.detect.mapevidence.seen_through_structure_kernel`); it counts the beams walked and the cells of
their branch-free first pass. Then two scratch forms of the walk, each checked for the same cells in the same order
on every scan (not library code):

* ``block``: the first pass skips runs of 8 steps whose 8 × 8 block of the map, dilated by one block, holds no
  cell with log-odds ≥ the long-occupied threshold (a run of 8 steps moves ≤ 7 cells along the major axis and
  ≤ 8 across it, so its cells lie in the start's block or a neighbour);
* ``dist``: the first pass jumps by the Chebyshev distance (capped at ``--cap`` cells) from its cell to the nearest
  long-occupied cell: t steps on move ≤ t cells along the major axis and ≤ t + 1 across (the rounding), so a cell at
  distance d leaves the next d − 2 steps without a hit.

Both read a mask the map's update would keep; here it is rebuilt whole when the map changed (its cost printed: the
incremental upkeep is the design's open part, docs/speed.md pass det31). Prints medians / means in µs per call.

``PYTHONPATH=src taskset -c 0 python benchmarks/bench_vacated_walk.py sim:paper negative_2/right --data DATA``
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

from dynslam2d.jitbox import njit  # noqa: E402
from dynslam2d.slam.cleanup import _scan_geometry  # noqa: E402


@njit(cache=False)
def _geometry(ranges, cos_a, sin_a, valid, px, py, th, res, margin, grazing, min_sin):  # pragma: no cover
    _, _, cx, cy, _, clear = _scan_geometry(ranges, cos_a, sin_a, valid, valid, px, py, th, res, margin, grazing,
                                            min_sin)
    return cx, cy, clear


@njit(cache=False, inline="always")
def _beam_reach(k, ox, oy, cx, cy, clear, depth):  # pragma: no cover
    """seen_through_structure_kernel's per-beam test: the reach (cells) of beam ``k`` short of the nearest clearing
    end of it and its two neighbours, or −1 where the three do not all clear (the same comparisons in its order)."""
    if not (clear[k] and clear[k - 1] and clear[k + 1]):
        return -1.0
    return math.sqrt(min(min((cx[k - 1] - ox) ** 2 + (cy[k - 1] - oy) ** 2,
                             (cx[k + 1] - ox) ** 2 + (cy[k + 1] - oy) ** 2),
                         (cx[k] - ox) ** 2 + (cy[k] - oy) ** 2)) - depth


@njit(cache=False)
def _walk_stats(ox, oy, cx, cy, clear, depth):  # pragma: no cover
    """Beams that pass the neighbour test and have a reach, and the cells of their first pass (before clipping)."""
    nb = 0
    cells = 0
    for k in range(1, cx.shape[0] - 1):
        reach = _beam_reach(k, ox, oy, cx, cy, clear, depth)
        if not reach > 0.0:
            continue
        nb += 1
        dx = cx[k] - ox
        dy = cy[k] - oy
        slope = (dy / dx if dx != 0.0 else 0.0) if abs(dx) >= abs(dy) else dx / dy
        cells += int((reach + 0.5) / math.sqrt(1.0 + slope * slope)) + 1
    return nb, cells


@njit(cache=False)
def _block_mask(logodds, occ_thr, out):  # pragma: no cover
    """out[R, C] = 1 where an 8 × 8 block within one block of (R, C) holds a cell ≥ occ_thr."""
    h, w = logodds.shape
    bh = out.shape[0]
    bw = out.shape[1]
    flag = np.zeros((bh + 2, bw + 2), np.uint8)
    for r in range(h):
        for c in range(w):
            if logodds[r, c] >= occ_thr:
                flag[(r >> 3) + 1, (c >> 3) + 1] = 1
    for r in range(bh):
        for c in range(bw):
            v = 0
            for dr in range(3):
                for dc in range(3):
                    v |= flag[r + dr, c + dc]
            out[r, c] = v


@njit(cache=False)
def _dist_field(logodds, occ_thr, cap, out):  # pragma: no cover
    """out = min(cap, Chebyshev distance in cells to the nearest cell ≥ occ_thr) (two-pass 8-neighbour chamfer)."""
    h, w = logodds.shape
    for r in range(h):
        for c in range(w):
            out[r, c] = 0 if logodds[r, c] >= occ_thr else cap
    for r in range(h):
        for c in range(w):
            v = out[r, c]
            if v:
                if c > 0:
                    v = min(v, out[r, c - 1] + 1)
                if r > 0:
                    v = min(v, out[r - 1, c] + 1)
                    if c > 0:
                        v = min(v, out[r - 1, c - 1] + 1)
                    if c + 1 < w:
                        v = min(v, out[r - 1, c + 1] + 1)
                out[r, c] = v
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            v = out[r, c]
            if v:
                if c + 1 < w:
                    v = min(v, out[r, c + 1] + 1)
                if r + 1 < h:
                    v = min(v, out[r + 1, c] + 1)
                    if c > 0:
                        v = min(v, out[r + 1, c - 1] + 1)
                    if c + 1 < w:
                        v = min(v, out[r + 1, c + 1] + 1)
                out[r, c] = v


@njit(cache=False, inline="always")
def _beam_axis(k, ox, oy, cx, cy, i0, j0, h, w, reach):  # pragma: no cover
    """seen_through_structure_kernel's walk of beam ``k`` with ``reach`` (cells), in its arithmetic: (x_major, slope,
    m0, n0, a_off, b_off, b_len, ar, br, start, step, cnt) — steps ``start + step · t`` for t < cnt along the major
    axis."""
    dx = cx[k] - ox
    dy = cy[k] - oy
    x_major = abs(dx) >= abs(dy)
    if x_major:
        a0 = int(math.floor(ox + 0.5))
        a1 = int(math.floor(cx[k] + 0.5))
        slope = dy / dx if dx != 0.0 else 0.0
        m0, n0 = ox, oy
        a_off, a_len, b_off, b_len, ar, br = i0, w, j0, h, 0, 1
    else:
        a0 = int(math.floor(oy + 0.5))
        a1 = int(math.floor(cy[k] + 0.5))
        slope = dx / dy
        m0, n0 = oy, ox
        a_off, a_len, b_off, b_len, ar, br = j0, h, i0, w, 1, 0
    along = (reach + 0.5) / math.sqrt(1.0 + slope * slope)
    if a1 >= a0:
        step = 1
        start = max(a0, a_off)
        cnt = min(min(a1, int(math.floor(m0 + along)) + 1), a_off + a_len - 1) - start + 1
    else:
        step = -1
        start = min(a0, a_off + a_len - 1)
        cnt = start - max(max(a1, int(math.ceil(m0 - along)) - 1), a_off) + 1
    return x_major, slope, m0, n0, a_off, b_off, b_len, ar, br, start, step, cnt


@njit(cache=False)
def _walk(logodds, i0, j0, ox, oy, cx, cy, clear, core, occ_thr, out_r, out_c, depth, mask, mode):  # pragma: no cover
    """seen_through_structure_kernel with its first pass skipping cells by ``mask``: mode 1 the dilated 8 × 8 block
    flags, mode 2 the capped Chebyshev distance field (module docstring). The second pass is the kernel's."""
    h = logodds.shape[0]
    w = logodds.shape[1]
    cap = out_r.shape[0]
    n = 0
    for k in range(1, cx.shape[0] - 1):
        reach = _beam_reach(k, ox, oy, cx, cy, clear, depth)
        if not reach > 0.0:
            continue
        reach2 = reach * reach
        x_major, slope, m0, n0, a_off, b_off, b_len, ar, br, start, step, cnt = _beam_axis(k, ox, oy, cx, cy, i0, j0, h,
                                                                                             w, reach)
        if cnt <= 0:
            continue
        first = cnt
        last = -1
        t = 0
        while t < cnt:
            a = start + step * t
            bi = int(math.floor(n0 + slope * (a - m0) + 0.5)) - b_off
            if mode == 1:
                bc = min(max(bi, 0), b_len - 1)
                row = (a - a_off) if not x_major else bc
                col = bc if not x_major else (a - a_off)
                t1 = min(t + 8, cnt)
                if mask[row >> 3, col >> 3]:
                    for u in range(t, t1):
                        a = start + step * u
                        bi = int(math.floor(n0 + slope * (a - m0) + 0.5)) - b_off
                        if bi < 0 or bi >= b_len:
                            continue
                        v = logodds[bi, a - a_off] if x_major else logodds[a - a_off, bi]
                        if v >= occ_thr:
                            first = min(first, u)
                            last = u
                t = t1
            else:
                if bi < 0 or bi >= b_len:
                    t += 1
                    continue
                d = mask[bi, a - a_off] if x_major else mask[a - a_off, bi]
                if d == 0:
                    first = min(first, t)
                    last = t
                    t += 1
                else:
                    t += max(1, d - 1)
        for t in range(first, last + 1):
            a = start + step * t
            b = n0 + slope * (a - m0)
            ib = int(math.floor(b + 0.5))
            bi = ib - b_off
            row = ar * (a - a_off) + br * bi
            col = (1 - ar) * (a - a_off) + (1 - br) * bi
            if bi < 0 or bi >= b_len or abs(b - ib) > core or logodds[row, col] < occ_thr:
                continue
            if n < cap and (a - m0) ** 2 + (ib - n0) ** 2 <= reach2:
                out_r[n] = row
                out_c[n] = col
                n += 1
    return n


def _best(fn, reps: int = 3) -> tuple[float, object]:
    best = math.inf
    out = None
    for _ in range(reps):
        t0 = time.perf_counter_ns()
        out = fn()
        best = min(best, time.perf_counter_ns() - t0)
    return best / 1e3, out


def run(name: str, data: Path, cap: int) -> None:
    import dynslam2d.pipeline as pl
    import dynslam2d.vacated as vac
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel as seen
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    kernel = vac.vacated_scan_kernel
    rows: list[tuple] = []
    masks: dict = {"key": None, "builds": [[], []]}

    def wrapped(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work, window):
        t0 = time.perf_counter_ns()
        r = kernel(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work, window)
        in_situ = (time.perf_counter_ns() - t0) / 1e3
        warm, _ = _best(lambda: kernel(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work,
                                       window))
        empty, _ = _best(lambda: kernel(ranges[:0], cos_a[:0], sin_a[:0], valid[:0], px, py, th, logodds, i0, j0,
                                        params, work, window), 1)
        res = float(params[0])
        geo, (cx, cy, clear) = _best(lambda: _geometry(ranges, cos_a, sin_a, valid, px, py, th, res, params[1],
                                                       params[2], params[3]))
        ox, oy = px / res, py / res
        outs = [np.empty(64 * ranges.shape[0], np.int64) for _ in range(6)]
        walk, n0 = _best(lambda: seen(logodds, i0, j0, ox, oy, cx, cy, clear, params[4], params[5], outs[0], outs[1],
                                      params[6]))
        key = (id(logodds), logodds.shape, i0, j0)
        if masks["key"] != key or not np.array_equal(masks["copy"], logodds):
            blk = np.empty(((logodds.shape[0] + 7) >> 3, (logodds.shape[1] + 7) >> 3), np.uint8)
            dist = np.empty(logodds.shape, np.int16)
            masks["builds"][0].append(_best(lambda: _block_mask(logodds, params[5], blk), 1)[0])
            masks["builds"][1].append(_best(lambda: _dist_field(logodds, params[5], cap, dist), 1)[0])
            masks.update(key=key, copy=logodds.copy(), blk=blk, dist=dist)
        same = []
        times = []
        for mode, mask, q in ((1, masks["blk"], 2), (2, masks["dist"], 4)):
            tm, n = _best(lambda mask=mask, mode=mode, q=q: _walk(logodds, i0, j0, ox, oy, cx, cy, clear, params[4],
                                                                  params[5], outs[q], outs[q + 1], params[6], mask,
                                                                  mode))
            times.append(tm)
            same.append(n == n0 and np.array_equal(outs[q][:n], outs[0][:n0])
                        and np.array_equal(outs[q + 1][:n], outs[1][:n0]))
        nb, cells = _walk_stats(ox, oy, cx, cy, clear, params[6])
        rows.append((in_situ, warm, empty, geo, walk, times[0], times[1], nb, cells, r[0], r[1], all(same)))
        return r

    vac.vacated_scan_kernel = wrapped
    try:
        warm_pipe = pl.Pipeline()
        for s in scans[:5]:
            warm_pipe.process(s)
        rows.clear()
        masks["builds"] = [[], []]
        pipe = pl.Pipeline()
        for s in scans:
            pipe.process(s)
    finally:
        vac.vacated_scan_kernel = kernel
    a = np.array(rows, dtype=float)
    labels = ("kernel in situ", "kernel warm (same call again)", "kernel with no beams", "clearing geometry",
              "seen-through walk", "walk, block form", f"walk, distance form (cap {cap})", "beams walked",
              "first-pass cells", "distinct seen-through cells", "yielding outlines")
    print(f"{name}: {len(rows)} calls, both forms identical on {int(a[:, 11].sum())}")
    for i, lab in enumerate(labels):
        print(f"  {lab:34s} median {np.median(a[:, i]):10.2f}  mean {a[:, i].mean():10.2f}")
    print(f"  ns per first-pass cell (walk / cells, median): {np.median(a[:, 4] * 1e3 / np.maximum(a[:, 8], 1)):.2f}")
    for lab, b in zip(("block mask", "distance field"), masks["builds"]):
        print(f"  {lab} rebuilt whole {len(b)} times (map changed), median {np.median(b):.1f} µs, "
              f"{sum(b) / len(rows):.1f} µs per scan spread")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--data", type=Path, default=Path("data"))
    ap.add_argument("--cap", type=int, default=64, help="distance field cap, cells")
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data, args.cap)


if __name__ == "__main__":
    main()
