"""The tracker alone on recorded inputs, two checkouts in lockstep, warm or with the caches flushed (not run by pytest).

One pipeline (this checkout) runs over an input once and records every ``Tracker.update`` call's arguments (the
scan, the pose, a deep copy of the map view, the body beams). Then a fresh tracker of each checkout (``--other``:
only its ``detect/tracker.py``, the rest of the code is this checkout's, as in ``bench_tracker_ab.py``) replays
those calls scan by scan, the two alternately first, each call timed in thread CPU time; over ``--reps``
repetitions the per-scan minimum is kept. Printed: the median and mean µs per scan of each and their ratio, and
the median of the per-scan ratios.

``--flush MB`` reads and writes an MB-sized buffer before every timed call, so each update starts with the
tracker's data and code out of the caches, as in the pipeline, where the SLAM stages run between two updates
(on this machine 16 MB does it; 1–4 MB do not change the time, so it is the shared L3, not L2, that matters).

    taskset -c 0 python benchmarks/bench_tracker_replay.py negative_2/right [--other /tmp/base/src] [--reps 3]
        [--flush 16]

Inputs: the names of ``bench_tracker_ab.py`` (every input of ``bench_digest.INPUTS``, ``mit-csail`` among them; an
unknown name stops with the list of accepted ones). The recorded map views take memory (≈ 650 MB for negative_2).
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tracker_ab import INPUTS, check_inputs, load_scans, other_tracker_module  # noqa: E402


def record(scans: list) -> tuple[object, list[tuple]]:
    """(the detect config, the arguments of every Tracker.update call of one pipeline run over ``scans``)."""
    from dynslam2d.pipeline import Pipeline

    p = Pipeline()
    calls = []
    orig = p.tracker.update

    def grab(*a):
        calls.append((a[0], a[1], copy.deepcopy(a[2]), None if a[3] is None else a[3].copy()))
        return orig(*a)

    p.tracker.update = grab
    for s in scans:
        p.process(s)
    return p.config.detect, calls


def replay_ab(cfg, calls: list[tuple], other, reps: int, flush_mb: int) -> dict[str, list[float]]:
    """Per checkout ("other", "this"): the per-scan minimum over ``reps`` lockstep replays of thread CPU µs."""
    from dynslam2d.detect import tracker as this

    mods = {"other": other, "this": this}
    buf = np.ones(max(flush_mb, 1) * 131072)  # (MB of float64)
    for mod in mods.values():  # (warm: every kernel loaded, every code path run once)
        tr = mod.Tracker(cfg)
        for c in calls:
            tr.update(*c)
    n = len(calls)
    best = {tag: [float("inf")] * n for tag in mods}
    for r in range(reps):
        trs = {tag: mod.Tracker(cfg) for tag, mod in mods.items()}
        for i, c in enumerate(calls):
            for tag in (("other", "this") if (i + r) % 2 == 0 else ("this", "other")):
                if flush_mb:
                    buf.sum()
                    buf[::8] += 1.0
                t0 = time.thread_time_ns()
                trs[tag].update(*c)
                best[tag][i] = min(best[tag][i], (time.thread_time_ns() - t0) / 1e3)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="+", metavar="INPUT", help=f"input names: {', '.join(INPUTS)}")
    ap.add_argument("--other", type=Path, default=Path(__file__).resolve().parents[1] / "src",
                    help="the other checkout's src/ (default: this one)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--flush", type=int, default=0, metavar="MB", help="touch MB of memory before every update")
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    a = ap.parse_args()
    check_inputs(ap, a.inputs)
    other = other_tracker_module(a.other)
    for name in a.inputs:
        cfg, calls = record(load_scans(a.data, name))
        best = replay_ab(cfg, calls, other, a.reps, a.flush)
        o, t = best["other"], best["this"]
        mo, mt = statistics.median(o), statistics.median(t)
        print(f"{name}: {len(calls)} scans, Tracker.update µs per scan{' (caches flushed)' if a.flush else ''}: "
              f"median {mo:.1f} → {mt:.1f} (×{mt / mo:.3f}), mean {statistics.fmean(o):.1f} → "
              f"{statistics.fmean(t):.1f}, median per-scan ratio {statistics.median(y / x for x, y in zip(o, t)):.3f}")
        del calls, best


if __name__ == "__main__":
    main()
