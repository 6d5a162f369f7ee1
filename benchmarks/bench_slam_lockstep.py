"""``HectorSlam`` alone (laser only) of two checkouts in lockstep: CPU per scan and of its match stage (not run by
pytest).

``bench_pipeline_ab.py mit-csail`` runs the pipeline with the log's odometry, where the front end's correlative
search is rare; ``bench_slam_ab.py`` replays ``match_multires`` only. This one runs ``HectorSlam(SlamConfig())`` on
an input's scans without odometry (``bench_slam.py``'s MIT CSAIL row: there the search runs on ≈ 90 % of the scans)
in two worker processes, one per checkout, scan by scan alternately (the parent sends scan i to one, waits, then to
the other; which one goes first alternates), and prints the medians and means of each side's thread CPU time of
``process`` and of its matching (``StepResult.match_ms`` with the processor's clock set to ``time.thread_time``),
and whether the two sides' poses were identical on every scan.

    python benchmarks/bench_slam_lockstep.py [--clf <data>/mit-csail/mit-csail.clf] --other <other checkout>/src
        [--reps 1] [--scans N]

Each worker first runs a throw-away ``HectorSlam`` over the first 60 scans (kernels compiled or loaded). Pin with
``taskset -c N``; the side named "this" gains a few per cent in lockstep: run it from both checkouts.
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
CLF = REPO.parent / "shared" / "data" / "mit-csail" / "mit-csail.clf"


def worker(clf: Path, limit: int) -> None:
    """Serve ``go`` lines on stdin: process the next scan, answer one JSON line (CPU ms, match ms, pose)."""
    import time
    import types

    from dynslam2d.io.carmen import CarmenSource
    from dynslam2d.slam import HectorSlam, SlamConfig, processor

    scans = list(CarmenSource(clf))
    if limit:
        scans = scans[:limit]
    warm = HectorSlam(SlamConfig())
    for s in scans[:60]:
        warm.process(s)
    processor.time = types.SimpleNamespace(perf_counter=time.thread_time)  # match_ms in thread CPU time
    slam = HectorSlam(SlamConfig())
    print(json.dumps({"scans": len(scans)}), flush=True)
    for i, line in enumerate(sys.stdin):
        if i >= len(scans) or line.strip() != "go":
            break
        t0 = time.thread_time_ns()
        st = slam.process(scans[i])
        cpu = (time.thread_time_ns() - t0) / 1e6
        pose = slam.pose
        print(json.dumps({"cpu": cpu, "m": st.match_ms,
                          "p": None if pose is None else [pose.x, pose.y, pose.theta]}), flush=True)


def compare(clf: Path, other: Path, reps: int, limit: int) -> None:
    """Lockstep runs of the two checkouts; prints the figures."""
    cpu: dict[str, list[float]] = {"other": [], "this": []}
    match: dict[str, list[float]] = {"other": [], "this": []}
    differ = 0
    for _ in range(reps):
        procs = {}
        for tag, src in (("other", other.resolve()), ("this", REPO / "src")):
            env = dict(os.environ, PYTHONPATH=str(src))
            procs[tag] = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker", "--clf", str(clf), "--scans", str(limit)],
                env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())
        for i in range(n):
            poses = {}
            for tag in (("other", "this") if i % 2 == 0 else ("this", "other")):
                p = procs[tag]
                p.stdin.write("go\n")
                p.stdin.flush()
                r = json.loads(p.stdout.readline())
                if i > 0:  # (the first scan: the map's first insertion)
                    cpu[tag].append(r["cpu"])
                    match[tag].append(r["m"])
                poses[tag] = r["p"]
            differ += poses["this"] != poses["other"]
        for p in procs.values():
            p.stdin.close()
            p.wait()
    for name, d in (("process", cpu), ("match", match)):
        mo, mt = statistics.median(d["other"]), statistics.median(d["this"])
        ao, at = statistics.fmean(d["other"]), statistics.fmean(d["this"])
        print(f"{name:<8} ms/scan median: other {mo:.4f}, this {mt:.4f}, ratio {mt / mo:.3f}; mean: other {ao:.4f}, "
              f"this {at:.4f}, ratio {at / ao:.3f} ({len(d['this'])} scans)")
    print(f"scans whose poses differ: {differ}; load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clf", type=Path, default=CLF, help="a CARMEN log (default: MIT CSAIL)")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=1, help="lockstep runs (pooled)")
    ap.add_argument("--scans", type=int, default=0, help="only the first N scans (0: all)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.clf, args.scans)
    else:
        compare(args.clf, args.other, args.reps, args.scans)


if __name__ == "__main__":
    main()
