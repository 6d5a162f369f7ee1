"""Replay a run's map updates (``MultiResMap.integrate`` calls) into a fresh map, two checkouts alternately (not run
by pytest).

``--record``: run this checkout's pipeline over an input and keep every call of the front end's
``MultiResMap.integrate`` (pose, returns, clearing ends; laser frame) and the map's settings in a pickle. Then, per
repetition, each checkout (``PYTHONPATH`` this ``src`` / ``--other``) replays the calls in a subprocess of its own,
the checkouts alternately: a fresh ``MultiResMap`` with the pipeline's settings gets every call, in order, timed in
thread CPU time (µs per call: the whole ``integrate`` and the ray kernel ``integrate_levels`` inside it, which since
pass map15 also computes the rays' ends and checks the levels' bounds), optionally
with ``--evict MB`` of memory written between two calls (the stages that run between two map updates in the
pipeline push the levels out of the caches; ``--evict 0`` replays warm). Printed: median and mean µs per call of
each checkout over ``--sweeps`` sweeps per repetition (the first sweep of a worker, which compiles, is not
counted), their ratios, and whether the levels after a sweep (log-odds, probability cache, update indices, offsets)
are byte-identical between the checkouts.

    taskset -c 0 python benchmarks/bench_map_replay.py negative_2/right --other /tmp/base/src --reps 2 --evict 8

``--inproc``: instead, one process replays the calls into a map of each checkout (the other checkout's
``slam/grid.py`` and ``slam/raycast.py`` loaded as modules of their own), call by call alternately (which goes
first alternates), ``--sweeps`` timed sweeps after one untimed; prints the median µs per call of each, the median of
the per-call ratios and whether the levels are identical. Per-call pairs on the same core a few µs apart: less
noisy than the subprocess replay on a loaded machine.

    taskset -c 0 python benchmarks/bench_map_replay.py negative_2/right --other /tmp/base/src --inproc --evict 8

The ledger's erasure, which writes into the map between two updates in the pipeline, is not replayed: the cells
and values differ from the pipeline's, the work per call is the same kind.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402


def record(data: Path, name: str, out: Path) -> None:
    """Run the pipeline over ``name`` and pickle its map settings and every ``MultiResMap.integrate`` call."""
    import numpy as np

    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    rel, topic = INPUTS[name]
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    pipe = Pipeline()
    m = pipe.slam.map
    calls = []
    f = m.integrate

    def keep(pose, hits, clear=None):
        calls.append((float(pose.x), float(pose.y), float(pose.theta), np.array(hits, dtype=np.float64),
                      None if clear is None else np.array(clear, dtype=np.float64)))
        return f(pose, hits, clear)

    m.integrate = keep
    for s in scans:
        pipe.process(s)
    c = pipe.slam.config
    settings = dict(resolution=c.map_resolution, levels=c.map_levels, l_free=c.logodds_free,
                    l_occ=c.logodds_occupied, cap=c.occupied_logodds_cap, growth_margin=c.map_growth_margin,
                    max_bytes=int(c.max_map_memory_mb * 1e6), grazing_cells=c.grazing_stop_cells,
                    min_incidence_deg=c.grazing_min_incidence_deg)
    with open(out, "wb") as fh:
        pickle.dump({"settings": settings, "calls": calls}, fh)


def replay(path: Path, sweeps: int, evict_mb: float) -> None:
    """Replay the recorded calls ``sweeps`` + 1 times into fresh maps; print one JSON line of per-call µs."""
    import time

    import numpy as np

    import dynslam2d.slam.grid as grid
    from dynslam2d.types import Pose2D

    with open(path, "rb") as fh:
        rec = pickle.load(fh)
    calls = [(Pose2D(x, y, t), h, c) for x, y, t, h, c in rec["calls"]]
    junk = np.zeros(max(int(evict_mb * 1e6) // 8, 1))
    acc = [0]
    kern = grid.integrate_levels

    def timed(*a):
        t0 = time.thread_time_ns()
        r = kern(*a)
        acc[0] += time.thread_time_ns() - t0
        return r

    grid.integrate_levels = timed
    whole: list[float] = []
    kernel: list[float] = []
    digest = ""
    for sweep in range(sweeps + 1):
        m = grid.MultiResMap(**rec["settings"])
        for pose, h, c in calls:
            if evict_mb > 0:
                junk += 1.0
            acc[0] = 0
            t0 = time.thread_time_ns()
            m.integrate(pose, h, c)
            t = time.thread_time_ns() - t0
            if sweep:
                whole.append(t / 1e3)
                kernel.append(acc[0] / 1e3)
        d = hashlib.sha1()
        for lv in m.levels:
            for a in (lv.logodds, lv.prob, lv.uidx):
                d.update(np.ascontiguousarray(a).tobytes())
            d.update(repr((lv.i0, lv.j0, lv.shape, lv.update_counter)).encode())
        digest = d.hexdigest()
    print(json.dumps({"whole": whole, "kernel": kernel, "digest": digest}), flush=True)


def inproc(path: Path, other: Path, sweeps: int, evict_mb: float) -> None:
    """Replay the recorded calls into a map of each checkout in this process, call by call alternately; print the
    median µs per call of each, the median per-call ratio (this / other) and whether the levels are identical."""
    import importlib.util
    import statistics
    import time

    import numpy as np

    import dynslam2d.slam.grid as this_grid
    from dynslam2d.types import Pose2D

    def load(rel: str, name: str):
        spec = importlib.util.spec_from_file_location(name, other / "dynslam2d" / rel)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
        return mod

    other_rays = load("slam/raycast.py", "other_raycast")
    this_rays = sys.modules["dynslam2d.slam.raycast"]
    sys.modules["dynslam2d.slam.raycast"] = other_rays  # (the other grid.py imports the other kernel's names)
    try:
        other_grid = load("slam/grid.py", "other_grid")
    finally:
        sys.modules["dynslam2d.slam.raycast"] = this_rays
    for k in ("integrate_levels", "integrate_rays", "integrate_rays_stop", "ray_ends", "new_prob_memo"):
        if hasattr(other_rays, k):
            setattr(other_grid, k, getattr(other_rays, k))
    other_memo = other_rays.new_prob_memo() if hasattr(other_rays, "new_prob_memo") else None  # (before map30)
    with open(path, "rb") as fh:
        rec = pickle.load(fh)
    calls = [(Pose2D(x, y, t), h, c) for x, y, t, h, c in rec["calls"]]
    junk = np.zeros(max(int(evict_mb * 1e6) // 8, 1))
    res: dict[str, list[float]] = {"other": [], "this": []}
    maps = {}
    for sweep in range(sweeps + 1):
        maps = {"other": other_grid.MultiResMap(**rec["settings"]), "this": this_grid.MultiResMap(**rec["settings"])}
        if other_memo is not None:
            maps["other"]._memo = other_memo  # (the other checkout's memo arrays, as its module would give)
        for i, (pose, h, c) in enumerate(calls):
            for tag in (("other", "this") if (i + sweep) % 2 == 0 else ("this", "other")):
                if evict_mb > 0:
                    junk += 1.0
                t0 = time.thread_time_ns()
                maps[tag].integrate(pose, h, c)
                t = time.thread_time_ns() - t0
                if sweep:
                    res[tag].append(t / 1e3)
    same = all(np.array_equal(a.logodds, b.logodds) and np.array_equal(a.prob, b.prob)
               and np.array_equal(a.uidx, b.uidx) and (a.i0, a.j0, a.update_counter) == (b.i0, b.j0, b.update_counter)
               for a, b in zip(maps["other"].levels, maps["this"].levels))
    o, t = res["other"], res["this"]
    ratio = statistics.median([b / a for a, b in zip(o, t)])
    print(f"  in one process, {sweeps} sweeps, evict {evict_mb} MB: whole µs per call, median other "
          f"{statistics.median(o):7.1f} this {statistics.median(t):7.1f}; median per-call ratio ×{ratio:.3f}; "
          f"levels identical: {same}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", choices=sorted(INPUTS))
    ap.add_argument("--other", type=Path, default=REPO.parent / "main" / "src", help="the other checkout's src/")
    ap.add_argument("--reps", type=int, default=2, help="alternations of the two checkouts")
    ap.add_argument("--sweeps", type=int, default=3, help="timed sweeps over the calls per worker")
    ap.add_argument("--evict", type=float, default=8.0, help="MB written between two calls (0: warm replay)")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--cache", type=Path, default=Path("/tmp"), help="where the recorded calls are kept")
    ap.add_argument("--rerecord", action="store_true", help="record the calls again even if a recording exists")
    ap.add_argument("--inproc", action="store_true", help="both checkouts in one process, call by call alternately")
    ap.add_argument("--replay", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.replay is not None:
        replay(args.replay, args.sweeps, args.evict)
        return
    this = REPO / "src"
    for name in args.inputs:
        path = args.cache / f"map_replay_{name.replace('/', '_').replace(':', '_')}.pkl"
        if args.rerecord or not path.exists():
            record(args.data, name, path)
        if args.inproc:
            print(f"{name}:")
            inproc(path, args.other.resolve(), args.sweeps, args.evict)
            continue
        res: dict[str, dict[str, list[float]]] = {k: {"whole": [], "kernel": []} for k in ("other", "this")}
        digests: dict[str, set[str]] = {"other": set(), "this": set()}
        for rep in range(args.reps):
            order = (("other", args.other), ("this", this)) if rep % 2 == 0 else (("this", this), ("other", args.other))
            for tag, src in order:
                env = dict(os.environ, PYTHONPATH=str(src))
                out = subprocess.run([sys.executable, __file__, name, "--replay", str(path), "--sweeps",
                                      str(args.sweeps), "--evict", str(args.evict)], env=env, check=True,
                                     capture_output=True, text=True).stdout
                r = json.loads(out.strip().splitlines()[-1])
                res[tag]["whole"] += r["whole"]
                res[tag]["kernel"] += r["kernel"]
                digests[tag].add(r["digest"])
        same = digests["other"] == digests["this"] and len(digests["this"]) == 1
        n = len(res["this"]["whole"]) // max(args.reps * args.sweeps, 1)
        print(f"{name}: {n} map updates, {args.reps} × {args.sweeps} sweeps per checkout, evict {args.evict} MB; "
              f"levels identical: {same}")
        for part in ("whole", "kernel"):
            o, t = res["other"][part], res["this"][part]
            mo, mt = statistics.median(o), statistics.median(t)
            ao, at = statistics.fmean(o), statistics.fmean(t)
            print(f"  {part:<7} µs per call, median other {mo:7.1f} this {mt:7.1f} (×{mt / mo:.3f}); "
                  f"mean other {ao:7.1f} this {at:7.1f} (×{at / ao:.3f})")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
