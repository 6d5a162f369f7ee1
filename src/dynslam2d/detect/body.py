"""The robot's own body in the scan: a configured footprint and returns fixed in the laser frame.

A laser mounted on a robot often sees parts of the robot itself (a bumper, a wheel, a mast,
returns at a few decimetres). They move with the robot, so in the map frame they look like an
object following it; they are never structure either. Two mechanisms drop them before
detection, matching and mapping (docs/tracking.md, "The robot's own body"):

1. **Footprint** (``detect.footprint.polygon``): a simple polygon in the laser frame (x forward,
   y left, m); every return inside it is dropped.
2. **Automatic**: a beam whose range stays within ``auto_tolerance`` of the same value (and
   below ``auto_max_range``) while the laser's pose moves ``auto_min_travel`` metres and turns
   ``auto_min_turn`` radians away from where it was when that range was first seen is looking at something that moves
   with the laser. Static structure cannot do that: translation along a wall keeps a perpendicular range, but the
   turn changes it. From then on, returns of that beam up to the body's range (+ tolerance)
   are dropped. :meth:`BodyFilter.report` gives the beams and a suggested footprint (the convex
   hull of the body returns grown by ``suggest_margin``), for summary.json.

Frames: laser frame for the footprint and the body returns; the laser pose in the map frame
only measures how far the laser travelled and turned. Units m, rad.
"""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.types import Pose2D, Scan, _copy_scan


def polygon_problem(polygon: list[tuple[float, float]] | np.ndarray) -> str | None:
    """Why ``polygon`` ((k, 2) vertices in order, m) cannot be a footprint, or None when it can.

    A footprint needs at least 3 finite vertices, a non-zero area (it must contain points) and no
    two non-adjacent edges that touch or cross (a simple polygon)."""
    p = np.asarray(polygon, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
        return f"needs at least 3 (x, y) vertices, got {p.shape[0] if p.ndim == 2 else 0}"
    if not np.isfinite(p).all():
        return "has a non-finite vertex"
    k = p.shape[0]

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    def on_seg(a: np.ndarray, b: np.ndarray, q: np.ndarray) -> bool:
        return min(a[0], b[0]) - 1e-12 <= q[0] <= max(a[0], b[0]) + 1e-12 and \
            min(a[1], b[1]) - 1e-12 <= q[1] <= max(a[1], b[1]) + 1e-12

    def touch(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
        d1, d2, d3, d4 = cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d)
        if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
            return True
        return (d1 == 0 and on_seg(c, d, a)) or (d2 == 0 and on_seg(c, d, b)) or \
            (d3 == 0 and on_seg(a, b, c)) or (d4 == 0 and on_seg(a, b, d))

    for i in range(k):
        a, b = p[i], p[(i + 1) % k]
        if np.array_equal(a, b):
            return f"has a repeated vertex ({a[0]:g}, {a[1]:g})"
        for j in range(i + 1, k):
            if j == i or (j + 1) % k == i or j == (i + 1) % k:
                continue  # adjacent edges share a vertex
            if touch(a, b, p[j], p[(j + 1) % k]):
                return f"is not simple: edge {i}-{(i + 1) % k} meets edge {j}-{(j + 1) % k}"
    x, y = p[:, 0], p[:, 1]
    area = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))  # shoelace formula
    if abs(area) < 1e-6:
        return "encloses no area (it contains no points)"
    return None


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(n,) bool: which (n, 2) points lie inside ``polygon`` ((k, 2), even-odd ray casting)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    poly = np.asarray(polygon, dtype=np.float64)
    x = pts[:, 0:1]
    y = pts[:, 1:2]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        crosses = ((y0 > y) != (y1 > y)) & (x < (x1 - x0) * (y - y0) / (y1 - y0) + x0)
    return (crosses.sum(axis=1) % 2 == 1) & np.isfinite(pts).all(axis=1)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """(h, 2) convex hull of (n, 2) points, counter-clockwise (Andrew's monotone chain)."""
    p = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 2), axis=0)
    if p.shape[0] < 3:
        return p

    def half(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for q in seq:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (q[1] - out[-2][1]) - \
                    (out[-1][1] - out[-2][1]) * (q[0] - out[-2][0]) <= 0:
                out.pop()
            out.append(q)
        return out

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


def grow_polygon(hull: np.ndarray, margin: float) -> np.ndarray:
    """A convex polygon grown by ``margin`` (m): each vertex pushed out along its bisector.
    Fewer than 3 vertices give the margin-sized square(s) around them."""
    h = np.asarray(hull, dtype=np.float64).reshape(-1, 2)
    if h.shape[0] == 0:
        return h
    if h.shape[0] < 3:
        lo, hi = h.min(axis=0) - margin, h.max(axis=0) + margin
        return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    c = h.mean(axis=0)
    d = h - c
    n = np.hypot(d[:, 0], d[:, 1])
    n[n == 0] = 1.0
    return h + d / n[:, None] * margin


@njit(cache=True)
def _observe_beams(r, valid, st, cnt, moved, body, body_r, new_body, prm, px, py, pth):  # pragma: no cover - numba
    """:meth:`BodyFilter.observe`'s per-beam update, in place, for ranges ``r`` (m) with ``valid`` returns at laser
    pose (``px``, ``py``, ``pth``) (map frame, m / rad). ``prm`` holds (max_range, tol, min_travel, min_turn,
    min_scans, share) (:meth:`BodyFilter._params`); per beam ``st`` holds (ref, start x, start y, start theta) and
    ``cnt`` (seen, same_n) (pass bdy122: packed, 12 arguments instead of 19). A valid return within ``max_range`` is
    *near*; it is *the same* when within ``tol`` of the beam's reference range ``ref``; ``seen`` / ``same_n`` count
    the beam's returns and those at the reference range. A near return that is not the same, on a beam whose
    reference explains less than half of its returns, starts the beam over from it (reference, counts 1, ``start``
    pose, not ``moved``). A beam that kept its range and is not ``moved`` yet becomes moved once the laser is
    ``min_travel`` (m) and ``min_turn`` (rad) away from its start pose: net motion away from where the range was
    first seen (summed increments would add up pose jitter). ``new_body`` gets the body beams: moved, at least
    ``min_scans`` returns at the reference range and at least ``share`` of all. Returns whether the body beams or
    their ranges differ from ``body`` / ``body_r``. (The same values as the array expressions it replaced, one
    beam at a time: math.hypot is the C library's hypot as numpy's, % the same floored remainder; ``min_scans`` is
    an integer held exactly as a float, so ``same_n >= min_scans`` is the integer comparison.)"""
    max_range = prm[0]
    tol = prm[1]
    min_travel = prm[2]
    min_turn = prm[3]
    min_scans = prm[4]
    share = prm[5]
    changed = False
    two_pi = 2.0 * math.pi
    for i in range(r.shape[0]):
        v = valid[i]
        near = v and r[i] <= max_range
        same = near and abs(r[i] - st[i, 0]) <= tol
        if v:
            cnt[i, 0] += 1
        if same:
            cnt[i, 1] += 1
        # a beam whose reference range explains less than half of its returns starts over from this one
        if near and not same and cnt[i, 1] < 0.5 * cnt[i, 0]:
            st[i, 0] = r[i]
            cnt[i, 1] = 1
            cnt[i, 0] = 1
            st[i, 1] = px
            st[i, 2] = py
            st[i, 3] = pth
            moved[i] = False
        if same and not moved[i]:
            if math.hypot(px - st[i, 1], py - st[i, 2]) >= min_travel and \
                    abs((pth - st[i, 3] + math.pi) % two_pi - math.pi) >= min_turn:  # (types.wrap_angle)
                moved[i] = True
        b = moved[i] and cnt[i, 1] >= min_scans and cnt[i, 1] >= share * cnt[i, 0]
        new_body[i] = b
        if b != body[i] or (b and st[i, 0] != body_r[i]):
            changed = True
    return changed


@njit(cache=True)
def _drop_body(ranges, lo, hi, valid, fill, drop_r, tol, footprint, drop, write, out_r, out_v):  # pragma: no cover
    """:meth:`BodyFilter.mask`'s automatic part, in place: a ``valid`` return on a beam with a drop range
    ``drop_r`` > 0 (m) is dropped when its range is at most ``drop_r + tol``; with a ``footprint`` only beams not
    yet in ``drop``. With ``fill`` it first writes ``valid`` itself: :meth:`Scan.valid_mask` of ``ranges`` with the
    sensor limits ``lo``, ``hi`` (m; finite and within [lo, hi], the same tests as its array expression), in the
    same pass (the scan's first mask: one call instead of five NumPy operations, pass rest18). With ``write`` it
    also writes the filtered scan's arrays in that pass (pass bdy122): ``out_r`` the ranges with NaN where ``drop``
    (``Scan.without``'s ``np.copyto(ranges, nan, where=drop)``) and ``out_v`` its valid mask ``valid and not drop``
    (``np.greater(valid, drop)``); without it they are not touched (size 0 is fine). Returns how many it dropped
    (the values of the array expressions it replaced)."""
    count = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if fill:
            valid[i] = math.isfinite(r) and r >= lo and r <= hi
        d = drop_r[i]
        if valid[i] and d > 0.0 and r <= d + tol and not (footprint and drop[i]):
            drop[i] = True
            count += 1
        if write:
            if drop[i]:
                out_r[i] = np.nan
                out_v[i] = False
            else:
                out_r[i] = r
                out_v[i] = valid[i]
    return count


_NO_R = np.zeros(0)  # (_drop_body's output arrays when it does not write them)
_NO_V = np.zeros(0, dtype=np.bool_)


class BodyFilter:
    """Drops the robot's own returns: footprint polygon + automatic detection (module docstring).

    Use: ``drop = body.mask(scan)`` before anything else sees the scan, then
    ``body.observe(scan, pose)`` with the laser pose estimated for it.
    """

    def __init__(self, config: object) -> None:
        self.config = config
        poly = getattr(config, "polygon", None)
        self.polygon = None if poly is None else np.asarray(poly, dtype=np.float64)
        if self.polygon is not None:
            why = polygon_problem(self.polygon)
            if why is not None:
                raise DynSlamError(f"detect.footprint.polygon {why}; give the vertices in order around the robot, "
                                   "laser frame, m")
        self._n = -1
        self._ref = np.zeros(0)
        self._start = np.zeros((0, 3))
        self.body = np.zeros(0, dtype=bool)  # beams found to look at the robot's body
        self._body_r = np.zeros(0)
        self._geom: tuple | None = None
        self._dropping = False
        self.footprint_dropped = 0
        self.auto_dropped = 0
        self.scans = 0

    def _reset(self, n: int) -> None:
        self._n = n
        # per beam (ref m, start x m, start y m, start theta rad) and (seen, same_n): _observe_beams' packed state;
        # ``_ref`` / ``_start`` / ``_seen`` / ``_same`` are views of its columns
        self._st = np.zeros((n, 4))
        self._st[:, 0] = np.nan
        self._cnt = np.zeros((n, 2), dtype=np.int64)
        self._ref = self._st[:, 0]
        self._start = self._st[:, 1:]
        self._seen = self._cnt[:, 0]
        self._same = self._cnt[:, 1]
        self._prm = self._params()
        self.body = np.zeros(n, dtype=bool)
        self._body_r = np.zeros(n)
        self._drop_r = np.zeros(n)
        self._dropping = False  # whether any drop range is > 0 (set where ``_drop_r`` changes)
        self._moved = np.zeros(n, dtype=bool)

    def _params(self) -> np.ndarray:
        """(6,) float64: ``_observe_beams``' settings (auto_max_range m, auto_tolerance m, auto_min_travel m,
        auto_min_turn rad, auto_min_scans, auto_share), read from the config at the first scan (and at a change of
        the beam count)."""
        c = self.config
        return np.array([float(getattr(c, "auto_max_range", 0.0)), float(getattr(c, "auto_tolerance", 0.0)),
                         float(getattr(c, "auto_min_travel", 0.0)), float(getattr(c, "auto_min_turn", 0.0)),
                         float(int(getattr(c, "auto_min_scans", 0))), float(getattr(c, "auto_share", 0.0))])

    def mask(self, scan: Scan) -> np.ndarray:
        """(beams,) bool: returns of ``scan`` to drop (inside the footprint, or on a body beam)."""
        return self._mask(scan, False)[0]

    def apply(self, scan: Scan) -> tuple[np.ndarray, Scan]:
        """(:meth:`mask`'s drop mask, the scan without those returns): ``scan`` itself when nothing is dropped, else
        ``scan.without(drop)``'s values (ranges NaN and not valid where dropped) written in the mask's own pass over
        the beams (pass bdy122: one kernel pass instead of the mask's and four NumPy operations)."""
        return self._mask(scan, True)

    def _mask(self, scan: Scan, apply: bool) -> tuple[np.ndarray, Scan]:
        """:meth:`mask` and, with ``apply``, :meth:`apply`'s filtered scan (else ``scan``)."""
        n = scan.n_beams
        if n != self._n:
            self._reset(n)
        drop = np.zeros(n, dtype=bool)
        auto = getattr(self.config, "auto", False)
        fill = auto and self.polygon is None and not scan.has_valid_mask()
        # (the scan's first mask: the kernel below writes it in its pass over the beams, the scan keeps it)
        valid = np.empty(n, dtype=bool) if fill else scan.valid_view()  # (only read here: no copy)
        dropped = 0
        if self.polygon is not None and valid.any():
            pts = scan.points(valid)
            inside = points_in_polygon(pts, self.polygon)
            drop[np.flatnonzero(valid)[inside]] = True
            dropped = int(inside.sum())
            self.footprint_dropped += dropped
        out = scan
        if auto:  # (without body beams every drop range is 0: nothing dropped)
            write = apply and (self._dropping or dropped > 0)
            out_r, out_v = (np.empty(n), np.empty(n, dtype=bool)) if write else (_NO_R, _NO_V)
            count = _drop_body(scan.ranges, float(scan.range_min), float(scan.range_max), valid, fill, self._drop_r,
                               float(self.config.auto_tolerance), self.polygon is not None, drop, write, out_r, out_v)
            self.auto_dropped += count
            if fill:
                scan.adopt_valid_mask(valid)
            if write and count + dropped > 0:
                out = _copy_scan(scan, out_r, out_v)
        elif apply and dropped > 0:
            out = scan.without(drop)
        self.scans += 1
        return drop, out

    def observe(self, scan: Scan, pose: Pose2D) -> None:
        """Update the automatic detection with ``scan`` and its laser pose (map frame)."""
        cfg = self.config
        if not getattr(cfg, "auto", False) or pose is None or not pose.is_finite():
            return
        n = scan.n_beams
        if n != self._n:
            self._reset(n)
        # per beam, in one pass (_observe_beams): the counts of returns and of returns at the reference range, the
        # restarts, the net motion test and the body beams
        body = np.empty(n, dtype=np.bool_)
        valid = scan.valid_view()  # (read only by the kernel: no copy)
        if not _observe_beams(scan.ranges, valid, self._st, self._cnt, self._moved, self.body, self._body_r, body,
                              self._prm, float(pose.x), float(pose.y), float(pose.theta)):
            return  # the same body beams at the same ranges (the usual case): the drop ranges stay as they are
        tol = float(cfg.auto_tolerance)
        self.body = body
        self._body_r = np.where(self.body, self._ref, 0.0)
        # the beams next to a body edge see it part of the time (mixed returns): they drop returns up to
        # the nearby body range + 2 tolerances
        self._drop_r = self._body_r.copy()
        self._dropping = bool((self._body_r > 0.0).any())  # (an edge beam's drop range needs a body beam's)
        k = int(cfg.auto_edge_beams)
        if k > 0 and self.body.any():
            grown = self._body_r.copy()
            for d in range(1, k + 1):
                grown[d:] = np.maximum(grown[d:], self._body_r[:-d])
                grown[:-d] = np.maximum(grown[:-d], self._body_r[d:])
            edge = ~self.body & (grown > 0.0)
            self._drop_r[edge] = grown[edge] + tol

    @property
    def body_ranges(self) -> np.ndarray:
        """(beams,) the fixed range of each body beam, m (0 where a beam is not a body beam)."""
        return self._body_r

    def report(self, scan: Scan | None = None) -> dict[str, object]:
        """What was dropped and, when body beams were found, a suggested footprint (laser frame, m)."""
        out: dict[str, object] = {
            "footprint": None if self.polygon is None else self.polygon.tolist(),
            "footprint_dropped_returns": int(self.footprint_dropped),
            "auto": bool(getattr(self.config, "auto", False)),
            "auto_body_beams": int(self.body.sum()),
            "auto_dropped_returns": int(self.auto_dropped),
            "suggested_footprint": None,
        }
        if self.body.any() and scan is not None and scan.n_beams == self._n:
            a = scan.angles[self.body]
            r = self._body_r[self.body]
            pts = np.column_stack((r * np.cos(a), r * np.sin(a)))
            poly = grow_polygon(convex_hull(np.vstack((pts, [[0.0, 0.0]]))), float(self.config.suggest_margin))
            # rounded to mm, without the vertices rounding made equal or collinear: ready to paste into
            # detect.footprint.polygon (it passes polygon_problem)
            poly = convex_hull(np.round(poly, 3))
            if polygon_problem(poly) is not None:
                lo, hi = poly.min(axis=0), poly.max(axis=0)
                poly = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
            out["suggested_footprint"] = [[round(float(x), 3), round(float(y), 3)] for x, y in poly]
            out["auto_body_beam_indices"] = np.flatnonzero(self.body).tolist()
        return out
