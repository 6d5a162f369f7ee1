"""Pipelines with different configurations over the same scans in lockstep, in one process (not run by pytest).

Made for clutter retirement (docs/real.md "Speed", ``tracker.structure_retire_updates`` / ``structure_birth_min``):
per input, each named configuration's tracks born, retired on structure, detections left unborn on structure,
live tracks per scan (``Tracker.n_tracks`` after each scan, mean; dormant tracks are not live), dormant tracks
per scan, tracks ever in M, and the median thread CPU ms of ``Pipeline.process`` and of ``Tracker.update``. The
pipelines process each scan alternately first. "off" (the defaults with both rules off) is always run; "on:" with
no assignment is the defaults (the rule is on by default). Before them a throw-away pipeline of each configuration
over the first 60 scans warms the kernels, then every other kernel numba's cache holds and the modules a run imports
late are loaded (``kernelwarm.preload``); the kernels loaded or compiled inside the measured run are printed (0 when
the warm-up did its work).

    taskset -c 1 python benchmarks/bench_clutter_ab.py negative_2/right,negative_2/left,negative_2/rear "on:" \
        [--scans N] [--data DIR]

Inputs: the names of ``bench_digest.py`` (paths under ``--data``) or a built-in scene (``sim:paper``); a
configuration is NAME:KEY=VALUE,….
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from kernelwarm import kernel_cache_calls, preload  # noqa: E402

from dynslam2d.config import Config, with_assignments  # noqa: E402
from dynslam2d.inputs import open_source  # noqa: E402
from dynslam2d.pipeline import Pipeline  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OFF = ["detect.tracker.structure_retire_updates=0", "detect.tracker.structure_birth_min=1.1"]
WARMUP = 60


def run(name: str, cfgs: dict[str, list[str]], data: Path = DATA, limit: int | None = None) -> list[str]:
    """One line per configuration for input ``name`` (its first ``limit`` scans where given; see the module
    docstring), then the kernels loaded or compiled inside the measured run."""
    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))[:limit]
    for a in cfgs.values():  # (the warm-up: each configuration's kernels compiled or loaded, first calls made)
        warm = Pipeline(with_assignments(Config(), a))
        for s in scans[:WARMUP]:
            warm.process(s)
    del warm
    preload()
    pipes = {n: Pipeline(with_assignments(Config(), a)) for n, a in cfgs.items()}
    upd_ms: dict[str, list[float]] = {n: [] for n in cfgs}
    for n, p in pipes.items():  # time Tracker.update inside Pipeline.process
        def timed(*args, _u=p.tracker.update, _l=upd_ms[n], **kw):
            t0 = time.thread_time_ns()
            r = _u(*args, **kw)
            _l.append((time.thread_time_ns() - t0) / 1e6)
            return r
        p.tracker.update = timed
    tot: dict[str, list[float]] = {n: [] for n in cfgs}
    live = dict.fromkeys(cfgs, 0)
    dormant = dict.fromkeys(cfgs, 0)
    in_m: dict[str, set[int]] = {n: set() for n in cfgs}
    looked = kernel_cache_calls()
    for i, scan in enumerate(scans):
        for n in (list(cfgs) if i % 2 == 0 else list(reversed(cfgs))):
            p = pipes[n]
            t0 = time.thread_time_ns()
            r = p.process(scan)
            tot[n].append((time.thread_time_ns() - t0) / 1e6)
            live[n] += p.tracker.n_tracks
            dormant[n] += len(p.tracker._dormant)
            in_m[n] |= {t.id for t in r.tracks if t.in_m}
    loads = kernel_cache_calls() - looked
    out = []
    for n, p in pipes.items():
        st = p.tracker.stats
        out.append(f"{name:18s} {n:8s} born {st.tracks_born:5d} retired {st.deleted_structure:4d} unborn "
                   f"{st.unborn_structure:5d} live/scan {live[n] / len(scans):5.1f} dormant/scan "
                   f"{dormant[n] / len(scans):4.1f} inM {len(in_m[n]):3d}  "
                   f"pipe {statistics.median(tot[n]):.3f} ms  track {statistics.median(upd_ms[n]):.3f} ms")
    out.append(f"{name:18s} inside the measured run kernels loaded or compiled: {loads}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", help="comma-separated input names")
    ap.add_argument("configs", nargs="*", help="NAME:KEY=VALUE,… (\"off\" is always run)")
    ap.add_argument("--scans", type=int, default=None, help="only the first N scans of each input")
    ap.add_argument("--data", type=Path, default=DATA)
    args = ap.parse_args()
    cfgs = {"off": OFF}
    for spec in args.configs:
        n, _, rest = spec.partition(":")
        cfgs[n] = [a for a in rest.split(",") if a]
    for name in args.inputs.split(","):
        print("\n".join(run(name, cfgs, args.data, args.scans)), flush=True)


if __name__ == "__main__":
    main()
