"""Scan integration into one log-odds grid level: Bresenham rays (numba).

Implements hector_mapping's ``OccGridMapBase::updateByScan`` / ``bresenham2D`` exactly:

* the integer Bresenham variant of the reference (major axis = larger |Δ|, ties to x,
  error starts at |Δa|/2, the start cell and every intermediate cell are free, the
  endpoint cell is not marked free);
* at most one free and one occupied update per cell per scan, occupied winning
  (a free update made earlier in the same scan is undone), via per-cell update indices;
* a hit is added only while the log-odds is below the cap; the free side is unbounded.

Grid arrays are indexed ``[row, col]`` = ``[y, x]`` in cell units of the level.
The probability cache (``prob``, uint32 words: a float32's bits XOR those of 0.5, slam/grid.py ``encode_probs``)
is refreshed for every touched cell, so the matcher
never needs a full-map recomputation; its values come from :func:`_prob_fast`, which gives the bits of
``float32(1 / (1 + exp(−v)))`` or asks for that plain form where it cannot guarantee them.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.jitbox import njit, numba_import  # numba's njit (or the AOT kernels'), numba's names

_lir, _nbtypes, cgutils, _intrinsic = numba_import(
    "llvmlite.ir", "numba.types", "numba.core.cgutils", "numba.extending.intrinsic")

#: placeholders of the inputs :func:`_rays` does not use on a call (its other way of giving the rays)
_NO_ENDS = np.zeros((2, 0))
_NO_CELLS = np.zeros(0, dtype=np.int64)
_NO_STOP = np.zeros(0)


@_intrinsic
def _bits(typingctx, v):
    """The IEEE-754 bits of a float64 as an int64 (a bit cast, no conversion)."""
    sig = _nbtypes.int64(_nbtypes.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], _lir.IntType(64))

    return sig, codegen


#: the walk computes a ray's minor-axis offsets with the multiply-shift below while its major length is less than
#: this (exact there; longer rays divide)
_MAGIC_MAX = 1 << 13
_MAGIC_SHIFT = 42
#: how many steps ahead of a walked cell the walk prefetches the cells' lines (up to the ray's end cell)
_PREFETCH = 32
#: updated cells a level's walks collect before their probabilities are written (:func:`_write_probs`; plus one
#: ray's cells at most)
_PROB_BATCH = 1024


@_intrinsic
def _prob_word(typingctx, p):
    """The probability cache's word of float32 ``p``: its bits XOR those of 0.5 (slam/grid.py ``encode_probs``)."""
    sig = _nbtypes.uint32(_nbtypes.float32)

    def codegen(context, builder, signature, args):
        i32 = _lir.IntType(32)
        return builder.xor(builder.bitcast(args[0], i32), i32(0x3F000000))

    return sig, codegen


@_intrinsic
def _from_bits(typingctx, v):
    """The float64 whose IEEE-754 bits are the int64 ``v`` (a bit cast, no conversion)."""
    sig = _nbtypes.float64(_nbtypes.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], _lir.DoubleType())

    return sig, codegen


@_intrinsic
def _fdiv(typingctx, a, b):
    """``a / b`` for float64 (IEEE division, no zero-divisor test: lets LLVM vectorise a loop holding it)."""
    sig = _nbtypes.float64(_nbtypes.float64, _nbtypes.float64)

    def codegen(context, builder, signature, args):
        return builder.fdiv(args[0], args[1])

    return sig, codegen


@_intrinsic
def _fma(typingctx, a, b, c):
    """``a · b + c`` for float64 with one rounding (LLVM's ``llvm.fma``)."""
    sig = _nbtypes.float64(_nbtypes.float64, _nbtypes.float64, _nbtypes.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


#: :func:`_prob_fast`: log2(e); 1.5 · 2^52 (adding it rounds a float64 below 2^51 to an integer) and its bits;
#: the Taylor coefficients ln(2)^i / i! of 2^r, i = 0 … 9; the relative half-width of the interval that holds both
#: the fast and the plain form's float64 value (2^−34 ≈ 5.8e-11, > 5 × the fast form's error bound)
_LOG2E = 1.4426950408889634
_ROUND = 6755399441055744.0
_ROUND_BITS = 4843621399236968448
_E0 = 1.0
_E1 = 0.6931471805599453
_E2 = 0.2402265069591007
_E3 = 0.055504108664821576
_E4 = 0.009618129107628477
_E5 = 0.0013333558146428441
_E6 = 0.00015403530393381606
_E7 = 1.5252733804059838e-05
_E8 = 1.3215486790144305e-06
_E9 = 1.0178086009239696e-07
_HALF_WIDTH = 2.0**-34
#: beyond this |log-odds| :func:`_prob_fast` gives NaN (2^k below stays a normal float64)
_FAST_MAX = 700.0


@_intrinsic
def _prefetch(typingctx, arr, idx):
    """Prefetch for writing the cache line of ``arr[idx]`` (1-D C array; LLVM's ``llvm.prefetch``, a hint that
    never faults, so ``idx`` may lie outside the array)."""
    sig = _nbtypes.void(arr, idx)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        i8p = _lir.IntType(8).as_pointer()
        i32 = _lir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, _lir.FunctionType(_lir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        ptr = builder.bitcast(builder.gep(ary.data, [args[1]]), i8p)
        builder.call(fn, [ptr, i32(1), i32(3), i32(1)])  # (write, keep in all cache levels, data)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, inline="always")
def _prob_fast(v):  # pragma: no cover - numba
    """The probability cache's value of float64 log-odds ``v``, float32(1 / (1 + exp(−v))) (hector_mapping
    GridMapLogOdds.h ``getGridProbability``: odds / (1 + odds), odds = exp(v)), with the bits of the plain form
    ``np.float32(1.0 / (1.0 + math.exp(-v)))`` — or NaN where it cannot guarantee them (≈ 0.1 % of values, and
    |v| > ``_FAST_MAX``): the caller then computes the plain form. Branch-free, so a loop of it vectorises.

    exp(−v) = 2^k · 2^r with y = −v · log2(e) rounded (absolute error ≤ 2.3e-13 for |v| ≤ 700, i.e. a relative
    error ≤ 1.6e-13 of exp), k = round(y), r = y − k ∈ [−½, ½] exact; 2^r = e^u, |u| = |r| ln 2 ≤ 0.347, by its
    Taylor polynomial of degree 9 in fused multiply-adds (remainder ≤ u^10 / 10! · e^|u| ≤ 9.8e-12 relative,
    roundings ≤ 3e-15); 2^k exact. So q = 1 / (1 + exp(−v)) computed from it is within 1.0e-11 (relative) of the
    true value, and the plain form's float64 value (libm's exp within 1 ulp, two roundings) within 5e-16: both lie
    in [q (1 − δ), q (1 + δ)], δ = ``_HALF_WIDTH``. Rounding to float32 is monotonic, so when both ends of that
    interval round to the same float32 the plain form rounds to it too. (``benchmarks/bench_ray_prob.py`` checks it
    against the plain form on every float32 in [−700, 700] and on the values the map's updates reach.)"""
    ok = abs(v) <= _FAST_MAX  # (False for NaN)
    y = (-v if ok else 0.0) * _LOG2E
    t = y + _ROUND
    r = y - (t - _ROUND)
    p = _fma(_E9, r, _E8)
    p = _fma(p, r, _E7)
    p = _fma(p, r, _E6)
    p = _fma(p, r, _E5)
    p = _fma(p, r, _E4)
    p = _fma(p, r, _E3)
    p = _fma(p, r, _E2)
    p = _fma(p, r, _E1)
    p = _fma(p, r, _E0)
    q = _fdiv(1.0, 1.0 + p * _from_bits((_bits(t) - _ROUND_BITS + 1023) << 52))  # (1 + 2^k · 2^r; |k| ≤ 1010)
    a = np.float32(q * (1.0 - _HALF_WIDTH))
    b = np.float32(q * (1.0 + _HALF_WIDTH))
    return a if ok & (a == b) else np.float32(np.nan)


@njit(cache=True, inline="always")
def _write_probs(pr, cells, vals, probs, n):  # pragma: no cover - numba
    """``pr[cells[i]] =`` the cache word (:func:`_prob_word`) of ``float32(1 / (1 + exp(−vals[i])))`` for
    i < ``n``, in that order (a cell listed twice keeps the later value): :func:`_prob_fast` in one vectorised loop
    into ``probs`` (float32 scratch, ≥ n), then the writes, with the plain form where it gave NaN. (Inlined:
    :func:`_rays` calls it at one place, which compiles ≈ 0.17 s less than a function of its own.)"""
    for i in range(n):
        probs[i] = _prob_fast(vals[i])
    for i in range(n):
        p = probs[i]
        if p != p:
            p = np.float32(1.0 / (1.0 + math.exp(-vals[i])))
        pr[cells[i]] = _prob_word(p)


@njit(cache=True)
def _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, ends, r, i0, j0, hit, stop, use_stop,
          l_free, l_occ, cap):  # pragma: no cover - numba
    """Rays from array cell (``sx``, ``sy``) into one level (arrays ``logodds``, ``prob``, ``uidx`` (H, W),
    C-contiguous): to cells (``ex[k]``, ``ey[k]``) or, when ``ends`` has columns, to the cells of the map-frame
    ends ``ends`` (2, n), m (``floor(v / r + 0.5)`` minus the offsets ``i0``, ``j0``: OccGridMapBase::updateByScan's
    rounding). ``hit[k]`` True: the start and intermediate cells free, the endpoint occupied; False: every cell
    free. With ``use_stop`` the last ``stop[k]`` cells of a ray (its endpoint included) get no free update.
    Rays with the start or end cell outside the array, or ending in the start cell, are skipped whole. Returns
    the number of rays integrated.

    Free update (OccGridMapBase::updateSetFree): at most one per cell per scan (update index ``free_idx``);
    occupied (updateSetOccupied): at most one, winning over this scan's free update, which it undoes first; a
    hit adds ``l_occ`` only while the log-odds is below ``cap`` (GridMapLogOdds.h); the probability cache is
    refreshed in every touched cell, from the float64 log-odds before its float32 store (:func:`_write_probs`).
    The cells are those of the reference's integer Bresenham walk
    (OccGridMapBase::bresenham2D: major axis = larger |Δ|, ties to x, error starting at |Δmajor|/2): after j steps
    along the major axis the walk has made ``(major // 2 + j·minor) // major`` minor steps, computed per cell with
    a multiply and a shift (exact below ``_MAGIC_MAX``, Granlund & Montgomery, PLDI 1994) instead of the error
    recurrence, so no step waits for the one before. The cell updates are written out
    in the loop (helpers taking the arrays, called per cell, were slower in every trial; docs/speed.md); the walks
    list each updated cell and its new log-odds, whose probabilities are written in one vectorised pass per
    ``_PROB_BATCH`` cells (:func:`_write_probs`, in the walks' order), and each walked cell prefetches the lines of
    the cell ``_PREFETCH`` steps on while that cell is on the ray (its end cell included; no lines beyond a ray's
    end are fetched, pass upd49). The free walk has no branch on whether a cell is new this scan (a cell already
    updated in this scan gets its own log-odds and update index written back and is not listed: the same values;
    the branch mispredicted where runs of new and seen cells alternate, pass upd48). The rays' end cells, which rays
    count and are walked, and each walked ray's lengths, steps and multiplier are computed in loops over all rays
    before the walks (the end cells vectorised), the walks after in the rays' order (docs/speed.md, pass map22)."""
    h, w = logodds.shape
    if sx < 0 or sy < 0 or sx >= w or sy >= h:
        return 0
    lo = logodds.reshape(h * w)  # (views: the arrays are C-contiguous)
    pr = prob.reshape(h * w)
    ui = uidx.reshape(h * w)
    from_ends = ends.shape[1] > 0
    n = ends.shape[1] if from_ends else ex.shape[0]
    f0 = sy * w + sx
    # the cells updated since the last _write_probs and their new log-odds (float64, before the float32 store)
    n_buf = _PROB_BATCH + max(h, w) + 1  # (a ray's cells: at most max(h, w))
    upd_f = np.empty(n_buf, dtype=np.uint64)
    upd_v = np.empty(n_buf)
    upd_p = np.empty(n_buf, dtype=np.float32)
    n_upd = 0
    # The rays' set-up in branch-free loops over all rays first (LLVM vectorises the end cells), the walks after,
    # in the rays' order (the same cells written in the same order as one loop doing both).
    # (1) the end cells
    cx = np.empty(n, dtype=np.int64)
    cy = np.empty(n, dtype=np.int64)
    if from_ends:
        e_x = ends[0]
        e_y = ends[1]
        for k in range(n):  # (OccGridMapBase::updateByScan's rounding)
            cx[k] = int(math.floor(e_x[k] / r + 0.5)) - i0
            cy[k] = int(math.floor(e_y[k] / r + 0.5)) - j0
    else:
        for k in range(n):
            cx[k] = ex[k]
            cy[k] = ey[k]
    # (2) which rays count and which are walked: a ray counts when its end cell is inside the array and not the
    # start cell; it is walked unless it repeats the ray before it (same start, end cell, kind and stop: the same
    # cells, which hold this scan's update indices after that ray — free_idx or occ_idx, and they only grow within a
    # scan — so walking it again would change nothing; whether it counts is the previous ray's answer too)
    walk = np.empty(n, dtype=np.int64)
    n_done = 0
    n_walk = 0
    for k in range(n):
        x1 = cx[k]
        y1 = cy[k]
        ok = ((x1 != sx) | (y1 != sy)) & (x1 >= 0) & (y1 >= 0) & (x1 < w) & (y1 < h)
        n_done += ok
        rep = False
        if k > 0:
            rep = (x1 == cx[k - 1]) & (y1 == cy[k - 1]) & (hit[k] == hit[k - 1])
            if use_stop:
                rep = rep & (stop[k] == stop[k - 1])
        walk[n_walk] = k
        n_walk += ok & (not rep)
    # (3) each walked ray's walk: major and minor lengths and steps (flat indices), free cells, multiplier
    setup = np.empty((7, n_walk), dtype=np.int64)
    for q in range(n_walk):
        k = walk[q]
        x1 = cx[k]
        y1 = cy[k]
        dx = x1 - sx
        dy = y1 - sy
        adx = abs(dx)
        ady = abs(dy)
        stx = 1 if dx > 0 else -1
        sty = w if dy > 0 else -w  # (a step along y in flat indices)
        xm = adx >= ady
        major = adx if xm else ady
        minor = ady if xm else adx
        skip = 0  # intermediate cell j major steps before the end lies j·L/major cells from it
        if use_stop and stop[k] > 1.0:
            skip = int((stop[k] - 1.0) * major / math.sqrt(float(dx * dx + dy * dy)))
            if skip > major - 1:
                skip = major - 1
        setup[0, q] = major
        setup[1, q] = minor
        setup[2, q] = stx if xm else sty
        setup[3, q] = sty if xm else stx
        # the start cell (j = 0), then the first major − 1 − skip intermediate cells of the walk: free
        setup[4, q] = major - skip
        setup[5, q] = ((1 << _MAGIC_SHIFT) + major - 1) // major  # ceil(2^42 / major)
        setup[6, q] = y1 * w + x1
    # (4) the walks, in the rays' order
    for q in range(n_walk + 1):
        if n_upd > _PROB_BATCH or q == n_walk:
            _write_probs(pr, upd_f, upd_v, upd_p, n_upd)
            n_upd = 0
            if q == n_walk:
                break
        k = walk[q]
        hk = hit[k]
        major = setup[0, q]
        minor = setup[1, q]
        d_major = setup[2, q]
        d_minor = setup[3, q]
        n_free = setup[4, q]
        c = major // 2
        if major < _MAGIC_MAX:
            magic = setup[5, q]
            t = c
            fb = f0
            # two runs of the same walk: the cells whose cell _PREFETCH steps on is still on the ray (the end cell,
            # step major, included) prefetch it, the last ones do not (no lines beyond the ray's end fetched)
            j_pf = min(n_free, max(major - _PREFETCH + 1, 0))
            j = 0
            for pf in (True, False):
                j_end = j_pf if pf else n_free
                for _ in range(j, j_end):
                    f = np.uint64(fb + ((t * magic) >> _MAGIC_SHIFT) * d_minor)  # (unsigned: no negative-index test)
                    if pf:
                        g = np.uint64(fb + _PREFETCH * d_major + (((t + _PREFETCH * minor) * magic) >> _MAGIC_SHIFT)
                                      * d_minor)
                        _prefetch(ui, g)
                        _prefetch(lo, g)
                        _prefetch(pr, g)
                    # branch-free: a cell seen already this scan (update index ≥ free_idx, so its lines were
                    # written this scan) gets its own log-odds and index written back, and its listing is overwritten
                    u = ui[f]
                    new = u < free_idx
                    o = lo[f]
                    v = o + l_free
                    lo[f] = v if new else o
                    ui[f] = free_idx if new else u
                    upd_f[n_upd] = f
                    upd_v[n_upd] = v
                    n_upd += new
                    t += minor
                    fb += d_major
                j = j_end
        else:
            t = c
            fb = f0
            for _ in range(n_free):
                f = np.uint64(fb + (t // major) * d_minor)
                if ui[f] < free_idx:
                    v = lo[f] + l_free
                    lo[f] = v
                    ui[f] = free_idx
                    upd_f[n_upd] = f
                    upd_v[n_upd] = v
                    n_upd += 1
                t += minor
                fb += d_major
        f = np.uint64(setup[6, q])
        u = ui[f]
        v = 0.0
        updated = False
        if hk:
            if u < occ_idx:
                v = lo[f]
                if u == free_idx:
                    v -= l_free
                if v < cap:
                    v += l_occ
                lo[f] = v
                ui[f] = occ_idx
                updated = True
        elif u < free_idx:
            v = lo[f] + l_free
            lo[f] = v
            ui[f] = free_idx
            updated = True
        if updated:
            upd_f[n_upd] = f
            upd_v[n_upd] = v
            n_upd += 1
    return n_done


@njit(cache=True)
def integrate_rays(
    logodds: np.ndarray,
    prob: np.ndarray,
    uidx: np.ndarray,
    free_idx: int,
    occ_idx: int,
    sx: int,
    sy: int,
    ex: np.ndarray,
    ey: np.ndarray,
    hit: np.ndarray,
    l_free: float,
    l_occ: float,
    cap: float,
) -> int:  # pragma: no cover - numba
    """Integrate rays from cell (sx, sy) to cells (ex[k], ey[k]) into one level.

    ``hit[k]`` True: a return (start + intermediate cells free, endpoint occupied);
    False: a free-space clearing ray (every cell including the endpoint free).
    Rays whose start or end cell lies outside the array are skipped whole
    (OccGridMapBase::updateByScan); rays ending in the start cell are skipped. Returns the
    number of rays integrated.
    """
    return _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, _NO_STOP,
                 False, l_free, l_occ, cap)


@njit(cache=True)
def bresenham_free_cells(x0: int, y0: int, x1: int, y1: int) -> np.ndarray:  # pragma: no cover - numba
    """(m, 2) int64 (x, y) cells the reference marks free on a ray from (x0, y0) to (x1, y1):
    the start cell and all intermediate cells, not the endpoint (OccGridMapBase::bresenham2D)."""
    dx = x1 - x0
    dy = y1 - y0
    adx = abs(dx)
    ady = abs(dy)
    n = max(adx, ady)
    out = np.empty((max(n, 1), 2), dtype=np.int64)
    if n == 0:
        return out[:0]
    stx = 1 if dx > 0 else -1
    sty = 1 if dy > 0 else -1
    x = x0
    y = y0
    out[0, 0] = x
    out[0, 1] = y
    if adx >= ady:
        err = adx // 2
        for i in range(adx - 1):
            x += stx
            err += ady
            if err >= adx:
                y += sty
                err -= adx
            out[i + 1, 0] = x
            out[i + 1, 1] = y
    else:
        err = ady // 2
        for i in range(ady - 1):
            y += sty
            err += adx
            if err >= ady:
                x += stx
                err -= ady
            out[i + 1, 0] = x
            out[i + 1, 1] = y
    return out


@njit(cache=True)
def integrate_rays_stop(
    logodds: np.ndarray,
    prob: np.ndarray,
    uidx: np.ndarray,
    free_idx: int,
    occ_idx: int,
    sx: int,
    sy: int,
    ex: np.ndarray,
    ey: np.ndarray,
    hit: np.ndarray,
    stop: np.ndarray,
    l_free: float,
    l_occ: float,
    cap: float,
) -> int:  # pragma: no cover - numba
    """:func:`integrate_rays` with a per-ray free-space stop: the intermediate cells of ray ``k`` that lie
    less than ``stop[k] − 1`` cells (along the ray) before its endpoint get no free update — the ray's last
    ``stop[k]`` cells, its endpoint cell included, which the reference never marks free. ``stop[k] ≤ 1``
    gives the reference's update exactly. (Where the stop comes from: ``MultiResMap.integrate``.)"""
    return _rays(logodds, prob, uidx, free_idx, occ_idx, sx, sy, ex, ey, _NO_ENDS, 1.0, 0, 0, hit, stop, True,
                 l_free, l_occ, cap)


@njit(cache=True)
def integrate_levels(hits, clear, c, s, x, y, logodds, prob, uidx, n_levels, res, i0, j0, counter, stop, use_stop,
                     max_bytes, l_free, l_occ, cap, bits, bits_thr):  # pragma: no cover - numba
    """One scan into every level in one call, when every level holds it already: the rays' ends in the map frame
    from the ``hits`` (n_hit, 2) then the ``clear`` (m, 2) ends (laser frame, m) moved by the pose (``x``, ``y``,
    cos ``c``, sin ``s``) as :func:`ray_ends` computes them, then per level ``k`` < ``n_levels`` (4-tuples
    ``logodds``, ``prob``, ``uidx``, cell side ``res`` m, array offsets ``i0``, ``j0``, update counter ``counter``
    before this scan) the rays from the pose's cell ``floor(x / r + 0.5)``, ``floor(y / r + 0.5)`` to the ends'
    cells (``floor(v / r + 0.5)``, OccGridMapBase::updateByScan's rounding, minus the offsets) by
    :func:`integrate_rays` (or :func:`integrate_rays_stop` with ``use_stop``) with the level's update indices
    ``counter + 1`` (free) and ``counter + 2`` (occupied). Returns the number of rays integrated on level 0, or −1,
    having written nothing, when ``MultiResMap.integrate`` must take its other way: a level's arrays do not hold
    the start cell and the cells of the ends' extremes (the level must grow: ``GridLevel._grown_bounds``), the
    three arrays of a level differ in shape, an end is not finite, or the levels hold more than ``max_bytes``
    (≥ 0; −1: no limit).

    ``bits`` (H, ⌈W / 64⌉) uint64: level 0's long-occupied bitmap (``GridLevel.occ_bits``; bit ``col & 63`` of word
    ``[row, col >> 6]``) for ``bits_thr`` (NaN, or a bitmap not of level 0's shape: none). After level 0's rays, the
    end cell of every hit (the only cells an occupied update raises; free updates add ``l_free`` ≤ 0) whose stored
    float32 log-odds, compared as float64, is ≥ ``bits_thr`` gets its bit set — in a loop of its own, not in
    :func:`_rays`' walks (their code stays as it was)."""
    ends, hit, box = ray_ends(hits, clear, c, s, x, y)
    if not (math.isfinite(box[0]) and math.isfinite(box[1]) and math.isfinite(box[2]) and math.isfinite(box[3])):
        return -1
    held = 0
    for k in range(n_levels):
        h, w = logodds[k].shape
        if h == 0 or w == 0 or prob[k].shape != (h, w) or uidx[k].shape != (h, w):
            return -1
        held += 12 * h * w  # (GridLevel.nbytes: float32 + float32 + int32 per cell)
        r = res[k]
        # every cell of the scan inside the array (GridLevel._grown_bounds gives None): the start cell and the
        # extreme ends' cells (v ↦ floor(v / r + 0.5) is monotonic), compared as floats (no int overflow)
        for v, a0, n in ((x, i0[k], w), (y, j0[k], h), (box[0], i0[k], w), (box[1], j0[k], h),
                         (box[2], i0[k], w), (box[3], j0[k], h)):
            cell = np.floor(v / r + 0.5)  # (a float: no conversion of a huge value)
            if cell < a0 or cell >= a0 + n:
                return -1
    if max_bytes >= 0 and held > max_bytes:
        return -1
    n0 = 0
    for k in range(n_levels):
        r = res[k]
        sx = int(math.floor(x / r + 0.5)) - i0[k]
        sy = int(math.floor(y / r + 0.5)) - j0[k]
        n_done = _rays(logodds[k], prob[k], uidx[k], counter[k] + 1, counter[k] + 2, sx, sy, _NO_CELLS,
                       _NO_CELLS, ends, r, i0[k], j0[k], hit, stop, use_stop, l_free, l_occ, cap)
        if k == 0:
            n0 = n_done
            h, w = logodds[0].shape
            if bits_thr == bits_thr and bits.shape[0] == h and bits.shape[1] == (w + 63) >> 6:
                lo = logodds[0]
                for q in range(hits.shape[0]):  # (the hits come first in ``ends``; _rays' rounding of their cells)
                    col = int(math.floor(ends[0, q] / r + 0.5)) - i0[0]
                    row = int(math.floor(ends[1, q] / r + 0.5)) - j0[0]
                    if 0 <= col < w and 0 <= row < h and lo[row, col] >= bits_thr:
                        bits[row, col >> 6] |= np.uint64(1) << np.uint64(col & 63)
    return n0


@njit(cache=True)
def ray_ends(hits, clear, c, s, x, y):  # pragma: no cover - numba
    """The ends of one scan's rays in the map frame: ((2, n) rows x and y of the ``hits`` (n_hit, 2) then the
    ``clear`` (m, 2) ends, laser frame, m, moved by the pose (``x``, ``y``, cos ``c``, sin ``s``) with the arithmetic
    of ``Pose2D.transform_points`` element by element; (n,) hit flags, True for the hits; [min x, min y, max x,
    max y] of the ends, NaN where a row holds a NaN, as numpy's ``min`` / ``max``)."""
    n_hit = hits.shape[0]
    n = n_hit + clear.shape[0]
    ends = np.empty((2, n))
    hit = np.empty(n, dtype=np.bool_)
    for k in range(n):
        if k < n_hit:
            px = hits[k, 0]
            py = hits[k, 1]
            hit[k] = True
        else:
            px = clear[k - n_hit, 0]
            py = clear[k - n_hit, 1]
            hit[k] = False
        ends[0, k] = c * px - s * py + x
        ends[1, k] = s * px + c * py + y
    box = np.empty(4)
    for r in range(2):
        lo = ends[r, 0]
        hi = lo
        for k in range(1, n):
            v = ends[r, k]
            if v != v:
                lo = v
                hi = v
                break
            if v < lo:
                lo = v
            if v > hi:
                hi = v
        box[r] = lo
        box[2 + r] = hi
    return ends, hit, box
