"""Benchmark scenes built from the simulator's parts (shared by the benchmark scripts)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


def ten_movers(duration: float):
    """The crowd hall with 10 movers on random walks (7 people, 3 carts), seed 42."""
    from dynslam2d.sim import Circle, Mover, Rect, build_scenario, random_waypoints, simulate

    base = build_scenario("crowd", duration=duration)
    rng = np.random.default_rng(42)
    movers = []
    regions = [(-3.2, 3.2, -1.7, 1.7)] * 4 + [(-6.0, 5.0, 3.4, 4.3)] * 3 + [(-6.0, 6.0, -4.3, -3.4)] * 3
    for k, region in enumerate(regions, start=1):
        walk = random_waypoints(rng, region, duration + 5.0, speed_range=(0.6, 1.4), pause_range=(0.0, 1.0))
        shape = Circle(float(rng.uniform(0.2, 0.25))) if k % 5 not in (0, 3) else Rect(0.8, 0.5)
        movers.append(Mover(k, f"mover-{k}", shape, walk))
    return simulate(dataclasses.replace(base, movers=tuple(movers), name="ten-movers"))


def input_scans(data: Path, name: str) -> list:
    """The scans of input ``name``: a key of bench_digest's ``INPUTS`` (recordings under ``data``), any other
    built-in scene by its name (``sim:paper``: README command 1), or ``ten-movers`` / ``sim:ten-movers``
    (:func:`ten_movers`, 30 s as bench_pipeline.py's default: the scene furthest from the speed target)."""
    if name in ("ten-movers", "sim:ten-movers"):
        return list(ten_movers(30.0).scans)
    from bench_digest import INPUTS

    from dynslam2d.inputs import open_source

    rel, topic = INPUTS.get(name, (name, None))
    return list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
