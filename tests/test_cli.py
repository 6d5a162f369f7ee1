"""The command line as a user meets it: outputs, exit codes, one-line errors."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import yaml
from conftest import run_cli

from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.types import Scan


def cli(capsys, *args: str) -> tuple[int, str, str]:
    return run_cli(capsys, *args)


def _scans(n=5, beams=90):
    return [
        Scan(stamp=100.0 + 0.1 * i, angle_min=-np.pi / 2, angle_increment=np.pi / beams, ranges=np.full(beams, 2.0 + i),
             range_min=0.1, range_max=10.0)
        for i in range(n)
    ]


def test_info_reports_counts_as_table_and_json(tmp_path, capsys):
    bag = write_scan_bag(tmp_path / "s.mcap", _scans())
    code, out, _ = cli(capsys, "info", str(bag))
    assert code == 0 and "mcap" in out and "scans" in out
    code, out, _ = cli(capsys, "info", str(bag), "--json")
    data = json.loads(out)
    assert data["scans"] == 5 and data["beams_max"] == 90
    assert data["valid_range_min"] == 2.0 and data["valid_range_max"] == 6.0
    assert data["rate_hz"] == pytest.approx(10.0)


@pytest.mark.parametrize(
    "setup, message",
    [
        (lambda p: p / "missing.bag", "no such file"),
        (lambda p: (p / "x.txt").write_text("hello\n") and p / "x.txt", "unknown format"),
        (lambda p: (p / "bad.clf").write_text("FLASER 3 1.0 2.0\n") and p / "bad.clf", "bad.clf:1"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, setup, message):
    path = setup(tmp_path)
    code, out, err = cli(capsys, "info", str(path))
    assert code == 2
    assert message in err and "Traceback" not in err
    assert err.strip().startswith("error:")


def test_skip_bad_continues_past_a_malformed_carmen_line(tmp_path, capsys):
    good = " ".join(["FLASER", "3", "1.0", "2.0", "3.0", "0 0 0 0 0 0", "{t}", "host", "0.0"])
    text = good.format(t=1.0) + "\nFLASER 3 1.0 junk\n" + good.format(t=2.0) + "\n"
    log = tmp_path / "l.clf"
    log.write_text(text)
    assert cli(capsys, "info", str(log))[0] == 2
    code, out, _ = cli(capsys, "info", str(log), "--skip-bad", "--json")
    assert code == 0 and json.loads(out)["scans"] == 2


def test_config_dump_is_valid_yaml_with_hector_names(capsys):
    code, out, _ = cli(capsys, "config", "dump")
    data = yaml.safe_load(out)
    assert code == 0 and data["slam"]["map_update_angle_thresh"] == 0.06


def test_simulate_then_run_with_gt_folder(tmp_path, capsys):
    sim_dir = tmp_path / "sim"
    code, out, err = cli(capsys, "simulate", "static", "--out", str(sim_dir), "--duration", "4")
    assert code == 0, err
    for name in ("scans.mcap", "gt_map.pgm", "gt_map.yaml", "gt_trajectory.tum", "labels.npz", "movers.csv",
                 "overview.png"):
        assert (sim_dir / name).exists(), name
    run_dir = tmp_path / "run"
    code, out, err = cli(capsys, "run", str(sim_dir / "scans.mcap"), "--gt", str(sim_dir), "--out", str(run_dir),
                         "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["scans"] == 80 and summary["match_failures"] == 0
    for name in ("map.pgm", "map.yaml", "map_logodds.npy", "trajectory.tum", "config.yaml", "summary.json", "map.png",
                 "metrics.json"):
        assert (run_dir / name).exists(), name
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["ate_rmse_m"] < 0.03 and metrics["poses_compared"] == 80
    assert len((run_dir / "trajectory.tum").read_text().splitlines()) == 81  # comment + one line per scan
    # a static scene mapped from the centre: structure found, no ghosts
    assert metrics["map"]["f1"] > 0.8 and metrics["map"]["ghost_area_m2"] < 0.05
    (run_dir / "metrics.json").unlink()
    code, out, err = cli(capsys, "eval", str(run_dir), "--gt", str(sim_dir), "--json")
    assert code == 0, err
    again = json.loads(out)
    assert again["ate_rmse_m"] == pytest.approx(metrics["ate_rmse_m"], abs=1e-6)
    assert again["map"]["f1"] == pytest.approx(metrics["map"]["f1"], abs=0.02)  # PGM+log-odds vs in-memory map
    assert (run_dir / "metrics.json").exists()


def test_run_options_reach_the_config(tmp_path, capsys):
    code, _, err = cli(capsys, "run", "sim:static", "--duration", "1", "--map-resolution", "0.1", "--update-angle",
                       "0.1",
                       "--out", str(tmp_path / "r"), "-q")
    assert code == 0, err
    cfg = yaml.safe_load((tmp_path / "r" / "config.yaml").read_text())
    assert cfg["slam"]["map_resolution"] == 0.1 and cfg["slam"]["map_update_angle_thresh"] == 0.1
    assert yaml.safe_load((tmp_path / "r" / "map.yaml").read_text())["resolution"] == 0.1


def test_bad_config_and_unknown_scenario_are_clear(tmp_path, capsys):
    bad = tmp_path / "c.yaml"
    bad.write_text("slam:\n  map_resolution: 0\n")
    code, _, err = cli(capsys, "run", "sim:static", "--config", str(bad), "--out", str(tmp_path / "r"))
    assert code == 2 and "c.yaml" in err and "map_resolution" in err
    code, _, err = cli(capsys, "run", "sim:nope", "--out", str(tmp_path / "r2"))
    assert code == 2 and "paper" in err
    assert not (tmp_path / "r").exists() and not (tmp_path / "r2").exists()


REAL_SCAN_FILES = {
    "mit-csail/mit-csail.clf": 1988,
    "intel/intel-lab.flirtlib.log": 2672,
    "intel/intel-corrected.log.gz": 910,
    "fr079/fr079.flirtlib.log": 1464,
    "fr079/freiburg-079-corrected.log.gz": 4791,
    "aces/aces-corrected.log.gz": 440,
    "freiburg-campus/freiburg-campus-corrected.log.gz": 2008,
    "dynamic/datmo/intersection.bag": 85,
    "dynamic/datmo/two_robots.bag": 388,
    "dynamic/leg_tracker/demo_stationary_simple_environment.bag": 1265,
    "dynamic/leg_tracker/positive_1.bag": 400,
    "dynamic/leg_tracker/positive_1_extracted.bag": 197,
}


@pytest.mark.parametrize("relative, count", sorted(REAL_SCAN_FILES.items()))
def test_info_opens_every_real_dataset(capsys, relative, count):
    from conftest import shared_file

    path = shared_file(relative)
    code, out, err = cli(capsys, "info", str(path), "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["scans"] == count
    assert data["last_stamp"] > data["first_stamp"]


def test_run_writes_a_bag_for_rviz_and_foxglove(tmp_path, capsys):
    from dynslam2d.io.rosbag import list_topics

    bag = tmp_path / "out.mcap"
    code, out, err = cli(capsys, "run", "sim:paper", "--duration", "2", "--out", str(tmp_path / "r"), "--write-bag",
                         str(bag))
    assert code == 0, err
    topics = list_topics(bag)
    assert topics["/scan_filtered"] == "sensor_msgs/msg/LaserScan"
    assert topics["/map"] == "nav_msgs/msg/OccupancyGrid"
    assert topics["/tracks"] == "visualization_msgs/msg/MarkerArray"
    assert {"/scan", "/slam_pose", "/tf"} <= set(topics)
    code, _, err = cli(capsys, "info", str(bag), "--topic", "/scan_filtered", "--json")
    assert code == 0, err


def test_viewer_without_the_extra_says_how_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r"), "--viewer", "rerun")
    assert code == 2
    assert 'pip install "dynslam2d[viewer]"' in err


def test_run_animate_writes_all_figures(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "2", "--animate", "--frame-step", "10", "--out",
                       str(out), "-q")
    assert code == 0, err
    for name in ("map.png", "tracks.png", "errors.png", "run.gif"):
        assert (out / name).stat().st_size > 5_000, name
    with Image.open(out / "run.gif") as gif:
        assert gif.n_frames == 5  # 40 scans at step 10: scans 0, 10, 20, 30 and the last one, 39
