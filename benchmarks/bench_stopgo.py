"""Track memory and retroactive erasure on simulated scenes, with and without (docs/maps.md; not run by pytest).

For each scene, two runs with the default configuration and the clean-up pass watching:
``off`` = ``detect.memory.enabled: false, erase: false`` (the behaviour before track memory)
and ``on`` = the defaults. Printed per run: ATE, ghost area and map F1 of the online and the
cleaned map, and the removed shares of ``metrics.json``'s ``removal_by_motion``: walking
movers, stopped movers (they moved before), movers with stopped ones counted as movers, the
same counting a stopped mover only once the sensor saw it walk, and static structure.

    python benchmarks/bench_stopgo.py sim:stop-and-go sim:parking [--seed N] [--memory both|on|off]
        [--set detect.segment.max_extent=5.6]
"""

from __future__ import annotations

import argparse
import time

import yaml

from dynslam2d.config import Config, config_from_dict
from dynslam2d.eval.maps import map_metrics
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import run
from dynslam2d.results import compute_metrics, ground_truth_for
from dynslam2d.slam.cleanup import CleanupRecorder
from dynslam2d.types import Pose2D


def _config(memory: bool, sets: list[str]) -> Config:
    data = Config().model_dump()
    data["detect"]["memory"]["enabled"] = memory
    data["detect"]["memory"]["erase"] = memory
    for item in sets:
        key, value = item.split("=", 1)
        node = data
        parts = key.split(".")
        for p in parts[:-1]:
            node = node[p]
        node[parts[-1]] = yaml.safe_load(value)
    return config_from_dict(data, origin="--set")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--set", action="append", default=[], help="KEY=VALUE config override (both runs)")
    ap.add_argument("--seed", type=int, default=None, help="simulator seed (default: the scene's own)")
    ap.add_argument("--memory", choices=("both", "on", "off"), default="both", help="which of the two runs")
    args = ap.parse_args()
    for inp in args.inputs:
        for memory in {"both": (False, True), "on": (True,), "off": (False,)}[args.memory]:
            src = open_source(inp, seed=args.seed)
            cfg = _config(memory, args.set)
            rec = CleanupRecorder(cfg.clean)
            t0 = time.perf_counter()
            result = run(src, cfg, observers=[rec])
            wall = time.perf_counter() - t0
            gt = ground_truth_for(src, None, cfg.slam.map_resolution)
            m = compute_metrics(result, gt)
            a = m["alignment"]
            mc = map_metrics(rec.result.grid, gt.static_map, transform=Pose2D(a["x"], a["y"], a["theta"]))
            nan = float("nan")
            r = m.get("removal_by_motion") or {k: nan for k in ("walking_recall", "stopped_removed_share",
                                                                 "mover_recall", "seen_mover_recall")}
            if "static_removed_share" not in r:  # a scene without movers: every removed beam is static
                r["static_removed_share"] = float(result.removed.mean()) if result.removed.size else 0.0
            mem = result.memory
            print(f"{inp}{'' if args.seed is None else f' seed {args.seed}'} memory {'on ' if memory else 'off'}: "
                  f"{result.n_scans} scans {wall:.1f} s, "
                  f"ATE {m['ate_rmse_m']:.4f} m, ghost {m['map']['ghost_area_m2']:.3f} -> {mc.ghost_area_m2:.3f} m2, "
                  f"F1 {m['map']['f1']:.4f} -> {mc.f1:.4f} (online -> cleaned)")
            print(f"    removed: walking {r['walking_recall']:.3f}, stopped {r['stopped_removed_share']:.3f}, "
                  f"movers {r['mover_recall']:.3f}, movers seen walking {r['seen_mover_recall']:.3f}, "
                  f"static {100 * r['static_removed_share']:.2f} %; remembered tracks "
                  f"{mem.get('remembered_tracks', 0)}, "
                  f"erased cells {mem.get('erased_cells_finest', 0)} ({mem.get('tracks_erased', 0)} "
                  f"tracks)", flush=True)


if __name__ == "__main__":
    main()
