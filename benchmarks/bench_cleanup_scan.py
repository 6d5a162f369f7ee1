"""Per-scan CPU of the command line's two run observers, two checkouts alternately in one process (not run by pytest).

``dynslam2d run`` feeds every scan to the clean-up recorder (``slam/cleanup.py``: the scan's rays counted into the
clean-up grid) and to the removed-points collector (``viz/collect.py``), outside ``Pipeline.process``. Here one run
of the pipeline (this checkout) keeps every scan and its ``StepResult``; then the two checkouts' ``cleanup`` and
``collect`` modules (the other's loaded from its files under other names) replay their observers over those scans,
alternately (which goes first alternates with the repetition), each scan's ``on_scan`` timed by thread CPU. Printed
per input and checkout: the median over repetitions of the median and of the mean µs a scan, and their ratios.
The replay also checks that both sides end with the same counts and the same points (exactness).

    taskset -c 1 python benchmarks/bench_cleanup_scan.py sim:paper sim:crowd negative_2/right --other <base>/src \\
        [--reps 9] [--data <data>]
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from scratch import scratch_dir  # noqa: E402


def _load(src: Path, rel: str, name: str):  # type: ignore[no-untyped-def]
    """The other checkout's module ``rel`` under the name ``name``, from a copy in a folder of its own (numba's
    cache of its kernels goes there: in the checkout's own cache they would name a module it does not have)."""
    copy = Path(scratch_dir("bench_cleanup_scan_")) / f"{name}.py"
    shutil.copyfile(src / rel, copy)
    spec = importlib.util.spec_from_file_location(name, copy)
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules[name] = mod
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def _steps(path: str, topic: str | None):  # type: ignore[no-untyped-def]
    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run

    kept: list = []

    class Keep:
        def on_scan(self, scan, step, pipeline):  # type: ignore[no-untyped-def]
            kept.append((scan, step))

        def on_finish(self, result, pipeline):  # type: ignore[no-untyped-def]
            kept.append(pipeline)

    run(open_source(path, topic), Config(), observers=[Keep()])
    pipe = kept.pop()
    return kept, pipe


def _replay(mods, kept, pipe, cfg):  # type: ignore[no-untyped-def]
    clean, collect = mods
    rec = clean.CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    col = collect.RemovedPointsCollector()
    tr, tc = [], []
    clock = time.thread_time_ns
    for scan, step in kept:
        t0 = clock()
        rec.on_scan(scan, step, pipe)
        t1 = clock()
        col.on_scan(scan, step, pipe)
        t2 = clock()
        tr.append(t1 - t0)
        tc.append(t2 - t1)
    flush = getattr(rec, "flush", None)
    t0 = clock()
    if flush is not None:
        flush()
    tail = clock() - t0
    return np.array(tr) / 1e3, np.array(tc) / 1e3, tail / 1e3 / max(len(kept), 1), rec, col


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--other", type=Path, required=True, help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=9)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    from dynslam2d.config import Config
    from dynslam2d.slam import cleanup as this_clean
    from dynslam2d.viz import collect as this_collect

    other = (_load(args.other, "dynslam2d/slam/cleanup.py", "_other_cleanup"),
             _load(args.other, "dynslam2d/viz/collect.py", "_other_collect"))
    this = (this_clean, this_collect)
    cfg = Config()
    for name in args.inputs:
        rel, topic = INPUTS.get(name, (name, None))
        kept, pipe = _steps(rel if rel.startswith("sim:") else str(args.data / rel), topic)
        stats: dict[str, list[tuple[float, ...]]] = {"other": [], "this": []}
        ends = {}
        for rep in range(args.reps + 1):
            order = [("other", other), ("this", this)]
            if rep % 2:
                order.reverse()
            for side, mods in order:
                tr, tc, tail, rec, col = _replay(mods, kept, pipe, cfg)
                if rep:  # the first repetition warms up
                    stats[side].append((float(np.median(tr)), float(tr.mean()) + tail, float(np.median(tc)),
                                        float(tc.mean()), float(np.median(tr + tc)), float((tr + tc).mean()) + tail))
                c = rec.counter
                ends[side] = (c.hits, c.through, c.switches, c.last_touch(), col.points())
        same = all(np.array_equal(a, b) for a, b in zip(ends["this"], ends["other"]))
        med = {s: [statistics.median(v[k] for v in stats[s]) for k in range(6)] for s in stats}
        labels = ("cleanup median", "cleanup mean", "collector median", "collector mean", "both median", "both mean")
        print(f"{name} ({len(kept)} scans; counts and points identical: {same}), µs a scan, other → this:")
        for k, lab in enumerate(labels):
            o, t = med["other"][k], med["this"][k]
            print(f"  {lab:17s} {o:8.2f} → {t:8.2f} (×{t / o:.3f})" if o else f"  {lab:17s} {o:8.2f} → {t:8.2f}")


if __name__ == "__main__":
    main()
