"""The detect path's fused kernels (select_detections, pass 11; detect_rows, pass fus40; the whole chain,
segment.detect_scan, pass trk72) give the results of the calls they replace, bit for bit (docs/speed.md, "The
tracker's kernels fused, pass 11")."""

from __future__ import annotations

import math

import numpy as np

import dynslam2d.detect.trackdetect as tracker_mod  # (_detect calls detect_scan there)
from dynslam2d.config import Config
from dynslam2d.detect import kernels as K
from dynslam2d.detect import segment as S
from dynslam2d.detect import shapes
from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.layout import (
    F_CENTROID_X,
    F_CENTROID_Y,
    F_CIRCLE_R,
    F_CIRCLE_RMS,
    F_CIRCLE_X,
    F_HI1,
    F_HI2,
    F_LO1,
    F_LO2,
    F_RECT_RMS,
    F_THETA,
    FIT_CENTROID,
    FIT_CIRCLE,
    N_FIT_COLS,
)
from dynslam2d.detect.mapevidence import MapView, map_evidence, map_evidence_kernel
from dynslam2d.detect.shapes import fit_clusters
from dynslam2d.detect.vehicles import admit_long_clusters, long_kept
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim.simulation import SimSource
from dynslam2d.types import Pose2D


def _admit_numpy(keep, fits, offsets, px, py, view, config) -> int:
    """The former numpy admit_long_clusters (pass 8), the reference."""
    seg = config.segment
    long_ = long_kept(keep, fits, float(seg.max_extent))
    if long_.shape[0] == 0:
        return 0
    if view is None:
        keep[long_] = False
        return 0
    sel = np.concatenate([np.arange(offsets[c], offsets[c + 1]) for c in long_.tolist()])
    tc = config.tracker
    structure, free, _ = map_evidence(np.column_stack((px[sel], py[sel])), view, tc.map_occupied_logodds,
                                      tc.map_free_logodds, tc.map_free_radius)
    n = (offsets[long_ + 1] - offsets[long_]).astype(np.float64)
    bounds = np.concatenate(([0], np.cumsum(n).astype(np.int64)))[:-1]
    s_share = np.add.reduceat(structure.astype(np.float64), bounds) / n
    f_share = np.add.reduceat(free.astype(np.float64), bounds) / n
    ok = (s_share <= seg.vehicle_max_structure) & (f_share >= seg.vehicle_min_free)
    keep[long_[~ok]] = False
    return int(ok.sum())


def test_admit_long_clusters_is_the_former_numpy_selection():
    """Random maps (free, occupied, unknown patches) and clusters, many long, some NaN points and sides, the shares
    at their limits (the limits set to shares that occur): the kernel keeps exactly the clusters the numpy code
    kept, and returns its count."""
    rng = np.random.default_rng(11)
    cfg = DetectConfig()
    res = 0.05
    n_diff = 0
    n_long_kept = n_long_dropped = 0
    for _ in range(300):
        lo = rng.choice(np.array([0.0, -2.0, -0.35, -0.3, 0.4, 0.6, 6.0, 8.0], dtype=np.float32), size=(60, 80),
                        p=[0.2, 0.35, 0.05, 0.05, 0.05, 0.05, 0.05, 0.2])
        view = MapView(lo, -5, -7, res)
        nc = int(rng.integers(1, 12))
        sizes = rng.integers(1, 40, nc)
        offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        px = rng.uniform(-0.5, 4.5, offsets[-1])
        py = rng.uniform(-0.5, 3.5, offsets[-1])
        px[rng.random(px.shape[0]) < 0.03] = np.nan
        fits = np.zeros((nc, N_FIT_COLS))
        fits[:, F_LO1] = rng.uniform(-1, 1, nc)
        fits[:, F_HI1] = fits[:, F_LO1] + rng.uniform(0, 6, nc)
        fits[:, F_LO2] = rng.uniform(-1, 1, nc)
        fits[:, F_HI2] = fits[:, F_LO2] + rng.uniform(0, 2, nc)
        fits[rng.random(nc) < 0.1, F_HI1] = np.nan
        keep0 = rng.random(nc) < 0.85
        cfg.segment.vehicle_max_structure = float(rng.choice([0.0, 0.1, 0.25, 1.0 / 3.0, 0.5]))
        cfg.segment.vehicle_min_free = float(rng.choice([0.0, 0.2, 0.25, 0.5, 2.0 / 3.0]))
        for v in (view, None):
            k_ref, k_new = keep0.copy(), keep0.copy()
            r_ref = _admit_numpy(k_ref, fits, offsets, px, py, v, cfg)
            r_new = admit_long_clusters(k_new, fits, offsets, px, py, v, cfg)
            n_diff += int(r_ref != r_new) + int((k_ref != k_new).any())
            if v is not None:
                n_long_kept += r_ref
                n_long_dropped += int((keep0 & ~k_ref).sum())
    assert n_diff == 0
    assert n_long_kept > 50 and n_long_dropped > 200  # (both outcomes occur often)


def _same(a, b) -> bool:
    """Equal arrays: dtype, shape and bytes (NaN payloads included)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def chain(a, fit=shapes.fit_cluster_rows, rows=K.detect_rows) -> tuple:
    """``segment.detect_scan(*a)`` as the three kernel calls ``Tracker._detect`` made from Python before pass trk72
    (the segmentation, ``fit`` — ``fit_cluster_rows`` or a wrapper of it — on the clusters not marked as structure
    with ``fq``'s values as the scalars ``Tracker._fit_args`` held, ``rows`` — ``detect_rows`` or a wrapper),
    the kept rows' columns of a leg merge's map evidence written as the fused kernel writes them; the tables
    ``trig`` / ``fit_trig`` the kernels fill are copies here, so the fused call after this one fills its own."""
    (ranges, angles, mask, trig, fill, q, wrap, cos_a, sin_a, c, s, x, y, ref, th, gpar, range_max, fangles, ftrig, fq,
     p, has_map, lo, i0, j0, res, dphi) = a
    labels, beams, offsets, structure, dropped, wrapped, ax, ay, px, py, pts, rr, par = S._segment_kernel(
        ranges, angles, mask, trig.copy(), fill, q, wrap, True, cos_a, sin_a, c, s, x, y, ref, th, gpar,
        range_max if ref else 0.0)
    fits = fit(px, py, offsets, ~structure, fangles, ftrig.copy(), int(fq[S.FQ_CRITERION]), fq.item(S.FQ_D0),
               int(fq[S.FQ_CIRCLE_MIN_POINTS]), int(fq[S.FQ_STRIDE]), True, fq.item(S.FQ_POINT_MAX_POINTS),
               fq.item(S.FQ_POINT_MAX_EXTENT), fq.item(S.FQ_MAX_EXTENT), fq.item(S.FQ_THIN),
               fq.item(S.FQ_CIRCLE_MAX_RADIUS), fq.item(S.FQ_DEPTH_RATIO), fq.item(S.FQ_RESIDUAL_RATIO))
    out = rows(px, py, beams, offsets, fits, structure, x, y, ranges, mask, ax, ay, wrapped, range_max, dphi, p,
               has_map, lo, i0, j0, res)
    ki, mmev = out[9], out[20]
    if ki.shape[0] and mmev.shape[1]:
        mmev[:, :ki.shape[0]] = out[6][:, ki]
    return (labels, beams, offsets, structure, dropped, wrapped, pts, rr, par, *out)


def unpacked(got: tuple, n: int, max_points: int) -> tuple:
    """``segment.detect_scan``'s 27 results (pass det109) in the 40 places of :func:`chain`'s: the segmentation's
    labels and structure by ``segment.segmentation_of`` (``n`` beams, ``max_points``), the leg merge's tuple unpacked
    where a pair was merged, and where none was its empty arrays and the selected rows again (as ``detect_rows``
    returns them)."""
    beams, offsets, dropped, wrapped, pts, rr, par, *rows7 = got[:14]
    merged, px2, py2 = got[14:17]
    seg = S.segmentation_of(beams, offsets, n, max_points, wrapped, dropped)
    if merged is None:
        none = np.empty(0, dtype=np.int64)
        starts, npts, kinds, lohi, rel, sfits, mfr = rows7
        merged = (none, none, none, kinds, sfits, lohi, rel, starts, npts, none, np.empty((0, 2)), mfr)
    return (seg.labels, beams, offsets, seg.structure, dropped, wrapped, pts, rr, par, *rows7, *merged[:9], px2, py2,
            *merged[9:], *got[17:])


def same_chain(got: tuple, want: tuple) -> bool:
    """Two results of ``detect_scan`` / :func:`chain` (``got`` already :func:`unpacked`): equal arrays
    (:func:`_same`) and scalars."""
    return len(got) == len(want) == 40 and all(
        _same(g, w) if isinstance(g, np.ndarray) else type(g) is type(w) and g == w for g, w in zip(got, want))


def chained(fit=shapes.fit_cluster_rows, rows=K.detect_rows, seen: dict | None = None):
    """A stand-in for ``trackdetect.detect_scan`` that runs :func:`chain` (with ``fit`` and ``rows``) and then the
    fused kernel, asserts both give the same results and returns the fused kernel's (``seen["chains"]`` counted)."""
    def detect_scan(*a):
        want = chain(a, fit, rows)
        got = S.detect_scan(*a)
        assert len(got) == 27 and (got[14] is None) == (want[16].shape[0] == 0)  # (None: no pair merged)
        assert same_chain(unpacked(got, a[0].shape[0], int(a[5][S.SP_MAX_POINTS])), want)
        if seen is not None:
            seen["chains"] = seen.get("chains", 0) + 1
        return got

    return detect_scan


def _select_ref(keep, kinds, lohi, rel, fits, offsets, px, py, admit, max_extent, max_structure, min_free, has_map,
                lo, i0, j0, res, occ, free_thr, radius):
    """The calls select_detections replaces (Tracker._detect before pass 11): the numpy vehicle test, the kept rows
    by flatnonzero and fancy indexing, map_evidence_kernel on the kept clusters' points and mask_fractions."""
    keep = keep.copy()
    if admit:
        cfg = DetectConfig()
        cfg.segment.max_extent, cfg.segment.vehicle_max_structure = max_extent, max_structure
        cfg.segment.vehicle_min_free = min_free
        cfg.tracker.map_occupied_logodds, cfg.tracker.map_free_logodds = occ, free_thr
        cfg.tracker.map_free_radius = radius
        _admit_numpy(keep, fits, offsets, px, py, MapView(lo, i0, j0, res) if has_map else None, cfg)
    idx = np.flatnonzero(keep)
    starts = offsets[idx]
    npts = offsets[idx + 1] - starts
    out = [starts, npts, kinds[idx], lohi[idx], rel[idx], fits[idx]]
    if not has_map:
        return (*out, np.zeros((3, 0)))
    sel = np.repeat(keep, offsets[1:] - offsets[:-1])
    det_off = np.zeros(idx.shape[0] + 1, dtype=np.int64)
    np.cumsum(npts, out=det_off[1:])
    ev = np.zeros((3, int(sel.sum())), dtype=bool)
    map_evidence_kernel(px[sel], py[sel], lo, i0, j0, res, occ, free_thr, radius, ev[0], ev[1], ev[2])
    return (*out, K.mask_fractions(ev, det_off))


def _van_source() -> SimSource:
    from test_detect_vehicles import _van_scene
    return SimSource(_van_scene())


def _walkers():
    """Scans of two people's legs (tests/test_detect_people.py's scene) seen from a slowly moving laser, with the
    poses."""
    from test_detect_people import RATE, render, scene

    return [(render(Pose2D(0.2 * i / RATE, 0.0, 0.0), i / RATE, *scene(i / RATE, 2.0, 1.2), i)[0],
             Pose2D(0.2 * i / RATE, 0.0, 0.0)) for i in range(int(6.0 * RATE))]


def _scalar_args(a, cfg: DetectConfig) -> tuple:
    """detect_rows' arguments ``a`` with the configuration's values as the scalars Tracker._detect passed before
    pass trk49 (made from ``cfg`` as it made them, not read back from ``p``'s ``DR_*`` columns; ``p``'s fit columns
    stay where the classification and ``measure_batch`` read them)."""
    sc, fc, tc = cfg.segment, cfg.fit, cfg.tracker
    return (*a[:13], int(sc.max_skip_beams), a[13], a[14], max(sc.max_extent, sc.vehicle_max_extent), a[15],
            sc.vehicle_max_extent > sc.max_extent, float(sc.max_extent), float(sc.vehicle_max_structure),
            float(sc.vehicle_min_free), *a[16:21], float(tc.map_occupied_logodds), float(tc.map_free_logodds),
            int(tc.map_free_radius), bool(fc.person_merge), float(fc.leg_max_extent), float(fc.leg_pair_distance))


def _detect_rows_ref(*a):
    """The calls detect_rows replaces (Tracker._detect before pass fus40), ``a`` its former arguments
    (:func:`_scalar_args`): classify_batch, the former calls of select_detections (_select_ref), merge_legs where
    people are merged and there are two detections or more, and the final rows' fit columns copied as
    DetectionBatch's were."""
    px, py, beams, offsets, fits = a[:5]
    keep, kinds, lohi, rel = K.classify_batch(*a[:18])
    sel = _select_ref(keep, kinds, lohi, rel, fits, offsets, px, py, *a[18:30])
    starts, npts, kinds, lohi, rel, sfits, mfr = sel
    none = np.empty(0, dtype=np.int64)
    merged = (none, none, none, kinds, sfits, lohi, rel, starts, npts, px, py, none, np.empty((0, 2)), mfr)
    if a[30] and starts.shape[0] > 1:
        merged = K.merge_legs(px, py, beams, starts, npts, kinds, sfits, lohi, rel, mfr, a[31], a[32])
    f = merged[4]
    cols = (f[:, F_THETA].copy(), f[:, FIT_CENTROID].copy(), f[:, FIT_CIRCLE].copy())
    # (and the final rows' default measurements, as Tracker._measure_rows made them before pass trk41)
    m = f.shape[0]
    kinds2, lohi2, rel2, starts2, npts2, px2, py2 = (merged[i] for i in (3, 5, 6, 7, 8, 9, 10))
    default = K.measure_batch(np.arange(m), kinds2, cols[0], lohi2, rel2, cols[1], cols[2], px2, py2, starts2, npts2,
                              np.zeros((m, 2)), np.zeros(m, dtype=bool), np.full(m, -1.0), np.zeros(m), a[17])
    return (*sel, *merged, *cols, *default)


def _written(got, i, g, w):
    """Result i of two detect_rows results (``g``, ``w``) as far as it is written: the merged map evidence (i = 20)
    only in the persons' columns when a pair was merged (merge_legs leaves the kept rows' columns unwritten)."""
    if i == 20 and got[7].shape[0]:
        nk = got[9].shape[0]
        return g[:, nk:], w[:, nk:]
    return g, w


def test_fused_kernels_give_the_former_calls_results_in_whole_runs(monkeypatch):
    """Every call of detect_rows in three simulated runs (people seen from a driving robot; a van longer than
    max_extent driving past, so the vehicle test runs with its map; two people's legs, so pairs of legs are merged)
    returns what the calls it replaces returned, bit for bit; the runs have detections, updates, vehicle-size
    clusters kept and dropped and merged pairs."""
    seen = {"calls": 0, "admit": 0, "map": 0, "pairs": 0}

    cfg = Config().detect  # (the runs' detection configuration)

    def rows(*a):
        o = _scalar_args(a, cfg)
        want = _detect_rows_ref(*o)
        got = K.detect_rows(*a)
        assert len(got) == len(want) == 31
        for i, (g, w) in enumerate(zip(got, want)):
            assert _same(*_written(got, i, g, w)), i
        seen["calls"] += 1
        seen["map"] += bool(o[22])
        seen["admit"] += bool(o[18] and o[22]) and bool(long_kept(K.classify_batch(*o[:18])[0], o[4], o[19]).shape[0])
        seen["pairs"] += got[7].shape[0]
        return got

    monkeypatch.setattr(tracker_mod, "detect_scan", chained(rows=rows, seen=seen))
    for src in (open_source("sim:drive", seed=11, duration=6.0), _van_source(), [s for s, _ in _walkers()]):
        pipe = Pipeline(Config())
        for scan in src:
            pipe.process(scan)
    assert seen["calls"] > 150 and seen["chains"] == seen["calls"]
    assert seen["map"] > 100 and seen["admit"] > 10 and seen["pairs"] > 20


def test_skipped_circle_fits_in_whole_runs(monkeypatch):
    """Passes det23 and fit34, in three simulated runs (people seen from a driving robot; two people's legs; a van):
    every ``fit_cluster_rows`` call of the tracker gives ``fit_clusters``' rows (every circle fitted) with NaN circle
    columns exactly on the rows that the plain-Python test below names, a cluster skipped as too long for a circle
    has a full fit the classification refuses, and the classification of every call is bit for bit the
    classification of the same clusters with every circle fitted."""
    seen = {"fits": 0, "skipped": 0, "long": 0}
    full_fits: list = []

    def fit_rows(*a):
        got = shapes.fit_cluster_rows(*a)
        x, y, offsets, mask, angles, trig, crit, d0, cmin, stride, skip, pmax_n, pmax_ext, max_ext, thin, maxr, \
            depth, ratio = a
        want = fit_clusters(x, y, offsets, mask, angles, crit, d0, cmin, stride)
        full_fits[:] = [want]
        want = want.copy()
        for q in range(want.shape[0]):
            n = int(offsets[q + 1] - offsets[q])
            e0, e1 = want[q, F_HI1] - want[q, F_LO1], want[q, F_HI2] - want[q, F_LO2]
            # (pass fit34: longer than any accepted circle's 2r + √(2n)·rms, r ≤ max radius and ≤ short side / depth
            # ratio, with the kernel's margin)
            r_top = min(maxr, min(e0, e1) / depth) if depth > 0.0 else maxr
            reach = (2.0 * r_top + math.sqrt(2.0 * n) * ratio * want[q, F_RECT_RMS]) * (1.0 + 1e-9) + 1e-9 * (
                1.0 + abs(want[q, F_CENTROID_X]) + abs(want[q, F_CENTROID_Y]) + max(e0, e1))
            long_ = max(e0, e1) >= reach
            if skip and mask[q] and n >= cmin and (n <= pmax_n or max(e0, e1) < pmax_ext or max(e0, e1) > max_ext
                                                   or min(e0, e1) < thin or long_):
                want[q, F_CIRCLE_X:F_CIRCLE_RMS + 1] = np.nan
                seen["skipped"] += 1
                if long_:  # (the full fit's circle fails the classification's radius or residual test)
                    seen["long"] += 1
                    cr = full_fits[0][q, F_CIRCLE_R]
                    assert not (cr <= maxr and min(e0, e1) >= depth * cr
                                and full_fits[0][q, F_CIRCLE_RMS] < ratio * want[q, F_RECT_RMS])
        assert _same(got, want)
        seen["fits"] += 1
        return got

    def classify(*a):
        got = K.detect_rows(*a)
        want = K.detect_rows(*a[:4], full_fits[0], *a[5:])  # (every circle fitted)
        # (the classification, the selection and the merge: all but the fit rows and circle columns, which differ
        # where a circle was skipped)
        assert all(_same(*_written(got, i, got[i], want[i])) for i in range(31) if i not in (5, 11, 23))
        return got

    monkeypatch.setattr(tracker_mod, "detect_scan", chained(fit_rows, classify))
    for src in (open_source("sim:drive", seed=11, duration=6.0), [s for s, _ in _walkers()], _van_source()):
        pipe = Pipeline(Config())
        for scan in src:
            pipe.process(scan)
    assert seen["fits"] > 150 and seen["skipped"] > 20 and seen["long"] > 5


def test_skipped_circle_fits_are_fitted_when_read():
    """The circle of every detection of two simulated runs (people and cars seen from a driving robot; two people's
    legs seen from a slowly moving robot), read after the scan (a skipped fit is then made by
    ``ScanDetection.circle``), is bit for bit the circle columns of ``fit_clusters`` on the detection's points
    (every circle fitted); skipped fits occur in both runs."""
    from dynslam2d.detect import Tracker
    from dynslam2d.detect.shapes import CRITERIA
    from dynslam2d.sim import simulate

    cfg = DetectConfig()
    fc = cfg.fit
    drive = simulate("drive", duration=4.0)
    runs = [_walkers(), list(zip(drive.scans, [Pose2D.from_array(q) for q in drive.ground_truth.poses_in("first")]))]
    for run in runs:
        tr = Tracker(cfg)
        skipped = checked = 0
        for scan, pose in run:
            tr.update(scan, pose)
            for d in tr.last_detections:
                if d.person:
                    continue
                skipped += bool(np.isnan(d._s.fits[d._j, F_CIRCLE_R]))
                pts = np.ascontiguousarray(d.points)
                n = pts.shape[0]
                want = fit_clusters(pts[:, 0].copy(), pts[:, 1].copy(), np.array([0, n]), np.ones(1, dtype=bool),
                                    tr._angles, CRITERIA[fc.criterion], fc.closeness_d0, fc.circle_min_points,
                                    fc.coarse_stride)[0, FIT_CIRCLE]
                assert _same(d.circle, want)
                checked += 1
        assert skipped >= 5 and checked > 2 * skipped


def test_structure_column_is_the_detections_own_values():
    """``Tracker._structure_column`` (the final rows' ``map_structure`` read as one list a scan, pass trk72) is, in
    every scan of two runs with a map (people and cars seen from a driving robot; two people's legs, merged into
    persons), each detection's own ``map_structure`` in their order, the merged persons' and the kept detections'
    after a merge too."""
    seen = {"scans": 0, "merged": 0, "on": 0}
    for src in (open_source("sim:drive", seed=11, duration=6.0), [s for s, _ in _walkers()]):
        pipe = Pipeline(Config())
        for scan in src:
            pipe.process(scan)
            tr = pipe.tracker
            dets = tr.last_detections
            if not dets or tr._map is None:
                continue
            tr._ms = None  # (read afresh, not the list an earlier step of this scan read)
            got = tr._structure_column(dets)
            assert got == [d.map_structure for d in dets]
            assert tr._ms_ev is not None
            seen["scans"] += 1
            seen["merged"] += any(d.person for d in dets)
            seen["on"] += any(v > 0.0 for v in got)
    assert seen["scans"] > 100 and seen["merged"] > 10 and seen["on"] > 10


def test_doomed_clusters_are_not_fitted_and_the_results_stay(monkeypatch):
    """Pass det118: ``detect_scan`` does not fit the clusters whose end points are more than √2 · the limit apart
    (``vehicles.doomed_clusters``: too long for the classification, or long and refused by the vehicle test's map
    shares), and every result stays bit for bit the chain's, which fits every cluster (:func:`chained`), on every
    tracker call of sim:crowd (walls longer than the limits) and the van scene (a long cluster the map test keeps).
    Each doomed cluster's full fit has a side longer than ``segment.max_extent`` (longer than the extent limit where
    doomed as too long) and none is a detection; long clusters the map test keeps occur, as do both kinds of
    doomed clusters."""
    from dynslam2d.detect.vehicles import doomed_clusters

    seen = {"too_long": 0, "refused": 0, "tested_kept": 0}
    fused = chained(seen=seen)

    def detect_scan(*a):
        got = fused(*a)
        (ranges, angles, mask, trig, fill, q, wrap, cos_a, sin_a, c, s, x, y, ref, th, gpar, range_max, fangles,
         ftrig, fq, p, has_map, lo, i0, j0, res, dphi) = a
        _, _, offsets, structure, _, _, _, _, px, py, _, _, _ = S._segment_kernel(
            ranges, angles, mask, trig.copy(), fill, q, wrap, True, cos_a, sin_a, c, s, x, y, ref, th, gpar,
            range_max if ref else 0.0)
        doomed = doomed_clusters(px, py, offsets, structure, ftrig, p[K.DR_EXT_LIM], p[K.DR_ADMIT] != 0.0,
                                 p[K.DR_SEG_MAX_EXTENT], has_map, lo, i0, j0, res, p[K.DR_OCC], p[K.DR_FREE],
                                 int(p[K.DR_FREE_RADIUS]), p[K.DR_MAX_STRUCTURE], p[K.DR_MIN_FREE])
        fits = fit_clusters(px, py, offsets, ~structure, fangles, int(fq[S.FQ_CRITERION]), fq.item(S.FQ_D0),
                            int(fq[S.FQ_CIRCLE_MIN_POINTS]), int(fq[S.FQ_STRIDE]))
        side = np.maximum(fits[:, F_HI1] - fits[:, F_LO1], fits[:, F_HI2] - fits[:, F_LO2])
        starts = set(got[7].tolist())  # (the detections' first points: the kept clusters)
        for cl in np.flatnonzero(doomed & ~structure).tolist():
            assert side[cl] > p[K.DR_SEG_MAX_EXTENT] and int(offsets[cl]) not in starts
            if side[cl] > p[K.DR_EXT_LIM]:
                seen["too_long"] += 1
            else:
                seen["refused"] += 1
        chord = np.hypot(px[offsets[1:] - 1] - px[offsets[:-1]], py[offsets[1:] - 1] - py[offsets[:-1]])
        tested = (chord / math.sqrt(2.0) > p[K.DR_SEG_MAX_EXTENT] * 1.001) & (side <= p[K.DR_EXT_LIM]) & ~structure
        seen["tested_kept"] += int((tested & ~doomed).sum()) if has_map else 0
        return got

    monkeypatch.setattr(tracker_mod, "detect_scan", detect_scan)
    for src in (open_source("sim:crowd", duration=8.0), _van_source()):
        pipe = Pipeline(Config())
        for scan in src:
            pipe.process(scan)
    assert seen["chains"] > 150
    assert seen["too_long"] > 50 and seen["refused"] > 50 and seen["tested_kept"] > 5, seen
