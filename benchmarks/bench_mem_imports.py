"""What a ``dynslam2d run`` imports and the resident memory each import adds (issue 13 item 3).

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_mem_imports.py INPUT [--topic T] [--json FILE] [--top 30]

Runs ``dynslam2d run INPUT --out <scratch> -q --force`` in this process with a hook around the interpreter's module
loader (``_frozen_importlib._find_and_load``): for every module loaded, the resident set size (``/proc/self/statm``)
before and after its first execution, less what the modules it imported added ("self"), and the import that
started it. Prints the RSS before the run and at its end, the self RSS by top-level package, the largest modules,
and the imports started from inside a function (lazy imports: the modules they pulled in, MiB) with the module
that ran them. ``DYNSLAM2D_KERNELS=jit`` / ``auto`` selects the kernels as for a run. RSS increments include the
shared libraries' pages touched while the module executed; a module's later use is not counted.

``--startup SRC_A SRC_B --reps N`` instead times the warm start of the same command for two checkouts, alternated
(A, B, B, A, ...), each in a fresh interpreter (``python -m dynslam2d run ...`` with ``PYTHONPATH=SRC``): wall time
from the parent's spawn to the end of the first ``Pipeline.process`` call, the child's CPU time then (user +
system), and the number of modules loaded then; medians per checkout. Not run by pytest; numbers go to
docs/speed.md (pass mem51).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import sys
import tempfile
import time

from scratch import scratch_dir

_PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mib() -> float:
    """Resident set size of this process now, MiB."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * _PAGE / 2**20


class ImportLog:
    """Per module: RSS added by its execution (self and with its imports), the importer, nesting depth."""

    def __init__(self) -> None:
        self.rows: list[dict] = []
        self._stack: list[dict] = []

    def install(self) -> None:
        import _frozen_importlib as bootstrap

        inner = bootstrap._find_and_load

        def find_and_load(name, import_):
            if name in sys.modules:
                return inner(name, import_)
            frame = sys._getframe(1)
            while frame is not None and frame.f_code.co_filename.startswith("<frozen"):
                frame = frame.f_back
            caller = frame.f_globals.get("__name__", "?") if frame is not None else "?"
            func = frame.f_code.co_name if frame is not None else "?"
            row = {"name": name, "caller": caller, "func": func, "depth": len(self._stack), "child_mib": 0.0}
            self._stack.append(row)
            r0, t0 = rss_mib(), time.perf_counter()
            try:
                return inner(name, import_)
            finally:
                self._stack.pop()
                row["cum_mib"] = rss_mib() - r0
                row["cum_ms"] = (time.perf_counter() - t0) * 1e3
                row["self_mib"] = row["cum_mib"] - row["child_mib"]
                if self._stack:
                    self._stack[-1]["child_mib"] += row["cum_mib"]
                self.rows.append(row)

        bootstrap._find_and_load = find_and_load


FIRST_SCAN = r"""
import _frozen_importlib as bootstrap, json, os, resource, sys, time
spawn, report = float(sys.argv.pop(1)), sys.argv.pop(1)
inner = bootstrap._find_and_load
def first_scan_hook(name, import_):
    mod = inner(name, import_)
    if name == "dynslam2d.pipeline" and not getattr(mod.Pipeline.process, "_timed", False):
        process = mod.Pipeline.process
        def timed(self, scan):
            step = process(self, scan)
            if not os.path.exists(report):
                ru = resource.getrusage(resource.RUSAGE_SELF)
                with open(report, "w") as fh:
                    json.dump({"wall_s": time.time() - spawn, "cpu_s": ru.ru_utime + ru.ru_stime,
                               "modules": len(sys.modules)}, fh)
            return step
        timed._timed = True
        mod.Pipeline.process = timed
    return mod
bootstrap._find_and_load = first_scan_hook
import runpy
runpy.run_module("dynslam2d", run_name="__main__", alter_sys=True)
"""


def startup(inp: str, srcs: list[str], reps: int, topic: str | None) -> None:
    """Warm start to the first scan of ``dynslam2d run INPUT`` for two checkouts, alternated."""
    import statistics
    import subprocess

    got: dict[str, list[dict]] = {src: [] for src in srcs}
    with tempfile.TemporaryDirectory(prefix="bench_mem_imports_") as tmp:
        for k in range(reps):
            for src in srcs if k % 2 == 0 else srcs[::-1]:
                report = os.path.join(tmp, "first.json")
                if os.path.exists(report):
                    os.unlink(report)
                cmd = [sys.executable, "-c", FIRST_SCAN, repr(time.time()), report, "run", inp, "--out",
                       os.path.join(tmp, "out"), "-q", "--force"] + (["--topic", topic] if topic else [])
                subprocess.run(cmd, env=dict(os.environ, PYTHONPATH=src), check=True, capture_output=True)
                with open(report) as fh:
                    row = json.load(fh)
                got[src].append(row)
                print(f"rep {k} {src}: first scan done after {row['wall_s']:.3f} s wall, {row['cpu_s']:.3f} s CPU, "
                      f"{row['modules']} modules", flush=True)
    for src, rows in got.items():
        print(f"{src}: median {statistics.median(r['wall_s'] for r in rows):.3f} s wall, "
              f"{statistics.median(r['cpu_s'] for r in rows):.3f} s CPU, {rows[0]['modules']} modules")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input")
    ap.add_argument("--startup", nargs=2, metavar="SRC", default=None)
    ap.add_argument("--reps", type=int, default=6)
    ap.add_argument("--topic", default=None)
    ap.add_argument("--json", default=None, help="write every module's row here")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    if args.startup:
        startup(args.input, args.startup, args.reps, args.topic)
        return
    log = ImportLog()
    start = rss_mib()
    log.install()
    from dynslam2d.cli import main as cli_main

    out = scratch_dir("bench_mem_imports_")
    argv = ["dynslam2d", "run", args.input, "--out", out, "-q", "--force"]
    if args.topic:
        argv += ["--topic", args.topic]
    sys.argv = argv
    try:
        cli_main()
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise
    end = rss_mib()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    by_pkg: dict[str, float] = collections.defaultdict(float)
    n_pkg: dict[str, int] = collections.Counter()
    for r in log.rows:
        top = r["name"].split(".")[0]
        by_pkg[top] += r["self_mib"]
        n_pkg[top] += 1
    print(f"RSS before the imports {start:.1f} MiB, at the end {end:.1f}, peak {peak:.1f}; "
          f"{len(log.rows)} modules loaded, {sum(r['self_mib'] for r in log.rows):.1f} MiB while loading")
    print("self RSS by package (MiB, modules):")
    for pkg, mib in sorted(by_pkg.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"  {pkg:24s} {mib:6.1f}  {n_pkg[pkg]}")
    print("largest modules (self MiB, with imports MiB, ms with imports):")
    for r in sorted(log.rows, key=lambda r: -r["self_mib"])[: args.top]:
        print(f"  {r['name']:48s} {r['self_mib']:6.1f} {r['cum_mib']:6.1f} {r['cum_ms']:7.1f}")
    print("imports run inside a function (lazy), in order (with imports MiB, ms; importer):")
    for r in log.rows:
        if r["depth"] == 0 and r["func"] != "<module>" and r["cum_mib"] >= 0.3:
            print(f"  {r['name']:48s} {r['cum_mib']:6.1f} {r['cum_ms']:7.1f}  {r['caller']}.{r['func']}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"start_mib": start, "end_mib": end, "peak_mib": peak, "rows": log.rows}, fh)


if __name__ == "__main__":
    main()
