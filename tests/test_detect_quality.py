"""Detection and tracking quality against simulator ground truth (issue 4).

Definitions of every number are in :mod:`dynslam2d.eval.tracking`. Scenes are shortened to 20 s
(ground-truth laser poses in the first-scan frame, as SLAM would give them).
"""

from __future__ import annotations

import math

import pytest

from dynslam2d.eval.tracking import SimTrackingResult, evaluate_sim

DURATION = 20.0


@pytest.fixture(scope="module")
def results() -> dict[str, SimTrackingResult]:
    return {scene: evaluate_sim(scene, duration=DURATION) for scene in ("paper", "crowd", "corridor", "static")}


@pytest.mark.parametrize("scene", ["paper", "crowd", "corridor"])
def test_dynamic_points_recall_and_precision(results: dict[str, SimTrackingResult], scene: str) -> None:
    r = results[scene]
    assert r.n_dynamic_truth > 5000  # the scene really has moving objects to find
    assert r.recall >= 0.95, r.row()
    assert r.precision >= 0.95, r.row()
    assert r.static_tracks_in_m == 0, r.row()


@pytest.mark.parametrize("scene", ["paper", "crowd", "corridor"])
def test_centre_and_speed_of_confirmed_mover_tracks(results: dict[str, SimTrackingResult], scene: str) -> None:
    r = results[scene]
    assert r.n_matched > 300
    assert r.median_center_error <= 0.05, r.row()
    assert r.median_speed_error <= 0.10, r.row()


def test_identity_switches_are_counted_and_few(results: dict[str, SimTrackingResult]) -> None:
    # measured (20 s): paper 1, crowd 28 (six people crossing), corridor 2
    assert results["paper"].id_switches <= 5
    assert results["corridor"].id_switches <= 8
    assert results["crowd"].id_switches <= 60


def test_static_scene_with_rotating_robot_has_no_mover(results: dict[str, SimTrackingResult]) -> None:
    r = results["static"]
    assert r.tracks_ever_in_m == 0
    assert r.fp_beam_rate <= 0.001
    assert r.stats["detections"] > 500  # there were plenty of small static clusters to be fooled by
    assert math.isnan(r.recall) and r.n_flagged == 0


def test_slam_poses_if_available() -> None:
    """The same scoring with poses from the SLAM processor instead of ground truth (paper scene)."""
    slam = pytest.importorskip("dynslam2d.slam")
    if not hasattr(slam, "HectorSlam"):
        pytest.skip("dynslam2d.slam.HectorSlam not available yet")
    r = evaluate_sim("paper", duration=12.0, pose_source="slam")
    assert r.recall >= 0.9 and r.precision >= 0.9, r.row()
