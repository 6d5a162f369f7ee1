"""The full pipeline: matching with movers removed, tracking in the map frame, filtering, mapping."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from dynslam2d.config import Config, with_overrides
from dynslam2d.experiments import run_experiment, write_experiment
from dynslam2d.pipeline import TRACK_COLUMNS, Pipeline, run
from dynslam2d.results import evaluate, ground_truth_for, write_results
from dynslam2d.sim import SimSource


@pytest.fixture(scope="module")
def paper_runs():
    source = SimSource("paper", duration=15.0)
    sim = source.simulation
    gt = ground_truth_for(source, None, 0.05)
    out = {}
    for mode in ("none", "default"):
        res = run(sim.source(), with_overrides(Config(), {"filter": {"mode": mode}}))
        out[mode] = (res, evaluate(res.trajectory, res.grid, gt, res.removed, res.trajectory.stamps))
    return sim, gt, out


def test_default_filter_removes_movers_and_keeps_walls(paper_runs):
    _, _, runs = paper_runs
    removal = runs["default"][1]["removal"]
    assert removal["recall"] >= 0.90
    assert removal["precision"] >= 0.95
    assert removal["static_removed_share"] <= 0.02
    assert runs["none"][0].removed.sum() == 0


def test_filtering_cleans_the_map(paper_runs):
    _, _, runs = paper_runs
    raw, clean = runs["none"][1]["map"], runs["default"][1]["map"]
    assert raw["ghost_area_m2"] > 0.1  # the movers leave ghost walls in the raw map
    assert clean["ghost_area_m2"] < 0.3 * raw["ghost_area_m2"]
    assert clean["weighted_rmse"] < raw["weighted_rmse"]
    assert clean["f1"] > raw["f1"]


def test_removed_beams_are_attributed_to_tracks_in_m(paper_runs):
    sim, _, _ = paper_runs
    pipe = Pipeline()
    attributed = 0
    for scan in sim.scans[:200]:
        step = pipe.process(scan)
        ids_in_m = {t.id for t in step.tracks if t.in_m}
        assert step.removed.shape == (scan.n_beams,)
        assert set(np.unique(step.removed_by[step.removed])) <= ids_in_m
        assert (step.removed_by[~step.removed] == -1).all()
        attributed += int(step.removed.sum())
        assert set(step.timings) == {"match", "track", "filter", "map_update", "loops", "total"}
    assert attributed > 0


def test_results_folder_holds_tracks_and_kept_mask(paper_runs, tmp_path):
    sim, gt, runs = paper_runs
    res = runs["default"][0]
    paths = write_results(res, tmp_path, gt)
    with np.load(paths["kept_mask.npz"]) as npz:
        assert npz["removed"].shape == (len(sim.scans), sim.scans[0].n_beams)
        assert npz["removed"].dtype == bool
        np.testing.assert_allclose(npz["stamps"], [s.stamp for s in sim.scans])
    with open(paths["tracks.csv"], newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == TRACK_COLUMNS + ("remembered",)
    assert any(r[10] == "1" for r in rows[1:])  # some track is in M
    metrics = json.loads(paths["metrics.json"].read_text())
    assert metrics["removal"]["recall"] == pytest.approx(runs["default"][1]["removal"]["recall"])


def test_static_scene_with_a_rotating_robot_removes_nothing():
    res = run(SimSource("static", duration=15.0))
    assert res.removed.mean() < 0.001
    assert not any(row[-1] for row in res.track_rows)


def test_shortened_paper_trial_filtering_lowers_ghost_area_and_weighted_rmse(tmp_path):
    result = run_experiment(("paper-1",), ("none", "default"), duration=15.0)
    rows = {r["config"]: r for r in result.rows}
    assert rows["default"]["ghost_area_m2"] < rows["none"]["ghost_area_m2"]
    assert rows["default"]["weighted_rmse"] < rows["none"]["weighted_rmse"]
    paths = write_experiment(result, tmp_path)
    assert set(paths) == {"table.md", "table.csv", "table.json", "figure2.png"}
    assert "| paper-1 | default |" in paths["table.md"].read_text()
    import matplotlib.image as mpimg

    img = mpimg.imread(paths["figure2.png"])
    assert img.shape[1] > 600 and img.shape[0] > 300
