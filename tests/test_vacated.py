"""Vacated footprints: a parked object's outline that the scan sees through yields to the map evidence
(detect/mapevidence.py, docs/maps.md "Vacated footprints")."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.config import Config
from dynslam2d.detect.mapevidence import MapView, VacatedHistory, map_evidence, vacated_outlines, yielding_view
from dynslam2d.pipeline import run
from dynslam2d.results import compute_metrics, ground_truth_for
from dynslam2d.sim import Mover, Rect, Scenario, oscillating_in_place, timeline
from dynslam2d.sim.scenarios import _build_world
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.simulation import SimSource
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.cleanup import scan_clearing
from dynslam2d.types import Pose2D

RES = 0.05


def _geo(r: np.ndarray, a: np.ndarray, valid: np.ndarray) -> tuple:
    """The clearing geometry of a scan from the laser at the origin, heading 0 (slam.cleanup.scan_clearing)."""
    return scan_clearing(r, a, valid, Pose2D(0.0, 0.0, 0.0), RES, CleanConfig())


def _map() -> MapView:
    """Free floor from −7.5 to 7.5 m; long-occupied: a car's outline x 1…5, y 2…3.8 m, a 14 m wall along
    y = −5 m."""
    lo = np.full((300, 300), -2.0, dtype=np.float32)  # cell (i, j) at (i, j) · 0.05 m, i0 = j0 = −150

    def cell(v: float) -> int:
        return int(np.floor(v / RES + 0.5)) + 150

    lo[cell(2.0), cell(1.0):cell(5.0) + 1] = 8.0
    lo[cell(3.8), cell(1.0):cell(5.0) + 1] = 8.0
    lo[cell(2.0):cell(3.8) + 1, cell(1.0)] = 8.0
    lo[cell(2.0):cell(3.8) + 1, cell(5.0)] = 8.0
    lo[cell(-5.0), cell(-7.0):cell(7.0) + 1] = 8.0
    return MapView(lo, -150, -150, RES)


def _scan() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 720-beam scan from (0, 0) after the car left, with the wall found 0.3 m farther than
    mapped (as pose error would show it): beams end on y = 6 m above and y = −5.3 m below."""
    a = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    s = np.sin(a)
    with np.errstate(divide="ignore"):
        r = np.where(s > 0.05, 6.0 / s, np.where(s < -0.05, 5.3 / -s, np.nan))
    r = np.where(r <= 20.0, r, np.nan)
    return r, a, np.isfinite(r)


def test_a_seen_through_outline_yields_and_a_wall_does_not():
    view = _map()
    r, a, valid = _scan()
    vac = vacated_outlines(view, *_geo(r, a, valid), occupied_logodds=6.0, min_cells=4, max_extent=6.0)
    assert vac.outlines == 1
    x = (vac.cols + view.i0) * RES
    y = (vac.rows + view.j0) * RES
    # the whole outline yields (its far side too, which the beams end behind), nothing of the wall
    assert x.min() == pytest.approx(1.0) and x.max() == pytest.approx(5.0)
    assert y.min() == pytest.approx(2.0) and y.max() == pytest.approx(3.8)
    assert vac.rows.shape[0] == 2 * 81 + 2 * 35
    # the wall was seen through too (the 0.3 m offset), in many cells, but it is 14 m long
    assert vac.seen_through > vac.rows.shape[0] // 4
    car = np.column_stack((np.linspace(1.2, 4.8, 20), np.full(20, 2.0)))
    wall = np.column_stack((np.linspace(-4.0, 4.0, 20), np.full(20, -5.0)))
    s0, f0, _ = map_evidence(car, view)
    assert s0.all() and not f0.any()  # without the rule: structure
    s1, f1, _ = map_evidence(car, yielding_view(view, vac))
    assert not s1.any() and f1.all()  # the outline being vacated: observed free
    s2, _, _ = map_evidence(wall, yielding_view(view, vac))
    assert s2.all()
    assert view.logodds[150 + 40, 150 + 20] == 8.0  # the map itself is not changed
    # the pipeline's limits (Config: segment.max_extent 3 m, map_vacate_min_depth 1 m) keep the 4 m outline;
    # an outline no longer than min_extent, or beams that end less than min_depth_m behind it, do not yield
    kw = dict(occupied_logodds=6.0, min_cells=4, max_extent=6.0)
    assert vacated_outlines(view, *_geo(r, a, valid), min_depth_m=1.0, min_extent=3.0, **kw).outlines == 1
    assert vacated_outlines(view, *_geo(r, a, valid), min_extent=4.5, **kw).outlines == 0
    assert vacated_outlines(view, *_geo(r, a, valid), min_depth_m=18.0, **kw).outlines == 0
    # a longer limit lets the wall yield too; min_cells 0 switches the rule off
    assert vacated_outlines(view, *_geo(r, a, valid), occupied_logodds=6.0, min_cells=4,
                            max_extent=15.0).outlines == 2
    assert vacated_outlines(view, *_geo(r, a, valid), occupied_logodds=6.0, min_cells=0,
                            max_extent=6.0).outlines == 0


def test_a_round_object_seen_past_its_edges_does_not_yield():
    """A 0.5 m round post in the map, still standing: the beams tangent to it pass through its boundary
    cells, but a neighbouring beam ends on the post, so no cell counts as seen through."""
    lo = np.full((300, 300), -2.0, dtype=np.float32)
    jj, ii = np.mgrid[0:300, 0:300]
    d = np.hypot((ii - 150) * RES - 3.0, (jj - 150) * RES)
    lo[(d <= 0.27) & (d >= 0.17)] = 8.0
    view = MapView(lo, -150, -150, RES)
    a = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    # the post (radius 0.25 at (3, 0)) in front of a circular wall at 8 m
    b = 3.0 * np.cos(a)
    disc = b * b - (9.0 - 0.0625)
    with np.errstate(invalid="ignore"):
        r = np.where(disc >= 0.0, b - np.sqrt(np.maximum(disc, 0.0)), 8.0)
    r = np.where(r > 0.0, r, 8.0)
    vac = vacated_outlines(view, *_geo(r, a, np.ones(720, dtype=bool)), occupied_logodds=6.0,
                           min_cells=1, max_extent=6.0)
    assert vac.seen_through == 0 and vac.outlines == 0


def _van_scene() -> Scenario:
    """A 16 × 10 m hall, a laser yawing ±0.5 rad at (−5, −2.5) (map updates as it turns); a 4.5 × 1.8 m van parked at
    (−3, 2) for 6 s (its outline becomes long-occupied) drives 9 m along the hall."""
    world = _build_world([(-8.0, -5.0), (8.0, -5.0), (8.0, 5.0), (-8.0, 5.0)], [])
    van = timeline((-3.0, 2.0), [("wait", 6.0), ("go", (6.0, 2.0), 1.5)], start_heading=0.0)
    robot = oscillating_in_place(-5.0, -2.5, 0.0, 0.5, 4.0)
    lidar = LidarModel(beams=720, rate_hz=10.0, range_max=15.0)
    return Scenario("vacate-test", "", world, (Mover(1, "van", Rect(4.5, 1.8), van),), robot, lidar, 12.0, 4)


def test_a_van_parked_from_the_start_is_removed_while_it_drives_off_its_outline():
    src = SimSource(_van_scene())
    gt = ground_truth_for(src, None, 0.05)
    out = {}
    for cells in (4, 0):
        cfg = Config()
        cfg.detect.tracker.map_vacate_min_cells = cells
        out[cells] = compute_metrics(run(src, cfg), gt)["removal_by_motion"]
    # with the rule 0.61 of its moving beams are removed, without 0.15 (structure until off its outline)
    assert out[4]["walking_recall"] > 0.5 and out[0]["walking_recall"] < 0.3
    assert out[4]["static_removed_share"] < 0.002


def test_an_outline_yields_only_after_it_persisted_and_with_enough_of_it_seen_through():
    view = _map()
    r, a, valid = _scan()
    kw = dict(occupied_logodds=6.0, min_cells=4, max_extent=6.0)
    vac = vacated_outlines(view, *_geo(r, a, valid), **kw)
    assert len(vac.sizes) == 1 and sum(vac.sizes) == vac.rows.shape[0]
    # a share of the outline's long-occupied cells seen through: enough for 0.2, not for 0.9
    assert vacated_outlines(view, *_geo(r, a, valid), min_share=0.2, **kw).outlines == 1
    assert vacated_outlines(view, *_geo(r, a, valid), min_share=0.9, **kw).outlines == 0
    hist = VacatedHistory(3)
    got = [hist.persistent(view, vac).outlines for _ in range(4)]
    assert got == [0, 0, 1, 1]  # the third consecutive scan yields
    hist = VacatedHistory(3)
    empty = vacated_outlines(view, *_geo(r, a, np.zeros_like(valid)), **kw)
    got = [hist.persistent(view, v).outlines for v in (vac, empty, vac, vac, vac)]
    assert got == [0, 0, 0, 0, 1]  # a gap restarts the count


def test_two_outlines_in_one_scan_are_judged_each_on_its_own():
    """A second, 2 m outline (x −5…−3 m, y 2…3.8 m) beside the 4 m car, both seen through by the same scan, with
    the 14 m wall seen through too: each outline yields or not by its own size, in the order of its lowest cell."""
    view = _map()
    lo = view.logodds.copy()

    def cell(v: float) -> int:
        return int(np.floor(v / RES + 0.5)) + 150

    lo[cell(2.0), cell(-5.0):cell(-3.0) + 1] = 8.0
    lo[cell(3.8), cell(-5.0):cell(-3.0) + 1] = 8.0
    lo[cell(2.0):cell(3.8) + 1, cell(-5.0)] = 8.0
    lo[cell(2.0):cell(3.8) + 1, cell(-3.0)] = 8.0
    view = MapView(lo, -150, -150, RES)
    r, a, valid = _scan()
    kw = dict(occupied_logodds=6.0, min_cells=4, max_extent=6.0)
    both = vacated_outlines(view, *_geo(r, a, valid), **kw)
    assert both.outlines == 2 and both.sizes == (2 * 41 + 2 * 35, 2 * 81 + 2 * 35)
    x = (both.cols + view.i0) * RES
    small, large = x[:both.sizes[0]], x[both.sizes[0]:]
    assert small.min() == pytest.approx(-5.0) and small.max() == pytest.approx(-3.0)
    assert large.min() == pytest.approx(1.0) and large.max() == pytest.approx(5.0)
    # the 2 m outline is no longer than min_extent 3 m: only the car yields, the same cells as on its own
    one = vacated_outlines(view, *_geo(r, a, valid), min_extent=3.0, **kw)
    alone = vacated_outlines(_map(), *_geo(r, a, valid), min_extent=3.0, **kw)
    assert one.outlines == 1 and one.sizes == alone.sizes
    assert np.array_equal(one.rows, alone.rows) and np.array_equal(one.cols, alone.cols)
    # the rejected outline's seen-through cells still count
    assert one.seen_through == both.seen_through > alone.seen_through
