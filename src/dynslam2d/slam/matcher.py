"""Gauss–Newton / Levenberg–Marquardt scan-to-map matching (Kohlbrecher et al., SSRR 2011 §IV-B;
hector_mapping matcher/ScanMatcher.h).

Objective (paper Eq. 7): ξ* = argmin Σ_i [1 − M(S_i(ξ))]², M the bilinearly interpolated
occupancy probability of one level, S_i(ξ) = R(θ)s_i + t in that level's cells.
Per level, H = Σ JᵀJ and g = Σ (1−M)·J with J = (Mx, My, ∇M·∂S/∂θ)
(OccGridMapUtil::getCompleteHessianDerivs).

``step_mode="gauss_newton"`` takes the reference's raw step Δ = H⁻¹g
(ScanMatcher::estimateTransformationLogLh, but with the step bounds applied); ``"lm"`` solves
(H + λ·diag H)Δ = g, bounds Δ, and accepts the step only if the cost drops (λ ÷ 10), otherwise
λ × 10 — so no single step can throw the pose away (the reference once took a 14 m step when people walked by).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.jitbox import njit, numba_import  # numba's njit (or the AOT kernels'), numba's names
from dynslam2d.slam.grid import GridLevel
from dynslam2d.slam.interp import cell_prob_pair, interp_value_grad

_nbtypes, _cgutils, _intrinsic, _populate_array = numba_import(
    "numba.types", "numba.core.cgutils", "numba.extending.intrinsic", "numba.np.arrayobj.populate_array")

#: An accepted LM step smaller than this (cells and rad) ends the iterations on a level early;
#: it only saves time (the reference always runs all steps).
_CONVERGED_CELLS = 1e-3
_CONVERGED_RAD = 1e-5
#: float64's dtype (an array's ``dtype is _F64``: the cheap form of ``== np.float64`` for the arrays NumPy makes)
_F64 = np.dtype(np.float64)
#: The all-zero prior information (no prior).
_ZERO3 = np.zeros((3, 3))
#: all-zero prior information of up to three levels (read only)
_ZERO_PRIORS = np.zeros((3, 3, 3))
#: ``_ZERO_PRIORS[:n]`` for n = 0 … 3, made once (not a new view on every match)
_ZERO_PRIOR_VIEWS = tuple(_ZERO_PRIORS[:n] for n in range(4))


#: points per block of :func:`_sums` (its scratch: (5 + 11, _BLOCK) float64, (4, _BLOCK) float32 and (_BLOCK,) uint64,
#: ≈ 19 KiB: within the first-level cache)
_BLOCK = 128
#: byte alignment of :func:`_stack_array`'s buffers (a cache line: the vectorised loops' stores do not straddle one)
_STACK_ALIGN = 64


@_intrinsic
def _stack_array(typingctx, dtype, rows, cols):  # type: ignore[no-untyped-def]
    """In a kernel: an uninitialised C-contiguous (``rows``, ``cols``) array of ``dtype`` (a NumPy scalar type; the
    sizes integer constants) in the calling kernel's stack frame, aligned to ``_STACK_ALIGN`` bytes — ``np.empty``
    without the allocator's call and its free. Made once per call of the kernel (the buffer is reserved in its entry
    block, also when the call sits in a loop); the array and its views must not outlive that call (no meminfo: never
    return or store it)."""
    if not (isinstance(rows, _nbtypes.IntegerLiteral) and isinstance(cols, _nbtypes.IntegerLiteral)
            and isinstance(dtype, _nbtypes.NumberClass)):
        return None
    dt = dtype.instance_type
    n_rows, n_cols = rows.literal_value, cols.literal_value
    arrty = _nbtypes.Array(dt, 2, "C")

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        lty = context.get_data_type(dt)
        data = _cgutils.alloca_once(builder, lty, size=n_rows * n_cols)
        data.align = _STACK_ALIGN
        size = context.get_abi_sizeof(lty)
        intp = context.get_value_type(_nbtypes.intp)
        ary = context.make_array(arrty)(context, builder)
        _populate_array(ary, data=data, shape=[intp(n_rows), intp(n_cols)],
                        strides=[intp(n_cols * size), intp(size)], itemsize=intp(size), meminfo=None)
        return ary._getvalue()

    return arrty(dtype, rows, cols), codegen


@njit(cache=True, inline="always")
def _split_xy(pts):  # pragma: no cover - numba
    """The (n, 2) points as two contiguous rows (2, n) (the same values), for :func:`_sums`' vectorised loops."""
    n = pts.shape[0]
    xy = np.empty((2, n))
    for i in range(n):
        xy[0, i] = pts[i, 0]
        xy[1, i] = pts[i, 1]
    return xy


@njit(cache=True, inline="always")
def _cell_of(sx, sy, c, s, x, y, xmax, ymax, w):  # pragma: no cover - numba
    """The point (``sx``, ``sy``) (cells, laser frame) at map pose (x, y cells, θ with cos ``c``, sin ``s``): its
    fractions (fx, fy) in its cell, the cell's key ``y0 · w + x0`` in a (h, w) cache's flat view and its in-bounds
    flag (1.0 / 0.0; 0 ≤ x ≤ ``xmax``, 0 ≤ y ≤ ``ymax``, NaN rejected), with
    :func:`~dynslam2d.slam.interp.interp_value_grad`'s operations; an outside point reads cell (0, 0). Branch-free
    (selects), for the blocks' vectorised first loops of :func:`_sums` and :func:`_support_kernel`."""
    qx = c * sx - s * sy + x
    qy = s * sx + c * sy + y
    inb = (qx >= 0.0) & (qy >= 0.0) & (qx <= xmax) & (qy <= ymax)  # (also rejects NaN)
    qx = qx if inb else 0.0
    qy = qy if inb else 0.0
    x0 = int(qx)
    y0 = int(qy)
    return qx - x0, qy - y0, np.uint64(y0 * w + x0), 1.0 if inb else 0.0


@njit(cache=True)
def _sums(prob, xy, x, y, th, swapped, full, stats, H, g):  # pragma: no cover - numba
    """:func:`accumulate`'s pass over the points ``xy`` (2, n) (rows x and y, cells); without ``full`` only the cost
    (H, g untouched; Σ M and n_inside returned as 0); with ``full`` but without ``stats``, the cost, H and g (Σ M and
    n_inside returned as 0: two sums fewer a point, pass map38). Without ``full`` but with ``stats``, the count mode:
    (unspecified, 0.0, the number of inside points whose M is below ``g[0]``; H, g untouched) —
    :func:`fraction_below`'s count (an integer: its order does not matter) from the cost-only pass's loops, each
    point's M kept for it in the terms' second row, without the cost's sum (pass mat148: one copy of the cell loops,
    not a second kernel body; the threshold read from ``g``, not a new argument held in a register through the other
    modes' loops, where it made LLVM spill the twelve sums to the stack).

    The same float64 (and float32: the cells' differences) operations per point as
    :func:`~dynslam2d.slam.interp.interp_value_grad` and the same sums in point order, so the same bits as the
    one-loop form (tests/test_slam_match_kernels.py keeps it as the reference): per block of ``_BLOCK`` points, a
    loop with no loop-carried value and no branch (LLVM vectorises it) gives each point's cell, fractions and
    in-bounds flag; a scalar loop reads the four cells; a second branch-free loop computes each point's eleven
    terms (an out-of-bounds point's: cost 1, the others +0.0 — adding +0.0 to a sum that starts at +0.0 leaves
    its bits unchanged: such a sum is never −0.0); the last loop adds them up in point order. An out-of-bounds
    point reads cell 0 (in the array: a map with a point inside has w, h ≥ 2) and its values are not used."""
    c = math.cos(th)
    s = math.sin(th)
    h, w = prob.shape
    flat = np.ascontiguousarray(prob).reshape(-1)  # (a view of the level's C-contiguous cache)
    xmax = w - 2
    ymax = h - 2
    n = xy.shape[1]
    px = xy[0]
    py = xy[1]
    uw = np.uint64(w)
    # per-block scratch, made here (not passed in: LLVM then knows the arrays do not overlap and vectorises the
    # loops without run-time overlap checks), in this call's stack frame (no allocation and free on every pass)
    fb = _stack_array(np.float64, 5, _BLOCK)
    tb = _stack_array(np.float64, 11, _BLOCK)
    qb = _stack_array(np.float32, 4, _BLOCK)
    kb = _stack_array(np.uint64, 1, _BLOCK)[0]
    cost = 0.0
    summ = 0.0
    n_in = 0.0
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    h00 = 0.0
    h01 = 0.0
    h02 = 0.0
    h11 = 0.0
    h12 = 0.0
    h22 = 0.0
    if w < 2 or h < 2:  # (no point can be inside: each adds (1 − 0)² = 1; H and g below are zeros)
        for _ in range(n):
            cost += 1.0
        n = 0
    for b0 in range(0, n, _BLOCK):
        m = min(_BLOCK, n - b0)
        for j in range(m):
            sx = px[np.uint64(b0 + j)]  # (unsigned: no negative-index select, so the loop vectorises)
            sy = py[np.uint64(b0 + j)]
            fb[0, j], fb[1, j], kb[j], fb[2, j] = _cell_of(sx, sy, c, s, x, y, xmax, ymax, w)
            fb[3, j] = -s * sx - c * sy
            fb[4, j] = c * sx - s * sy
        for j in range(m):
            k = kb[j]
            # (the cache's words decoded: slam/grid.py encode_probs; each row's two cells from one 8-byte load)
            qb[0, j], qb[1, j] = cell_prob_pair(flat, k)
            qb[2, j], qb[3, j] = cell_prob_pair(flat, k + uw)
        if not full:  # (the cost alone: only each point's (1 − M)², the same operations as below)
            for j in range(m):
                fx = fb[0, j]
                fy = fb[1, j]
                mv = (1.0 - fy) * ((1.0 - fx) * qb[0, j] + fx * qb[1, j]) \
                    + fy * ((1.0 - fx) * qb[2, j] + fx * qb[3, j])
                r = 1.0 - mv
                tb[0, j] = r * r if fb[2, j] != 0.0 else 1.0
                tb[1, j] = mv
            if stats:  # (the count mode: the inside points whose M is below g[0])
                below = g[0]
                nb = 0
                for j in range(m):
                    nb += 1 if (fb[2, j] != 0.0) & (tb[1, j] < below) else 0
                n_in += nb
                continue
            for j in range(m):
                cost += tb[0, j]
            continue
        for j in range(m):
            fx = fb[0, j]
            fy = fb[1, j]
            p00 = qb[0, j]
            p10 = qb[1, j]
            p01 = qb[2, j]
            p11 = qb[3, j]
            mv = (1.0 - fy) * ((1.0 - fx) * p00 + fx * p10) + fy * ((1.0 - fx) * p01 + fx * p11)
            r = 1.0 - mv
            # Kohlbrecher et al. 2011 Eqs. 5–6 (the value's gradient); hector_gradient_bug (``swapped``) weighs
            # the two differences of each with the other fraction
            ax = fx if swapped else fy
            ay = fy if swapped else fx
            mx = (1.0 - ax) * (p10 - p00) + ax * (p11 - p01)
            my = (1.0 - ay) * (p01 - p00) + ay * (p11 - p10)
            dth = fb[3, j] * mx + fb[4, j] * my  # Kohlbrecher et al. 2011 Eq. 11
            inb = fb[2, j] != 0.0
            tb[0, j] = r * r if inb else 1.0
            tb[1, j] = mv if inb else 0.0
            tb[2, j] = r * mx if inb else 0.0
            tb[3, j] = r * my if inb else 0.0
            tb[4, j] = r * dth if inb else 0.0
            tb[5, j] = mx * mx if inb else 0.0
            tb[6, j] = mx * my if inb else 0.0
            tb[7, j] = mx * dth if inb else 0.0
            tb[8, j] = my * my if inb else 0.0
            tb[9, j] = my * dth if inb else 0.0
            tb[10, j] = dth * dth if inb else 0.0
        if not stats:  # (the same sums of the cost, g and H, in the same order: each has its own accumulator)
            for j in range(m):
                cost += tb[0, j]
                g0 += tb[2, j]
                g1 += tb[3, j]
                g2 += tb[4, j]
                h00 += tb[5, j]
                h01 += tb[6, j]
                h02 += tb[7, j]
                h11 += tb[8, j]
                h12 += tb[9, j]
                h22 += tb[10, j]
            continue
        for j in range(m):
            cost += tb[0, j]
            summ += tb[1, j]
            g0 += tb[2, j]
            g1 += tb[3, j]
            g2 += tb[4, j]
            h00 += tb[5, j]
            h01 += tb[6, j]
            h02 += tb[7, j]
            h11 += tb[8, j]
            h12 += tb[9, j]
            h22 += tb[10, j]
            n_in += fb[2, j]
    if full:
        g[0] = g0
        g[1] = g1
        g[2] = g2
        H[0, 0] = h00
        H[0, 1] = h01
        H[0, 2] = h02
        H[1, 0] = h01
        H[1, 1] = h11
        H[1, 2] = h12
        H[2, 0] = h02
        H[2, 1] = h12
        H[2, 2] = h22
    return cost, summ, int(n_in)


@njit(cache=True, inline="always")
def accumulate(prob, pts, x, y, th, swapped, H, g):  # pragma: no cover - numba
    """Fill H (3, 3) and g (3,) at map pose (x, y, θ); return (cost, Σ M, n_inside).

    cost = Σ (1−M)² over all points, out-of-bounds points counting M = 0;
    out-of-bounds points add nothing to H, g (as getCompleteHessianDerivs).
    """
    return _sums(prob, _split_xy(pts), x, y, th, swapped, np.bool_(True), np.bool_(True), H, g)


@njit(cache=True, inline="always")
def fraction_below(prob, pts, x, y, th, thresh):  # pragma: no cover - numba
    """Fraction of points whose interpolated probability at map pose (x, y, θ) is in bounds and
    below ``thresh`` — endpoints that land in space the map knows to be free."""
    c = math.cos(th)
    s = math.sin(th)
    n = 0
    for i in range(pts.shape[0]):
        sx = pts[i, 0]
        sy = pts[i, 1]
        m, _, _, inside = interp_value_grad(prob, c * sx - s * sy + x, s * sx + c * sy + y, np.bool_(False))
        if inside and m < thresh:
            n += 1
    return n / max(pts.shape[0], 1)


@njit(cache=True, inline="always")
def _solve3(A, b, out):  # pragma: no cover - numba
    """Solve the 3×3 system A·out = b by the adjugate; return False if A is (near) singular."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    scale = abs(A[0, 0] * A[1, 1] * A[2, 2]) + 1e-300
    if not (abs(det) > 1e-12 * scale) or not math.isfinite(det):
        return False
    inv00 = c00 / det
    inv01 = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / det
    inv02 = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / det
    inv10 = c01 / det
    inv11 = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
    inv12 = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
    inv20 = c02 / det
    inv21 = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
    inv22 = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det
    out[0] = inv00 * b[0] + inv01 * b[1] + inv02 * b[2]
    out[1] = inv10 * b[0] + inv11 * b[1] + inv12 * b[2]
    out[2] = inv20 * b[0] + inv21 * b[1] + inv22 * b[2]
    return math.isfinite(out[0]) and math.isfinite(out[1]) and math.isfinite(out[2])


@njit(cache=True)
def _prior_cost(x, y, th, prior, lam_p):  # pragma: no cover - numba
    """(ξ − ξp)ᵀ Λp (ξ − ξp) in the level's cell / rad units."""
    d0 = x - prior[0]
    d1 = y - prior[1]
    d2 = th - prior[2]
    return (d0 * (lam_p[0, 0] * d0 + lam_p[0, 1] * d1 + lam_p[0, 2] * d2)
            + d1 * (lam_p[1, 0] * d0 + lam_p[1, 1] * d1 + lam_p[1, 2] * d2)
            + d2 * (lam_p[2, 0] * d0 + lam_p[2, 1] * d1 + lam_p[2, 2] * d2))


@njit(cache=True)
def _same_float(a, b):  # pragma: no cover - numba
    """``a`` and ``b`` are the same float, sign of zero included (finite values)."""
    return a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))


@njit(cache=True, inline="always")
def _round_trips(x, y, th, res, i0, j0):  # pragma: no cover - numba
    """Map pose (x, y, θ) comes back bit for bit from the world pose :func:`match_pyramid` makes of it (((x + i0)·res,
    (y + j0)·res, wrapped θ) and back: x / res − i0 …), so that its finest-level evaluation is this pose's sums."""
    wx = (x + i0) * res
    wy = (y + j0) * res
    wth = (th + math.pi) % (2.0 * math.pi) - math.pi
    return _same_float(wx / res - i0, x) and _same_float(wy / res - j0, y) and _same_float(wth, th)


@njit(cache=True, inline="always")
def _scaled_rows(pts_m, res):  # pragma: no cover - numba
    """``_split_xy(pts_m / res)`` in one pass: the (n, 2) points divided by ``res`` as two rows (2, n) (each value
    the same division)."""
    n = pts_m.shape[0]
    xy = np.empty((2, n))
    for i in range(n):
        xy[0, i] = pts_m[i, 0] / res
        xy[1, i] = pts_m[i, 1] / res
    return xy


@njit(cache=True)
def _match_core(prob, xy, pose, n_iter, swapped, use_lm, lam0, lam_max, max_rot, max_trans,
                prior, lam_p, H_out, keep, res, i0, j0):  # pragma: no cover - numba
    """:func:`match_level`'s iterations on the points ``xy`` (2, n) (rows x and y, cells: :func:`_split_xy` of
    match_level's); returns (x, y, θ, accepted steps, cost, Σ M, n_inside) with H at the
    returned pose in ``H_out`` (cost, Σ M and n_inside of :func:`accumulate` there: without the prior term).

    H, Σ M and n_inside at the returned pose are needed only with ``keep`` and when that pose survives
    :func:`_round_trips` with (``res``, ``i0``, ``j0``) (else ``H_out``, Σ M and n_inside are unspecified: without
    ``keep`` no pass sums Σ M and n_inside — two of the twelve sums a point, pass map38). An LM
    trial step that, if accepted, ends the iterations (the last one, or converged) and whose H is not needed
    so runs the cost-only pass: its cost is the same sum (the rejected / accepted decision and the pose do not
    change), and the H, g it would have made are never read."""
    # (the small work arrays in this call's stack frame: _stack_array, no allocation per level)
    H = _stack_array(np.float64, 3, 3)
    H[:] = 0.0
    g = _stack_array(np.float64, 1, 3)[0]
    g[:] = 0.0
    H2 = _stack_array(np.float64, 3, 3)  # H, g at a trial LM step (they become H, g when it is accepted)
    H2[:] = 0.0
    g2 = _stack_array(np.float64, 1, 3)[0]
    g2[:] = 0.0
    A = _stack_array(np.float64, 3, 3)
    A[:] = 0.0
    d = _stack_array(np.float64, 1, 3)[0]
    d[:] = 0.0
    x = pose[0]
    y = pose[1]
    th = pose[2]
    use_prior = False
    for a in range(3):
        for b in range(3):
            if lam_p[a, b] != 0.0:
                use_prior = True
    gp = _stack_array(np.float64, 1, 3)[0]
    gp[:] = 0.0
    raw, summ, n_in = _sums(prob, xy, x, y, th, swapped, np.bool_(True), keep, H, g)
    cost = raw
    if use_prior:
        cost += _prior_cost(x, y, th, prior, lam_p)
    lam = lam0
    n_acc = 0
    for it in range(n_iter):
        if H[0, 0] == 0.0 or H[1, 1] == 0.0:
            break
        for a in range(3):
            gp[a] = g[a]
            for b in range(3):
                A[a, b] = H[a, b]
        if use_prior:
            # prior term in the normal equations (Zhang et al. 2016: the prior constrains the directions
            # the measurement leaves degenerate; lam_p is zero along the well-constrained ones)
            r0 = prior[0] - x
            r1 = prior[1] - y
            r2 = prior[2] - th
            for a in range(3):
                gp[a] += lam_p[a, 0] * r0 + lam_p[a, 1] * r1 + lam_p[a, 2] * r2
                for b in range(3):
                    A[a, b] += lam_p[a, b]
        if use_lm:
            for a in range(3):
                A[a, a] += lam * A[a, a] + 1e-9
        if not _solve3(A, gp, d):
            if use_lm:
                lam *= 10.0
                if lam > lam_max:
                    break
                continue
            break
        # bounded step: reference rotation clamp + translation trust bound
        if d[2] > max_rot:
            d[2] = max_rot
        elif d[2] < -max_rot:
            d[2] = -max_rot
        nt = math.sqrt(d[0] * d[0] + d[1] * d[1])
        if nt > max_trans:
            d[0] *= max_trans / nt
            d[1] *= max_trans / nt
        nx = x + d[0]
        ny = y + d[1]
        nth = th + d[2]
        if use_lm:
            # one pass gives the trial cost and, if the step is accepted, the new H and g (the same sums as a
            # cost-only pass followed by accumulate at the accepted pose); a step whose acceptance ends the
            # iterations needs them only when the caller keeps this pose's H
            ends = it == n_iter - 1 or (nt < _CONVERGED_CELLS and abs(d[2]) < _CONVERGED_RAD)
            full = not ends or (keep and _round_trips(nx, ny, nth, res, i0, j0))
            new_raw, new_summ, new_in = _sums(prob, xy, nx, ny, nth, swapped, full, full and keep, H2, g2)
            new_cost = new_raw
            if use_prior:
                new_cost += _prior_cost(nx, ny, nth, prior, lam_p)
            if new_cost < cost:
                x, y, th = nx, ny, nth
                cost = new_cost
                raw, summ, n_in = new_raw, new_summ, new_in
                if full:
                    H, H2 = H2, H
                    g, g2 = g2, g
                lam = max(lam * 0.1, 1e-7)
                n_acc += 1
                if nt < _CONVERGED_CELLS and abs(d[2]) < _CONVERGED_RAD:
                    break
            else:
                lam *= 10.0
                if lam > lam_max:
                    break
        else:
            x, y, th = nx, ny, nth
            raw, summ, n_in = _sums(prob, xy, x, y, th, swapped, np.bool_(True), keep, H, g)
            cost = raw
            if use_prior:
                cost += _prior_cost(x, y, th, prior, lam_p)
            n_acc += 1
    for a in range(3):
        for b in range(3):
            H_out[a, b] = H[a, b]
    return x, y, th, n_acc, raw, summ, n_in


@njit(cache=True)
def match_level(prob, pts, pose, n_iter, swapped, use_lm, lam0, lam_max, max_rot, max_trans,
                prior, lam_p):  # pragma: no cover
    """Run ``n_iter`` GN/LM steps on one level from map pose ``pose`` (x, y cells, θ rad).

    Returns (pose (3,), number of accepted steps). Steps are bounded: |Δθ| ≤ max_rot
    (reference ±0.2 rad clamp), |Δxy| ≤ max_trans cells. With an empty map (H00 or H11 = 0)
    no step is taken (as ScanMatcher::estimateTransformationLogLh).

    ``prior`` (3,) and ``lam_p`` (3, 3) add a prior term ½(ξ−ξp)ᵀΛp(ξ−ξp) to the objective (same
    units as ``pose``): the normal equations become (H + Λp)Δ = g + Λp(ξp − ξ). An all-zero
    ``lam_p`` is the plain matcher.
    """
    H = np.empty((3, 3))
    H[:] = 0.0
    x, y, th, n_acc, _, _, _ = _match_core(prob, _split_xy(pts), pose, n_iter, swapped, use_lm, lam0, lam_max, max_rot,
                                           max_trans, prior, lam_p, H, False, 1.0, 0.0, 0.0)
    out = np.empty(3)
    out[0] = x
    out[1] = y
    out[2] = th
    return out, n_acc


def _degeneracy_math(h00: float, h01: float, h02: float, h10: float, h11: float, h12: float, h20: float,
                     h21: float, h22: float, resolution: float, n: int, sumsq: float, threshold: float,
                     two: float) -> tuple[float, float, float, float, float, float, float, bool, bool]:
    """:func:`degeneracy_values` of the Hessian cells ``h00`` … ``h22`` (world units: m, m, rad) with ``n`` points of
    Σ x² + y² = ``sumsq`` m², the weakest axis (ax, ay) returned before its normalisation (:func:`unit_axis`:
    Python's ``math.hypot`` is not numba's). Plain Python, called as it is by :func:`degeneracy_values` and compiled
    into :func:`match_pyramid` (:func:`_degeneracy_kernel`): one text, the same float operations in the same order
    both ways. ``two`` is 2.0 given at run time: in a kernel ``x ** two`` then calls the C library's ``pow``, as
    CPython's ``x ** 2`` does (a literal 2 would be compiled to ``x * x``, which rounds differently for about one
    value in a thousand)."""
    rho = math.sqrt(sumsq / n) if n else 1.0
    rho = 1e-3 if 1e-3 > rho else rho  # (max(rho, 1e-3) without the call: the same value, NaN kept)
    k = 1.0 / resolution  # world (m, m, rad) → cells / rad
    a = h00 * k * k
    b = 0.5 * (h01 + h10) * k * k
    d = h11 * k * k
    u = 0.5 * (h02 + h20) * k
    v = 0.5 * (h12 + h21) * k
    r = h22
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(d) and math.isfinite(u) and math.isfinite(v)
            and math.isfinite(r)) or not a + d > 0.0:
        return 0.0, 0.0, 0.0, 1.0, 0.0, rho, 0.0, True, True
    if r > 1e-12 * (a + d):  # rotation marginalized (Schur complement)
        a2 = a - u * u / r
        b2 = b - u * v / r
        d2 = d - v * v / r
    else:  # the scan sees no rotation at all
        a2 = a
        b2 = b
        d2 = d
    half_tr = 0.5 * (a2 + d2)
    disc = 0.25 * (a2 - d2) ** two + b2 * b2
    disc = math.sqrt(0.0 if 0.0 > disc else disc)  # (max(…, 0.0) as a conditional: the same value, NaN kept)
    lam_max = half_tr + disc
    lam_min = half_tr - disc
    if not lam_max > 0.0:
        return 0.0, 0.0, 0.0, 1.0, 0.0, rho, 0.0, True, True
    # eigenvector of lam_min
    if abs(b2) > 1e-300:
        ax = lam_min - d2
        ay = b2
    elif a2 <= d2:
        ax = 1.0
        ay = 0.0
    else:
        ax = 0.0
        ay = 1.0
    t_ratio = (0.0 if 0.0 > lam_min else lam_min) / lam_max
    det = a * d - b * b
    s_rot = r - (u * (d * u - b * v) + v * (a * v - b * u)) / det if det > 1e-300 * (a * d + 1e-300) else 0.0
    r_ratio = (0.0 if 0.0 > s_rot else s_rot) / (rho * rho * lam_max)
    return (r_ratio if r_ratio < t_ratio else t_ratio, t_ratio, r_ratio, ax, ay, rho, lam_max,
            t_ratio < threshold, r_ratio < threshold)


_degeneracy_jit = njit(cache=True, inline="always")(_degeneracy_math)


@njit(cache=True, inline="always")
def _degeneracy_kernel(H, resolution, n, sumsq, threshold, two):  # pragma: no cover - numba
    """:func:`_degeneracy_math` of ``H`` (3, 3) in a kernel (the axis not normalised)."""
    return _degeneracy_jit(H[0, 0], H[0, 1], H[0, 2], H[1, 0], H[1, 1], H[1, 2], H[2, 0], H[2, 1], H[2, 2],
                           resolution, n, sumsq, threshold, two)


#: :func:`match_pyramid`'s degeneracy values when it computes none
_NO_DEGENERACY = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, False, False)


@njit(cache=True)
def match_pyramid(prob0, prob1, prob2, geo, pts_m, sx, sy, sth, it_coarse, it_finest, swapped, use_lm, lam0, lam_max,
                  max_rot, max_trans, use_prior, px, py, pth, lam_ps, want_fit, free_thresh, H_out,
                  pose, support_thresh, deg_thresh, sumsq, two):  # pragma: no cover
    """:func:`match_multires` on a map of at most three levels in one call (the same arithmetic as its Python
    loop): ``prob0`` … ``prob2`` the levels' probability caches (finest first; unused ones any array), ``geo``
    (L, 4) per level (cell side m, i0, j0, 1.0 if empty), ``pts_m`` (n, 2) laser-frame points m, (``sx``, ``sy``,
    ``sth``) the start world pose (x m, y m, θ rad); (``px``, ``py``, ``pth``) the prior's world pose with ``lam_ps``
    (L, 3, 3) the prior per level in its cell units when ``use_prior`` (poses as floats, not arrays: two array
    arguments fewer to dispatch, and no copy of the caller's start).

    Writes the world pose into ``pose`` (3,) and returns (fitted, cost, Σ M, n_inside,
    free, support count, support bins). With ``want_fit`` and a finite result on a
    non-empty finest level, ``fitted`` is True and H (in ``H_out``), cost, Σ M and n_inside are :func:`evaluate`'s
    at the returned pose on level 0 (unswapped weights), from one :func:`accumulate` pass there (the iterations sum
    neither Σ M nor n_inside: their last pose is that pose, bit for bit, in only 8–11 % of the calls; pass mat146);
    ``free`` is
    :func:`free_fraction` below ``free_thresh`` on level min(1, L − 1) at the returned pose with θ wrapped once more
    (as ``Pose2D(x, y, wrap_angle(θ))``); and, unless ``support_thresh`` is NaN, the support count and bins are
    :func:`support_at`'s (count already scaled by the stride; bins, not rad) above ``support_thresh`` on level 0 at
    that same pose (else 0, 0). Unless ``deg_thresh`` is NaN, the last value returned is :func:`degeneracy_values`
    of that H with ``deg_thresh`` and ``sumsq`` (Σ x² + y² of ``pts_m``, m²), its axis not normalised
    (:func:`_degeneracy_kernel`; ``two`` = 2.0); else ``_NO_DEGENERACY``."""
    pose[0] = sx
    pose[1] = sy
    pose[2] = sth
    n_lv = geo.shape[0]
    Hk = _stack_array(np.float64, 3, 3)  # (the work arrays in this call's stack frame, as _match_core's)
    Hk[:] = 0.0
    mp = _stack_array(np.float64, 1, 3)[0]
    pp = _stack_array(np.float64, 1, 3)[0]
    fl = min(1, n_lv - 1)  # the free fraction's level
    xy_fl = np.empty((2, 0))  # its points as rows once its iterations made them (else made below)
    xy_0 = xy_fl  # level 0's points as rows once its iterations made them (the evaluation's below; else made there)
    for k in range(n_lv - 1, -1, -1):
        if geo[k, 3] != 0.0:
            continue
        n_iter = it_finest if k == 0 else it_coarse
        if n_iter <= 0:
            continue
        res = geo[k, 0]
        i0 = geo[k, 1]
        j0 = geo[k, 2]
        mp[0] = pose[0] / res - i0
        mp[1] = pose[1] / res - j0
        mp[2] = pose[2]
        if use_prior:
            pp[0] = px / res - i0
            pp[1] = py / res - j0
            pp[2] = mp[2] + (pth - mp[2] + math.pi) % (2.0 * math.pi) - math.pi  # same branch as θ
        else:
            pp[0] = mp[0]
            pp[1] = mp[1]
            pp[2] = mp[2]
        xy = _scaled_rows(pts_m, res)  # (the level's points as rows, made once per level)
        if k == fl:
            xy_fl = xy  # (the free fraction's points below: the same divisions)
        if k == 0:
            xy_0 = xy
        prob = prob0 if k == 0 else (prob1 if k == 1 else prob2)
        # (no level's H, Σ M or n_inside at its result is read: level 0's come from the evaluation below)
        x, y, th, _, _, _, _ = _match_core(prob, xy, mp, n_iter, swapped, use_lm, lam0, lam_max, max_rot, max_trans,
                                           pp, lam_ps[k], Hk, np.bool_(False), res, i0, j0)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)):
            pose[0] = np.nan
            pose[1] = np.nan
            pose[2] = np.nan
            return False, 0.0, 0.0, 0, 0.0, 0, 0, _NO_DEGENERACY
        pose[0] = (x + i0) * res
        pose[1] = (y + j0) * res
        pose[2] = (th + math.pi) % (2.0 * math.pi) - math.pi  # wrap after each level (§2.5)
    if not want_fit or geo[0, 3] != 0.0:
        return False, 0.0, 0.0, 0, 0.0, 0, 0, _NO_DEGENERACY
    free = 0.0
    g = _stack_array(np.float64, 1, 3)[0]
    g[:] = 0.0
    # (np.bool_, not literals: _match_core's signature of _sums)
    yes = np.bool_(True)
    no = np.bool_(False)
    wth = (pose[2] + math.pi) % (2.0 * math.pi) - math.pi  # (the wrapped θ of Pose2D(x, y, wrap_angle(θ)))
    if geo[fl, 3] == 0.0:
        res = geo[fl, 0]
        if xy_fl.shape[1] != pts_m.shape[0]:  # (its level ran no iterations: pts_m / res as rows, made here)
            xy_fl = _scaled_rows(pts_m, res)
        # (fraction_below of pts_m / res: the same values from the rows the level's iterations divided; _sums' count
        # mode, H and g untouched)
        g[0] = free_thresh
        _, _, n_free = _sums(prob1 if fl == 1 else prob0, xy_fl, pose[0] / res - geo[fl, 1],
                             pose[1] / res - geo[fl, 2], wth, no, no, yes, Hk, g)
        free = n_free / max(pts_m.shape[0], 1)
    res = geo[0, 0]
    m0 = pose[0] / res - geo[0, 1]
    m1 = pose[1] / res - geo[0, 2]
    m2 = pose[2]
    n_sup = 0
    k_sup = 0
    if support_thresh == support_thresh:  # (not NaN) support_at's arithmetic: (x / res − i0, y / res − j0, θ)
        stride = max(1, pts_m.shape[0] // _SUPPORT_POINTS)
        n_sup, k_sup = _support_kernel(prob0, pts_m, stride, 1.0 / res, m0, m1, wth, support_thresh,
                                       np.int64(_N_BINS))  # (an int64, not a literal: the Python call's signature)
        n_sup *= stride
    # (accumulate's pass on level 0's rows, those its iterations made)
    if xy_0.shape[1] != pts_m.shape[0]:  # (level 0 ran no iterations: pts_m / res as rows, made here)
        xy_0 = _scaled_rows(pts_m, res)
    cost, summ, n_in = _sums(prob0, xy_0, m0, m1, m2, no, yes, yes, H_out, g)
    dg = _NO_DEGENERACY
    if deg_thresh == deg_thresh:  # (not NaN) the processor's degeneracy analysis of this H, in the same call
        dg = _degeneracy_kernel(H_out, res, pts_m.shape[0], sumsq, deg_thresh, two)
    return True, cost, summ, n_in, free, n_sup, k_sup, dg


#: the levels' :attr:`~dynslam2d.slam.grid.GridLevel.geometry_stamp` s → (L, 4) float64 array of match_pyramid's
#: ``geo`` (see _level_geometry); a few maps (the front end's, the warm-up's, the loop closer's submaps) share it, each
#: level's stamp changing only when the level grows or is released
_GEO: dict[tuple, np.ndarray] = {}
_GEO_MAX = 32


def _level_geometry(levels: list[GridLevel]) -> np.ndarray:
    """(L, 4) float64 (cell side m, i0, j0, 1.0 if empty) of ``levels``, shared between calls with the same levels'
    geometry stamps (not to be written to; the kernel only reads it). A stamp is unique to one level's
    (resolution, i0, j0, empty) (:class:`~dynslam2d.slam.grid.GridLevel`), so the key of stamps stands for the
    values the array holds: one small-integer tuple instead of the twelve values read and hashed on every call."""
    if len(levels) == 3:  # (the default map: one flat key)
        a, b, c = levels
        key: tuple = (a.geometry_stamp, b.geometry_stamp, c.geometry_stamp)
    else:
        key = tuple([lv.geometry_stamp for lv in levels])
    geo = _GEO.get(key)
    if geo is None:
        if len(_GEO) >= _GEO_MAX:
            _GEO.clear()
        geo = _GEO[key] = np.array([(lv.resolution, lv.i0, lv.j0, lv.logodds.size == 0) for lv in levels],
                                   dtype=np.float64).reshape(len(levels), 4)
    return geo


@dataclass(slots=True)
class LevelFit:
    """Evaluation of a world pose on one level.

    Attributes:
        hessian: (3, 3) H in that level's cells / rad (what ScanMatcher::matchData returns as covMatrix).
        cost: Σ (1−M)², dimensionless.
        score: mean interpolated occupancy probability over all points (out-of-bounds = 0).
        n_inside: points that fell inside the map.
    """

    hessian: np.ndarray
    cost: float
    score: float
    n_inside: int
    #: :func:`degeneracy_values` of ``hessian`` (axis not normalised: :func:`unit_axis`) when the matcher's call
    #: computed it (``match_multires``' ``degeneracy_threshold``), else None
    degeneracy: tuple | None = field(default=None, compare=False, repr=False)


def evaluate(level: GridLevel, pts_m: np.ndarray, pose_world: np.ndarray, swapped: bool = False) -> LevelFit:
    """H, cost and score of laser-frame points ``pts_m`` (n, 2, m) at ``pose_world`` on ``level``."""
    H = np.zeros((3, 3))
    g = np.zeros(3)
    if level.empty or pts_m.shape[0] == 0:
        return LevelFit(H, float(pts_m.shape[0]), 0.0, 0)
    mp = level.pose_to_map(pose_world)
    cost, summ, n_in = accumulate(level.prob, pts_m / level.resolution, mp[0], mp[1], mp[2], swapped, H, g)
    return LevelFit(H, float(cost), float(summ) / pts_m.shape[0], int(n_in))


def match_multires(
    levels: list[GridLevel],
    pts_m: np.ndarray,
    start_world: np.ndarray,
    iterations_coarse: int,
    iterations_finest: int,
    swapped: bool = False,
    use_lm: bool = True,
    lam0: float = 0.1,
    lam_max: float = 1e4,
    max_rot: float = 0.2,
    max_trans_cells: float = 2.0,
    prior_world: np.ndarray | None = None,
    prior_info: np.ndarray | None = None,
    fit: list | None = None,
    free_thresh: float = 0.5,
    support_thresh: float | None = None,
    degeneracy_threshold: float | None = None,
    sumsq: float | None = None,
) -> np.ndarray:
    """Coarse-to-fine matching (Kohlbrecher et al., SSRR 2011 §IV-C; MapRepMultiMap::matchData):
    from the coarsest level down to level 0,
    each level starting at the previous level's result; θ wrapped after each level.

    ``pts_m``: (n, 2) points in the laser frame, m. ``start_world``: (x m, y m, θ rad).
    ``prior_world`` (x m, y m, θ rad) with ``prior_info`` (3, 3, information in world units:
    1/m², 1/(m·rad), 1/rad²) adds the prior term ½(ξ−ξp)ᵀΛ(ξ−ξp) on every level.
    ``fit``: a list that receives ``[evaluate(levels[0], pts_m, pose), free_fraction(levels[min(1, L − 1)], pts_m,
    (x, y, wrap_angle(θ)), free_thresh)]`` of the returned pose when it is finite (from the same kernel call; on a
    map of more than three levels, or for points that are not a C-contiguous float64 array, it stays empty), and with
    ``support_thresh`` a third item: :func:`support_at` ``(levels[0], pts_m, x, y, wrap_angle(θ), support_thresh)``;
    with ``degeneracy_threshold`` and ``sumsq`` (Σ x² + y² of ``pts_m``, m², as :func:`gated_points` gives it) the
    fit's ``degeneracy`` holds :func:`degeneracy_values` of its Hessian with them, the axis not normalised (else
    None). :func:`match_fit` returns these items instead of filling a list.
    Returns the world pose (3,).
    """
    p, lf, free, sup = match_fit(levels, pts_m, start_world, iterations_coarse, iterations_finest, swapped, use_lm,
                                 lam0, lam_max, max_rot, max_trans_cells, free_thresh, support_thresh,
                                 degeneracy_threshold, sumsq, prior_world, prior_info, fit is not None)
    if lf is not None and fit is not None:
        fit[:] = [lf, free] if sup is None else [lf, free, sup]
    return p


def match_fit(levels: list[GridLevel], pts_m: np.ndarray, start_world: np.ndarray, iterations_coarse: int,
              iterations_finest: int, swapped: bool, use_lm: bool, lam0: float, lam_max: float, max_rot: float,
              max_trans_cells: float, free_thresh: float, support_thresh: float | None,
              degeneracy_threshold: float | None, sumsq: float | None, prior_world: np.ndarray | None = None,
              prior_info: np.ndarray | None = None, want_fit: bool = True,
              ) -> tuple[np.ndarray, LevelFit | None, float | None, tuple[int, float] | None]:
    """:func:`match_multires` (the same arguments, every one positional) with its ``fit`` list's items returned:
    (world pose (3,) x m, y m, θ rad, level 0's :class:`LevelFit` there, the free fraction, the support (count,
    spread rad)), the last three None where ``match_multires`` leaves the list empty (``want_fit`` False, a pose that
    is not finite, more than three levels, points that are not a C-contiguous float64 array; the support also
    without ``support_thresh``). :func:`match_fit_at` of the start's three float64 values."""
    sx, sy, sth = (start_world if type(start_world) is np.ndarray and start_world.dtype is _F64 else np.array(
        start_world, dtype=np.float64)).tolist()
    return match_fit_at(levels, pts_m, sx, sy, sth, iterations_coarse, iterations_finest, swapped, use_lm, lam0,
                        lam_max, max_rot, max_trans_cells, free_thresh, support_thresh, degeneracy_threshold, sumsq,
                        prior_world, prior_info, want_fit)


def match_fit_at(levels: list[GridLevel], pts_m: np.ndarray, sx: float, sy: float, sth: float, iterations_coarse: int,
                 iterations_finest: int, swapped: bool, use_lm: bool, lam0: float, lam_max: float, max_rot: float,
                 max_trans_cells: float, free_thresh: float, support_thresh: float | None,
                 degeneracy_threshold: float | None, sumsq: float | None, prior_world: np.ndarray | None = None,
                 prior_info: np.ndarray | None = None, want_fit: bool = True,
                 ) -> tuple[np.ndarray, LevelFit | None, float | None, tuple[int, float] | None]:
    """:func:`match_fit` from the start (``sx`` m, ``sy`` m, ``sth`` rad; Python floats) without its array (the
    processor's first refine of a scan, from its start pose's floats). Maps of at most three levels take one
    :func:`match_pyramid` call (every level and the evaluation), the others :func:`_match_levels`."""
    n_lv = len(levels)
    dt = pts_m.dtype
    if not (n_lv <= 3 and pts_m.shape[0] != 0 and (dt is _F64 or dt == np.float64) and pts_m.flags.c_contiguous):
        # (other point arrays take the loop: their scaled copies have the loop's dtype and layout)
        return _match_levels(levels, pts_m, np.array([sx, sy, sth]), iterations_coarse, iterations_finest, swapped,
                             use_lm, lam0, lam_max, max_rot, max_trans_cells, prior_world, prior_info), None, None, None
    if prior_world is not None and prior_info is not None and bool(np.any(prior_info)):
        info = np.asarray(prior_info, dtype=np.float64)
        lam_ps = np.empty((n_lv, 3, 3))
        for k, lv in enumerate(levels):
            S = np.diag([lv.resolution, lv.resolution, 1.0])  # cells → m
            lam_ps[k] = S @ info @ S
        px, py, pth = np.asarray(prior_world, dtype=np.float64).tolist()
        use_prior = True
    else:
        lam_ps, px, py, pth, use_prior = _ZERO_PRIOR_VIEWS[n_lv], sx, sy, sth, False
    p0 = levels[0].prob
    p1 = levels[1].prob if n_lv > 1 else p0
    p2 = levels[2].prob if n_lv > 2 else p0
    H = np.empty((3, 3))
    out = np.empty(3)  # (filled by the kernel: a new array is cheaper made here than returned from numba)
    no_deg = degeneracy_threshold is None or sumsq is None
    last = _PYRAMID_LAST
    call = last[3] if last[0]() is p0 and last[1]() is p1 and last[2]() is p2 and pts_m.ndim == 2 else \
        _pyramid_callable(p0, p1, p2, pts_m)
    fitted, cost, summ, n_in, free, n_sup, k_sup, dg = call(
        p0, p1, p2, _level_geometry(levels), pts_m,
        sx, sy, sth, iterations_coarse, iterations_finest, swapped, use_lm, lam0, lam_max, max_rot, max_trans_cells,
        use_prior, px, py, pth, lam_ps, want_fit, free_thresh, H, out,
        math.nan if support_thresh is None else support_thresh, math.nan if no_deg else degeneracy_threshold,
        math.nan if sumsq is None else sumsq, 2.0,
    )
    if not fitted:
        return out, None, None, None
    # (the kernel returns Python floats and ints: no conversion)
    return (out, LevelFit(H, cost, summ / pts_m.shape[0], n_in, None if no_deg else dg),
            free, None if support_thresh is None else (n_sup, k_sup * BIN_ANGLE))


def _dead_ref() -> None:
    """A stand-in for a weak reference whose array is gone (:data:`_PYRAMID_LAST` before the first call)."""
    return None


#: match_pyramid's callable for the caches of its usual types (uint32, 2-D, C order, writeable) and points of two
#: dimensions: its compiled entry point once known (:func:`_resolving_pyramid`), else a call that finds it
_PYRAMID_STD: list = [None]
#: the last (weak references to the level 0, 1, 2 caches, callable) of :func:`match_fit_at` (:func:`_pyramid_callable`):
#: weak, so that a map's caches (a loop closure's submap, a grown level's old arrays) are freed when their map lets
#: them go, not kept until the next match (≈ 3 MiB more at MIT CSAIL's peak with strong references)
_PYRAMID_LAST: list = [_dead_ref, _dead_ref, _dead_ref, None]
_U32 = np.dtype(np.uint32)


def _usual_cache(p: np.ndarray) -> bool:
    """``p`` is a probability cache of the type :data:`_PYRAMID_STD`'s entry point was compiled for."""
    if type(p) is not np.ndarray or p.dtype is not _U32 or p.ndim != 2:
        return False
    flags = p.flags
    return flags.c_contiguous and flags.writeable and flags.aligned


def _pyramid_callable(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, pts_m: np.ndarray):  # noqa: ANN202
    """The callable of :func:`match_pyramid` for these caches (levels 0–2) and points, kept for the next call with the
    same three arrays: its compiled entry point when every cache is of the usual type and ``pts_m`` (float64, C
    order: the caller's test) has two dimensions, else numba's dispatcher. The entry point skips the dispatcher's
    type resolution of the 29 arguments (≈ 0.7 µs a call, pass mat146); the types it trusts are the caches' (tested
    here, and an array's dtype, dimensions and layout never change), the points' and those of the arrays and numbers
    :func:`match_fit_at` makes itself. An array does not change its type, so the same objects need no new test."""
    usual = pts_m.ndim == 2 and _usual_cache(p0) and _usual_cache(p1) and _usual_cache(p2)
    call = (_PYRAMID_STD[0] or _resolving_pyramid) if usual else match_pyramid
    _PYRAMID_LAST[:] = (weakref.ref(p0), weakref.ref(p1), weakref.ref(p2), call)
    return call


#: the Python types of :func:`match_pyramid`'s arguments as :func:`match_fit_at` passes them: a = ndarray, f = float,
#: i = int, b = bool (the signature :data:`_PYRAMID_STD` is taken for)
_PYRAMID_KINDS = "aaaaafffiibbffffbfffabfaaffff"
_KIND = {np.ndarray: "a", float: "f", int: "i", bool: "b"}


def _resolving_pyramid(*args):  # noqa: ANN002, ANN202
    """:func:`match_pyramid` through numba's dispatcher (which compiles or loads it); then, if the arguments are of
    the usual Python types (:data:`_PYRAMID_KINDS`), its entry point for their numba types made :data:`_PYRAMID_STD`
    (the dispatcher itself with the AOT kernels: no numba overloads). A number of another type later (an int where
    the entry takes a float64, a NumPy scalar) is converted by the entry point's unboxing to the same value the
    dispatcher's own specialisation would compute with."""
    got = match_pyramid(*args)
    if "".join([_KIND.get(type(a), "?") for a in args]) != _PYRAMID_KINDS:
        return got
    overloads = getattr(match_pyramid, "overloads", None)
    entry = match_pyramid
    if overloads is not None:
        cres = overloads.get(tuple(match_pyramid.typeof_pyval(a) for a in args))
        candidate = getattr(cres, "entry_point", None)
        if type(candidate) is _BUILTIN:  # (the machine code's wrapper, not a stand-in kept for linking)
            entry = candidate
    _PYRAMID_STD[0] = entry
    if _PYRAMID_LAST[3] is _resolving_pyramid:
        _PYRAMID_LAST[3] = entry
    return got


_BUILTIN = type(len)


def _match_levels(levels: list[GridLevel], pts_m: np.ndarray, start_world: np.ndarray, iterations_coarse: int,
                  iterations_finest: int, swapped: bool, use_lm: bool, lam0: float, lam_max: float, max_rot: float,
                  max_trans_cells: float, prior_world: np.ndarray | None, prior_info: np.ndarray | None
                  ) -> np.ndarray:
    """:func:`match_multires`' pose by one :func:`match_level` call per level (any number of levels, any point
    array; no evaluation); a copy of the start for no points."""
    # (a float64 array's copy: np.array's values, C order, without its dtype conversion machinery)
    pose = start_world.copy() if type(start_world) is np.ndarray and start_world.dtype is _F64 else np.array(
        start_world, dtype=np.float64)
    if pts_m.shape[0] == 0:
        return pose
    use_prior = prior_world is not None and prior_info is not None and bool(np.any(prior_info))
    for k in range(len(levels) - 1, -1, -1):
        lv = levels[k]
        if lv.empty:
            continue
        n_iter = iterations_finest if k == 0 else iterations_coarse
        if n_iter <= 0:
            continue
        mp = lv.pose_to_map(pose)
        if use_prior:
            pp = lv.pose_to_map(np.asarray(prior_world, dtype=np.float64))
            pp[2] = mp[2] + (pp[2] - mp[2] + math.pi) % (2.0 * math.pi) - math.pi  # same branch as θ
            S = np.diag([lv.resolution, lv.resolution, 1.0])  # cells → m
            lam_k = S @ np.asarray(prior_info, dtype=np.float64) @ S
        else:
            pp, lam_k = mp, _ZERO3
        out, _ = match_level(
            lv.prob, pts_m / lv.resolution, mp, n_iter, swapped, use_lm, lam0, lam_max, max_rot, max_trans_cells,
            pp, lam_k,
        )
        if not (math.isfinite(out[0]) and math.isfinite(out[1]) and math.isfinite(out[2])):
            return np.full(3, np.nan)
        pose = lv.pose_to_world(out)
        pose[2] = (pose[2] + math.pi) % (2.0 * math.pi) - math.pi  # wrap after each level (§2.5)
    return pose


def free_fraction(level: GridLevel, pts_m: np.ndarray, pose_world: np.ndarray, thresh: float) -> float:
    """Fraction of laser-frame points ``pts_m`` that fall on cells of ``level`` whose interpolated
    occupancy probability is below ``thresh`` at ``pose_world`` (0 on an empty level)."""
    if level.empty or pts_m.shape[0] == 0:
        return 0.0
    mp = level.pose_to_map(pose_world)
    return float(fraction_below(level.prob, pts_m / level.resolution, mp[0], mp[1], mp[2], thresh))


def covariance_world(hessian: np.ndarray, sigma2: float, resolution: float) -> np.ndarray:
    """σ²·H⁻¹ converted from level-0 cell units to world units
    (Kohlbrecher et al., SSRR 2011 §IV: R = σ²·H⁻¹;
    the scaling of hector_mapping's getCovMatrixWorldCoords).

    A singular or indefinite H (empty map, degenerate corridor) is guarded by flooring its
    eigenvalues at 1e-9 of the largest, so the variance along a degenerate direction is large
    but finite. An all-zero H gives diag(1e6 m², 1e6 m², π² rad²).
    """
    Hs = 0.5 * (hessian + hessian.T)
    if not np.all(np.isfinite(Hs)):
        return np.diag([1e6, 1e6, math.pi**2])
    w, V = np.linalg.eigh(Hs)
    wmax = float(w.max())
    if not wmax > 0.0:
        return np.diag([1e6, 1e6, math.pi**2])
    wc = np.maximum(w, wmax * 1e-9)
    C = (V / wc) @ V.T * sigma2
    S = np.diag([resolution, resolution, 1.0])
    C = S @ C @ S
    return 0.5 * (C + C.T)


try:  # np.einsum without optimize calls this directly (the same result without the Python wrapper's dispatch)
    from numpy._core._multiarray_umath import c_einsum as _einsum
except ImportError:  # pragma: no cover - another NumPy layout
    _einsum = np.einsum

#: Width of the bearing bins of :func:`angular_spread` / :func:`support`, rad (5°).
SPREAD_BIN = math.radians(5.0)
_N_BINS = 72
#: the angle of one bin as the spread is computed (bins × this), rad (bit for bit 2π / 72, not math.radians(5))
BIN_ANGLE = 2.0 * math.pi / _N_BINS
#: Points evaluated by :func:`support` / :func:`angular_spread` (dense scans are subsampled).
_SUPPORT_POINTS = 240
#: Points :func:`angular_spread` looks at (it only has to tell a narrow view from a wide one).
_SPREAD_POINTS = 120


#: Coefficients of the odd polynomial for atan(z), 0 ≤ z ≤ 1, |error| ≤ 1e-5 rad (Abramowitz & Stegun,
#: Handbook of Mathematical Functions, 4.4.49; 1.15e-5 with these rounded coefficients, checked on a dense grid).
_ATAN_C1 = 0.9998660
_ATAN_C3 = -0.3302995
_ATAN_C5 = 0.1801410
_ATAN_C7 = -0.0851330
_ATAN_C9 = 0.0208351
#: A bin position (in bins) closer than this to a bin edge is recomputed with atan2: 1e-3 bins of 5° is
#: 8.7e-5 rad, over seven times the polynomial's error.
_BIN_EDGE_MARGIN = 1e-3


@njit(cache=True, inline="always")
def _bearing_pos(x, y, nb):  # pragma: no cover - numba
    """``(atan2(y, x) + π) / 2π · nb``, the bearing of (x, y) in bins, with the angle from a polynomial (|error| ≤
    1.15e-5 rad); NaN at the origin. Branch-free (selects; the one division's divisor is never zero), so that a
    loop of it vectorises (pass mat148: numba's Python error model tests a division's divisor for zero, which LLVM
    drops only when it can see the divisor is not zero). :func:`_bearing_bin`'s polynomial and operations;
    ``_bearing_bin`` keeps its own body: written with this and :func:`_bin_at` inlined, jitcache's lazy callee
    (``CALLEE_OPTIMISED_ONCE``) left dynamic globals in its unoptimised module and numba no longer cached it."""
    ax = abs(x)
    ay = abs(y)
    ge = ax >= ay
    lo = ay if ge else ax
    hi = ax if ge else ay  # (z = ay / ax when ax ≥ ay, else ax / ay: the same division)
    z = lo / (hi if hi > 0.0 else 1.0)
    z2 = z * z
    a = z * (_ATAN_C1 + z2 * (_ATAN_C3 + z2 * (_ATAN_C5 + z2 * (_ATAN_C7 + z2 * _ATAN_C9))))
    a = 0.5 * math.pi - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    a = -a if y < 0.0 else a
    t = (a + math.pi) / (2.0 * math.pi) * nb
    return t if hi > 0.0 else math.nan


@njit(cache=True, inline="always")
def _bin_at(t, x, y, nb):  # pragma: no cover - numba
    """The bearing bin of (x, y) from its :func:`_bearing_pos` ``t``: ``floor(t)`` away from a bin edge, else (within
    ``_BIN_EDGE_MARGIN`` of one, or ``t`` NaN) ``int(floor((atan2(y, x) + π) / 2π · nb)) % nb``."""
    f = t - math.floor(t)
    if f >= _BIN_EDGE_MARGIN and f <= 1.0 - _BIN_EDGE_MARGIN:
        # (a is in [−π, π], so t in [0, nb] and, away from a bin edge, floor(t) in [0, nb − 1]: ``% nb`` would
        # leave it as it is — without it, no integer division a point)
        return int(math.floor(t))
    return int(math.floor((math.atan2(y, x) + math.pi) / (2.0 * math.pi) * nb)) % nb


@njit(cache=True)
def _bearing_bin(x, y, nb):  # pragma: no cover - numba
    """``int(floor((atan2(y, x) + π) / 2π · nb)) % nb``, the bearing bin of (x, y) — the same integer: the
    angle from a polynomial, and ``atan2`` itself when that lands within ``_BIN_EDGE_MARGIN`` of a bin edge
    (or at the origin / on a non-finite point)."""
    two_pi = 2.0 * math.pi
    ax = abs(x)
    ay = abs(y)
    if ax >= ay:
        z = ay / ax if ax > 0.0 else math.nan
    else:
        z = ax / ay
    z2 = z * z
    a = z * (_ATAN_C1 + z2 * (_ATAN_C3 + z2 * (_ATAN_C5 + z2 * (_ATAN_C7 + z2 * _ATAN_C9))))
    if ay > ax:
        a = 0.5 * math.pi - a
    if x < 0.0:
        a = math.pi - a
    if y < 0.0:
        a = -a
    t = (a + math.pi) / two_pi * nb
    f = t - math.floor(t)
    if f >= _BIN_EDGE_MARGIN and f <= 1.0 - _BIN_EDGE_MARGIN:
        # (a is in [−π, π], so t in [0, nb] and, away from a bin edge, floor(t) in [0, nb − 1]: ``% nb`` would
        # leave it as it is — without it, no integer division a point)
        return int(math.floor(t))
    return int(math.floor((math.atan2(y, x) + math.pi) / two_pi * nb)) % nb


@njit(cache=True)
def _spread_kernel(pts, use, nb):  # pragma: no cover - numba
    """Number of the ``nb`` bearing bins holding a point of ``pts`` (rows with ``use``)."""
    seen = np.empty(nb, dtype=np.bool_)
    seen[:] = False
    k = 0
    for i in range(pts.shape[0]):
        if not use[i]:
            continue
        b = _bearing_bin(pts[i, 0], pts[i, 1], nb)
        if not seen[b]:
            seen[b] = True
            k += 1
    return k


@njit(cache=True, inline="always")
def _support_kernel(prob, pts_m, stride, inv_res, x, y, th, thresh, nb):  # pragma: no cover - numba
    """Over every ``stride``-th laser-frame point (m): count those whose interpolated probability at
    map pose (x cells, y cells, θ) exceeds ``thresh``; return (count, bearing bins they occupy).

    In :func:`_sums`' blocks (pass mat148; one scalar loop with two branches a point before): per block of
    ``_BLOCK`` points a branch-free loop (vectorised) gives each point's cell, fractions, in-bounds flag (the
    operations of :func:`~dynslam2d.slam.interp.interp_value_grad`'s value and inside test) and bearing position
    (:func:`_bearing_pos`), a scalar loop reads the four cells, and a last loop counts the inside points above
    ``thresh`` and marks their bins (:func:`_bin_at`)."""
    c = math.cos(th)
    s = math.sin(th)
    seen = np.empty(nb, dtype=np.bool_)
    seen[:] = False
    n = 0
    k = 0
    h, w = prob.shape
    if w < 2 or h < 2:  # (no point can be inside)
        return n, k
    flat = np.ascontiguousarray(prob).reshape(-1)  # (a view of the level's C-contiguous cache)
    xmax = w - 2
    ymax = h - 2
    uw = np.uint64(w)
    npt = (pts_m.shape[0] + stride - 1) // stride  # (the points of range(0, n, stride))
    fb = _stack_array(np.float64, 4, _BLOCK)
    qb = _stack_array(np.float32, 4, _BLOCK)
    kb = _stack_array(np.uint64, 1, _BLOCK)[0]
    ust = np.uint64(stride)
    for b0 in range(0, npt, _BLOCK):
        m = min(_BLOCK, npt - b0)
        for j in range(m):
            ui = np.uint64(b0 + j) * ust  # (unsigned: no negative-index select, so the loop vectorises)
            ex = pts_m[ui, 0]
            ey = pts_m[ui, 1]
            sx = ex * inv_res
            sy = ey * inv_res
            fb[0, j], fb[1, j], kb[j], fb[2, j] = _cell_of(sx, sy, c, s, x, y, xmax, ymax, w)
            fb[3, j] = _bearing_pos(ex, ey, nb)
        for j in range(m):
            kk = kb[j]
            qb[0, j], qb[1, j] = cell_prob_pair(flat, kk)  # (each row's two cells from one 8-byte load)
            qb[2, j], qb[3, j] = cell_prob_pair(flat, kk + uw)
        for j in range(m):
            fx = fb[0, j]
            fy = fb[1, j]
            mv = (1.0 - fy) * ((1.0 - fx) * qb[0, j] + fx * qb[1, j]) + fy * ((1.0 - fx) * qb[2, j] + fx * qb[3, j])
            if fb[2, j] != 0.0 and mv > thresh:
                n += 1
                i = (b0 + j) * stride
                b = _bin_at(fb[3, j], pts_m[i, 0], pts_m[i, 1], nb)
                if not seen[b]:
                    seen[b] = True
                    k += 1
    return n, k


@njit(cache=True)
def close_count(ranges, lo, hi, min_dist):  # pragma: no cover - numba
    """(valid returns, valid returns ≤ ``min_dist``) of a range array; valid = finite, in [lo, hi] (m)."""
    n = 0
    k = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if math.isfinite(r) and r >= lo and r <= hi:
            n += 1
            if r <= min_dist:
                k += 1
    return n, k


def support(level: GridLevel, pts_m: np.ndarray, pose_world: np.ndarray, thresh: float) -> tuple[int, float]:
    """(count, angular spread in rad) of the laser-frame points ``pts_m`` (n, 2, m) that land on cells of
    ``level`` whose interpolated occupancy probability exceeds ``thresh`` at ``pose_world`` — the points
    the map confirms, and the angle (5° bins) their bearings cover. (0, 0) on an empty level.
    Dense scans are evaluated on every k-th point (at most about 240; the count is scaled back by k)."""
    if level.empty or pts_m.shape[0] == 0:
        return 0, 0.0
    stride = max(1, pts_m.shape[0] // _SUPPORT_POINTS)
    mp = level.pose_to_map(pose_world)
    n, bins = _support_kernel(level.prob, pts_m, stride, 1.0 / level.resolution, mp[0], mp[1], mp[2], thresh,
                              _N_BINS)
    return int(n) * stride, bins * (2.0 * math.pi / _N_BINS)


def support_at(level: GridLevel, pts_m: np.ndarray, x: float, y: float, theta: float,
               thresh: float) -> tuple[int, float]:
    """:func:`support` at the world pose (``x`` m, ``y`` m, ``theta`` rad) given as floats (no pose arrays: the
    map pose is :meth:`GridLevel.pose_to_map`'s arithmetic on floats, the same values)."""
    if level.empty or pts_m.shape[0] == 0:
        return 0, 0.0
    stride = max(1, pts_m.shape[0] // _SUPPORT_POINTS)
    r = level.resolution
    n, bins = _support_kernel(level.prob, pts_m, stride, 1.0 / r, float(x) / r - level.i0, float(y) / r - level.j0,
                              float(theta), thresh, _N_BINS)
    return int(n) * stride, bins * (2.0 * math.pi / _N_BINS)


def angular_spread(pts_m: np.ndarray) -> float:
    """Angular extent covered by the bearings of laser-frame points ``pts_m`` (n, 2), rad: the
    number of 5° bearing bins holding a point times the bin width (0 … 2π)."""
    if pts_m.shape[0] == 0:
        return 0.0
    sub = pts_m[:: max(1, pts_m.shape[0] // _SPREAD_POINTS)]  # ≥ 1.6 points per 5° bin of a dense full circle
    return _spread_kernel(sub, _all_true(sub.shape[0]), _N_BINS) * (2.0 * math.pi / _N_BINS)


#: a shared all-True mask for _spread_kernel (it only reads it; kept writeable: numba compiles a read-only
#: array type as another specialisation)
_ALL_TRUE = np.ones(2 * _SPREAD_POINTS + 2, dtype=np.bool_)


def _all_true(n: int) -> np.ndarray:
    """(n,) True (a view of a shared buffer, grown when too short; never written)."""
    global _ALL_TRUE
    if n > _ALL_TRUE.shape[0]:
        _ALL_TRUE = np.ones(n, dtype=np.bool_)
    return _ALL_TRUE[:n]


#: a shared all-False mask: :func:`gated_points`' ``drop`` of a scan that drops nothing (one specialisation of the
#: kernel for every caller; writeable as ``_ALL_TRUE``)
_NO_DROP = np.zeros(2048, dtype=np.bool_)


#: n → ``no_drop(n)``'s view, made once per beam count (a scan source has one or two; the views stay all False)
_NO_DROP_VIEWS: dict[int, np.ndarray] = {}


def no_drop(n: int) -> np.ndarray:
    """(n,) False (a view of a shared buffer, grown when too short; never written): :func:`gated_points`' ``drop``
    when no beam is dropped."""
    v = _NO_DROP_VIEWS.get(n)
    if v is not None:
        return v
    global _NO_DROP
    if n > _NO_DROP.shape[0]:
        _NO_DROP = np.zeros(n, dtype=np.bool_)
    v = _NO_DROP[:n]
    if len(_NO_DROP_VIEWS) < 64:
        _NO_DROP_VIEWS[n] = v
    return v


#: points per block of numpy's einsum sum over an (n, 2) float64 array (its iterator's buffer: 8192 elements)
_EINSUM_BLOCK = 4096


@njit(cache=True)
def gated_points(r, cos_a, sin_a, valid, range_min, range_max, min_dist, max_dist, clear_dist,
                 stats, drop=None):  # pragma: no cover - numba
    """``HectorSlam.scan_points`` of ranges ``r`` (m) with beam (cos, sin) ``cos_a``, ``sin_a`` and ``valid``
    returns (finite, within the sensor's limits): (returns (n, 2), clearing-ray ends (m, 2), n_valid, n_close,
    spread bins) in the laser frame, m — the valid returns strictly inside (``min_dist``, ``max_dist``) at
    (r·cos, r·sin) (Scan.points), and, when ``clear_dist`` > 0, at ``clear_dist`` along every beam without a return
    (not finite, beyond ``range_max`` or at least ``max_dist``; not "too close"). ``clear_dist`` 0: the returns
    alone (the loop closer's keyframes).

    With ``stats`` also what the processor asks of every scan, from the same pass: :func:`close_count` of ``r``
    with (``range_min``, ``range_max``, ``min_dist``) as (n_valid, n_close), and the number of bearing bins
    :func:`angular_spread` finds on the returns (every ``max(1, n // _SPREAD_POINTS)``-th one), and the sum of the
    returns' squared coordinates as :func:`degeneracy` sums them (:func:`_sum_squares`); else 0, 0, 0, 0.0.

    ``drop`` (n,) bool: beams taken as having no return (range NaN) — the same outputs as for the ranges with NaN at
    those beams and ``valid`` False there (``Scan.without(drop)``), without the copy of the scan."""
    n = r.shape[0]
    m = 0
    k = 0
    n_valid = 0
    n_close = 0
    # one branch-free pass classifies every beam (1: a return kept as a point, 2: a clearing ray, 0: neither) and
    # counts; the second pass only reads the class (the same tests as before, each made once: the same outputs)
    kind = np.empty(n, dtype=np.uint8)
    clearing = clear_dist > 0.0
    for i in range(n):
        ri = r[i]
        if drop is not None:
            ri = math.nan if drop[i] else ri
        fin = math.isfinite(ri)
        if stats:
            v = fin & (ri >= range_min) & (ri <= range_max)
            n_valid += 1 if v else 0
            n_close += 1 if v & (ri <= min_dist) else 0
        p = valid[i] & (ri > min_dist) & (ri < max_dist)
        q = (not p) & clearing & ((not fin) | (ri > range_max) | (ri >= max_dist))
        m += 1 if p else 0
        k += 1 if q else 0
        kind[i] = 1 if p else (2 if q else 0)
    pts = np.empty((m, 2))
    clear = np.empty((k, 2))
    m = 0
    k = 0
    for i in range(n):
        c = kind[i]
        if c == 1:
            ri = r[i]  # (a dropped beam is never a point: its range is read as it is)
            pts[m, 0] = ri * cos_a[i]
            pts[m, 1] = ri * sin_a[i]
            m += 1
        elif c == 2:
            clear[k, 0] = clear_dist * cos_a[i]
            clear[k, 1] = clear_dist * sin_a[i]
            k += 1
    bins = 0
    if stats and m > 0:
        seen = np.empty(_N_BINS, dtype=np.bool_)
        seen[:] = False
        for i in range(0, m, max(1, m // _SPREAD_POINTS)):
            b = _bearing_bin(pts[i, 0], pts[i, 1], seen.shape[0])  # (_N_BINS as an int64, not a literal:
            # the signature _support_kernel compiles, not a second one)
            if not seen[b]:
                seen[b] = True
                bins += 1
    sumsq = _sum_squares(pts) if stats else 0.0
    return pts, clear, n_valid, n_close, bins, sumsq


@njit(cache=True, inline="always")
def _sum_squares(pts):  # pragma: no cover - numba
    """Σ x² + y² over the rows of ``pts`` (m, 2) float64, C-contiguous, in the order of NumPy's
    ``einsum("ij,ij->", pts, pts)`` (2.x, x86-64-v2 baseline: no FMA), so the same bits: the flattened values
    summed in two lanes (x and y), four rows a step with the last row added first, the rest row by row, the lanes
    added at the end; blocks of ``_EINSUM_BLOCK`` rows (the iterator's buffer) summed that way each, and the block
    sums added in order to 0.0. (The sum of :func:`degeneracy`'s ρ, from the pass that makes the points.)"""
    m = pts.shape[0]
    out = 0.0
    s = 0
    while s < m:
        e = min(m, s + _EINSUM_BLOCK)
        l0 = 0.0
        l1 = 0.0
        p = s
        while p < e:
            # rows p … p + 3 of a full group of four are added last row first, the rest in order
            q = p + 3 if e - p >= 4 else p
            step = -1 if e - p >= 4 else 1
            for _ in range(4 if e - p >= 4 else e - p):
                l0 = pts[q, 0] * pts[q, 0] + l0
                l1 = pts[q, 1] * pts[q, 1] + l1
                q += step
            p += 4 if e - p >= 4 else e - p
        out = out + (l0 + l1)
        s = e
    return out


@dataclass(slots=True)
class Degeneracy:
    """Degeneracy analysis of a match Hessian (after Zhang, Kaess & Singh 2016, "On degeneracy of
    optimization-based state estimation problems", ICRA: the eigenvectors of the information
    matrix with small eigenvalues are the directions the measurement cannot constrain).

    Translation and rotation have different units, so they are analysed separately, each with the
    other marginalized out (Schur complement): the translational block's eigenvectors give the
    degenerate translation direction (a corridor's axis); the rotational information, scaled by
    the RMS point range ρ² (a rotation δθ moves the points by about ρ·δθ), is compared with the
    largest translational eigenvalue.

    Attributes:
        ratio: smallest normalized eigenvalue / largest (0 … 1; 0 = a direction the scan cannot
            see at all): min of the translational ratio and the rotational one.
        translation_ratio: smallest / largest eigenvalue of the translational Schur complement.
        rotation_ratio: rotational Schur complement · ρ⁻² / largest translational eigenvalue.
        axis: (2,) unit vector (map frame) of the weakest translation direction.
        scale: ρ, m.
        lam_max: largest translational eigenvalue, 1/m² (probability² per m²).
        translation_degenerate, rotation_degenerate: below the threshold given.
    """

    ratio: float
    translation_ratio: float
    rotation_ratio: float
    axis: np.ndarray
    scale: float
    lam_max: float
    translation_degenerate: bool
    rotation_degenerate: bool

    @property
    def any(self) -> bool:
        return self.translation_degenerate or self.rotation_degenerate

    def prior_information(self, weight: float, axes: np.ndarray | None = None) -> np.ndarray:
        """(3, 3) prior information in world units (1/m², 1/(m·rad), 1/rad²) that acts only along
        the degenerate directions, with stiffness ``weight`` × the largest translational eigenvalue.

        ``axes`` (3,) bool: the pose components the prior knows (x, y, θ); e.g. only θ for an IMU.
        """
        lam = weight * self.lam_max
        info = np.zeros((3, 3))
        if not lam > 0.0:
            return info
        known = np.ones(3, dtype=bool) if axes is None else np.asarray(axes, dtype=bool)
        if self.translation_degenerate and known[0] and known[1]:
            u = np.array([self.axis[0], self.axis[1], 0.0])
            info += lam * np.outer(u, u)
        if self.rotation_degenerate and known[2]:
            info[2, 2] += lam * self.scale**2
        return info


def degeneracy(hessian_cells: np.ndarray, resolution: float, pts_m: np.ndarray, threshold: float,
               sumsq: float | None = None) -> Degeneracy:
    """Degeneracy analysis of the level-0 Gauss–Newton Hessian ``hessian_cells`` (cells / rad units,
    cell side ``resolution`` m) for laser-frame points ``pts_m`` (n, 2, m); a direction is
    degenerate when its normalized eigenvalue is below ``threshold`` × the largest. ``sumsq``: Σ x² + y² of
    ``pts_m``, m², as :func:`gated_points` returns it with the points (else summed here: the same value).

    Closed-form 2×2 / scalar algebra (it runs on every scan): :func:`degeneracy_values` as a :class:`Degeneracy`."""
    ratio, t_ratio, r_ratio, ax, ay, rho, lam_max, t_deg, r_deg = degeneracy_values(
        hessian_cells, resolution, pts_m, threshold, sumsq)
    return Degeneracy(ratio, t_ratio, r_ratio, np.array([ax, ay]), rho, lam_max, t_deg, r_deg)


def unit_axis(ax: float, ay: float) -> tuple[float, float]:
    """(ax, ay) divided by its length ((1, 0) for a zero vector): :func:`degeneracy_values`' weakest axis."""
    nrm = math.hypot(ax, ay)
    if nrm > 0.0:
        return ax / nrm, ay / nrm
    return 1.0, 0.0


def degeneracy_values(hessian_cells: np.ndarray, resolution: float, pts_m: np.ndarray, threshold: float,
                      sumsq: float | None = None) -> tuple[float, float, float, float, float, float, float, bool, bool]:
    """:func:`degeneracy`'s fields as a tuple, the axis as its two floats: (ratio, translation_ratio, rotation_ratio,
    axis x, axis y, scale m, lam_max 1/m², translation_degenerate, rotation_degenerate) — the same values without the
    record and the axis array (the processor builds them only when a prior needs the axis)."""
    n = pts_m.shape[0]
    if sumsq is None:
        sumsq = float(_einsum("ij,ij->", pts_m, pts_m))
    (h00, h01, h02), (h10, h11, h12), (h20, h21, h22) = hessian_cells.tolist()
    ratio, t_ratio, r_ratio, ax, ay, rho, lam_max, t_deg, r_deg = _degeneracy_math(
        h00, h01, h02, h10, h11, h12, h20, h21, h22, resolution, n, sumsq, threshold, 2.0)
    ax, ay = unit_axis(ax, ay)
    return ratio, t_ratio, r_ratio, ax, ay, rho, lam_max, t_deg, r_deg
