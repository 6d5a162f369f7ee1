"""One ledger kernel's call in place in the pipeline, and the same call again at once (warm), scan by scan (not run
by pytest).

The pipeline runs the input with ``slam/ledgerkernels.KERNEL`` wrapped: each call is timed as the pipeline makes it
(its data and code as the scan left them), then repeated with the same arguments (everything now in cache). The
gap between the two is what cold caches cost the call; the warm figure is what its arithmetic costs. Wall clock
(``perf_counter_ns``), µs, over the calls after a warm-up of ``WARMUP`` scans.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_ledger_inplace.py negative_2/right [--kernel level_rows]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402

WARMUP = 60


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", choices=sorted(INPUTS))
    ap.add_argument("--kernel", default="record_cells", choices=("record_cells", "level_rows"))
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = ap.parse_args()

    import dynslam2d.pipeline as pl
    import dynslam2d.slam.erasure as er
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS[args.input]
    scans = list(open_source(rel if rel.startswith("sim:") else str(args.data / rel), topic))
    lk = er._kernels()
    kernel = getattr(lk, args.kernel)
    tn = time.perf_counter_ns
    cold: list[int] = []
    warm: list[int] = []

    def timed(*a):
        t0 = tn()
        r = kernel(*a)
        t1 = tn()
        kernel(*a)  # (the kernels only read their arguments: the same call again)
        t2 = tn()
        cold.append(t1 - t0)
        warm.append(t2 - t1)
        return r

    setattr(lk, args.kernel, timed)
    try:
        p = pl.Pipeline()
        for s in scans[:WARMUP]:
            p.process(s)
        cold.clear()
        warm.clear()
        for s in scans:
            p.process(s)
    finally:
        setattr(lk, args.kernel, kernel)
    print(f"{args.input}: {args.kernel}, {len(cold)} calls; µs median / mean: in place "
          f"{statistics.median(cold) / 1e3:.1f} / {statistics.mean(cold) / 1e3:.1f}, "
          f"again at once {statistics.median(warm) / 1e3:.1f} / {statistics.mean(warm) / 1e3:.1f}")


if __name__ == "__main__":
    main()
