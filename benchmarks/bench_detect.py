"""Speed of detection and tracking (not run by pytest).

Scene: the crowd hall (720 beams, 20 Hz, robot driving a circuit) with 10 movers — six people
and four boxes/carts on random walks. Measures, per scan:

  * numba compile / cache-load time (separately): a throw-away tracker over the first 60 scans,
    its first call and its slowest later call (some kernels first run once tracks exist),
  * segmentation alone (``segment_scan``),
  * segmentation + map transform + shape fits (``fit_clusters``, the numba batch),
  * the whole ``Tracker.update`` (segmentation + fitting + measurement geometry + free-space
    test + association + Kalman updates + track management),

as median and p95 in ms. Target (issue 4): whole update ≤ 1 ms median.

    python benchmarks/bench_detect.py [--duration 30] [--cold]

``--cold`` points numba at an empty cache directory first, so the first-call line measures a
full compile instead of a cache load.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scenes import ten_movers
from scratch import scratch_dir


def _stats(ms: list[float]) -> str:
    a = np.asarray(ms)
    return f"median {np.median(a):.3f} ms, p95 {np.percentile(a, 95):.3f} ms, mean {a.mean():.3f} ms (n={a.size})"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--cold", action="store_true")
    args = ap.parse_args()
    if args.cold:
        os.environ["NUMBA_CACHE_DIR"] = scratch_dir("numba-cold-")

    from dynslam2d.detect import DetectConfig, Tracker, fit_clusters, search_angles, segment_scan
    from dynslam2d.detect.shapes import CRITERIA
    from dynslam2d.types import Pose2D

    t0 = time.perf_counter()
    sim = ten_movers(args.duration)
    print(f"simulated {len(sim.scans)} scans in {time.perf_counter() - t0:.1f} s "
          f"(10 movers, mean {(sim.ground_truth.mover_hits > 0).sum(1).mean():.1f} visible per scan)")
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    cfg = DetectConfig()

    # warm-up on a throw-away tracker: some kernels first run once tracks exist or are confirmed
    warm = Tracker(cfg)
    times = []
    for scan, pose in zip(sim.scans[:60], poses[:60]):
        t0 = time.perf_counter()
        warm.update(scan, pose)
        times.append((time.perf_counter() - t0) * 1e3)
    print(f"first update (numba compile or cache load): {times[0]:.0f} ms; slowest of the next "
          f"{len(times) - 1}: {max(times[1:], default=0.0):.1f} ms (warm-up, not in the figures below)")
    tr = Tracker(cfg)
    tr.update(sim.scans[0], poses[0])

    seg_ms, fit_ms, upd_ms = [], [], []
    angles = search_angles(cfg.fit.angle_step_deg)
    for scan, pose in zip(sim.scans[1:], poses[1:]):
        t0 = time.perf_counter()
        seg = segment_scan(scan, cfg.segment)
        t1 = time.perf_counter()
        pts = pose.transform_points(scan.points(np.ones(scan.n_beams, dtype=bool)))[seg.beams]
        fit_clusters(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), seg.offsets, ~seg.structure,
                     angles, CRITERIA[cfg.fit.criterion], cfg.fit.closeness_d0, cfg.fit.circle_min_points,
                     cfg.fit.coarse_stride)
        t2 = time.perf_counter()
        tr.update(scan, pose)
        t3 = time.perf_counter()
        seg_ms.append((t1 - t0) * 1e3)
        fit_ms.append((t2 - t0) * 1e3)
        upd_ms.append((t3 - t2) * 1e3)
    print(f"segmentation:                 {_stats(seg_ms)}")
    print(f"segmentation + shape fits:    {_stats(fit_ms)}")
    print(f"Tracker.update (everything):  {_stats(upd_ms)}")
    st = tr.stats
    print(f"per scan: {st.clusters / st.scans:.1f} clusters, {st.detections / st.scans:.1f} detections, "
          f"{tr.n_tracks} live tracks at the end; counters {st.as_dict()}")


if __name__ == "__main__":
    main()
