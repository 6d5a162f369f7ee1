"""The map update stage's parts on scans without a map update, two checkouts in lockstep (not run by pytest).

``bench_pipeline_ab.py``'s lockstep (two workers, one per checkout, scan by scan alternately, thread CPU time), with
thread-CPU timers around the evidence ledger's ``observe`` and ``erase_entering``, the tracker's ``report_states``
and ``needs_map_update``; printed: each part's median µs over the scans that do not update the map, both sides, and
the stage's rest. ``--keep N``: each worker also keeps its last N steps' results alive (what their release costs
then lands outside the stage); ``--nogc``: the collector off in the scan loop.

    taskset -c 0 python benchmarks/bench_mapupdate_ab.py sim:paper --other <base>/src [--keep 3] [--nogc]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import scan_loop_gc, warm_up  # noqa: E402

PARTS = ("observe", "erase_entering", "report_states", "needs_map_update")


def worker(data: Path, name: str, keep: int, nogc: bool) -> None:
    """Serve ``go`` lines: process the next scan, answer its stage and part µs (thread CPU) as one JSON line."""
    import collections
    import gc
    import time
    import types

    import dynslam2d.pipeline as pl
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    warm_up(scans, 60)
    pl.time = types.SimpleNamespace(perf_counter=time.thread_time)
    pipe = pl.Pipeline()
    acc: dict[str, float] = {}
    clock = time.thread_time_ns

    def wrap(obj: object, attr: str) -> None:
        f = getattr(obj, attr)

        def timed(*a: object, **k: object) -> object:
            t0 = clock()
            try:
                return f(*a, **k)
            finally:
                acc[attr] = acc.get(attr, 0) + clock() - t0
        setattr(obj, attr, timed)

    wrap(pipe.ledger, "observe")
    wrap(pipe.ledger, "erase_entering")
    wrap(pipe.tracker, "report_states")
    wrap(pipe.slam, "needs_map_update")
    kept: collections.deque = collections.deque(maxlen=max(keep, 1))
    print(json.dumps({"scans": len(scans)}), flush=True)
    with scan_loop_gc():
        if nogc:
            gc.disable()
        for i, line in enumerate(sys.stdin):
            if i >= len(scans) or line.strip() != "go":
                break
            acc.clear()
            step = pipe.process(scans[i])
            r = {k: acc.get(k, 0) / 1e3 for k in PARTS}
            r["map_update"] = step.timings["map_update"] * 1e3
            r["track"] = step.timings["track"] * 1e3
            r["filter"] = step.timings["filter"] * 1e3
            r["total"] = step.timings["total"] * 1e3
            if keep:
                kept.append(step)
            print(json.dumps({"r": r, "u": bool(step.map_updated)}), flush=True)
            del step
        gc.enable()


def compare(data: Path, name: str, other: Path, reps: int, keep: int, nogc: bool) -> None:
    """Lockstep both checkouts over ``name`` and print the parts' medians on the scans without a map update."""
    vals: dict[str, dict[str, list[float]]] = {"other": {}, "this": {}}
    for _ in range(reps):
        procs = {}
        for tag, src in (("other", other.resolve()), ("this", REPO / "src")):
            env = dict(os.environ, PYTHONPATH=str(src))
            extra = ["--keep", str(keep)] + (["--nogc"] if nogc else [])
            procs[tag] = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data", str(data), *extra],
                env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())
        for i in range(n):
            got = {}
            for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
                p = procs[tag]
                p.stdin.write("go\n")
                p.stdin.flush()
                got[tag] = json.loads(p.stdout.readline())
            if got["other"]["u"] or got["this"]["u"]:
                continue
            for tag, g in got.items():
                r = g["r"]
                r["rest"] = r["map_update"] - r["observe"] - r["erase_entering"] - r["report_states"] \
                    - r["needs_map_update"]
                for k, v in r.items():
                    vals[tag].setdefault(k, []).append(v)
        for p in procs.values():
            p.stdin.close()
            p.wait()
    print(f"{name}: {len(vals['this']['total'])} scans without a map update; µs median (keep {keep}, nogc {nogc})")
    for k in vals["this"]:
        a, b = statistics.median(vals["other"][k]), statistics.median(vals["this"][k])
        qa, qb = (statistics.quantiles(vals[g][k], n=10) for g in ("other", "this"))
        print(f"  {k:<17} other {a:8.1f}  this {b:8.1f}  ratio {b / a if a else float('nan'):.3f}   deciles 1, 3, 7, "
              f"9: other {qa[0]:.1f} {qa[2]:.1f} {qa[6]:.1f} {qa[8]:.1f}, this {qb[0]:.1f} {qb[2]:.1f} {qb[6]:.1f} "
              f"{qb[8]:.1f}")
    sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--other", type=Path, default=None, help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--keep", type=int, default=0)
    ap.add_argument("--nogc", action="store_true")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.data, args.inputs[0], args.keep, args.nogc)
        return
    for name in args.inputs:
        compare(args.data, name, args.other, args.reps, args.keep, args.nogc)


if __name__ == "__main__":
    main()
