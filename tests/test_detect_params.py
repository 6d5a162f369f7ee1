"""The detection step's configuration values packed once per tracker (docs/speed.md, pass trk49): the segmentation's
(``segment.segment_params``), ``detect_rows``' (``kernels.detect_params``) and ``fit_cluster_rows``' arguments
(``Tracker._fit_q``) are the values the tracker converted on every scan before, the same floats and types."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect import kernels as K
from dynslam2d.detect import segment as S
from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.shapes import CRITERIA
from dynslam2d.detect.tracker import Tracker


def _configs():
    """The default configuration and one with every value these arrays hold changed (integers too; the vehicle test
    on, the leg merge off, the fixed-gap segmentation)."""
    yield DetectConfig()
    cfg = DetectConfig()
    sc, fc, tc = cfg.segment, cfg.fit, cfg.tracker
    sc.mode, sc.fixed_gap, sc.lambda_deg, sc.sigma_r, sc.d_min, sc.d_max = "fixed", 0.27, 13.0, 0.021, 0.07, 0.61
    sc.max_skip_beams, sc.min_points, sc.max_points = 3, 4, 171
    sc.max_extent, sc.vehicle_max_extent, sc.vehicle_max_structure, sc.vehicle_min_free = 2.2, 5.5, 0.31, 0.43
    tc.map_occupied_logodds, tc.map_free_logodds, tc.map_free_radius = 1.7, -0.9, 2
    fc.person_merge, fc.leg_max_extent, fc.leg_pair_distance = False, 0.29, 0.57
    fc.closeness_d0, fc.circle_min_points, fc.coarse_stride = 0.013, 6, 3
    fc.point_max_points, fc.point_max_extent, fc.circle_min_radius, fc.circle_max_radius = 4, 0.17, 0.04, 0.45
    fc.circle_min_depth_ratio, fc.circle_residual_ratio = 0.35, 0.8
    yield cfg


def test_detect_params_are_the_former_scalars() -> None:
    """``detect_params``' array: ``fit_params``' columns first (the classification and ``measure_batch`` read them),
    then the twelve values ``Tracker._detect`` passed to ``detect_rows`` as scalars before pass trk49, the same
    floats (integers and flags exact)."""
    for cfg in _configs():
        sc, fc, tc = cfg.segment, cfg.fit, cfg.tracker
        fp = K.fit_params(fc)
        q = Tracker(cfg)._det_p
        assert q.dtype == np.float64 and q.shape == (K._DR_N,) and q.flags.c_contiguous
        assert q[:K._N_PARAMS].tobytes() == fp.tobytes()
        want = {K.DR_MAX_SKIP: int(sc.max_skip_beams), K.DR_EXT_LIM: max(sc.max_extent, sc.vehicle_max_extent),
                K.DR_ADMIT: sc.vehicle_max_extent > sc.max_extent, K.DR_SEG_MAX_EXTENT: float(sc.max_extent),
                K.DR_MAX_STRUCTURE: float(sc.vehicle_max_structure), K.DR_MIN_FREE: float(sc.vehicle_min_free),
                K.DR_OCC: float(tc.map_occupied_logodds), K.DR_FREE: float(tc.map_free_logodds),
                K.DR_FREE_RADIUS: int(tc.map_free_radius), K.DR_MERGE: bool(fc.person_merge),
                K.DR_LEG_MAX_EXTENT: float(fc.leg_max_extent), K.DR_PAIR_DISTANCE: float(fc.leg_pair_distance)}
        assert sorted(want) == list(range(K._N_PARAMS, K._DR_N))
        for col, v in want.items():
            assert q[col] == v, (col, q[col], v)


def test_segment_params_are_the_former_scalars() -> None:
    """``segment_params``: λ in rad, the wrap-around mode and the array of the nine values ``_segment`` passed to
    ``_segment_kernel`` as scalars before pass trk49; the tracker's is made of its configuration."""
    for cfg in _configs():
        sc = cfg.segment
        lam, mode, q = S.segment_params(sc)
        assert lam == math.radians(sc.lambda_deg) and mode == sc.wrap_around
        assert q.dtype == np.float64 and q.shape == (S._SP_N,) and q.flags.c_contiguous
        want = {S.SP_FIXED: sc.mode == "fixed", S.SP_FIXED_GAP: float(sc.fixed_gap), S.SP_LAMBDA: lam,
                S.SP_THREE_SIGMA: 3.0 * float(sc.sigma_r), S.SP_D_MIN: float(sc.d_min), S.SP_D_MAX: float(sc.d_max),
                S.SP_MAX_SKIP: int(sc.max_skip_beams), S.SP_MIN_POINTS: int(sc.min_points),
                S.SP_MAX_POINTS: int(sc.max_points)}
        assert sorted(want) == list(range(S._SP_N))
        for col, v in want.items():
            assert q[col] == v, (col, q[col], v)
        tl, tm, tq = Tracker(cfg)._seg_p
        assert tl == lam and tm == mode and tq.tobytes() == q.tobytes()


def test_fit_q_holds_the_former_arguments() -> None:
    """``Tracker._fit_q``: ``fit_cluster_rows``' eleven arguments after the arrays (but ``skip``, True in the kernel)
    as ``_detect`` made them on every scan before pass trk49, in the columns ``segment.FQ_*`` that
    ``segment.detect_scan`` reads: the same floats, the integers exact (the kernel makes them integers again, so the
    callee is compiled for the same argument types)."""
    for cfg in _configs():
        fc, sc = cfg.fit, cfg.segment
        tr = Tracker(cfg)
        fp = tr._fit_p
        ratio, rmin = fp.item(K._P_CIRCLE_DEPTH_RATIO), fp.item(K._P_CIRCLE_MIN_RADIUS)
        want = {S.FQ_CRITERION: CRITERIA[fc.criterion], S.FQ_D0: fc.closeness_d0,
                S.FQ_CIRCLE_MIN_POINTS: fc.circle_min_points, S.FQ_STRIDE: fc.coarse_stride,
                S.FQ_POINT_MAX_POINTS: fp.item(K._P_POINT_MAX_POINTS),
                S.FQ_POINT_MAX_EXTENT: fp.item(K._P_POINT_MAX_EXTENT),
                S.FQ_MAX_EXTENT: max(sc.max_extent, sc.vehicle_max_extent),
                S.FQ_THIN: ratio * rmin if ratio >= 0.0 else -math.inf,
                S.FQ_CIRCLE_MAX_RADIUS: fp.item(K._P_CIRCLE_MAX_RADIUS), S.FQ_DEPTH_RATIO: ratio,
                S.FQ_RESIDUAL_RATIO: fp.item(K._P_CIRCLE_RES_RATIO)}
        assert sorted(want) == list(range(S.N_FQ))
        fq = tr._fit_q
        assert fq.dtype == np.float64 and fq.shape == (S.N_FQ,) and fq.flags.c_contiguous
        for col, v in want.items():
            assert fq[col] == v, (col, fq[col], v)
            if type(v) is int:
                assert int(fq[col]) == v
            else:
                assert type(v) is float

def test_detect_rows_reads_each_packed_value(monkeypatch) -> None:
    """``detect_rows`` with random values in ``p``'s ``DR_*`` columns (the vehicle test's limits and shares, the map
    thresholds and radius, the leg merge's flag and distances, the classification's skip and extent limit) gives,
    bit for bit, the calls it replaces with those values as scalars (tests/test_detect_fused.py's reference), on the
    tracker's calls of two simulated runs (a van longer than max_extent; two people's legs), each with a random map."""
    from test_detect_fused import _detect_rows_ref, _same, _van_source, _walkers, _written, chained

    import dynslam2d.detect.trackdetect as td
    from dynslam2d.config import Config
    from dynslam2d.pipeline import Pipeline

    calls = []

    def capture(*a):
        if len(calls) < 400 and a[16]:  # (with the map: every value is read)
            calls.append(tuple(x.copy() if isinstance(x, np.ndarray) else x for x in a))
        return K.detect_rows(*a)

    monkeypatch.setattr(td, "detect_scan", chained(rows=capture))
    for src in (_van_source(), [s for s, _ in _walkers()]):
        pipe = Pipeline(Config())
        for scan in src:
            pipe.process(scan)
    rng = np.random.default_rng(17)
    seen = {"admit": 0, "pairs": 0, "differs": 0}
    for a in calls[::4]:
        p0 = a[15]
        for _ in range(3):
            p = p0.copy()
            p[K.DR_MAX_SKIP] = int(rng.integers(0, 4))
            p[K.DR_EXT_LIM] = rng.choice([1.0, 3.0, 6.0])
            p[K.DR_ADMIT] = float(rng.random() < 0.7)
            p[K.DR_SEG_MAX_EXTENT] = rng.choice([0.5, 1.5, 3.0])
            p[K.DR_MAX_STRUCTURE] = rng.choice([0.0, 0.2, 0.5, 1.0])
            p[K.DR_MIN_FREE] = rng.choice([0.0, 0.2, 0.5, 1.0])
            p[K.DR_OCC] = rng.choice([0.4, 1.0, 2.0])
            p[K.DR_FREE] = rng.choice([-2.0, -0.5, -0.1])
            p[K.DR_FREE_RADIUS] = int(rng.integers(0, 3))
            p[K.DR_MERGE] = float(rng.random() < 0.7)
            p[K.DR_LEG_MAX_EXTENT] = rng.choice([0.1, 0.2, 0.4])
            p[K.DR_PAIR_DISTANCE] = rng.choice([0.3, 0.6, 1.2])
            # (a random map of the call's extent: the points' shares on structure and free vary)
            lo = rng.choice(np.array([-2.0, 0.0, 0.5, 6.0], dtype=np.float32), size=a[17].shape)
            b = (*a[:15], p, a[16], lo, *a[18:])
            o = (*a[:13], int(p[K.DR_MAX_SKIP]), a[13], a[14], float(p[K.DR_EXT_LIM]), p, bool(p[K.DR_ADMIT]),
                 float(p[K.DR_SEG_MAX_EXTENT]), float(p[K.DR_MAX_STRUCTURE]), float(p[K.DR_MIN_FREE]), *b[16:21],
                 float(p[K.DR_OCC]), float(p[K.DR_FREE]), int(p[K.DR_FREE_RADIUS]), bool(p[K.DR_MERGE]),
                 float(p[K.DR_LEG_MAX_EXTENT]), float(p[K.DR_PAIR_DISTANCE]))
            got = K.detect_rows(*b)
            want = _detect_rows_ref(*o)
            for i, (g, w) in enumerate(zip(got, want)):
                assert _same(*_written(got, i, g, w)), i
            base = K.detect_rows(*a[:15], p0, *b[16:])
            seen["differs"] += not all(_same(*_written(got, i, got[i], base[i])) for i in range(7))
            seen["admit"] += bool(o[18])
            seen["pairs"] += got[7].shape[0] > 0
    assert len(calls) > 100 and seen["admit"] > 10 and seen["pairs"] > 5 and seen["differs"] > 10
