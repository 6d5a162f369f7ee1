"""Pipelines with different configurations over the same scans in lockstep, in one process (not run by pytest).

Made for clutter retirement (docs/real.md "Speed", ``tracker.structure_retire_updates`` / ``structure_birth_min``):
per input, each named configuration's tracks born, retired on structure, detections left unborn on structure,
live tracks per scan (``Tracker.n_tracks`` after each scan, mean; dormant tracks are not live), dormant tracks
per scan, tracks ever in M, and the median thread CPU ms of ``Pipeline.process`` and of ``Tracker.update``. The
pipelines process each scan alternately first. "off" (the defaults with both rules off) is always run; "on:" with
no assignment is the defaults (the rule is on by default).

    taskset -c 1 python benchmarks/bench_clutter_ab.py negative_2/right,negative_2/left,negative_2/rear "on:"

Inputs: the names of ``bench_digest.py`` (paths under ../shared/data); a configuration is NAME:KEY=VALUE,….
"""

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402

from dynslam2d.config import Config, with_assignments  # noqa: E402
from dynslam2d.inputs import open_source  # noqa: E402
from dynslam2d.pipeline import Pipeline  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OFF = ["detect.tracker.structure_retire_updates=0", "detect.tracker.structure_birth_min=1.1"]


def run(name: str, cfgs: dict[str, list[str]]) -> list[str]:
    """One line per configuration for input ``name`` (see the module docstring)."""
    rel, topic = INPUTS[name]
    scans = list(open_source(rel if rel.startswith("sim:") else str(DATA / rel), topic))
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
    for i, scan in enumerate(scans):
        for n in (list(cfgs) if i % 2 == 0 else list(reversed(cfgs))):
            p = pipes[n]
            t0 = time.thread_time_ns()
            r = p.process(scan)
            tot[n].append((time.thread_time_ns() - t0) / 1e6)
            live[n] += p.tracker.n_tracks
            dormant[n] += len(p.tracker._dormant)
            in_m[n] |= {t.id for t in r.tracks if t.in_m}
    out = []
    for n, p in pipes.items():
        st = p.tracker.stats
        out.append(f"{name:18s} {n:8s} born {st.tracks_born:5d} retired {st.deleted_structure:4d} unborn "
                   f"{st.unborn_structure:5d} live/scan {live[n] / len(scans):5.1f} dormant/scan "
                   f"{dormant[n] / len(scans):4.1f} inM {len(in_m[n]):3d}  "
                   f"pipe {statistics.median(tot[n]):.3f} ms  track {statistics.median(upd_ms[n]):.3f} ms")
    return out


def main() -> None:
    cfgs = {"off": OFF}
    for spec in sys.argv[2:]:
        n, _, rest = spec.partition(":")
        cfgs[n] = [a for a in rest.split(",") if a]
    for name in sys.argv[1].split(","):
        print("\n".join(run(name, cfgs)), flush=True)


if __name__ == "__main__":
    main()
