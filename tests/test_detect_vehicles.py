"""Vehicle-size clusters are detections only over observed-free map cells (detect/vehicles.py)."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.config import Config
from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.layout import F_HI1, F_HI2, F_LO1, F_LO2, N_FIT_COLS
from dynslam2d.detect.mapevidence import MapView
from dynslam2d.detect.vehicles import admit_long_clusters, extent_limit, long_kept
from dynslam2d.pipeline import run
from dynslam2d.results import compute_metrics, ground_truth_for
from dynslam2d.sim import Mover, Rect, Scenario, oscillating_in_place, timeline
from dynslam2d.sim.scenarios import _build_world
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.simulation import SimSource


def _fits(lengths: list[float]) -> np.ndarray:
    f = np.zeros((len(lengths), N_FIT_COLS))
    for i, n in enumerate(lengths):
        f[i, F_LO1], f[i, F_HI1], f[i, F_LO2], f[i, F_HI2] = 0.0, n, 0.0, 0.3
    return f


def test_long_clusters_are_kept_only_on_observed_free_cells():
    """Four 4 m clusters along x at y = 0, 1, 2, 3 m on a map that is free around y = 0, long-occupied
    along y = 1, unknown at y = 2 and half free at y = 3; and a 2 m cluster on the occupied row, which
    the vehicle rule never touches."""
    cfg = DetectConfig()
    res = 0.05
    lo = np.zeros((100, 140), dtype=np.float32)  # cells i0 = j0 = −10: x, y from −0.5 to 6.5 / 4.5 m
    lo[5:15, :] = -2.0  # y ≈ −0.25 … 0.25: observed free
    lo[28:33, :] = 8.0  # y ≈ 0.9 … 1.1: a long-occupied wall
    lo[68:73, :90] = -2.0  # y ≈ 3: free for x < 4 m …
    lo[68:73, 90:] = 8.0  # … a wall after it
    view = MapView(lo, -10, -10, res)
    xs = np.linspace(0.0, 4.0, 41)
    rows = [(xs, 0.0), (xs, 1.0), (xs, 2.0), (np.linspace(2.0, 6.0, 41), 3.0), (np.linspace(0.0, 2.0, 21), 1.0)]
    px = np.concatenate([x for x, _ in rows])
    py = np.concatenate([np.full(x.shape, y) for x, y in rows])
    offsets = np.concatenate(([0], np.cumsum([x.shape[0] for x, _ in rows])))
    fits = _fits([4.0, 4.0, 4.0, 4.0, 2.0])
    keep = np.ones(5, dtype=bool)
    assert admit_long_clusters(keep, fits, offsets, px, py, view, cfg) == 1
    assert keep.tolist() == [True, False, False, False, True]
    keep = np.ones(5, dtype=bool)
    admit_long_clusters(keep, fits, offsets, px, py, None, cfg)  # no map: no long cluster
    assert keep.tolist() == [False, False, False, False, True]
    assert extent_limit(cfg) == pytest.approx(6.0)
    cfg.segment.vehicle_max_extent = 0.0
    assert extent_limit(cfg) == pytest.approx(cfg.segment.max_extent)


def _van_scene() -> Scenario:
    """A 16 × 10 m hall, a motionless laser at (−5, −2.5); a 4.5 × 1.8 m van drives 13 m along the hall."""
    world = _build_world([(-8.0, -5.0), (8.0, -5.0), (8.0, 5.0), (-8.0, 5.0)], [])
    van = timeline((-6.5, 2.0), [("wait", 1.0), ("go", (6.5, 2.0), 1.5)], start_heading=0.0)
    robot = oscillating_in_place(-5.0, -2.5, 0.0, 0.0, 1.0)
    lidar = LidarModel(beams=360, rate_hz=10.0, range_max=15.0)
    return Scenario("van-test", "", world, (Mover(1, "van", Rect(4.5, 1.8), van),), robot, lidar, 10.0, 3)


def test_a_van_driving_past_is_tracked_and_removed_and_no_wall_is():
    src = SimSource(_van_scene())
    gt = ground_truth_for(src, None, 0.05)
    out = {}
    for limit in (6.0, 0.0):
        cfg = Config()
        cfg.detect.segment.vehicle_max_extent = limit
        r = compute_metrics(run(src, cfg), gt)["removal_by_motion"]
        out[limit] = r
    # tracked once it has left its outline of the first scan and drives over floor the laser saw free (0.52)
    assert out[6.0]["walking_recall"] > 0.4
    # longer than max_extent (3 m): structure, tracked only while seen end-on (0.15)
    assert out[0.0]["walking_recall"] < 0.25 and out[6.0]["walking_recall"] > 2.5 * out[0.0]["walking_recall"]
    assert out[6.0]["static_removed_share"] < 0.002


def test_long_kept_is_the_numpy_selection_also_with_nan_sides():
    """long_kept equals flatnonzero(keep & (maximum(ext1, ext2) > limit)): a NaN side is never long (np.maximum
    propagates it), either side may be the long one, a dropped cluster is never listed."""
    rng = np.random.default_rng(3)
    f = np.zeros((400, N_FIT_COLS))
    f[:, F_LO1] = rng.uniform(-2.0, 2.0, 400)
    f[:, F_HI1] = f[:, F_LO1] + rng.uniform(0.0, 6.0, 400)
    f[:, F_LO2] = rng.uniform(-2.0, 2.0, 400)
    f[:, F_HI2] = f[:, F_LO2] + rng.uniform(0.0, 6.0, 400)
    f[::7, F_HI1] = np.nan
    f[3::11, F_LO2] = np.nan
    f[5, F_HI1] = f[5, F_LO1] + 3.0  # exactly the limit: not longer
    keep = rng.random(400) < 0.7
    ext = np.maximum(f[:, F_HI1] - f[:, F_LO1], f[:, F_HI2] - f[:, F_LO2])
    want = np.flatnonzero(keep & (ext > 3.0))
    got = long_kept(keep, f, 3.0)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)
    assert 50 < want.shape[0] < 250
    # NaN in one side with the other side long: numpy says not long, a plain "either side > limit" would say long
    nan_long = np.flatnonzero(keep & np.isnan(ext) & ((f[:, F_HI1] - f[:, F_LO1] > 3.0)
                                                      | (f[:, F_HI2] - f[:, F_LO2] > 3.0)))
    assert nan_long.shape[0] > 0 and not np.isin(nan_long, got).any()
