"""Replay the loop closer on a recorded front end: loop settings tried in seconds instead of a full run.

``record`` runs ``dynslam2d run LOG ARGS...`` in this process and stores what the pipeline gave the loop
closer (every ``LoopCloser.add`` / ``drop_beams`` call, the slam and loop configs, the front end's final
log-odds map for the map check) in a pickle; ``replay`` feeds that to a new ``LoopCloser`` with ``loop:``
settings changed (``KEY=VALUE``), finishes it, applies the map check as the pipeline does and scores the
trajectory against a relations file. With the recorded settings the replay gives the run's own relations
(docs/slam.md, "Intel: where the error is")::

    python benchmarks/replay_loops.py record /tmp/intel/rec.pkl ../shared/data/intel/intel-lab.flirtlib.log --odom none
    python benchmarks/replay_loops.py replay /tmp/intel/rec.pkl ../shared/data/intel/intel.relations --tol 0.05 \
        [KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import pickle
import runpy
import sys
import tempfile
import time

import numpy as np


def record(out: str, argv: list[str]) -> None:
    """Run ``dynslam2d run`` with ``argv`` and pickle the loop closer's inputs to ``out``."""
    import dynslam2d.pipeline as pl
    from dynslam2d.slam import loops as lp

    rec: dict[str, object] = {"calls": [], "front_logodds": None}
    orig_init, orig_add, orig_drop, orig_keep = (lp.LoopCloser.__init__, lp.LoopCloser.add,
                                                lp.LoopCloser.drop_beams, pl.keep_optimised)

    def init(self, config=None, slam=None):  # noqa: ANN001
        orig_init(self, config, slam)
        rec["loop"], rec["slam"] = self.config, self.slam

    def add(self, stamp, pose, scan, removed, keyframe, weak=False, score=float("nan")):  # noqa: ANN001
        rec["calls"].append(("add", (stamp, pose, scan, np.array(removed, copy=True), keyframe, weak, score)))
        orig_add(self, stamp, pose, scan, removed, keyframe, weak, score)

    def drop(self, items):  # noqa: ANN001
        rec["calls"].append(("drop", ([(i, np.array(b, copy=True)) for i, b in items],)))
        return orig_drop(self, items)

    def keep(loop, front, opt, config):  # noqa: ANN001
        rec["front_logodds"] = np.array(front, copy=True)
        return orig_keep(loop, front, opt, config)

    lp.LoopCloser.__init__, lp.LoopCloser.add, lp.LoopCloser.drop_beams = init, add, drop
    pl.keep_optimised = keep
    with tempfile.TemporaryDirectory() as tmp:
        sys.argv = ["dynslam2d", "run", *argv, "--out", tmp, "--force", "-q"]
        try:
            runpy.run_module("dynslam2d", run_name="__main__")
        except SystemExit as e:
            if e.code:
                raise
    with open(out, "wb") as f:
        pickle.dump(rec, f, protocol=pickle.HIGHEST_PROTOCOL)


def replay(path: str, relations: str, tol: float, settings: list[str]) -> dict[str, object]:
    """Replay the recording at ``path`` with ``loop:`` ``settings`` (KEY=VALUE) and score it."""
    import yaml

    from dynslam2d.eval.relations import relation_errors_from
    from dynslam2d.io.relations import read_relations
    from dynslam2d.pipeline import keep_optimised, render_map
    from dynslam2d.slam.loops import LoopCloser
    from dynslam2d.trajectory import Trajectory

    with open(path, "rb") as f:
        rec = pickle.load(f)
    over = {kv.split("=", 1)[0]: yaml.safe_load(kv.split("=", 1)[1]) for kv in settings}
    cfg = rec["loop"].model_copy(update=over)
    cfg = type(cfg).model_validate(cfg.model_dump())
    t0 = time.process_time()
    lc = LoopCloser(cfg, rec["slam"])
    stamps = []
    for kind, args in rec["calls"]:
        if kind == "add":
            stamps.append(args[0])
            lc.add(*args)
        else:
            lc.drop_beams(*args)
    res = lc.finish()
    poses = res.frontend
    if res.corrected and rec["front_logodds"] is not None:
        _grid, lo = render_map(res, rec["slam"])
        if keep_optimised(res, rec["front_logodds"], lo, cfg):
            poses = res.poses
    cpu = time.process_time() - t0
    ev = relation_errors_from(Trajectory(np.asarray(stamps), poses), read_relations(relations), tol=tol)
    keys = ("far_searches", "far_loops", "loops_accepted", "loops_active", "rematch_edges", "rematch_checked",
            "map_entropy_optimised", "map_entropy_frontend", "search_ms", "optimise_ms", "rematch_ms")
    keys += tuple(k for k in res.stats if k.startswith("second_"))
    return {"settings": settings, "trans_mean": round(ev.trans_mean, 4), "trans_std": round(ev.trans_std, 4),
            "rot_deg_mean": round(ev.rot_deg_mean, 3), "relations": ev.n_used, "kept": bool(res.corrected),
            "cpu_s": round(cpu, 1), **{k: round(float(res.stats.get(k, 0)), 1) for k in keys}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out")
    r.add_argument("run_args", nargs=argparse.REMAINDER)
    p = sub.add_parser("replay")
    p.add_argument("recording")
    p.add_argument("relations")
    p.add_argument("--tol", type=float, default=0.05)
    p.add_argument("settings", nargs="*")
    a = ap.parse_args()
    if a.cmd == "record":
        record(a.out, a.run_args)
    else:
        print(json.dumps(replay(a.recording, a.relations, a.tol, a.settings)))


if __name__ == "__main__":
    main()
