"""Benchmark scenes built from the simulator's parts (shared by the benchmark scripts)."""

from __future__ import annotations

import dataclasses

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
