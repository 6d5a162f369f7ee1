"""CPU of ``pipeline.run``'s per-scan loop outside ``Pipeline.process``, two checkouts alternately (not run by pytest).

``run`` does per scan, besides ``process``: the scan's row, its removed beams (``BitRows``), its live tracks' rows
(``TrackRows``), its stage timings, the observers and the progress callback. The lockstep (``bench_pipeline_ab.py``)
times ``process`` only, so it cannot see this. Here each checkout runs ``run`` over the input's scans (read into
memory first, so no decoding) in a subprocess of its own (``PYTHONPATH``), once to warm up and then ``--runs`` times,
with ``Pipeline.process`` wrapped to take the thread CPU time from the end of one ``process`` call to the start of
the next: the loop's own work between two scans (the wrapper's two clock reads included, the same on both sides).
The checkouts alternate (which goes first alternates with the repetition). Printed per input and checkout: the median
over the runs of the median and of the mean gap per scan, µs.

    taskset -c 1 python benchmarks/bench_pipeline_runloop.py sim:paper negative_2/right mit-csail \
        --other <base>/src [--reps 3] [--runs 3] [--data <data>]

Inputs: the names of ``bench_digest.py`` or any built-in scene (``sim:NAME``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402


def worker(data: Path, name: str, runs: int) -> None:
    """Print one JSON line: per run, [median gap µs, mean gap µs]."""
    import dynslam2d.pipeline as pl
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    src = open_source(rel if rel.startswith("sim:") else str(data / rel), topic)
    scans = list(src)

    class Memory:
        """The scans in memory, with the source's metadata."""

        meta = src.meta

        def __iter__(self):  # type: ignore[no-untyped-def]
            return iter(scans)

        def __len__(self) -> int:
            return len(scans)

    last: list[int | None] = [None]
    gaps: list[int] = []
    process = pl.Pipeline.process

    def timed(self, scan):  # type: ignore[no-untyped-def]
        t = time.thread_time_ns()
        if last[0] is not None:
            gaps.append(t - last[0])
        out = process(self, scan)
        last[0] = time.thread_time_ns()
        return out

    pl.Pipeline.process = timed  # type: ignore[method-assign]
    pl.run(Memory())  # (warm-up: kernels loaded, first-use paths run)
    out = []
    for _ in range(runs):
        gaps.clear()
        last[0] = None
        pl.run(Memory())
        out.append([statistics.median(gaps) / 1e3, statistics.fmean(gaps) / 1e3])
    print(json.dumps(out), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or another built-in scene (sim:NAME)")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=3, help="alternations of the two checkouts")
    ap.add_argument("--runs", type=int, default=3, help="timed runs per worker")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    for name in args.inputs:
        if name not in INPUTS and not name.startswith("sim:"):
            ap.error(f"unknown input {name!r}")
    if args.worker:
        worker(args.data, args.inputs[0], args.runs)
        return
    for name in args.inputs:
        res: dict[str, list[list[float]]] = {"other": [], "this": []}
        for rep in range(args.reps):
            order = [("other", args.other.resolve()), ("this", REPO / "src")]
            for tag, src in order if rep % 2 == 0 else order[::-1]:
                out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data",
                                      str(args.data), "--runs", str(args.runs)],
                                     env=dict(os.environ, PYTHONPATH=str(src)), capture_output=True, text=True,
                                     check=True)
                res[tag] += json.loads(out.stdout.strip().splitlines()[-1])
        med = {k: (statistics.median(r[0] for r in v), statistics.median(r[1] for r in v)) for k, v in res.items()}
        print(f"{name}: run loop outside process, µs per scan, median gap other {med['other'][0]:.1f} this "
              f"{med['this'][0]:.1f} (ratio {med['this'][0] / med['other'][0]:.3f}); mean gap other "
              f"{med['other'][1]:.1f} this {med['this'][1]:.1f} (ratio {med['this'][1] / med['other'][1]:.3f})",
              flush=True)


if __name__ == "__main__":
    main()
