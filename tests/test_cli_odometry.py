"""--odom / --imu / --laser-offset / --frame on the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_cli import cli

from dynslam2d.io.odometry import compose_mount
from dynslam2d.io.trajectory import read_tum
from dynslam2d.types import Pose2D


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


def test_simulate_odometry_noise_and_mount_options(tmp_path, capsys):
    from dynslam2d.inputs import open_source

    out = tmp_path / "sim"
    code, _, err = cli(capsys, "simulate", "crowd", "--duration", "3", "--beams", "90", "--out", str(out),
                       "--odom-noise", "0", "--laser-mount", "0.3,0,0")
    assert code == 0, err
    gt = read_tum(out / "gt_trajectory.tum")
    odom = read_tum(out / "odom.tum")
    assert np.abs(odom.poses[:, :2] - gt.poses[:, :2]).max() < 2e-3  # perfect odometry = the true motion
    src = open_source(out / "scans.mcap")
    assert src.meta.extra["odometry"]["mount"] == pytest.approx([0.3, 0.0, 0.0])
    noisy = tmp_path / "noisy"
    code, _, err = cli(capsys, "simulate", "crowd", "--duration", "3", "--beams", "90", "--out", str(noisy),
                       "--odom-noise", "3")
    assert code == 0, err
    drift = np.abs(read_tum(noisy / "odom.tum").poses[:, :2] - gt.poses[:, :2]).max()
    assert drift > 0.02
    code, _, err = cli(capsys, "simulate", "crowd", "--out", str(tmp_path / "x"), "--laser-mount", "a,b")
    assert code == 2 and "--laser-mount 'a,b'" in err
