"""CPU cost of retroactive erasure's evidence ledger per scan (docs/maps.md, "Cost"; not run by pytest).

The four ledger calls of :meth:`dynslam2d.pipeline.Pipeline.process` (``observe``, ``erase_entering``,
``before_update``, ``after_update``) are timed with ``time.thread_time`` over whole simulated scenes
(30 s, as ``bench_pipeline.py``); printed: ledger ms per scan and the whole loop's CPU ms per scan,
medians of ``--repeat`` runs. ``--compare FILE`` loads another version of ``slam/erasure.py`` (e.g. a
released one: ``git show 282e4fe:src/dynslam2d/slam/erasure.py > /tmp/erasure_old.py``) and runs the two
alternately in the same process. Pin to one core for "one core":

    taskset -c 0 python benchmarks/bench_ledger.py [--scenes paper crowd ten-movers] [--compare FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import sys
import time

import numpy as np
from scenes import ten_movers


def _timed(cls: type) -> type:
    """``cls`` with its four per-scan calls timed (thread time, accumulated in ``T.acc``)."""
    takes_index = "index" in inspect.signature(cls.before_update).parameters
    takes_keep = "keep_beams" in inspect.signature(cls.__init__).parameters

    class T(cls):  # type: ignore[misc,valid-type]
        acc = [0.0]

        def __init__(self, config, lo, hi, keep_beams=False):
            if takes_keep:
                super().__init__(config, lo, hi, keep_beams=keep_beams)
            else:
                super().__init__(config, lo, hi)
                self.erased_beams = []

        def before_update(self, *a):
            t = time.thread_time()
            r = super().before_update(*(a if takes_index else a[:5]))
            T.acc[0] += time.thread_time() - t
            return r

        def after_update(self, *a):
            t = time.thread_time()
            r = super().after_update(*a)
            T.acc[0] += time.thread_time() - t
            return r

        def observe(self, *a):
            t = time.thread_time()
            r = super().observe(*a)
            T.acc[0] += time.thread_time() - t
            return r

        def erase_entering(self, *a):
            t = time.thread_time()
            r = super().erase_entering(*a)
            T.acc[0] += time.thread_time() - t
            return r

    return T


def main() -> None:
    import dynslam2d.pipeline as P
    from dynslam2d.sim import simulate

    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["paper", "crowd", "ten-movers"])
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--compare", default=None, help="another erasure.py to run alternately ('before')")
    args = ap.parse_args()
    versions = []
    if args.compare:
        spec = importlib.util.spec_from_file_location("erasure_compare", args.compare)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["erasure_compare"] = mod  # (dataclasses look their module up)
        spec.loader.exec_module(mod)
        versions.append(("compare", mod.EvidenceLedger))
    versions.append(("this", P.EvidenceLedger))
    for name in args.scenes:
        sim = ten_movers(args.duration) if name == "ten-movers" else simulate(name, duration=args.duration)
        scans = list(sim.scans)
        out: dict[str, list[tuple[float, float]]] = {v: [] for v, _ in versions}
        for _ in range(args.repeat):
            for label, cls in versions:
                T = _timed(cls)
                P.EvidenceLedger = T
                pipe = P.Pipeline()
                c0 = time.thread_time()
                for s in scans:
                    pipe.process(s)
                total = time.thread_time() - c0
                out[label].append((T.acc[0] * 1e3 / len(scans), total * 1e3 / len(scans)))
        parts = []
        for label, _ in versions:
            led = float(np.median([r[0] for r in out[label]]))
            tot = float(np.median([r[1] for r in out[label]]))
            parts.append(f"{label}: ledger {led:.3f} ms/scan, pipeline {tot:.3f} ms/scan CPU")
        print(f"{name} ({len(scans)} scans): " + "; ".join(parts), flush=True)


if __name__ == "__main__":
    main()
