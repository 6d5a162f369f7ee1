"""A run is evaluated once (issue 15 item 11): metrics.json, the figures and the printed table
share one RunEvaluation; nothing recomputes the ATE or the map cell sets, nothing reads the
written summary.json / metrics.json back."""

from __future__ import annotations

import io
import json
import re

from conftest import run_cli

import dynslam2d.eval.maps as eval_maps
import dynslam2d.eval.trajectory as eval_trajectory
from dynslam2d.config import Config
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import run as run_pipeline
from dynslam2d.results import ground_truth_for, metrics_json, write_outputs
from dynslam2d.slam.cleanup import CleanupRecorder


def _count_calls(monkeypatch, module, name: str) -> list[int]:
    """Wrap ``module.name`` (looked up as a module global by every caller) to count its calls."""
    calls = [0]
    original = getattr(module, name)

    def counted(*args, **kwargs):
        calls[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def test_run_with_ground_truth_scores_once_and_figures_draw_that_score(tmp_path, capsys, monkeypatch):
    # Every ATE goes through eval.trajectory.associate and every set of map cells through
    # eval.maps.comparison_grids, whoever calls them: count both during a whole 'dynslam2d run'.
    associations = _count_calls(monkeypatch, eval_trajectory, "associate")
    comparisons = _count_calls(monkeypatch, eval_maps, "comparison_grids")
    drawn: dict[str, object] = {}
    from dynslam2d.viz import errorsplot  # (viz.figures imports it where errors.png is drawn: pass mem51)

    plot_errors = errorsplot.plot_errors

    def spy_errors(path, ate_result, diff, **kwargs):
        drawn["ate"], drawn["diff"] = ate_result, diff
        return plot_errors(path, ate_result, diff, **kwargs)

    monkeypatch.setattr(errorsplot, "plot_errors", spy_errors)
    read: list[str] = []
    open_file = io.open

    def spy_open(file, mode="r", *args, **kwargs):
        if "r" in mode:
            read.append(str(file))
        return open_file(file, mode, *args, **kwargs)

    monkeypatch.setattr(io, "open", spy_open)  # pathlib's read_text / open go through io.open
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "run", "sim:paper", "--duration", "3", "--out", str(out_dir))
    monkeypatch.setattr(io, "open", open_file)
    assert code == 0, err
    # one ATE; cell sets for the cleaned map and the online map (clean-up is on by default), no more
    assert associations[0] == 1
    assert comparisons[0] == 2
    assert not [p for p in read if p.endswith(("summary.json", "metrics.json"))]
    metrics = json.loads((out_dir / "metrics.json").read_text())
    assert "map_online" in metrics and (out_dir / "errors.png").exists()
    # errors.png drew the evaluation metrics.json holds: the same ATE and the cleaned map's ghost cells
    assert drawn["ate"].rmse == metrics["ate_rmse_m"] and drawn["ate"].n == metrics["poses_compared"]
    assert drawn["diff"].n_ghost == metrics["map"]["ghost_cells"]
    # the table printed the same numbers
    row = re.search(r"ATE RMSE\s+([0-9.]+) m \((\d+) poses\)", out)
    assert row and float(row.group(1)) == round(metrics["ate_rmse_m"], 4) and int(row.group(2)) == 60
    assert f"{metrics['map']['f1']:.3f}" in re.search(r"precision / recall / F1\s+(.*)", out).group(1)


def test_write_outputs_returns_what_it_wrote(tmp_path):
    source = open_source("sim:static", seed=3, duration=1.5)
    cfg = Config()
    cleaner = CleanupRecorder(cfg.clean, cfg.slam)
    result = run_pipeline(source, cfg, observers=[cleaner])
    gt = ground_truth_for(source, None, cfg.slam.map_resolution)
    outputs = write_outputs(result, tmp_path, gt, cleaned=cleaner.result)
    assert outputs.paths["summary.json"] == tmp_path / "summary.json"
    assert metrics_json(outputs.summary) == (tmp_path / "summary.json").read_text()
    assert metrics_json(outputs.metrics) == (tmp_path / "metrics.json").read_text()
    ev = outputs.evaluation
    assert outputs.summary["ate_rmse_m"] == ev.ate.rmse == outputs.metrics["ate_rmse_m"]
    assert ev.map_online is not None and ev.cleanup == outputs.summary["cleanup"]
    # the cleaned map is "map", the online one "map_online", each counted from its own cell sets
    assert ev.map.metrics.n_estimate_occupied == int(ev.map.sets.estimate_occupied.sum())
    assert ev.map_online.metrics.n_estimate_occupied == int(ev.map_online.sets.estimate_occupied.sum())
    assert outputs.metrics["map"]["ghost_cells"] == int(ev.map.sets.ghost.sum())
