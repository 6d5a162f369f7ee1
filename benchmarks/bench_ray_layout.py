"""What the map update's ray kernel could gain from another memory layout, measured on real scans (not run by pytest).

Pass front26's ceiling measurement for the lever pass front25 named (one interleaved cell array instead of the
three per-level arrays log-odds / probability / update index). Runs this checkout's pipeline over an input and keeps
every call of ``raycast.integrate_levels`` on the front end's three-level map (returns, clearing ends, pose, stops,
settings) and the map's final levels; then replays all calls, in order, into copies of those final levels (the
update indices continuing from the last scan's), calling ``raycast._rays`` level by level from Python, timed per
scan with ``perf_counter_ns``, optionally with ``--evict MB`` of memory written before each scan (the stages
between two map updates push the levels out of the caches). The variants, alternated over ``--reps`` repetitions:

* ``kernel``: ``_rays`` as it is (three arrays);
* ``cells12`` / ``cells16``: ``_rays``' source with every ``lo[f]`` / ``pr[f]`` / ``ui[f]`` rewritten to one
  int32 buffer of 3 / 4 words per cell (float32 views for the log-odds and probability), one prefetch per new
  cell instead of three — the layout change's ceiling in this kernel;
* ``huge``: the three arrays in 2 MiB-aligned memory advised ``MADV_HUGEPAGE`` (TLB misses);
* ``no_prob``: the probabilities not written (``_write_probs`` removed; wrong values, timing only: what writing
  the probabilities costs — before pass map30 this was ``no_memo``, the probability memo's lookup replaced by a
  constant);
* ``no_prefetch``: the three prefetches removed.

Printed per variant: the median and mean µs per scan (all three levels) of the per-scan medians over the
repetitions, their ratios to ``kernel``, the median per-scan ratio, and whether the levels after a replay are
byte-identical to the kernel's (``no_prob`` is not, by construction). Also the cache lines a scan's updated cells
occupy in each layout.

    PYTHONPATH=src taskset -c 0 python benchmarks/bench_ray_layout.py negative_2/right --data <data> --evict 16
"""

from __future__ import annotations

import argparse
import inspect
import mmap
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402

_HUGE = 2 << 20


def record(data: Path, name: str) -> tuple[list[dict], list[tuple]]:
    """The pipeline's ``integrate_levels`` calls on its three-level map and that map's final levels."""
    import dynslam2d.pipeline as pl
    import dynslam2d.slam.grid as grid
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS[name]
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    calls: list[dict] = []
    orig = grid.integrate_levels

    def keep(hits, clear, c, s, x, y, lo, pr, ui, n_levels, res, i0, j0, counter, stop, use_stop, max_bytes,
             l_free, l_occ, cap):
        n = orig(hits, clear, c, s, x, y, lo, pr, ui, n_levels, res, i0, j0, counter, stop, use_stop, max_bytes,
                 l_free, l_occ, cap)
        if n >= 0 and n_levels == 3:
            calls.append(dict(hits=hits.copy(), clear=clear.copy(), c=c, s=s, x=x, y=y, res=res, stop=stop.copy(),
                              use_stop=use_stop, l_free=l_free, l_occ=l_occ, cap=cap))
        return n

    grid.integrate_levels = keep
    pipe = pl.Pipeline()
    m = pipe.slam.map
    for scan in scans:
        pipe.process(scan)
    grid.integrate_levels = orig
    levels = [(lv.logodds.copy(), lv.prob.copy(), lv.uidx.copy(), lv.i0, lv.j0, lv.update_counter)
              for lv in m.levels]
    return calls, levels


def variants() -> dict[str, object]:
    """The compiled variants of ``raycast._rays`` (the kernel itself under ``kernel`` and ``huge``)."""
    import dynslam2d.slam.raycast as rc
    from dynslam2d.jitbox import njit

    base = inspect.getsource(rc._rays.py_func).replace("@njit(cache=True)\n", "")
    out: dict[str, object] = {"kernel": rc._rays, "huge": rc._rays}

    def build(src: str) -> object:
        ns = dict(vars(rc))
        exec(src, ns)  # noqa: S102 - the kernel's own source, rewritten
        return njit(ns["_rays"])

    # raycast._write_probs for the interleaved cells (the probability the second word of ``_W``), from its own source
    write_cells = re.sub(r"@njit\(.*\)\n", "", inspect.getsource(rc._write_probs.py_func))
    write_cells = write_cells.replace("def _write_probs(pr, ", "def _write_probs_cells(cf, ")
    assert write_cells.count("pr[cells[i]] = p") == 1
    write_cells = write_cells.replace("pr[cells[i]] = p", "cf[cells[i] * _W + np.uint64(1)] = p")
    for words in (3, 4):
        s = base.replace("def _rays(logodds, prob, uidx,", "def _rays(cf, ci, h, w,")
        s = s.replace("    h, w = logodds.shape\n", "")
        s = re.sub(r"    lo = logodds.reshape\(h \* w\).*\n    pr = prob.reshape\(h \* w\)\n"
                   r"    ui = uidx.reshape\(h \* w\)\n", "", s)
        s = s.replace("_write_probs(pr, ", "_write_probs_cells(cf, ")
        s = re.sub(r"\blo\[([^\]]+)\]", r"cf[np.uint64(\1) * _W]", s)
        s = re.sub(r"\bpr\[([^\]]+)\]", r"cf[np.uint64(\1) * _W + np.uint64(1)]", s)
        s = re.sub(r"\bui\[([^\]]+)\]", r"ci[np.uint64(\1) * _W + np.uint64(2)]", s)
        s = s.replace("_prefetch(ui, g)", "_prefetch(ci, g * _W)")
        for p in ("                    _prefetch(lo, g)\n", "                    _prefetch(pr, g)\n"):
            s = s.replace(p, "")
        assert "lo[" not in s and "ui[" not in s and "pr[" not in s
        ns = dict(vars(rc))
        ns["_W"] = np.uint64(words)
        exec(write_cells, ns)  # noqa: S102
        ns["_write_probs_cells"] = njit(ns["_write_probs_cells"])
        exec(s, ns)  # noqa: S102
        out[f"cells{4 * words}"] = njit(ns["_rays"])
    probs = "_write_probs(pr, upd_f, upd_v, upd_p, n_upd)"
    assert base.count(probs) == 1
    out["no_prob"] = build(base.replace(probs, "n_upd + 0"))
    pf = ["                    _prefetch(ui, g)\n", "                    _prefetch(lo, g)\n",
          "                    _prefetch(pr, g)\n"]
    s = base
    for p in pf:
        assert p in s
        s = s.replace(p, "")
    out["no_prefetch"] = build(s)
    return out


def _huge_copy(a: np.ndarray) -> np.ndarray:
    m = mmap.mmap(-1, a.nbytes + _HUGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    m.madvise(mmap.MADV_HUGEPAGE)
    buf = np.frombuffer(m, dtype=np.uint8)
    off = (-buf.ctypes.data) % _HUGE
    out = buf[off:off + a.nbytes].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


def fresh(name: str, levels: list[tuple]) -> list[tuple]:
    """Copies of the final levels in the variant's layout."""
    out = []
    for lo, pr, ui, *_ in levels:
        if name.startswith("cells"):
            words = int(name[5:]) // 4
            h, w = lo.shape
            buf = np.zeros(h * w * words, dtype=np.int32)
            cf = buf.view(np.float32)
            cf[0::words] = lo.ravel()
            cf[1::words] = pr.ravel()
            buf[2::words] = ui.ravel()
            out.append((cf, buf, h, w))
        elif name == "huge":
            out.append((_huge_copy(lo), _huge_copy(pr), _huge_copy(ui)))
        else:
            out.append((lo.copy(), pr.copy(), ui.copy()))
    return out


def as_arrays(name: str, maps: list[tuple]) -> list[tuple]:
    """(log-odds, probability, update index) of each level as (H·W,) arrays."""
    if not name.startswith("cells"):
        return [tuple(a.ravel() for a in m) for m in maps]
    words = int(name[5:]) // 4
    return [(cf[0::words].copy(), cf[1::words].copy(), buf[2::words].copy()) for cf, buf, _, _ in maps]


def replay(kern, name: str, maps: list[tuple], calls: list[dict], levels: list[tuple],
           evict: np.ndarray | None) -> np.ndarray:
    """µs per scan (all levels) of replaying ``calls`` into ``maps``."""
    import dynslam2d.slam.raycast as rc

    per = np.empty(len(calls))
    for q, cl in enumerate(calls):
        ends, hit, _ = rc.ray_ends(cl["hits"], cl["clear"], cl["c"], cl["s"], cl["x"], cl["y"])
        if evict is not None:
            np.add(evict, 1.0, out=evict)
        t0 = time.perf_counter_ns()
        for k in range(3):
            _, _, _, i0, j0, ctr0 = levels[k]
            r = cl["res"][k]
            sx = int(np.floor(cl["x"] / r + 0.5)) - i0
            sy = int(np.floor(cl["y"] / r + 0.5)) - j0
            ctr = ctr0 + 3 * q
            args = (ctr + 1, ctr + 2, sx, sy, rc._NO_CELLS, rc._NO_CELLS, ends, r, i0, j0, hit, cl["stop"],
                    cl["use_stop"], cl["l_free"], cl["l_occ"], cl["cap"])
            kern(*maps[k], *args)
        per[q] = (time.perf_counter_ns() - t0) / 1e3
    return per


def lines(calls: list[dict], levels: list[tuple]) -> np.ndarray:
    """Per level, the mean per scan of: cells updated, cache lines they occupy in three arrays, in 12-byte and in
    16-byte cells (every tenth scan)."""
    import dynslam2d.slam.raycast as rc

    maps = fresh("kernel", levels)
    acc = np.zeros((3, 4))
    sel = list(range(0, len(calls), 10))
    for q in sel:
        cl = calls[q]
        ends, hit, _ = rc.ray_ends(cl["hits"], cl["clear"], cl["c"], cl["s"], cl["x"], cl["y"])
        for k in range(3):
            _, _, _, i0, j0, ctr0 = levels[k]
            r = cl["res"][k]
            ctr = ctr0 + 3 * q + (1 << 24)  # (above every index the level holds: the cells this call updates)
            lo, pr, ui = maps[k]
            rc._rays(lo, pr, ui, ctr + 1, ctr + 2, int(np.floor(cl["x"] / r + 0.5)) - i0,
                     int(np.floor(cl["y"] / r + 0.5)) - j0, rc._NO_CELLS, rc._NO_CELLS, ends, r, i0, j0, hit,
                     cl["stop"], cl["use_stop"], cl["l_free"], cl["l_occ"], cl["cap"])
            f = np.flatnonzero(ui.ravel() > ctr)
            acc[k] += (f.size, 3 * np.unique(f // 16).size,
                       np.unique(np.concatenate([(12 * f) // 64, (12 * f + 11) // 64])).size, np.unique(f // 4).size)
    return acc / len(sel)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input", choices=sorted(INPUTS))
    ap.add_argument("--data", type=Path, default=Path("data"))
    ap.add_argument("--evict", type=float, default=16.0, help="MB written before each scan (0: warm)")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--only", default="", help="comma-separated variants (default: all)")
    a = ap.parse_args()
    import dynslam2d.memtrim as mt

    mt.map_large_blocks()
    calls, levels = record(a.data, a.input)
    kerns = variants()
    if a.only:
        kerns = {k: v for k, v in kerns.items() if k == "kernel" or k in a.only.split(",")}
    evict = np.zeros(int(a.evict * 2**20) // 8) if a.evict > 0 else None
    ref = None
    same = {}
    for k, kern in kerns.items():  # (compiles)
        maps = fresh(k, levels)
        replay(kern, k, maps, calls, levels, None)
        arrs = as_arrays(k, maps)
        if ref is None:
            ref = arrs
        same[k] = all(np.array_equal(x.view(np.int32), y.view(np.int32)) for lv, rv in zip(arrs, ref)
                      for x, y in zip(lv, rv))
    names = list(kerns)
    times: dict[str, list[np.ndarray]] = {k: [] for k in names}
    for rep in range(a.reps):
        for k in (names if rep % 2 == 0 else names[::-1]):
            times[k].append(replay(kerns[k], k, fresh(k, levels), calls, levels, evict))
    base = np.median(np.array(times["kernel"]), axis=0)
    print(f"{a.input}: {len(calls)} map updates replayed into the final levels {[lv[0].shape for lv in levels]}, "
          f"{a.reps} repetitions, {a.evict:g} MB written before each scan; µs per scan (three levels)")
    for k in names:
        t = np.median(np.array(times[k]), axis=0)
        print(f"  {k:<12} median {statistics.median(t):7.1f}  mean {t.mean():7.1f}  ratio of medians "
              f"{statistics.median(t) / statistics.median(base):.3f}  median per-scan ratio {np.median(t / base):.3f}"
              f"  mean ratio {t.mean() / base.mean():.3f}  levels identical: {same[k]}")
    acc = lines(calls, levels)
    print("  per scan (every tenth), level: cells updated, cache lines in three arrays / 12-byte cells / 16-byte cells")
    for k in range(3):
        print(f"    {k}: {acc[k, 0]:8.0f}  {acc[k, 1]:7.0f} / {acc[k, 2]:7.0f} / {acc[k, 3]:7.0f}")


if __name__ == "__main__":
    main()
