"""Per-part CPU time of the per-scan path of two checkouts, in lockstep (not run by pytest).

``bench_pipeline_ab.py --parts`` times the parts of one checkout alone; on a machine shared with other jobs its
figures move with the load by a factor of two between runs, too much to compare two checkouts run one after the
other. Here two worker processes (this checkout and ``--other``, each on its own ``PYTHONPATH``) wrap the same
parts with thread-CPU timers (``time.thread_time_ns``) and process scan ``i`` when told to, the order alternating
with ``i`` (as ``bench_pipeline_ab.py``), so both see the same load scan by scan. Printed per input and part: the
median µs per scan of each checkout over the scans that update the map and over the others, and their ratio.

Parts: the whole ``Pipeline.process``; its top-level parts (body filter, the whole match, the tracker's map view
``_evidence_view``, the tracker's ``update``, both exclusions, the observed boxes, the evidence ledger's
methods, ``needs_map_update``, the map update, the loop closer's ``add``); inside the map view the
vacated-footprint kernel; "unattributed" = whole minus the top-level parts (``process``'s own Python, the step
record, the frame's teardown, and about 1 µs per wrapped call of this harness), and "outside the stages" = map
view + body filter + exclusions + observed boxes + unattributed (what the view2 pass worked on). Inside
"unattributed" (pass prc124): the movers' exclusion from the report columns, the harness's own share (the calls of
the top-level parts times a wrapper's cost outside its window, calibrated on a no-op in each worker) and the rest.

    taskset -c 0 python benchmarks/bench_parts_ab.py negative_2/right mit-csail sim:drive --other /tmp/base/src

Inputs: the names of ``bench_digest.py`` (paths under ``--data``).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import warm_up  # noqa: E402

WARMUP = 60
#: The top-level parts of ``Pipeline.process`` (what "unattributed" subtracts from the whole).
TOP = ("body filter", "match", "map view (_evidence_view)", "tracker update", "exclusion (both calls)",
       "observed boxes (_observed_rows)", "ledger", "map: needs_map_update", "map update", "loops add")
#: Inside "unattributed": the movers' exclusion from the report columns (``process`` calls them directly), the
#: wrappers' own cost outside their timed windows (calibrated on a no-op: ≈ 0.8–1.2 µs a wrapped call, each
#: top-level call's charged to ``process``), and what is left: ``process``'s own Python, the step record and the
#: frame's teardown, plus the calls not wrapped (``scan.without`` of the body filter, ``moving_index``, ``predict``,
#: ``report_states``, ``count_nonzero``) (pass prc124).
MOVERS = "  movers' columns (mover_pack + mover_exclusions)"
HARNESS = "  harness (wrappers' own, estimated)"
OWN = "  process's own + calls not wrapped"
#: The parts the view2 pass worked on ("outside the stages").
OUTSIDE = ("map view (_evidence_view)", "body filter", "exclusion (both calls)", "observed boxes (_observed_rows)",
           "unattributed")


def _counted_wrapper(acc: collections.Counter, calls: collections.Counter) -> Callable[[Any, str, str], None]:
    """``cputimers.thread_cpu_wrapper`` that also counts the calls of each tag in ``calls`` (outside the window)."""
    from cputimers import thread_cpu_wrapper

    return thread_cpu_wrapper(acc, calls)


def _wrapper_cost(make: Callable, n: int = 2000, reps: int = 25) -> float:
    """Median thread CPU ns a wrapper made by ``make(acc, calls)`` adds outside its timed window per call (what
    the caller is charged), measured on a method that does nothing."""

    class _Noop:
        def f(self, a: object, b: object = None) -> object:
            return a

    out = []
    for _ in range(reps):
        acc: collections.Counter = collections.Counter()
        obj = _Noop()
        make(acc, collections.Counter())(obj, "f", "noop")
        t0 = time.thread_time_ns()
        for _ in range(n):
            obj.f(1, b=2)
        out.append((time.thread_time_ns() - t0 - acc["noop"]) / n)
    return sorted(out)[reps // 2]


def worker(data: Path, name: str) -> None:
    """Serve ``go`` lines on stdin: process the next scan, answer one JSON line (ns per part, updated)."""
    import dynslam2d.detect.mapevidence as me
    import dynslam2d.memtrim as mt
    import dynslam2d.pipeline as pl
    from dynslam2d.inputs import open_source

    if hasattr(mt, "map_large_blocks"):  # the allocator setting of the command line (as bench_pipeline_ab.py)
        mt.map_large_blocks()
    rel, topic = INPUTS.get(name, (name, None))  # any other built-in scene by its name (sim:paper)
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    warm_up(scans, WARMUP)  # (and every kernel numba's cache holds loaded: none is loaded in the measured run)
    acc: collections.Counter = collections.Counter()

    calls: collections.Counter = collections.Counter()  # wrapped calls per scan and part
    wrap = _counted_wrapper(acc, calls)
    outside_ns = _wrapper_cost(_counted_wrapper)

    wrap(me, "vacated_outlines_kernel", "  vacated-footprint kernel")
    try:
        import dynslam2d.vacated as va
    except ImportError:  # a checkout before the view2 pass
        va = None
    if va is not None:
        wrap(va, "vacated_scan_kernel", "  vacated-footprint kernel")
    pipe = pl.Pipeline()
    wrap(pipe, "process", "whole")
    wrap(pipe.slam, "match", "match")
    wrap(pipe.tracker, "update", "tracker update")
    wrap(pipe, "_evidence_view", "map view (_evidence_view)")
    wrap(pipe, "_exclude", "exclusion (both calls)")
    wrap(pl, "_observed_rows", "observed boxes (_observed_rows)")
    wrap(pipe.slam, "update_map", "map update")
    wrap(pipe.slam, "needs_map_update", "map: needs_map_update")
    wrap(pipe.body, "mask", "body filter")
    wrap(pipe.body, "observe", "body filter")
    if hasattr(pipe.body, "apply"):  # (pass bdy122: mask and the filtered scan in one call)
        wrap(pipe.body, "apply", "body filter")
    else:  # before it: ``process``' own ``scan.without(body)`` is the body filter's too
        _body_without(pl, acc)
    if pipe.ledger is not None:
        for k in ("before_update", "after_update", "observe", "erase_entering"):
            wrap(pipe.ledger, k, "ledger")
    if pipe.loops is not None:
        wrap(pipe.loops, "add", "loops add")
    # (called by process itself, so far inside "unattributed": the movers' exclusion from the tracker's report columns)
    import dynslam2d.detect.trackreport as tr
    if hasattr(pl, "mover_exclusions"):
        wrap(pl, "mover_exclusions", MOVERS)
    if hasattr(tr.TrackReports, "mover_pack"):
        wrap(tr.TrackReports, "mover_pack", MOVERS)
    print(json.dumps({"scans": len(scans)}), flush=True)
    for i, line in enumerate(sys.stdin):
        if i >= len(scans) or line.strip() != "go":
            break
        acc.clear()
        calls.clear()
        step = pipe.process(scans[i])
        r = dict(acc)
        r["unattributed"] = r["whole"] - sum(r.get(k, 0) for k in TOP)
        r[HARNESS] = outside_ns * sum(calls[k] for k in (*TOP, MOVERS))
        r[OWN] = r["unattributed"] - r[HARNESS] - r.get(MOVERS, 0)
        r["outside the stages"] = sum(r.get(k, 0) for k in OUTSIDE)
        print(json.dumps({"p": r, "u": bool(step.map_updated)}), flush=True)


def _body_without(pl: object, acc: dict) -> None:
    """Time ``Scan.without`` into "body filter" when ``Pipeline.process`` itself calls it (the body's drop; its other
    callers are inside other parts)."""
    import time

    from dynslam2d.types import Scan

    code = pl.Pipeline.process.__code__
    inner = Scan.without

    def without(self, mask):  # noqa: ANN001, ANN202
        if sys._getframe(1).f_code is not code:
            return inner(self, mask)
        t = time.thread_time_ns()
        out = inner(self, mask)
        acc["body filter"] += time.thread_time_ns() - t
        return out

    Scan.without = without


def compare(data: Path, name: str, other: Path, reps: int) -> None:
    """Run both checkouts over ``name`` ``reps`` times in lockstep and print the per-part medians."""
    import numpy as np

    rows: dict[str, list[dict]] = {"other": [], "this": []}
    upd: list[bool] = []
    for _ in range(reps):
        procs = {}
        for key, src in (("this", REPO / "src"), ("other", other)):
            env = dict(os.environ, PYTHONPATH=str(src))
            procs[key] = subprocess.Popen([sys.executable, __file__, name, "--worker", "--data", str(data)],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())
        for i in range(n):
            order = ("this", "other") if i % 2 == 0 else ("other", "this")
            got = {}
            for key in order:
                procs[key].stdin.write("go\n")
                procs[key].stdin.flush()
                got[key] = json.loads(procs[key].stdout.readline())
            for key in ("this", "other"):
                rows[key].append(got[key]["p"])
            upd.append(got["this"]["u"])
        for p in procs.values():
            p.stdin.close()
            p.wait()
    u = np.array(upd)
    tags = sorted({k for r in rows["this"] + rows["other"] for k in r}, key=lambda t: (t.strip() != t, t))
    print(f"{name}: {len(u)} scans ({reps} run(s)), {int(u.sum())} update the map; CPU µs per scan, median, "
          f"other → this (ratio)")
    w = max(len(t) for t in tags)
    print(f"  {'part':<{w}} {'updating scans':>26} {'other scans':>26}")
    for tag in tags:
        cols = []
        for m in (u, ~u):
            if not m.any():
                cols.append("-")
                continue
            a, b = (float(np.median(np.array([r.get(tag, 0) for r in rows[k]])[m])) / 1e3 for k in ("other", "this"))
            cols.append(f"{a:7.0f} → {b:6.0f} ({b / a:.2f})" if a > 0 else f"{a:7.0f} → {b:6.0f}")
        print(f"  {tag:<{w}} {cols[0]:>26} {cols[1]:>26}")
    sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or another built-in scene (sim:NAME)")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=1, help="lockstep runs per input (pooled)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.data, args.inputs[0])
        return
    for name in args.inputs:
        compare(args.data, name, args.other, args.reps)


if __name__ == "__main__":
    main()
