"""Map metrics and dynamic-point removal metrics on hand-made inputs with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.eval.maps import comparison_grids, load_run_map, map_metrics
from dynslam2d.eval.removal import match_scans, removal_metrics
from dynslam2d.gridmap import GridMap
from dynslam2d.io.mapfile import write_map
from dynslam2d.types import Pose2D

RES = 0.05
NAN = np.nan


def _wall_map(shape=(20, 20), col=8, rows=(3, 15), origin=(0.0, 0.0), occ=1.0, free=0.0):
    """Known-free map with one vertical wall (cells [rows) at column col)."""
    p = np.full(shape, free, dtype=float)
    p[rows[0] : rows[1], col] = occ
    return GridMap(p, RES, origin)


# --- map metrics ----------------------------------------------------------------------------


def test_identical_maps():
    gt = _wall_map()
    m = map_metrics(gt, gt)
    assert m.iou == 1.0 and m.iou_tolerant == 1.0
    assert m.weighted_rmse == 0.0 and m.rmse_occupied == 0.0 and m.rmse_free == 0.0
    assert m.precision == 1.0 and m.recall == 1.0 and m.recall_all == 1.0 and m.f1 == 1.0
    assert m.ghost_area_m2 == 0.0 and m.ghost_cells == 0
    assert m.n_truth_occupied == 12 and m.n_estimate_occupied == 12
    assert m.n_compared_occupied == 12 and m.n_compared_free == 400 - 12


def test_shift_by_one_cell_strict_drops_tolerant_stays():
    gt = _wall_map()
    est = _wall_map(col=9)  # one cell (0.05 m) to the right
    m = map_metrics(est, gt)
    assert m.iou == 0.0
    assert m.iou_tolerant == 1.0
    assert m.precision == 1.0 and m.recall == 1.0 and m.f1 == 1.0
    assert m.ghost_area_m2 == 0.0
    # Two cells = 0.10 m: still within the tolerance (boundary included).
    assert map_metrics(_wall_map(col=10), gt).iou_tolerant == 1.0
    # Three cells = 0.15 m: outside the tolerance, but not a ghost (≤ 0.2 m).
    m3 = map_metrics(_wall_map(col=11), gt)
    assert m3.iou_tolerant == 0.0 and m3.precision == 0.0 and m3.recall == 0.0 and m3.f1 == 0.0
    assert m3.ghost_cells == 0
    # Five cells = 0.25 m: every estimated wall cell is a ghost.
    m5 = map_metrics(_wall_map(col=13), gt)
    assert m5.ghost_cells == 12
    assert m5.ghost_area_m2 == pytest.approx(12 * RES * RES)


def test_shift_expressed_through_origin_and_transform():
    gt = _wall_map()
    # Same array, origin one cell to the right: the wall lands one cell right.
    m = map_metrics(_wall_map(origin=(RES, 0.0)), gt)
    assert m.iou == 0.0 and m.iou_tolerant == 1.0
    # Same array and origin, but a transform moving it back by one cell: exact again.
    m = map_metrics(_wall_map(origin=(RES, 0.0)), gt, transform=Pose2D(-RES, 0.0, 0.0))
    assert m.iou == 1.0 and m.weighted_rmse == 0.0


def test_tolerant_iou_partial_value_and_symmetry():
    gt = _wall_map()  # 12 cells in column 8, rows 3..14
    p = np.zeros((20, 20))
    p[3:9, 8] = 1.0  # 6 cells exact
    p[3:9, 14] = 1.0  # 6 cells 0.30 m away: unmatched (and ghosts)
    est = GridMap(p, RES)
    m = map_metrics(est, gt)
    # A matched: rows 3..8 plus rows 9 and 10 (within 0.10 m of row 8) = 8, unmatched 4.
    # B matched 6, unmatched 6. I = (8 + 6)/2 = 7; IoU_tol = 7 / (7 + 4 + 6) = 7/17.
    assert m.iou_tolerant == pytest.approx(7 / 17)
    assert m.iou == pytest.approx(6 / 18)
    assert m.precision == pytest.approx(0.5)
    assert m.recall == pytest.approx(8 / 12)
    assert m.f1 == pytest.approx(2 * 0.5 * (8 / 12) / (0.5 + 8 / 12))
    assert m.ghost_cells == 6
    swapped = map_metrics(gt, est)
    assert swapped.iou_tolerant == pytest.approx(m.iou_tolerant)
    assert swapped.iou == pytest.approx(m.iou)
    # Tolerance 0 reduces the tolerant IoU to the strict one (paper Eq. 9).
    assert map_metrics(est, gt, tolerance=0.0).iou_tolerant == pytest.approx(m.iou)


def test_ghost_blob_area_exact():
    gt = GridMap(np.zeros((40, 40)), RES, (-1.0, -1.0))
    gt.prob[0, :] = gt.prob[-1, :] = gt.prob[:, 0] = gt.prob[:, -1] = 1.0  # room walls
    n_walls = int((gt.prob == 1.0).sum())
    est = GridMap(gt.prob.copy(), RES, gt.origin)
    est.prob[15:19, 20:23] = 0.97  # a 4 × 3 blob in the middle of the room
    est.prob[1, 10] = 0.9  # next to a wall: within 0.2 m, not a ghost (but not exact either)
    m = map_metrics(est, gt)
    assert m.ghost_cells == 12
    assert m.ghost_area_m2 == pytest.approx(12 * RES**2)  # 0.03 m²
    assert m.iou == pytest.approx(n_walls / (n_walls + 13))
    assert m.precision == pytest.approx((n_walls + 1) / (n_walls + 13))
    assert m.recall == 1.0


def test_weighted_rmse_hand_computed_3x3():
    # Rows listed bottom-up (row 0 = bottom); NaN = unknown.
    gt = GridMap(np.array([[1, 0, 0], [1, 0, NAN], [0, 0, 0]], dtype=float), 1.0)
    est = GridMap(np.array([[0.9, 0.2, NAN], [0.6, 0.1, 0.5], [0.0, 0.3, 0.4]]), 1.0)
    m = map_metrics(est, gt, occupied_threshold=0.65)
    # Known in both: all but (0,2) (estimate unknown) and (1,2) (truth unknown).
    # GT occupied: (0,0) err² 0.01, (1,0) 0.16 → N_occ = 2, Σ = 0.17, σ = 1/4.
    # GT free: (0,1) 0.04, (1,1) 0.01, (2,0) 0, (2,1) 0.09, (2,2) 0.16 → N_free = 5,
    # Σ = 0.30, σ = 1/10. Eq. 10: sqrt((0.17/4 + 0.30/10) / (2/4 + 5/10)) = sqrt(0.0725).
    assert m.weighted_rmse == pytest.approx(math.sqrt(0.0725))
    assert m.rmse_occupied == pytest.approx(math.sqrt(0.085))
    assert m.rmse_free == pytest.approx(math.sqrt(0.06))
    assert m.n_compared_occupied == 2 and m.n_compared_free == 5
    # Occupied sets: A = {(0,0), (1,0)}, B = {(0,0)} (0.6 is below 0.65).
    assert m.iou == pytest.approx(0.5)
    # An unweighted RMSE would be sqrt(0.47/7) ≈ 0.259: the weighting matters.
    assert abs(m.weighted_rmse - math.sqrt(0.47 / 7)) > 0.01


def test_weighted_rmse_single_class_and_empty():
    gt = GridMap(np.zeros((3, 3)), RES)
    est = GridMap(np.full((3, 3), 0.2), RES)
    m = map_metrics(est, gt)
    assert m.weighted_rmse == pytest.approx(0.2) and math.isnan(m.rmse_occupied)
    assert math.isnan(m.iou) and math.isnan(m.precision) and m.ghost_area_m2 == 0.0
    unknown = GridMap(np.full((3, 3), NAN), RES)
    assert math.isnan(map_metrics(unknown, gt).weighted_rmse)


def test_recall_observable_versus_all():
    gt = np.zeros((20, 30))
    gt[5:15, 5] = 1.0  # wall 1 (seen)
    gt[5:15, 25] = 1.0  # wall 2 (never observed by the estimate)
    est = np.full((20, 30), NAN)
    est[:, :12] = 0.1
    est[5:15, 5] = 0.95
    m = map_metrics(GridMap(est, RES), GridMap(gt, RES))
    assert m.recall == 1.0 and m.recall_all == pytest.approx(0.5)
    assert m.n_truth_observable == 10
    assert m.precision == 1.0 and m.f1 == 1.0


def test_estimate_beyond_truth_extent_is_compared():
    gt = _wall_map(shape=(20, 20))
    p = np.zeros((20, 40))
    p[3:15, 8] = 1.0
    p[10, 35] = 1.0  # 1.35 m right of the truth map's edge
    m = map_metrics(GridMap(p, RES), gt)
    assert m.ghost_cells == 1 and m.n_estimate_occupied == 13
    assert m.precision == pytest.approx(12 / 13)
    est, truth, res, origin = comparison_grids(GridMap(p, RES), gt)
    assert est.shape == truth.shape == (20, 40) and origin == (0.0, 0.0) and res == RES
    assert np.isnan(truth[:, 20:]).all()


def _room_segments():
    return [((0.2, 0.2), (3.0, 0.2)), ((3.0, 0.2), (3.0, 2.5)), ((3.0, 2.5), (0.2, 2.5)),
            ((0.2, 2.5), (0.2, 0.2)), ((1.2, 1.0), (2.0, 1.6))]


def _raster_room(shape, origin, to_truth: Pose2D) -> GridMap:
    """Rasterise the room in a grid whose frame is mapped into the truth frame by ``to_truth``."""
    p = np.full(shape, NAN)
    g = GridMap(p, RES, origin)
    X, Y = g.cell_centers()
    w = to_truth.transform_points(np.column_stack([X.ravel(), Y.ravel()])).reshape(shape + (2,))
    inside = (w[..., 0] > 0.2) & (w[..., 0] < 3.0) & (w[..., 1] > 0.2) & (w[..., 1] < 2.5)
    p[inside] = 0.1
    pts = []
    for a, b in _room_segments():
        t = np.linspace(0.0, 1.0, 400)[:, None]
        pts.append(np.asarray(a) + t * (np.asarray(b) - np.asarray(a)))
    local = to_truth.inverse().transform_points(np.vstack(pts))
    cells = g.world_to_cell(local)
    ok = (cells[:, 0] >= 0) & (cells[:, 0] < shape[1]) & (cells[:, 1] >= 0) & (cells[:, 1] < shape[0])
    p[cells[ok, 1], cells[ok, 0]] = 0.95
    return GridMap(p, RES, origin)


def test_rotated_translated_estimate_aligned_by_transform():
    truth = _raster_room((60, 70), (0.0, 0.0), Pose2D())
    truth.prob[truth.prob == 0.95] = 1.0
    truth.prob[truth.prob == 0.1] = 0.0
    straight = _raster_room((60, 70), (0.0, 0.0), Pose2D())
    ref = map_metrics(straight, truth)
    assert ref.iou == 1.0 and ref.ghost_cells == 0
    T = Pose2D(0.7, -0.4, math.radians(30.0))  # estimate frame → truth frame
    # The estimate's own frame: the room lies at T⁻¹(room), so shift the grid to hold it.
    rotated = _raster_room((90, 90), (-0.5, -1.0), T)
    m = map_metrics(rotated, truth, transform=T)
    # Within a cell of the unrotated result: the tolerant metrics agree; the strict per-cell
    # ones (IoU, weighted RMSE) do not, because a wall rasterised at 30° and resampled by
    # nearest cell centre lands up to one cell off (that is what the tolerance is for).
    assert m.iou_tolerant == pytest.approx(ref.iou_tolerant, abs=0.02)
    assert m.precision == pytest.approx(1.0, abs=0.02)
    assert m.recall == pytest.approx(1.0, abs=0.02)
    assert m.f1 > 0.98
    assert m.ghost_cells == 0
    assert m.n_estimate_occupied == pytest.approx(ref.n_estimate_occupied, rel=0.3)
    # Without the transform the same estimate does not line up.
    bad = map_metrics(rotated, truth)
    assert bad.f1 < 0.5 and bad.ghost_cells > 50


def test_rotation_by_90_degrees_is_exact():
    # A 90° rotation plus a whole-cell translation maps cells onto cells: every metric,
    # strict ones included, must equal the unrotated result.
    truth = _raster_room((60, 70), (0.0, 0.0), Pose2D())
    truth.prob[truth.prob == 0.95] = 1.0
    truth.prob[truth.prob == 0.1] = 0.0
    straight = _raster_room((60, 70), (0.0, 0.0), Pose2D())
    ref = map_metrics(straight, truth)
    T = Pose2D(3.5, -0.25, math.pi / 2)
    # T⁻¹ q = (q_y + 0.25, 3.5 − q_x): the truth extent x ∈ [0, 3.5], y ∈ [0, 3] becomes
    # x ∈ [0.25, 3.25], y ∈ [0, 3.5], and estimate cell (r, c) shows truth cell (c, 69 − r),
    # i.e. the array rotated a quarter turn counter-clockwise.
    est_prob = np.rot90(straight.prob, k=1)  # (70, 60)
    rotated = GridMap(est_prob, RES, (0.25, 0.0))
    m = map_metrics(rotated, truth, transform=T)
    assert m.iou == 1.0 and m.iou_tolerant == 1.0 and m.ghost_cells == 0
    assert m.weighted_rmse == pytest.approx(ref.weighted_rmse, abs=1e-12)
    assert m.n_compared_free == ref.n_compared_free
    # The opposite rotation does not line up.
    assert map_metrics(rotated, truth, transform=Pose2D(3.5, -0.25, -math.pi / 2)).iou < 0.2


def test_invalid_tolerance():
    gt = _wall_map()
    with pytest.raises(DynSlamError):
        map_metrics(gt, gt, tolerance=-0.1)


def test_as_dict_roundtrip():
    m = map_metrics(_wall_map(col=9), _wall_map())
    d = m.as_dict()
    assert d["iou"] == 0.0 and d["iou_tolerant"] == 1.0 and d["ghost_cells"] == 0
    assert isinstance(d["n_truth_occupied"], int) and d["tolerance_m"] == 0.1


def test_load_run_map_uses_logodds(tmp_path):
    p = np.array([[0.02, 0.5, NAN], [0.97, 0.3, 0.8]])
    grid = GridMap(p, RES, (1.0, -2.0))
    write_map(tmp_path / "map.yaml", grid)
    lo = np.where(np.isfinite(p), np.log(np.nan_to_num(p, nan=0.5) / (1 - np.nan_to_num(p, nan=0.5))), 0.0)
    np.save(tmp_path / "map_logodds.npy", lo.astype(np.float32))
    got = load_run_map(tmp_path)
    assert got.origin == pytest.approx((1.0, -2.0)) and got.resolution == pytest.approx(RES)
    # 0.5 has L = 0 and is "unknown" in the trinary PGM: indistinguishable from never seen.
    expect = np.array([[0.02, NAN, NAN], [0.97, 0.3, 0.8]])
    np.testing.assert_allclose(got.prob, expect, atol=1e-6)
    (tmp_path / "map_logodds.npy").unlink()
    tri = load_run_map(tmp_path)
    np.testing.assert_array_equal(np.isnan(tri.prob), [[False, True, True], [False, True, False]])
    with pytest.raises(DynSlamError):
        load_run_map(tmp_path / "missing")


# --- removal metrics ------------------------------------------------------------------------


def test_removal_metrics_small_array():
    labels = np.array(
        [
            [-1, 0, 0, 1, 1, 0],
            [0, 0, 2, 2, 1, -1],
            [0, 0, 0, 0, 0, 0],
        ],
        dtype=np.int16,
    )
    removed = np.array(
        [
            [True, False, False, True, True, True],  # 1 no-return, 2 dynamic, 1 static
            [False, False, True, False, True, False],  # 2 dynamic
            [False, False, False, False, False, False],
        ]
    )
    r = removal_metrics(removed, labels)
    assert r.n_dynamic == 5 and r.n_static == 11 and r.n_no_return == 2
    assert r.n_removed_dynamic == 4 and r.n_removed_static == 1 and r.n_removed == 5
    assert r.n_removed_no_return == 1
    assert r.precision == pytest.approx(4 / 5)
    assert r.recall == pytest.approx(4 / 5)
    assert r.f1 == pytest.approx(0.8)
    assert r.static_removed_share == pytest.approx(1 / 11)
    assert r.per_mover_recall == {1: pytest.approx(1.0), 2: pytest.approx(0.5)}
    assert r.n_scans == 3
    d = r.as_dict()
    assert d["per_mover_recall"] == {"1": 1.0, "2": 0.5}


def test_removal_metrics_nothing_removed_and_shape_error():
    labels = np.array([[0, 1, 1]], dtype=np.int16)
    r = removal_metrics(np.zeros((1, 3), bool), labels)
    assert math.isnan(r.precision) and r.recall == 0.0 and r.static_removed_share == 0.0
    with pytest.raises(DynSlamError):
        removal_metrics(np.zeros((2, 3), bool), labels)


def test_match_scans_by_stamp():
    i_r, i_l = match_scans(np.array([0.1, 0.2, 0.35]), np.array([0.0, 0.2, 0.1, 0.3]), max_dt=0.01)
    assert i_r.tolist() == [0, 1] and i_l.tolist() == [2, 1]
    with pytest.raises(DynSlamError):
        match_scans(np.array([5.0]), np.array([0.0]), max_dt=0.01)
