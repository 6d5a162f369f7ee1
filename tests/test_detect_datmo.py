"""Tracking the red car of the datmo bags against motion capture (issue 4; DATMO: Konstantinidis et al. 2020).

DATMO's own logic (its published evaluation on these bags): centre RMSE 0.125 / 0.134 / 0.176 / 0.112 m on overtakes /
overtake_ego / overtake_red / parallel and 0.463 m on intersection, with up to 12 identity
changes. Errors include the offset of the mocap marker from the car's centre (≈0.08 m along the
car on parallel, where the car's length is fully seen).
"""

from __future__ import annotations

import pytest
from conftest import shared_file

from dynslam2d.eval.tracking import DATMO_RMSE, evaluate_datmo_bag

#: Regression bounds: measured value + a small margin (measured: 0.118, 0.111, 0.161, 0.093, 0.156;
#: intersection has only ≈34 matched scans, so one stray match moves it). A broken detector or
#: tracker gives 0.3 m and more.
BOUNDS = {"overtakes": 0.125, "overtake_ego": 0.12, "overtake_red": 0.17, "parallel": 0.105, "intersection": 0.26}


@pytest.mark.parametrize("bag", sorted(BOUNDS))
def test_red_car_centre_speed_and_identity(bag: str) -> None:
    path = shared_file(f"dynamic/datmo/{bag}.bag")
    (r,) = evaluate_datmo_bag(path)
    assert r.target == "/red_pose" and r.datmo_rmse == DATMO_RMSE[bag]
    assert r.rmse_center <= BOUNDS[bag], r.row()
    assert r.rmse_center < DATMO_RMSE[bag], r.row()  # beat DATMO's own logic
    assert r.median_speed_error <= 0.25, r.row()  # DATMO: 0.09–0.16, 0.57 on intersection
    assert r.id_switches <= 2, r.row()  # DATMO: 0–12
    if bag != "intersection":  # there the car is mostly out of reach (≤ 2 beams) until scan 35
        assert r.n_matched >= 0.95 * r.n_with_truth, r.row()
    else:
        assert r.n_matched >= 25, r.row()


def test_two_robots_bag_uses_mocap_ego_and_both_robots() -> None:
    path = shared_file("dynamic/datmo/two_robots.bag")
    rows = evaluate_datmo_bag(path)
    assert [r.target for r in rows] == ["/robot_1", "/robot_2"]
    for r in rows:
        assert r.n_matched >= 0.95 * r.n_with_truth and r.rmse_center <= 0.2, r.row()
