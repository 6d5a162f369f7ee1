"""The pipeline's one-call vacated-footprint trace (dynslam2d/vacated.py) gives the views of the separate calls it
replaced: scan_clearing → vacated_outlines → VacatedHistory.persistent → yielding_view (docs/speed.md, view2
pass)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.config import Config
from dynslam2d.detect.mapevidence import MapView, VacatedHistory, vacated_outlines, yielding_view
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import Mover, Rect, Scenario, oscillating_in_place, timeline
from dynslam2d.sim.scenarios import _build_world
from dynslam2d.sim.sensor import LidarModel
from dynslam2d.sim.simulation import SimSource
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.cleanup import scan_clearing
from dynslam2d.types import Pose2D, Scan
from dynslam2d.vacated import VacatedTrace

RES = 0.05
KW = dict(occupied_logodds=6.0, min_cells=4, max_extent=6.0, min_depth_m=1.0, min_extent=3.0, min_share=0.2)


def _old_view(view: MapView, scan: Scan, pose: Pose2D, hist: VacatedHistory, clean: CleanConfig) -> MapView:
    """The separate calls the trace replaced (the pipeline's _evidence_view before the view2 pass)."""
    origin, cx, cy, clear = scan_clearing(scan.ranges, scan.trig(), scan.valid_mask(), pose, view.resolution, clean)
    vac = vacated_outlines(view, origin, cx, cy, clear, ray_core=clean.ray_core, **KW)
    return yielding_view(view, hist.persistent(view, vac))


def _map(rng: np.random.Generator) -> MapView:
    """Free floor with a car-sized outline, a 14 m wall and random long-occupied specks and boxes."""
    lo = np.full((300, 300), -2.0, dtype=np.float32)
    lo[190, 170:251] = 8.0
    lo[226, 170:251] = 8.0
    lo[190:227, 170] = 8.0
    lo[190:227, 250] = 8.0
    lo[50, 10:290] = 8.0
    for _ in range(6):
        r, c = rng.integers(20, 280, size=2)
        h, w = rng.integers(3, 40, size=2)
        lo[r:r + h, c] = lo[r:r + h, min(c + w, 299)] = rng.uniform(5.0, 9.0)
        lo[r, c:c + w] = lo[min(r + h, 299), c:c + w] = 7.0
    lo[rng.random(lo.shape) < 0.01] = 6.5
    return MapView(lo, -150, -150, RES)


def _scan(rng: np.random.Generator, stamp: float) -> Scan:
    """720 beams from −π ending on a wavy round wall 8–9 m away (through the car's outline), some missing and a few
    short."""
    a = -math.pi + np.arange(720) * (2 * math.pi / 720)
    r = 8.5 + 0.4 * np.sin(3 * a) + rng.normal(0.0, 0.02, 720)
    r[rng.random(720) < 0.05] = np.nan
    r[rng.random(720) < 0.05] = rng.uniform(0.5, 4.0)
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=2 * math.pi / 720, ranges=r, range_min=0.05,
                range_max=20.0)


def test_the_trace_gives_the_views_of_the_separate_calls_on_random_maps_and_scans() -> None:
    rng = np.random.default_rng(7)
    clean = CleanConfig()
    yielded = 0
    for trial in range(40):
        view = _map(rng)
        trace = VacatedTrace(clean, scans=1 + trial % 3, **KW)
        hist = VacatedHistory(1 + trial % 3)
        for k in range(4):  # the same scan and pose repeated: the history lets an outline yield from the 3rd on
            scan = _scan(np.random.default_rng(100 * trial), float(k))
            pose = Pose2D(0.1 * (trial % 4), 0.1 * (trial % 5), 0.05 * trial)
            new, old = trace.view(view, scan, pose), _old_view(view, scan, pose, hist, clean)
            assert (new is view) == (old is view)
            assert np.array_equal(new.logodds, old.logodds)
            yielded += new is not view
        assert not trace._window.any()  # the growth window is left all 0 for the next scan
    assert yielded > 10  # outlines did yield (the comparison is not only of unchanged views)


def _van_scene() -> Scenario:
    """tests/test_vacated.py's van: parked for 6 s, then driving 9 m along a hall, seen by a yawing laser."""
    world = _build_world([(-8.0, -5.0), (8.0, -5.0), (8.0, 5.0), (-8.0, 5.0)], [])
    van = timeline((-3.0, 2.0), [("wait", 6.0), ("go", (6.0, 2.0), 1.5)], start_heading=0.0)
    robot = oscillating_in_place(-5.0, -2.5, 0.0, 0.5, 4.0)
    lidar = LidarModel(beams=720, rate_hz=10.0, range_max=15.0)
    return Scenario("vacate-test", "", world, (Mover(1, "van", Rect(4.5, 1.8), van),), robot, lidar, 12.0, 4)


def test_the_pipelines_views_equal_the_separate_calls_while_a_van_drives_off() -> None:
    cfg = Config()
    pipe = Pipeline(cfg)
    tc = cfg.detect.tracker
    hist = VacatedHistory(tc.map_vacate_scans)
    kw = dict(occupied_logodds=tc.map_occupied_logodds, min_cells=tc.map_vacate_min_cells,
              max_extent=tc.map_vacate_max_extent, min_depth_m=tc.map_vacate_min_depth,
              min_extent=cfg.detect.segment.max_extent, min_share=tc.map_vacate_min_share)
    assert kw == KW  # (the defaults _old_view passes)
    inner = pipe._evidence_view
    seen = {"scans": 0, "yielded": 0}

    def checked(scan: Scan, pose: Pose2D) -> MapView | None:
        new = inner(scan, pose)
        view = MapView.of_level(pipe.slam.map.levels[0])
        if view is None:
            assert new is None
            return new
        old = _old_view(view, scan, pose, hist, cfg.clean)
        assert np.array_equal(new.logodds, old.logodds) and (new.i0, new.j0) == (old.i0, old.j0)
        assert (new.logodds is view.logodds) == (old is view)
        seen["scans"] += 1
        seen["yielded"] += old is not view
        return new

    pipe._evidence_view = checked
    for scan in SimSource(_van_scene()):
        pipe.process(scan)
    assert seen["scans"] > 100 and seen["yielded"] > 5


def test_a_scan_without_beams_breaks_a_persistence_run_as_before() -> None:
    view = _map(np.random.default_rng(3))
    clean = CleanConfig()
    trace, hist = VacatedTrace(clean, scans=3, **KW), VacatedHistory(3)
    scan = _scan(np.random.default_rng(0), 0.0)
    empty = Scan(stamp=1.0, angle_min=0.0, angle_increment=0.01, ranges=np.zeros(0), range_min=0.05, range_max=20.0)
    pose = Pose2D(0.0, 0.0, 0.0)
    got_new, got_old = [], []
    for s in (scan, scan, empty, scan, scan, scan):
        got_new.append(trace.view(view, s, pose) is not view)
        got_old.append(_old_view(view, s, pose, hist, clean) is not view)
    assert got_new == got_old == [False, False, False, False, False, True]


def _grown_outlines(lo: np.ndarray, cells: list[tuple[int, int]], near: float, occ32: float, max_side: int,
                    min_cells: int, res: float, min_extent: float, min_share: float
                    ) -> tuple[list[int], list[int], list[int], int]:
    """vacated_core's outlines from the seen-through cells ``cells`` (row, column) as its docstring defines them,
    with a Python set for the cells of a growth (the kernel keeps them in a window about the start)."""
    h, w = lo.shape
    codes = sorted({r * w + c for r, c in cells})
    nc = len(codes)
    if len(cells) < min_cells or nc < min_cells:
        return [], [], [], nc if len(cells) >= min_cells else 0
    done = [False] * nc
    out_r: list[int] = []
    out_c: list[int] = []
    sizes: list[int] = []
    for s, code in enumerate(codes):
        if done[s]:
            continue
        r0, c0 = divmod(code, w)
        grown = [(r0, c0)]
        member = {(r0, c0)}
        ok = True
        head = 0
        while head < len(grown) and ok:
            r, c = grown[head]
            head += 1
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    if (dr, dc) == (0, 0) or not (0 <= rr < h and 0 <= cc < w) or lo[rr, cc] <= near:
                        continue
                    if abs(rr - r0) > max_side or abs(cc - c0) > max_side or len(grown) >= max_side ** 2 + 1 and \
                            (rr, cc) not in member:
                        ok = False
                    elif (rr, cc) not in member:
                        member.add((rr, cc))
                        grown.append((rr, cc))
                        rs = [p[0] for p in grown]
                        cs = [p[1] for p in grown]
                        ok = max(rs) - min(rs) < max_side and max(cs) - min(cs) < max_side
                    if not ok:
                        break
                if not ok:
                    break
        if not ok and lo[r0, c0] <= near:
            done[s] = True
            continue
        longocc = [p for p in grown if lo[p] >= occ32]
        seen = 0
        for p in longocc:
            q = p[0] * w + p[1]
            if q in codes:
                done[codes.index(q)] = True
                seen += 1
        rs = [p[0] for p in grown]
        cs = [p[1] for p in grown]
        if ok and seen >= min_cells and max(max(rs) - min(rs), max(cs) - min(cs)) * res > min_extent and \
                seen >= min_share * len(longocc):
            out_r += rs
            out_c += cs
            sizes.append(len(grown))
    return out_r, out_c, sizes, nc


def test_the_outlines_growth_equals_its_definition_on_random_maps() -> None:
    """vacated_core's outlines (the growth in its window, kept between starts) against their definition on maps of
    random outlines 1-3 cells thick, walls longer than the window and cells exactly at near_thr (max_side 70)."""
    from dynslam2d.detect.mapevidence import seen_through_structure_kernel, vacated_outlines_kernel

    rng = np.random.default_rng(7)
    yielded = 0
    for trial in range(40):
        lo = np.full((260, 260), -1.0, dtype=np.float32)
        for _ in range(rng.integers(3, 12)):  # rectangle outlines of 1-3 cell thick walls, some of them long walls
            r, c = rng.integers(0, 250, size=2)
            hh, ww = rng.integers(2, 150 if trial % 3 else 80, size=2)
            t = int(rng.integers(1, 4))
            v = float(rng.choice([0.4, 3.0, 7.0]))
            lo[r:r + hh, c:c + t] = lo[r:r + hh, c + ww:c + ww + t] = v
            lo[r:r + t, c:c + ww] = lo[r + hh:r + hh + t, c:c + ww + t] = v
        lo[rng.random(lo.shape) < 0.02] = 6.5
        lo[rng.random(lo.shape) < 0.02] = 0.5  # (exactly near_thr: outside the outlines)
        ox, oy = rng.uniform(20.0, 240.0, size=2)
        a = np.linspace(-math.pi, math.pi, 900, endpoint=False)
        d = rng.uniform(60.0, 300.0)
        cx, cy = ox + d * np.cos(a), oy + d * np.sin(a)
        clear = np.ones(900, dtype=bool)
        args = (lo, 0, 0, ox, oy, cx, cy, clear, 0.5, 6.0)
        max_side, min_cells, res, min_extent = 70, int(rng.integers(1, 4)), 0.05, float(rng.uniform(0.2, 2.0))
        got_r, got_c, got_s, got_nc = vacated_outlines_kernel(*args, 0.0, 0.5, np.float32(6.0), max_side, min_cells,
                                                              res, min_extent, 0.1)
        out_r = np.empty(64 * 900, dtype=np.int64)
        out_c = np.empty(64 * 900, dtype=np.int64)
        n = seen_through_structure_kernel(*args, out_r, out_c, 0.0)
        want = _grown_outlines(lo, list(zip(out_r[:n].tolist(), out_c[:n].tolist())), 0.5, 6.0, max_side, min_cells,
                               res, min_extent, 0.1)
        assert (got_r.tolist(), got_c.tolist(), got_s.tolist(), got_nc) == want
        yielded += len(want[2])
    assert yielded > 20
