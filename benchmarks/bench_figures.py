"""Time of tracks.png with many tracks (issue 14, item 8).

Builds N synthetic track paths (random walks of 2-60 reports, a third of them in M)
and times ``plot_tracks`` on them, in a subprocess importing dynslam2d from ``--src``
(so an older checkout can be compared).

    PYTHONPATH=src python benchmarks/bench_figures.py --tracks 5000 36168
    PYTHONPATH=src python benchmarks/bench_figures.py --tracks 5000 --src /path/to/old/src
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import sys, tempfile, time
import numpy as np
import matplotlib
matplotlib.use("Agg")
from dynslam2d.types import Box
from dynslam2d.viz.trackpaths import TrackPath
from dynslam2d.viz.tracksplot import plot_tracks

n = int(sys.argv[1])
rng = np.random.default_rng(0)
tracks = []
for i in range(n):
    k = int(rng.integers(2, 60))
    xy = np.cumsum(rng.normal(0, 0.05, (k, 2)), axis=0) + rng.uniform(-40, 40, 2)
    in_m = np.full(k, i % 3 == 0)
    tracks.append(TrackPath(i, np.arange(k, dtype=float) * 0.1, xy, rng.normal(0, 0.5, (k, 2)), in_m,
                            np.array(["confirmed"] * k), Box(float(xy[-1, 0]), float(xy[-1, 1]), 0.0, 0.5, 0.5)))
with tempfile.TemporaryDirectory() as d:
    t0 = time.perf_counter()
    plot_tracks(f"{d}/tracks.png", tracks, None, title="bench")
    print(f"{time.perf_counter() - t0:.2f}")
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracks", type=int, nargs="+", default=[5000, 36168])
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    args = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=args.src)
    for n in args.tracks:
        res = subprocess.run([sys.executable, "-c", CHILD, str(n)], env=env, capture_output=True, text=True)
        if res.returncode:
            raise SystemExit(res.stderr)
        print(f"{n:>7} tracks: tracks.png in {float(res.stdout.strip()):7.2f} s  (src {args.src})", flush=True)


if __name__ == "__main__":
    main()
