"""Offline map clean-up: erase occupied cells that beams were seen to pass through.

The 2D form of visibility-based removal (docs/maps.md): a cell that scans *hit* but
that other scans *saw through* held something that was not always there (a parked car
that left, a person who stood and walked on, a box that arrived). Removert (Kim & Kim,
IROS 2020) removes map points that lie in front of a later scan's range measurement;
Peopleremover (Schauer & Nüchter, RA-L 2018) counts, per voxel, the scans whose rays
traverse it and removes points in traversed voxels; ERASOR (Lim et al., RA-L 2021)
compares region-wise occupancy of the map and of each scan. Here, per map cell:

* ``hits``: number of scans with a kept beam ending in the cell (beams the dynamic
  filter removed add no hit: they belong to movers);
* ``through``: number of scans with a beam (kept or removed: both saw free space up to
  their endpoint) that passes through the cell *before* its endpoint minus a margin,
  in a scan that did not also hit the cell;
* ``switches``: how often the cell's sequence of scans changed between hit and pass.

A cell occupied in the online map is erased when ``through ≥ min_through``,
``through ≥ through_ratio · hits`` (Peopleremover's count of traversing scans, with
ERASOR's idea of a ratio against the occupancy) and ``switches ≤ max_switches +
switch_share · min(hits, through)``: a parked object is hit in one block of scans and
seen through in another, while glass, railings, the copies of a wall that pose drift
put apart and wall cells clipped by grazing rays alternate (our stand-in for Removert's
"revert" of removals caused by pose and discretisation ambiguity).

Structure seen again after it was seen through: a cell hit by at least ``rehit_min_hits`` (6) scans whose
first and latest counted touches were both hits (``S`` even and ≥ 2, latest a hit) is never erased. An object
that left (hits, then passes), arrived (passes, then hits) or stood for a while (passes, hits, passes) is not of
that kind; a wall is, when the scans of one visit were placed with pose error: they see through where the other
visits, before and after, hit it (docs/maps.md, "What the erased cells are"). Removert's "revert" (Kim & Kim,
IROS 2020) for the removals that pose error causes, judged from the order of the observations instead of a
coarser resolution.

Walls at grazing incidence: a ray that meets a surface at angle α runs within one
cell of it for about ``resolution / sin α`` before the endpoint, so the margin grows
to ``grazing_cells · resolution / sin α`` (α estimated per beam from the neighbouring
endpoints); a cell counts as passed only where the ray runs near its centre
(``ray_core``), so rays that clip the corner of a wall end or door frame do not count.

Walls that grazing rays cleared: Hector's online update frees every cell before a return, so rays that run
along a wall seen only at grazing incidence clear wall cells that other rays hit (docs/maps.md). The same
counts find them: a cell the online map observed free, that at least ``restore_min_hits`` scans hit with a kept
beam and that beams passed beyond their incidence-scaled margin at most ``restore_through_ratio · hits``
times, is put back as occupied — Removert's "revert" of removals that the sensor's geometry, not a change,
caused; the margin is Peopleremover's ray shortening and the inverse sensor model's no-update zone within an
obstacle's depth before the measured range (Thrun, Burgard & Fox, Probabilistic Robotics, Table 9.2) with the
depth of a one-cell surface seen at incidence α.

Memory: the pass never keeps scans. :class:`VisibilityCounter` is fed scan by scan
during the run (:class:`CleanupRecorder` is a pipeline observer) and holds, per cell, three uint16
counts and one uint16 latest touch (8 bytes per cell; counts saturate at 65535 scans), in
16 × 16-cell tiles allocated where a beam first ends or passes: the counted extent grows with the
scans as a dense grid would (never beyond the SLAM's ``max_map_memory_mb``), but only the tiles
that rays reach take memory (15 % of MIT CSAIL's extent; docs/speed.md, "Memory, ninth pass").
Hector-style SLAM never changes a pose after its scan (no loop closure), so the pose a scan
had when it was processed is its pose in the final trajectory; counting during the run is the same as counting after it.

Frames and units: world / map frame in m; cell (i, j) of the counters is absolute
(centre at (i·r, j·r), as the SLAM grid levels), arrays indexed [row = y, col = x].
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.memtrim import release_free_memory
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.grid import _zeroed
from dynslam2d.types import Pose2D, Scan

#: Occupancy probability written into erased cells of the cleaned map (clearly free).
ERASED_PROBABILITY = 0.1

#: Occupancy probability written into restored cells of the cleaned map (one hit's worth: Hector's 0.9).
RESTORED_PROBABILITY = 0.9


#: Channels of a counted cell (uint16 each): hits, passes, switches and the latest touch (:func:`_count_scan`).
_HIT, _THROUGH, _SWITCH, _LAST = 0, 1, 2, 3

#: Tiles of the counter: 2**_TILE_SHIFT cells a side, aligned on absolute cells (tile (a, b) holds cells
#: i = 16·a … 16·a + 15, j = 16·b … 16·b + 15), each (256, 4) uint16 in the counter's tile pool (2 KiB).
_TILE_SHIFT = 4
_TILE = 1 << _TILE_SHIFT
_TILE_MASK = _TILE - 1

#: Largest count a channel holds (uint16); counts saturate there instead of wrapping. A cell
#: counted by more than 65535 scans (a robot parked for hours in front of a wall) keeps 65535:
#: the erase rule compares counts with thresholds and ratios, which saturation leaves on the
#: side of the larger count (docs/speed.md).
COUNT_MAX = 65535

#: Bytes per counted cell: three uint16 counts and one uint16 "last touch" (scan number · 2 + hit).
BYTES_PER_CELL = 8
#: Largest scan number in the "last touch" array (2 · 32767 + 1 fits uint16); past it the counter renumbers the
#: earlier touches (:meth:`VisibilityCounter._renumber`), which leaves every count the same.
_ID_SPAN = 32767

#: ``(1 << 8·k) · _BYTE_OF_BIT`` (uint64, wrapping) holds k in its top byte, k = 0 … 7: the place of a word's
#: lowest marked byte without a loop (:func:`_count_beams`)
_BYTE_OF_BIT = np.uint64(0x0001020304050607)
#: the machine's byte order: byte k of a uint64 read from memory is its bits 8·k … 8·k + 7 when little-endian
_LITTLE = sys.byteorder == "little"

#: no beam removed (:meth:`VisibilityCounter.add` without the filter's mask)
_NO_BEAMS = np.zeros(0, dtype=np.bool_)


def _count_scan(counts: np.ndarray, last: np.ndarray, scan_id: int, ox: float, oy: float, hx: np.ndarray,
                hy: np.ndarray, cx: np.ndarray, cy: np.ndarray, core: float) -> None:
    """One scan into the counters ``counts`` (H, W, 3) uint16 (hits, passes, switches; saturating at
    :data:`COUNT_MAX`) and ``last`` (H, W) uint16, the cell's latest touch as ``2 · n + 1`` for a hit, ``2 · n``
    for a pass, n the number of the scan that touched it (1 … :data:`_ID_SPAN`; 0 = never; ``scan_id`` is this
    scan's, larger than every number in ``last``). Coordinates are in cell units of the arrays
    (cell (i, j) centred on integers). ``(hx, hy)``: hit endpoints; ``(cx, cy)``: ends of
    the clearing segments from ``(ox, oy)``. Per scan, a cell gets at most one hit and
    one pass, and no pass if the scan hit it (hits are counted first). Switches count changes between
    hit and pass in each cell's sequence of scans (the kind of its latest touch is its state).

    The kernel :meth:`VisibilityCounter.add` runs (:func:`_count_beams`) with every beam kept and clearing and no
    offset, on tiles made from the dense arrays and written back: the counting rule in array coordinates, for
    tests and callers that hold the endpoints already."""
    h, w = last.shape
    table, pool, n = _tiles_of(counts, last)  # every tile allocated: no pool row is needed
    _count_beams(table, pool, n, 0, 0, scan_id, float(ox), float(oy), hx, hy, np.ones(hx.shape[0], dtype=np.bool_),
                 cx, cy, np.ones(cx.shape[0], dtype=np.bool_), 0, 0, h, w, float(core), np.zeros(0, dtype=np.uint8),
                 False)
    hit, through, switch, latest = _tile_channels(table, pool, 0, 0, h, w, (_HIT, _THROUGH, _SWITCH, _LAST))
    counts[:, :, _HIT], counts[:, :, _THROUGH], counts[:, :, _SWITCH] = hit, through, switch
    last[...] = latest


def _tiles_of(counts: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The tile table and pool (:class:`VisibilityCounter`) of dense arrays ``counts`` (H, W, 3) / ``last`` (H, W)
    whose cell (0, 0) is absolute cell (0, 0): every tile of the arrays allocated, in row order."""
    h, w = last.shape
    th, tw = -(-h // _TILE), -(-w // _TILE)
    full = np.zeros((th * _TILE, tw * _TILE, 4), dtype=np.uint16)
    full[:h, :w, :3] = counts
    full[:h, :w, _LAST] = last
    pool = np.ascontiguousarray(full.reshape(th, _TILE, tw, _TILE, 4).transpose(0, 2, 1, 3, 4)).reshape(
        th * tw, _TILE * _TILE, 4)
    return np.arange(th * tw, dtype=np.int32).reshape(th, tw), pool, th * tw


def _tile_channels(table: np.ndarray, pool: np.ndarray, r0: int, c0: int, h: int, w: int,
                   channels: Sequence[int]) -> list[np.ndarray]:
    """(h, w) uint16 arrays, one per channel of ``channels`` (:data:`_HIT` … :data:`_LAST`), of the cells rows
    r0 … r0 + h − 1, cols c0 … c0 + w − 1 in the tiles' cell units (tile (0, 0) of ``table`` starts at cell
    (0, 0); the range may pass the table's edges): the counted cells' values, zeros where no tile is allocated.
    Filled tile by tile, only the channels asked for (the clean-up pass reads three of four over the whole map)."""
    outs = [np.zeros((h, w), dtype=np.uint16) for _ in channels]
    if h <= 0 or w <= 0:
        return outs
    tr0, tc0 = max(r0 >> _TILE_SHIFT, 0), max(c0 >> _TILE_SHIFT, 0)
    tr1 = min((r0 + h - 1) >> _TILE_SHIFT, table.shape[0] - 1)
    tc1 = min((c0 + w - 1) >> _TILE_SHIFT, table.shape[1] - 1)
    if tr1 < tr0 or tc1 < tc0:
        return outs
    sub = table[tr0:tr1 + 1, tc0:tc1 + 1]
    for tr, tc in zip(*np.nonzero(sub >= 0)):
        tile = pool[sub[tr, tc]].reshape(_TILE, _TILE, 4)
        y0, x0 = (int(tr) + tr0) * _TILE - r0, (int(tc) + tc0) * _TILE - c0  # the tile's first cell in the output
        ya, xa = max(y0, 0), max(x0, 0)
        yb, xb = min(y0 + _TILE, h), min(x0 + _TILE, w)
        for out, ch in zip(outs, channels):
            out[ya:yb, xa:xb] = tile[ya - y0:yb - y0, xa - x0:xb - x0, ch]
    return outs


@njit(cache=True)
def _count_beams(table, pool, n_tiles, ti0, tj0, scan_id, ox, oy, ex, ey, kept, cx, cy, clear, i0, j0, h, w, core,
                 mask, resume):  # pragma: no cover - numba
    """:func:`_count_beams_inline` as a kernel of its own (the counter's resume after the pool ran full,
    :func:`_count_scan`)."""
    return _count_beams_inline(table, pool, n_tiles, ti0, tj0, scan_id, ox, oy, ex, ey, kept, cx, cy, clear, i0, j0,
                               h, w, core, mask, resume)


@njit(cache=True, inline="always")
def _count_beams_inline(table, pool, n_tiles, ti0, tj0, scan_id, ox, oy, ex, ey, kept, cx, cy, clear, i0, j0, h, w,
                        core, mask, resume):  # pragma: no cover - numba
    """:func:`_count_scan` of the beams as :func:`_scan_geometry` gives them (world cell units) into the counter's
    tiles: hits at ``(ex, ey)[kept]``, clearing segments to ``(cx, cy)[clear]``, all shifted by the counted
    extent's first cell ``(i0, j0)`` here (the same float64 subtractions numpy's ``ex[kept] - i0`` does) instead
    of in four masked numpy copies per scan; cells outside the extent's ``h`` × ``w`` cells are dropped.
    ``(ox, oy)``: the laser in extent cell units. ``table`` (TH, TW) int32: the pool row of each tile (−1: none
    yet), tile (0, 0) being absolute tile ``(ti0, tj0)``; ``pool`` (cap, 256, 4) uint16 with ``n_tiles`` rows in
    use; a tile gets the next row when a beam first touches one of its cells. The pool must have a free row for
    every kept beam (the hits); when the passes need more, the kernel stops with the rest of the passes still
    marked in ``mask`` and returns ``full`` True: called again with a larger pool and ``resume`` True it counts
    them (the marked cells left; hits and marking are not done again).
    Returns the scratch ``mask`` (uint8, all zero when not ``full``; a larger one when the scan's box needs it)
    for the next scan, the rows in use and ``full``.

    The passes in two steps, with the counts of :func:`_count_scan`: the rays first mark the cells they pass
    in ``mask`` (one byte per cell of the scan's bounding box, which stays in the first cache levels), then the
    marked cells are counted in row order. A cell gets at most one pass per scan and the counts depend only on
    the set of cells hit and the set passed, so the order does not matter; walking the rays straight into the
    counts touched a new cache line of both arrays at every step of a ray running along y, and about two in three
    steps land on a cell an earlier ray of the scan already passed."""
    fi0 = float(i0)
    fj0 = float(j0)
    if not resume:
        hit_code = 2 * scan_id + 1
        for k in range(ex.shape[0]):
            if kept[k]:
                ix = int(math.floor(ex[k] - fi0 + 0.5))
                iy = int(math.floor(ey[k] - fj0 + 0.5))
                if 0 <= ix < w and 0 <= iy < h:
                    xa = ix + i0
                    ya = iy + j0
                    r = (ya >> _TILE_SHIFT) - tj0
                    q = (xa >> _TILE_SHIFT) - ti0
                    t = table[r, q]
                    if t < 0:  # (a free row per kept beam: the caller's)
                        t = n_tiles
                        table[r, q] = t
                        n_tiles += 1
                    c = ((ya & _TILE_MASK) << _TILE_SHIFT) | (xa & _TILE_MASK)
                    lt = pool[t, c, 3]
                    if lt != hit_code:
                        if lt != 0 and (lt & 1) == 0 and pool[t, c, 2] < COUNT_MAX:
                            pool[t, c, 2] += 1
                        pool[t, c, 3] = hit_code
                        if pool[t, c, 0] < COUNT_MAX:
                            pool[t, c, 0] += 1
    # the cells any ray can reach: its major axis runs over rounded ends, its minor coordinate at most half a
    # cell (|slope| ≤ 1) beyond the segment's; one more cell each side, clipped to the extent (the rest is dropped)
    lo_x = ox
    hi_x = ox
    lo_y = oy
    hi_y = oy
    for k in range(cx.shape[0]):
        if clear[k]:
            lo_x = min(lo_x, cx[k] - fi0)
            hi_x = max(hi_x, cx[k] - fi0)
            lo_y = min(lo_y, cy[k] - fj0)
            hi_y = max(hi_y, cy[k] - fj0)
    x0 = max(int(math.floor(lo_x)) - 1, 0)
    x1 = min(int(math.floor(hi_x)) + 2, w - 1)
    y0 = max(int(math.floor(lo_y)) - 1, 0)
    y1 = min(int(math.floor(hi_y)) + 2, h - 1)
    if x1 < x0 or y1 < y0:
        return mask, n_tiles, False
    stride = (x1 - x0 + 8) // 8 * 8  # whole 8-byte words per row
    need = stride * (y1 - y0 + 1)
    if not resume:
        if mask.shape[0] < need + 8:  # (one word past the box's rows: the byte the steps without a mark go to)
            mask = np.empty(need + 8, dtype=np.uint8)
            for i in range(need + 8):
                mask[i] = 0
        idx = np.empty(max(x1 - x0, y1 - y0) + 1, dtype=np.int64)  # (a ray's steps inside the box: at most this)
        for k in range(cx.shape[0]):
            if clear[k]:
                _mark_ray(mask, x0, y0, x1, y1, stride, ox, oy, cx[k] - fi0, cy[k] - fj0, core, idx, need)
        mask[need] = 0  # (the spare byte: the mask is zero outside the box's marked cells)
    per_row = stride // 8
    pass_code = 2 * scan_id
    cap = pool.shape[0]
    words = mask.view(np.uint64)  # (8 cells a word; the mask's length is whole words: rows of whole words)
    for r in range(y1 - y0 + 1):
        ya = y0 + r + j0
        rt = (ya >> _TILE_SHIFT) - tj0
        in_tile = (ya & _TILE_MASK) << _TILE_SHIFT
        tc = -1  # the tile column of the last cell counted in this row, and its pool row
        t = -1
        for q in range(per_row):
            wi = r * per_row + q
            word = words[wi]
            if word == 0:
                continue
            words[wi] = 0  # the word's cells cleared at once (put back below if the pool runs full)
            while word != 0:  # its marked bytes (each 0 or 1), lowest bit first: no branch per unmarked cell
                low = word & (~word + np.uint64(1))  # the lowest set bit, 1 << 8 · (the byte's place in the word)
                word ^= low
                jj = np.int64((low * _BYTE_OF_BIT) >> np.uint64(56))  # that place (the multiply puts it on top)
                if not _LITTLE:
                    jj = 7 - jj
                xa = x0 + q * 8 + jj + i0
                if (xa >> _TILE_SHIFT) - ti0 != tc:
                    tc = (xa >> _TILE_SHIFT) - ti0
                    t = table[rt, tc]
                    if t < 0:
                        if n_tiles == cap:
                            words[wi] = word | low  # this cell and the rest still marked
                            return mask, n_tiles, True
                        t = n_tiles
                        table[rt, tc] = t
                        n_tiles += 1
                c = in_tile | (xa & _TILE_MASK)
                lt = pool[t, c, 3]
                if (lt >> 1) != scan_id:  # not hit by this scan
                    if (lt & 1) == 1 and pool[t, c, 2] < COUNT_MAX:
                        pool[t, c, 2] += 1
                    pool[t, c, 3] = pass_code
                    if pool[t, c, 1] < COUNT_MAX:
                        pool[t, c, 1] += 1
    return mask, n_tiles, False


@njit(cache=True, inline="always")
def _mark_ray(mask, x0, y0, x1, y1, stride, ox, oy, ex, ey, core, idx, spare):  # pragma: no cover - numba
    """Mark in ``mask`` (rows of ``stride`` bytes from cell (x0, y0); cells beyond (x1, y1) dropped) the cells the
    segment ``(ox, oy)`` → ``(ex, ey)`` passes: one cell per step of the major axis, where the segment runs
    within ``core`` of the cell centre across it.

    In two loops over the steps whose major coordinate lies in the box (the others are dropped): the first
    computes each step's byte in ``mask`` into the scratch ``idx`` (int64, as long as the box's longer side), with
    no store into ``mask`` and no branch, so the compiler runs it on vector registers; the second stores 1 into
    those bytes: a step whose cell is outside the box or off the ray's core goes to the byte ``spare`` instead
    (past the box's rows; the caller zeroes it after the rays). A store without the load an or needs (pass
    cln113: was ``mask[i] | val[k]``, a step off the core or the box or-ing 0 into byte 0); the same cells marked.
    Each step's values are those of the one-loop walk: the major coordinate ``a`` is an integer held exactly in
    float64, so ``(fa + k) − m0`` is the walk's ``a − m0`` bit for bit (docs/speed.md, pass cln96)."""
    dx = ex - ox
    dy = ey - oy
    if abs(dx) >= abs(dy):
        a0 = int(math.floor(ox + 0.5))
        a1 = int(math.floor(ex + 0.5))
        slope = dy / dx if dx != 0.0 else 0.0
        m0 = ox
        n0 = oy
        lo_a = x0
        hi_a = x1
        lo_b = y0
        hi_b = y1
        sa = 1
        sb = stride
    else:
        a0 = int(math.floor(oy + 0.5))
        a1 = int(math.floor(ey + 0.5))
        slope = dx / dy
        m0 = oy
        n0 = ox
        lo_a = y0
        hi_a = y1
        lo_b = x0
        hi_b = x1
        sa = stride
        sb = 1
    if a1 >= a0:  # the steps a = a0 + step · k, k = ka … kb, from a0 to a1 and inside [lo_a, hi_a]
        step = 1
        ka = max(lo_a - a0, 0)
        kb = min(hi_a - a0, a1 - a0)
    else:
        step = -1
        ka = max(a0 - hi_a, 0)
        kb = min(a0 - lo_a, a0 - a1)
    n = kb - ka + 1
    if n <= 0:
        return
    fa = float(a0 + step * ka)
    fs = float(step)
    flo = float(lo_b)
    fhi = float(hi_b)
    base = (a0 + step * ka - lo_a) * sa - lo_b * sb
    dk = step * sa
    for k in range(n):
        b = n0 + slope * ((fa + fs * k) - m0)
        fl = math.floor(b + 0.5)
        on = (fl >= flo) & (fl <= fhi) & (abs(b - fl) <= core)
        idx[k] = base + dk * k + np.int64(np.int32(fl)) * sb if on else spare
    for k in range(n):
        mask[idx[k]] = 1


@njit(cache=True)
def _scan_geometry(ranges, cos_a, sin_a, valid, removed, px, py, th, res, margin_m, grazing_cells,
                   min_sin):  # pragma: no cover - numba
    """Endpoints (ex, ey) and clearing ends (cx, cy) of one scan in world cell units (m / res),
    with ``kept`` (valid and not removed: a hit) and ``clear`` (valid and longer than its
    margin). Incidence: |sin α| between the beam and the local surface ``p[i+1] − p[i−1]``
    (or the one valid neighbour; 1 without any); at a depth jump the "surface" spans both
    sides and reads as grazing, which only makes the margin larger. Margin =
    max(margin_m, grazing_cells·res / max(sin α, min_sin))."""
    n = ranges.shape[0]
    # (every element written by the loops: no ``a[:] = 0`` fills, each ≈ 300 LLVM instructions of numba's slice
    # assignment to type, lower and optimise; pass cmp149)
    lx = np.empty(n)
    ly = np.empty(n)
    for i in range(n):
        lx[i] = ranges[i] * cos_a[i] if valid[i] else 0.0
        ly[i] = ranges[i] * sin_a[i] if valid[i] else 0.0
    ca = math.cos(th)
    sa = math.sin(th)
    ex = np.empty(n)
    ey = np.empty(n)
    cx = np.empty(n)
    cy = np.empty(n)
    kept = np.empty(n, dtype=np.bool_)
    clear = np.empty(n, dtype=np.bool_)
    ox = px / res
    oy = py / res
    for i in range(n):
        ex[i] = ox
        ey[i] = oy
        cx[i] = ox
        cy[i] = oy
        kept[i] = False
        clear[i] = False
        if not valid[i]:
            continue
        ax = lx[i]
        ay = ly[i]
        bx = lx[i]
        by = ly[i]
        has = False
        if i > 0 and valid[i - 1]:
            ax = lx[i - 1]
            ay = ly[i - 1]
            has = True
        if i + 1 < n and valid[i + 1]:
            bx = lx[i + 1]
            by = ly[i + 1]
            has = True
        tx = bx - ax
        ty = by - ay
        tn = math.sqrt(tx * tx + ty * ty)
        r = ranges[i]
        sn = 1.0
        if has and tn > 0.0 and r > 0.0:
            sn = abs(lx[i] * ty - ly[i] * tx) / (tn * r)
        if sn < min_sin:
            sn = min_sin
        margin = grazing_cells * res / sn
        if margin < margin_m:
            margin = margin_m
        wx = px + ca * lx[i] - sa * ly[i]
        wy = py + sa * lx[i] + ca * ly[i]
        ex[i] = wx / res
        ey[i] = wy / res
        kept[i] = not removed[i]
        if r > margin:
            f = (r - margin) / r
            cx[i] = ox + (ex[i] - ox) * f
            cy[i] = oy + (ey[i] - oy) * f
            clear[i] = True
    return ex, ey, cx, cy, kept, clear


@njit(cache=True)
def _geometry_bounds(ranges, cos_a, sin_a, valid, removed, px, py, th, res, margin_m, grazing_cells,
                     min_sin):  # pragma: no cover - numba
    """:func:`_geometry_bounds_inline` as a kernel of its own."""
    return _geometry_bounds_inline(ranges, cos_a, sin_a, valid, removed, px, py, th, res, margin_m, grazing_cells,
                                   min_sin)


@njit(cache=True, inline="always")
def _geometry_bounds_inline(ranges, cos_a, sin_a, valid, removed, px, py, th, res, margin_m, grazing_cells,
                            min_sin):  # pragma: no cover - numba
    """:func:`_scan_geometry` (same arguments) and the absolute cells (imin, jmin, imax, jmax) of the laser
    and the valid endpoints (:meth:`VisibilityCounter._cell_bounds`: the same minima and maxima, exact, and
    roundings) in one call, without the masked copies (``valid`` must hold a beam)."""
    ex, ey, cx, cy, kept, clear = _scan_geometry(ranges, cos_a, sin_a, valid, removed, px, py, th, res, margin_m,
                                                 grazing_cells, min_sin)
    lo_x = px / res
    hi_x = lo_x
    lo_y = py / res
    hi_y = lo_y
    for i in range(ex.shape[0]):
        if valid[i]:
            lo_x = min(lo_x, ex[i])
            hi_x = max(hi_x, ex[i])
            lo_y = min(lo_y, ey[i])
            hi_y = max(hi_y, ey[i])
    return (ex, ey, cx, cy, kept, clear, int(math.floor(lo_x + 0.5)), int(math.floor(lo_y + 0.5)),
            int(math.floor(hi_x + 0.5)), int(math.floor(hi_y + 0.5)))


#: :func:`_add_scan`'s answers: the scan counted; no beam held a return (nothing done); the extent must grow
#: to the returned cells first; the tile pool needs free rows first; the pool ran full while the passes were
#: counted (the rest of them still marked in the mask: :meth:`VisibilityCounter._resume`)
_DONE, _NO_BEAM, _GROW, _POOL, _FULL = 0, 1, 2, 3, 4


@njit(cache=True)
def _add_scan(ranges, cos_a, sin_a, valid_in, removed, px, py, th, res, margin_m, grazing_cells, min_sin, min_dist,
              max_dist, table, pool, n_tiles, ti0, tj0, scan_id, i0, j0, h, w, core, mask):  # pragma: no cover - numba
    """:meth:`VisibilityCounter.add`'s work on one scan in one call: the beams with a return (``valid_in``, the
    scan's :meth:`Scan.valid_mask`) within (``min_dist``, ``max_dist``) m (NaN compares False, as NumPy's tests),
    their geometry and cell bounds (:func:`_geometry_bounds`; ``removed`` (n,) bool or, when it is not the scan's
    length, no beam removed), the extent's test (:meth:`VisibilityCounter._ensure`: cells (``i0``, ``j0``) …
    (``i0 + w − 1``, ``j0 + h − 1``)), the pool's free rows (:meth:`VisibilityCounter._reserve_tiles`: one per
    beam, or a row for every tile of ``table``) and the counting (:func:`_count_beams`, laser at
    (``px``, ``py``) m / ``res`` − (``i0``, ``j0``) cells). Returns (mask, rows in use, answer, imin, jmin, imax,
    jmax): answer :data:`_DONE` or :data:`_FULL` (counted; the rest as :func:`_count_beams` leaves it),
    :data:`_NO_BEAM` (nothing done), :data:`_GROW` (nothing done; the absolute cells the extent must hold) or
    :data:`_POOL` (nothing done: the caller reserves rows and calls again). The same operations in the same order
    as the step-by-step calls, so the counts are the same bit for bit; the two kernels' bodies are inlined here
    (numba's IR), so a run compiles them once, not once on their own and again inlined (docs/speed.md, pass
    cln102)."""
    n = ranges.shape[0]
    valid = np.empty(n, dtype=np.bool_)
    some = False
    for i in range(n):
        r = ranges[i]
        v = valid_in[i] and r > min_dist and r < max_dist
        valid[i] = v
        some = some or v
    if not some:
        return mask, n_tiles, _NO_BEAM, 0, 0, 0, 0
    rem = np.empty(n, dtype=np.bool_)  # (not np.zeros: its implementation and zero fill are two more compiles)
    given = removed.shape[0] == n
    for i in range(n):
        rem[i] = removed[i] if given else False
    ex, ey, cx, cy, kept, clear, imin, jmin, imax, jmax = _geometry_bounds_inline(
        ranges, cos_a, sin_a, valid, rem, px, py, th, res, margin_m, grazing_cells, min_sin)
    if h == 0 or imin < i0 or jmin < j0 or imax >= i0 + w or jmax >= j0 + h:
        return mask, n_tiles, _GROW, imin, jmin, imax, jmax
    if pool.shape[0] - n_tiles < min(n, table.size - n_tiles):
        return mask, n_tiles, _POOL, imin, jmin, imax, jmax
    mask, n_tiles, full = _count_beams_inline(table, pool, n_tiles, ti0, tj0, scan_id, px / res - i0, py / res - j0,
                                              ex, ey, kept, cx, cy, clear, i0, j0, h, w, core, mask, False)
    return mask, n_tiles, _FULL if full else _DONE, imin, jmin, imax, jmax


class VisibilityCounter:
    """Per-cell counts of scans that hit a cell and scans that passed through it.

    Grows with the scans it is fed (absolute cells, resolution ``resolution`` m): the counted extent, cells
    (:attr:`i0` … :attr:`i0` + w − 1, :attr:`j0` … :attr:`j0` + h − 1) with (h, w) = :attr:`shape`, grows as a
    dense grid of :data:`BYTES_PER_CELL` bytes per cell would (:attr:`nbytes`, held to the SLAM's
    ``max_map_memory_mb``); the counts are kept in 16 × 16-cell tiles allocated where a beam first ends or passes
    (:attr:`resident_bytes`). Feed with :meth:`add`; read with :meth:`window`.
    """

    def __init__(self, resolution: float, config: CleanConfig | None = None,
                 slam: SlamConfig | None = None, growth_margin_m: float = 5.0) -> None:
        self.resolution = float(resolution)
        self.config = config if config is not None else CleanConfig()
        self.slam = slam if slam is not None else SlamConfig(map_resolution=resolution)
        self.margin_cells = max(int(math.ceil(growth_margin_m / self.resolution)), 1)
        self.i0 = 0  # absolute col of the extent's column 0
        self.j0 = 0  # absolute row of the extent's row 0
        self._h = 0
        self._w = 0
        #: pool row of each tile of the extent (−1: not allocated); tile (0, 0) is absolute tile (_ti0, _tj0)
        self._table = np.zeros((0, 0), dtype=np.int32)
        self._ti0 = 0
        self._tj0 = 0
        #: the allocated tiles, (capacity, 256, 4) uint16: per cell hits, passes, switches and the latest touch
        #: (2 · scan number, + 1 for a hit), cells in row order inside the tile; rows 0 … _n_tiles − 1 in use
        self._pool = np.zeros((0, _TILE * _TILE, 4), dtype=np.uint16)
        self._n_tiles = 0
        self._id_base = 0  # scan number = scan id − this (see _renumber)
        #: scratch of the counting kernel (one byte per cell of a scan's bounding box, zero between scans)
        self._mask = np.zeros(0, dtype=np.uint8)
        self.scans = 0  # scans counted (also the id of the next scan)
        self.too_large = 0  # scans left out: counting them would exceed the memory limit
        self.seconds = 0.0

    @property
    def shape(self) -> tuple[int, int]:
        """(h, w): rows and columns of the counted extent."""
        return self._h, self._w

    def _extent_channel(self, channel: int) -> np.ndarray:
        """(h, w) uint16 copy of one channel (:data:`_HIT` … :data:`_LAST`) over the whole extent."""
        (out,) = _tile_channels(self._table, self._pool, self.j0 - (self._tj0 << _TILE_SHIFT),
                                self.i0 - (self._ti0 << _TILE_SHIFT), self._h, self._w, (channel,))
        return out

    @property
    def hits(self) -> np.ndarray:
        """(h, w) uint16 copy: scans that hit each cell of the extent (see :attr:`i0`, :attr:`j0`)."""
        return self._extent_channel(_HIT)

    @property
    def through(self) -> np.ndarray:
        """(h, w) uint16 copy: scans that passed through each cell."""
        return self._extent_channel(_THROUGH)

    @property
    def switches(self) -> np.ndarray:
        """(h, w) uint16 copy: changes between hit and pass in each cell's scan sequence."""
        return self._extent_channel(_SWITCH)

    def last_touch(self) -> np.ndarray:
        """(h, w) uint16 copy: each cell's latest touch (2 · scan number, + 1 for a hit; 0 = never)."""
        return self._extent_channel(_LAST)

    def at(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(n, 4) uint16: hits, passes, switches and latest touch of absolute cells (i[k], j[k]) (zeros outside
        the extent or where nothing was counted)."""
        i = np.asarray(i, dtype=np.int64)
        j = np.asarray(j, dtype=np.int64)
        out = np.zeros((i.shape[0], 4), dtype=np.uint16)
        ok = (i >= self.i0) & (i < self.i0 + self._w) & (j >= self.j0) & (j < self.j0 + self._h)
        t = np.full(i.shape[0], -1, dtype=np.int64)
        t[ok] = self._table[(j[ok] >> _TILE_SHIFT) - self._tj0, (i[ok] >> _TILE_SHIFT) - self._ti0]
        has = t >= 0
        out[has] = self._pool[t[has], ((j[has] & _TILE_MASK) << _TILE_SHIFT) | (i[has] & _TILE_MASK)]
        return out

    def clear(self) -> None:
        """Forget every count and scan (the extent stays)."""
        self._table[...] = -1
        self._pool = np.zeros((0, _TILE * _TILE, 4), dtype=np.uint16)
        self._n_tiles = 0
        self._id_base = 0
        self.scans = 0

    @property
    def nbytes(self) -> int:
        """Bytes of the counted extent at :data:`BYTES_PER_CELL` per cell (summary.json's ``counter_bytes``,
        the figure held to ``max_map_memory_mb``); the tiles hold :attr:`resident_bytes`."""
        return int(self._h * self._w * BYTES_PER_CELL)

    @property
    def resident_bytes(self) -> int:
        """Bytes the counts take: the tile pool's rows in use (the pool's other rows are zeroed memory never
        written) and the tile table."""
        return int(self._n_tiles * _TILE * _TILE * 4 * 2 + self._table.nbytes)

    def _ensure(self, imin: int, jmin: int, imax: int, jmax: int) -> bool:
        """Grow to hold cells [imin, imax] × [jmin, jmax]; False (nothing changed) if that
        would take more than the SLAM's map memory limit (``max_map_memory_mb``)."""
        h, w = self._h, self._w
        if h and imin >= self.i0 and jmin >= self.j0 and imax < self.i0 + w and jmax < self.j0 + h:
            return True
        if h == 0:
            m = self.margin_cells
            ni0, nj0, ni1, nj1 = imin - m, jmin - m, imax + m + 1, jmax + m + 1
        else:
            mx, my = max(self.margin_cells, w // 2), max(self.margin_cells, h // 2)
            ni0 = min(self.i0, imin - mx) if imin < self.i0 else self.i0
            nj0 = min(self.j0, jmin - my) if jmin < self.j0 else self.j0
            ni1 = max(self.i0 + w, imax + mx + 1) if imax >= self.i0 + w else self.i0 + w
            nj1 = max(self.j0 + h, jmax + my + 1) if jmax >= self.j0 + h else self.j0 + h
        if (nj1 - nj0) * (ni1 - ni0) * BYTES_PER_CELL > self.slam.max_map_memory_mb * 1e6:
            return False
        # the tile table over the new extent (tiles are absolute: the allocated ones keep their pool rows)
        ti0, tj0 = ni0 >> _TILE_SHIFT, nj0 >> _TILE_SHIFT
        table = np.full((((nj1 - 1) >> _TILE_SHIFT) - tj0 + 1, ((ni1 - 1) >> _TILE_SHIFT) - ti0 + 1), -1,
                        dtype=np.int32)
        if self._table.size:
            th, tw = self._table.shape
            table[self._tj0 - tj0:self._tj0 - tj0 + th, self._ti0 - ti0:self._ti0 - ti0 + tw] = self._table
        self._table, self._ti0, self._tj0 = table, ti0, tj0
        self.i0, self.j0, self._h, self._w = ni0, nj0, nj1 - nj0, ni1 - ni0
        return True

    def _valid(self, scan: Scan) -> np.ndarray:
        s, r = self.slam, scan.ranges
        with np.errstate(invalid="ignore"):
            return scan.valid_mask() & (r > s.laser_min_dist) & (r < s.laser_max_dist)

    def _geometry(self, scan: Scan, pose: Pose2D, valid: np.ndarray,
                  removed: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """:func:`_scan_geometry` of one scan (ex, ey, cx, cy, kept, clear)."""
        return _scan_geometry(*self._geometry_args(scan, pose, valid, removed))

    def _geometry_args(self, scan: Scan, pose: Pose2D, valid: np.ndarray, removed: np.ndarray | None) -> tuple:
        """The arguments of :func:`_scan_geometry` / :func:`_geometry_bounds` for one scan."""
        c = self.config
        rem = removed if removed is not None and removed.shape == valid.shape else np.zeros_like(valid)
        cos_a, sin_a = scan.trig()
        return (np.asarray(scan.ranges, dtype=np.float64), cos_a, sin_a, valid, np.asarray(rem, dtype=np.bool_),
                pose.x, pose.y, pose.theta, self.resolution, c.margin_m, c.grazing_cells,
                math.sin(math.radians(c.min_incidence_deg)))

    @staticmethod
    def _cell_bounds(ox: float, oy: float, ex: np.ndarray, ey: np.ndarray,
                     valid: np.ndarray) -> tuple[int, int, int, int]:
        """(imin, jmin, imax, jmax) absolute cells of the scan origin and its valid endpoints (cell units)."""
        ev, fv = ex[valid], ey[valid]
        return (int(math.floor(min(ox, ev.min()) + 0.5)), int(math.floor(min(oy, fv.min()) + 0.5)),
                int(math.floor(max(ox, ev.max()) + 0.5)), int(math.floor(max(oy, fv.max()) + 0.5)))

    def reserve(self, scans: Sequence[tuple[Scan, Pose2D]]) -> bool:
        """Allocate the counts once for every cell ``scans`` (scan, pose) will touch, before adding them:
        the counts grow by half their size per side otherwise, copying and leaving the old arrays to the
        allocator (issue 13 item 3). The counts are the same either way (cells are absolute). Does nothing
        (False) when the array would pass the SLAM's map memory limit; :meth:`add` then grows as usual."""
        b: list[int] | None = None
        for scan, pose in scans:
            valid = self._valid(scan)
            if not valid.any() or not pose.is_finite():
                continue
            ex, ey, _cx, _cy, _kept, _clear = self._geometry(scan, pose, valid, None)
            c = self._cell_bounds(pose.x / self.resolution, pose.y / self.resolution, ex, ey, valid)
            b = list(c) if b is None else [min(b[0], c[0]), min(b[1], c[1]), max(b[2], c[2]), max(b[3], c[3])]
        if b is None or self._h:
            return False
        m = self.margin_cells
        if (b[3] - b[1] + 2 * m + 1) * (b[2] - b[0] + 2 * m + 1) * BYTES_PER_CELL > self.slam.max_map_memory_mb * 1e6:
            return False
        return self._ensure(*b)

    def add(self, scan: Scan, pose: Pose2D, removed: np.ndarray | None = None) -> None:
        """Count one scan taken at laser pose ``pose`` (map frame); ``removed`` (beams,) bool
        marks the beams the dynamic filter took out (no hit; they still pass through).

        One kernel call a scan (:func:`_add_scan`: the beams' validity, geometry, bounds and counting); Python only
        when the extent grows, the tile pool needs rows, or the scan numbers are renumbered (docs/speed.md, pass
        cln102; :meth:`add_steps` is the same count call by call)."""
        t0 = time.perf_counter()
        if self.scans + 1 - self._id_base > _ID_SPAN:  # (once in 32767 counted scans: the steps, renumbering)
            self.add_steps(scan, pose, removed)
            return
        c, res = self.config, self.resolution
        n = scan.ranges.shape[0]
        if removed is None or removed.shape != (n,):
            removed = _NO_BEAMS
        elif removed.dtype != np.bool_:
            removed = np.asarray(removed, dtype=np.bool_)
        cos_a, sin_a = scan.trig()
        px, py, th = float(pose.x), float(pose.y), float(pose.theta)
        s = self.slam
        while True:
            self._mask, self._n_tiles, answer, imin, jmin, imax, jmax = _add_scan(
                scan.ranges, cos_a, sin_a, scan.valid_view(), removed, px, py, th, res, float(c.margin_m),
                float(c.grazing_cells), math.sin(math.radians(c.min_incidence_deg)), float(s.laser_min_dist),
                float(s.laser_max_dist), self._table, self._pool, self._n_tiles, self._ti0, self._tj0,
                self.scans + 1 - self._id_base, self.i0, self.j0, self._h, self._w, float(c.ray_core), self._mask)
            if answer == _GROW:
                if not self._ensure(imin, jmin, imax, jmax):
                    self.too_large += 1  # the SLAM refuses such scans too ('map_too_large')
                    self.seconds += time.perf_counter() - t0
                    return
            elif answer == _POOL:
                self._reserve_tiles(n)
            else:
                break
        if answer == _FULL:  # (the pool ran full: the geometry again, the rest of the passes counted as _count does)
            ex, ey, cx, cy, kept, clear, *_ = _geometry_bounds(*self._geometry_args(scan, pose, self._valid(scan),
                                                                                      removed))
            self._count(ex, ey, kept, cx, cy, clear, pose.x / res, pose.y / res, float(c.ray_core), resume=True)
        self.scans += 1
        self.seconds += time.perf_counter() - t0

    def add_steps(self, scan: Scan, pose: Pose2D, removed: np.ndarray | None = None) -> None:
        """:meth:`add` call by call (validity, geometry and bounds, extent, renumbering, counting): the counts
        :meth:`add` makes in one kernel call, for the renumbering scan and the tests."""
        t0 = time.perf_counter()
        c, res = self.config, self.resolution
        valid = self._valid(scan)
        if not valid.any():
            self.scans += 1
            self.seconds += time.perf_counter() - t0
            return
        ex, ey, cx, cy, kept, clear, imin, jmin, imax, jmax = _geometry_bounds(
            *self._geometry_args(scan, pose, valid, removed))
        ox, oy = pose.x / res, pose.y / res
        if not self._ensure(imin, jmin, imax, jmax):
            self.too_large += 1  # the SLAM refuses such scans too ('map_too_large')
            self.seconds += time.perf_counter() - t0
            return
        if self.scans + 1 - self._id_base > _ID_SPAN:
            self._renumber()
        self._count(ex, ey, kept, cx, cy, clear, ox, oy, float(c.ray_core))
        self.scans += 1
        self.seconds += time.perf_counter() - t0

    def _count(self, ex: np.ndarray, ey: np.ndarray, kept: np.ndarray, cx: np.ndarray, cy: np.ndarray,
               clear: np.ndarray, ox: float, oy: float, core: float, resume: bool = False) -> None:
        """One scan's beams (:func:`_scan_geometry`, world cell units; laser at (ox, oy)) into the tiles: a free
        pool row for every beam first (the hits), more when the passes need them (:func:`_count_beams`).
        ``resume``: the scan's hits are counted and its remaining passes marked in the mask already (the pool ran
        full in :func:`_add_scan`): rows for them, then the rest."""
        self._reserve_tiles(ex.shape[0] + 1 if resume else ex.shape[0])  # (each beam's hit allocates at most one tile)
        while True:
            self._mask, self._n_tiles, full = _count_beams(
                self._table, self._pool, self._n_tiles, self._ti0, self._tj0, self.scans + 1 - self._id_base,
                ox - self.i0, oy - self.j0, ex, ey, kept, cx, cy, clear, self.i0, self.j0, self._h, self._w, core,
                self._mask, resume)
            if not full:
                return
            self._reserve_tiles(ex.shape[0] + 1)
            resume = True

    def _reserve_tiles(self, free: int) -> None:
        """At least ``free`` unused rows in the tile pool, or a row for every tile of the extent: the pool, when it
        has fewer, is made anew with a row for every tile of the extent, copying the rows in use, in zeroed memory
        of its own (``grid._zeroed``: its pages take memory when first written, so only the rows in use count).
        (Issue 13 item 3, pass mem63: it grew by a quarter or a scan's beams, 12–96 copies for one size of the extent on
        MIT CSAIL, 283 in all, each a new heap block of up to 5 MiB beside the old one — heap pages that
        stayed resident while the scan loop's peak came.)"""
        cap, n, tiles = self._pool.shape[0], self._n_tiles, self._table.size
        free = min(free, tiles - n)
        if cap - n >= free:
            return
        pool = _zeroed((tiles, _TILE * _TILE * 4), np.uint16).reshape(tiles, _TILE * _TILE, 4)
        pool[:n] = self._pool[:n]
        self._pool = pool

    def _renumber(self) -> None:
        """Make every touch so far one of scan number 1 (its kind kept) and the next scan number 2. The counting
        kernel compares a cell's latest touch only with the current scan's number (touched by this scan or
        not) and reads its kind, so the counts are those the scan ids themselves would give: the "last touch"
        array holds 2 bytes per cell instead of 4 whatever the length of the log (issue 13 item 3)."""
        last = self._pool[:self._n_tiles, :, _LAST]
        np.copyto(last, (last & 1) + 2, where=last != 0)
        self._id_base = self.scans - 1

    def _overlap(self, grid: GridMap) -> tuple[int, int] | None:
        """The absolute cell (i, j) of ``grid``'s cell (0, 0), or None when ``grid`` and the extent share no cell.

        ``grid`` must share the counter's resolution and have its cell centres on
        multiples of it (as the SLAM levels do)."""
        if abs(grid.resolution - self.resolution) > 1e-9 * self.resolution:
            raise ValueError(f"grid resolution {grid.resolution} m differs from the counter's {self.resolution} m")
        gi0 = int(round(grid.origin[0] / self.resolution + 0.5))
        gj0 = int(round(grid.origin[1] / self.resolution + 0.5))
        H, W = grid.shape
        h, w = self._h, self._w
        c0, c1 = max(gi0, self.i0), min(gi0 + W, self.i0 + w)
        r0, r1 = max(gj0, self.j0), min(gj0 + H, self.j0 + h)
        if c1 <= c0 or r1 <= r0:
            return None
        return gi0, gj0

    def _grid_channels(self, grid: GridMap, channels: Sequence[int]) -> list[np.ndarray]:
        """(H, W) uint16 arrays shaped like ``grid`` (same cells), one per channel of ``channels``: the counted
        cells' values, zeros elsewhere (outside the extent or never counted)."""
        H, W = grid.shape
        g = self._overlap(grid)
        if g is None:
            return [np.zeros((H, W), dtype=np.uint16) for _ in channels]
        gi0, gj0 = g  # (cells of the table outside the extent are never counted: zeros, as outside the table)
        return _tile_channels(self._table, self._pool, gj0 - (self._tj0 << _TILE_SHIFT),
                              gi0 - (self._ti0 << _TILE_SHIFT), H, W, channels)

    def window(self, grid: GridMap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(hits, through, switches), each shaped like ``grid`` (same cells; zeros where
        never counted)."""
        hits, through, switches = self._grid_channels(grid, (_HIT, _THROUGH, _SWITCH))
        return hits, through, switches

    def latest_hit(self, grid: GridMap) -> np.ndarray:
        """(H, W) bool shaped like ``grid``: the cell's latest counted touch was a hit (False where never
        counted). With the switch count's parity it gives the first touch too (:func:`erase_rule`)."""
        (last,) = self._grid_channels(grid, (_LAST,))
        return (last & 1) == 1

    def rows(self, grid: GridMap, r0: int, n: int, latest: bool) -> tuple[np.ndarray, ...]:
        """(hits, through, switches[, latest hit]) of ``grid``'s rows r0 … r0 + n − 1 (clipped to the grid), as
        :meth:`window` and :meth:`latest_hit` give them on those rows: a band of the windows read from the tiles
        without the whole windows (:func:`clean_windows`)."""
        H, W = grid.shape
        n = max(min(n, H - r0), 0)
        g = self._overlap(grid)
        channels = (_HIT, _THROUGH, _SWITCH, _LAST) if latest else (_HIT, _THROUGH, _SWITCH)
        if g is None:
            out = [np.zeros((n, W), dtype=np.uint16) for _ in channels]
        else:
            gi0, gj0 = g
            out = _tile_channels(self._table, self._pool, gj0 - (self._tj0 << _TILE_SHIFT) + r0,
                                 gi0 - (self._ti0 << _TILE_SHIFT), n, W, channels)
        if latest:
            out[3] = (out[3] & 1) == 1
        return tuple(out)


@dataclass(eq=False)
class CleanResult:
    """The cleaned map and what the pass did.

    Attributes:
        grid: the cleaned map (erased cells at :data:`ERASED_PROBABILITY`), same cells as the online map.
        logodds: its log-odds (same cells), or None if no online log-odds was given; with ``keep_counts`` False
            a :class:`CleanedLogodds` (made when read: ``np.asarray``).
        erased: (H, W) bool, cells occupied in the online map that the pass erased.
        hits, through: (H, W) uint16, scans that hit / passed through each cell (saturating at
            :data:`COUNT_MAX`).
        switches: (H, W) uint16, changes between hit and pass in each cell's scan sequence.
        stats: numbers for summary.json / metrics.json (cells, m², seconds).
        restored: (H, W) bool, cells observed free in the online map that the pass put back as occupied (at
            :data:`RESTORED_PROBABILITY`), or None when not computed.
    """

    grid: GridMap
    logodds: np.ndarray | CleanedLogodds | None
    erased: np.ndarray
    hits: np.ndarray
    through: np.ndarray
    switches: np.ndarray
    stats: dict[str, float | int] = field(default_factory=dict)
    restored: np.ndarray | None = None


#: :class:`GridMap`'s own storage of ``prob`` (a slot), under :class:`_CleanedGrid`'s property
_PROB_SLOT = GridMap.__dict__["prob"]


def _mark_probs(prob: np.ndarray, erased: np.ndarray, restored: np.ndarray) -> np.ndarray:
    """``prob`` (probabilities, in place) with the erased cells at :data:`ERASED_PROBABILITY` and the restored ones
    at :data:`RESTORED_PROBABILITY`: the cleaned map's values; returns ``prob``."""
    prob[erased] = ERASED_PROBABILITY
    prob[restored] = RESTORED_PROBABILITY
    return prob


def _mark_logodds(lo: np.ndarray, erased: np.ndarray, restored: np.ndarray) -> np.ndarray:
    """``lo`` (log-odds, in place) with the erased and restored cells at the logits of :data:`ERASED_PROBABILITY`
    and :data:`RESTORED_PROBABILITY`: the cleaned log-odds; returns ``lo``."""
    lo[erased] = math.log(ERASED_PROBABILITY / (1.0 - ERASED_PROBABILITY))
    lo[restored] = math.log(RESTORED_PROBABILITY / (1.0 - RESTORED_PROBABILITY))
    return lo


class _CleanedGrid(GridMap):
    """The cleaned map as :func:`clean_windows` makes it — the online map's probabilities, erased cells at
    :data:`ERASED_PROBABILITY`, restored ones at :data:`RESTORED_PROBABILITY` — made when ``prob`` is first read,
    not at the end of the pass: the pass's end and the results' start no longer hold a second float64 map beside
    the online one (8 bytes a cell, 14.5 MB on MIT CSAIL; issue 13 item 3). Until then it holds the online map and
    the two masks (which must not change before); afterwards it is a plain :class:`GridMap`."""

    __slots__ = ("_parts",)

    def __init__(self, online: GridMap, erased: np.ndarray, restored: np.ndarray) -> None:  # noqa: D107
        self._parts: tuple[GridMap, np.ndarray, np.ndarray] | None = (online, erased, restored)
        self.resolution = online.resolution
        self.origin = online.origin

    @property  # type: ignore[override]
    def prob(self) -> np.ndarray:
        parts = self._parts
        if parts is not None:
            online, erased, restored = parts
            _PROB_SLOT.__set__(self, _mark_probs(online.prob.copy(), erased, restored))
            self._parts = None
        return _PROB_SLOT.__get__(self)

    @prob.setter
    def prob(self, value: np.ndarray) -> None:
        _PROB_SLOT.__set__(self, np.asarray(value, dtype=np.float64))
        self._parts = None

    def make_over(self, online: GridMap) -> bool:
        """Make the cleaned probabilities in ``online``'s own array (the same values ``prob`` makes in a copy) when
        this map is not made yet and was made from ``online``; True if so. ``online`` must not be read afterwards
        (its ``prob`` is this map's, cleaned): for a caller done with the online map (the results' files, once the
        online map's are written; issue 13 item 3: one float64 map instead of two)."""
        parts = self._parts
        if parts is None or parts[0] is not online or not online.prob.flags.writeable:
            return False
        _, erased, restored = parts
        _PROB_SLOT.__set__(self, _mark_probs(online.prob, erased, restored))
        self._parts = None
        return True

    @property
    def shape(self) -> tuple[int, int]:
        parts = self._parts
        return parts[0].shape if parts is not None else _PROB_SLOT.__get__(self).shape  # (without making it)


class CleanedLogodds:
    """The cleaned log-odds as :func:`clean_windows` makes them — a copy of the online map's log-odds (in
    ``dtype``), erased cells at logit(:data:`ERASED_PROBABILITY`), restored ones at
    logit(:data:`RESTORED_PROBABILITY`) — without the copy: ``np.asarray`` makes it (a new array each time) and
    :meth:`write_npy` writes its ``.npy`` file a band of rows at a time (the bytes ``np.save`` writes of the
    copy). The pass's end and the results' map files then hold the online log-odds only (4 bytes a cell, 7.3 MB
    on MIT CSAIL; issue 13 item 3). The online log-odds and the two masks must not change while it is read."""

    __slots__ = ("_logodds", "_erased", "_restored", "dtype")

    def __init__(self, logodds: np.ndarray, erased: np.ndarray, restored: np.ndarray, dtype: np.dtype) -> None:  # noqa: D107
        self._logodds, self._erased, self._restored, self.dtype = logodds, erased, restored, np.dtype(dtype)

    @property
    def shape(self) -> tuple[int, int]:
        return self._logodds.shape

    def _rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows r0 … r1 − 1 of the cleaned log-odds (a new array)."""
        lo = np.array(self._logodds[r0:r1], dtype=self.dtype, copy=True)
        return _mark_logodds(lo, self._erased[r0:r1], self._restored[r0:r1])

    def __array__(self, dtype: np.dtype | None = None, copy: bool | None = None) -> np.ndarray:
        lo = self._rows(0, self.shape[0])
        return lo if dtype is None else lo.astype(dtype, copy=False)

    def write_npy(self, fh: object, dtype: np.dtype = np.float32) -> None:
        """The ``.npy`` file of ``np.asarray(self, dtype)`` into the binary file ``fh``, :data:`_RULE_ROWS` rows
        at a time: format 1.0's header as ``np.save`` writes it for a C-ordered array, then the rows' bytes."""
        dt = np.dtype(dtype)
        np.lib.format.write_array_header_1_0(fh, {"descr": np.lib.format.dtype_to_descr(dt), "fortran_order": False,
                                                  "shape": self.shape})
        for r0 in range(0, self.shape[0], _RULE_ROWS):
            fh.write(self._rows(r0, r0 + _RULE_ROWS).astype(dt, copy=False).tobytes())  # type: ignore[attr-defined]


def restore_rule(hits: np.ndarray, through: np.ndarray, config: CleanConfig) -> np.ndarray:
    """Cells (bool, same shape) hit often and (almost) never seen through: ``H ≥ restore_min_hits`` and
    ``T ≤ restore_through_ratio·H`` (all False when ``restore_min_hits`` is 0). Applied to the online map's
    observed free cells, these are the wall cells that Hector's update let rays running along the wall clear
    (module docstring)."""
    c = config
    if c.restore_min_hits <= 0:
        return np.zeros(hits.shape, dtype=bool)
    return (hits >= c.restore_min_hits) & (through <= c.restore_through_ratio * hits)


def erase_rule(hits: np.ndarray, through: np.ndarray, switches: np.ndarray, config: CleanConfig,
               latest_hit: np.ndarray | None = None) -> np.ndarray:
    """Cells (bool, same shape) that were seen through often enough, relative to their hits,
    in few blocks: ``T ≥ min_through``, ``T ≥ through_ratio·H`` and
    ``S ≤ max_switches + switch_share·min(H, T)`` (module docstring). With ``latest_hit`` (the cell's latest
    counted touch was a hit, :meth:`VisibilityCounter.latest_hit`), cells hit at least ``rehit_min_hits`` times
    whose first and latest touches were both hits (``S`` even and ≥ 2, latest a hit: hit, seen through, hit
    again) are left out (``rehit_min_hits`` 0: none)."""
    c = config
    out = ((through >= c.min_through) & (through >= c.through_ratio * hits)
           & (switches <= c.max_switches + c.switch_share * np.minimum(hits, through)))
    if c.rehit_min_hits > 0 and latest_hit is not None:
        out &= ~(latest_hit & (switches >= 2) & (switches % 2 == 0) & (hits >= c.rehit_min_hits))
    return out


#: Rows of the map :func:`clean_map` applies the erase rule to at a time (the rule's ratios are float64).
_RULE_ROWS = 256


@dataclass(eq=False)
class CountWindows:
    """What :func:`clean_map` reads from a :class:`VisibilityCounter`, on the online map's cells: the count windows
    (:meth:`VisibilityCounter.window`), the latest-touch mask (None when the rule does not use it) and the counter's
    numbers for the stats. Taking them first lets a caller free the counter before the cleaned copies are made.
    :meth:`banded` instead holds the counter (:attr:`counter`) and no windows: :func:`clean_windows` reads them a
    band of rows at a time from its tiles and lets the counter go once the rules are applied."""

    hits: np.ndarray
    through: np.ndarray
    switches: np.ndarray
    latest_hit: np.ndarray | None
    config: CleanConfig
    scans: int
    too_large: int
    seconds: float
    nbytes: int
    #: the counter the windows are read from band by band (:meth:`banded`), None when they are held
    counter: VisibilityCounter | None = None

    @classmethod
    def of(cls, online: GridMap, counter: VisibilityCounter) -> CountWindows:
        c = counter.config
        hits, through, switches = counter.window(online)
        latest_hit = counter.latest_hit(online) if c.rehit_min_hits > 0 else None
        return cls(hits, through, switches, latest_hit, c, int(counter.scans), int(counter.too_large),
                   float(counter.seconds), counter.nbytes)

    @classmethod
    def banded(cls, counter: VisibilityCounter) -> CountWindows:
        """The counter's numbers and the counter itself, no dense window (0 × 0): for :func:`clean_windows` with
        ``keep_counts`` False, which reads the windows :data:`_RULE_ROWS` rows at a time (issue 13 item 3: the
        three uint16 windows and the latest-hit mask, 7 bytes a cell, never live beside the counter's tiles)."""
        empty = np.zeros((0, 0), dtype=np.uint16)
        return cls(empty, empty, empty, None, counter.config, int(counter.scans), int(counter.too_large),
                   float(counter.seconds), counter.nbytes, counter)


def _prob_rows(grid: GridMap, r0: int, r1: int) -> np.ndarray:
    """Rows ``r0`` … ``r1`` − 1 of ``grid.prob``; from a map that makes its probabilities when read and offers them
    by rows (``prob_rows``: :class:`dynslam2d.pipeline.ExportGridMap`), without making the whole map."""
    rows = getattr(grid, "prob_rows", None)
    return rows(r0, r1) if rows is not None else grid.prob[r0:r1]


def clean_map(online: GridMap, counter: VisibilityCounter, logodds: np.ndarray | None = None,
              occupied_threshold: float = 0.65) -> CleanResult:
    """Erase the cells of ``online`` (occupied: p > ``occupied_threshold``) that ``counter``
    saw through often enough (rule in the module docstring). ``logodds``: the online
    map's raw log-odds (same cells), returned cleaned alongside."""
    t0 = time.perf_counter()
    return clean_windows(online, CountWindows.of(online, counter), logodds, occupied_threshold, t0=t0)


def clean_windows(online: GridMap, counts: CountWindows, logodds: np.ndarray | None = None,
                  occupied_threshold: float = 0.65, keep_counts: bool = True, t0: float | None = None) -> CleanResult:
    """:func:`clean_map` from the counts read off the counter (:meth:`CountWindows.of`). With ``keep_counts``
    False the result's count windows are empty (0 × 0) and ``counts`` lets go of them once the rules are
    applied, before the cleaned copies of the map are made (issue 13 item 3: the command line keeps only the
    map, the erased cells and the stats), and the result's float64 map is made when first read
    (:class:`_CleanedGrid`: ``online`` and the result's masks must not change before). ``t0``: when the pass
    started (``time.perf_counter``), for its time."""
    t0 = time.perf_counter() if t0 is None else t0
    c = counts.config
    hits, through, switches, latest_hit = counts.hits, counts.through, counts.switches, counts.latest_hit
    counter = counts.counter
    if counter is not None and keep_counts:
        raise ValueError("banded count windows (CountWindows.banded) are not kept: use keep_counts=False")
    latest = c.rehit_min_hits > 0
    occ = np.empty(online.shape, dtype=bool)
    erased = np.empty(occ.shape, dtype=bool)
    restored = np.empty(occ.shape, dtype=bool)
    for r0 in range(0, occ.shape[0], _RULE_ROWS):  # a block of rows at a time: no map-sized float64 temporaries
        rows = slice(r0, r0 + _RULE_ROWS)
        # the online map's probabilities a band at a time: a map made when read (the run's, pipeline.ExportGridMap)
        # is not made by the pass (issue 13 item 3, pass mem61)
        prob = _prob_rows(online, r0, r0 + _RULE_ROWS)
        occ[rows] = GridMap(prob, online.resolution, online.origin).occupied(occupied_threshold)
        if counter is not None:  # (the band of the windows, read from the counter's tiles)
            band = counter.rows(online, r0, _RULE_ROWS, latest)
            h_r, t_r, s_r, l_r = band[0], band[1], band[2], band[3] if latest else None
            del band
        else:
            h_r, t_r, s_r = hits[rows], through[rows], switches[rows]
            l_r = None if latest_hit is None else latest_hit[rows]
        erased[rows] = erase_rule(h_r, t_r, s_r, c, l_r) & occ[rows]
        # observed free in the online map (unknown cells were never cleared: nothing to restore there)
        restored[rows] = restore_rule(h_r, t_r, c) & ~occ[rows] & np.isfinite(prob)
        del h_r, t_r, s_r, l_r, prob
    del counter
    if not keep_counts:
        empty = np.zeros((0, 0), dtype=np.uint16)
        hits = through = switches = counts.hits = counts.through = counts.switches = empty
        latest_hit = counts.latest_hit = None
        counts.counter = None  # (the counter's tiles, when the caller let go of it too)
        # the windows (2 bytes a cell each: below the allocator's mmap threshold on most maps, so their memory stays
        # in the heap when freed) go back to the OS before the cleaned copies are made (memtrim.py)
        release_free_memory()
    if c.revert_neighbors > 0:
        # Removert's "revert" step in 2D: a cell at the edge of structure that stays is kept.
        from scipy.ndimage import convolve

        kept = (occ & ~erased).astype(np.int16)
        n_kept = convolve(kept, np.ones((3, 3), dtype=np.int16), mode="constant") - kept
        del kept
        erased &= n_kept < c.revert_neighbors
        del n_kept
    n_occ = int(occ.sum())
    del occ  # (one byte a cell) before the cleaned copies are made, the pass's highest point (issue 13 item 3)
    if keep_counts:
        grid = GridMap(_mark_probs(online.prob.copy(), erased, restored), online.resolution, online.origin)
    else:  # (the command line's pass: the cleaned float64 map made when the results first read it)
        grid = _CleanedGrid(online, erased, restored)
    lo = None
    if logodds is not None:
        # the input's dtype (the SLAM's log-odds are float32, written as float32): no float64 copy of the map
        dtype = np.result_type(logodds, np.float32)
        if not keep_counts and np.shape(logodds) == erased.shape:  # (the command line's: made when read, or written)
            lo = CleanedLogodds(logodds, erased, restored, dtype)
        else:
            lo = np.array(logodds, dtype=dtype, copy=True)
            if lo.shape == erased.shape:
                _mark_logodds(lo, erased, restored)
    area = online.resolution ** 2
    stats: dict[str, float | int] = {
        "occupied_cells_online": n_occ,
        "erased_cells": int(erased.sum()),
        "erased_area_m2": float(erased.sum() * area),
        "restored_cells": int(restored.sum()),
        "restored_area_m2": float(restored.sum() * area),
        "scans_counted": counts.scans,
        "scans_too_large": counts.too_large,
        "pass_time_s": float(counts.seconds + time.perf_counter() - t0),
        "counter_bytes": counts.nbytes,
    }
    return CleanResult(grid, lo, erased, hits, through, switches, stats, restored)


def compare_online(online: GridMap, cleaned: CleanResult, tolerance: float = 0.10,
                   occupied_threshold: float = 0.65) -> dict[str, float | int]:
    """How much of the online map's structure the cleaned map still holds (same cells).

    ``f1``: F1 of the cleaned occupied cells against the online ones, cell by cell
    (2·|cleaned| / (|online| + |cleaned|), the cleaned set being a subset);
    ``lost_cells`` / ``lost_area_m2``: online occupied cells farther than ``tolerance`` (m)
    from every cleaned occupied cell, i.e. structure that disappeared rather than got
    thinner; ``lost_share``: their share of the online occupied cells.
    """
    from dynslam2d.eval.maps import distance_to

    occ = online.occupied(occupied_threshold)
    kept = occ & ~cleaned.erased
    n_o, n_k = int(occ.sum()), int(kept.sum())
    lost = occ & (distance_to(kept, online.resolution) > tolerance + 1e-9)
    return {
        "f1": 2.0 * n_k / (n_o + n_k) if n_o + n_k else 1.0,
        "lost_cells": int(lost.sum()),
        "lost_area_m2": float(lost.sum() * online.resolution ** 2),
        "lost_share": float(lost.sum() / n_o) if n_o else 0.0,
        "tolerance_m": float(tolerance),
    }


class CleanupRecorder:
    """Pipeline observer (:class:`dynslam2d.pipeline.RunObserver`) that feeds a
    :class:`VisibilityCounter` with every matched scan and, at the end of the run,
    cleans the final map into :attr:`result`. :attr:`counter_class` builds the counter (a subclass may
    count differently, e.g. ``benchmarks/bench_erased.py`` keeps the counted scans to explain the erasures)."""

    counter_class: type[VisibilityCounter] = VisibilityCounter
    #: it reads only the scan, its result and the pipeline's config: :func:`dynslam2d.pipeline.run` feeds it 32
    #: scans at a time, so its counting does not push the pipeline's arrays out of the CPU caches every scan
    #: (docs/speed.md, pass wall38)
    scan_batch: int = 32

    def __init__(self, config: CleanConfig | None = None, slam: SlamConfig | None = None,
                 keep_counts: bool = True) -> None:
        self.config = config if config is not None else CleanConfig()
        self.slam = slam
        #: False: the counter is let go once the map is cleaned (before the cleaned copies are made) and the
        #: result's count windows are empty (:func:`clean_windows`; the command line needs neither)
        self.keep_counts = bool(keep_counts)
        self.counter: VisibilityCounter | None = None
        self.result: CleanResult | None = None
        self._last_stamp = -math.inf

    def on_scan(self, scan: Scan, step: object, pipeline: object) -> None:
        if not self.config.enabled or step.rejected or step.skipped:  # type: ignore[attr-defined]
            return
        if self.config.scans == "map_updates" and not step.map_updated:  # type: ignore[attr-defined]
            return
        updated = bool(step.map_updated)  # type: ignore[attr-defined]
        if not updated and scan.stamp - self._last_stamp < self.config.min_interval_s - 1e-6:
            return
        self._last_stamp = scan.stamp
        if self.counter is None:
            slam = self.slam if self.slam is not None else pipeline.config.slam  # type: ignore[attr-defined]
            self.counter = self.counter_class(slam.map_resolution, self.config, slam)
        self.counter.add(scan, step.pose, step.removed)  # type: ignore[attr-defined]

    def on_finish(self, result: object, pipeline: object) -> None:
        if not self.config.enabled:
            return
        if self.counter is None:
            slam = pipeline.config.slam  # type: ignore[attr-defined]
            self.counter = self.counter_class(slam.map_resolution, self.config, slam)
        loop = getattr(result, "loop", None)
        if loop is not None and loop.corrected:
            # loop closure moved the poses after counting: count the keyframes (the scans written into the
            # map) again at their optimised poses, so the counts match the re-rendered map (docs/slam.md)
            slam = self.slam if self.slam is not None else pipeline.config.slam  # type: ignore[attr-defined]
            self.counter = None  # the run's counts go before the recount's are allocated
            self.counter = self.counter_class(slam.map_resolution, self.config, slam)
            poses = [Pose2D(float(p[0]), float(p[1]), float(p[2])) for p in loop.node_poses]
            self.counter.reserve([(kf.scan, p) for kf, p in zip(loop.keyframes, poses)])
            for kf, p in zip(loop.keyframes, poses):
                self.counter.add(kf.scan, p, kf.removed if kf.removed.size else None)
        t0 = time.perf_counter()
        if self.keep_counts:
            counts = CountWindows.of(result.grid, self.counter)  # type: ignore[attr-defined]
        else:  # the windows read band by band; the counter (its tiles) goes once the rules are applied
            counts = CountWindows.banded(self.counter)
            self.counter = None
        self.result = clean_windows(result.grid, counts, result.logodds,  # type: ignore[attr-defined]
                                    keep_counts=self.keep_counts, t0=t0)



def _read_only_trig(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of ``angles`` as read-only float64 arrays, the array type :meth:`Scan.trig` gives (numba
    compiles :func:`_scan_geometry` once for it)."""
    a = np.asarray(angles, dtype=np.float64)
    out = (np.cos(a), np.sin(a))
    for arr in out:
        arr.flags.writeable = False
    return out


def scan_clearing(ranges: np.ndarray, angles: np.ndarray | tuple[np.ndarray, np.ndarray], valid: np.ndarray,
                  pose: Pose2D, resolution: float,
                  clean: CleanConfig) -> tuple[tuple[float, float], np.ndarray, np.ndarray, np.ndarray]:
    """The clean-up pass's beam geometry for one scan (docs/maps.md, "What the pass counts"): the laser's
    position and the ends (cx, cy) of the beams' clearing segments, (n,) in world cell units (m /
    ``resolution``), and ``clear`` (n,) bool, the beams with a return (``valid``) longer than their margin
    (``clean.margin_m``, grown to ``clean.grazing_cells · resolution / sin α`` at grazing incidence).
    ``ranges`` / ``angles``: the beams in the laser frame (m, rad), or instead of the angles their (cos, sin)
    (:meth:`Scan.trig`, computed once per laser); ``pose``: the laser pose, map frame."""
    cos_a, sin_a = angles if isinstance(angles, tuple) else _read_only_trig(angles)
    _, _, cx, cy, _, clear = _scan_geometry(np.ascontiguousarray(ranges, dtype=np.float64), cos_a, sin_a,
                                            np.ascontiguousarray(valid, dtype=np.bool_),
                                            np.zeros(ranges.shape[0], dtype=np.bool_), float(pose.x), float(pose.y),
                                            float(pose.theta), float(resolution), float(clean.margin_m),
                                            float(clean.grazing_cells),
                                            math.sin(math.radians(clean.min_incidence_deg)))
    return (float(pose.x) / resolution, float(pose.y) / resolution), cx, cy, clear


__all__ = ["ERASED_PROBABILITY", "RESTORED_PROBABILITY", "CleanResult", "CleanedLogodds", "CleanupRecorder",
           "CountWindows", "VisibilityCounter", "clean_map", "clean_windows", "compare_online", "erase_rule",
           "restore_rule", "scan_clearing"]
