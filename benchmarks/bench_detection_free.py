"""What freeing one scan's detections costs, by part, and a lean scratch form of them (pass det31).

Runs the pipeline over each input keeping every scan's detection list (``Tracker.last_detections``) and, built from
the same ``scan_detections`` arguments, a lean form: one per-scan record (slots: the scan's arrays) and one object per
detection holding the record and its row. After the run (``gc`` off), times freeing each scan's list:

* the current lists with parts taken off beforehand (untimed; one variant per fifth of the scans, interleaved):
  the ``beams`` views, then the free-space test, the boxed floats and ints, the shared arrays;
* the current and the lean list of the same scan, alternating which goes first (the first pays only its own part).

Prints medians (means) in µs per scan. Not library code: the lean form is a prototype.

``PYTHONPATH=src taskset -c 0 python benchmarks/bench_detection_free.py negative_2/right --data DATA``
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402


class ScanRec:
    """One scan's detection arrays (the lean form's record)."""

    __slots__ = ("beams", "pts", "starts", "npts", "kinds", "fits", "lohi", "rel", "mev", "ff")


class Lean:
    """A lean detection: its scan's record and its row."""

    __slots__ = ("_s", "_j", "_ff", "person")


def _strip(dets: list, level: int) -> None:
    zero = 0.0
    for d in dets:
        if level >= 1:
            d.beams = None
        if level >= 2:
            d._ff = zero
        if level >= 3:
            d.theta = d.map_structure = d.map_free = d.map_unknown = zero
            d._a0 = d.n_points = d._j = 0
        if level >= 4:
            d._pts = d._fits = d._lohi = d._rel = None


def _free(holder: list, i: int) -> float:
    t0 = time.perf_counter_ns()
    holder[i] = None
    return (time.perf_counter_ns() - t0) / 1e3


def _med(v: list[float]) -> str:
    return f"{statistics.median(v):6.2f} ({statistics.mean(v):6.2f})"


def run(name: str, data: Path) -> None:
    import dynslam2d.detect.trackdetect as td
    import dynslam2d.pipeline as pl
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    make = td.scan_detections
    pairs: list[list] = []

    def wrapped(beams, points, starts, npts, kinds, theta, ff, fs, fm, fu, fits, lohi, rel_, *rest):
        out = make(beams, points, starts, npts, kinds, theta, ff, fs, fm, fu, fits, lohi, rel_, *rest)
        r = ScanRec()
        r.beams, r.pts, r.fits, r.lohi, r.rel, r.ff = beams, points, fits, lohi, rel_, ff
        r.starts, r.npts, r.kinds, r.mev = np.array(starts), np.array(npts), np.array(kinds), np.array([fs, fm, fu])
        lean = []
        for j in range(len(npts)):
            d = object.__new__(Lean)
            d._s, d._j, d._ff, d.person = r, j, ff, False
            lean.append(d)
        pairs.append([None, lean])
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
    counts = [len(d) for d in kept]
    # the parts: the lists of scans without a lean twin (every scan here has one; the twins are split off first)
    half = {id(p[0]): p for p in pairs}
    gc.collect()
    gc.disable()
    try:
        labels = ("as made", "without the beams views", "… and the free-space test", "… and the boxed numbers",
                  "… and the shared arrays")
        parts: dict[int, list[float]] = {v: [] for v in range(5)}
        own: dict[str, list[float]] = {"current": [], "lean": []}
        second: dict[str, list[float]] = {"current": [], "lean": []}
        for i in range(len(kept)):
            p = half.get(id(kept[i]))
            if not kept[i] or p is None:
                continue
            if i % 2 == 0:  # half the scans: current and lean, alternating which is freed first
                kept[i] = None
                first = (i // 2) % 2
                names = ("current", "lean")
                own[names[first]].append(_free(p, first))
                second[names[1 - first]].append(_free(p, 1 - first))
            else:  # the other half: the parts of the current list (the lean twin freed first, untimed)
                p[1] = None
                p[0] = None
                v = (i // 2) % 5
                _strip(kept[i], v)
                parts[v].append(_free(kept, i))
    finally:
        gc.enable()
    print(f"{name}: {len(kept)} scans, detections per scan mean {statistics.mean(counts):.1f}, "
          f"median {statistics.median(counts)}, max {max(counts)}; µs per scan, median (mean)")
    for v, lab in enumerate(labels):
        print(f"  parts: {lab:30s} {_med(parts[v])}  ({len(parts[v])} scans)")
    for k in ("current", "lean"):
        print(f"  {k:8s} own part (freed first) {_med(own[k])}; freed second (with the shared arrays and the "
              f"free-space test) {_med(second[k])}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--data", type=Path, default=Path("data"))
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data)


if __name__ == "__main__":
    main()
