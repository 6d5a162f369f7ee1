"""Which far loop searches pay: far-search settings swept over the real recordings and simulated scenes (a study,
not run by pytest; docs/speed.md, pass far42).

Two parts:

``sweep``: one ``dynslam2d run`` per (input, policy) with the policy's ``--set loop.…`` overrides, into
``<out>/<policy>/<input>``; per run the loop closer's counters (``summary.json``: far searches, far candidates, far
loops, loops accepted / active, second-search searches and loops), the loop edges of ``graph.g2o`` (edges between
keyframes that are not consecutive) that the default policy has and this one lacks, the largest position
difference of ``trajectory.tum`` against the default policy's (0 = the same trajectory), the ATE (simulated
scenes: ``metrics.json``) and MIT CSAIL's relation error (``dynslam2d eval relations``). An input whose default
run does no far search and no second search runs only the default policy (the settings swept are then never read
in a way that could change anything: ``far_after`` and ``far_searches`` only gate the far search)::

    taskset -c 1 python benchmarks/study_far_searches.py sweep --data <data> --out <scratch> [--only negative_2 ...]

``time``: the ``loops`` stage's mean per scan under each policy, in process (thread CPU of ``LoopCloser.add``,
all scans; one fresh pipeline per run after a throw-away warm-up; policies alternated round by round), and whether
the final keyframe poses equal the first policy's::

    taskset -c 1 python benchmarks/study_far_searches.py time --data <data> --rounds 3 [--only negative_2 ...]

``ranks``: every far search of a default run in process, with the place-descriptor distance of the submap
searched and whether it returned a pose, passed the jump check and was accepted::

    taskset -c 1 python benchmarks/study_far_searches.py ranks --data <data> --only negative_2 mit-csail intel \
        [--policies cap=off]

The default policy's settings: ``loop.far_after=20``, ``loop.far_searches=4``, ``loop.far_max_place_distance=0.66``,
``loop.far_best_place_distance=0.74`` (slam/loopconfig.py; ``cap=off`` = the far search before pass far43).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

#: policy name → overrides (dotted config keys)
POLICIES: dict[str, dict[str, object]] = {
    "default": {},
    # the place-distance caps of the run's far search (pass far43; default 0.66, the best-ranked submap 0.74): off, and
    # the single absolute cap of pass far42's study
    "cap=off": {"loop.far_max_place_distance": 2.0},
    "cap=0.70": {"loop.far_max_place_distance": 0.70, "loop.far_best_place_distance": 0.70},
    "far_after=40": {"loop.far_after": 40.0},
    "far_after=inf": {"loop.far_after": 1.0e9},  # no far search during the run (the second search stays)
    "far_searches=2": {"loop.far_searches": 2},
    "far_searches=1": {"loop.far_searches": 1},
    "far_search=off": {"loop.far_search": False},  # neither during the run nor the second search
}

#: input name → (path relative to the data folder or sim:…, extra run options)
INPUTS: dict[str, tuple[str, list[str]]] = {
    "negative_2/right": ("dynamic/leg_tracker/negative_2.bag", ["--topic", "/right_scan"]),
    "negative_2/rear": ("dynamic/leg_tracker/negative_2.bag", ["--topic", "/rear_scan"]),
    "negative_2/left": ("dynamic/leg_tracker/negative_2.bag", ["--topic", "/left_scan"]),
    "positive_1": ("dynamic/leg_tracker/positive_1.bag", []),
    "positive_7": ("dynamic/leg_tracker/positive_7.bag", []),
    "demo_stationary": ("dynamic/leg_tracker/demo_stationary_simple_environment.bag", []),
    "person_following_outdoor_1": ("dynamic/leg_tracker/person_following_outdoor_1.bag.zip", []),
    "datmo/intersection": ("dynamic/datmo/intersection.bag", []),
    "datmo/overtake_ego": ("dynamic/datmo/overtake_ego.bag", []),
    "datmo/overtake_red": ("dynamic/datmo/overtake_red.bag", []),
    "datmo/overtakes": ("dynamic/datmo/overtakes.bag", []),
    "datmo/parallel": ("dynamic/datmo/parallel.bag", []),
    "datmo/two_robots": ("dynamic/datmo/two_robots.bag", []),
    "mit-csail": ("mit-csail/mit-csail.clf", ["--odom", "none"]),
    "intel": ("intel/intel-lab.flirtlib.log", ["--odom", "none"]),
    "fr079": ("fr079/freiburg-079-corrected.log.gz", ["--odom", "none"]),
    "sim:paper": ("sim:paper", []),
    "sim:crowd": ("sim:crowd", []),
    "sim:corridor": ("sim:corridor", []),
    "sim:drive-11": ("sim:drive", ["--seed", "11"]),
    "sim:drive-12": ("sim:drive", ["--seed", "12"]),
    "sim:drive-13": ("sim:drive", ["--seed", "13"]),
}

#: input name → (relations file, extra ``eval relations`` options; {data} = the data folder), as bench_loops.py
RELATIONS: dict[str, tuple[str, list[str]]] = {
    "mit-csail": ("mit-csail/mit-csail.relations", []),
    "intel": ("intel/intel.relations", ["--tol", "0.05"]),
    "fr079": ("fr079/fr079.relations", ["--clock", "{data}/fr079/fr079.flirtlib.log", "--tol", "0.1"]),
}


def _sets(policy: str) -> list[str]:
    out: list[str] = []
    for k, v in POLICIES[policy].items():
        out += ["--set", f"{k}={str(v).lower() if isinstance(v, bool) else v}"]
    return out


def _loop_edges(g2o: Path) -> set[tuple[int, int]]:
    """The graph's loop edges (keyframe pairs that are not consecutive)."""
    edges = set()
    if not g2o.exists():
        return edges
    for line in g2o.read_text().splitlines():
        f = line.split()
        if f and f[0].startswith("EDGE"):
            i, j = int(f[1]), int(f[2])
            if abs(j - i) != 1:
                edges.add((min(i, j), max(i, j)))
    return edges


def _tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, comments="#", ndmin=2)


def _run_one(data: Path, name: str, policy: str, out: Path) -> dict[str, object]:
    rel, opts = INPUTS[name]
    src = rel if rel.startswith("sim:") else str(data / rel)
    d = out / policy.replace("=", "_") / name.replace("/", "_").replace(":", "_")
    d.parent.mkdir(parents=True, exist_ok=True)
    cmd = ["dynslam2d", "run", src, *opts, "--out", str(d), "--filter", "box", "--quiet", "--force", *_sets(policy)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        cmd.remove("--force")  # (an older CLI without --force: the folder is fresh anyway)
        p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        return {"input": name, "policy": policy, "error": p.stderr[-500:]}
    summ = json.loads((d / "summary.json").read_text())
    lc = summ.get("loop_closure", {})
    r: dict[str, object] = {"input": name, "policy": policy, "dir": str(d), "wall_s": round(wall, 1),
                            "scans": summ.get("scans")}
    for k in ("keyframes", "far_searches", "far_skipped", "far_candidates", "far_loops", "loops_accepted",
              "loops_active", "second_searches", "second_loops", "corrected"):
        r[k] = lc.get(k)
    m = d / "metrics.json"
    if m.exists():
        r["ate_m"] = json.loads(m.read_text()).get("ate_rmse_m")
    if name in RELATIONS:
        rf, ro = RELATIONS[name]
        q = subprocess.run(["dynslam2d", "eval", "relations", str(d), str(data / rf),
                            *[o.format(data=data) for o in ro], "--json"], capture_output=True, text=True)
        if q.returncode == 0:
            e = json.loads(q.stdout)
            r["relations"] = {k: v for k, v in e.items() if "trans" in k or "rot" in k or "used" in k}
    return r


def _compare(base: dict[str, object], r: dict[str, object]) -> None:
    """Loop edges lost / gained and the trajectory's largest position difference against the default policy."""
    bd, d = Path(str(base["dir"])), Path(str(r["dir"]))
    be, e = _loop_edges(bd / "graph.g2o"), _loop_edges(d / "graph.g2o")
    r["loop_edges"] = len(e)
    r["edges_lost"] = sorted(be - e)
    r["edges_gained"] = len(e - be)
    a, b = _tum(bd / "trajectory.tum"), _tum(d / "trajectory.tum")
    if a.shape == b.shape:
        r["traj_max_dxy_m"] = float(np.max(np.hypot(a[:, 1] - b[:, 1], a[:, 2] - b[:, 2]))) if a.size else 0.0
        r["traj_identical"] = bool(np.array_equal(a, b))
        mb, m = bd / "map.pgm", d / "map.pgm"
        r["map_identical"] = mb.exists() and m.exists() and mb.read_bytes() == m.read_bytes()
    else:
        r["traj_max_dxy_m"] = None
        r["traj_identical"] = False


def sweep(args: argparse.Namespace) -> None:
    out = Path(args.out)
    names = [n for n in INPUTS if not args.only or any(o in n for o in args.only)]
    rows = []
    for name in names:
        base = _run_one(args.data, name, "default", out)
        rows.append(base)
        print(json.dumps(base), flush=True)
        if "error" in base:
            continue
        base["edges_lost"], base["loop_edges"] = [], len(_loop_edges(Path(str(base["dir"])) / "graph.g2o"))
        if not base.get("far_searches") and not base.get("second_searches") and not args.all:
            continue
        for pol in POLICIES:
            if pol == "default" or (args.policies and pol not in args.policies):
                continue
            r = _run_one(args.data, name, pol, out)
            if "error" not in r:
                _compare(base, r)
            rows.append(r)
            print(json.dumps(r), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


def _config(policy: str):  # noqa: ANN202
    from dynslam2d.config import Config, config_from_dict, set_key

    data = Config().model_dump()
    set_key(data, "filter.mode", "box")
    for k, v in POLICIES.get(policy, {}).items():
        set_key(data, k, v)
    return config_from_dict(data, origin=policy)


def _timed_run(scans: list, policy: str) -> tuple[float, float, dict[str, float], np.ndarray]:
    """One fresh pipeline: (loops stage mean µs a scan in thread CPU, whole loop CPU ms a scan, far counters,
    the keyframes' optimised poses after ``finish``)."""
    from dynslam2d.pipeline import Pipeline
    from dynslam2d.slam.loops import LoopCloser

    acc = [0]
    add = LoopCloser.add

    def timed(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        t0 = time.thread_time_ns()
        try:
            return add(self, *a, **k)
        finally:
            acc[0] += time.thread_time_ns() - t0

    LoopCloser.add = timed
    try:
        pipe = Pipeline(_config(policy))
        c0 = time.thread_time()
        for s in scans:
            pipe.process(s)
        cpu = (time.thread_time() - c0) * 1e3 / len(scans)
        st = dict(pipe.loops.stats)
        nodes = pipe.loops.finish().node_poses.copy()
    finally:
        LoopCloser.add = add
    out = {k: st.get(k, 0) for k in ("far_searches", "far_skipped", "far_loops", "loops_accepted")}
    return acc[0] / 1e3 / len(scans), cpu, out, nodes


def timing(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_pipeline import warm_up

    pols = args.policies or list(POLICIES)
    names = [n for n in INPUTS if not args.only or any(o in n for o in args.only)]
    for name in names:
        scans = _open(args.data, name)
        warm_up(scans)
        res: dict[str, list[tuple[float, float]]] = {p: [] for p in pols}
        counts: dict[str, dict[str, float]] = {}
        same: dict[str, str] = {}
        ref = None
        for _ in range(args.rounds):
            for p in pols:
                lo, cpu, counts[p], nodes = _timed_run(scans, p)
                res[p].append((lo, cpu))
                ref = nodes if ref is None else ref
                if p not in same:
                    same[p] = ("identical" if np.array_equal(nodes, ref) else
                               f"max {np.max(np.hypot(*(nodes - ref)[:, :2].T)):.3f} m" if nodes.shape == ref.shape
                               else "other shape")
        print(f"== {name}: {len(scans)} scans, {args.rounds} rounds (medians; µs / ms a scan, thread CPU)")
        b = statistics.median(x[0] for x in res[pols[0]])
        bc = statistics.median(x[1] for x in res[pols[0]])
        for p in pols:
            lo = statistics.median(x[0] for x in res[p])
            cpu = statistics.median(x[1] for x in res[p])
            print(f"  {p:<16} loops mean {lo:7.1f} µs (×{lo / b:.2f})  pipeline CPU {cpu:.3f} ms (×{cpu / bc:.3f})  "
                  f"runs {' '.join(f'{x[0]:.0f}' for x in res[p])}  {counts[p]}  "
                  f"keyframe poses vs {pols[0]}: {same[p]}",
                  flush=True)


def _open(data: Path, name: str) -> list:
    from dynslam2d.inputs import open_source

    rel, opts = INPUTS[name]
    kw: dict[str, object] = {}
    for i in range(0, len(opts), 2):
        kw[opts[i].lstrip("-")] = int(opts[i + 1]) if opts[i] == "--seed" else opts[i + 1]
    return list(open_source(rel if rel.startswith("sim:") else str(data / rel), **kw))


def _far_log(scans: list, policy: str = "default") -> list[dict[str, object]]:
    """One default run in process; a row per far search (:func:`ranks`)."""
    import math

    from dynslam2d.pipeline import Pipeline
    from dynslam2d.slam.loops import LoopCloser

    saved = {k: getattr(LoopCloser, k) for k in ("_place_ranks", "_match_at", "_verify_far", "_far_verified",
                                                 "_far_pick")}
    rows: list[dict[str, object]] = []
    last_rank: dict[int, float] = {}
    picked: dict[int, tuple[int, float]] = {}  # submap → (its rank among the searches picked, the first's distance)
    accepted: set[tuple[int, int]] = set()

    def far_pick(self, node, elig, count, _f=saved["_far_pick"]):  # noqa: ANN001, ANN202
        out = _f(self, node, elig, count)
        picked.clear()
        picked.update({e[2]: (i, float(elig[0][0])) for i, e in enumerate(elig[:count])})
        return out

    def place_ranks(self, node, _f=saved["_place_ranks"]):  # noqa: ANN001, ANN202
        r = _f(self, node)
        last_rank.clear()
        last_rank.update(r)
        return r

    def match_at(self, node, s, pts, pred, lin, ang, margin, *a, _f=saved["_match_at"], **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        cand = _f(self, node, s, pts, pred, lin, ang, margin, *a, **k)
        if ang == math.pi:  # a far search (every rotation)
            srt = sorted(last_rank.values())
            d = last_rank.get(s, 2.0)
            pk, best = picked.get(s, (-1, 2.0))
            rows.append({"node": node, "submap": s, "dist": d, "rank": srt.index(d) if d in srt else -1,
                         "pick": pk, "best": best, "cover": self._place_cover(node, s),
                         "next": last_rank.get(s + 1, 2.0),
                         "second": self._second is not None, "pose": cand is not None, "verify": False,
                         "accepted": False, "path": self.keyframes[node].path - self._loop_path})
        return cand

    def verify_far(self, cand, s, _f=saved["_verify_far"]):  # noqa: ANN001, ANN202
        for r in rows[::-1]:
            if r["node"] == cand.node and r["submap"] == s:
                r["verify"] = True
                break
        return _f(self, cand, s)

    def far_verified(self, cand, partners, _f=saved["_far_verified"]):  # noqa: ANN001, ANN202
        ok = _f(self, cand, partners)
        if ok:
            accepted.add((cand.node, cand.anchor // self.config.submap_keyframes))
        return ok

    LoopCloser._place_ranks, LoopCloser._match_at = place_ranks, match_at
    LoopCloser._verify_far, LoopCloser._far_verified = verify_far, far_verified
    LoopCloser._far_pick = far_pick
    try:
        pipe = Pipeline(_config(policy))
        # every place ranked, as before pass neg60 (a run ranks only the eligible submaps' places above
        # _RANK_ROWS_MIN stored places: the same values, but this study's "next" column reads other submaps')
        pipe.loops._rank_min = 1 << 62
        for sc in scans:
            pipe.process(sc)
        pipe.loops.finish()
    finally:
        for k, f in saved.items():
            setattr(LoopCloser, k, f)
    for r in rows:
        r["accepted"] = (r["node"], r["submap"]) in accepted
    return rows


def ranks(args: argparse.Namespace) -> None:
    """Each far search of the run (default policy, in process): the place-descriptor distance of the submap searched
    (``_place_ranks``: smaller = more alike; 2.0 = no descriptor) and its rank among the eligible submaps, whether
    the search returned a pose, passed the jump check, and whether it was accepted as a loop (with its partners)."""
    names = [n for n in INPUTS if not args.only or any(o in n for o in args.only)]
    for name in names:
        rows = _far_log(_open(args.data, name), args.policies[0] if args.policies else "default")
        run = [r for r in rows if not r["second"]]
        print(f"== {name}: {len(run)} far searches during the run ({len(rows) - len(run)} by the second search)")
        for lab, sel in (("returned a pose", [r for r in run if r["pose"]]),
                         ("passed the jump check", [r for r in run if r["verify"]]),
                         ("accepted", [r for r in run if r["accepted"]]),
                         ("refused", [r for r in run if not r["pose"]])):
            ds = sorted(float(r["dist"]) for r in sel)
            rk = collections_count(int(r["pick"]) for r in sel)
            gap = sorted(float(r["dist"]) - float(r["best"]) for r in sel)
            cv = sorted(min(float(r["dist"]), float(r["cover"])) for r in sel)
            print(f"  {lab:<22} {len(sel):4d}  place distance for the caps "
                  + (f"min {cv[0]:.3f} median {statistics.median(cv):.3f} max {cv[-1]:.3f}" if cv else "—")
                  + f"\n  {'':<22}       descriptor distance "
                  + (f"min {ds[0]:.3f} median {statistics.median(ds):.3f} max {ds[-1]:.3f}" if ds else "—")
                  + (f"  above the best picked: median {statistics.median(gap):.3f} max {gap[-1]:.3f}" if gap else "")
                  + f"  rank among the picked {rk}")
        for r in run:
            if r["pose"]:
                print(f"    node {r['node']} submap {r['submap']} dist {r['dist']:.3f} for the caps {r['cover']:.3f} "
                      f"(best picked {r['best']:.3f}, "
                      f"rank {r['pick']}) path since loop {r['path']:.1f} m verify {r['verify']} "
                      f"accepted {r['accepted']}")
        if args.json:
            Path(args.json).with_suffix(f".{name.replace('/', '_').replace(':', '_')}.json").write_text(
                json.dumps(rows))


def collections_count(it) -> dict[int, int]:  # noqa: ANN001
    out: dict[int, int] = {}
    for x in it:
        out[x] = out.get(x, 0) + 1
    return dict(sorted(out.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("sweep", "time", "ranks"))
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("DYNSLAM2D_DATA", "../shared/data")))
    ap.add_argument("--out", default="study_far", help="sweep: run folders go here (<scratch>)")
    ap.add_argument("--only", nargs="*", help="inputs whose name contains one of these")
    ap.add_argument("--policies", nargs="*", help="policies (default: all of POLICIES)")
    ap.add_argument("--all", action="store_true", help="sweep: every policy even where the default does no far search")
    ap.add_argument("--json", help="sweep: write the rows here")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    {"sweep": sweep, "time": timing, "ranks": ranks}[args.mode](args)


if __name__ == "__main__":
    main()
