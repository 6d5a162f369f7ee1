"""Layouts of a level's three per-cell fields (log-odds, probability cache, update index) under the map update's ray
walk, measured on a run's recorded map updates (not run by pytest; docs/speed.md "Map update, pass 13").

One copy of the ray kernel (``slam.raycast._rays``, the walk of ``MultiResMap.integrate`` with the multiply-shift,
the probability memo and the prefetch on a new cell) takes the three fields through a per-field stride and offset
into one 32-bit buffer per level, so every layout runs the same code: three separate arrays (what ``GridLevel``
holds), the three fields of a cell side by side (12 bytes a cell), and the three ways of pairing two fields with
the third apart. Further variants of the separate layout: the buffers in 2 MiB pages (``madvise(MADV_HUGEPAGE)``)
or in 4 KiB pages only, the probability written with a non-temporal store, the memo read into the caches before
each call, and two inexact ones that bound what the probability cache costs: a constant written instead of the
memo's value, and no probability written at all. Every variant runs on the final geometry of a first replay (no
growth), the variants in turn call by call (the order alternating), each on its own level buffers, with ``--evict
MB`` of memory written before every call; printed: median µs per call (all three levels), its ratio to the first
variant, the median of the per-call ratios, and whether the fields after the sweep equal those of
``slam.grid.MultiResMap``.

``--derived`` also prints, per level, how many cells' cached probability differs from the probability computed
from the stored float32 log-odds: the ray kernel computes ``float32(1 / (1 + exp(−v)))`` from the float64 sum
``v`` before it is rounded to the float32 log-odds, so the cache is not a function of the stored log-odds.

    python benchmarks/bench_map_replay.py negative_2/right --reps 1 --sweeps 1   # records the calls once
    taskset -c 0 python benchmarks/bench_map_layouts.py /tmp/map_replay_negative_2_right.pkl --evict 40 \\
        --variants separate,interleaved,lo_ui+prob,noprob
"""

from __future__ import annotations

import argparse
import math
import mmap
import pickle
import statistics
import time

import numpy as np
from llvmlite import ir as lir
from numba import njit
from numba import types as nbt
from numba.extending import intrinsic

import dynslam2d.slam.grid as grid
from dynslam2d.slam.raycast import _MAGIC_SHIFT, _PREFETCH, _bits, _prefetch, ray_ends
from dynslam2d.types import Pose2D

#: the probability memo's hash multiplier (Fibonacci hashing), as the ray kernel had it before pass map30
_FIB = -7046029254386353131


@njit(cache=True, inline="always")
def _prob(v, keys, vals):  # pragma: no cover - numba
    """The probability memo's value of float64 log-odds ``v`` (the ray kernel's ``_prob`` before pass map30
    replaced the memo): float32(1 / (1 + exp(−v))), looked up by the bits of ``v``, computed and stored on a miss."""
    key = _bits(v)
    h = np.uint64(((key * _FIB) >> 50) & (keys.shape[0] - 1))
    if keys[h] == key:
        return vals[h]
    p = np.float32(1.0 / (1.0 + math.exp(-v)))
    keys[h] = key
    vals[h] = p
    return p

#: per variant: ((stride, offset) of the log-odds, of the probability, of the update index) in 32-bit words of the
#: level's buffer, for a level of ``n`` cells
LAYOUTS = {
    "separate": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "interleaved": lambda n: ((3, 0), (3, 1), (3, 2)),
    "lo_ui+prob": lambda n: ((2, 0), (1, 2 * n), (2, 1)),
    "prob_ui+lo": lambda n: ((1, 2 * n), (2, 0), (2, 1)),
    "lo_prob+ui": lambda n: ((2, 0), (2, 1), (1, 2 * n)),
    "hugepages": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "smallpages": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "nontemporal": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "warm_memo": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "constant": lambda n: ((1, 0), (1, n), (1, 2 * n)),
    "noprob": lambda n: ((1, 0), (1, n), (1, 2 * n)),
}
#: how a variant writes the probability cache: 1 memo (exact), 2 a constant (inexact), 3 the memo with a
#: non-temporal store, 0 not at all (inexact)
PROB_MODE = {"constant": 2, "nontemporal": 3, "noprob": 0}
_HUGE = 2 << 20
_KEEP: list[mmap.mmap] = []


@intrinsic
def _nt_store(typingctx, arr, idx, val):
    """``arr[idx] = val`` with LLVM's ``!nontemporal`` hint (1-D C array)."""
    sig = nbt.void(arr, idx, val)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        st = builder.store(args[2], builder.gep(ary.data, [args[1]]))
        st.set_metadata("nontemporal", builder.module.add_metadata([lir.Constant(lir.IntType(32), 1)]))
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True)
def _rays_strided(buf, s_lo, o_lo, s_pr, o_pr, s_ui, o_ui, h, w, free_idx, occ_idx, sx, sy, ends, r, i0, j0, hit,
                  stop, use_stop, l_free, l_occ, cap, keys, vals, mode):  # pragma: no cover - numba
    """``raycast._rays`` (its multiply-shift branch, rays from the map-frame ends) on one level whose log-odds,
    probability and update index of flat cell ``f`` are the 32-bit words ``f·s + o`` of ``buf``."""
    lo = buf.view(np.float32)
    ui = buf
    pr = lo
    f0 = sy * w + sx
    n_done = 0
    mask = keys.shape[0] - 1
    miss_f = np.empty(max(h, w) + 1, dtype=np.uint64)
    miss_v = np.empty(max(h, w) + 1)
    for k in range(ends.shape[1]):
        x1 = int(math.floor(ends[0, k] / r + 0.5)) - i0
        y1 = int(math.floor(ends[1, k] / r + 0.5)) - j0
        if x1 == sx and y1 == sy:
            continue
        if x1 < 0 or y1 < 0 or x1 >= w or y1 >= h:
            continue
        dx = x1 - sx
        dy = y1 - sy
        adx = abs(dx)
        ady = abs(dy)
        stx = 1 if dx > 0 else -1
        sty = w if dy > 0 else -w
        if adx >= ady:
            major, minor, d_major, d_minor = adx, ady, stx, sty
        else:
            major, minor, d_major, d_minor = ady, adx, sty, stx
        skip = 0
        if use_stop and stop[k] > 1.0:
            skip = int((stop[k] - 1.0) * major / math.sqrt(float(dx * dx + dy * dy)))
            if skip > major - 1:
                skip = major - 1
        n_miss = 0
        magic = ((1 << _MAGIC_SHIFT) + major - 1) // major
        t = major // 2
        fb = f0
        for _ in range(major - skip):
            f = np.uint64(fb + ((t * magic) >> _MAGIC_SHIFT) * d_minor)
            if ui[f * s_ui + o_ui] < free_idx:
                g = np.uint64(fb + _PREFETCH * d_major + (((t + _PREFETCH * minor) * magic) >> _MAGIC_SHIFT)
                              * d_minor)
                _prefetch(ui, g * s_ui + o_ui)
                if s_lo == 1 or s_ui == 1:
                    _prefetch(lo, g * s_lo + o_lo)
                if (mode == 1 or mode == 2) and s_pr == 1:
                    _prefetch(pr, g * s_pr + o_pr)
                v = lo[f * s_lo + o_lo] + l_free
                lo[f * s_lo + o_lo] = v
                ui[f * s_ui + o_ui] = free_idx
                if mode == 2:
                    pr[f * s_pr + o_pr] = np.float32(0.5)
                elif mode:
                    key = _bits(v)
                    e = np.uint64(((key * _FIB) >> 50) & mask)
                    if keys[e] == key:
                        if mode == 3:
                            _nt_store(pr, f * s_pr + o_pr, vals[e])
                        else:
                            pr[f * s_pr + o_pr] = vals[e]
                    else:
                        miss_f[n_miss] = f
                        miss_v[n_miss] = v
                        n_miss += 1
            t += minor
            fb += d_major
        f = np.uint64(y1 * w + x1)
        u = ui[f * s_ui + o_ui]
        v = 0.0
        updated = False
        if hit[k]:
            if u < occ_idx:
                v = lo[f * s_lo + o_lo]
                if u == free_idx:
                    v -= l_free
                if v < cap:
                    v += l_occ
                lo[f * s_lo + o_lo] = v
                ui[f * s_ui + o_ui] = occ_idx
                updated = True
        elif u < free_idx:
            v = lo[f * s_lo + o_lo] + l_free
            lo[f * s_lo + o_lo] = v
            ui[f * s_ui + o_ui] = free_idx
            updated = True
        if updated and mode:
            key = _bits(v)
            e = np.uint64(((key * _FIB) >> 50) & mask)
            if keys[e] == key:
                pr[f * s_pr + o_pr] = vals[e]
            else:
                miss_f[n_miss] = f
                miss_v[n_miss] = v
                n_miss += 1
        for i in range(n_miss):
            pr[miss_f[i] * s_pr + o_pr] = _prob(miss_v[i], keys, vals)
        n_done += 1
    return n_done


def _paged_buffer(n_words: int, huge: bool) -> np.ndarray:
    """An int32 buffer of ``n_words`` in an anonymous mapping, 2 MiB-aligned, advised to use 2 MiB pages (``huge``)
    or not to (numpy advises them itself for arrays of 4 MiB or more, so the reference buffer of a level is in part
    in 2 MiB pages; the ``GridLevel`` arrays of a map the size of negative_2's are not)."""
    mm = mmap.mmap(-1, n_words * 4 + _HUGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    mm.madvise(mmap.MADV_HUGEPAGE if huge else mmap.MADV_NOHUGEPAGE)
    raw = np.frombuffer(mm, dtype=np.uint8)
    off = (-raw.ctypes.data) % _HUGE
    _KEEP.append(mm)
    return raw[off:off + n_words * 4].view(np.int32)


def _fields(buf: np.ndarray, variant: str, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(log-odds float32, probability float32, update index int32) views of a level buffer, n cells each."""
    (a1, b1), (a2, b2), (a3, b3) = LAYOUTS[variant](n)
    fl = buf.view(np.float32)
    return fl[b1::a1][:n], fl[b2::a2][:n], buf[b3::a3][:n]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recording", help="a pickle of bench_map_replay.py --record (/tmp/map_replay_*.pkl)")
    ap.add_argument("--variants", default="separate,interleaved,lo_ui+prob,prob_ui+lo,lo_prob+ui,noprob",
                    help=f"comma-separated, the first is the reference; of {', '.join(LAYOUTS)}")
    ap.add_argument("--evict", type=float, default=40.0, help="MB written before every call (0: warm)")
    ap.add_argument("--reps", type=int, default=2, help="sweeps over the calls (the first, which compiles, is "
                    "not timed)")
    ap.add_argument("--derived", action="store_true", help="count the cells whose cached probability differs "
                    "from the one of their stored float32 log-odds")
    args = ap.parse_args()
    if args.reps < 2:
        ap.error("--reps must be at least 2: the first sweep compiles and is not timed")
    variants = args.variants.split(",")
    with open(args.recording, "rb") as fh:
        rec = pickle.load(fh)
    st = rec["settings"]
    calls = [(Pose2D(x, y, t), h, c) for x, y, t, h, c in rec["calls"]]
    ref_map = grid.MultiResMap(**st)
    for pose, h, c in calls:
        ref_map.integrate(pose, h, c)
    if args.derived:
        for lv in ref_map.levels:
            seen = lv.uidx >= 0
            derived = (1.0 / (1.0 + np.exp(-lv.logodds.astype(np.float64)))).astype(np.float32)
            print(f"level {lv.resolution:.3f} m {lv.shape}: {int(seen.sum())} cells observed, "
                  f"{int((derived != lv.prob).sum())} with a cached probability other than "
                  f"float32(1 / (1 + exp(-log-odds))); {np.unique(lv.logodds[seen]).size} distinct log-odds")
    geo = [(lv.resolution, lv.i0, lv.j0, lv.shape) for lv in ref_map.levels]
    use_stop = st["grazing_cells"] > 0.0
    min_sin = math.sin(math.radians(st["min_incidence_deg"]))
    junk = np.zeros(max(int(args.evict * 1e6) // 8, 1))
    keys, vals = np.zeros(4096, np.int64), np.full(4096, 0.5, np.float32)  # (the memo as the map kept it)
    times: dict[str, list[float]] = {v: [] for v in variants}
    for rep in range(args.reps):
        levels: dict[str, list[tuple]] = {}
        for v in variants:
            levels[v] = []
            for res, i0, j0, (h, w) in geo:
                n = h * w
                if v in ("hugepages", "smallpages"):
                    buf = _paged_buffer(3 * n, v == "hugepages")
                else:
                    buf = np.empty(3 * n, dtype=np.int32)
                lo, pr, ui = _fields(buf, v, n)
                lo[:] = 0.0
                pr[:] = 0.5
                ui[:] = -1
                (a1, b1), (a2, b2), (a3, b3) = LAYOUTS[v](n)
                levels[v].append((buf, a1, b1, a2, b2, a3, b3, h, w, res, i0, j0))
        counter = [0] * len(geo)
        for ci, (pose, hits, clear) in enumerate(calls):
            hits = np.asarray(hits, dtype=np.float64).reshape(-1, 2)
            clr = np.zeros((0, 2)) if clear is None else np.asarray(clear, dtype=np.float64).reshape(-1, 2)
            ends, hit, _ = ray_ends(hits, clr, math.cos(pose.theta), math.sin(pose.theta), float(pose.x),
                                    float(pose.y))
            stop = np.zeros(hit.shape[0])
            if use_stop:
                stop[:hits.shape[0]] = grid.grazing_stop(hits, st["grazing_cells"], min_sin)
            for v in (variants if (ci + rep) % 2 == 0 else variants[::-1]):
                if args.evict > 0:
                    junk += 1.0
                if v == "warm_memo":
                    keys.sum()
                    vals.sum()
                mode = PROB_MODE.get(v, 1)
                t0 = time.thread_time_ns()
                for k, (buf, a1, b1, a2, b2, a3, b3, h, w, res, i0, j0) in enumerate(levels[v]):
                    sx = math.floor(pose.x / res + 0.5) - i0
                    sy = math.floor(pose.y / res + 0.5) - j0
                    _rays_strided(buf, a1, b1, a2, b2, a3, b3, h, w, counter[k] + 1, counter[k] + 2, sx, sy, ends,
                                  res, i0, j0, hit, stop, use_stop, st["l_free"], st["l_occ"], st["cap"], keys,
                                  vals, mode)
                if rep:
                    times[v].append((time.thread_time_ns() - t0) / 1e3)
            counter = [c + 3 for c in counter]
        if rep == args.reps - 1:
            for v in variants:
                same = True
                for (buf, *rest), lv in zip(levels[v], ref_map.levels):
                    lo, pr, ui = _fields(buf, v, rest[6] * rest[7])
                    same &= np.array_equal(lo.view(np.int32), lv.logodds.view(np.int32).ravel())
                    same &= np.array_equal(ui, lv.uidx.ravel())
                    same &= np.array_equal(pr.view(np.int32), lv.prob.view(np.int32).ravel())
                print(f"{v}: fields equal to MultiResMap's: {same}")
    ref = times[variants[0]]
    print(f"{len(calls)} map updates, {args.reps - 1} timed sweep(s), evict {args.evict} MB; µs per call, all levels")
    for v in variants:
        md = statistics.median(times[v])
        per_call = statistics.median(a / b for a, b in zip(times[v], ref))
        print(f"  {v:<12} median {md:7.1f} (×{md / statistics.median(ref):.3f}); median per-call ratio "
              f"{per_call:.3f}")


if __name__ == "__main__":
    main()
