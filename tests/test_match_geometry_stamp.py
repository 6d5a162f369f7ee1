"""The matcher's level geometry keyed on the levels' geometry stamps (pass mat134): the cached ``geo`` array always
holds the levels' current (cell side, i0, j0, empty), through growth, release and several maps, and a matched scan
gives the same pose as with a fresh array."""

from __future__ import annotations

import numpy as np

from dynslam2d.slam import matcher
from dynslam2d.slam.grid import MultiResMap


def _values(levels) -> np.ndarray:
    return np.array([(lv.resolution, lv.i0, lv.j0, lv.logodds.size == 0) for lv in levels], dtype=np.float64)


def _grown_map(resolution: float, half: int) -> MultiResMap:
    m = MultiResMap(resolution, 3, -0.4, 0.9)
    for k, lv in enumerate(m.levels):
        lv.ensure(-half >> k, -half >> k, half >> k, half >> k)
    return m


def test_geometry_follows_growth_and_release() -> None:
    m = MultiResMap(0.05, 3, -0.4, 0.9)
    geo = matcher._level_geometry(m.levels)
    assert np.array_equal(geo, _values(m.levels)) and geo[:, 3].tolist() == [1.0, 1.0, 1.0]
    stamps = [lv.geometry_stamp for lv in m.levels]
    assert len(set(stamps)) == 3
    m.levels[0].ensure(-40, -30, 40, 30)
    assert m.levels[0].geometry_stamp not in stamps  # a growth takes a new stamp
    geo = matcher._level_geometry(m.levels)
    assert np.array_equal(geo, _values(m.levels)) and geo[0, 3] == 0.0 and geo[0, 1] < 0.0
    m.levels[0].ensure(-400, -300, 40, 30)  # grown again (to the left and down: i0 and j0 change)
    assert np.array_equal(matcher._level_geometry(m.levels), _values(m.levels))
    m.levels[0].release()
    geo = matcher._level_geometry(m.levels)
    assert np.array_equal(geo, _values(m.levels)) and geo[0, 3] == 1.0
    # an unchanged map takes the cached array itself
    assert matcher._level_geometry(m.levels) is geo


def test_maps_of_other_geometry_do_not_share() -> None:
    a, b = _grown_map(0.05, 60), _grown_map(0.1, 90)
    ga, gb = matcher._level_geometry(a.levels), matcher._level_geometry(b.levels)
    assert np.array_equal(ga, _values(a.levels)) and np.array_equal(gb, _values(b.levels))
    assert not np.array_equal(ga, gb)
    assert {lv.geometry_stamp for lv in a.levels}.isdisjoint({lv.geometry_stamp for lv in b.levels})


def test_match_pose_after_growth_as_with_a_fresh_geometry(monkeypatch) -> None:
    rng = np.random.default_rng(3)
    m = _grown_map(0.05, 80)
    ang = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    r = 2.0 + 0.5 * np.cos(3 * ang)
    pts = np.ascontiguousarray(np.column_stack([r * np.cos(ang), r * np.sin(ang)]))
    for lv in m.levels:
        lv.logodds[:] = 0.0
    m.integrate(__import__("dynslam2d.types", fromlist=["Pose2D"]).Pose2D(0.0, 0.0, 0.0), pts)
    start = np.array([0.03, -0.02, 0.01]) + rng.normal(0.0, 0.001, 3)
    args = (3, 5, False, True, 0.1, 1e4, 0.2, 2.0, 0.5, None, None, None)
    p1 = matcher.match_fit(m.levels, pts, start, *args)[0]
    m.levels[0].ensure(-300, -300, 300, 300)  # the map grows: the cached geometry must not be reused
    p2 = matcher.match_fit(m.levels, pts, start, *args)[0]
    monkeypatch.setattr(matcher, "_GEO", {})  # a fresh array for the grown map
    p3 = matcher.match_fit(m.levels, pts, start, *args)[0]
    assert np.array_equal(p2, p3)
    assert np.allclose(p1, p2, atol=1e-9)
