"""The update step's kernels (detect/kernels_update.py) against the plain Python they replace: ``py_hypot`` against
``math.hypot`` bit for bit, ``accel_bound`` against ``Tracker._bound_acceleration``'s former per-row loop."""

from __future__ import annotations

import math
import struct

import numpy as np

from dynslam2d.detect.kernels import accel_candidates
from dynslam2d.detect.kernels_update import accel_bound, hypot_rows


def _bits(values) -> list[int]:
    """The IEEE bit patterns of floats (so −0.0 ≠ 0.0 and a NaN equals a NaN of the same bits)."""
    return [struct.unpack("<q", struct.pack("<d", v))[0] for v in values]


def test_py_hypot_is_math_hypot_bit_for_bit() -> None:
    """Random pairs over every scale (one coordinate up to 1e16 times the other, where the last bits of the
    correction decide), velocities like the tracker's, and the edge values: zeros of both signs, subnormals (the
    DBL_MIN scaling), the largest doubles, infinities and NaNs in every combination. A libm hypot, or the square
    root of the plain sum of squares, differs from math.hypot on this many pairs (checked below)."""
    rng = np.random.default_rng(7)
    n = 400_000
    xs, ys = [], []
    for scale in (1e-300, 1e-9, 1e-3, 1.0, 3.0, 1e3, 1e150, 1e300):
        a = rng.normal(size=n) * scale
        b = a * rng.choice([1e-16, 1e-8, 1e-3, 0.1, 1.0, 0.5, 7.0], n) * rng.normal(size=n)
        xs.append(a)
        ys.append(b)
    # velocity changes of the acceleration bound: m/s, near a few limits
    v = rng.uniform(-3.0, 3.0, (n, 2))
    xs.append(v[:, 0])
    ys.append(v[:, 1])
    edge = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-310, 1.7976931348623157e308,
            -1.7976931348623157e308, math.inf, -math.inf, math.nan, 1.0, -2.5, 3e-320]
    ea, eb = np.meshgrid(np.array(edge), np.array(edge))
    xs.append(ea.ravel())
    ys.append(eb.ravel())
    a = np.concatenate(xs)
    b = np.concatenate(ys)
    got = hypot_rows(a, b)
    want = list(map(math.hypot, a.tolist(), b.tolist()))
    assert _bits(got.tolist()) == _bits(want)
    # (the test can fail: the naive form differs from math.hypot on these pairs)
    with np.errstate(over="ignore", invalid="ignore"):
        naive = np.sqrt(a * a + b * b)
    assert sum(x != y for x, y in zip(naive.tolist(), want) if x == x and y == y) > 1000


def _bound_python(X_prior: np.ndarray, X_new: np.ndarray, hits: list[int], lim: float, after: int) -> int:
    """``Tracker._bound_acceleration``'s loop before the kernel (main at 0c1213a), on its own."""
    near = accel_candidates(X_prior, X_new, (0.999 * lim) ** 2)
    nb = 0
    for r, (pvx, pvy), (nvx, nvy) in zip(near.tolist(), X_prior.take(near, axis=0)[:, 2:].tolist(),
                                              X_new.take(near, axis=0)[:, 2:].tolist()):
        if hits[r] < after:
            continue
        dvx = nvx - pvx
        dvy = nvy - pvy
        d = math.hypot(dvx, dvy)
        if d > lim:
            X_new[r, 2] = pvx + dvx * lim / d
            X_new[r, 3] = pvy + dvy * lim / d
            nb += 1
    return nb


def test_accel_bound_is_the_former_per_row_loop() -> None:
    """Random updates (velocity changes spread around the limit, some exactly on it or on the candidate filter's
    0.999 of it, young tracks skipped): the bounded states' bytes and the count equal the Python loop's."""
    rng = np.random.default_rng(11)
    bounded = 0
    for _ in range(3000):
        n = int(rng.integers(1, 40))
        lim = float(rng.choice([0.05, 0.25, 0.4 * 0.1, 1.5]))
        Xp = rng.normal(size=(n, 4))
        ang = rng.uniform(-math.pi, math.pi, n)
        mag = lim * rng.choice([0.5, 0.999, 0.9995, 1.0, 1.0000001, 1.2, 5.0], n) * rng.uniform(0.999, 1.001, n)
        Xn = Xp + rng.normal(scale=0.05, size=(n, 4))
        Xn[:, 2] = Xp[:, 2] + mag * np.cos(ang)
        Xn[:, 3] = Xp[:, 3] + mag * np.sin(ang)
        exact = rng.random(n) < 0.1  # (a change of exactly lim along an axis)
        Xn[exact, 2] = Xp[exact, 2] + lim
        Xn[exact, 3] = Xp[exact, 3]
        hits = rng.integers(1, 6, n).tolist()
        after = int(rng.integers(1, 5))
        want = Xn.copy()
        nb_want = _bound_python(Xp, want, hits, lim, after)
        got = Xn.copy()
        near = accel_candidates(Xp, got, (0.999 * lim) ** 2)
        rows = [r for r in near.tolist() if hits[r] >= after]
        nb = accel_bound(Xp, got, np.array(rows, dtype=np.int64), lim) if rows else 0
        assert nb == nb_want
        assert got.tobytes() == want.tobytes()
        bounded += nb
    assert bounded > 5000


def test_manage_counters_speeds_are_manage_rows_with_python_speeds() -> None:
    """``manage_counters`` gives ``manage_rows``' covariance outcomes and σ with the speeds Python's math.hypot gives
    (the values ``Tracker._manage`` handed to ``manage_rows`` before pass cnt36), bit for bit, on random rows in a
    shuffled order: non-finite covariances, speeds at rest and below 1e-9, velocities whose libm hypot differs from
    math.hypot. All rows confirmed and updated, no speed limit: the outcome is "updated" or "updated, covariance
    deleted" exactly where ``manage_rows`` says the covariance fails."""
    from dynslam2d.detect.kernels import manage_rows
    from dynslam2d.detect.kernels_update import (
        C_STATE,
        C_UPD,
        MC_DEL_COVARIANCE,
        MC_UPD_FIRM,
        MC_UPDATED,
        ST_CONFIRMED,
        UP_MAX_COAST,
        UP_MAX_POS_SIG,
        UP_MAX_SPEED,
        UP_NEED,
        UP_WINDOW,
        manage_counters,
    )

    rng = np.random.default_rng(5)
    n = 6000
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) * rng.uniform(0.01, 2.0, size=(n, 1, 1))
    P[5::101, 1, 2] = np.nan
    P[7::103, 0, 0] = np.inf
    X = rng.normal(size=(n, 4)) * rng.choice([1e-12, 1e-3, 1.0, 30.0], size=(n, 1))
    X[::17, 2:] = 0.0
    rows = rng.permutation(n)
    speeds = list(map(math.hypot, X[rows, 2].tolist(), X[rows, 3].tolist()))
    assert any(s != float(h) for s, h in zip(speeds, np.hypot(X[rows, 2], X[rows, 3])))  # (libm's differs here)
    bad0, sig0 = manage_rows(P, X, rows, np.array(speeds), 1.5)
    CI = np.zeros((n, 6), dtype=np.int64)
    CI[:, C_STATE] = ST_CONFIRMED
    CI[:, C_UPD] = 1
    q = np.zeros(UP_MAX_POS_SIG + 1)
    q[UP_WINDOW], q[UP_NEED], q[UP_MAX_COAST], q[UP_MAX_SPEED], q[UP_MAX_POS_SIG] = 3, 2, 1.0, np.inf, 1.5
    WN = rng.integers(0, 3, size=(n, 3))
    out, sig, speed, near = manage_counters(P, X, CI, np.zeros(n), WN, rows, q, 0.0)
    assert near.tolist() == WN[rows, 2].tolist()  # (the windows' riding pre-test, read in the same call: pass trk41)
    assert _bits(speed.tolist()) == _bits(speeds)
    assert (out == MC_UPDATED + MC_DEL_COVARIANCE).tolist() == bad0.tolist()
    assert set(out[~bad0].tolist()) == {MC_UPD_FIRM}
    assert sig.tobytes() == sig0.tobytes()
    assert 0 < bad0.sum() < n and not CI[:, C_UPD].any()


def _kalman_pairs_python(Xs, Ps, sel, H, zm, Rm, bound, hits, after, lim, X, P, trows) -> tuple:
    """``Tracker._update_pairs``' Kalman step before ``kalman_pairs`` (main at 4f30595): two gathers, the kernel,
    the acceleration bound's candidates filtered in Python and ``accel_bound``, two scatters (on ``X``, ``P``)."""
    from dynslam2d.detect.kernels import kalman_update_batch

    X_prior = Xs.take(sel, axis=0)
    Xn, Pn, ok = kalman_update_batch(X_prior, Ps.take(sel, axis=0), H, zm, Rm)
    nb = 0
    if bound:
        near = accel_candidates(X_prior, Xn, (0.999 * lim) ** 2)
        rows = [r for r in near.tolist() if hits[r] >= after]
        if rows:
            nb = accel_bound(X_prior, Xn, np.array(rows, dtype=np.int64), float(lim))
    if all(ok.tolist()):
        X[trows] = Xn
        P[trows] = Pn
    else:
        X[trows[ok]] = Xn[ok]
        P[trows[ok]] = Pn[ok]
    return ok, nb


def test_merged_kernels_are_the_calls_they_replace_in_a_tracker_run() -> None:
    """``association_gates`` (inside ``associate_scan`` since pass trk75: checked on its arguments) against
    ``association_rows`` → ``gate_costs`` → ``size_jump_gate`` and ``kalman_pairs`` against the former Python of
    ``_update_pairs``, on every call of a tracker run over a simulated crowd and a drive (bytes of every output and
    of the written state rows), and ``kalman_pairs`` again on the same calls with a limit 30 × tighter (most
    established rows bounded) and with the bound off."""
    from dynslam2d.detect import DetectConfig, Tracker
    from dynslam2d.detect import kernels_assign as ka
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect import tracker as trk
    from dynslam2d.detect.kernels import (
        _N_PARAMS,
        association_rows,
        gate_costs,
        measure_batch,
        pair_priors,
        size_jump_gate,
    )
    from dynslam2d.detect.kernels_assign import associate_scan
    from dynslam2d.sim import simulate
    from dynslam2d.types import Pose2D

    seen = {"gates": 0, "kalman": 0, "bounded": 0, "not_ok": 0}

    def gates(G, Gi, rows, CI, Xs, Ps, Z, R, *rest):
        # (the configuration's values and the fit parameters: columns of one array since pass call35)
        batch, q = rest[:10], rest[10]
        gd, chi2, ratio, jump = (float(q[c]) for c in (ku.UP_GATE_DISTANCE, ku.UP_GATE_CHI2, ku.UP_JUMP_RATIO,
                                                       ku.UP_JUMP))
        p = q[:_N_PARAMS].copy()
        got = ku.association_gates(G, Gi, rows, CI, Xs, Ps, Z, R, *rest)
        # (the flags from the counter table, pass cnt36: as _associate's loop over the tracks made them before)
        missed = np.array([CI[r, ku.C_MISSES] > 0 for r in rows.tolist()], dtype=np.bool_)
        firm = np.array([CI[r, ku.C_STATE] != ku.ST_TENTATIVE for r in rows.tolist()], dtype=np.bool_)
        tsize, tmax, rect, theta, known = association_rows(G, Gi, rows, missed)
        d2, _, ok = gate_costs(Xs, Ps, 0.5 * tmax, rect, theta, tsize, Z, R, gd, chi2, *batch, p)
        ok, ext = size_jump_gate(ok, batch[2], tmax, known, ratio, jump)
        assert len(got) == 6
        for a, b in zip(got, (tsize, d2, ok, ext, firm, missed)):
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
        seen["gates"] += 1
        return got

    def kalman(Xs, Ps, sel, H, zm, Rm, bound, hits, after, lim, lim2, X, P, trows):
        bad = Rm.copy()
        bad[0] = np.nan  # (a failed update: ok False, its row not written)
        cases = [(bound, lim, Rm), (True, lim / 30.0, Rm), (False, lim, Rm), (True, lim / 30.0, bad)]
        for bd, li, R in cases:
            X1, P1, X2, P2 = X.copy(), P.copy(), X.copy(), P.copy()
            ok1, nb1 = ku.kalman_pairs(Xs, Ps, sel, H, zm, R, bd, hits, after, li, (0.999 * li) ** 2, X1, P1, trows)
            ok2, nb2 = _kalman_pairs_python(Xs, Ps, sel, H, zm, R, bd, hits, after, li, X2, P2, trows)
            assert ok1.tobytes() == ok2.tobytes() and nb1 == nb2
            assert X1.tobytes() == X2.tobytes() and P1.tobytes() == P2.tobytes()
            seen["bounded"] += nb1
            seen["not_ok"] += int((~ok1).sum())
        seen["kalman"] += 1
        return ku.kalman_pairs(Xs, Ps, sel, H, zm, Rm, bound, hits, after, lim, lim2, X, P, trows)

    def merged(*a):
        # (since pass upd34 kalman_pairs runs inside update_pairs: its inputs are made here as update_pairs makes them)
        G, Gi, X, P, Xs, Ps, sel, trows, dis, _missed, *batch, sig, p, bound, hits, after, lim, lim2 = _old_args(a)[:27]
        swaps, sizes, has, radius = pair_priors(G, Gi, trows, dis, batch[0], batch[1])
        mr = measure_batch(dis, *batch, sizes, has, radius, np.full(sel.shape[0], sig), p)
        kalman(Xs, Ps, sel, mr[2], mr[3], mr[4], bound, hits, after, lim, lim2, X.copy(), P.copy(), trows)
        return ku.update_pairs(*a)

    def fused(*a):
        # (since pass trk75 association_gates runs inside associate_scan: checked on its first 19 arguments)
        gates(*a[:19])
        return associate_scan(*a)

    # (since pass trk108 both run inside associate_update: its Python runs instead, its calls through kernels_assign's
    # names)
    saved = trk.associate_update, ka.associate_scan, ka.update_pairs
    trk.associate_update, ka.associate_scan, ka.update_pairs = ka.associate_update.py_func, fused, merged
    try:
        for scene in ("crowd", "drive"):
            sim = simulate(scene, duration=4.0)
            tr = Tracker(DetectConfig())
            for scan, pose in zip(sim.scans, sim.ground_truth.poses_in("first")):
                tr.update(scan, Pose2D.from_array(pose))
    finally:
        trk.associate_update, ka.associate_scan, ka.update_pairs = saved
    assert seen["gates"] > 50 and seen["kalman"] > 50 and seen["bounded"] > 20 and seen["not_ok"] > 50


def test_report_rows_is_report_boxes_with_the_python_speed_test() -> None:
    """``report_rows`` against ``_report``'s former reads (main at 4f30595): ``report_boxes``, its undecided rows
    decided by ``math.hypot`` and a second call, and the gathers of the states, covariances and kinds — on 20 000
    random rows of every kind, with speeds drawn at, an ulp around and far from the limit and velocities where
    libm's hypot differs from Python's (the undecided path is taken: checked)."""
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect.kernels import GI_KIND, N_G, N_GI, report_boxes
    from dynslam2d.detect.kernels_update import report_rows
    from dynslam2d.detect.layout import K_CIRCLE, K_POINT, K_RECT

    rng = np.random.default_rng(11)
    n, slow = 20_000, 0.15
    X = rng.normal(size=(n + 5, 4)) * 3.0
    ang = rng.uniform(-math.pi, math.pi, n + 5)
    sp = np.where(rng.random(n + 5) < 0.5, slow, rng.uniform(0.0, 0.4, n + 5))
    sp = sp * (1.0 + rng.choice([-2.2e-16, 0.0, 2.2e-16, 1e-13, -1e-13], n + 5))
    X[:, 2] = sp * np.cos(ang)
    X[:, 3] = sp * np.sin(ang)
    P = rng.normal(size=(n + 5, 4, 4))
    G = rng.uniform(-3.0, 3.0, (n + 5, N_G))
    Gi = np.zeros((n + 5, N_GI), dtype=np.int8)
    Gi[:, GI_KIND] = rng.choice([K_RECT, K_CIRCLE, K_POINT], n + 5)
    rows = rng.permutation(n + 5)[:n].astype(np.int64)
    fast = np.full(n, -1, dtype=np.int8)
    boxes, undecided = report_boxes(G, Gi, X, rows, slow, fast)
    assert np.count_nonzero(undecided) > 100
    for i in undecided.nonzero()[0].tolist():
        vx, vy = X[rows[i], 2:].tolist()
        fast[i] = math.hypot(vx, vy) > slow
    boxes, _ = report_boxes(G, Gi, X, rows, slow, fast)
    # (the counters: random rows of a counter table, pass cnt36)
    CI = rng.integers(0, 1000, (n + 5, ku.N_C)).astype(np.int64)
    got = report_rows(G, Gi, X, P, CI, rows, slow)
    ints = np.stack([Gi[:, GI_KIND].take(rows).astype(np.int64)] + [CI[:, c].take(rows) for c in (
        ku.C_STATE, ku.C_HITS, ku.C_MISSES, ku.C_BS, ku.C_BN)])
    want = (boxes, X.take(rows, axis=0), P.take(rows, axis=0), ints)
    for a, b in zip(got, want):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_fragment_hosts_rows_is_fragment_hosts_after_the_gathers() -> None:
    """``fragment_hosts_rows`` against ``_hosts_of_fragments``' former call (main at 4f30595): the five columns of
    the candidate rows gathered with ``take``, then ``fragment_hosts`` — on 300 random scenes of boxes and point
    clusters, some inside a box, some across two, some outside every one (hosts found and not found: checked)."""
    from dynslam2d.detect.kernels import G_SIZE0, G_SIZE1, G_THETA, N_G, fragment_hosts
    from dynslam2d.detect.kernels_update import fragment_hosts_rows

    rng = np.random.default_rng(5)
    found = missed = 0
    for _ in range(300):
        nrow, m = int(rng.integers(1, 40)), int(rng.integers(1, 12))
        X = rng.uniform(-5.0, 5.0, (nrow, 4))
        G = rng.uniform(-math.pi, math.pi, (nrow, N_G))
        G[:, [G_SIZE0, G_SIZE1]] = rng.uniform(0.1, 3.0, (nrow, 2))
        npts = rng.integers(1, 15, m)
        start = np.concatenate(([0], np.cumsum(npts)[:-1])).astype(np.int64)
        centres = X[rng.integers(0, nrow, m), :2] + rng.normal(scale=rng.choice([0.1, 1.0, 4.0]), size=(m, 2))
        pts = np.repeat(centres, npts, axis=0) + rng.normal(scale=0.2, size=(int(npts.sum()), 2))
        px, py = pts[:, 0].copy(), pts[:, 1].copy()
        det = rng.permutation(m)[: int(rng.integers(1, m + 1))].astype(np.int64)
        rows = rng.permutation(nrow)[: int(rng.integers(1, nrow + 1))].astype(np.int64)
        margin = float(rng.choice([0.05, 0.3, 1.0]))
        got = fragment_hosts_rows(px, py, start, npts, det, X, G, rows, margin)
        want = fragment_hosts(px, py, start, npts, det, X[:, 0].take(rows), X[:, 1].take(rows),
                              G[:, G_THETA].take(rows), G[:, G_SIZE0].take(rows), G[:, G_SIZE1].take(rows), margin)
        assert got.dtype == want.dtype and got.tolist() == want.tolist()
        found += int((got >= 0).sum())
        missed += int((got < 0).sum())
    assert found > 100 and missed > 100


def _ride_python(R, W, row, beams, body_near, ride_updates, ride_r, ride_time) -> tuple:
    """``Tracker._rides_with_laser``'s tests and floats before ``ride_window`` (main at 1c7c2d9): the window as a view,
    the body beams by fancy indexing, the stamps as a list, the last n entries' NumPy copies, ``np.hypot``, ``mean`` and
    ``max``. Returns (outcome, spread, moved) as ``ride_window`` does."""
    from dynslam2d.detect import kernels_update as ku

    ride = R[row, :W.item(row, 1)]
    if ride.shape[0] < ride_updates:
        return ku.RIDE_FEW, 0.0, 0.0
    lx_last, ly_last = ride[-1, :2].tolist()
    if lx_last * lx_last + ly_last * ly_last > ride_r * ride_r:
        return ku.RIDE_FAR, 0.0, 0.0
    nb = beams.shape[0]
    if body_near is not None and (nb == 0 or np.count_nonzero(body_near[beams]) / nb < 0.5):
        return ku.RIDE_OFF_BODY, 0.0, 0.0
    stamps = ride[:, 4].tolist()
    t_end = stamps[-1]
    n = sum(1 for e in stamps if t_end - e <= ride_time)
    if n < ride_updates or t_end - stamps[-n] < 0.5 * ride_time:
        return ku.RIDE_SHORT, 0.0, 0.0
    lx = np.array(ride[-n:, :2])
    if float(np.hypot(lx[:, 0], lx[:, 1]).max()) > ride_r:
        return ku.RIDE_OUT, 0.0, 0.0
    spread = float(np.hypot(*(lx - lx.mean(axis=0)).T).max())
    mx = np.array(ride[-n:, 2:4])
    return ku.RIDE_JUDGE, spread, float(np.hypot(*(mx[-1] - mx[0])))


def test_ride_window_is_the_former_numpy_riding_test() -> None:
    """``ride_window`` against the former Python / NumPy form of ``_rides_with_laser``'s tests, on random riding
    windows (rows of a shared array in a random order, 0–40 entries, stamps at 10–40 Hz with gaps so that n within
    ``ride_time`` varies, laser-frame centres near and beyond ``ride_max_range``, a NaN now and then), with and
    without the body beams: the same outcome on every window and the spread and motion bit for bit; every outcome
    reached."""
    from dynslam2d.detect import kernels_update as ku

    rng = np.random.default_rng(11)
    rows, L = 64, 48
    seen = set()
    nbeams = 720
    for rep in range(4000):
        R = np.zeros((rows, L, 5))
        W = np.zeros((rows, 3), dtype=np.int64)
        row = int(rng.integers(rows))
        m = int(rng.integers(0, 41))
        W[row, 1] = m
        dt = rng.uniform(0.025, 0.1, size=m) * rng.choice([1.0, 1.0, 1.0, 6.0], size=m)
        R[row, :m, 4] = 100.0 + np.cumsum(dt)
        centre = rng.normal(size=2) * rng.choice([0.2, 0.5, 0.8])
        R[row, :m, :2] = centre + rng.normal(size=(m, 2)) * rng.choice([1e-3, 0.02, 0.3])
        R[row, :m, 2:4] = rng.normal(size=2) * 5 + np.cumsum(rng.normal(size=(m, 2)) * 0.05, axis=0)
        if m and rep % 37 == 0:
            R[row, int(rng.integers(m)), int(rng.integers(4))] = np.nan
        beams = np.sort(rng.choice(nbeams, size=int(rng.integers(0, 30)), replace=False)).astype(np.int64)
        body = None
        if rep % 2:
            body = np.zeros(nbeams, dtype=bool)
            body[rng.choice(nbeams, size=int(rng.integers(0, nbeams)), replace=False)] = True
        args = (int(rng.choice([2, 3, 5])), float(rng.choice([0.6, 1.0])), float(rng.choice([0.3, 0.5, 1.0])))
        want = _ride_python(R, W, row, beams, body, *args)
        got = ku.ride_window(R, W, row, beams, np.zeros(0, dtype=np.bool_) if body is None else body,
                             body is not None, *args)
        assert got[0] == want[0], (rep, got, want)
        assert _bits([got[1], got[2]]) == _bits([want[1], want[2]]), (rep, got, want)
        seen.add(got[0])
    assert seen == {ku.RIDE_FEW, ku.RIDE_FAR, ku.RIDE_OFF_BODY, ku.RIDE_SHORT, ku.RIDE_OUT, ku.RIDE_JUDGE}


def _old_args(a: tuple) -> list:
    """``update_pairs``' arguments (this form: the pairs' state rows gathered in the kernel, the configuration's values
    in one array ``q``, kernels_update.update_params) in the order of its form before pass call35 (main at 8df8347):
    ``trows`` in place of ``rows``, then the size σ, the fit parameters, the bound's arguments with
    ``accel_bound_after``, the shape update's four values, …, the riding window's three and the person's radii as
    scalars, read from ``q``'s columns; the pairs' hits gathered from the counter table (``CI``, pass cnt36; its
    counter writes are checked apart, :func:`_counters_python`). The same array objects (the arrays the call writes
    stay the caller's)."""
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect.kernels import _N_PARAMS

    G, Gi, X, P, Xs, Ps, sel, rows, dis, missed = a[:10]
    batch = list(a[10:20])
    q, bound, CI, CL, lim, lim2 = a[20:26]
    hits = CI[rows[sel], ku.C_HITS].copy()  # (before the call's own counter writes)
    mev, use_map, px, py, c, s, t = list(a[26:34]), a[34], a[35], a[36], a[37], a[38], a[39]
    f = q.tolist()
    return [G, Gi, X, P, Xs, Ps, sel, rows[sel], dis, missed, *batch, f[ku.UP_SIZE_SIGMA], q[:_N_PARAMS].copy(),
            bound, hits, int(f[ku.UP_ACCEL_AFTER]) if bound else 0, lim, lim2, f[ku.UP_DEFAULT_DEPTH],
            f[ku.UP_DEFAULT_DEPTH_RATIO], f[ku.UP_HEADING_GAIN], f[ku.UP_SIZE_GAIN], *mev, use_map, px, py, c, s, t,
            f[ku.UP_RIDE_TIME], int(f[ku.UP_RIDE_N]), f[ku.UP_RIDE_R2], f[ku.UP_PERSON_MIN_R], f[ku.UP_PERSON_MAX_R]]


def test_update_params_are_the_former_scalars() -> None:
    """``update_params``' array: ``fit_params``' columns first (``measure_batch`` and ``gate_costs`` read them), then
    the values ``Tracker._update_pairs`` and ``Tracker._associate`` passed as scalars before pass call35, as the
    same floats, on the default configuration and on one with every value changed (integers exact)."""
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect.config import DetectConfig
    from dynslam2d.detect.kernels import _N_PARAMS, fit_params

    for changed in (False, True):
        cfg = DetectConfig()
        fc, tc = cfg.fit, cfg.tracker
        if changed:
            fc.default_depth, fc.default_depth_ratio = 0.37, 0.61
            fc.person_min_radius, fc.person_max_radius = 0.031, 0.29
            tc.heading_gain, tc.size_gain, tc.ride_time, tc.ride_max_range = 0.13, 0.21, 1.7, 2.3
            tc.accel_bound_after, tc.ride_updates, tc.confirm_window, tc.confirm_hits = 7, 9, 6, 4
            tc.max_coast_time, tc.max_object_speed, tc.max_position_sigma = 1.7, 13.5, 2.25
            tc.gate_distance, tc.gate_chi2, tc.max_size_jump_ratio, tc.max_size_jump = 1.3, 11.5, 1.9, 0.45
            tc.map_structure_exit, tc.sustain_updates = 0.63, 5
            tc.structure_retire_updates, tc.structure_retire_fraction = 3, 0.55
            tc.map_structure_stop, tc.merge_size_jump, tc.map_structure_max = 0.71, 0.33, 0.27
        fp = fit_params(fc)
        q = ku.update_params(fp, fc, tc)
        assert q.dtype == np.float64 and q.shape == (ku._UP_N,) and q[:_N_PARAMS].tobytes() == fp.tobytes()
        want = {ku.UP_SIZE_SIGMA: 0.05, ku.UP_DEFAULT_DEPTH: float(fc.default_depth),
                ku.UP_DEFAULT_DEPTH_RATIO: float(fc.default_depth_ratio), ku.UP_HEADING_GAIN: float(tc.heading_gain),
                ku.UP_SIZE_GAIN: float(tc.size_gain), ku.UP_RIDE_TIME: float(tc.ride_time),
                ku.UP_RIDE_R2: tc.ride_max_range * tc.ride_max_range,
                ku.UP_PERSON_MIN_R: float(fc.person_min_radius), ku.UP_PERSON_MAX_R: float(fc.person_max_radius),
                ku.UP_ACCEL_AFTER: tc.accel_bound_after, ku.UP_RIDE_N: tc.ride_updates,
                ku.UP_GATE_DISTANCE: float(tc.gate_distance), ku.UP_GATE_CHI2: float(tc.gate_chi2),
                ku.UP_JUMP_RATIO: float(tc.max_size_jump_ratio), ku.UP_JUMP: float(tc.max_size_jump),
                ku.UP_WINDOW: tc.confirm_window, ku.UP_NEED: tc.confirm_hits,
                ku.UP_MAX_COAST: float(tc.max_coast_time), ku.UP_MAX_SPEED: float(tc.max_object_speed),
                ku.UP_MAX_POS_SIG: float(tc.max_position_sigma), ku.UP_S_EXIT: float(tc.map_structure_exit),
                ku.UP_SUSTAIN: tc.sustain_updates, ku.UP_RETIRE_N: tc.structure_retire_updates or 0,
                ku.UP_RETIRE_S: float(tc.structure_retire_fraction),
                # (the association's, passed as floats before pass trk129: the merge veto's three, the cost outside
                # the gates)
                ku.UP_S_STOP: float(tc.map_structure_stop), ku.UP_MERGE_JUMP: float(tc.merge_size_jump),
                ku.UP_S_MAX: float(tc.map_structure_max), ku.UP_BIG: 1e12}
        assert sorted(want) == list(range(_N_PARAMS, ku._UP_N))
        for col, v in want.items():
            assert q[col] == v and (not isinstance(v, int) or int(q[col]) == v), (col, q[col], v)


def _update_pairs_separate(G, Gi, X, P, Xs, Ps, sel, trows, dis, missed, kind, theta, lohi, rel, centroid, circle,
                           bpx, bpy, start, npts, size_sigma, p, bound, hits, after, lim, lim2, dd, ddr, hg, sg, mfr,
                           kept, first, second, mnpts, MEV, RIDE, WN, use_map, *rest) -> tuple:
    """``Tracker._update_pairs`` before ``update_pairs`` (main at 10af139): ``pair_priors``, ``measure_batch``,
    ``kalman_pairs`` and ``shape_update`` called one by one from Python, then ``_restart_windows`` of each
    re-acquired track whose update applied (in ``_update_tracks``' loop over the pairs), and what ``_update_tracks``
    read per pair: ``ok``, the batch's ``start`` and ``npts`` as lists and the person's circle test on Python
    floats."""
    from types import SimpleNamespace

    from dynslam2d.detect import kernels as K
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect.layout import K_CIRCLE
    from dynslam2d.detect.tracktable import TrackRows

    n = sel.shape[0]
    swaps, sizes, has, radius = K.pair_priors(G, Gi, trows, dis, kind, theta)
    mr = K.measure_batch(dis, kind, theta, lohi, rel, centroid, circle, bpx, bpy, start, npts, sizes, has, radius,
                         np.full(n, size_sigma), p)
    ok, nb = ku.kalman_pairs(Xs, Ps, sel, mr[2], mr[3], mr[4], bound, hits, after, lim, lim2, X, P, trows)
    *rest, pmin_r, pmax_r = rest
    top = K.shape_update(G, Gi, X, trows, dis, ok, kind, theta, lohi, rel, circle, mr[5], mr[6], swaps, dd, ddr, hg,
                         sg, mfr, kept, first, second, mnpts, MEV, RIDE, WN, use_map, *rest)
    rows = SimpleNamespace(_WN=WN, _RIDE=RIDE, _MEV=MEV)
    for r, applied in enumerate(ok.tolist()):
        if applied and missed[sel[r]]:
            TrackRows._restart_windows(rows, int(trows[r]), use_map)
    radii, kinds, starts, counts = circle[:, 2].tolist(), kind.tolist(), start.tolist(), npts.tolist()
    # (the applied flag 2 for a re-acquired track's update: ``_update_tracks``' former ``missed`` list, pass trk71)
    info = [[(2 if missed[i] else 1) if a else 0, starts[j], counts[j],
             int(kinds[j] == K_CIRCLE and pmin_r <= radii[j] <= pmax_r)]
            for a, j, i in zip(ok.tolist(), dis.tolist(), sel.tolist())]
    return nb, top, np.array(info, dtype=np.int64).reshape(n, 4), ok.tolist().count(False)


def _counters_python(CI: np.ndarray, CL: np.ndarray, trows, applied, t: float, window: int, info=None) -> None:
    """The counter lines of ``Tracker._update_tracks``' loop over the pairs before pass cnt36 (``k.hits += 1``,
    ``k.last_hit = t``, the M-of-N counts within the first ``window``, ``k.misses = 0`` of a re-acquired track) on the
    rows ``trows`` of the tracks whose update ``applied``, and the updated flag the management step reads; with the
    pairs' ``info`` rows, the beams' segment its slice ``beams[a0:a0 + npt]`` takes (pass rep149)."""
    from dynslam2d.detect import kernels_update as ku

    for r, (k, a) in enumerate(zip(trows, applied)):
        if a and info is not None:
            CI[k, ku.C_BS] = info[r, 1]
            CI[k, ku.C_BN] = info[r, 2]
        if a:
            CI[k, ku.C_HITS] += 1
            CL[k] = t
            if CI[k, ku.C_HIST_N] < window:
                CI[k, ku.C_HIST_N] += 1
                CI[k, ku.C_HIST_HITS] += 1
            CI[k, ku.C_MISSES] = 0
            CI[k, ku.C_UPD] = 1


def _update_pairs_reference(c: list) -> tuple:
    """:func:`_update_pairs_separate` of ``update_pairs``' arguments ``c``, then :func:`_counters_python`."""
    from dynslam2d.detect import kernels_update as ku

    got = _update_pairs_separate(*_old_args(c))
    _counters_python(c[22], c[23], c[7][c[6]].tolist(), got[2][:, 0].tolist(), c[39], int(c[20][ku.UP_WINDOW]),
                     got[2])
    return got


def test_update_pairs_is_the_four_calls_it_replaces_in_pipeline_runs() -> None:
    """``update_pairs`` against ``pair_priors`` → ``measure_batch`` → ``kalman_pairs`` → ``shape_update`` and the
    re-acquired tracks' ``_restart_windows`` in Python, on every call of two pipeline runs (sim:drive with its map
    evidence, sim:crowd with the tracker's map evidence off): the results (the per-pair rows ``_update_tracks``
    reads, with the person's circle test) and the bytes of every array the call writes (states, covariances, shape
    rows, windows, the counter table and last hits against ``_update_tracks``' former counter lines, pass cnt36),
    each call also with a limit 30 × tighter (most established rows bounded), with every track taken as re-acquired
    and with a failed update, on copies."""
    from dynslam2d.config import Config
    from dynslam2d.detect import kernels_assign as ka
    from dynslam2d.detect import kernels_update as ku
    from dynslam2d.detect import tracker as trk
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    seen = {"calls": 0, "bounded": 0, "restarted": 0, "use_map": 0, "rejected": 0}

    def merged(*a):
        a = list(a)
        cases = [a]
        tight = list(a)
        tight[24], tight[25] = a[24] / 30.0, (0.999 * a[24] / 30.0) ** 2
        tight[21] = True
        every = list(a)
        every[9] = np.ones_like(a[9])
        bad = list(a)
        bad[5] = a[5].copy()
        bad[5][a[6][0]] = np.nan  # (the first pair's prior covariance: its update fails, ok False, its row unwritten)
        cases += [tight, every, bad]
        for case in cases:
            outs = []
            for f in (ku.update_pairs, lambda *c: _update_pairs_reference(list(c))):
                c = list(case)
                for i in (0, 1, 2, 3, 22, 23, 31, 32, 33):  # (the arrays the call writes: copies)
                    c[i] = c[i].copy()
                got = f(*c)
                written = [c[i].tobytes() for i in (0, 1, 2, 3, 22, 23, 31, 32, 33)]
                outs.append((got[0], got[1], got[2].tobytes(), got[3], written))
            assert outs[0] == outs[1]
            seen["bounded"] += outs[0][0]
            seen["rejected"] += outs[0][3]
        seen["restarted"] += int((a[9][a[6]]).sum())
        seen["use_map"] += bool(a[34])
        seen["calls"] += 1
        return ku.update_pairs(*a)

    # (since pass trk108 update_pairs runs inside associate_update: its Python runs instead, its calls through
    # kernels_assign's names)
    saved = trk.associate_update, ka.update_pairs
    trk.associate_update, ka.update_pairs = ka.associate_update.py_func, merged
    try:
        for name, use_map in (("sim:drive", True), ("sim:crowd", False)):
            cfg = Config()
            cfg.detect.tracker.map_evidence = use_map
            pipe = Pipeline(cfg)
            for scan in open_source(name, seed=11, duration=6.0):
                pipe.process(scan)
    finally:
        trk.associate_update, ka.update_pairs = saved
    assert seen["calls"] > 100 and seen["bounded"] > 20 and seen["restarted"] > 5
    assert 20 < seen["use_map"] < seen["calls"] and seen["rejected"] > 0
