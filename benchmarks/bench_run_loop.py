"""What ``dynslam2d run`` pays per scan: its whole scan loop, by part, one checkout or two in lockstep (not run by
pytest).

The README's speed table (``bench_pipeline.py``) times ``Pipeline.process`` only. ``dynslam2d run`` runs more per
scan: ``pipeline.run``'s loop writes the scan's records (``records.py``: the scan row, removed bits, track rows, stage
timings) and feeds the command line's observers — the removed-points collector (``viz/collect.py``), the
checkpointer (``io/checkpoint.py``) and the clean-up recorder (``slam/cleanup.py``), in the order and with the
settings ``cli.run`` gives them — and the progress callback. Here the command line's own run path does all
of that: ``cli._map_with_progress`` (the progress callback of ``dynslam2d run --quiet``) calls ``pipeline.run`` with
the observers ``cli.run`` builds (``cli._run_observers``; no animation, bag or viewer); nothing of the loop is
re-implemented. Thread-CPU timers wrap ``Pipeline.process`` and each observer's ``on_scan`` (≈ 0.1 µs a clock read);
the scans come from memory (read first: no decoding) through an iterator that takes the clock when the loop asks for
the next scan. Per scan:

* ``process``: ``Pipeline.process``;
* ``clean-up recorder``, ``collector``, ``checkpointer``: each observer's ``on_scan`` of that scan (the recorder and
  the collector are fed 32 scans at a time, ``RunObserver.scan_batch``: each call is counted for the scan it
  observes, not the one whose loop body made it);
* ``records``: the rest of the loop body between the end of ``process`` and the loop's next request (the scan's
  records, the stage timings, the progress callback, ``release_free_memory`` every ``TRIM_EVERY_SCANS``);
* ``whole``: their sum — the scan as ``dynslam2d run`` pays it; ``outside process``: ``whole`` − ``process``.

Printed per input: the median and the mean of each (ms a scan for ``whole`` and ``process``, µs for the others), the
throughput ``1000 / mean whole ms`` (scans/s), and the end of the run after the loop once (``run``'s export, the loop
closer's end, the observers' ``on_finish``: the clean-up pass), ms.

With ``--other <checkout>/src`` the two checkouts run in two worker processes in lockstep (the parent lets one worker
do one scan's loop body, then the other; which goes first alternates with the scan; the end of the run one after the
other), so both see the same load; run it also from the other checkout's copy of this script with ``--other`` this
one (both roles, docs/speed.md) — or, where the other checkout has no copy of it, from this copy with ``--this
<other>/src --other <this checkout>/src`` (the side named "this" is the one ``--this`` names). ``--markdown`` prints
the figures of this checkout as rows for the README beside ``bench_pipeline.py``'s table, with the command and the
machine's load.

    taskset -c 0 python benchmarks/bench_run_loop.py sim:paper sim:crowd negative_2/right mit-csail \\
        [--other <base>/src] [--this <src>] [--reps 1] [--data <data>] [--markdown]

Inputs: the names of ``bench_digest.py`` or any built-in scene (``sim:NAME``). Both workers inherit this process's
CPU affinity: pin the parent with ``taskset``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402

WARMUP = 60
#: the parts of a scan, in the printed order (``whole`` is their sum)
PARTS = ("whole", "process", "records", "clean-up recorder", "collector", "checkpointer")


def worker(data: Path, name: str) -> None:
    """Serve the parent over stdin / stdout: ``go`` → the next scan's loop body, answered ``ok`` once the loop asks
    for the scan after it; ``end`` → the run's end; then one JSON line of per-scan µs per part and the end's ms."""
    from bench_pipeline import warm_up

    import dynslam2d.memtrim as mt
    import dynslam2d.pipeline as pl
    from dynslam2d import cli
    from dynslam2d.config import Config
    from dynslam2d.inputs import open_source
    from dynslam2d.io.checkpoint import Checkpointer
    from dynslam2d.slam.cleanup import CleanupRecorder
    from dynslam2d.viz.collect import RemovedPointsCollector

    if hasattr(mt, "map_large_blocks"):  # the allocator setting the command line makes
        mt.map_large_blocks()
    rel, topic = INPUTS.get(name, (name, None))
    src = open_source(rel if rel.startswith("sim:") else str(data / rel), topic)
    scans = list(src)
    clock = time.thread_time_ns
    state = {"i": -1, "lockstep": False}
    marks: dict[str, list[int]] = {"p0": [], "p1": [], "ask": [], "end": []}
    calls: dict[str, list[tuple[int, int]]] = {}  # observer part → (scan index of the loop body, ns) per call

    class Memory:
        """The scans in memory with the source's metadata; in lockstep each scan waits for the parent's ``go``."""

        meta = src.meta

        def __init__(self, n: int) -> None:
            self.n = n

        def __iter__(self):  # type: ignore[no-untyped-def]
            for i in range(self.n):
                if state["lockstep"] and sys.stdin.readline().strip() != "go":
                    return
                state["i"] = i
                yield scans[i]
                marks["ask"].append(clock())  # (the loop asks for the next scan: scan i's loop body is done)
                if state["lockstep"]:
                    print("ok", flush=True)
            if state["lockstep"]:
                sys.stdin.readline()  # "end": the run's end, one worker at a time
            state["i"] = self.n  # (the late observers' last calls, after the loop: counted for their scans only)
            marks["end"].append(clock())

        def __len__(self) -> int:
            return self.n

    process = pl.Pipeline.process

    def timed_process(self, scan):  # type: ignore[no-untyped-def]
        marks["p0"].append(clock())
        out = process(self, scan)
        marks["p1"].append(clock())
        return out

    def timed(part: str, fn):  # type: ignore[no-untyped-def]
        rows = calls.setdefault(part, [])

        def on_scan(scan, step, pipeline):  # type: ignore[no-untyped-def]
            t0 = clock()
            fn(scan, step, pipeline)
            rows.append((state["i"], clock() - t0))

        return on_scan

    def observers(cfg: Config, work: Path, stack) -> list:  # type: ignore[no-untyped-def]
        """``cli.run``'s observers (its order and settings), each ``on_scan`` timed."""
        collector = RemovedPointsCollector()
        cleaner = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
        checkpointer = Checkpointer(work, every_s=60.0, every_scans=0, info={"input": src.meta.origin})
        obs = [collector, checkpointer]
        obs += cli._run_observers(stack, cfg, work, cleaner, animate=False, frame_step=5, write_bag=None,
                                  bag_storage=None, map_period=1.0, viewer="none", rerun_save=None)
        for o, part in ((collector, "collector"), (checkpointer, "checkpointer"), (cleaner, "clean-up recorder")):
            o.on_scan = timed(part, o.on_scan)  # type: ignore[method-assign]
        return obs

    def one_run(n: int) -> float:
        """``dynslam2d run --quiet``'s loop over the first ``n`` scans; the end of the run (after the loop, the late
        observers' last ``on_scan`` calls left out: they count for their scans), thread-CPU ms."""
        import contextlib

        cfg = Config()
        with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
            cli._map_with_progress(Memory(n), cfg, observers(cfg, Path(tmp), stack), False)
            t1 = clock()
        late = sum(ns for rows in calls.values() for body, ns in rows if body == n)
        return (t1 - marks["end"][-1] - late) / 1e6

    warm_up(scans, WARMUP)  # (the pipeline's kernels and every other kernel numba's cache holds loaded)
    one_run(min(len(scans), 3 * WARMUP))  # (the observers' first calls, the command line's imports)
    for v in (*marks.values(), *calls.values()):
        v.clear()
    pl.Pipeline.process = timed_process  # type: ignore[method-assign]
    print(json.dumps({"scans": len(scans)}), flush=True)
    state["lockstep"] = True
    end_ms = one_run(len(scans))
    n = len(marks["p1"])
    per: dict[str, list[float]] = {p: [0.0] * n for p in PARTS}
    inside = [0] * (n + 1)  # ns of observer calls made inside each scan's loop body (n: after the loop)
    for part, rows in calls.items():
        for k, (body, ns) in enumerate(rows):  # the k-th call observes scan k
            per[part][k] = ns / 1e3
            inside[body] += ns
    for i in range(n):
        per["process"][i] = (marks["p1"][i] - marks["p0"][i]) / 1e3
        per["records"][i] = (marks["ask"][i] - marks["p1"][i] - inside[i]) / 1e3
        per["whole"][i] = sum(per[p][i] for p in PARTS[1:])
    print(json.dumps({"per": per, "end_ms": end_ms}), flush=True)


def _start(src: Path, name: str, data: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker", name, "--data", str(data)],
                            env=dict(os.environ, PYTHONPATH=str(src)), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)


def measure(name: str, sides: dict[str, Path], data: Path, reps: int) -> dict[str, dict[str, object]]:
    """``reps`` lockstep runs of ``name`` per side ({tag: src}); per side the pooled per-scan µs of each part and
    the ends' ms."""
    out: dict[str, dict[str, object]] = {t: {"per": {p: [] for p in PARTS}, "end_ms": []} for t in sides}
    for _ in range(reps):
        procs = {t: _start(s, name, data) for t, s in sides.items()}
        n = min(json.loads(p.stdout.readline())["scans"] for p in procs.values())  # type: ignore[union-attr]
        tags = list(procs)
        for i in range(n):
            for t in tags if i % 2 == 0 else tags[::-1]:
                p = procs[t]
                p.stdin.write("go\n")  # type: ignore[union-attr]
                p.stdin.flush()  # type: ignore[union-attr]
                if p.stdout.readline().strip() != "ok":  # type: ignore[union-attr]
                    raise RuntimeError(f"{t} worker stopped at scan {i} of {name}")
        for t in tags:  # (the run's end: one worker at a time)
            p = procs[t]
            p.stdin.write("end\n")  # type: ignore[union-attr]
            p.stdin.flush()  # type: ignore[union-attr]
            r = json.loads(p.stdout.readline())  # type: ignore[union-attr]
            p.stdin.close()  # type: ignore[union-attr]
            p.wait()
            for part in PARTS:
                out[t]["per"][part] += r["per"][part]  # type: ignore[index]
            out[t]["end_ms"].append(r["end_ms"])  # type: ignore[union-attr]
    return out


def figures(side: dict[str, object]) -> dict[str, tuple[float, float]]:
    """{part: (median, mean)}: ms for ``whole`` and ``process``, µs for the others; ``scans/s`` (1000 / mean whole
    ms, twice) and ``end`` (median end of the run, ms, twice)."""
    per: dict[str, list[float]] = side["per"]  # type: ignore[assignment]
    out = {}
    for part in PARTS:
        v = per[part]
        k = 1e3 if part in ("whole", "process") else 1.0
        out[part] = (statistics.median(v) / k, statistics.fmean(v) / k)
    outside = [w - q for w, q in zip(per["whole"], per["process"])]  # (µs: the loop's work besides process)
    out["outside process"] = (statistics.median(outside), statistics.fmean(outside))
    rate = 1e3 / out["whole"][1]
    out["scans/s"] = (rate, rate)
    end = statistics.median(side["end_ms"])  # type: ignore[arg-type]
    out["end"] = (end, end)
    return out


def report(name: str, res: dict[str, dict[str, object]]) -> dict[str, dict[str, tuple[float, float]]]:
    """Print one input's figures (``other → this`` and the ratio with two sides); return them per side."""
    fig = {t: figures(s) for t, s in res.items()}
    n = len(res["this"]["per"]["whole"])  # type: ignore[index]
    two = "other" in fig
    print(f"{name}: {n} scans, dynslam2d run's scan loop, thread CPU, median / mean"
          + (" (other → this, ratio)" if two else ""))
    for part in (*PARTS, "outside process", "scans/s", "end"):
        unit = {"whole": "ms", "process": "ms", "scans/s": "", "end": "ms once"}.get(part, "µs")
        label = f"{part} ({unit})" if unit else part
        t = fig["this"][part]
        if part in ("scans/s", "end"):
            row = (f"{fig['other'][part][0]:9.3f} → {t[0]:9.3f} (×{t[0] / fig['other'][part][0]:.3f})" if two
                   else f"{t[0]:9.3f}")
        elif two:
            o = fig["other"][part]
            row = "   ".join(f"{a:9.3f} → {b:9.3f} (×{b / a:.3f})" if a else f"{a:9.3f} → {b:9.3f}"
                           for a, b in zip(o, t))
        else:
            row = f"{t[0]:9.3f} / {t[1]:9.3f}"
        print(f"  {label:<24} {row}")
    sys.stdout.flush()
    return fig


def markdown(rows: list[tuple[str, dict[str, tuple[float, float]]]], argv: list[str]) -> None:
    """This checkout's figures as README rows, the command and the machine's load."""
    print()
    print(f"`{' '.join(['python', 'benchmarks/bench_run_loop.py', *argv])}` (load average "
          f"{' / '.join(f'{x:.1f}' for x in os.getloadavg())}; thread CPU; `dynslam2d run`'s whole scan loop: "
          "`process`, records, clean-up recorder, removed-points collector, checkpointer)")
    print()
    print("| input | whole scan, median ms | mean ms | scans/s (1 / mean) | `process` median ms | records µs "
          "| clean-up recorder µs (median / mean) | collector µs (median / mean) | end of run ms |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, f in rows:
        print(f"| {name} | {f['whole'][0]:.3f} | {f['whole'][1]:.3f} | {f['scans/s'][0]:.0f} | {f['process'][0]:.3f} "
              f"| {f['records'][0]:.1f} | {f['clean-up recorder'][0]:.1f} / {f['clean-up recorder'][1]:.1f} "
              f"| {f['collector'][0]:.1f} / {f['collector'][1]:.1f} | {f['end'][0]:.0f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or another built-in scene (sim:NAME)")
    ap.add_argument("--this", type=Path, default=REPO / "src",
                    help="the src/ of the side named 'this' (default: this script's checkout); with --other the "
                         "second role of a lockstep whose other checkout has no copy of this script")
    ap.add_argument("--other", type=Path, default=None, help="the other checkout's src/: lockstep A/B")
    ap.add_argument("--reps", type=int, default=1, help="runs per input (pooled)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--markdown", action="store_true", help="also print README rows of this checkout")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    for name in args.inputs:
        if name not in INPUTS and not name.startswith("sim:"):
            ap.error(f"unknown input {name!r}")
    if args.worker:
        worker(args.data, args.inputs[0])
        return
    sides = {"this": args.this.resolve()}
    if args.other is not None:
        sides = {"other": args.other.resolve(), **sides}
    rows = []
    for name in args.inputs:
        rows.append((name, report(name, measure(name, sides, args.data, args.reps))["this"]))
    if args.markdown:
        markdown(rows, sys.argv[1:])


if __name__ == "__main__":
    main()
