"""Range scale (laser.range_scale, --range-scale): fixed and estimated from odometry."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dynslam2d.config import Config
from dynslam2d.errors import DynSlamError
from dynslam2d.rangescale import LaserConfig, RangeScaleSource, apply_range_scale, estimate_range_scale, scale_ranges
from dynslam2d.sim import SimSource
from dynslam2d.sim.odometry import OdometryModel
from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.types import Pose2D, Scan


def _window_distance(poses: np.ndarray, k: int = 5) -> np.ndarray:
    return np.hypot(*(poses[k:, :2] - poses[:-k, :2]).T)


def test_scale_ranges_keeps_returns_geometry_and_odometry() -> None:
    ranges = np.array([0.05, 1.0, np.inf, 9.0, 12.0, np.nan])
    scan = Scan(stamp=1.0, angle_min=-0.5, angle_increment=0.2, ranges=ranges, range_min=0.1, range_max=10.0,
                frame_id="laser").with_odometry(Pose2D(1.0, 2.0, 0.3), 0.1)
    out = scale_ranges(scan, 1.05)
    assert np.allclose(out.ranges[[0, 1, 3, 4]], ranges[[0, 1, 3, 4]] * 1.05)
    assert np.array_equal(out.valid_mask(), scan.valid_mask())  # a return stays a return, a miss a miss
    assert out.angle_min == scan.angle_min and out.angle_increment == scan.angle_increment
    assert out.odom == scan.odom and out.yaw_rate == 0.1


def test_short_lidar_scale_is_estimated_from_odometry_and_corrects_the_path() -> None:
    """A lidar reading 5 % short (ranges × 0.95, as the datmo bags' lidar): laser-only SLAM covers
    5 % too little; the odometry-vs-laser estimate finds 1/0.95 within 1 % and the corrected run's
    path is within 2 % of the ground truth."""
    sim = SimSource("corridor", duration=20.0, odometry_model=OdometryModel().scaled(0.25))
    short = RangeScaleSource(sim, 0.95)
    est = estimate_range_scale(short, LaserConfig(range_scale="auto"))
    assert est.scale == pytest.approx(1.0 / 0.95, rel=0.01)
    assert est.odom_distance > 5.0 and est.windows > 20
    truth = _window_distance(sim.ground_truth.poses)
    moving = truth > 0.05
    ratios = {}
    for name, k in (("short", 1.0), ("corrected", est.scale)):
        slam = HectorSlam(SlamConfig(use_odometry=False))
        poses = np.array([slam.process(s).pose.as_array() for s in RangeScaleSource(short, k)])
        ratios[name] = _window_distance(poses)[moving].sum() / truth[moving].sum()
    assert ratios["short"] == pytest.approx(0.95, abs=0.01)  # the error the scale corrects
    assert ratios["corrected"] == pytest.approx(1.0, abs=0.02)


def test_pipeline_applies_and_reports_the_range_scale() -> None:
    from dynslam2d.pipeline import run

    sim = SimSource("static", duration=2.0)
    plain = run(SimSource("static", duration=2.0))
    assert plain.summary()["range_scale"] == {"mode": "fixed", "used": 1.0}
    res = run(sim, Config(laser={"range_scale": 1.1}))
    assert res.summary()["range_scale"] == {"mode": "fixed", "used": 1.1}
    # the scaled world: the map's extent grows with the ranges
    assert res.grid.shape[0] * res.grid.shape[1] > 1.1 * plain.grid.shape[0] * plain.grid.shape[1]
    # auto with too little motion: scale 1, a warning, valid JSON
    short = SimSource("static", duration=2.0)
    out = apply_range_scale(short, LaserConfig(range_scale="auto"))
    assert out is short
    info = short.meta.extra["range_scale"]
    assert info["mode"] == "auto" and info["used"] == 1.0 and info["scale"] is None
    json.dumps(info, allow_nan=False)
    assert any("range scale 1 used" in w for w in short.meta.extra["warnings"])


def test_range_scale_bad_input() -> None:
    with pytest.raises(Exception, match="range_scale"):
        Config(laser={"range_scale": 3.0})
    with pytest.raises(Exception, match="range_scale"):
        Config(laser={"range_scale": "often"})
    from dynslam2d.io.odomsource import attach_odometry

    laser_only = attach_odometry(SimSource("static", duration=1.0), "sim", odom="none", imu="none")
    with pytest.raises(DynSlamError, match="--range-scale auto needs odometry"):
        apply_range_scale(laser_only, LaserConfig(range_scale="auto"))


def test_cli_range_scale_option(tmp_path, capsys) -> None:
    from test_cli import cli

    code, _, err = cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(tmp_path / "x"), "--range-scale",
                       "big")
    assert code == 2 and "--range-scale must be 'auto' or a number" in err and len(err.strip().splitlines()) == 1
    code, out, _ = cli(capsys, "run", "sim:static", "--duration", "2", "--out", str(tmp_path / "y"), "--range-scale",
                       "1.05")
    assert code == 0 and "range scale" in out and "1.05 (given)" in out
    summary = json.loads((tmp_path / "y" / "summary.json").read_text())
    assert summary["range_scale"] == {"mode": "fixed", "used": 1.05}
    # auto without odometry (the IMU alone does not count): one line before anything is written
    code, _, err = cli(capsys, "run", "sim:static", "--duration", "1", "--odom", "none", "--out", str(tmp_path / "z"),
                       "--range-scale", "auto")
    assert code == 2 and "--range-scale auto needs odometry" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "z").exists()
