"""The tracker's state arrays (issue 9 speed): every live track's Kalman state x and covariance P are views of
one row of ``Tracker._X`` / ``_P``, kept for the track's life, with the rows of deleted tracks reused by
births and the arrays doubled when full. Checked on a simulated room with a moving box and short-lived posts
(many births and deletions): each track keeps its own state through deletions of others and row reuse,
the reports carry exactly the track's state, and growth or a deep copy changes no report."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.sim import cast_rays, rect_segments
from dynslam2d.types import Pose2D, Scan

N = 360
DT = 0.1


def _scan(i: int) -> Scan:
    """Scan i of a 12 × 10 m room seen from the centre: a 0.6 m box driving at 1 m/s, and 0.2 m posts that each
    stand for 2-6 scans at places drawn per post (tentative tracks that are born and deleted)."""
    rng = np.random.default_rng(1000 + i)
    segs = [rect_segments(0.0, 0.0, 0.0, 12.0, 10.0), rect_segments(-3.0 + 1.0 * i * DT, 2.0, 0.0, 0.6, 0.6)]
    for p in range(12):
        life = np.random.default_rng(p).integers(2, 7)
        born = (p * 5) % 40
        if born <= i % 40 < born + life:
            prng = np.random.default_rng(100 * p + i // 40)
            segs.append(rect_segments(prng.uniform(-4.5, 4.5), prng.uniform(-3.5, -0.5), 0.0, 0.2, 0.2))
    segs = np.vstack(segs)
    angles = -math.pi + np.arange(N) * 2 * math.pi / N
    dist, _ = cast_rays((0.0, 0.0), angles, segs, np.zeros(segs.shape[0], dtype=np.int32), np.zeros((0, 3)),
                        np.zeros(0, dtype=np.int32))
    r = dist + rng.normal(0.0, 0.005, dist.shape)
    r[~np.isfinite(dist)] = np.inf
    return Scan(stamp=i * DT, angle_min=-math.pi, angle_increment=2 * math.pi / N, ranges=r, range_min=0.1,
                range_max=20.0)


SCANS = 90
POSE = Pose2D(0.0, 0.0, 0.0)


def _same(a: list, b: list) -> bool:
    """Two reports equal field by field (floats and arrays bit for bit)."""
    if [t.id for t in a] != [t.id for t in b]:
        return False
    for x, y in zip(a, b):
        if (x.state, x.hits, x.misses, x.kind, x.in_m, x.m_reason, x.box) != (
                y.state, y.hits, y.misses, y.kind, y.in_m, y.m_reason, y.box):
            return False
        for f in ("velocity", "covariance", "beams"):
            if getattr(x, f).tobytes() != getattr(y, f).tobytes():
                return False
    return True


def test_each_track_keeps_its_own_state_row_through_births_and_deletions() -> None:
    tr = Tracker(DetectConfig())
    prev: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    coasting_checked = 0
    for i in range(SCANS):
        out = tr.update(_scan(i), POSE)
        rows = [k.row for k in tr._tracks]
        assert len(set(rows)) == len(rows)  # one row per live track
        by_id = {t.id: t for t in out}
        for k in tr._tracks:
            assert np.shares_memory(k.x, tr._X[k.row]) and np.shares_memory(k.P, tr._P[k.row])
            t = by_id[k.id]
            assert t.velocity.tobytes() == k.x[2:].tobytes() and t.covariance.tobytes() == k.P.tobytes()
            assert not np.shares_memory(t.covariance, tr._P)  # the reports have memory of their own
            if k.id in prev and t.misses > 0:
                # not detected: the constant-velocity prediction of its own previous state (another track's
                # row would put it elsewhere)
                x0, _ = prev[k.id]
                assert t.velocity.tolist() == x0[2:].tolist()
                assert np.allclose(t.box.center, x0[:2] + DT * x0[2:], atol=1e-9)
                coasting_checked += 1
        prev = {k.id: (k.x.copy(), k.P.copy()) for k in tr._tracks}
    st = tr.stats
    assert st.tracks_born >= 30 and st.tracks_deleted >= 25  # the posts were tracked and dropped
    assert tr._rows_used < st.tracks_born  # rows of deleted tracks were reused
    assert coasting_checked >= 10
    assert any(t.hits >= 40 and t.in_m for t in out)  # the box kept one track through it all, and moves


def test_growth_and_deep_copy_change_no_report() -> None:
    ref = Tracker(DetectConfig())
    small = Tracker(DetectConfig())
    small._init_rows(1, small.config.tracker.sustain_updates)  # one row: doubled again and again
    copied = None
    for i in range(SCANS):
        scan = _scan(i)
        a = ref.update(scan, POSE)
        assert _same(a, small.update(scan, POSE))
        if i == 45:
            copied = copy.deepcopy(ref)
        elif copied is not None:
            assert _same(a, copied.update(scan, POSE))
    assert small._X.shape[0] >= 8 and copied is not None
    # (the tables stay views of the two buffers through the doublings and in the copy: pass trk129)
    for tr in (ref, small, copied):
        for a in (tr._X, tr._P, tr._G, tr._CL, tr._MEV):
            assert np.shares_memory(a, tr._F)
        assert np.shares_memory(tr._CI, tr._Fi) and np.shares_memory(tr._WN, tr._Fi)
        assert all(k.x.base is not None and np.shares_memory(k.x, tr._F) for k in tr._tracks)


def test_a_track_whose_covariance_turns_non_finite_is_deleted() -> None:
    """The management tests every entry of each live track's covariance row (no per-track flag kept): a NaN
    velocity variance, which the position-σ test cannot see (max(NaN, σ²) is NaN, never above the limit), deletes
    the track (``deleted_covariance``) in the next scan, and only that track; no report carries a non-finite P."""
    tr = Tracker(DetectConfig())
    for i in range(30):
        tr.update(_scan(i), POSE)
    k = max(tr._tracks, key=lambda k: k.hits)  # the moving box
    k.P[2, 2] = np.nan  # (a view of its row of the state arrays)
    before = tr.stats.deleted_covariance
    out = tr.update(_scan(30), POSE)
    assert tr.stats.deleted_covariance == before + 1
    assert k.id not in {t.id for t in out}
    assert all(np.isfinite(t.covariance).all() for t in out)


def _box_reference(k, vx: float, vy: float, slow: float) -> tuple[float, float, float]:
    """The reported heading, length and width of a track as the per-track Python of the reports computed them
    before the shape rows (the kernel ``report_boxes`` must give the same floats)."""
    speed = math.hypot(vx, vy)
    if k.kind == "circle":
        return (math.atan2(vy, vx) if speed > slow else 0.0), 2.0 * k.radius, 2.0 * k.radius
    sa, sb = k.size
    tb = k.theta_box
    if speed > slow:
        q = int(round(((math.atan2(vy, vx) - tb + math.pi) % (2 * math.pi) - math.pi) / (0.5 * math.pi)))
        theta, length, width = tb + q * 0.5 * math.pi, *((sa, sb) if q % 2 == 0 else (sb, sa))
    elif sb > sa:
        theta, length, width = tb + 0.5 * math.pi, sb, sa
    else:
        theta, length, width = tb, sa, sb
    return (theta + math.pi) % (2 * math.pi) - math.pi, length, width


def test_shape_rows_and_reported_boxes() -> None:
    """Every live track's shape state (axis angle, sizes, radius, kind, flags) is a view of its rows of
    ``Tracker._G`` / ``_Gi``. The boxes of the reports (kernel
    ``report_boxes``) equal the per-track reference above bit for bit, and so does a track whose speed equals the
    moving limit exactly: the kernel leaves it undecided and ``math.hypot`` decides (still: along its longer side)."""
    tr = Tracker(DetectConfig())
    slow = 0.5 * tr.config.tracker.v_min
    checked = 0
    for i in range(SCANS):
        out = tr.update(_scan(i), POSE)
        by_id = {t.id: t for t in out}
        for k in tr._tracks:
            assert np.shares_memory(k.g, tr._G[k.row]) and np.shares_memory(k.gi, tr._Gi[k.row])
            b = by_id[k.id].box
            assert (b.theta, b.length, b.width) == _box_reference(k, *k.x[2:].tolist(), slow)
            checked += 1
    assert checked >= 300 and any(t.in_m and t.kind == "rect" for t in out)
    k = max(tr._tracks, key=lambda k: k.hits)  # the moving box
    k.x[2:] = (slow, 0.0)  # exactly at the limit: hypot(slow, 0) == slow, not above it
    t = next(t for t in tr._report(SCANS * DT, set()) if t.id == k.id)
    assert (t.box.theta, t.box.length, t.box.width) == _box_reference(k, slow, 0.0, slow)
    assert t.box.length == max(k.size)
    k.x[2:] = (np.nextafter(slow, 1.0), 0.0)  # one ulp above: moving, headed along +x
    t = next(t for t in tr._report(SCANS * DT, set()) if t.id == k.id)
    assert (t.box.theta, t.box.length, t.box.width) == _box_reference(k, float(np.nextafter(slow, 1.0)), 0.0, slow)
    assert abs(t.box.theta) < 0.5


def test_births_one_at_a_time_when_confirmed_at_once() -> None:
    """With ``confirm_hits`` 1 a birth is confirmed at once and may host the next detections as fragments, so the
    fragments and births of a scan are decided one detection at a time (``Tracker._host_of_fragment``): every new
    track is reported confirmed in its first scan with its own rows (state and shape), and the moving box keeps one
    track into M."""
    tr = Tracker(DetectConfig.model_validate({"tracker": {"confirm_hits": 1, "confirm_window": 1}}))
    seen: set[int] = set()
    born = 0
    for i in range(SCANS):
        out = tr.update(_scan(i), POSE)
        rows = [k.row for k in tr._tracks]
        assert len(set(rows)) == len(rows)
        for t in out:
            if t.id not in seen:
                seen.add(t.id)
                born += 1
                k = next(k for k in tr._tracks if k.id == t.id)
                assert t.state == "confirmed" and t.hits == 1 and t.misses == 0
                assert np.shares_memory(k.g, tr._G[k.row]) and t.kind == k.kind
    assert born == tr.stats.tracks_born >= 10
    assert any(t.hits >= 40 and t.in_m for t in out)


def _manage_reference(P: np.ndarray, vx: float, vy: float, max_sig: float) -> tuple[bool, float]:
    """The management's covariance test and σ of the speed along the velocity as its per-track Python computed them
    before the kernel ``manage_rows`` (Python floats, math.sqrt, max)."""
    if not np.isfinite(P).all():
        return True, 0.0
    p = P.tolist()
    if math.sqrt(max(p[0][0], p[1][1])) > max_sig:
        return True, 0.0
    speed = math.hypot(vx, vy)
    if speed > 1e-9:
        u0, u1 = vx / speed, vy / speed
        return False, math.sqrt(max((u0 * p[2][2] + u1 * p[3][2]) * u0 + (u0 * p[2][3] + u1 * p[3][3]) * u1, 0.0))
    return False, math.sqrt(max(p[2][2], p[3][3]))


def test_manage_rows_is_the_former_per_track_arithmetic() -> None:
    """``manage_rows`` (the management's covariance test and speed σ of all live tracks) gives the per-track Python's
    outcomes and floats bit for bit on random rows in a shuffled order: non-finite entries, a position σ just above
    and below the limit, velocities at rest or below 1e-9, a velocity covariance whose quadratic form is negative
    (σ 0), and velocities whose libm hypot differs from Python's math.hypot by an ulp (the speeds are given)."""
    from dynslam2d.detect.kernels import manage_rows

    rng = np.random.default_rng(7)
    n = 4000
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) * rng.uniform(0.01, 2.0, size=(n, 1, 1))
    P[::97, 2, 3] = P[::97, 3, 2] = -5.0 * (P[::97, 2, 2] + P[::97, 3, 3])  # indefinite: uᵀ P_v u < 0 for some u
    P[5::101, rng.integers(0, 4), rng.integers(0, 4)] = np.nan
    P[7::103, 1, 1] = np.inf
    max_sig = 1.5
    P[11::53, 0, 0] = max_sig * max_sig
    P[13::53, 0, 0] = np.nextafter(max_sig * max_sig, 10.0)
    X = rng.normal(size=(n, 4)) * rng.choice([1e-12, 1e-3, 1.0, 30.0], size=(n, 1))
    X[::17, 2:] = 0.0
    vx, vy = X[:, 2].tolist(), X[:, 3].tolist()
    speeds = [math.hypot(a, b) for a, b in zip(vx, vy)]
    assert any(s != float(h) for s, h in zip(speeds, np.hypot(X[:, 2], X[:, 3])))  # (libm's hypot differs here)
    rows = rng.permutation(n)
    bad, sig = manage_rows(P, X, rows, np.array([speeds[r] for r in rows]), max_sig)
    ref = [_manage_reference(P[r], vx[r], vy[r], max_sig) for r in rows.tolist()]
    assert bad.tolist() == [b for b, _ in ref]
    assert [s for s, b in zip(sig.tolist(), bad.tolist()) if not b] == [s for b, s in ref if not b]
    assert 0 < bad.sum() < n and any(s == 0.0 for b, s in ref if not b)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal bit for bit (NaN equal to NaN)."""
    return bool(np.all((a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))))


def test_cv_predict_is_numpys_prediction_bit_for_bit() -> None:
    """``cv_predict`` (the Kalman prediction of all live tracks in one kernel call) gives numpy's ``X[rows] @ F.T``
    and ``F @ P[rows] @ F.T + Q`` bit for bit (OpenBLAS's dgemm sums: one FMA per term) on random stacks of 2-200
    rows in a shuffled order, with magnitudes over ten decades and non-finite entries, and writes the same values
    into the rows; a plain sum of rounded products (no FMA) differs on most stacks, so the test tells them apart."""
    from dynslam2d.detect.kernels import cv_predict
    from dynslam2d.detect.tracker import _cv_matrices

    rng = np.random.default_rng(11)
    plain_differs = 0
    bitwise: list[bool] = []
    for trial in range(300):
        n = int(rng.integers(2, 200))
        m = n + int(rng.integers(0, 20))
        X = rng.normal(size=(m, 4)) * 10.0 ** rng.uniform(-4, 4, size=(m, 1))
        A = rng.normal(size=(m, 4, 4)) * 10.0 ** rng.uniform(-3, 2, size=(m, 1, 1))
        P = A @ A.transpose(0, 2, 1)
        if trial % 4 == 0:
            P[rng.integers(0, m), rng.integers(0, 4), rng.integers(0, 4)] = rng.choice([np.inf, -np.inf, np.nan, -0.0])
            X[rng.integers(0, m), rng.integers(0, 4)] = rng.choice([np.inf, np.nan, -0.0])
        rows = rng.permutation(m)[:n].astype(np.int64)
        F, Q = _cv_matrices(float(rng.uniform(0.01, 0.3)), float(rng.uniform(0.1, 5.0)))
        with np.errstate(invalid="ignore"):
            Xr = X[rows] @ F.T
            Pr = F @ P[rows] @ F.T + Q
        Xw, Pw = X.copy(), P.copy()
        Xo, Po = cv_predict(Xw, Pw, rows, F, Q)
        rest = np.setdiff1d(np.arange(m), rows)
        assert _same_bits(Xw[rest], X[rest]) and _same_bits(Pw[rest], P[rest])
        with np.errstate(invalid="ignore"):
            assert np.allclose(Po, Pr, rtol=1e-12, atol=0.0, equal_nan=True)
        FP = np.einsum("ik,nkj->nij", F, P[rows])  # (rounded products summed: no FMA)
        plain = np.einsum("nik,jk->nij", FP, F) + Q
        plain_differs += not _same_bits(plain, Pr)
        bitwise.append(_same_bits(Xo, Xr) and _same_bits(Po, Pr) and _same_bits(Xw[rows], Xr)
                       and _same_bits(Pw[rows], Pr))
    if plain_differs <= 100:
        pytest.skip("numpy's BLAS here sums without one FMA per term (not OpenBLAS's dgemm), so the bitwise "
                    "comparison does not apply; the values agree to 1e-12")
    assert all(bitwise)


def test_cv_fill_rewrites_the_prediction_matrices_of_each_step() -> None:
    """``_cv_fill`` (the tracker's own F and Q arrays with this step's entries written, ``Tracker._predict``) leaves
    them equal bit for bit to ``_cv_matrices``' new arrays for every step of a sequence of dt (1e-4 … 2 s, the same
    two arrays reused from step to step, so an entry it forgot to rewrite would keep the previous step's value) and
    noise densities."""
    from dynslam2d.detect.tracker import _cv_fill, _cv_matrices

    rng = np.random.default_rng(13)
    F, Q = np.eye(4), np.zeros((4, 4))
    for _ in range(2000):
        dt = float(10.0 ** rng.uniform(-4, 0.3))
        q = float(rng.uniform(0.0, 5.0))
        _cv_fill(F, Q, dt, q)
        F0, Q0 = _cv_matrices(dt, q)
        assert F.tobytes() == F0.tobytes() and Q.tobytes() == Q0.tobytes()
