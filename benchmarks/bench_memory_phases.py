"""Resident memory of one ``dynslam2d run`` by phase (issue 13 item 3): RSS sampled every 10 ms in the run's
own process, with marks at the imports, the run loop, the loop closure's finish and re-render, the written map's
render, the clean-up pass, the results (their grey maps) and the figures (map.png, tracks.png); prints the peak of
every phase, the process's ``ru_maxrss`` and the run loop's exact peak (``VmHWM`` when the loop ends).

    PYTHONPATH=src python benchmarks/bench_memory_phases.py ../shared/data/mit-csail/mit-csail.clf

Run it with a warm numba cache (a compile inside the loop adds LLVM's memory to the loop's phase).
Not run by pytest; numbers go to docs/speed.md with this command.
"""

from __future__ import annotations

import functools
import importlib
import os
import resource
import sys
import threading
import time

from scratch import keep_requested, scratch_dir

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mib() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE / 2**20


def hwm_mib() -> float:
    """The process's exact peak RSS so far (``VmHWM``: a transient shorter than the 10 ms sampling counts too)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return 0.0


class Phases:
    """The current phase's name and every phase's peak RSS (a sampling thread)."""

    def __init__(self) -> None:
        self.current = "imports"
        self.peak: dict[str, float] = {}
        #: the exact peak RSS so far (VmHWM) when each phase was first left (pass mem63: the run loop's true peak,
        #: the 10 ms sampling misses its short transients, e.g. a map level's growth)
        self.hwm_left: dict[str, float] = {}
        self.lock = threading.Lock()
        threading.Thread(target=self._sample, daemon=True).start()

    def mark(self, name: str) -> None:
        with self.lock:
            if name != self.current:
                self.hwm_left.setdefault(self.current, hwm_mib())
            self.current = name
            r = rss_mib()
            self.peak[name] = max(self.peak.get(name, 0.0), r)

    def _sample(self) -> None:
        while True:
            r = rss_mib()
            with self.lock:
                self.peak[self.current] = max(self.peak.get(self.current, 0.0), r)
            time.sleep(0.01)


def wrap(phases: Phases, module: str, attr: str, label: str, after: str | None) -> None:
    """Mark ``label`` when ``module.attr`` (``Class.method`` allowed) starts and ``after`` when it returns (None: the
    phase it started in)."""
    owner = importlib.import_module(module)
    *path, name = attr.split(".")
    for p in path:
        owner = getattr(owner, p)
    fn = getattr(owner, name)

    @functools.wraps(fn)
    def marked(*a, **k):
        before = phases.current
        phases.mark(label)
        try:
            return fn(*a, **k)
        finally:
            phases.mark(before if after is None else after)

    setattr(owner, name, marked)


def main() -> None:
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    phases = Phases()
    import dynslam2d.cli
    import dynslam2d.pipeline as P

    phases.mark("after imports")
    first = P.Pipeline.process

    @functools.wraps(first)
    def process(self, scan):  # the loop starts with the first scan (kernels load then)
        if phases.current == "after imports":
            phases.mark("run loop")
        return first(self, scan)

    P.Pipeline.process = process
    wrap(phases, "dynslam2d.slam.loops", "LoopCloser.finish", "loop closure: optimise", "after the optimisation")
    render = P.render_map

    @functools.wraps(render)
    def render_map(*a, **k):  # the optimised poses' re-render; inside render_written_map its own phase stays
        if phases.current.startswith("written"):
            return render(*a, **k)
        phases.mark("loop closure: re-render")
        try:
            return render(*a, **k)
        finally:
            phases.mark("after the re-render")

    P.render_map = render_map
    wrap(phases, "dynslam2d.slam.cleanup", "CleanupRecorder.on_finish", "clean-up pass", "after the clean-up pass")
    wrap(phases, "dynslam2d.pipeline", "render_written_map", "written-map render", "after the written-map render")
    wrap(phases, "dynslam2d.results", "write_outputs", "results files", "end")
    wrap(phases, "dynslam2d.results", "figure_maps", "results: grey maps", "results files")
    wrap(phases, "dynslam2d.results", "write_figures", "figures", "results files after the figures")
    # inside the results files (pass mem48): the map files, the summary, the grey indices made outside figure_maps
    wrap(phases, "dynslam2d.results", "write_map", "results: map files", None)
    wrap(phases, "dynslam2d.pipeline", "RunResult.summary", "results: summary", None)
    wrap(phases, "dynslam2d.results", "tracks_csv", "results: tracks.csv", None)
    wrap(phases, "dynslam2d.viz.figures", "plot_map", "figures: map.png", "figures")
    wrap(phases, "dynslam2d.viz.figures", "plot_tracks", "figures: tracks.png", "figures")
    out = scratch_dir("bench-memory-phases-")
    sys.argv = ["dynslam2d", "run", sys.argv[1], "--out", out + "/run", "-q", *sys.argv[2:]]
    try:
        dynslam2d.cli.main()
    except SystemExit:
        pass
    phases.mark("end")
    for name, mib in phases.peak.items():
        print(f"{name:<28} peak RSS {mib:7.1f} MiB")
    print(f"{'process ru_maxrss':<28} {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.1f} MiB")
    if "run loop" in phases.hwm_left:  # (exact: the imports' and the loop's peak, the loop's in practice)
        print(f"{'run loop (VmHWM at its end)':<28} {phases.hwm_left['run loop']:7.1f} MiB")
    print(f"outputs in {out}/run" + ("" if keep_requested() else " (removed at exit: BENCH_KEEP_SCRATCH=1 keeps them)"))


if __name__ == "__main__":
    main()
