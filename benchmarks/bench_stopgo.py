"""Track memory and retroactive erasure on simulated scenes, with and without (docs/maps.md; not run by pytest).

For each scene, two runs with the default configuration and the clean-up pass watching:
``off`` = ``detect.memory.enabled: false, erase: false`` (the behaviour before track memory)
and ``on`` = the defaults. Printed per run: ATE, ghost area and map F1 of the online and the
cleaned map, and the removed shares of ``metrics.json``'s ``removal_by_motion``: walking
movers, stopped movers (they moved before), movers with stopped ones counted as movers, the
same counting a stopped mover only once the sensor saw it walk, and static structure.

    python benchmarks/bench_stopgo.py sim:stop-and-go sim:parking [--seed N] [--memory both|on|off]
        [--set detect.segment.max_extent=5.6] [--explain] [--per-mover]

``--explain`` adds, per run, what limits the F1 and ghost of the online and the cleaned map: the ground-truth
occupied cells the recall counts (observable) but the map misses — never observed (unknown) or observed free, and of
those how many kept beams hit (≥ 5 hits: structure the rays later cleared, e.g. walls seen at grazing
incidence) — and the ghost cells of both maps by the nearest ground-truth mover.

``--per-mover`` adds, per simulated mover, the removed share of its beams while it moves (speed above
0.05 m/s, as ``removal_by_motion``), while it stands after having moved, and while it stands before it
first moved (from the simulator's per-beam labels).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import yaml

from dynslam2d.config import Config, config_from_dict
from dynslam2d.eval.maps import cell_sets, map_metrics
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


class HitCounter:
    """Observer: per finest-level cell (absolute index), the kept beams that hit it in map updates."""

    def __init__(self) -> None:
        self.keys: list[np.ndarray] = []
        self.resolution = 0.05

    def on_scan(self, scan, step, pipeline) -> None:
        if not step.map_updated:
            return
        c = pipeline.config.slam
        self.resolution = c.map_resolution
        with np.errstate(invalid="ignore"):
            r = scan.ranges
            keep = scan.valid_mask() & ~step.removed & (r > c.laser_min_dist) & (r < c.laser_max_dist)
        cells = np.floor(step.pose.transform_points(scan.points(keep)) / c.map_resolution + 0.5).astype(np.int64)
        self.keys.append(cells[:, 0] * 4294967296 + cells[:, 1])

    def on_finish(self, result, pipeline) -> None:
        pass

    def hits_near(self, xy: np.ndarray) -> np.ndarray:
        """Hits within one cell (3 × 3) of each map-frame point (n, 2), m."""
        k = np.concatenate(self.keys) if self.keys else np.zeros(0, np.int64)
        u, n = np.unique(k, return_counts=True)
        out = np.zeros(xy.shape[0], dtype=np.int64)
        if u.shape[0] == 0:
            return out
        c = np.floor(xy / self.resolution + 0.5).astype(np.int64)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                q = (c[:, 0] + di) * 4294967296 + (c[:, 1] + dj)
                i = np.clip(np.searchsorted(u, q), 0, u.shape[0] - 1)
                out += np.where(u[i] == q, n[i], 0)
        return out


def explain(result, cleaned, gt, transform: Pose2D, hits: HitCounter) -> None:
    """Print what limits the F1 of both maps (missed observable cells) and the ghost cells by nearest mover."""
    for label, grid in (("online", result.grid), ("cleaned", cleaned.grid)):
        cs = cell_sets(grid, gt.static_map, transform)
        miss = cs.observable & ~cs.truth_matched
        est = cs.estimate[miss]
        r, c = np.nonzero(miss)
        xy = np.column_stack((cs.origin[0] + (c + 0.5) * cs.resolution, cs.origin[1] + (r + 0.5) * cs.resolution))
        h = hits.hits_near(transform.inverse().transform_points(xy)) if xy.size else np.zeros(0, np.int64)
        free = np.isfinite(est)
        print(f"    {label} map misses {int(miss.sum())} of {int(cs.observable.sum())} observable structure cells: "
              f"{int((~free).sum())} never observed, {int(free.sum())} observed free ({int((free & (h >= 5)).sum())} "
              f"of them hit >= 5 times by kept beams, {int((free & (h == 0)).sum())} never hit)")
    restored = cleaned.stats.get("restored_cells", 0)
    print(f"    clean-up pass: erased {cleaned.stats['erased_cells']}, restored {restored} cells")
    mv = gt.movers
    for label, grid in (("online", result.grid), ("cleaned", cleaned.grid)):
        g = cell_sets(grid, gt.static_map, transform).ghost
        r, c = np.nonzero(g)
        near: dict[int, int] = {}
        for x, y in zip(cs.origin[0] + (c + 0.5) * cs.resolution, cs.origin[1] + (r + 0.5) * cs.resolution):
            k = int(np.argmin(np.hypot(mv["x"] - x, mv["y"] - y))) if mv.shape[0] else -1
            mid = int(mv["id"][k]) if k >= 0 else -1
            near[mid] = near.get(mid, 0) + 1
        print(f"    {label} ghost cells by nearest mover: " + (", ".join(f"mover {m}: {n}" for m, n in
                                                                   sorted(near.items())) or "none"))


def per_mover(src, result) -> None:
    """Print, per simulated mover, the removed share of its beams moving / stopped after moving / before."""
    gt = getattr(getattr(src, "inner", src), "ground_truth", None)
    if gt is None:
        return
    st, lab, rem = gt.mover_states, gt.labels, result.removed
    for j, m in enumerate(gt.movers):
        moving = np.hypot(st[:, j, 3], st[:, j, 4]) > 0.05
        before = np.cumsum(moving) == 0
        mine = lab == m.id
        parts = []
        for name, rows in (("moving", moving), ("stopped after moving", ~moving & ~before),
                           ("standing before moving", before)):
            sel = mine & rows[:, None]
            n = int(sel.sum())
            parts.append(f"{name} {rem[sel].mean():.3f} of {n}" if n else f"{name} -")
        print(f"    mover {m.id} {m.name}: " + ", ".join(parts))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--set", action="append", default=[], help="KEY=VALUE config override (both runs)")
    ap.add_argument("--seed", type=int, default=None, help="simulator seed (default: the scene's own)")
    ap.add_argument("--memory", choices=("both", "on", "off"), default="both", help="which of the two runs")
    ap.add_argument("--explain", action="store_true", help="what limits F1 and ghost (module docstring)")
    ap.add_argument("--per-mover", action="store_true", help="removed shares per simulated mover")
    args = ap.parse_args()
    for inp in args.inputs:
        for memory in {"both": (False, True), "on": (True,), "off": (False,)}[args.memory]:
            src = open_source(inp, seed=args.seed)
            cfg = _config(memory, args.set)
            rec = CleanupRecorder(cfg.clean)
            t0 = time.perf_counter()
            hits = HitCounter()
            result = run(src, cfg, observers=[rec, hits] if args.explain else [rec])
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
            if args.explain:
                explain(result, rec.result, gt, Pose2D(a["x"], a["y"], a["theta"]), hits)
            if args.per_mover:
                per_mover(src, result)


if __name__ == "__main__":
    main()
