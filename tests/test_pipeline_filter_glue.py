"""The filter stage's glue in ``Pipeline.process`` (pass neg112): the vehicle-size movers' test as Python's
``max(l, w) > lim`` and the scans without a mover's arrays, made without the ``_exclude`` call."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.pipeline import Pipeline, _vehicle_ids
from dynslam2d.sim import SimSource
from dynslam2d.types import Pose2D


def test_vehicle_ids_are_the_rows_whose_python_max_side_exceeds_the_limit() -> None:
    nan, inf = math.nan, math.inf
    sides = [(1.0, 2.0), (2.0, 1.0), (1.5, 1.5), (1.2, 0.3), (nan, 2.0), (2.0, nan), (nan, nan), (inf, 0.1),
             (0.1, -inf), (-3.0, 0.5), (1.5000000000000002, 0.0)]
    rows = np.array([[0.1 * j, -0.2, 0.3, length, width, 0.5, 0.0] for j, (length, width) in enumerate(sides)])
    ids = [10 + 3 * j for j in range(len(sides))]
    for lim in (1.5, 0.2, 1.9, -1.0, inf, -inf):
        ref = [tid for tid, (length, width) in zip(ids, rows[:, 3:5].tolist()) if max(length, width) > lim]
        assert _vehicle_ids(ids, rows, lim) == ref, lim
    # (a NaN length wins Python's max, a NaN width loses: the cases where the two orders of the test differ)
    assert _vehicle_ids([1, 2], np.array([[0, 0, 0, nan, 2.0], [0, 0, 0, 2.0, nan]]), 1.0) == [2]
    assert _vehicle_ids([], np.zeros((0, 7)), 1.0) == []


def test_scans_without_a_mover_get_their_own_all_kept_arrays() -> None:
    scans = SimSource("paper", duration=3.0).simulation.scans
    pipe = Pipeline()
    kept = []
    for scan in scans[:25]:
        step = pipe.process(scan)
        if not pipe._moving:
            kept.append((scan.n_beams, step))
    assert len(kept) >= 10
    for n, step in kept:
        assert step.removed.dtype == np.bool_ and step.removed.shape == (n,) and not step.removed.any()
        assert step.removed_by.dtype == np.int64 and step.removed_by.shape == (n,)
        assert (step.removed_by == -1).all()
    # (each scan's arrays are its own: a caller writing into one changes no other scan's, nor the next one's)
    arrays = [a for _, s in kept for a in (s.removed, s.removed_by)]
    assert len({id(a) for a in arrays}) == len(arrays)
    assert not any(np.shares_memory(a, b) for i, a in enumerate(arrays) for b in arrays[i + 1:])
    kept[0][1].removed[:] = True
    kept[0][1].removed_by[:] = 7
    pipe._no_remover = np.full(5, -1, dtype=np.int64)  # (a kept −1 row of another beam count: made again)
    step = pipe.process(scans[25])
    if not pipe._moving:
        n = scans[25].n_beams
        assert step.removed.shape == (n,) and not step.removed.any()
        assert step.removed_by.shape == (n,) and (step.removed_by == -1).all()


def _python_side(rows: np.ndarray) -> float:
    """The largest ``max(l, w)`` of the rows with Python's ``max``, NaN ones left out (−inf for none)."""
    sides = [max(length, width) for length, width in rows[:, 3:5].tolist()]
    return max([s for s in sides if s == s], default=-math.inf)


def test_mover_exclusions_count_the_removed_beams_and_give_the_longest_python_side() -> None:
    from dynslam2d.config import Config
    from dynslam2d.filter import mover_exclusions

    scan = SimSource("paper", duration=1.0).simulation.scans[5]
    pose = Pose2D(0.3, -0.2, 0.1)
    rng = np.random.default_rng(4)
    nan = math.nan
    n = 9
    boxes = np.column_stack((rng.uniform(-6, 6, (n, 2)), rng.uniform(-3, 3, n), rng.uniform(0.2, 4, (n, 2))))
    boxes[2, 3] = nan  # (a NaN length: Python's max gives NaN, skipped)
    boxes[4, 4] = nan  # (a NaN width: Python's max gives the length)
    boxes[6, 3:5] = (2.5, 2.5)
    states = np.column_stack((boxes[:, :2], rng.uniform(-1, 1, (n, 2))))
    checked = 0
    for mode in ({}, {"default_shape": "square"}, {"mode": "adaptive"}, {"speed_margin_time": 0.1}):
        cfg = Config().filter.model_copy(update=mode)
        for idx in ([2], [4], [0, 6], [1, 2, 3, 4, 5, 6, 7, 8], [2, 4]):
            k = len(idx)
            packed = np.array(idx + [100 + i for i in idx] + [0] * (2 * k) + [0], dtype=np.int64)
            kept, ids, removed, removed_by, count, side = mover_exclusions(
                cfg, scan, pose, boxes, states, packed, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
            assert count == int(np.count_nonzero(removed)) and type(count) is int
            want = _python_side(kept)
            assert side == want or (side == -math.inf and want == -math.inf), (mode, idx)
            for lim in (0.5, 2.0, 2.5, 3.9, math.inf):
                assert (side > lim) == bool(_vehicle_ids(list(ids), kept, lim)), (mode, idx, lim)
            checked += count
    assert checked > 0
