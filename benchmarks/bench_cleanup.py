"""Cost and effect of the offline map clean-up pass (docs/maps.md; not run by pytest).

For each input: one run with the clean-up recorder watching, then

  * SLAM time (the run's wall time minus the pass) and the pass's time (counting during
    the run + the final erase), as a share of the SLAM time (target: < 20 % on MIT CSAIL
    and fr079);
  * occupied cells of the online map, cells erased (and restored: free online, hit, never seen
    through), F1 of the cleaned occupied cells
    against the online ones, "lost" structure (online occupied cells farther than 0.10 m
    from every cleaned occupied cell) and its largest connected piece (m);
  * with ground truth (sim:<scenario>): ghost area and F1 of the online and the cleaned map.

``--figure PNG`` draws the online map with the erased cells (amber) and lost cells
(red) for the first input, with a zoom on the 12 × 12 m window holding most erased cells.

    python benchmarks/bench_cleanup.py ../shared/data/mit-csail/mit-csail.clf \\
        ../shared/data/fr079/freiburg-079-corrected.log.gz sim:stop-and-go sim:parking
    python benchmarks/bench_cleanup.py ../shared/data/dynamic/leg_tracker/negative_2.bag --topic /right_scan \\
        --set clean.rehit_min_hits=0      # the rule before the rehit test
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import ndimage

from dynslam2d.config import Config, with_assignments
from dynslam2d.eval.maps import distance_to, map_metrics
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import run
from dynslam2d.results import compute_metrics, ground_truth_for
from dynslam2d.slam.cleanup import CleanupRecorder, compare_online
from dynslam2d.types import Pose2D


def _lost(online, cleaned) -> tuple[np.ndarray, float]:
    kept = online.occupied() & ~cleaned.erased
    lost = online.occupied() & (distance_to(kept, online.resolution) > 0.1 + 1e-9)
    lab, n = ndimage.label(lost, structure=np.ones((3, 3)))
    longest = 0.0
    for sl in ndimage.find_objects(lab):
        if sl is not None:
            h, w = sl[0].stop - sl[0].start, sl[1].stop - sl[1].start
            longest = max(longest, float(np.hypot(h, w)) * online.resolution)
    return lost, longest


def _figure(path: str, name: str, online, cleaned, lost: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch, Rectangle

    occ = online.occupied()
    img = np.ones(online.shape + (3,))
    img[~online.known()] = 0.85
    img[occ] = 0.0
    img[cleaned.erased] = (1.0, 0.69, 0.0)
    img[lost] = (0.85, 0.0, 0.0)
    restored = cleaned.restored if cleaned.restored is not None else np.zeros(occ.shape, dtype=bool)
    img[restored] = (0.0, 0.55, 0.9)
    res = online.resolution
    win = int(round(12.0 / res))
    score = ndimage.uniform_filter(cleaned.erased.astype(float), size=win, mode="constant")
    r, c = np.unravel_index(int(np.argmax(score)), score.shape)
    r0, c0 = max(r - win // 2, 0), max(c - win // 2, 0)
    fig, axes = plt.subplots(1, 2, figsize=(15, 7.5))
    ext = online.extent
    axes[0].imshow(img, origin="lower", extent=ext, interpolation="nearest")
    x0, y0 = online.origin[0] + c0 * res, online.origin[1] + r0 * res
    axes[0].add_patch(Rectangle((x0, y0), win * res, win * res, fill=False, ec="tab:blue", lw=1.5))
    axes[0].set_title(f"{name}: online map, {int(cleaned.erased.sum())} of {int(occ.sum())} occupied cells erased, "
                      f"{int(restored.sum())} restored")
    sub = img[r0:r0 + win, c0:c0 + win]
    axes[1].imshow(sub, origin="lower", interpolation="nearest",
                   extent=(x0, x0 + sub.shape[1] * res, y0, y0 + sub.shape[0] * res))
    axes[1].set_title("zoom (blue square)")
    for ax in axes:
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    axes[1].legend(handles=[Patch(color="black", label="kept (occupied in both maps)"),
                            Patch(color=(1.0, 0.69, 0.0), label="erased by the clean-up"),
                            Patch(color=(0.85, 0.0, 0.0), label="lost: > 0.10 m from any kept cell"),
                            Patch(color=(0.0, 0.55, 0.9), label="restored (free online, hit, not seen through)")],
                   loc="upper right", fontsize="small", framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--figure", default=None, help="PNG of the first input's maps")
    ap.add_argument("--topic", default=None, help="scan topic of a bag with several (every bag input)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="configuration override, e.g. clean.rehit_min_hits=0 (repeatable)")
    args = ap.parse_args()
    for k, inp in enumerate(args.inputs):
        src = open_source(inp, topic=args.topic if not inp.startswith("sim:") else None)
        cfg = with_assignments(Config(), args.set)
        rec = CleanupRecorder(cfg.clean)
        t0 = time.perf_counter()
        result = run(src, cfg, observers=[rec])
        wall = time.perf_counter() - t0
        cl = rec.result
        assert cl is not None
        slam_s = wall - cl.stats["pass_time_s"]
        cmp = compare_online(result.grid, cl)
        lost, longest = _lost(result.grid, cl)
        print(f"{inp}: {result.n_scans} scans, SLAM {slam_s:.2f} s, pass {cl.stats['pass_time_s']:.2f} s "
              f"({100 * cl.stats['pass_time_s'] / slam_s:.1f} % of SLAM, {cl.stats['scans_counted']} scans counted)")
        print(f"  erased {cl.stats['erased_cells']} of {cl.stats['occupied_cells_online']} occupied cells "
              f"({cl.stats['erased_area_m2']:.2f} m2); cleaned vs online F1 {cmp['f1']:.4f}; lost "
              f"{cmp['lost_cells']} cells ({100 * cmp['lost_share']:.2f} %), longest lost piece {longest:.2f} m")
        if cl.restored is not None and cl.restored.any():
            d = distance_to(result.grid.occupied() & ~cl.erased, result.grid.resolution)[cl.restored]
            print(f"  restored {int(cl.restored.sum())} cells ({cl.stats['restored_area_m2']:.2f} m2), "
                  f"{int((d <= 1.5 * result.grid.resolution).sum())} of them beside a kept occupied cell, farthest "
                  f"{float(d.max()):.2f} m from one")
        gt = ground_truth_for(src, None, cfg.slam.map_resolution)
        if gt is not None:
            m = compute_metrics(result, gt)
            a = m["alignment"]
            mc = map_metrics(cl.grid, gt.static_map, transform=Pose2D(a["x"], a["y"], a["theta"]))
            print(f"  ghost {m['map']['ghost_area_m2']:.3f} -> {mc.ghost_area_m2:.3f} m2, "
                  f"F1 {m['map']['f1']:.4f} -> {mc.f1:.4f} (online -> cleaned)")
        if k == 0 and args.figure:
            _figure(args.figure, inp.rsplit("/", 1)[-1], result.grid, cl, lost)


if __name__ == "__main__":
    main()
