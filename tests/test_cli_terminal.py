"""The command line at a terminal and in a pipe: help, full-width plain output, --json, argument order."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.types import Scan

SRC = str(Path(__file__).resolve().parents[1] / "src")


def sh(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``dynslam2d ARGS`` with stdout and stderr to pipes (not a terminal), COLUMNS=80."""
    env = {**os.environ, "PYTHONPATH": SRC, "COLUMNS": "80"}
    env.pop("FORCE_COLOR", None)
    return subprocess.run([sys.executable, "-m", "dynslam2d", *args], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=600)


def test_bare_command_prints_help_on_stdout_with_exit_0():
    r = sh()
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("Usage: ") and "Commands:" in r.stdout
    assert r.stderr == ""
    sub = sh("config")
    assert sub.returncode == 0 and "dump" in sub.stdout


def test_dash_h_is_help_everywhere_and_usage_names_arguments_in_capitals():
    for args in ((), ("info",), ("run",), ("eval",), ("eval", "ate"), ("config", "dump"), ("experiment", "paper")):
        r = sh(*args, "-h")
        assert r.returncode == 0, (args, r.stderr)
        assert r.stdout.startswith("Usage: "), args
    info = sh("info", "-h").stdout
    assert "info [OPTIONS] INPUT" in info and "{input}" not in info
    assert "eval ate [OPTIONS] REFERENCE ESTIMATE" in sh("eval", "ate", "-h").stdout


def test_command_summaries_are_whole_sentences():
    top = sh("-h").stdout
    assert "..." not in top.split("Commands:")[1]
    # the whole first sentence of run's docstring, possibly wrapped over two lines
    assert "Hector-style SLAM." in " ".join(top.split())
    ev = sh("eval", "-h").stdout
    assert "..." not in ev.split("Commands:")[1]
    assert "(Kümmerle et al., 2009)." in " ".join(ev.split())
    # the short form 'eval RUN_DIR --gt GT_DIR' is visible in the usage line and explained
    assert "eval [OPTIONS] RUN_DIR --gt GT_DIR | COMMAND" in ev
    assert "is short for 'dynslam2d eval run RUN_DIR --gt GT_DIR'" in " ".join(ev.split())


def test_piped_tables_are_plain_and_full_width():
    r = sh("simulate", "--list")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == "scenarios"
    assert not any(ch in r.stdout for ch in "│┃━─…")  # no box drawing, nothing cut
    paper = next(line for line in lines if line.startswith("paper "))
    # the longest description stays whole on one line, beyond 80 columns
    assert paper.endswith("0.1×2 bar on an L") and len(paper) > 80
    names = [line.split()[0] for line in lines[2:]]
    assert "long-corridor" in names and "stop-and-go" in names


def test_piped_long_title_is_not_broken(tmp_path):
    deep = tmp_path / ("a_rather_long_folder_name_for_a_recording_" * 2)
    deep.mkdir()
    scans = [Scan(stamp=100.0 + 0.1 * i, angle_min=-np.pi / 2, angle_increment=np.pi / 90,
                  ranges=np.full(90, 2.0 + i), range_min=0.1, range_max=10.0) for i in range(5)]
    bag = write_scan_bag(deep / "s.mcap", scans)
    r = sh("info", str(bag))
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == str(bag)  # the title: one line, the whole path
    assert any(line.startswith("scans") and line.rstrip().endswith("5") for line in r.stdout.splitlines())


def test_json_where_tables_are_printed(tmp_path):
    r = sh("simulate", "--list", "--json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert {"paper", "static", "crowd"} <= {row["name"] for row in rows}
    assert next(row for row in rows if row["name"] == "static")["duration_s"] == 40
    cfg = json.loads(sh("config", "dump", "--json").stdout)
    assert cfg["slam"]["map_resolution"] == pytest.approx(0.05)


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory):
    """A short simulated scene and a run of it (3 s of the static room)."""
    d = tmp_path_factory.mktemp("term")
    made = sh("simulate", "static", "--duration", "3", "--out", str(d / "sim"), "--json")
    assert made.returncode == 0, made.stderr
    info = json.loads(made.stdout)
    assert info["scans"] == 60 and Path(info["files"]["scans"]).name == "scans.mcap"
    r = sh("run", str(d / "sim" / "scans.mcap"), "--gt", str(d / "sim"), "--out", str(d / "run"), "--quiet",
           "--filter", "default")  # the old name of the filter mode 'box'
    assert r.returncode == 0, r.stderr
    return d


def test_eval_ate_says_whether_it_aligns_and_catches_swapped_arguments(sim_run):
    ref, run = sim_run / "sim" / "gt_trajectory.tum", sim_run / "run"
    aligned = sh("eval", "ate", str(ref), str(run))
    assert aligned.returncode == 0, aligned.stderr
    assert "SE(2), as evo_ape -a" in aligned.stdout
    raw = sh("eval", "ate", str(ref), str(run), "--no-align", "--json")
    assert json.loads(raw.stdout)["aligned"] is False
    assert "as evo_ape without -a" in sh("eval", "ate", str(ref), str(run), "--no-align").stdout
    swapped = sh("eval", "ate", str(run), str(ref))
    assert swapped.returncode == 2
    assert "arguments look swapped" in swapped.stderr and "--ref-topic" not in swapped.stderr
    bag_last = sh("eval", "rpe", str(run / "trajectory.tum"), str(sim_run / "sim" / "scans.mcap"))
    assert bag_last.returncode == 2 and "arguments look swapped" in bag_last.stderr


def test_eval_rpe_takes_a_bag_reference_with_ref_topic(sim_run):
    """The simulator's bag holds /odom (base_link odometry, laser 0.15 m ahead): the CLI's RPE against it
    is the library's RPE against that topic moved to the laser, and the offset matters."""
    from dynslam2d.eval.reference import load_reference
    from dynslam2d.eval.trajectory import rpe
    from dynslam2d.io.trajectory import read_tum
    from dynslam2d.types import Pose2D

    bag, run = sim_run / "sim" / "scans.mcap", sim_run / "run"
    r = sh("eval", "rpe", str(bag), str(run), "--ref-topic", "/odom", "--sensor-offset", "0.15", "0", "0", "--json")
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)["translation_m"]["rmse"]
    want = rpe(load_reference(bag, "/odom", Pose2D(0.15, 0.0, 0.0)), read_tum(run / "trajectory.tum"),
               delta=1, delta_unit="frames", max_dt=0.01).trans.rmse
    assert got == pytest.approx(want, rel=1e-9) and got > 0
    at_base = json.loads(sh("eval", "rpe", str(bag), str(run), "--ref-topic", "/odom", "--json").stdout)
    assert at_base["translation_m"]["rmse"] > 1.5 * got  # the yawing robot's base moves differently from its laser
    no_topic = sh("eval", "rpe", str(bag), str(run))
    assert no_topic.returncode == 2 and "--ref-topic" in no_topic.stderr


def test_filter_mode_default_is_an_alias_of_box(sim_run, tmp_path):
    from dynslam2d.config import Config, load_config, with_overrides

    summary = json.loads((sim_run / "run" / "summary.json").read_text())
    assert summary["filter"] == "box"  # run with --filter default
    assert with_overrides(Config(), {"filter": {"mode": "default"}}) == Config()
    assert Config().filter.mode == "box"
    f = tmp_path / "old.yaml"
    f.write_text("filter:\n  mode: default\n  margin: 0.3\n")
    cfg = load_config(f)
    assert cfg.filter.mode == "box" and cfg.filter.margin == pytest.approx(0.3)
    assert "box (ours" in " ".join(sh("run", "-h").stdout.split())


# --- config dump: commented YAML, hector_mapping names, one family of names --------------------------


def test_commented_dump_round_trips_to_the_same_config(tmp_path):
    import yaml

    from dynslam2d.config import Config, dump_config, load_config

    custom = tmp_path / "custom.yaml"
    custom.write_text("slam:\n  map_resolution: 0.1\n  covariance_sigma: 0.5\ndetect:\n  tracker:\n"
                      "    free_ref_ages: [0.2, 0.9, 1.5]\nfilter:\n  mode: adaptive\n")
    r = sh("config", "dump", "--config", str(custom))
    assert r.returncode == 0, r.stderr
    back = tmp_path / "back.yaml"
    back.write_text(r.stdout)
    want = load_config(custom)
    assert want != Config() and load_config(back) == want
    assert load_config(back).detect.tracker.free_ref_ages == (0.2, 0.9, 1.5)
    assert yaml.safe_load(dump_config(Config())) == yaml.safe_load(dump_config(Config(), comments=False))
    text = r.stdout
    assert text.startswith("# dynslam2d configuration")
    lines = text.splitlines()

    def comment_above(key: str) -> str:
        i = next(i for i, line in enumerate(lines) if line.strip().startswith(f"{key}:"))
        j = i
        while lines[j - 1].strip().startswith("#"):
            j -= 1
        return " ".join(line.strip().lstrip("# ") for line in lines[j:i])

    assert "hector_mapping: map_update_distance_thresh" in comment_above("map_update_distance_thresh")
    assert "option: --map-update-distance-thresh (or --update-distance)" in comment_above("map_update_distance_thresh")
    assert ", m " in comment_above("map_update_distance_thresh")  # the unit
    assert "hector_mapping: map_multi_res_levels" in comment_above("map_levels")
    assert "hector_mapping: laser_min_dist" in comment_above("laser_min_dist")
    assert "(paper Eq. 1" in comment_above("mode")  # the first 'mode' is detect.segment.mode
    assert "option: --filter-mode (or --filter)" in " ".join(line.strip().lstrip("# ") for line in lines)


def test_hector_mapping_names_are_accepted_in_config(tmp_path):
    from dynslam2d.config import load_config
    from dynslam2d.errors import DynSlamError

    flat = tmp_path / "hector.yaml"  # a hector_mapping parameter file: flat ROS names
    flat.write_text("map_resolution: 0.1\nmap_multi_res_levels: 2\nmap_update_distance_thresh: 0.2\n"
                    "laser_max_dist: 12.0\nfilter:\n  mode: none\n")
    cfg = load_config(flat)
    assert (cfg.slam.map_resolution, cfg.slam.map_levels) == (0.1, 2)
    assert cfg.slam.map_update_distance_thresh == 0.2 and cfg.slam.laser_max_dist == 12.0
    assert cfg.filter.mode == "none"
    nested = tmp_path / "nested.yaml"
    nested.write_text("slam:\n  map_multi_res_levels: 4\n")
    assert load_config(nested).slam.map_levels == 4
    both = tmp_path / "both.yaml"
    both.write_text("map_multi_res_levels: 2\nslam:\n  map_levels: 3\n")
    with pytest.raises(DynSlamError, match="map_multi_res_levels.*slam.map_levels"):
        load_config(both)
    r = sh("config", "dump", "--config", str(flat), "--json")
    assert json.loads(r.stdout)["slam"]["map_levels"] == 2


def test_run_options_are_the_config_keys_with_dashes():
    import typer.main

    from dynslam2d.cli import app
    from dynslam2d.config import RUN_OPTIONS, Config

    run = typer.main.get_command(app).commands["run"]
    names = {opt for p in run.params for opt in (*p.opts, *p.secondary_opts)}
    data = Config().model_dump()
    for key, (flag, short) in RUN_OPTIONS.items():
        stage, field = key.split(".")
        assert field in data[stage], key
        assert flag == "--" + (field if stage == "slam" else f"{stage}-{field}").replace("_", "-"), key
        assert flag in names and (short is None or short in names), key


# --- first run: compiling kernels, steady-state speed ---------------------------------------------------


def test_cold_numba_cache_is_announced(tmp_path):
    """With an empty numba cache every kernel must compile: the run says so before it starts."""
    env = {**os.environ, "PYTHONPATH": SRC, "NUMBA_CACHE_DIR": str(tmp_path / "empty-cache")}
    code = ("import dynslam2d.pipeline, sys\n"
            "from dynslam2d.jitcache import kernel_cache_state\n"
            "from dynslam2d.cli import _say_if_compiling\n"
            "s = kernel_cache_state()\n"
            "_say_if_compiling(True, s.cold)\n"
            "print(s.total, s.cached, s.cold)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    total, cached, cold = r.stdout.split()
    assert int(total) >= 20 and int(cached) == 0 and cold == "True"
    assert "compiling kernels (first run only" in r.stderr


def test_a_compiling_run_suggests_the_kernels_built_ahead_of_time(capsys):
    """After a run that compiled (JIT), one line points to `dynslam2d kernels build`; after a warm run, none."""
    from dynslam2d import cli

    cli._suggest_kernel_build(False)
    assert capsys.readouterr().err == ""
    cli._suggest_kernel_build(True)
    err = " ".join(capsys.readouterr().err.split())
    assert "dynslam2d kernels build" in err and "docs/kernels.md" in err


def test_warm_cache_is_not_cold_and_summary_reports_steady_speed(sim_run):
    import importlib

    from dynslam2d.jitcache import kernel_cache_state

    importlib.import_module("dynslam2d.pipeline")  # loads every kernel module
    from dynslam2d.pipeline import _steady_speed

    state = kernel_cache_state()  # the fixture's run compiled (or loaded) the kernels into the default cache
    assert state.total >= 20 and not state.cold
    summary = json.loads((sim_run / "run" / "summary.json").read_text())
    med = summary["steady_ms_median"]  # rounded to 3 decimals; scans/s is 1000 / the unrounded median
    assert summary["steady_scans_per_s"] == pytest.approx(1e3 / med, abs=1e3 * 5e-4 / (med * (med - 5e-4)) + 0.01)
    assert summary["first_scan_ms"] > 0 and summary["scans_per_s"] > 0
    # a first scan of 5 s (compiling), then 10 ms scans: steady 100 scans/s whatever the first scans cost
    fake = np.array([5000.0, 900.0, 40.0] + [10.0] * 40 + [12.0] * 5)
    s = _steady_speed(fake)
    assert s["first_scan_ms"] == 5000.0 and s["steady_ms_median"] == 10.0 and s["steady_scans_per_s"] == 100.0
    assert _steady_speed(np.zeros(0))["steady_scans_per_s"] is None


def test_cache_state_counts_the_kernels_a_run_needs_not_the_references_kept_for_tests():
    """Kernels no run calls from Python (``report_boxes``, ``manage_rows``: the tests' references of the merged
    kernels) stay uncompiled after every run; counted, they made a warm cache look cold (a second README run said
    "compiling kernels" and started the background compile)."""
    import importlib

    from dynslam2d.jitcache import kernel_cache_state
    from dynslam2d.jitmanifest import KERNELS

    importlib.import_module("dynslam2d.pipeline")
    needed = {k for k, _ in KERNELS}
    refs = {"dynslam2d.detect.kernels.report_boxes", "dynslam2d.detect.kernels.manage_rows"}
    assert not refs & needed
    assert kernel_cache_state(needed=frozenset(refs)).total == 2
    every = kernel_cache_state(needed=frozenset())
    run = kernel_cache_state()
    assert 20 <= run.total <= len(needed) and every.total >= run.total + len(refs)


def test_terminal_table_keeps_its_title_on_one_line():
    import io

    from rich.console import Console
    from rich.table import Table

    from dynslam2d.cli import _show

    buf = io.StringIO()
    con = Console(file=buf, force_terminal=True, width=100, color_system=None)
    title = "RPE (delta 1 frames) results/some-run-folder vs ground/truth/trajectory.tum"
    t = Table(title=title, show_header=False)
    t.add_column()
    t.add_column(justify="right")
    t.add_row("pairs", "59")
    _show(t, con)
    out = buf.getvalue().splitlines()
    assert out[0].rstrip() == title  # longer than the table, still whole
    assert "│ pairs │ 59 │" in buf.getvalue()


def test_experiment_json_names_the_filter_box(tmp_path):
    r = sh("experiment", "paper", "--trial", "paper-1", "--duration", "3", "--out", str(tmp_path / "exp"), "--json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)["rows"]
    assert [row["config"] for row in rows] == ["none", "fixed", "adaptive", "box"]
    assert "| paper-1 | box |" in (tmp_path / "exp" / "table.md").read_text()
