"""Static evidence from the SLAM map: is a point on long-occupied structure or in observed free space?

The map is the strongest witness of what does not move (docs/architecture.md): an endpoint on a cell
that many earlier scans hit is structure; an endpoint in a cell that earlier scans passed
through (log-odds below zero: more free observations than hits) is space that was empty a
moment ago, so whatever returns from there now has moved in. A cell that was never observed
(log-odds 0, e.g. a wall sliding into view as the robot drives) is evidence of neither.

The tracker uses two per-point flags (docs/tracking.md, "Static evidence from the map"):

- **structure**: the point's own cell has log-odds ≥ ``occupied_logodds`` (hector's hit adds
  logit(0.9) = 2.2 and a free pass logit(0.4) = −0.4, so the tracker's default 6.0 needs at
  least three net hits);
- **free**: the point's own cell has log-odds ≤ ``free_logodds`` (default −0.35: at least one net
  free observation) and no cell within ``free_radius`` cells is occupied (log-odds > 0.5): a
  wall point that range noise put one cell in front of the wall still has the wall next to it,
  while the hidden back of a moving object is merely unknown.

Frames: map frame (the finest map level's world coordinates), units m. The map is read only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle

#: no long-occupied bitmap (:class:`MapView`'s default)
_NO_BITS = np.zeros((0, 0), dtype=np.uint64)
#: the log-odds of a view whose level is growing (:meth:`MapView.detach`)
_NO_LOGODDS = np.zeros((0, 0), dtype=np.float32)


@dataclass(frozen=True, slots=True, eq=False, weakref_slot=True)
class MapView:
    """Read-only view of one log-odds grid level.

    Attributes:
        logodds: (H, W) float32 log-odds, indexed [row, col] = [y, x] in cells; 0 = unknown.
        i0, j0: absolute cell index of column 0 / row 0 (cell (i, j) is centred at (i·res, j·res)).
        resolution: cell side, m.
        occ_bits, occ_bits_thr: the level's long-occupied bitmap and its threshold (``GridLevel.occ_bits``: every
            cell with log-odds ≥ the threshold has its bit set), or a (0, 0) array and NaN: none.
    """

    logodds: np.ndarray
    i0: int
    j0: int
    resolution: float
    occ_bits: np.ndarray = field(default_factory=lambda: _NO_BITS)
    occ_bits_thr: float = math.nan

    @classmethod
    def of_level(cls, level: object) -> MapView | None:
        """A view of a :class:`dynslam2d.slam.grid.GridLevel` (None while the level is empty). It follows the
        level's growth (``GridLevel.follow``): when the level grows it is pointed at the grown arrays and offsets,
        the same cells with the same values, as a view made after the growth (it views the level's live arrays,
        as any view does between growths), and it never keeps the old arrays alive while the level copies them
        (docs/speed.md, pass mem120)."""
        lo = level.logodds
        if lo.size == 0:
            return None
        view = cls(lo, int(level.i0), int(level.j0), float(level.resolution),
                   getattr(level, "occ_bits", _NO_BITS), float(getattr(level, "occ_bits_thr", math.nan)))
        follow = getattr(level, "follow", None)
        if follow is not None:
            follow(view)
        return view

    def detach(self) -> None:
        """Let go of the level's arrays while it grows (``GridLevel.follow``): empty arrays until :meth:`follow`."""
        object.__setattr__(self, "logodds", _NO_LOGODDS)  # (frozen to its readers; only its level re-points it)
        object.__setattr__(self, "occ_bits", _NO_BITS)

    def follow(self, level: object) -> None:
        """Take ``level``'s current arrays and offsets (after its growth), as :meth:`of_level` would."""
        for name, value in (("logodds", level.logodds), ("i0", int(level.i0)), ("j0", int(level.j0)),
                            ("resolution", float(level.resolution)),
                            ("occ_bits", getattr(level, "occ_bits", _NO_BITS)),
                            ("occ_bits_thr", float(getattr(level, "occ_bits_thr", math.nan)))):
            object.__setattr__(self, name, value)


@njit(cache=True)
def map_evidence_kernel(px: np.ndarray, py: np.ndarray, logodds: np.ndarray, i0: int, j0: int, res: float,
                        occ_thr: float, free_thr: float, free_radius: int, structure: np.ndarray,
                        free: np.ndarray, unknown: np.ndarray, near_thr: float = 0.5) -> None:
    """Fill ``structure`` / ``free`` (n,) bool for the map-frame points (``px``, ``py``, m): the point's
    cell is long-occupied (log-odds ≥ ``occ_thr``); the point's cell is observed free (log-odds ≤
    ``free_thr``) with no occupied cell (log-odds > ``near_thr``) within ``free_radius``; ``unknown``: the point's cell
    was never observed (log-odds 0, or outside the grid)."""
    h = logodds.shape[0]
    w = logodds.shape[1]
    for i in range(px.shape[0]):
        structure[i] = False
        free[i] = False
        unknown[i] = True
        x = px[i]
        y = py[i]
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        cx = int(np.floor(x / res + 0.5)) - i0  # hector's cell rounding (slam/grid.py)
        cy = int(np.floor(y / res + 0.5)) - j0
        if cx < 0 or cy < 0 or cx >= w or cy >= h:
            continue
        unknown[i] = logodds[cy, cx] == 0.0
        if logodds[cy, cx] >= occ_thr:
            structure[i] = True
            continue
        if logodds[cy, cx] > free_thr:
            continue
        ok = True
        for dy in range(-free_radius, free_radius + 1):
            for dx in range(-free_radius, free_radius + 1):
                yy = cy + dy
                xx = cx + dx
                if 0 <= yy < h and 0 <= xx < w and logodds[yy, xx] > near_thr:
                    ok = False
                    break
            if not ok:
                break
        free[i] = ok


def map_evidence(points: np.ndarray, view: MapView | None, occupied_logodds: float = 6.0,
                 free_logodds: float = -0.35, free_radius: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(structure, free, unknown): three (n,) bool arrays for the (n, 2) map-frame points (module docstring;
    unknown = the point's cell was never observed).

    Example:
        >>> import numpy as np
        >>> lo = np.zeros((5, 5), dtype=np.float32); lo[2, 2] = 7.0; lo[:, 4] = -1.0
        >>> s, f, u = map_evidence(np.array([[0.0, 0.0], [0.15, 0.0]]), MapView(lo, -2, -2, 0.05))
        >>> s.tolist(), f.tolist(), u.tolist()
        ([True, False], [False, False], [False, True])
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    structure = np.zeros(n, dtype=bool)
    free = np.zeros(n, dtype=bool)
    unknown = np.ones(n, dtype=bool)
    if view is None or n == 0:
        return structure, free, unknown
    map_evidence_kernel(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), view.logodds,
                        int(view.i0), int(view.j0), float(view.resolution), float(occupied_logodds),
                        float(free_logodds), int(free_radius), structure, free, unknown)
    return structure, free, unknown


# ----------------------------------------------------------------------------- vacated footprints
#
# A vehicle parked since before the robot saw the place is in the map: its outline is long-occupied, so the
# structure test above calls its points structure, and while it drives off its own outline (about its
# length) it cannot be a mover. What tells it from a wall is the scan itself: beams of the current scan pass
# through long-occupied cells of its outline where it no longer stands. A wall is never seen through (the
# clean-up pass's tolerances, docs/maps.md, keep grazing rays and pose error from looking so). When a small,
# bounded outline of long-occupied cells is seen through in enough cells, the whole outline "yields": for
# the map evidence of this scan its cells count as observed free, not structure (docs/maps.md, "Vacated
# footprints").


#: the most steps :func:`_free_steps` looks ahead per octant (a line costs up to ``cap`` + 5 reads, a skipped step of
#: the walk's beams in the octant about one each: farther lines seldom pay)
_FREE_CAP = 64


@njit(cache=True)
def _free_steps(logodds: np.ndarray, i0: int, j0: int, ox: float, oy: float, occ_thr: float, cap: int,
                out: np.ndarray) -> None:  # pragma: no cover - numba
    """How many steps of a ray from the laser (``ox``, ``oy``, world cell units) surely pass no cell with log-odds ≥
    ``occ_thr``, per octant: ``out[2 · q + s]`` for the major axis and direction ``q`` (0: +x, 1: −x, 2: +y, 3: −y)
    and the side ``s`` of the minor coordinate (0: it grows along the ray, 1: it shrinks) is the largest ``d`` ≤
    ``cap`` such that the lines ``0 … d`` of the major axis from the laser's cell hold no such cell from the laser's
    minor cell − 2 to + line + 2 on that side (off the grid counts as none); −1 everywhere with the laser off the
    grid.

    Step ``t`` of :func:`seen_through_structure_kernel`'s walk lies on line ``t`` (the laser inside the grid: the
    walk starts at its cell) and, its slope at most 1 in magnitude and the laser within half a cell of its cell's
    centre, its minor cell within −1 … ``t`` + 1 of the laser's on its side: steps ``t`` ≤ ``out`` have no hit (one
    more cell each side against rounding).

    One loop reads every octant's lines in the flat map (a line is a column segment for ±x, a row segment for ±y:
    the minor axis' stride is the row length or 1); a free square first and both axes' loops of their own read a
    little less but compile ≈ 0.3 s longer (docs/speed.md, pass det38)."""
    h = logodds.shape[0]
    w = logodds.shape[1]
    c = int(math.floor(ox + 0.5)) - i0
    r = int(math.floor(oy + 0.5)) - j0
    if r < 0 or c < 0 or r >= h or c >= w:
        for q in range(8):
            out[q] = -1
        return
    flat = logodds.ravel()
    for q in range(8):
        xq = q < 4
        sgn = 1 if q < 2 or 4 <= q < 6 else -1  # (q // 2: +x, −x, +y, −y)
        grow = q % 2 == 0
        # (the laser's major cell and the major axis' length; its minor cell, length and stride in the flat map)
        p, np_ = (c, w) if xq else (r, h)
        m, nm, sm = (r, h, w) if xq else (c, w, 1)
        d = 0
        while d <= cap:
            a = p + sgn * d
            if a < 0 or a >= np_:  # (the rest of the walk is off the grid: no step reads it)
                d = cap + 1
                break
            base = (a if xq else a * w)
            lo_b = max(m + (-2 if grow else -d - 2), 0)
            hi_b = min(m + (d + 2 if grow else 2), nm - 1)
            hit = False
            for b in range(lo_b, hi_b + 1):
                hit |= flat[base + b * sm] >= occ_thr
            if hit:
                break
            d += 1
        out[q] = min(d - 1, cap)


@njit(cache=True)
def seen_through_structure_kernel(logodds: np.ndarray, i0: int, j0: int, ox: float, oy: float, cx: np.ndarray,
                                  cy: np.ndarray, clear: np.ndarray, core: float, occ_thr: float,
                                  out_r: np.ndarray, out_c: np.ndarray, depth: float = 0.0) -> int:  # pragma: no cover
    """Cells with log-odds ≥ ``occ_thr`` that the clearing segments from (``ox``, ``oy``) to (``cx``, ``cy``)
    (world cell units, m / resolution; only where ``clear``) pass through within ``core`` cells of the cell
    centre across the ray's major axis (the traversal of :func:`dynslam2d.slam.cleanup._mark_ray`), and at
    least ``depth`` (cells) nearer to the origin than the clearing ends of the beam and both its neighbours
    (``k ± 1``, which must clear).
    Writes array rows / columns into ``out_r`` / ``out_c`` (possibly repeated) and returns their number
    (at most the arrays' length)."""
    h = logodds.shape[0]
    w = logodds.shape[1]
    cap = out_r.shape[0]
    flat = logodds.ravel()  # (a view: the map is C-contiguous)
    # the steps near the laser that no long-occupied cell can be on, per octant (the first pass starts after them)
    free = np.empty(8, dtype=np.int64)
    _free_steps(logodds, i0, j0, ox, oy, occ_thr, _FREE_CAP, free)
    n = 0
    for k in range(1, cx.shape[0] - 1):
        # both neighbouring beams must clear at least as far: the silhouette edge of a round object (a ray
        # tangent to it, a neighbour ending on it) does not see through it
        if not (clear[k] and clear[k - 1] and clear[k + 1]):
            continue
        # (min of two, twice: numba compiles min/max once per argument count and type, and its 3-argument forms
        # served only this kernel; the same comparisons in the same order as min of three)
        reach = math.sqrt(min(min((cx[k - 1] - ox) ** 2 + (cy[k - 1] - oy) ** 2,
                                  (cx[k + 1] - ox) ** 2 + (cy[k + 1] - oy) ** 2),
                              (cx[k] - ox) ** 2 + (cy[k] - oy) ** 2)) - depth
        if not reach > 0.0:
            continue
        reach2 = reach * reach
        dx = cx[k] - ox
        dy = cy[k] - oy
        # walk the major axis a (array axis 1 − ar), the minor coordinate b of the ray at a (array axis 1 − br)
        x_major = abs(dx) >= abs(dy)
        if x_major:
            a0 = int(math.floor(ox + 0.5))
            a1 = int(math.floor(cx[k] + 0.5))
            slope = dy / dx if dx != 0.0 else 0.0
            m0, n0 = ox, oy
            a_off, a_len, b_off, b_len, ar, br = i0, w, j0, h, 0, 1
        else:
            a0 = int(math.floor(oy + 0.5))
            a1 = int(math.floor(cy[k] + 0.5))
            slope = dx / dy
            m0, n0 = oy, ox
            a_off, a_len, b_off, b_len, ar, br = j0, h, i0, w, 1, 0
        # only a inside the grid and within the reach: a cell the ray passes within core ≤ 0.5 of its centre at
        # a is at least |a − m0|·√(1 + slope²) − 0.5 from the laser (+1 against rounding: the distance test
        # below is the exact one)
        along = (reach + 0.5) / math.sqrt(1.0 + slope * slope)
        if a1 >= a0:
            step = 1
            start = max(a0, a_off)
            cnt = min(min(a1, int(math.floor(m0 + along)) + 1), a_off + a_len - 1) - start + 1
        else:
            step = -1
            start = min(a0, a_off + a_len - 1)
            cnt = start - max(max(a1, int(math.ceil(m0 - along)) - 1), a_off) + 1
        if cnt <= 0:  # (no step inside the grid: a laser outside it walking away; the pass from the first to the
            continue  # last hit below would run from t = cnt to −1, off the grid)
        # (−1 with the laser off the grid: its walk starts at the grid's edge, not at its cell)
        skip = min(free[(0 if x_major else 4) + (0 if step == 1 else 2) + (0 if slope * step >= 0.0 else 1)] + 1,
                   cnt)
        # a branch-free first pass (it vectorises): most beams pass no long-occupied cell at all. One loop per major
        # axis, each reading the flat map at row · w + column (no per-cell choice of the axes: ≈ ×0.85 on negative_2)
        first = cnt
        last = -1
        if x_major:  # (a: the column, b: the row)
            for t in range(skip, cnt):
                a = start + step * t
                bi = int(math.floor(n0 + slope * (a - m0) + 0.5)) - b_off
                inside = (bi >= 0) & (bi < b_len)
                bi = bi if inside else 0
                hit = inside & (flat[bi * w + (a - a_off)] >= occ_thr)
                first = min(first, t if hit else cnt)
                last = max(last, t if hit else -1)
        else:  # (a: the row, b: the column)
            for t in range(skip, cnt):
                a = start + step * t
                bi = int(math.floor(n0 + slope * (a - m0) + 0.5)) - b_off
                inside = (bi >= 0) & (bi < b_len)
                bi = bi if inside else 0
                hit = inside & (flat[(a - a_off) * w + bi] >= occ_thr)
                first = min(first, t if hit else cnt)
                last = max(last, t if hit else -1)
        for t in range(first, last + 1):
            a = start + step * t
            b = n0 + slope * (a - m0)
            ib = int(math.floor(b + 0.5))
            bi = ib - b_off
            row = ar * (a - a_off) + br * bi  # (the cell (x, y) = (a, ib) or (ib, a): row y − j0, column x − i0)
            col = (1 - ar) * (a - a_off) + (1 - br) * bi
            if bi < 0 or bi >= b_len or abs(b - ib) > core or logodds[row, col] < occ_thr:
                continue
            # (x − ox)² + (y − oy)² in either axis order: the same two terms, and IEEE addition commutes
            if n < cap and (a - m0) ** 2 + (ib - n0) ** 2 <= reach2:
                out_r[n] = row
                out_c[n] = col
                n += 1
    return n


@njit(cache=True)
def vacated_outlines_kernel(logodds: np.ndarray, i0: int, j0: int, ox: float, oy: float, cx: np.ndarray,
                            cy: np.ndarray, clear: np.ndarray, core: float, occ_thr: float, depth: float,
                            near_thr: float, occ32: np.float32, max_side: int, min_cells: int, res: float,
                            min_extent: float, min_share: float
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:  # pragma: no cover - numba
    """The long-occupied cells the beams see through (:func:`seen_through_structure_kernel`, arguments up to
    ``depth`` as there, at most 64 per beam), their outlines and which of them yield (:func:`vacated_outlines`):
    :func:`vacated_core` with buffers of its own."""
    n = cx.shape[0]
    cap = max_side * max_side + 1
    seen = np.empty((2 * max_side + 1, 2 * max_side + 1), dtype=np.uint8)
    seen[:] = 0
    return vacated_core(logodds, i0, j0, ox, oy, cx, cy, clear, core, occ_thr, depth, near_thr, occ32, max_side,
                        min_cells, res, min_extent, min_share, np.empty(64 * n, dtype=np.int64),
                        np.empty(64 * n, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64),
                        seen)


@njit(cache=True)
def vacated_core(logodds: np.ndarray, i0: int, j0: int, ox: float, oy: float, cx: np.ndarray, cy: np.ndarray,
                 clear: np.ndarray, core: float, occ_thr: float, depth: float, near_thr: float, occ32: np.float32,
                 max_side: int, min_cells: int, res: float, min_extent: float, min_share: float, out_r: np.ndarray,
                 out_c: np.ndarray, gr: np.ndarray, gc: np.ndarray, window: np.ndarray, n_seen: int = -1
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:  # pragma: no cover - numba
    """:func:`vacated_outlines_kernel` on buffers the caller keeps between scans: ``out_r`` / ``out_c`` (64 ·
    beams) for the seen-through cells, ``gr`` / ``gc`` (``max_side``² + 1) for a growth, ``window``
    (2 · ``max_side`` + 1 square, all 0; left all 0) for the cells of a growth.

    Nothing when fewer than ``min_cells`` cells are seen through. Else the distinct seen-through cells are taken in
    order of their code ``row · W + col``; each one not yet in an outline grows its 8-connected component of cells
    with log-odds > ``near_thr`` (breadth first). A component spanning more than ``max_side`` cells along a grid
    axis (a wall, not an object) is abandoned as soon as its cells so far show it; every cell grown so far
    belongs to it, so none of them starts another growth. A complete outline yields when its longer side
    (cells · ``res``, m) is more than ``min_extent`` (m) and it holds at least ``min_cells`` seen-through cells
    and ``min_share`` of its cells with log-odds ≥ ``occ32``: ``occ_thr`` in float32, as NumPy compares the
    float32 map with a Python float.
    Returns the yielding outlines' rows and columns, one outline after the other (each in its growth order),
    their sizes and the number of distinct seen-through cells (0 when fewer than ``min_cells`` were found).
    ``n_seen`` ≥ 0: the caller found the seen-through cells already (the same cells with the same repeats, in any
    order: ``out_r`` / ``out_c``' first ``n_seen``; ``dynslam2d.vacated``'s inverse form), the walk is not run.
    """
    n = n_seen if n_seen >= 0 else seen_through_structure_kernel(logodds, i0, j0, ox, oy, cx, cy, clear, core,
                                                                 occ_thr, out_r, out_c, depth)
    if n < min_cells:
        return out_r[:0], out_c[:0], out_r[:0], 0
    h = logodds.shape[0]
    w = logodds.shape[1]
    # the distinct codes, ascending (a Shell sort here: np.unique would add numba's sort to the cold compile)
    codes = np.empty(n, dtype=np.int64)
    for i in range(n):
        codes[i] = out_r[i] * w + out_c[i]
    gap = n // 2
    while gap > 0:
        for i in range(gap, n):
            v = codes[i]
            j = i
            while j >= gap and codes[j - gap] > v:
                codes[j] = codes[j - gap]
                j -= gap
            codes[j] = v
        gap //= 2
    nc = 0
    for i in range(n):
        if nc == 0 or codes[i] != codes[nc - 1]:
            codes[nc] = codes[i]
            nc += 1
    codes = codes[:nc]
    comp_r = np.empty(0 if nc < min_cells else 1024, dtype=np.int64)
    comp_c = np.empty(comp_r.shape[0], dtype=np.int64)
    sizes = np.empty(nc, dtype=np.int64)
    if nc < min_cells:
        return comp_r, comp_c, sizes[:0], nc
    done = np.empty(nc, dtype=np.bool_)
    done[:] = False
    side = 2 * max_side + 1  # window: cells of the current growth, around its start
    # a growth stops once its cells span more than max_side along an axis: it never holds more than max_side² + 1
    cap = max_side * max_side + 1
    k = 0
    total = 0
    for s in range(nc):
        if done[s]:
            continue
        r0 = codes[s] // w
        c0 = codes[s] - r0 * w
        gr[0] = r0
        gc[0] = c0
        window[max_side, max_side] = 1
        m = 1
        head = 0
        rmin = rmax = r0
        cmin = cmax = c0
        ok = True
        while head < m and ok:
            r = gr[head]
            c = gc[head]
            head += 1
            for dr in range(-1, 2):
                if not ok:
                    break
                for dc in range(-1, 2):
                    rr = r + dr
                    cc = c + dc
                    if (dr == 0 and dc == 0) or rr < 0 or cc < 0 or rr >= h or cc >= w:
                        continue
                    if logodds[rr, cc] <= near_thr:
                        continue
                    lr = rr - r0 + max_side
                    lc = cc - c0 + max_side
                    if lr < 0 or lc < 0 or lr >= side or lc >= side:
                        ok = False
                        break
                    if window[lr, lc]:
                        continue
                    window[lr, lc] = 1
                    if m >= cap:
                        ok = False
                        break
                    gr[m] = rr
                    gc[m] = cc
                    m += 1
                    rmin = min(rmin, rr)
                    rmax = max(rmax, rr)
                    cmin = min(cmin, cc)
                    cmax = max(cmax, cc)
                    if rmax - rmin + 1 > max_side or cmax - cmin + 1 > max_side:
                        ok = False
                        break
        for q in range(m):
            window[gr[q] - r0 + max_side, gc[q] - c0 + max_side] = 0
        if not ok and logodds[r0, c0] <= near_thr:
            # a start below near_thr joins the components around it: only it is known to fail
            done[s] = True
            continue
        seen = 0
        longocc = 0
        for q in range(m):
            # a seen-through cell is ≥ occ_thr, so ≥ occ32 (float32 rounds to nearest)
            if logodds[gr[q], gc[q]] >= occ32:
                longocc += 1
                code = gr[q] * w + gc[q]
                p = 0
                hi = nc
                while p < hi:
                    mid = (p + hi) // 2
                    if codes[mid] < code:
                        p = mid + 1
                    else:
                        hi = mid
                if p < nc and codes[p] == code:
                    done[p] = True
                    seen += 1
        if ok and seen >= min_cells and max(rmax - rmin, cmax - cmin) * res > min_extent and \
                seen >= min_share * longocc:
            if total + m > comp_r.shape[0]:
                grown_r = np.empty(2 * (total + m), dtype=np.int64)
                grown_c = np.empty(2 * (total + m), dtype=np.int64)
                for q in range(total):
                    grown_r[q] = comp_r[q]
                    grown_c[q] = comp_c[q]
                comp_r = grown_r
                comp_c = grown_c
            for q in range(m):
                comp_r[total + q] = gr[q]
                comp_c[total + q] = gc[q]
            sizes[k] = m
            k += 1
            total += m
    return comp_r[:total], comp_c[:total], sizes[:k], nc


@dataclass(frozen=True, slots=True)
class VacatedOutlines:
    """What :func:`vacated_outlines` found in one scan.

    Attributes:
        rows, cols: array cells (of the view's level) of the outlines that yield; empty if none.
        seen_through: long-occupied cells the scan saw through (all outlines, yielding or not).
        outlines: outlines that yield.
        sizes: cells of each yielding outline (``rows`` / ``cols`` hold them one outline after the other).
    """

    rows: np.ndarray
    cols: np.ndarray
    seen_through: int
    outlines: int
    sizes: tuple[int, ...] = ()


def vacated_outlines(view: MapView | None, origin: tuple[float, float], cx: np.ndarray, cy: np.ndarray,
                     clear: np.ndarray, *, occupied_logodds: float, min_cells: int, max_extent: float,
                     ray_core: float = 0.4, near_logodds: float = 0.5, min_depth_m: float = 0.0,
                     min_extent: float = 0.0, min_share: float = 0.0) -> VacatedOutlines:
    """Outlines of long-occupied cells that one scan sees through (section comment above).

    The scan's beams are the clearing segments from the laser at ``origin`` to (``cx``, ``cy``), (n,) in beam
    order, in world cell units (m / the view's resolution), only where ``clear``: the clean-up pass's beam
    geometry, which ends each beam a margin before its return, longer at grazing incidence
    (:func:`dynslam2d.slam.cleanup.scan_clearing`; docs/maps.md "What the pass counts"). A long-occupied cell
    (log-odds ≥ ``occupied_logodds``) counts as seen through where a beam passes within ``ray_core`` of its
    centre and that beam and both its neighbours clear at least ``min_depth_m`` (m) beyond it. Such cells are
    grouped into their 8-connected outline of occupied cells (log-odds > ``near_logodds``); an outline yields
    when its longer side along the grid axes is more than ``min_extent`` and at most ``max_extent`` (m), and
    the scan saw through at least ``min_cells`` of its cells and at least ``min_share`` of its long-occupied
    cells."""
    empty = np.zeros(0, dtype=np.int64)
    if view is None or min_cells <= 0 or cx.shape[0] == 0:
        return VacatedOutlines(empty, empty, 0, 0)
    res = float(view.resolution)
    rows, cols, sizes, nc = vacated_outlines_kernel(
        np.ascontiguousarray(view.logodds), int(view.i0), int(view.j0), float(origin[0]), float(origin[1]),
        np.ascontiguousarray(cx, dtype=np.float64), np.ascontiguousarray(cy, dtype=np.float64),
        np.ascontiguousarray(clear, dtype=np.bool_), float(ray_core), float(occupied_logodds),
        float(min_depth_m) / res, float(near_logodds), np.float32(occupied_logodds),
        max(int(math.ceil(max_extent / res)), 1), int(min_cells), res, float(min_extent), float(min_share))
    if sizes.shape[0] == 0:
        return VacatedOutlines(empty, empty, int(nc), 0)
    return VacatedOutlines(rows, cols, int(nc), int(sizes.shape[0]), tuple(int(m) for m in sizes))


_NO_CODES = np.zeros(0, dtype=np.int64)
_NO_CODES.flags.writeable = False


class VacatedHistory:
    """Keeps an outline's yield only when it persists: the same outline (at least half of its cells) was a
    yielding candidate in each of the ``scans − 1`` scans before (docs/maps.md, "Vacated footprints"). A
    vehicle driving off its outline is seen through scan after scan; pose error or a beam slipping past
    furniture passes through a mapped outline in a scan here and there."""

    def __init__(self, scans: int) -> None:
        self.scans = max(int(scans), 1)
        self._past: list[np.ndarray] = []  # absolute cell codes of earlier scans' candidates, newest last

    def none(self) -> None:
        """Remember a scan without candidates (what :meth:`persistent` does with one)."""
        self._past.append(_NO_CODES)
        del self._past[:-max(self.scans - 1, 1)]

    def persistent(self, view: MapView, vac: VacatedOutlines) -> VacatedOutlines:
        """``vac`` with only the outlines that persisted; remembers this scan's candidates."""
        if not vac.sizes and vac.rows.shape[0] == 0:  # no candidate in this scan (the usual case)
            self.none()
            return VacatedOutlines(_NO_CODES, _NO_CODES, vac.seen_through, 0)
        w = 1 << 31
        codes = (vac.rows + view.j0).astype(np.int64) * w + (vac.cols + view.i0)
        past = self._past[-(self.scans - 1):] if self.scans > 1 else []
        keep_r: list[np.ndarray] = []
        keep_c: list[np.ndarray] = []
        sizes: list[int] = []
        a = 0
        for n in vac.sizes:
            c = codes[a:a + n]
            if len(past) == self.scans - 1 and all(np.count_nonzero(np.isin(c, p)) * 2 >= n for p in past):
                keep_r.append(vac.rows[a:a + n])
                keep_c.append(vac.cols[a:a + n])
                sizes.append(n)
            a += n
        self._past.append(codes)
        del self._past[:-max(self.scans - 1, 1)]
        if not sizes:
            e = np.zeros(0, dtype=np.int64)
            return VacatedOutlines(e, e, vac.seen_through, 0)
        return VacatedOutlines(np.concatenate(keep_r), np.concatenate(keep_c), vac.seen_through, len(sizes),
                               tuple(sizes))


def yielding_view(view: MapView, vacated: VacatedOutlines, free_value: float = -2.0) -> MapView:
    """``view`` with the cells of the yielding outlines set to ``free_value`` (observed free): a copy, only
    when there are any (else ``view`` itself). Only the map evidence of one scan reads it; the SLAM map is
    not changed."""
    if vacated.rows.shape[0] == 0:
        return view
    lo = view.logodds.copy()
    lo[vacated.rows, vacated.cols] = free_value
    return MapView(lo, view.i0, view.j0, view.resolution)
