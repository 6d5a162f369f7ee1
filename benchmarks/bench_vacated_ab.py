"""The vacated-footprint kernel of two checkouts, in situ and in lockstep (passes det38, dyn39; not run by pytest).

Runs this checkout's pipeline over each input; at every call of :func:`dynslam2d.vacated.vacated_scan_kernel` it
calls both this checkout's kernel and the other checkout's (``--other``: its ``vacated.py`` and
``detect/mapevidence.py``, loaded as modules of their own, so its whole kernel chain — the clearing geometry, the
seen-through walk, the outlines — is its own) on the same arguments, each with work buffers of its own, which goes
first alternating per call, timed in thread CPU time; the outputs are compared (count of seen-through cells, of
yielding outlines, and the outlines' cells) and the pipeline goes on with this checkout's. Prints per input: the
calls, how many gave identical outputs, the median µs of the first-called timings of each (the in-situ figure: caches
as the pipeline leaves them), the median of all timings, the median per-call ratio and the means.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_vacated_ab.py negative_2/left sim:paper --other <base>/src

Inputs: every name of ``bench_digest.INPUTS`` or a ``sim:`` scene name (``sim:paper``); recorded files under
``--data``. The other checkout's kernels compile into its own numba cache on the first run.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from dynslam2d.slam.cleanconfig import CleanConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from kernelwarm import preload  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def other_kernel(src: Path):
    """The other checkout's ``vacated_scan_kernel``, its ``vacated.py`` run with its ``detect/mapevidence.py`` under
    their own module names (numba's cache rebuilds a kernel's environment by module name), this checkout's modules
    put back afterwards."""
    import dynslam2d.detect.mapevidence as this_me
    import dynslam2d.vacated as this_vac

    folder = src / "dynslam2d"
    try:
        for name, path in (("dynslam2d.detect.mapevidence", folder / "detect" / "mapevidence.py"),
                           ("dynslam2d.vacated", folder / "vacated.py")):
            spec = importlib.util.spec_from_file_location(name, path)
            mod = importlib.util.module_from_spec(spec)
            sys.modules[name] = mod
            spec.loader.exec_module(mod)
        return mod.vacated_scan_kernel, mod.VacatedTrace
    finally:
        sys.modules["dynslam2d.detect.mapevidence"] = this_me
        sys.modules["dynslam2d.vacated"] = this_vac


def run(name: str, data: Path, other_src: Path, warm: int = 30) -> None:
    import dynslam2d.pipeline as pl
    import dynslam2d.vacated as vac
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    this_k = vac.vacated_scan_kernel
    other_k, other_trace = other_kernel(other_src)
    rec: list[tuple[str, int, int, bool]] = []
    own: dict = {"i": 0, "bufs": None, "res": None}

    def both(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, work, window, *more):
        # (``more``: this checkout's arguments after ``window`` — since pass vac77 the long-occupied bitmap and the
        # beams' angles; an other checkout from before takes the first 13 only)
        i = own["i"]
        own["i"] += 1
        bufs = own["bufs"]
        if bufs is None or bufs[0].shape != work.shape or own["res"] != params[0]:
            # (the other checkout's own buffers: its window's layout may differ from this one's)
            tr = other_trace(CleanConfig(), occupied_logodds=6.0, min_cells=1, max_extent=(params[9] - 0.5) * params[0],
                             min_depth_m=0.0, min_extent=1.0, min_share=0.0, scans=1)
            tr._prepare(float(params[0]), ranges.shape[0])
            bufs = own["bufs"] = (tr._work, tr._window, getattr(tr, "_fwork", None))
            own["res"] = params[0]
        got = {}
        order = ("other", "this") if i % 2 == 0 else ("this", "other")
        for tag in order:
            k, w, win = (other_k, *bufs[:2]) if tag == "other" else (this_k, work, window)
            # (an other checkout since pass vac83 takes the same extra arguments, with an ``fwork`` of its own)
            extra = more if tag == "this" else ((bufs[2], *more[1:]) if bufs[2] is not None and more else ())
            t0 = time.thread_time_ns()
            r = k(ranges, cos_a, sin_a, valid, px, py, th, logodds, i0, j0, params, w, win, *extra)
            got[tag] = (time.thread_time_ns() - t0, r)
        a, b = got["this"][1], got["other"][1]
        same = a[0] == b[0] and a[1] == b[1] and np.array_equal(a[2], b[2])
        rec.append((order[0], got["other"][0], got["this"][0], same))
        return a

    vac.vacated_scan_kernel = both
    try:
        pipe = pl.Pipeline()
        for s in scans[:warm]:
            pipe.process(s)
        preload()  # (kernels first called after the warm-up: not loaded inside the measured run)
        rec.clear()
        pipe = pl.Pipeline()
        for s in scans:
            pipe.process(s)
    finally:
        vac.vacated_scan_kernel = this_k
    med = statistics.median
    fo = med([r[1] for r in rec if r[0] == "other"]) / 1e3
    ft = med([r[2] for r in rec if r[0] == "this"]) / 1e3
    ao, at = med([r[1] for r in rec]) / 1e3, med([r[2] for r in rec]) / 1e3
    print(f"{name}: {len(rec)} calls, {sum(r[3] for r in rec)} identical; µs a call, other → this: first-called "
          f"median {fo:.1f} → {ft:.1f} (×{ft / fo:.3f}), all {ao:.1f} → {at:.1f} (×{at / ao:.3f}), median per-call "
          f"ratio ×{med([r[2] / r[1] for r in rec]):.3f}, means {sum(r[1] for r in rec) / len(rec) / 1e3:.1f} → "
          f"{sum(r[2] for r in rec) / len(rec) / 1e3:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data, args.other)


if __name__ == "__main__":
    main()
