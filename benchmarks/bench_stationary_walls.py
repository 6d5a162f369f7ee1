"""People left in the map and walls lost, for runs of a motionless sensor (docs/maps.md; not run by pytest).

For each results folder of ``dynslam2d run`` on the same recording:

  * residue: m² occupied in the run's map (map.yaml + map_logodds.npy, the written map) but
    free in the map of the per-beam median scan (the background) — the number
    ``dynslam2d eval stationary`` prints;
  * of the residue, the part within 0.10 m of an occupied background cell (on or beside the walls
    the median scan sees: wall cells the background map's own single Hector update cleared, which the
    clean-up pass restores) and the part farther away (people and things the median scan does not see);
  * walls lost: cells occupied in the background map farther than 0.10 m from every
    occupied cell of the run's map (structure the median scan sees and the run's map lost),
    as a count and a share of the background's occupied cells.

    python benchmarks/bench_stationary_walls.py BAG RUN_DIR [RUN_DIR ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dynslam2d.config import load_config
from dynslam2d.eval.maps import distance_to, load_run_map
from dynslam2d.eval.stationary import background_map, median_background_scan, residue_area
from dynslam2d.inputs import open_source


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("input")
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args()
    background = median_background_scan(open_source(args.input))
    for run_dir in args.runs:
        cfg = load_config(run_dir / "config.yaml")
        bg = background_map(background, cfg.slam)
        run_map = load_run_map(run_dir)
        occ_bg = bg.occupied()
        # the run's occupied cells on the background's cells (same resolution, nearest cell)
        xs, ys = run_map.cell_centers()
        occ = run_map.occupied()
        cells = bg.world_to_cell(np.column_stack((xs[occ], ys[occ])))
        h, w = bg.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < w) & (cells[:, 1] >= 0) & (cells[:, 1] < h)
        run_on_bg = np.zeros(bg.shape, dtype=bool)
        run_on_bg[cells[ok, 1], cells[ok, 0]] = True
        lost = occ_bg & (distance_to(run_on_bg, bg.resolution) > 0.10 + 1e-9)
        # residue cells (run occupied, background free: residue_area's test) by distance to the background's walls
        prob = np.full(cells.shape[0], np.nan)
        prob[ok] = bg.prob[cells[ok, 1], cells[ok, 0]]
        with np.errstate(invalid="ignore"):
            res = ok & (prob < 0.5)
        near = np.zeros(cells.shape[0], dtype=bool)
        near[res] = distance_to(occ_bg, bg.resolution)[cells[res, 1], cells[res, 0]] <= 0.10 + 1e-9
        a = run_map.resolution ** 2
        print(f"{run_dir}: residue {residue_area(run_map, bg):.4f} m2 ({near.sum() * a:.4f} within 0.10 m of the "
              f"background's walls, {(res & ~near).sum() * a:.4f} farther), walls lost {int(lost.sum())} of "
              f"{int(occ_bg.sum())} background cells ({100 * lost.sum() / max(occ_bg.sum(), 1):.2f} %)")


if __name__ == "__main__":
    main()
