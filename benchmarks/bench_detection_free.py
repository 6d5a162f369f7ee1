"""What freeing one scan's detections costs, by part, and against their former form (passes det31, det32).

Runs the pipeline over each input keeping every scan's detection list (``Tracker.last_detections``: since pass det32
each detection is its scan's arrays, ``detect.measure.ScanArrays``, and its row) and, built from the same
``scan_detections`` arguments, the former form of pass det31's base (a slotted object per detection owning its
``beams`` view, its first point index and its axis angle and map evidence as boxed numbers, ``Former`` below; the
persons of a leg merge have no twin, the legs they replace do). After the run (``gc`` off), times freeing each scan's
list:

* the current lists with parts taken off beforehand (untimed; one variant per third of the scans, interleaved):
  the free-space test, then the scan's shared arrays;
* the current and the former list of the same scan, alternating which goes first (the first pays only its own
  part).

Also times making them (the captured arguments replayed, warm). Prints medians (means) in µs per scan. Not library
code: the former form is a copy kept here for the comparison.

``PYTHONPATH=src taskset -c 0 python benchmarks/bench_detection_free.py negative_2/right --data DATA``
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402


class Former:
    """A scan detection as pass det31 found it (its slots; the properties it had do not matter to the free)."""

    __slots__ = ("beams", "_pts", "_a0", "kind", "theta", "n_points", "_ff", "map_structure", "map_free", "map_unknown",
                 "person", "_fits", "_lohi", "_rel", "_j")


def former_detections(arrays, ff, _new=object.__new__) -> list[Former]:
    """The former ``scan_detections`` (det31's base) of the same scan: the lists it took (``tolist`` of the starts,
    counts, kinds, axis angles and map evidence, as ``_detect`` made them) and one object per detection."""
    from dynslam2d.detect.layout import F_THETA, KIND_NAMES

    beams, points, fits = arrays.beams, arrays.pts, arrays.fits
    starts, npts, kinds = arrays.starts.tolist(), arrays.npts.tolist(), arrays.kinds.tolist()
    theta = fits[:, F_THETA].tolist()
    nd = len(starts)
    fs, fm, fu = arrays.mev.tolist() if arrays.mev is not None else ([0.0] * nd,) * 3
    out = []
    append, names = out.append, KIND_NAMES
    for j, a0, n, kd, th, s, f, u in zip(range(nd), starts, npts, kinds, theta, fs, fm, fu):
        d = _new(Former)
        d.beams = beams[a0:a0 + n]
        d._pts = points
        d._a0 = a0
        d.kind = names[kd]
        d.theta = th
        d.n_points = n
        d._ff = ff
        d.map_structure = s
        d.map_free = f
        d.map_unknown = u
        d.person = False
        d._fits = fits
        d._lohi = arrays.lohi
        d._rel = arrays.rel
        d._j = j
        append(d)
    return out


def _strip(dets: list, level: int) -> None:
    for d in dets:
        if level >= 1:
            d._ff = 0.0
        if level >= 2:
            s = d._s
            s.beams = s.pts = s.starts = s.npts = s.kinds = s.fits = s.lohi = s.rel = s.mev = None


def _free(holder: list, i: int) -> float:
    t0 = time.perf_counter_ns()
    holder[i] = None
    return (time.perf_counter_ns() - t0) / 1e3


def _med(v: list[float]) -> str:
    return f"{statistics.median(v):6.2f} ({statistics.mean(v):6.2f})"


def _make_times(calls: list[tuple], make, passes: int = 5) -> tuple[float, float]:
    """Median over ``passes`` of the mean µs per scan of making every captured scan's list, current and former."""
    cur, old = [], []
    for _ in range(passes):
        for fn, out in ((make, cur), (former_detections, old)):
            t0 = time.perf_counter_ns()
            for a in calls:
                fn(*a)
            out.append((time.perf_counter_ns() - t0) / 1e3 / len(calls))
    return statistics.median(cur), statistics.median(old)


def run(name: str, data: Path) -> None:
    import dynslam2d.detect.trackdetect as td
    import dynslam2d.pipeline as pl
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    make = td.scan_detections
    pairs: list[list] = []
    calls: list[tuple] = []

    def wrapped(arrays, ff, *rest):
        out = make(arrays, ff, *rest)
        pairs.append([None, former_detections(arrays, ff)])
        if len(calls) < 50:
            calls.append((arrays, ff))
        return out

    td.scan_detections = wrapped
    try:
        pipe = pl.Pipeline()
        kept = []
        for s in scans:
            n0 = len(pairs)
            pipe.process(s)
            dets = pipe.tracker.last_detections
            kept.append(dets)
            if len(pairs) > n0:
                pairs[-1][0] = dets
    finally:
        td.scan_detections = make
    del pipe
    mk_cur, mk_old = _make_times(calls, make)
    calls.clear()
    counts = [len(d) for d in kept]
    half = {id(p[0]): p for p in pairs}
    gc.collect()
    gc.disable()
    try:
        labels = ("as made", "without the free-space test", "… and without the shared arrays")
        parts: dict[int, list[float]] = {v: [] for v in range(3)}
        own: dict[str, list[float]] = {"current": [], "former": []}
        second: dict[str, list[float]] = {"current": [], "former": []}
        for i in range(len(kept)):
            p = half.get(id(kept[i]))
            if not kept[i] or p is None:
                continue
            if i % 2 == 0:  # half the scans: current and former, alternating which is freed first
                kept[i] = None
                first = (i // 2) % 2
                names = ("current", "former")
                own[names[first]].append(_free(p, first))
                second[names[1 - first]].append(_free(p, 1 - first))
            else:  # the other half: the parts of the current list (the former twin freed first, untimed)
                p[1] = None
                p[0] = None
                v = (i // 2) % 3
                _strip(kept[i], v)
                parts[v].append(_free(kept, i))
    finally:
        gc.enable()
    print(f"{name}: {len(kept)} scans, detections per scan mean {statistics.mean(counts):.1f}, "
          f"median {statistics.median(counts)}, max {max(counts)}; µs per scan, median (mean)")
    for v, lab in enumerate(labels):
        print(f"  parts: {lab:32s} {_med(parts[v])}  ({len(parts[v])} scans)")
    for k in ("current", "former"):
        print(f"  {k:8s} own part (freed first) {_med(own[k])}; freed second (with the shared arrays and the "
              f"free-space test) {_med(second[k])}")
    print(f"  make (warm, 50 scans, median of 5 passes): current {mk_cur:.2f}, former {mk_old:.2f} µs per scan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--data", type=Path, default=Path("data"))
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data)


if __name__ == "__main__":
    main()
