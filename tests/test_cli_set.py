"""``--set KEY=VALUE`` on ``run`` and ``experiment``: one config key from the command line."""

from __future__ import annotations

import json

import pytest
import yaml
from conftest import run_cli

from dynslam2d.config import Config, with_assignments
from dynslam2d.errors import DynSlamError


def test_assignments_apply_in_order_and_are_validated():
    cfg = with_assignments(Config(), ["detect.tracker.m_exit_time=3", "loop.enabled=off",
                                      "detect.tracker.m_exit_time=4.5"])
    assert cfg.detect.tracker.m_exit_time == 4.5  # the later assignment wins
    assert cfg.loop.enabled is False  # YAML 'off'
    assert with_assignments(Config(), []) == Config()
    for spec, words in (("detect.trackr.x=3", "has no key 'trackr'"), ("detect.tracker=3", "is a section"),
                        ("detect.tracker.m_exit_time", "expected KEY=VALUE"),
                        ("detect.tracker.m_exit_time=[1", "not valid YAML"),
                        ("detect.tracker.m_exit_time=abc", "m_exit_time")):
        with pytest.raises(DynSlamError, match=words.replace("[", r"\[")):
            with_assignments(Config(), [spec])


def test_run_set_reaches_config_yaml_and_named_options_win(tmp_path, capsys):
    out = tmp_path / "r"
    code, _, err = run_cli(capsys, "run", "sim:paper-1", "--duration", "2", "-o", str(out), "-q",
                           "--set", "detect.tracker.m_exit_time=3", "--set", "slam.map_resolution=0.1",
                           "--map-resolution", "0.05")
    assert code == 0, err
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    assert cfg["detect"]["tracker"]["m_exit_time"] == 3.0
    assert cfg["slam"]["map_resolution"] == 0.05  # the named option is applied after --set
    code, _, err = run_cli(capsys, "run", "sim:paper-1", "-o", str(tmp_path / "bad"), "--set", "slam.nope=1")
    assert code != 0 and "slam has no key 'nope'" in err and not (tmp_path / "bad").exists()


def test_experiment_set_changes_every_cell(tmp_path, capsys):
    # v_min = 100 m/s: no track ever enters M, so no filter mode removes a beam and every row equals 'none'.
    out = tmp_path / "e"
    code, text, err = run_cli(capsys, "experiment", "paper", "--trial", "paper-1", "--duration", "3", "--out",
                              str(out), "--json", "--set", "detect.tracker.v_min=100")
    assert code == 0, err
    rows = json.loads(text)["rows"]
    assert [r["config"] for r in rows] == ["none", "fixed", "adaptive", "box"]
    assert all(r["removal_recall"] == 0.0 and r["iou"] == rows[0]["iou"] for r in rows)
    assert yaml.safe_load((out / "config.yaml").read_text())["detect"]["tracker"]["v_min"] == 100.0
    code, _, err = run_cli(capsys, "experiment", "paper", "--out", str(tmp_path / "e2"), "--set", "filter.mode=box")
    assert code != 0 and "runs every filter mode itself" in err
