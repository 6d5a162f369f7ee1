"""Kernels of the tracker's update step (``detect/trackupdate.py``): Python's ``math.hypot`` to the last bit, and the
physical acceleration bound of the updated states (``Tracker._bound_acceleration``).

``py_hypot`` is CPython's ``math.hypot`` for two coordinates (``Modules/mathmodule.c``, ``math_hypot`` →
``vector_norm``: lossless power-of-two scaling, exact squares (``dl_mul``: Dekker 1971, "A floating-point technique
for extending the available precision", mul12 on Veltkamp's splits — CPython 3.11's form, and 3.12's without a
reliable fma; 3.12 and later take the low part with an fma, the same (hi, lo) of these squares: checked in plain
Python against 3.11.7, 3.12.1 and 3.13.0's ``math.hypot``), the compensated sums (``dl_fast_sum``) and one
differential correction of the square root), operation for operation, so a kernel can decide and compute with
the same float the tracker's Python did (libm's ``hypot``, which numba's ``math.hypot`` calls, may differ from it
by an ulp). numba compiles without fast-math, so no product and sum is contracted into an FMA and every operation
is rounded alone, as in the C source. ``tests/test_detect_kernels_update.py`` compares it with the running
interpreter's ``math.hypot`` on millions of pairs and the edge values."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels import (
    _N_PARAMS,
    G_LB0,
    G_LB1,
    G_RADIUS,
    G_SIZE0,
    G_SIZE1,
    G_THETA,
    GI_HEADING,
    GI_KIND,
    GI_KNOWN0,
    GI_KNOWN1,
    N_G,
    accel_candidates,
    association_rows,
    box_row,
    fragment_hosts,
    gate_costs,
    kalman_update_batch,
    measure_batch,
    pair_priors,
    shape_update,
    size_jump_gate,
)
from dynslam2d.detect.layout import K_CIRCLE, K_RECT, SIZE_MEASURED
from dynslam2d.jitbox import njit

_DBL_MIN = 2.2250738585072014e-308  # the smallest normal double (C's DBL_MIN)
_SPLIT = 134217729.0  # 2^27 + 1: Veltkamp's splitter for doubles (dl_split)


@njit(cache=True, inline="always")
def _dl_mul(x: float, y: float) -> tuple[float, float]:
    """x·y as an unevaluated sum hi + lo, exactly (CPython's ``dl_mul``: Dekker's mul12 on Veltkamp's splits)."""
    t = x * _SPLIT
    xh = t - (t - x)
    xl = x - xh
    t = y * _SPLIT
    yh = t - (t - y)
    yl = y - yh
    p = xh * yh
    q = xh * yl + xl * yh
    z = p + q
    zz = p - z + q + xl * yl
    return z, zz


@njit(cache=True, inline="always")
def py_hypot(a: float, b: float) -> float:
    """``math.hypot(a, b)`` of CPython, bit for bit (module docstring): an infinity wins over a NaN, a
    NaN gives NaN, zeros give 0.0; subnormal inputs are scaled by DBL_MIN first, as there."""
    x0 = abs(a)
    x1 = abs(b)
    found_nan = False
    mx = 0.0
    if math.isnan(x0):
        found_nan = True
    elif x0 > mx:
        mx = x0
    if math.isnan(x1):
        found_nan = True
    elif x1 > mx:
        mx = x1
    if math.isinf(mx):
        return mx
    if found_nan:
        return math.nan
    if mx == 0.0:
        return mx
    mult = 1.0
    _, max_e = math.frexp(mx)
    if max_e < -1023:  # (ldexp(1.0, -max_e) would overflow: subnormals made normal, the result scaled back)
        x0 /= _DBL_MIN
        x1 /= _DBL_MIN
        mx /= _DBL_MIN
        mult = _DBL_MIN
        _, max_e = math.frexp(mx)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for i in range(2):
        x = (x0 if i == 0 else x1) * scale  # lossless scaling
        ph, pl = _dl_mul(x, x)  # lossless squaring
        hi = csum + ph  # lossless addition (dl_fast_sum)
        lo = ph - (hi - csum)
        csum = hi
        frac1 += pl  # lossy additions
        frac2 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    ph, pl = _dl_mul(-h, h)
    hi = csum + ph
    lo = ph - (hi - csum)
    csum = hi
    frac1 += pl
    frac2 += lo
    x = csum - 1.0 + (frac1 + frac2)
    h += x / (2.0 * h)  # differential correction
    out = h / scale
    return out if mult == 1.0 else mult * out


@njit(cache=True)
def hypot_rows(vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    """(n,) ``math.hypot(vx[i], vy[i])`` bit for bit (:func:`py_hypot`): for the tests and the bound below."""
    n = vx.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = py_hypot(vx[i], vy[i])
    return out


@njit(cache=True, inline="always")
def accel_bound(X_prior: np.ndarray, X_new: np.ndarray, rows: np.ndarray, lim: float) -> int:
    """The physical acceleration bound, in place on ``X_new`` ((r, 4) states [x, y, vx, vy], m, m/s; row r's prior
    ``X_prior[r]``) for the rows ``rows`` (the candidates of ``accel_candidates`` whose track is established, in
    increasing order): a row whose velocity change (dvx, dvy) has norm d > ``lim`` (m/s; d Python's
    ``math.hypot``, :func:`py_hypot`) gets the velocity pvx + dvx·lim / d, pvy + dvy·lim / d. Returns how many rows
    were bounded. ``Tracker._bound_acceleration``'s former Python arithmetic, operation for operation."""
    nb = 0
    for i in range(rows.shape[0]):
        r = rows[i]
        pvx = X_prior[r, 2]
        pvy = X_prior[r, 3]
        dvx = X_new[r, 2] - pvx
        dvy = X_new[r, 3] - pvy
        d = py_hypot(dvx, dvy)
        if d > lim:
            X_new[r, 2] = pvx + dvx * lim / d
            X_new[r, 3] = pvy + dvy * lim / d
            nb += 1
    return nb


@njit(cache=True)
def manage_counters(P: np.ndarray, X: np.ndarray, CI: np.ndarray, CL: np.ndarray, WN: np.ndarray, rows: np.ndarray,
                    q: np.ndarray, t: float) -> tuple:
    """:func:`manage_scan` without the map-evidence tests: the fourth output is the riding pre-test alone (``WN[rows,
    2]``), ``q`` needs no column after ``UP_MAX_POS_SIG`` (tests and studies; the tracker calls :func:`manage_scan`)."""
    return _manage_rows(P, X, CI, CL, WN, np.empty((0, 1, 3)), rows, q, t, False)


@njit(cache=True)
def manage_scan(P: np.ndarray, X: np.ndarray, CI: np.ndarray, CL: np.ndarray, WN: np.ndarray, MEV: np.ndarray,
                rows: np.ndarray, q: np.ndarray, t: float) -> tuple:
    """``Tracker._manage``'s one kernel call a scan: :func:`manage_counters`' counter tests, σ and speeds, its fourth
    output ``aux`` (n,) int64 the riding pre-test (bits 0–1, ``AUX_NEAR``) plus three per-track values of the test
    of M that ``_manage``'s loop read in Python (its Python now tests a bit), from the tracks' map-evidence windows
    ``MEV`` (rows, w, 3; column 0 the fraction of the points on long-occupied map cells) with counts ``WN[:, 0]``
    and the speed (docs/speed.md, pass upd91):

    * ``AUX_EXIT``: the structure exit of a track in M (``_dynamic``'s first test): at least ``sustain_updates``
      (``q[UP_SUSTAIN]``) entries, and their column-0 mean ≥ ``map_structure_exit`` (``q[UP_S_EXIT]``) — the sum
      from 0.0 left to right divided by the count, Python's ``sum(list) / n`` bit for bit (CPython 3.11's float
      ``sum`` adds in order from its int start 0; 3.12's compensated sum would differ: the tests compare it with
      the running interpreter's).
    * ``AUX_RETIRE``: clutter retirement's window test: ``structure_retire_updates`` (``q[UP_RETIRE_N]`` > 0)
      entries or more, and the smallest of the last that many ≥ ``structure_retire_fraction`` (``q[UP_RETIRE_S]``;
      Python's ``min``: the first entry kept unless a later one compares smaller, so a NaN first stays).
    * bits ``AUX_SLOW_SHIFT`` on: 1 + the index of the slow reason's text (``trackmanage._slow_reason``: the
      speed in hundredths, rounded as ``format`` rounds it), 0 where it must be formatted (within 10⁻⁷ of a tie)
      or the speed is above ``_SLOW_TEXTS_MAX`` (10 m/s) or not a number."""
    return _manage_rows(P, X, CI, CL, WN, MEV, rows, q, t, True)


# manage_scan's fourth output per track: the riding pre-test (0 / 1 / 2, TrackRows' WN[:, 2]) in its low two bits,
# the structure exit and the retirement window flags, and 1 + the slow reason's text index from bit AUX_SLOW_SHIFT on
AUX_NEAR = 3
AUX_EXIT = 4
AUX_RETIRE = 8
AUX_SLOW_SHIFT = 4


@njit(cache=True, inline="always")
def _manage_rows(P: np.ndarray, X: np.ndarray, CI: np.ndarray, CL: np.ndarray, WN: np.ndarray, MEV: np.ndarray,
                 rows: np.ndarray, q: np.ndarray, t: float, ev: bool) -> tuple:
    """``Tracker._manage``'s counter tests of the live tracks (state rows ``rows``) as one pass over their rows of the
    counter table ``CI`` (columns ``C_*``) and last-hit stamps ``CL`` (s), with ``kernels.manage_rows``' covariance
    test (max_position_sigma, m) and σ of the speed along the velocity, operation for operation, and the speed as
    Python's ``math.hypot`` bit for bit (:func:`py_hypot`, as the reasons print it): returns (outcome (n,) int8
    (``MC_*``), σ (n,), speed (n,), m/s, and the riding pre-test of the tracks' windows, ``WN[rows, 2]`` (n,) int64,
    ``TrackRows``' window counts, pass trk41). The tests in the order of the former per-track loop (docs/speed.md passes
    mgr34, cnt36); the configuration's values from ``q``
    (:func:`update_params`' array: confirm_window, confirm_hits = ``need``, max_coast_time, max_object_speed,
    max_position_sigma). An updated track (``C_UPD`` set by :func:`update_pairs`; cleared here): coasting → confirmed;
    tentative → confirmed with ``need`` hits, deleted when M of N (``need`` of the first ``window``) can no longer be
    reached; then deleted when its covariance fails or its speed exceeds ``max_speed`` (m/s). A track without detection:
    misses + 1, the M-of-N count + 1 (within the first ``window``), confirmed → coasting, the tentative test as above
    (nothing else for a tentative one then), a confirmed or coasting one flagged ``MC_COAST`` when it has coasted more
    than ``max_coast`` (s) since its last hit at stamp ``t``, then the covariance and speed deletions (an updated
    track's with ``MC_UPDATED``). The new states and counts are written into ``CI``."""
    n = rows.shape[0]
    out = np.empty(n, dtype=np.int8)
    window = int(q[UP_WINDOW])
    need = int(q[UP_NEED])
    max_coast = q[UP_MAX_COAST]
    max_speed = q[UP_MAX_SPEED]
    max_sig = q[UP_MAX_POS_SIG]
    sig = np.empty(n)
    speed = np.empty(n)
    near = np.empty(n, dtype=np.int64)
    if ev:
        s_exit = q[UP_S_EXIT]
        nsus = int(q[UP_SUSTAIN])
        retire_n = int(q[UP_RETIRE_N])
        retire_s = q[UP_RETIRE_S]
    else:
        s_exit, nsus, retire_n, retire_s = 0.0, 0, 0, 0.0
    for i in range(n):
        k = rows[i]
        a = WN[k, 2]
        if ev:
            nm = WN[k, 0]
            if nm != 0 and nm >= nsus:
                acc = 0.0
                for j in range(nm):
                    acc += MEV[k, j, 0]
                if acc / nm >= s_exit:
                    a += AUX_EXIT
            if retire_n > 0 and nm >= retire_n:
                lo = MEV[k, nm - retire_n, 0]
                for j in range(nm - retire_n + 1, nm):
                    v = MEV[k, j, 0]
                    if v < lo:
                        lo = v
                if lo >= retire_s:
                    a += AUX_RETIRE
        near[i] = a
        # (kernels.manage_rows' arithmetic for row k, operation for operation, here instead of called: no library of
        # its own to compile in a run)
        s = py_hypot(X[k, 2], X[k, 3])
        speed[i] = s
        if ev and s <= 10.0:  # (the slow reason's text index: trackmanage._slow_reason's arithmetic)
            sq = s * 100.0
            si = int(sq)
            sf = sq - si
            if sf < 0.4999999:
                near[i] += (si + 1) << AUX_SLOW_SHIFT
            elif sf > 0.5000001:
                near[i] += (si + 2) << AUX_SLOW_SHIFT
        sig[i] = 0.0
        fin = True
        for a in range(4):
            for b in range(4):
                if not np.isfinite(P[k, a, b]):
                    fin = False
        p00 = P[k, 0, 0]
        p11 = P[k, 1, 1]
        bad = not fin or math.sqrt(p11 if p11 > p00 else p00) > max_sig
        if not bad:
            p22 = P[k, 2, 2]
            p33 = P[k, 3, 3]
            if s > 1e-9:
                u0 = X[k, 2] / s
                u1 = X[k, 3] / s
                v = (u0 * p22 + u1 * P[k, 3, 2]) * u0 + (u0 * P[k, 2, 3] + u1 * p33) * u1
                sig[i] = math.sqrt(0.0 if 0.0 > v else v)
            else:
                sig[i] = math.sqrt(p33 if p33 > p22 else p22)
        st = CI[k, C_STATE]
        nh = CI[k, C_HIST_HITS]
        if CI[k, C_UPD] != 0:
            CI[k, C_UPD] = 0
            code = MC_UPD_FIRM
            if st == ST_COASTING:
                st = ST_CONFIRMED
            elif st == ST_TENTATIVE:
                hn = CI[k, C_HIST_N]
                if nh >= need:
                    st = ST_CONFIRMED
                elif nh + (window - hn) < need or CI[k, C_MISSES] > 0 and hn >= window:
                    out[i] = MC_UPDATED + MC_DEL_TENTATIVE
                    continue
                else:
                    code = MC_UPD_TENTATIVE
            CI[k, C_STATE] = st
        else:
            code = MC_KEPT
            CI[k, C_MISSES] += 1
            hn = CI[k, C_HIST_N]
            if hn < window:
                hn += 1
                CI[k, C_HIST_N] = hn
            if st == ST_CONFIRMED:
                CI[k, C_STATE] = ST_COASTING
            elif st == ST_TENTATIVE:
                if nh >= need:
                    CI[k, C_STATE] = ST_CONFIRMED
                elif nh + (window - hn) < need or CI[k, C_MISSES] > 0 and hn >= window:
                    out[i] = MC_DEL_TENTATIVE
                    continue
            if st != ST_TENTATIVE and t - CL[k] > max_coast:
                code += MC_COAST
        if bad or s > max_speed:
            d = MC_DEL_COVARIANCE if bad else MC_DEL_SPEED
            code = (code & MC_COAST) + d if code >= MC_KEPT else MC_UPDATED + d
        out[i] = code
    return out, sig, speed, near


@njit(cache=True)
def association_gates(G: np.ndarray, Gi: np.ndarray, rows: np.ndarray, CI: np.ndarray, Xs: np.ndarray,
                      Ps: np.ndarray, Z: np.ndarray, R: np.ndarray, kind: np.ndarray, theta: np.ndarray,
                      lohi: np.ndarray, rel: np.ndarray, centroid: np.ndarray, circle: np.ndarray, px: np.ndarray,
                      py: np.ndarray, start: np.ndarray, npts: np.ndarray, q: np.ndarray) -> tuple:
    """``Tracker._associate``'s three gate kernels in one call: ``kernels.association_rows`` (the tracks' sizes,
    longest sides, rectangle flags, axis angles and known-size flags from their shape rows ``rows``), then
    ``kernels.gate_costs`` with the reach 0.5 × the longest side (the gate distance, m, and χ² bound, the fit
    parameters: ``q``, :func:`update_params`' array), then ``kernels.size_jump_gate``'s size-jump test (its ratio and
    jump, m, from ``q``) — the same functions, so the same floats; the tracks' "missed their last scan" flags (misses
    > 0) and "established" flags (not tentative) read from their rows of the counter table ``CI`` (columns ``C_*``;
    pass cnt36). Returns (tsize (n, 2) m, d2 (n, m), ok (n, m) bool after the size-jump test, det_ext (m,) m, firm
    (n,) bool, missed (n,) bool). One dispatch instead of three: with the caches cold (the
    pipeline's SLAM stages run between two updates) each call of a small kernel costs a few µs on its own
    (docs/speed.md, passes trk24, call35)."""
    n = rows.shape[0]
    missed = np.empty(n, dtype=np.bool_)
    firm = np.empty(n, dtype=np.bool_)
    for i in range(n):
        missed[i] = CI[rows[i], C_MISSES] > 0
        firm[i] = CI[rows[i], C_STATE] != ST_TENTATIVE
    tsize, tmax, rect, theta_box, known = association_rows(G, Gi, rows, missed)
    reach = np.empty(n)
    for i in range(n):
        reach[i] = 0.5 * tmax[i]
    d2, _near, ok = gate_costs(Xs, Ps, reach, rect, theta_box, tsize, Z, R, q[UP_GATE_DISTANCE], q[UP_GATE_CHI2],
                               kind, theta, lohi, rel, centroid, circle, px, py, start, npts, q)
    ok, det_ext = size_jump_gate(ok, lohi, tmax, known, q[UP_JUMP_RATIO], q[UP_JUMP])
    return tsize, d2, ok, det_ext, firm, missed


@njit(cache=True, inline="always")  # (compiled inside update_pairs, its one caller in a run: pass upd34)
def kalman_pairs(Xs: np.ndarray, Ps: np.ndarray, sel: np.ndarray, H: np.ndarray, zm: np.ndarray, Rm: np.ndarray,
                 bound: bool, hits: np.ndarray, after: int, lim: float, lim2: float, X: np.ndarray, P: np.ndarray,
                 trows: np.ndarray) -> tuple:
    """``Tracker._associate_update``' Kalman step in one call: the priors ``Xs[sel]``, ``Ps[sel]`` (the predicted (n, 4)
    states and (n, 4, 4) covariances of the live tracks, rows ``sel`` of the pairs), ``kernels.kalman_update_batch``
    with the pairs' measurements (H, zm, Rm), then — where ``bound`` — the physical acceleration bound
    (``kernels.accel_candidates`` with ``lim2`` (m/s)², the candidates of pairs whose track has ``hits`` ≥ ``after``,
    :func:`accel_bound` with ``lim`` m/s), and the updated states and covariances written into the state rows
    ``trows`` of ``X`` / ``P`` where the update applied. The same functions in the same order as the former Python
    (two gathers, three kernel calls, the filter of the candidates, two scatters): the same floats. Returns (ok (n,)
    bool, the number of rows bounded). One dispatch instead of three (docs/speed.md, pass trk24)."""
    n = sel.shape[0]
    Xp = np.empty((n, 4))
    Pp = np.empty((n, 4, 4))
    for r in range(n):
        q = sel[r]
        for a in range(4):
            Xp[r, a] = Xs[q, a]
            for b in range(4):
                Pp[r, a, b] = Ps[q, a, b]
    Xn, Pn, ok = kalman_update_batch(Xp, Pp, H, zm, Rm)
    nb = 0
    if bound:
        near = accel_candidates(Xp, Xn, lim2)
        rows = np.empty(near.shape[0], dtype=np.int64)
        m = 0
        for i in range(near.shape[0]):
            if hits[near[i]] >= after:
                rows[m] = near[i]
                m += 1
        if m:
            nb = accel_bound(Xp, Xn, rows[:m], lim)
    for r in range(n):
        if ok[r]:
            q = trows[r]
            for a in range(4):
                X[q, a] = Xn[r, a]
                for b in range(4):
                    P[q, a, b] = Pn[r, a, b]
    return ok, nb


#: columns of :func:`update_params`' array (``Tracker._upd_p``): ``kernels.fit_params``' columns, then the tracker's
#: and fit configuration's values ``update_pairs`` and ``association_gates`` read, fixed for a tracker's life
UP_SIZE_SIGMA = _N_PARAMS  # the measurements' size σ, m
UP_DEFAULT_DEPTH = _N_PARAMS + 1  # FitConfig.default_depth, m
UP_DEFAULT_DEPTH_RATIO = _N_PARAMS + 2  # FitConfig.default_depth_ratio
UP_HEADING_GAIN = _N_PARAMS + 3  # TrackerConfig.heading_gain
UP_SIZE_GAIN = _N_PARAMS + 4  # TrackerConfig.size_gain
UP_RIDE_TIME = _N_PARAMS + 5  # TrackerConfig.ride_time, s
UP_RIDE_R2 = _N_PARAMS + 6  # TrackerConfig.ride_max_range², m²
UP_PERSON_MIN_R = _N_PARAMS + 7  # FitConfig.person_min_radius, m
UP_PERSON_MAX_R = _N_PARAMS + 8  # FitConfig.person_max_radius, m
UP_ACCEL_AFTER = _N_PARAMS + 9  # TrackerConfig.accel_bound_after (an integer, exact in a float64)
UP_RIDE_N = _N_PARAMS + 10  # TrackerConfig.ride_updates (an integer, exact in a float64)
UP_GATE_DISTANCE = _N_PARAMS + 11  # TrackerConfig.gate_distance, m (association_gates)
UP_GATE_CHI2 = _N_PARAMS + 12  # TrackerConfig.gate_chi2 (association_gates)
UP_JUMP_RATIO = _N_PARAMS + 13  # TrackerConfig.max_size_jump_ratio (association_gates)
UP_JUMP = _N_PARAMS + 14  # TrackerConfig.max_size_jump, m (association_gates)
UP_WINDOW = _N_PARAMS + 15  # TrackerConfig.confirm_window (an integer, exact in a float64; the M-of-N counts)
UP_NEED = _N_PARAMS + 16  # TrackerConfig.confirm_hits (an integer; manage_counters)
UP_MAX_COAST = _N_PARAMS + 17  # TrackerConfig.max_coast_time, s (manage_counters)
UP_MAX_SPEED = _N_PARAMS + 18  # TrackerConfig.max_object_speed, m/s (manage_counters)
UP_MAX_POS_SIG = _N_PARAMS + 19  # TrackerConfig.max_position_sigma, m (manage_counters)
UP_S_EXIT = _N_PARAMS + 20  # TrackerConfig.map_structure_exit (manage_scan)
UP_SUSTAIN = _N_PARAMS + 21  # TrackerConfig.sustain_updates (an integer; manage_scan)
UP_RETIRE_N = _N_PARAMS + 22  # TrackerConfig.structure_retire_updates (an integer, 0 for None; manage_scan)
UP_RETIRE_S = _N_PARAMS + 23  # TrackerConfig.structure_retire_fraction (manage_scan)
UP_S_STOP = _N_PARAMS + 24  # TrackerConfig.map_structure_stop (the association's merge veto, veto_merged)
UP_MERGE_JUMP = _N_PARAMS + 25  # TrackerConfig.merge_size_jump, m (veto_merged)
UP_S_MAX = _N_PARAMS + 26  # TrackerConfig.map_structure_max (veto_merged)
UP_BIG = _N_PARAMS + 27  # the assignment's cost outside the gates (_BIG; assign_groups)
_UP_N = _N_PARAMS + 28
_BIG = 1e12  # the association's cost of a pair outside the gates (assign_groups, as update_params' UP_BIG)

# the columns of the tracker's counter table (``Tracker._CI``, int64, one row per state row; docs/speed.md pass cnt36)
C_STATE = 0  # the track's state: ST_TENTATIVE, ST_CONFIRMED or ST_COASTING
C_HITS = 1  # its updates (hits) since birth
C_MISSES = 2  # consecutive scans without detection
C_HIST_N = 3  # updates (hits and misses) among its first confirm_window scans (the M-of-N rule's count)
C_HIST_HITS = 4  # hits among them
C_UPD = 5  # 1: updated in this scan (written by update_pairs, read and cleared by manage_counters)
# the track's beams in this scan as a segment of the scan's detection points (pass rep149): the first point (its index
# in the batch's points, the persons' after the others) and the count, written by update_pairs with the update; −1 in
# C_BN where the beams are not that one segment (a birth's, a revival's new row, a fragment's host: Tracker.update)
C_BS = 6
C_BN = 7
N_C = 8


@njit(cache=True, inline="always")
def row_tables(F: np.ndarray, Fi: np.ndarray, n: int) -> tuple:
    """The tracker's row tables for ``n`` rows as C-contiguous views of its two flat buffers (``TrackRows._F``,
    ``_Fi``; pass trk129): from the float64 ``F`` the states ``X`` (n, 4) (m, m/s, map frame), covariances ``P``
    (n, 4, 4), shape rows ``G`` (n, N_G), last hits' stamps ``CL`` (n,) (s) and map-evidence windows ``MEV``
    (n, nsus, 3), one after the other; from the int64 ``Fi`` the counters ``CI`` (n, N_C) and window counts ``WN``
    (n, 3). nsus (sustain_updates) follows from ``F``'s length. The same function makes the tracker's views
    (its ``py_func``, NumPy's slices and reshapes) and a kernel's (numba's): one layout, and one array argument
    for each buffer instead of seven (numba's dispatcher types and unboxes each array argument)."""
    a = 4 * n
    b = a + 16 * n
    c = b + N_G * n
    d = c + n
    nsus = (F.shape[0] - d) // (3 * n)
    e = N_C * n
    return (F[:a].reshape((n, 4)), F[a:b].reshape((n, 4, 4)), F[b:c].reshape((n, N_G)), F[c:d],
            F[d:].reshape((n, nsus, 3)), Fi[:e].reshape((n, N_C)), Fi[e:].reshape((n, 3)))


ST_TENTATIVE = 0
ST_CONFIRMED = 1
ST_COASTING = 2
# manage_counters' outcome per track: an updated track kept by the counter tests, tentative or not; a track without
# detection kept; deleted (tentative by M of N, covariance, speed); plus MC_COAST when a track without detection has
# coasted longer than max_coast_time (deleted unless its memory keeps it: decided in Python, then the outcome applies);
# plus MC_UPDATED for the deletions of an updated track
MC_UPD_TENTATIVE = 0
MC_UPD_FIRM = 1
MC_KEPT = 2
MC_DEL_TENTATIVE = 3
MC_DEL_COVARIANCE = 4
MC_DEL_SPEED = 5
MC_COAST = 8
MC_UPDATED = 16


def update_params(fit_p: np.ndarray, fc, tc, size_sigma: float = 0.05) -> np.ndarray:
    """The parameters :func:`update_pairs` and :func:`association_gates` read, packed in one float64 array, built
    once per tracker: ``fit_p`` (``kernels.fit_params``' array, which ``measure_batch`` and ``gate_costs`` read; its
    columns first), then (columns ``UP_*``) the values of ``fc`` (the tracker's
    :class:`~dynslam2d.detect.config.FitConfig`) and ``tc`` (its ``TrackerConfig``) and ``size_sigma``, the
    measurements' size σ (m). One array argument instead of twelve (update_pairs) and five (association_gates): the
    fit parameters and scalars converted in Python and typed and unboxed by numba's dispatcher on every call
    (docs/speed.md, pass call35). The values are the same floats the scalars were (``float(x)``;
    ``ride_max_range²`` computed as before, in Python). The association's four constants (the merge veto's
    ``map_structure_stop``, ``merge_size_jump``, ``map_structure_max`` and the assignment's cost ``big`` outside the
    gates) too: ``kernels_assign.associate_update`` reads them from here (pass trk129)."""
    q = np.empty(_UP_N)
    q[:_N_PARAMS] = fit_p
    q[UP_SIZE_SIGMA] = size_sigma
    q[UP_DEFAULT_DEPTH] = float(fc.default_depth)
    q[UP_DEFAULT_DEPTH_RATIO] = float(fc.default_depth_ratio)
    q[UP_HEADING_GAIN] = float(tc.heading_gain)
    q[UP_SIZE_GAIN] = float(tc.size_gain)
    q[UP_RIDE_TIME] = float(tc.ride_time)
    q[UP_RIDE_R2] = tc.ride_max_range * tc.ride_max_range
    q[UP_PERSON_MIN_R] = float(fc.person_min_radius)
    q[UP_PERSON_MAX_R] = float(fc.person_max_radius)
    q[UP_ACCEL_AFTER] = int(tc.accel_bound_after)
    q[UP_RIDE_N] = int(tc.ride_updates)
    q[UP_GATE_DISTANCE] = float(tc.gate_distance)
    q[UP_GATE_CHI2] = float(tc.gate_chi2)
    q[UP_JUMP_RATIO] = float(tc.max_size_jump_ratio)
    q[UP_JUMP] = float(tc.max_size_jump)
    q[UP_WINDOW] = int(tc.confirm_window)
    q[UP_NEED] = int(tc.confirm_hits)
    q[UP_MAX_COAST] = float(tc.max_coast_time)
    q[UP_MAX_SPEED] = float(tc.max_object_speed)
    q[UP_MAX_POS_SIG] = float(tc.max_position_sigma)
    q[UP_S_EXIT] = float(tc.map_structure_exit)
    q[UP_SUSTAIN] = int(tc.sustain_updates)
    q[UP_RETIRE_N] = int(tc.structure_retire_updates or 0)
    q[UP_RETIRE_S] = float(tc.structure_retire_fraction)
    q[UP_S_STOP] = float(tc.map_structure_stop)
    q[UP_MERGE_JUMP] = float(tc.merge_size_jump)
    q[UP_S_MAX] = float(tc.map_structure_max)
    q[UP_BIG] = _BIG
    return q


@njit(cache=True)
def update_pairs(G: np.ndarray, Gi: np.ndarray, X: np.ndarray, P: np.ndarray, Xs: np.ndarray, Ps: np.ndarray,
                 sel: np.ndarray, rows: np.ndarray, dis: np.ndarray, missed: np.ndarray, kind: np.ndarray,
                 theta: np.ndarray, lohi: np.ndarray, rel: np.ndarray, centroid: np.ndarray, circle: np.ndarray,
                 bpx: np.ndarray, bpy: np.ndarray, start: np.ndarray, npts: np.ndarray, q: np.ndarray, bound: bool,
                 CI: np.ndarray, CL: np.ndarray, lim: float, lim2: float, mfr: np.ndarray, kept: np.ndarray,
                 first: np.ndarray, second: np.ndarray, mnpts: np.ndarray, MEV: np.ndarray, RIDE: np.ndarray,
                 WN: np.ndarray, use_map: bool, px: float, py: float, c: float, s: float, t: float) -> tuple:
    """The pairs' update of ``Tracker._associate_update``: four kernels in one call, the same functions in the same
    order (so the same floats):
    ``kernels.pair_priors`` (the priors of the pairs: track rows ``trows = rows[sel]``, ``rows`` the state rows of the
    live tracks, detections ``dis``), ``kernels.measure_batch`` (the detections' arrays ``kind`` … ``npts`` of the
    scan's :class:`~dynslam2d.detect.layout.DetectionBatch`, each pair's size σ, the fit parameters in ``q``'s first
    columns), :func:`kalman_pairs` (``Xs`` / ``Ps``: the predicted states of the live tracks, ``sel`` the pairs' indices
    of them; ``bound``, ``lim``, ``lim2`` its acceleration bound, the tracks' hits read from the counter table ``CI``)
    and ``kernels.shape_update`` (``mfr`` … ``mnpts`` the map-evidence sources, ``px``, ``py``, ``c``, ``s`` the laser
    pose, ``t`` the stamp). The configuration's values (the fit parameters, the size σ, the shape update's depth and
    gains, the riding window's time, count and range², the person's radii, the bound's ``accel_bound_after``) come in
    ``q``, :func:`update_params`' array (columns ``UP_*`` after ``kernels.fit_params``'). Then the windows of the
    re-acquired tracks restarted: a pair whose update applied and whose track ``missed`` (per live track, indexed by
    ``sel``) its last scans keeps only this push's entries (``TrackRows._restart_windows``: the riding window's and,
    with ``use_map``, the map evidence's; without a map that window is emptied), and the counters of the tracks whose
    update applied written in their rows of ``CI`` (columns ``C_*``: hits + 1, misses 0, the M-of-N counts while fewer
    than confirm_window, the updated flag ``C_UPD``) and ``CL`` (the last hit's stamp ``t``; docs/speed.md pass cnt36).
    Returns (the number of rows bounded, the longest riding window after the push, before the restarts, ``info`` (n, 4)
    int64, the number of pairs whose update did not apply): per pair 1 where the Kalman update applied (2 where it
    applied and the track ``missed``: re-acquired; 0 where it did not), the
    detection's ``start`` and ``npts`` and 1 where it is a circle whose radius is within the person's radii (else 0) —
    what ``Tracker._update_tracks`` reads per pair, in one array. One dispatch instead of four, and none of the
    intermediate arrays (priors, measurements) boxed for Python and unboxed again (docs/speed.md, passes upd34,
    call35)."""
    n = dis.shape[0]
    trows = np.empty(n, dtype=np.int64)
    for r in range(n):
        trows[r] = rows[sel[r]]
    size_sigma = q[UP_SIZE_SIGMA]
    after = int(q[UP_ACCEL_AFTER])
    pmin_r = q[UP_PERSON_MIN_R]
    pmax_r = q[UP_PERSON_MAX_R]
    swaps, sizes, has, radius = pair_priors(G, Gi, trows, dis, kind, theta)
    sig = np.empty(n)
    sig[:] = size_sigma
    _z, _R, H, zm, Rm, size_obs, size_kind = measure_batch(dis, kind, theta, lohi, rel, centroid, circle, bpx, bpy,
                                                          start, npts, sizes, has, radius, sig, q)
    hits = np.empty(n, dtype=np.int64)
    for r in range(n):
        hits[r] = CI[trows[r], C_HITS]
    ok, nb = kalman_pairs(Xs, Ps, sel, H, zm, Rm, bound, hits, after, lim, lim2, X, P, trows)
    top = shape_update(G, Gi, X, trows, dis, ok, kind, theta, lohi, rel, circle, size_obs, size_kind, swaps,
                       q[UP_DEFAULT_DEPTH], q[UP_DEFAULT_DEPTH_RATIO], q[UP_HEADING_GAIN], q[UP_SIZE_GAIN], mfr, kept,
                       first, second, mnpts, MEV, RIDE, WN, use_map, px, py, c, s, t, q[UP_RIDE_TIME],
                       int(q[UP_RIDE_N]), q[UP_RIDE_R2])
    for r in range(n):
        if ok[r] and missed[sel[r]]:
            k = trows[r]
            m = WN[k, 1]
            if m > 1:
                for a in range(RIDE.shape[2]):
                    RIDE[k, 0, a] = RIDE[k, m - 1, a]
            WN[k, 1] = 1
            WN[k, 2] = 0  # (one entry: fewer than ride_updates ≥ 2)
            if use_map:
                m = WN[k, 0]
                if m > 1:
                    for a in range(MEV.shape[2]):
                        MEV[k, 0, a] = MEV[k, m - 1, a]
                WN[k, 0] = 1
            else:
                WN[k, 0] = 0
    info = np.empty((n, 4), dtype=np.int64)
    nrej = 0
    window = int(q[UP_WINDOW])
    for r in range(n):
        j = dis[r]
        info[r, 0] = (2 if missed[sel[r]] else 1) if ok[r] else 0  # (2: re-acquired, pass trk71)
        if ok[r]:  # (the counters of Tracker._update_tracks' loop as it was: hits, misses, last hit, M of N)
            k = trows[r]
            CI[k, C_HITS] += 1
            CI[k, C_MISSES] = 0
            CL[k] = t
            if CI[k, C_HIST_N] < window:  # (only the first window is read)
                CI[k, C_HIST_N] += 1
                CI[k, C_HIST_HITS] += 1
            CI[k, C_UPD] = 1
            CI[k, C_BS] = start[j]  # (its beams: Tracker._update_tracks' slice of this detection's, pass rep149)
            CI[k, C_BN] = npts[j]
        nrej += 0 if ok[r] else 1
        info[r, 1] = start[j]
        info[r, 2] = npts[j]
        rad = circle[j, 2]
        info[r, 3] = 1 if kind[j] == K_CIRCLE and pmin_r <= rad and rad <= pmax_r else 0
    return nb, top, info, nrej


@njit(cache=True)
def report_rows(G: np.ndarray, Gi: np.ndarray, X: np.ndarray, P: np.ndarray, CI: np.ndarray, rows: np.ndarray,
                slow: float) -> tuple:
    """Everything ``Tracker._report`` reads from the state rows ``rows`` of the reported tracks, in one call:
    (boxes (n, 5) centre x, y, heading, length, width (m, rad, map frame), states (n, 4) ``X[rows]``, covariances
    (n, 4, 4) ``P[rows]``, (6, n) int64: the kind codes and, from the counter table ``CI``, the state codes, hits and
    misses (pass cnt36), the beam segments' first points and counts (``C_BS``, ``C_BN``, pass rep149)). The boxes:
    ``kernels.report_boxes``' arithmetic, a track moving
    when its speed — Python's ``math.hypot`` bit for bit (:func:`py_hypot`) — is above ``slow`` (m/s); so no speed
    is left undecided for a second call as ``report_boxes`` (libm's hypot) leaves the ones within 1e-12 of the
    limit (docs/speed.md, pass trk24). A moving box is headed along its velocity (the axis nearest it, its sides
    swapped when that is the second axis), a still box along its longer side, a still circle at 0; the heading of
    a box wrapped to [−π, π)."""
    n = rows.shape[0]
    out = np.empty((n, 5))
    Xo = np.empty((n, 4))
    Po = np.empty((n, 4, 4))
    ints = np.empty((6, n), dtype=np.int64)
    for i in range(n):
        k = rows[i]
        for a in range(4):
            Xo[i, a] = X[k, a]
            for b in range(4):
                Po[i, a, b] = P[k, a, b]
        kd = Gi[k, GI_KIND]
        ints[0, i] = kd
        ints[1, i] = CI[k, C_STATE]
        ints[2, i] = CI[k, C_HITS]
        ints[3, i] = CI[k, C_MISSES]
        ints[4, i] = CI[k, C_BS]
        ints[5, i] = CI[k, C_BN]
        box_row(out, i, X, G, k, kd == K_CIRCLE, py_hypot(X[k, 2], X[k, 3]) > slow)
    return out, Xo, Po, ints


@njit(cache=True)
def fragment_hosts_rows(px: np.ndarray, py: np.ndarray, start: np.ndarray, npts: np.ndarray, det: np.ndarray,
                        X: np.ndarray, G: np.ndarray, rows: np.ndarray, margin: float) -> np.ndarray:
    """``kernels.fragment_hosts`` with the candidate boxes read from the state rows ``rows`` (centre ``X[rows, :2]``,
    axis angle and sizes from the shape rows ``G``, m, rad, map frame) in the call instead of five gathers before
    it (docs/speed.md, pass trk24): for each detection ``det[r]`` the index in ``rows`` of the box that holds every
    point with the least overshoot below ``margin`` (m), −1 for none."""
    nt = rows.shape[0]
    tx = np.empty(nt)
    ty = np.empty(nt)
    tth = np.empty(nt)
    ts0 = np.empty(nt)
    ts1 = np.empty(nt)
    for i in range(nt):
        k = rows[i]
        tx[i] = X[k, 0]
        ty[i] = X[k, 1]
        tth[i] = G[k, G_THETA]
        ts0[i] = G[k, G_SIZE0]
        ts1[i] = G[k, G_SIZE1]
    return fragment_hosts(px, py, start, npts, det, tx, ty, tth, ts0, ts1, margin)



@njit(cache=True)
def birth_rows(X: np.ndarray, P: np.ndarray, G: np.ndarray, Gi: np.ndarray, CI: np.ndarray, CL: np.ndarray,
               MEV: np.ndarray, WN: np.ndarray, rows: np.ndarray, js: np.ndarray, kind: np.ndarray, theta: np.ndarray,
               lohi: np.ndarray, rel: np.ndarray, circle: np.ndarray, z: np.ndarray, R: np.ndarray,
               size_kind: np.ndarray, mev: np.ndarray, q: np.ndarray, speed_var: float, has_map: bool,
               t: float) -> None:
    """The rows of the tentative tracks born in one scan, in one call (``Tracker._births``; docs/speed.md, pass
    trk38): birth i from the scan's detection ``js[i]`` (its rows of the batch arrays ``kind`` … ``circle`` and of
    the default measurements ``z``, ``R``, ``size_kind``) gets row ``rows[i]`` of the state arrays: state [z, 0, 0]
    (map frame, m, m/s), covariance R on the position and ``speed_var`` (init_speed_sigma², m²/s²) on each velocity
    component, the shape row (axis angle, sizes and known flags of ``Tracker._birth_shape``: a rectangle's sizes
    from its bounds with the default depth where a bound is not real (``q``'s ``UP_DEFAULT_DEPTH*`` columns), a
    circle's its diameter, a point's its extent at least 0.05 m; the radius for a circle), the counter row
    (tentative, one hit, no miss, M of N 1 / 1) and last hit ``t`` (s), and its windows: no riding entry, with a map
    (``has_map``) the detection's map evidence ``mev[i]`` (structure, free, unknown) as the one entry. The same
    floats as ``Tracker._birth``'s Python: Python's ``max`` / ``min`` (the first argument unless the second is
    larger / smaller) written out."""
    dd = q[UP_DEFAULT_DEPTH]
    ratio = q[UP_DEFAULT_DEPTH_RATIO]
    for i in range(rows.shape[0]):
        r = rows[i]
        j = js[i]
        kd = kind[j]
        circ = 0.0
        if kd == K_RECT:
            e0 = lohi[j, 2] - lohi[j, 0]
            e1 = lohi[j, 3] - lohi[j, 1]
            if rel[j, 0, 0] and rel[j, 0, 1]:
                s0 = e0
            else:  # max(e0, min(dd, ratio * max(e1, 0.0)))
                m = 0.0 if 0.0 > e1 else e1
                m = ratio * m
                m = m if m < dd else dd
                s0 = m if m > e0 else e0
            if rel[j, 1, 0] and rel[j, 1, 1]:
                s1 = e1
            else:
                m = 0.0 if 0.0 > e0 else e0
                m = ratio * m
                m = m if m < dd else dd
                s1 = m if m > e1 else e1
            k0 = size_kind[j, 0] == SIZE_MEASURED
            k1 = size_kind[j, 1] == SIZE_MEASURED
        elif kd == K_CIRCLE:
            circ = circle[j, 2]
            s0 = 2.0 * circ
            s1 = s0
            k0 = True
            k1 = True
        else:  # max(extent, 0.05)
            e0 = lohi[j, 2] - lohi[j, 0]
            e1 = lohi[j, 3] - lohi[j, 1]
            s0 = 0.05 if 0.05 > e0 else e0
            s1 = 0.05 if 0.05 > e1 else e1
            k0 = False
            k1 = False
        G[r, G_THETA] = theta[j]
        G[r, G_SIZE0] = s0
        G[r, G_SIZE1] = s1
        G[r, G_RADIUS] = circ
        G[r, G_LB0] = 0.0
        G[r, G_LB1] = 0.0
        Gi[r, GI_KIND] = kd
        Gi[r, GI_HEADING] = 1 if kd == K_RECT else 0
        Gi[r, GI_KNOWN0] = 1 if k0 else 0
        Gi[r, GI_KNOWN1] = 1 if k1 else 0
        CI[r, C_STATE] = ST_TENTATIVE
        CI[r, C_HITS] = 1
        CI[r, C_MISSES] = 0
        CI[r, C_HIST_N] = 1
        CI[r, C_HIST_HITS] = 1
        CI[r, C_UPD] = 0
        CL[r] = t
        X[r, 0] = z[j, 0]
        X[r, 1] = z[j, 1]
        X[r, 2] = 0.0
        X[r, 3] = 0.0
        for a in range(4):
            for b in range(4):
                P[r, a, b] = 0.0
        P[r, 0, 0] = R[j, 0, 0]
        P[r, 0, 1] = R[j, 0, 1]
        P[r, 1, 0] = R[j, 1, 0]
        P[r, 1, 1] = R[j, 1, 1]
        P[r, 2, 2] = speed_var
        P[r, 3, 3] = speed_var
        if has_map:
            MEV[r, 0, 0] = mev[i, 0]
            MEV[r, 0, 1] = mev[i, 1]
            MEV[r, 0, 2] = mev[i, 2]
            WN[r, 0] = 1
        else:
            WN[r, 0] = 0
        WN[r, 1] = 0
        WN[r, 2] = 0


#: outcomes of :func:`ride_window` (``Tracker._rides_with_laser``'s tests, in their order)
RIDE_FEW = 0  # fewer than ride_updates entries in the window: it cannot ride
RIDE_FAR = 1  # its last laser-frame centre farther than ride_max_range from the laser
RIDE_OFF_BODY = 2  # fewer than half its beams near the robot's body (or none)
RIDE_SHORT = 3  # fewer than ride_updates entries within ride_time, or spanning less than half of it
RIDE_OUT = 4  # one of those entries' laser-frame centres beyond ride_max_range
RIDE_JUDGE = 5  # judged by the spread and the motion returned


@njit(cache=True)
def ride_window(R: np.ndarray, W: np.ndarray, row: int, beams: np.ndarray, body_near: np.ndarray, has_body: bool,
                ride_updates: int, ride_r: float, ride_time: float) -> tuple:
    """``Tracker._rides_with_laser``'s arithmetic on row ``row`` of the riding windows (``R`` (rows, L, 5): laser-frame
    x, y, map-frame x, y (m), stamp (s) per update, oldest first; ``W[row, 1]`` entries) in one call: (outcome, spread,
    moved) with the outcome one of ``RIDE_*`` — its tests in order, the first that stops it — and, for
    :data:`RIDE_JUDGE`, the largest distance of the last n laser-frame centres from their mean (m) and the map-frame
    distance between the first and last of them (m), n the entries within ``ride_time`` (s) of the last one.
    ``beams``: the track's beams in this scan; ``body_near`` (scan beams,) bool: near the robot's body, read only
    with ``has_body``; ``ride_r``: ride_max_range, m. The former NumPy forms, operation for operation: ``np.hypot`` is
    libm's ``hypot`` as numba's; the mean over the entries NumPy's axis-0 reduction (the rows added in order from the
    first, then divided by n); a largest value NaN if any is (NumPy's ``max``)."""
    m = W[row, 1]
    if m < ride_updates:
        return RIDE_FEW, 0.0, 0.0
    lx_last = R[row, m - 1, 0]
    ly_last = R[row, m - 1, 1]
    if lx_last * lx_last + ly_last * ly_last > ride_r * ride_r:
        return RIDE_FAR, 0.0, 0.0
    if has_body:
        nb = beams.shape[0]
        if nb == 0:
            return RIDE_OFF_BODY, 0.0, 0.0
        cnt = 0
        for i in range(nb):
            if body_near[beams[i]]:
                cnt += 1
        if cnt / nb < 0.5:
            return RIDE_OFF_BODY, 0.0, 0.0
    t_end = R[row, m - 1, 4]
    n = 0
    for i in range(m):
        if t_end - R[row, i, 4] <= ride_time:
            n += 1
    if n < ride_updates or t_end - R[row, m - n, 4] < 0.5 * ride_time:
        return RIDE_SHORT, 0.0, 0.0
    a = m - n
    top = 0.0
    for i in range(a, m):
        h = np.hypot(R[row, i, 0], R[row, i, 1])
        if i == a or h > top or h != h:
            top = h
        if top != top:
            break
    if top > ride_r:
        return RIDE_OUT, 0.0, 0.0
    sx = R[row, a, 0]
    sy = R[row, a, 1]
    for i in range(a + 1, m):
        sx += R[row, i, 0]
        sy += R[row, i, 1]
    mx = sx / n
    my = sy / n
    spread = 0.0
    for i in range(a, m):
        h = np.hypot(R[row, i, 0] - mx, R[row, i, 1] - my)
        if i == a or h > spread or h != h:
            spread = h
        if spread != spread:
            break
    moved = np.hypot(R[row, m - 1, 2] - R[row, a, 2], R[row, m - 1, 3] - R[row, a, 3])
    return RIDE_JUDGE, spread, moved
