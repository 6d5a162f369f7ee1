"""numba kernels of the evidence ledger's per-update recording (slam/erasure.py, issue 9).

Each map update of the pipeline records, per track and map level, the cells the track's kept beams hit and the
log-odds the update added there. The pipeline does that work in two calls per update: :func:`record_cells` before
the map update (everything read before it) and :func:`level_rows` after it (the rows of every level), instead of
about a hundred small numpy calls. They are built from single-step kernels that compute exactly what the numpy code
they replaced computed (``tests/test_ledger_kernels.py`` checks them against it on random inputs,
``tests/test_ledger_fused.py`` the fused kernels against the single steps):

* :func:`beam_owners`: each beam's owner track (the last track listing it), from all tracks' beams in one array;
* :func:`kept_beams`: each track's kept beams (loop closure's record of what an erasure takes out);
* :func:`scan_cells`: the kept beams (valid, inside the laser's ranges, not removed), their map-frame points
  and owner tracks, and every point's (level, owner, cell) as one int64;
* :func:`unpack_cells`: from the sorted packed values, each distinct (level, owner > 0, cell) that no owner-0
  value shares (a cell another kept beam of the scan hits is the structure's), decoded to track id, cell key
  ``i·2^32 + j`` and cell (i, j), in (level, track, cell) order;
* :func:`read_cells`: log-odds and update index of cells (0 and 0 — never updated — outside the level's array)
  and their flat array indices (−1 outside);
* :func:`update_rows`: after the update, the rows (key, update index before, after, added log-odds' bits) of the
  cells the update changed, and the per-track groups of those rows;
* :func:`stand_marks`: the per-scan standing test of ``EvidenceLedger.observe`` over the tracker's state rows
  (pass led32; one specialisation, declared);
* :func:`record_cells` = beam_owners, the distinct track ids, scan_cells, a radix sort, unpack_cells, the reads of
  three levels and kept_beams; :func:`level_rows` = update_rows of three levels, re-reading by cell, the rows
  written in (track, level) order with their level as a fifth row.

Signatures: the two fused kernels declare theirs (one specialisation each, compiled or loaded from numba's cache
when the module is imported, with the single steps they call); the single steps are compiled at first use (the
level-by-level path of more than three levels or of cells beyond the packed range, and the tests), so a cold start
does not compile those the fused kernels do not call. Units: points in m (map frame), resolutions in m, cells
absolute level indices."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels_update import py_hypot
from dynslam2d.jitbox import float_bits, float_from_bits, njit, numba_import  # bit casts lowered in place

types = numba_import("numba.types")  # (an inert stand-in when the AOT kernels replace numba)

_KEY_SHIFT = 4294967296
#: packed values must stay below this (they are int64)
_LIMIT = 1 << 62
#: |v / r| at or beyond this cannot be a valid cell (keys hold |i|, |j| < 2^31): the caller's per-level path
_CELL_LIMIT = 2.0 ** 31


@njit(cache=True)
def _lower_bound(a, hi, v):  # pragma: no cover - numba
    """The first index in ``a[:hi]`` (sorted) whose value is not below ``v`` (``hi`` if none)."""
    lo = 0
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def beam_owners(n, beams, ends, ids):  # pragma: no cover - numba
    """(n,) int64: per beam of a scan of ``n`` beams, the id of the track that lists it (−1: none); track ``t``
    (id ``ids[t]``) lists ``beams[ends[t]:ends[t + 1]]`` (``ends`` (T + 1,), from 0). A beam two tracks list goes
    to the later one, as numpy's ``owner[beams_t] = ids[t]`` track after track; negative beams count from the end
    as numpy's indices do."""
    owner = np.empty(n, dtype=np.int64)
    for b in range(n):  # (element loops, not ``a[:] = v``: ≈ half its LLVM instructions to compile; pass cmp149)
        owner[b] = -1
    for t in range(ids.shape[0]):
        tid = ids[t]
        for e in range(ends[t], ends[t + 1]):
            b = beams[e]
            if b < 0:
                b += n
            if b < 0 or b >= n:
                raise IndexError("beam index out of the scan")
            owner[b] = tid
    return owner


@njit(cache=True, inline="always")
def kept_beams(valid, beams, ends):  # pragma: no cover - numba
    """(the beams ``b`` of ``beams`` with ``valid[b]``, as int32, in order; bounds (T + 1,) of each track's
    part of them) for tracks listing ``beams[ends[t]:ends[t + 1]]`` (``ends`` (T + 1,), from 0): numpy's
    ``beams[valid[beams]].astype(np.int32)`` and the cumulative counts of kept beams at ``ends``, negative beams
    counting from the end as numpy's indices do."""
    n = valid.shape[0]
    n_tr = ends.shape[0] - 1
    kb = np.empty(ends[n_tr], dtype=np.int32)
    bounds = np.empty(n_tr + 1, dtype=np.int64)
    j = 0
    for t in range(n_tr):
        bounds[t] = j
        for e in range(ends[t], ends[t + 1]):
            b = beams[e]
            i = b + n if b < 0 else b
            if i < 0 or i >= n:
                raise IndexError("beam index out of the scan")
            if valid[i]:
                kb[j] = b
                j += 1
    bounds[n_tr] = j
    return kb[:j], bounds


_I1 = types.int64[::1]
_F1 = types.float64[::1]
_F1_RO = types.Array(types.float64, 1, "C", readonly=True)  # Scan.trig's shared cos / sin


@njit(cache=True)
def scan_cells(r, cos_a, sin_a, vm, removed, owner, uids, rmin, rmax, c, s, px, py, rs):  # pragma: no cover
    """A scan's kept beams, their points' (level, owner, cell) packed: (packed (L·m,) int64 values
    ``level·block + owner·wi·wj + cx·wj + cy``, level by level, cells relative to each level's smallest cell
    (``floor(v / r + 0.5)`` as slam/grid.py); params [lox_0…, loy_0…, wi, wj, block]; the kept beams (n,) bool;
    the number of kept beams of each track (R,)). Kept: ``vm`` (the scan's valid mask), ``rmin < r < rmax`` and not
    ``removed``; ``owner``: each beam's track id (−1: none), ``uids``: the sorted ids of the tracks with beams
    (owner 1 + rank). Points in the map frame at pose (``px``, ``py``, cos ``c``, sin ``s``), computed as
    ``Pose2D.transform_points`` computes them. Packed values and params are empty when no kept beam has a
    track, or when the values would not fit in an int64 or a cell in a key (the caller then takes the per-level
    path)."""
    n = r.shape[0]
    n_tr = uids.shape[0]
    valid = np.empty(n, dtype=np.bool_)
    counts = np.empty(n_tr, dtype=np.int64)
    for t in range(n_tr):
        counts[t] = 0
    m = 0
    for b in range(n):
        rb = r[b]
        ok = vm[b] and rb > rmin and rb < rmax and not removed[b]
        valid[b] = ok
        if ok:
            m += 1
    xs = np.empty(m)
    ys = np.empty(m)
    rank = np.empty(m, dtype=np.int64)
    p = 0
    n_own = 0
    for b in range(n):
        if not valid[b]:
            continue
        lx = r[b] * cos_a[b]
        ly = r[b] * sin_a[b]
        xs[p] = c * lx - s * ly + px
        ys[p] = s * lx + c * ly + py
        rank[p] = 0
        o = owner[b]
        if o >= 0:
            lo = _lower_bound(uids, n_tr, o)
            rank[p] = lo + 1
            counts[lo] += 1
            n_own += 1
        p += 1
    empty = np.empty(0, dtype=np.int64)
    if n_own == 0:
        return empty, empty, valid, counts
    # every point's (level, owner, cell) as one int64 (owner 0 = no track, else 1 + rank)
    n_lv = rs.shape[0]
    x0 = xs[0]
    x1 = xs[0]
    y0 = ys[0]
    y1 = ys[0]
    for p in range(1, m):
        x = xs[p]
        y = ys[p]
        if x < x0:
            x0 = x
        if x > x1:
            x1 = x
        if y < y0:
            y0 = y
        if y > y1:
            y1 = y
    params = np.empty(2 * n_lv + 3, dtype=np.int64)
    wi = 0
    wj = 0
    for k in range(n_lv):
        res = rs[k]
        for v in (x0 / res, x1 / res, y0 / res, y1 / res):
            if not abs(v) < _CELL_LIMIT:
                return empty, empty, valid, counts
        # v ↦ floor(v / res + 0.5) is monotonic: the extreme points give each level's extreme cells
        cx0 = math.floor(x0 / res + 0.5)
        cy0 = math.floor(y0 / res + 0.5)
        params[k] = cx0
        params[n_lv + k] = cy0
        wi = max(wi, math.floor(x1 / res + 0.5) - cx0 + 1)
        wj = max(wj, math.floor(y1 / res + 0.5) - cy0 + 1)
    # n_lv · (n_tr + 1) · wi · wj < 2^62, tested factor by factor (p · f ≥ L ⇔ f > (L − 1) // p)
    prod = n_lv
    for f in (n_tr + 1, wi, wj):
        if f > (_LIMIT - 1) // prod:
            return empty, empty, valid, counts
        prod *= f
    wij = wi * wj
    block = (n_tr + 1) * wij
    params[2 * n_lv] = wi
    params[2 * n_lv + 1] = wj
    params[2 * n_lv + 2] = block
    packed = np.empty(n_lv * m, dtype=np.int64)
    for k in range(n_lv):
        res = rs[k]
        cx0 = params[k]
        cy0 = params[n_lv + k]
        base = k * block
        for p in range(m):
            cx = np.int64(math.floor(xs[p] / res + 0.5)) - cx0
            cy = np.int64(math.floor(ys[p] / res + 0.5)) - cy0
            packed[k * m + p] = cx * wj + cy + rank[p] * wij + base
    return packed, params, valid, counts


@njit(cache=True)
def unpack_cells(u, params, uids, n_lv):  # pragma: no cover - numba
    """(track ids, cell keys, (m, 2) cells, level bounds (L + 1,)) of the sorted packed values ``u`` of
    :func:`scan_cells` (``params``; ``uids``: the track ids by rank): each distinct value of an owner > 0 whose
    (level, cell) has no owner-0 value, in the values' order."""
    n = u.shape[0]
    n_tr = uids.shape[0]
    wi = params[2 * n_lv]
    wj = params[2 * n_lv + 1]
    block = params[2 * n_lv + 2]
    wij = wi * wj
    # one pass in the values' order: the (level, owner) group of a value follows from comparisons with its group's
    # end (the values are sorted), and each owner group's cells are matched against its level's owner-0 cells by
    # a merge (both ascending), not by a search and divisions per value
    ids = np.empty(n, dtype=np.int64)
    keys = np.empty(n, dtype=np.int64)
    cells = np.empty((n, 2), dtype=np.int64)
    bounds = np.empty(n_lv + 1, dtype=np.int64)
    for k in range(n_lv + 1):
        bounds[k] = 0
    lvl = 0
    own = 0
    base = 0  # lvl · block + own · wij: the group's smallest value
    z_lo = 0  # the level's owner-0 values: u[z_lo:z_hi]
    z_hi = 0
    zp = 0  # merge position in them
    m = 0
    for p in range(n):
        v = u[p]
        if p > 0 and v == u[p - 1]:
            continue
        while v >= base + wij:  # the next (level, owner) group
            own += 1
            if own > n_tr:
                lvl += 1
                own = 0
            base = lvl * block + own * wij
            if own == 0:
                z_lo = p
                z_hi = p
            zp = z_lo
        if own == 0:
            z_hi = p + 1
            continue
        q = v - own * wij  # the same level and cell with owner 0
        while zp < z_hi and u[zp] < q:
            zp += 1
        if zp < z_hi and u[zp] == q:
            continue
        cell = v - base
        ci = cell // wj
        ids[m] = uids[own - 1]
        keys[m] = (ci + params[lvl]) * _KEY_SHIFT + (cell - ci * wj + params[n_lv + lvl])
        cells[m, 0] = ci + params[lvl]
        cells[m, 1] = cell - ci * wj + params[n_lv + lvl]
        bounds[lvl + 1] += 1
        m += 1
    for k in range(n_lv):
        bounds[k + 1] += bounds[k]
    return ids[:m], keys[:m], cells[:m], bounds  # (views: a copy each is ≈ 110 more instructions to compile)


@njit(cache=True)
def read_cells(logodds, uidx, cells, i0, j0):  # pragma: no cover - numba
    """(log-odds (float64), update index (int64), flat index into the (H, W) arrays, number outside) of absolute
    ``cells`` (m, 2) on a level whose array starts at cell (``i0``, ``j0``); 0, 0 (never updated), −1 outside the
    array."""
    h, w = logodds.shape
    m = cells.shape[0]
    lo = np.empty(m)
    lo[:] = 0.0
    ui = np.empty(m, dtype=np.int64)
    ui[:] = 0
    f = np.empty(m, dtype=np.int64)
    f[:] = -1
    n_out = 0
    for t in range(m):
        col = cells[t, 0] - i0
        row = cells[t, 1] - j0
        if col >= 0 and row >= 0 and col < w and row < h:
            lo[t] = logodds[row, col]
            ui[t] = uidx[row, col]
            f[t] = row * w + col
        else:
            n_out += 1
    return lo, ui, f, n_out


@njit(cache=True)
def update_rows(logodds, uidx, f, ids, keys, before, ub):  # pragma: no cover - numba
    """After a map update: ((4, m) rows — cell key, update index before, update index after, the added log-odds'
    float64 bits — of the cells whose update index changed; the track id of each group of rows; the groups'
    bounds (g + 1,)), from the cells' flat indices ``f`` (−1: outside the array, read as log-odds 0 and index 0)
    and what :func:`read_cells` read before the update. ``ids`` is sorted, so each track's rows are one group."""
    w = logodds.shape[1]
    n = f.shape[0]
    delta = np.empty(n)
    ua = np.empty(n, dtype=np.int64)
    m = 0
    g = 0
    last = 0
    for t in range(n):
        ft = f[t]
        after = 0.0
        u = 0
        if ft >= 0:
            row = ft // w
            col = ft - row * w
            after = logodds[row, col]
            u = uidx[row, col]
        ua[t] = u
        delta[t] = after - before[t]
        if u != ub[t]:  # else not updated (outside the array, or the ray was skipped)
            if m == 0 or ids[t] != last:
                g += 1
                last = ids[t]
            m += 1
    bits = delta.view(np.int64)
    rows = np.empty((4, m), dtype=np.int64)
    gid = np.empty(g, dtype=np.int64)
    starts = np.empty(g + 1, dtype=np.int64)
    k = 0
    j = 0
    for t in range(n):
        if ua[t] == ub[t]:
            continue
        rows[0, j] = keys[t]
        rows[1, j] = ub[t]
        rows[2, j] = ua[t]
        rows[3, j] = bits[t]
        if j == 0 or ids[t] != gid[k - 1]:
            gid[k] = ids[t]
            starts[k] = j
            k += 1
        j += 1
    starts[g] = m
    return rows, gid, starts



#: levels the fused kernels take (3-tuples of level arrays, padded with empty ones; the map update's own kernel takes
#: four, slam/grid.py's ``_FUSED_LEVELS``)
FUSED_LEVELS = 3
_LO3 = types.UniTuple(types.float32[:, ::1], FUSED_LEVELS)
_UI3 = types.UniTuple(types.int32[:, ::1], FUSED_LEVELS)
_IT3 = types.UniTuple(types.int64, FUSED_LEVELS)


# (record_cells' first part is inlined into it, its second part written in it: as functions of their own the two
# parts cost ≈ 0.7–1 s more cold compile)
@njit(cache=True, inline="always")
def _track_points(beams, lens, ids, r, cos_a, sin_a, vm, removed, rmin, rmax, c, s, px, py, rs):  # pragma: no cover
    """:func:`beam_owners`, the tracks' distinct ids in ascending order and :func:`scan_cells` in one call: (packed
    values, params, kept beams (n,), kept beams per distinct track (R,), the distinct track ids ``uids`` (R,), the
    tracks' ends in ``beams`` (T + 1,), from 0) of a scan whose track ``t`` (id ``ids[t]``) lists the next
    ``lens[t]`` beams of ``beams``; the other arguments as :func:`scan_cells`. Each beam's owner is the last track
    listing it."""
    n_t = ids.shape[0]
    ends = np.empty(n_t + 1, dtype=np.int64)
    ends[0] = 0
    for t in range(n_t):
        ends[t + 1] = ends[t] + lens[t]
    owner = beam_owners(r.shape[0], beams, ends, ids)
    # the distinct ids, ascending (sorted(set(ids)); an insertion sort of a few dozen)
    u = np.empty(n_t, dtype=np.int64)
    m = 0
    for t in range(n_t):
        v = ids[t]
        p = m
        while p > 0 and u[p - 1] > v:
            p -= 1
        if p > 0 and u[p - 1] == v:
            continue
        for q in range(m, p, -1):
            u[q] = u[q - 1]
        u[p] = v
        m += 1
    uids = u[:m]
    packed, params, valid, counts = scan_cells(r, cos_a, sin_a, vm, removed, owner, uids, rmin, rmax, c, s, px, py,
                                               rs)
    return packed, params, valid, counts, uids, ends


@njit(cache=True, inline="always")
def _radix_sort(a):  # pragma: no cover - numba
    """Sort the non-negative int64 values ``a`` in place (least significant digit first, at most 11 bits a digit:
    a few passes over the values, where a comparison sort of the ≈ 2000 values of a scan takes more)."""
    n = a.shape[0]
    mx = 0
    for i in range(n):
        if a[i] > mx:
            mx = a[i]
    bits = 0
    while bits < 63 and (mx >> bits) > 0:
        bits += 1
    if bits == 0:
        return
    passes = (bits + 10) // 11
    width = (bits + passes - 1) // passes
    mask = (1 << width) - 1
    cnt = np.empty(1 << width, dtype=np.int64)
    src = a
    dst = np.empty(n, dtype=np.int64)
    for q in range(passes):
        sh = q * width
        for d in range(mask + 1):
            cnt[d] = 0
        for i in range(n):
            cnt[(src[i] >> sh) & mask] += 1
        tot = 0
        for d in range(mask + 1):
            k = cnt[d]
            cnt[d] = tot
            tot += k
        for i in range(n):
            v = src[i]
            d = (v >> sh) & mask
            dst[cnt[d]] = v
            cnt[d] += 1
        src, dst = dst, src
    if passes % 2:  # (the sorted values are in the scratch array; an element loop: a slice assignment compiles
        for i in range(n):  # numpy's broadcast checks and their error messages, seconds of a cold compile)
            a[i] = src[i]


_B1 = types.boolean[::1]
#: (status, the (6, m) cell block, the small int64 outputs, the kept beams): four outputs where pass ledger14's
#: version boxed fourteen (≈ 0.45 µs per boxed array warm, pass ledger15)
_RECORD_SIG = types.Tuple((types.int64, types.int64[:, ::1], _I1, types.int32[::1]))(
    _I1, _I1, _F1, _F1_RO, _F1_RO, _B1, types.boolean[:], *(types.float64,) * 6, _F1,
    _LO3, _UI3, _IT3, _IT3, types.boolean)
#: :func:`record_cells`' status: the cells are in the block; no kept beam of any track (nothing to record); the
#: values would not fit (the caller's level-by-level path)
PACKED, NO_KEPT, PLAIN = 0, 1, 2


@njit(_RECORD_SIG, cache=True)
def record_cells(beams, idl, r, cos_a, sin_a, vm, removed, rmin, rmax, c, s, px, py, rs, logodds, uidx, i0, j0,
                 want_kb):  # pragma: no cover - numba
    """Everything the evidence ledger reads before a map update, in one call: each beam's owner track
    (:func:`beam_owners`; ``idl`` (2T,): the T tracks' ids, then their numbers of beams — track ``t`` lists the next
    ``idl[T + t]`` of ``beams``), the kept beams' points packed (:func:`scan_cells`; levels of cell side ``rs``),
    sorted, decoded (:func:`unpack_cells`) and their cells read on the first ``min(L, 3)`` levels (``logodds``,
    ``uidx``, offsets ``i0``, ``j0``: 3-tuples, padded). Returns (status — :data:`PACKED`, or :data:`NO_KEPT` /
    :data:`PLAIN` with the other outputs empty; the cells as a (6, m) block of rows: track id, cell key, cell i,
    cell j, update index before (0 outside a level's array and on levels ≥ 3, which the caller reads) and the
    float64 bits of the log-odds before (0 there); ``small``: the level bounds (L + 1,), per track whether a kept
    beam of it is left (T,: 0 / 1) and, with ``want_kb``, the kept beams' per-track bounds (T + 1,); with
    ``want_kb`` the kept beams (:func:`kept_beams`), else empty)."""
    n_t = idl.shape[0] // 2
    ids = idl[:n_t]  # (read only: no copy)
    packed, params, valid, counts, uids, ends = _track_points(beams, idl[n_t:], ids, r, cos_a, sin_a, vm, removed,
                                                              rmin, rmax, c, s, px, py, rs)
    n_lv = rs.shape[0]
    if params.shape[0] == 0:
        # no kept beam of any track: every count 0 (counts are >= 0; a loop instead of ``counts.max() == 0``,
        # whose numba implementation (np.max with its take and comparator helpers) no other kernel of a run
        # compiles: about 0.5 s of cold compile CPU)
        status = NO_KEPT
        for k in range(counts.shape[0]):
            if counts[k] != 0:
                status = PLAIN
                break
        return (status, np.empty((6, 0), dtype=np.int64), np.empty(0, dtype=np.int64),
                np.empty(0, dtype=np.int32))
    # a value equal to the one before it goes (the sorted values' repeats are skipped by unpack_cells anyway):
    # neighbouring beams of a track hit the same cell, most of all on the coarse levels, so about two thirds of
    # the values of a negative_2 scan go before the sort (≈ 1850 → 650; pass led33). Branch-free: each value is
    # written after the kept ones and kept when it differs from the last kept one (there is at least one value:
    # params are non-empty only when a kept beam has a track)
    n_u = 1
    for p in range(1, packed.shape[0]):
        v = packed[p]
        packed[n_u] = v
        n_u += v != packed[n_u - 1]
    u = packed[:n_u]
    _radix_sort(u)
    # the cells (:func:`unpack_cells`) into the block, and their update index and log-odds before read on the first
    # min(L, 3) levels straight into its rows 4 and 5 (0 outside a level's array and on levels >= 3; written here,
    # not through arrays of their own copied in: less code to compile, pass cmp149)
    out_ids, keys, cells, bounds = unpack_cells(u, params, uids, n_lv)
    m = out_ids.shape[0]
    blk = np.empty((6, m), dtype=np.int64)
    for t in range(m):
        blk[0, t] = out_ids[t]
        blk[1, t] = keys[t]
        blk[2, t] = cells[t, 0]
        blk[3, t] = cells[t, 1]
        blk[4, t] = 0
        blk[5, t] = 0  # (the bits of 0.0)
    for k in range(min(n_lv, FUSED_LEVELS)):
        a = logodds[k]
        b = uidx[k]
        h, w = a.shape
        ci0 = i0[k]
        cj0 = j0[k]
        for t in range(bounds[k], bounds[k + 1]):
            col = cells[t, 0] - ci0
            row = cells[t, 1] - cj0
            if col >= 0 and row >= 0 and col < w and row < h:
                blk[4, t] = b[row, col]
                blk[5, t] = float_bits(np.float64(a[row, col]))  # (as lo.view(np.int64), without numba's view helper)
    if want_kb:
        kb, kb_b = kept_beams(valid, beams, ends)
    else:
        kb = np.empty(0, dtype=np.int32)
        kb_b = np.empty(0, dtype=np.int64)
    n_kb = kb_b.shape[0]
    n_r = uids.shape[0]
    small = np.empty(n_lv + 1 + n_t + n_kb, dtype=np.int64)
    for k in range(n_lv + 1):
        small[k] = bounds[k]
    for t in range(n_t):  # (whether a kept beam of track t is left: the count of its id's rank)
        small[n_lv + 1 + t] = 1 if counts[_lower_bound(uids, n_r, ids[t])] > 0 else 0
    for t in range(n_kb):
        small[n_lv + 1 + n_t + t] = kb_b[t]
    return PACKED, blk, small, kb


_ROWS_SIG = types.Tuple((types.int64[:, ::1], _I1, _I1, _I1))(
    _LO3, _UI3, _IT3, _IT3, types.int64, types.int64[:, ::1], _I1)


@njit(_ROWS_SIG, cache=True)
def level_rows(logodds, uidx, i0, j0, n_lv, blk, small):  # pragma: no cover - numba
    """:func:`update_rows` of every level (``n_lv`` ≤ 3) in one call, the cells re-read after the map update from
    the levels' current arrays and offsets (a level may have grown), the rows written in (track id, level) order:
    ((5, m) rows: key, update index before, after, added log-odds' bits and the row's level; per track with rows,
    in id order: its id (T,), its rows' column bounds (T + 1,: track ``t``'s rows are ``[b[t], b[t + 1])``, its
    levels' rows one after the other) and the levels it has rows on (T,: bit ``k`` for level ``k``)). A track's
    rows of one level are the rows :func:`update_rows` gives it on that level, in the same order. ``blk`` and
    ``small`` are what :func:`record_cells` returned (the cells of level ``k`` are columns ``small[k]:small[k + 1]``
    of ``blk``, sorted by track id within a level). (Pass ledger14: one column range per track, so that the ledger
    settles an update's rows of a track with one slice, slam/erasure.py ``_Ledger.settle``.)"""
    n = blk.shape[1]
    ids = blk[0]
    keys = blk[1]
    ub = blk[4]
    delta = np.empty(n)
    ua = np.empty(n, dtype=np.int64)
    # groups (a track's updated rows on one level), level by level, each level's in id order: id, the input
    # span [first updated row, after the last one) and the number of updated rows in it
    gid = np.empty(n, dtype=np.int64)
    g_a = np.empty(n, dtype=np.int64)
    g_b = np.empty(n, dtype=np.int64)
    g_n = np.empty(n, dtype=np.int64)
    lg = np.empty(n_lv + 1, dtype=np.int64)  # the groups of level k: lg[k]:lg[k + 1]
    g = 0
    for k in range(n_lv):
        a = logodds[k]
        b = uidx[k]
        h, w = a.shape
        ci0 = i0[k]
        cj0 = j0[k]
        lg[k] = g
        first = True
        for t in range(small[k], small[k + 1]):
            col = blk[2, t] - ci0
            row = blk[3, t] - cj0
            after = 0.0
            v = 0
            if col >= 0 and row >= 0 and col < w and row < h:
                after = a[row, col]
                v = b[row, col]
            ua[t] = v
            delta[t] = after - float_from_bits(blk[5, t])  # (the log-odds before, stored as its bits)
            if v != ub[t]:  # else not updated (outside the array, or the ray was skipped)
                if first or ids[t] != gid[g - 1]:
                    gid[g] = ids[t]
                    g_a[g] = t
                    g_n[g] = 0
                    g += 1
                    first = False
                g_b[g - 1] = t + 1
                g_n[g - 1] += 1
    lg[n_lv] = g
    # the groups in (track id, level) order (a merge of the levels' runs, each sorted by track id), their rows
    # written in that order; per track: id, column bounds, levels
    m = 0
    for q in range(g):
        m += g_n[q]
    rows = np.empty((5, m), dtype=np.int64)
    t_id = np.empty(g, dtype=np.int64)
    t_bnd = np.empty(g + 1, dtype=np.int64)
    t_lv = np.empty(g, dtype=np.int64)
    for q in range(g):
        t_lv[q] = 0
    pos = lg[:n_lv].copy()
    n_t = 0
    j = 0
    for _ in range(g):
        best = -1
        for k in range(n_lv):
            if pos[k] < lg[k + 1] and (best < 0 or gid[pos[k]] < gid[pos[best]]):
                best = k
        src = pos[best]
        pos[best] += 1
        if n_t == 0 or gid[src] != t_id[n_t - 1]:
            t_id[n_t] = gid[src]
            t_bnd[n_t] = j
            n_t += 1
        t_lv[n_t - 1] |= 1 << best
        for t in range(g_a[src], g_b[src]):
            if ua[t] == ub[t]:
                continue
            rows[0, j] = keys[t]
            rows[1, j] = ub[t]
            rows[2, j] = ua[t]
            rows[3, j] = float_bits(delta[t])
            rows[4, j] = best
            j += 1
    t_bnd[n_t] = m
    return rows, t_id[:n_t], t_bnd[:n_t + 1], t_lv[:n_t]


_F2 = types.float64[:, ::1]
#: :func:`stand_marks`' signature (one specialisation, compiled or loaded when the module is imported)
_STAND_SIG = _I1(_F2, _I1, _F2, _F2, _I1, _I1, _F2, _I1, types.int64, types.float64, types.float64, types.float64)


@njit(_STAND_SIG, cache=True)
def stand_marks(X, rows, B, E, ids, rm, F, mark, c, stamp, stand, reach):  # pragma: no cover - numba
    """``EvidenceLedger.observe``'s standing test of one scan's reports, in report order (slam/erasure.py).

    Report ``i`` (id ``ids[i]``) is at ``X[rows[i], 0:2]`` with velocity ``X[rows[i], 2:4]`` for ``i`` below
    ``rows``' length (the tracker's state rows: a live report's box centre and velocity are that row's values),
    else at ``E[i - len(rows), 0:2]`` with velocity ``E[…, 2:4]`` (m, m/s, map frame); its box's half longer side
    (m) is ``0.5 * max(l, w)`` of ``B[i, 3:5]`` (the live reports' boxes [p_x, p_y, θ, l, w], report order), else
    ``E[…, 4]``. The standing boxes are
    id-indexed: ``F[id]`` = (centre x, y, half size, stamp it began standing there, last stamp it stood there),
    valid when ``mark[id] >= c - 1`` (it was reported in the previous call, ``c - 1``, or earlier in this one).
    In the order of the reports: a report without a standing box gets one where it is (``F[id, 0:3]``, both
    stamps ``stamp``; the half size written here since pass obs114, the caller's before: the indices of those
    reports are returned); one
    not in the removal set ``rm`` (ids) that is slower than ``stand`` (m/s) stood there still (the last stamp
    set to ``stamp``) when its centre is within ``reach`` (m) of the box's, else starts standing where it is
    (as a new one). Speeds and distances are Python's ``math.hypot`` bit for bit (``kernels_update.py_hypot``).
    Every report's ``mark`` becomes ``c``. Returns the indices of the reports given a new box; ``[-1]`` for a
    negative id and ``[-1 - n]`` when ``F`` and ``mark`` need ``n`` rows (nothing is written then)."""
    n = ids.shape[0]
    nr = rows.shape[0]
    cap = mark.shape[0]
    hi = -1
    for i in range(n):
        if ids[i] < 0:
            out = np.empty(1, dtype=np.int64)
            out[0] = -1
            return out
        hi = max(hi, ids[i])
    if hi >= cap:
        out = np.empty(1, dtype=np.int64)
        out[0] = -2 - hi
        return out
    new = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        tid = ids[i]
        if i < nr:
            k = rows[i]
            x = X[k, 0]
            y = X[k, 1]
            vx = X[k, 2]
            vy = X[k, 3]
        else:
            x = E[i - nr, 0]
            y = E[i - nr, 1]
            vx = E[i - nr, 2]
            vy = E[i - nr, 3]
        start = mark[tid] < c - 1
        if not start:
            out_of_m = True
            for j in range(rm.shape[0]):
                if rm[j] == tid:
                    out_of_m = False
                    break
            if out_of_m:
                # the speed, then (slower than stand) the distance to the box: one call site of py_hypot (each site
                # inlines its code: ≈ 0.15–0.3 s of cold compile a site)
                a, b = vx, vy
                for q in range(2):
                    h = py_hypot(a, b)
                    if q == 0:
                        if not h < stand:
                            break
                        a, b = x - F[tid, 0], y - F[tid, 1]
                    elif h <= reach:
                        F[tid, 4] = stamp  # still standing where it stood
                    else:
                        start = True  # standing at a new place
        if start:
            F[tid, 0] = x
            F[tid, 1] = y
            if i < nr:  # (Python's ``max(ln, wd)``: ln unless wd > ln, NaN included; erasure._box_key)
                ln, wd = B[i, 3], B[i, 4]
                F[tid, 2] = 0.5 * (wd if wd > ln else ln)
            else:
                F[tid, 2] = E[i - nr, 4]
            F[tid, 3] = stamp
            F[tid, 4] = stamp
            new[m] = i
            m += 1
        mark[tid] = c
    return new[:m]
