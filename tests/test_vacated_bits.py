"""The finest map level's long-occupied bitmap (GridLevel.occ_bits) that the vacated-footprint trace reads: every
writer of the level keeps its invariant — every cell whose stored float32 log-odds, compared as float64, is at or
above the threshold has its bit set (docs/speed.md, pass vac77)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_vacated_trace import KW, RES, _map, _scan

from dynslam2d.config import Config
from dynslam2d.detect.mapevidence import MapView, seen_through_structure_kernel
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim.scenarios import build_scenario
from dynslam2d.sim.simulation import SimSource
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.cleanup import scan_clearing
from dynslam2d.slam.erasure import EvidenceLedger
from dynslam2d.slam.grid import GridLevel
from dynslam2d.types import Pose2D, Scan
from dynslam2d.vacated import _CELLS_PER_BEAM, _INV_CELL, _RECOUNT, VacatedTrace, _atan2_approx, seen_through_inverse


def _missing(lv: GridLevel) -> int:
    """Cells at or above the level's bitmap threshold whose bit is clear."""
    lo = lv.logodds
    h, w = lo.shape
    assert lv.occ_bits.shape == (h, (w + 63) >> 6)
    cols = np.arange(w)
    have = (lv.occ_bits[:, cols >> 6] >> (cols & 63).astype(np.uint64)) & np.uint64(1)
    return int(((lo.astype(np.float64) >= lv.occ_bits_thr) & (have == 0)).sum())


def _run(name: str, duration: float, cfg: Config) -> dict[str, int]:
    """The pipeline over the simulated scene ``name`` (360 beams), the invariant asserted after every scan; counts
    of what the run did."""
    pipe = Pipeline(cfg)
    lv = pipe.slam.map.levels[0]
    assert lv.occ_bits_thr == cfg.detect.tracker.map_occupied_logodds
    seen = {"scans": 0}
    for scan in SimSource(build_scenario(name, duration=duration, beams=360)):
        pipe.process(scan)
        assert _missing(lv) == 0, f"scan {seen['scans']}"
        seen["scans"] += 1
    seen["grows"] = lv.n_grows
    seen["erased"] = pipe.ledger.stats["cells_changed"] if pipe.ledger is not None else 0
    return seen


def test_the_bitmap_holds_every_long_occupied_cell_while_the_map_grows() -> None:
    seen = _run("long-corridor", 10.0, Config())
    assert seen["scans"] == 200 and seen["grows"] >= 2


def test_a_growth_that_skips_the_bitmap_fails_the_check(monkeypatch: pytest.MonkeyPatch) -> None:
    grow = GridLevel._grow

    def skipped(self: GridLevel, b: tuple[int, int, int, int]) -> None:
        thr, self.occ_bits_thr = self.occ_bits_thr, float("nan")  # (the growth's bitmap update left out)
        grow(self, b)
        self.occ_bits_thr = thr
        if thr == thr:
            self.occ_bits = np.zeros((self.logodds.shape[0], (self.logodds.shape[1] + 63) >> 6), dtype=np.uint64)

    monkeypatch.setattr(GridLevel, "_grow", skipped)
    with pytest.raises(AssertionError, match="scan"):
        _run("long-corridor", 10.0, Config())


def _raising_erasure(monkeypatch: pytest.MonkeyPatch) -> Config:
    """A configuration and an erasure that raises cells: every erased track's level-0 evidence made −10 (as if its
    rays had cleared them) with erase_min_share 5, so its free cells (log-odds ≤ −2) are raised to ≥ 8."""
    fold = EvidenceLedger._fold

    def folded(self: EvidenceLedger, led: object) -> None:
        fold(self, led)
        rec = led.levels[0]
        rec.delta = np.full(rec.delta.shape[0], -10.0)

    monkeypatch.setattr(EvidenceLedger, "_fold", folded)
    cfg = Config()
    cfg.detect.memory.erase_min_share = 5.0
    return cfg


def test_the_bitmap_holds_every_long_occupied_cell_through_erasures(monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _run("stop-and-go", 13.0, Config())  # (the erasure as configured: it lowers cells)
    assert seen["erased"] > 0
    raised = []
    mark = GridLevel.mark_long_occupied

    def counted(self: GridLevel, row: np.ndarray, col: np.ndarray) -> None:
        before = int(np.bitwise_count(self.occ_bits).sum())
        mark(self, row, col)
        raised.append(int(np.bitwise_count(self.occ_bits).sum()) - before)

    monkeypatch.setattr(GridLevel, "mark_long_occupied", counted)
    seen = _run("stop-and-go", 13.0, _raising_erasure(monkeypatch))
    assert seen["erased"] > 0 and sum(raised) > 0


def test_an_erasure_that_skips_the_bitmap_fails_the_check(monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = _raising_erasure(monkeypatch)
    monkeypatch.setattr(GridLevel, "mark_long_occupied", lambda self, row, col: None)
    with pytest.raises(AssertionError, match="scan"):
        _run("stop-and-go", 13.0, cfg)


def _bitmap(lo: np.ndarray, thr: float) -> np.ndarray:
    """The exact bitmap of ``lo`` ≥ ``thr`` (compared as float64)."""
    h, w = lo.shape
    occ = np.zeros((h, ((w + 63) >> 6) * 64), dtype=bool)
    occ[:, :w] = lo.astype(np.float64) >= thr
    return np.packbits(occ, axis=1, bitorder="little").view("<u8").copy()


def test_the_inverse_form_finds_the_walks_cells_on_random_maps_with_stale_bits() -> None:
    rng = np.random.default_rng(11)
    clean = CleanConfig()
    found = 0
    for trial in range(30):
        view = _map(rng)
        lo = view.logodds
        bits = _bitmap(lo, KW["occupied_logodds"])
        # stale bits: cells once long-occupied, lowered since (some below the threshold by one float32 step)
        stale = rng.random(lo.shape) < 0.02
        lo[stale & (lo >= 6.0)] = np.nextafter(np.float32(6.0), np.float32(0.0))
        bits |= _bitmap(np.where(stale, np.float32(9.0), np.float32(0.0)), 6.0)
        lo[rng.random(lo.shape) < 0.003] = np.float32(6.0)  # (exactly at the threshold: must have a bit)
        bits |= _bitmap(lo, 6.0)
        scan = _scan(np.random.default_rng(100 * trial), 0.0)
        if trial % 3 == 0:  # (beams from another first angle and fewer beams)
            scan = Scan(stamp=0.0, angle_min=-2.0, angle_increment=4.0 / 480, ranges=scan.ranges[:481],
                        range_min=0.05, range_max=20.0)
        elif trial % 3 == 1:  # (more than a turn of beams: the last beams' window wraps onto the first ones')
            scan = Scan(stamp=0.0, angle_min=-3.0, angle_increment=2.0 * math.pi / 470, ranges=scan.ranges[:481],
                        range_min=0.05, range_max=20.0)
        pose = Pose2D(0.37 * (trial % 5) - 0.7, 0.21 * (trial % 7) - 0.6, 0.3 * trial)
        origin, cx, cy, clear = scan_clearing(scan.ranges, scan.trig(), scan.valid_mask(), pose, RES, clean)
        ox, oy = pose.x / RES, pose.y / RES
        nb = cx.shape[0]
        args = (lo, view.i0, view.j0, ox, oy, cx, cy, clear, clean.ray_core, 6.0)
        wr, wc = np.empty(64 * nb, np.int64), np.empty(64 * nb, np.int64)
        n = seen_through_structure_kernel(*args, wr, wc, 1.0 / RES)
        ir, ic = np.empty(64 * nb, np.int64), np.empty(64 * nb, np.int64)
        iw = np.empty((2 * _CELLS_PER_BEAM + 3) * nb, np.int64)
        m = seen_through_inverse(*args, 1.0 / RES, bits, scan.angle_min, scan.angle_increment, pose.theta, ir, ic,
                                 iw, np.empty(2 * nb), 0.0)
        assert m == n
        w = lo.shape[1]
        assert np.array_equal(np.sort(wr[:n] * w + wc[:n]), np.sort(ir[:m] * w + ic[:m]))
        found += n
        # the pipeline's kernel with the bitmap gives what it gives without
        trace = VacatedTrace(clean, scans=1, **KW)
        plain = trace.view(view, scan, pose)
        kept = VacatedTrace(clean, scans=1, **KW).view(MapView(lo, view.i0, view.j0, RES, bits, 6.0), scan, pose)
        assert np.array_equal(plain.logodds, kept.logodds)
    assert found > 100


def test_the_choice_takes_the_inverse_form_on_a_sparse_map_and_the_walk_on_a_dense_one() -> None:
    """The cost model (pass vac83): few long-occupied cells in reach → the inverse form runs (and finds the walk's
    cells); many → −1 (the walk), then the next ``_RECOUNT`` − 1 scans decline at once, then it counts again. Forced
    (cell cost 0) both forms give the same cells on the dense map too."""
    rng = np.random.default_rng(3)
    clean = CleanConfig()
    sparse = _map(rng)
    dense = sparse.logodds.copy()
    dense[rng.random(dense.shape) < 0.08] = np.float32(9.0)
    scan = _scan(np.random.default_rng(5), 0.0)
    pose = Pose2D(0.1, -0.2, 0.4)
    origin, cx, cy, clear = scan_clearing(scan.ranges, scan.trig(), scan.valid_mask(), pose, RES, clean)
    nb = cx.shape[0]
    for lo, chosen in ((sparse.logodds, True), (dense, False)):
        bits = _bitmap(lo, KW["occupied_logodds"])
        args = (lo, sparse.i0, sparse.j0, pose.x / RES, pose.y / RES, cx, cy, clear, clean.ray_core, 6.0)
        wr, wc = np.empty(64 * nb, np.int64), np.empty(64 * nb, np.int64)
        n = seen_through_structure_kernel(*args, wr, wc, 1.0 / RES)
        fw = np.zeros(2 * nb + 2)
        iw = np.empty((2 * _CELLS_PER_BEAM + 3) * nb, np.int64)
        for cost in (_INV_CELL, 0.0):
            ir, ic = np.empty(64 * nb, np.int64), np.empty(64 * nb, np.int64)
            m = seen_through_inverse(*args, 1.0 / RES, bits, scan.angle_min, scan.angle_increment, pose.theta, ir,
                                     ic, iw, fw if cost > 0.0 else np.empty(2 * nb), cost)
            if cost > 0.0 and not chosen:
                assert m == -1
                continue
            assert m == n
            w = lo.shape[1]
            assert np.array_equal(np.sort(wr[:n] * w + wc[:n]), np.sort(ir[:m] * w + ic[:m]))
        if chosen:
            assert n > 0 and fw[2 * nb] == np.count_nonzero(lo >= 6.0)  # (every long-occupied cell is in reach)
            continue
        over = fw[2 * nb]
        assert over > 0 and fw[2 * nb + 1] == _RECOUNT - 1
        for s in range(1, _RECOUNT):  # declined at once: not counted again
            fw[2 * nb] = -5.0
            assert seen_through_inverse(*args, 1.0 / RES, bits, scan.angle_min, scan.angle_increment, pose.theta, ir,
                                        ic, iw, fw, _INV_CELL) == -1
            assert fw[2 * nb + 1] == _RECOUNT - 1 - s and fw[2 * nb] == -5.0
        assert seen_through_inverse(*args, 1.0 / RES, bits, scan.angle_min, scan.angle_increment, pose.theta, ir, ic,
                                    iw, fw, _INV_CELL) == -1
        assert fw[2 * nb] == over and fw[2 * nb + 1] == _RECOUNT - 1  # (counted again)


def test_the_branch_free_angle_is_atan2_within_its_bound_in_every_octant() -> None:
    """``_atan2_approx`` (selects only since pass vac125, so the inverse form's per-cell loop vectorises): within
    1.2e-5 rad of atan2 in every octant, on the axes, the diagonals and at the origin (0)."""
    rng = np.random.default_rng(7)
    pts = np.concatenate([rng.normal(size=(2000, 2)) * 50.0,
                          np.array([[0.0, 0.0], [0.0, 3.0], [0.0, -3.0], [3.0, 0.0], [-3.0, 0.0], [2.0, 2.0],
                                    [-2.0, 2.0], [2.0, -2.0], [-2.0, -2.0], [1e-9, -5.0], [-5.0, 1e-9]])])
    for y, x in pts:
        assert abs(_atan2_approx(y, x) - math.atan2(y, x)) <= 1.2e-5, (y, x)
    assert _atan2_approx(0.0, 0.0) == 0.0
