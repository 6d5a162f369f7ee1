"""--odom / --imu / --laser-offset / --frame on the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dynslam2d.io.odometry import compose_mount
from dynslam2d.io.trajectory import read_tum
from dynslam2d.types import Pose2D

from test_cli import cli


def test_run_reports_the_odometry_source_and_frame_base_link(tmp_path, capsys):
    laser_dir, base_dir, none_dir = tmp_path / "laser", tmp_path / "base", tmp_path / "none"
    code, out, err = cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(laser_dir), "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["odometry"] == "sim" and summary["trajectory_frame"] == "laser"
    assert summary["odometry_detail"]["mount"] == pytest.approx([0.15, 0.0, 0.0])
    code, out, err = cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(base_dir), "--frame", "base_link")
    assert code == 0, err
    assert "odometry: sim" in err  # the terminal names the source
    laser = read_tum(laser_dir / "trajectory.tum")
    base = read_tum(base_dir / "trajectory.tum")
    # base_link poses = laser poses ⊕ (base_link→laser)⁻¹, in the same map frame
    assert np.abs(base.poses[:, :2] - compose_mount(laser.poses, Pose2D(0.15, 0, 0).inverse())[:, :2]).max() < 1e-9
    assert np.hypot(*base.poses[0, :2]) == pytest.approx(0.15)
    assert json.loads((base_dir / "summary.json").read_text())["trajectory_frame"] == "base_link"
    code, out, err = cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(none_dir), "--odom", "none",
                         "--imu", "none", "--json")
    assert code == 0, err
    assert json.loads(out)["odometry"] is None
    assert (none_dir / "metrics.json").exists()  # stripping odometry keeps the simulator's ground truth


def test_odometry_option_errors_are_one_line(tmp_path, capsys):
    cases = [
        (("--odom", "/odom"), "a simulated source has only its own odometry"),
        (("--frame", "map"), "--frame must be 'laser' or 'base_link'"),
        (("--odom", "none", "--frame", "base_link"), "--frame base_link needs the base_link → laser transform"),
    ]
    for args, message in cases:
        code, _, err = cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(tmp_path / "x"), *args)
        assert code == 2 and message in err, err
        assert len(err.strip().splitlines()) == 1
    code, _, err = cli(capsys, "info", "sim:static", "--duration", "1", "--laser-offset", "1,2")
    assert code == 2 and "--laser-offset '1,2'" in err
