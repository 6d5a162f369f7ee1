"""eval foreground: beams in front of the per-beam median background of a motionless sensor."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.cli import main
from dynslam2d.errors import DynSlamError
from dynslam2d.eval.foreground import evaluate_foreground, foreground_mask, foreground_removal
from dynslam2d.inputs import open_source
from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.sim import Circle, Mover, Scenario, oscillating_in_place, ping_pong, simulate
from dynslam2d.sim.scenarios import _build_world
from dynslam2d.sim.sensor import LidarModel


@pytest.fixture(scope="module")
def sim():
    """A motionless 360° laser at (−3, 0) in a 10×8 m room, 6 m reach: beams towards the far
    wall (8 m) usually return nothing; a person walks back and forth 2 m in front of it."""
    world = _build_world([(-5.0, -4.0), (5.0, -4.0), (5.0, 4.0), (-5.0, 4.0)], [])
    walker = Mover(1, "walker", Circle(0.22), ping_pong([(-1.0, -3.0), (-1.0, 3.0)], 1.0, heading=None))
    robot = oscillating_in_place(-3.0, 0.0, 0.0, 0.0, 1.0)
    lidar = LidarModel(beams=360, rate_hz=10.0, range_max=6.0)
    return simulate(Scenario("fg-test", "", world, (walker,), robot, lidar, 12.0, 4))


def _mask(sim):
    lab = sim.ground_truth.labels
    removed = (lab == 1) & (np.arange(lab.shape[0]) % 2 == 0)[:, None]
    removed[3, np.flatnonzero(lab[3] == 0)[:7]] = True
    return removed


def test_foreground_is_the_person_in_front_of_the_background(sim):
    lab = sim.ground_truth.labels
    fg, valid, stable = foreground_mask(sim.scans)
    assert np.array_equal(valid, lab >= 0)
    on_stable = stable[None, :]
    # every person beam with a wall behind it is foreground, nothing else is
    assert np.array_equal(fg, (lab == 1) & on_stable)
    assert ((lab == 1) & ~on_stable).sum() > 50  # and some person beams have only open space behind
    m = foreground_removal(sim.scans, _mask(sim), sim.ground_truth.stamps)
    removed = _mask(sim)
    assert m.foreground_beams == int(fg.sum())
    assert m.foreground_removed == int((removed & fg).sum())
    assert m.foreground_removed_share == m.foreground_removed / m.foreground_beams
    assert 0.4 < m.foreground_removed_share < 0.6
    assert (m.background_removed, m.background_beams) == (7, int(((lab == 0) & on_stable).sum()))
    assert m.rare_removed == int((removed & (lab >= 0) & ~on_stable).sum()) > 0
    assert m.scans_with_foreground == int((fg.sum(axis=1) >= 5).sum())


def test_cli_and_file_inputs(sim, tmp_path, capsys):
    bag = write_scan_bag(tmp_path / "rec.bag", sim.scans)
    run = tmp_path / "run"
    run.mkdir()
    removed = _mask(sim)
    # a run that skipped scan 0: the row is left out
    np.savez_compressed(run / "kept_mask.npz", stamps=sim.ground_truth.stamps[1:], removed=removed[1:])
    old, sys.argv = sys.argv, ["dynslam2d", "eval", "foreground", str(bag), str(run), "--json"]
    try:
        with pytest.raises(SystemExit) as exc:
            main()
    finally:
        sys.argv = old
    assert exc.value.code in (0, None)
    data = json.loads(capsys.readouterr().out)
    full = foreground_removal(sim.scans, removed, sim.ground_truth.stamps)
    assert data["scans"] == len(sim.scans) - 1 and data["background_removed"] == 7
    first_fg = int((removed[0] & (sim.ground_truth.labels[0] == 1)).sum())
    assert data["foreground_removed"] == full.foreground_removed - first_fg
    shifted = tmp_path / "other"
    shifted.mkdir()
    np.savez_compressed(shifted / "kept_mask.npz", stamps=sim.ground_truth.stamps + 0.01, removed=removed)
    with pytest.raises(DynSlamError, match="no scan of the recording has a stamp in the run"):
        evaluate_foreground(bag, shifted)
    np.savez_compressed(shifted / "kept_mask.npz", stamps=sim.ground_truth.stamps, removed=removed[:, :10])
    with pytest.raises(DynSlamError, match="360 beams"):
        evaluate_foreground(bag, shifted)


@pytest.mark.parametrize("name, with_fg", [("demo_stationary_simple_environment", 1006), ("positive_1", 204)])
def test_real_stationary_bags_match_the_data_readme(name, with_fg):
    """The data README's own count of scans with ≥ 5 foreground beams."""
    bag = shared_file(f"dynamic/leg_tracker/{name}.bag")
    scans = list(open_source(bag))
    fg, _, _ = foreground_mask(scans)
    assert int((fg.sum(axis=1) >= 5).sum()) == with_fg
