"""Static geometry of a simulated world and vectorised 2D ray casting.

Everything here is in the simulator's **world frame** (metres, radians, REP-103
axes). Static structure is a set of line segments (walls, pillar outlines,
furniture); moving objects contribute extra segments (oriented rectangles, 4
segments each) or circles at each instant. :func:`cast_rays` intersects a fan
of rays from one origin with all of them in one compiled kernel (no Python loop
per beam) and reports, per ray, the distance to the nearest hit and the id of
the object hit (0 = static structure, k ≥ 1 = mover k, -1 = nothing).

:meth:`World.static_map` rasterises the static segments into a
:class:`~dynslam2d.gridmap.GridMap` (1 = a segment touches the cell, 0 = free
space inside the building, NaN = outside the building or inside a solid
obstacle, when the world defines those polygons).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.types import Pose2D

#: Label of a beam that hit static structure (per-beam ground-truth labels).
LABEL_STATIC = 0
#: Label of a beam with no return (nothing within range, dropout, below range_min).
LABEL_NONE = -1

#: Rays are treated as parallel to a segment when |cross(d, e)| is below this (m).
_PARALLEL_EPS = 1e-12


@njit(cache=True)
def _cast_kernel(
    ox: float,
    oy: float,
    cos_a: np.ndarray,
    sin_a: np.ndarray,
    segs: np.ndarray,
    seg_ids: np.ndarray,
    circles: np.ndarray,
    circle_ids: np.ndarray,
    max_dist: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit along each ray (unit direction (cos_a[i], sin_a[i])) from (ox, oy).

    Ray–segment: solve o + t·d = a + u·e with e = b − a, t > 0, u ∈ [0, 1]
    (t = cross(a−o, e)/cross(d, e), u = cross(a−o, d)/cross(d, e)).
    Ray–circle: |o + t·d − c|² = r² ⇒ t = −β ± √(β² − γ), β = d·(o−c),
    γ = |o−c|² − r²; the smallest positive root wins.
    """
    n = cos_a.shape[0]
    m = segs.shape[0]
    k = circles.shape[0]
    dist = np.empty(n)
    dist[:] = np.inf
    ids = np.empty(n, dtype=np.int32)
    ids[:] = -1
    # per-segment constants
    wx = np.empty(m)
    wy = np.empty(m)
    ex = np.empty(m)
    ey = np.empty(m)
    for j in range(m):
        wx[j] = segs[j, 0] - ox
        wy[j] = segs[j, 1] - oy
        ex[j] = segs[j, 2] - segs[j, 0]
        ey[j] = segs[j, 3] - segs[j, 1]
    cx = np.empty(k)
    cy = np.empty(k)
    gam = np.empty(k)
    for j in range(k):
        cx[j] = ox - circles[j, 0]
        cy[j] = oy - circles[j, 1]
        gam[j] = cx[j] * cx[j] + cy[j] * cy[j] - circles[j, 2] * circles[j, 2]
    for i in range(n):
        dx = cos_a[i]
        dy = sin_a[i]
        best = max_dist
        best_id = -1
        for j in range(m):
            den = dx * ey[j] - dy * ex[j]
            if abs(den) < _PARALLEL_EPS:
                continue
            t = (wx[j] * ey[j] - wy[j] * ex[j]) / den
            if t <= 0.0 or t >= best:
                continue
            u = (wx[j] * dy - wy[j] * dx) / den
            if u < 0.0 or u > 1.0:
                continue
            best = t
            best_id = seg_ids[j]
        for j in range(k):
            beta = dx * cx[j] + dy * cy[j]
            disc = beta * beta - gam[j]
            if disc < 0.0:
                continue
            sq = math.sqrt(disc)
            t = -beta - sq
            if t <= 0.0:
                t = -beta + sq
            if t <= 0.0 or t >= best:
                continue
            best = t
            best_id = circle_ids[j]
        if best_id >= 0:
            dist[i] = best
            ids[i] = best_id
    return dist, ids


def cast_rays(
    origin: tuple[float, float] | np.ndarray,
    angles: np.ndarray,
    segments: np.ndarray,
    segment_ids: np.ndarray | None = None,
    circles: np.ndarray | None = None,
    circle_ids: np.ndarray | None = None,
    max_dist: float = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Cast rays from ``origin`` at world ``angles`` against segments and circles.

    Args:
        origin: (x, y) of the ray origin in the world frame, m.
        angles: (n,) ray directions in the world frame, rad.
        segments: (m, 4) segments ``x0, y0, x1, y1`` in the world frame, m.
        segment_ids: (m,) int label of each segment (default 0 = static).
        circles: (k, 3) circles ``cx, cy, radius``, m (default none).
        circle_ids: (k,) int label of each circle (default 1..k).
        max_dist: hits at or beyond this distance are ignored, m.

    Returns:
        ``(dist, ids)``: (n,) float64 distance to the nearest hit (``inf`` if
        none) and (n,) int32 label of what was hit (-1 if none).
    """
    angles = np.ascontiguousarray(angles, dtype=np.float64)
    segs = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 4))
    sid = (
        np.zeros(segs.shape[0], dtype=np.int32)
        if segment_ids is None
        else np.ascontiguousarray(segment_ids, dtype=np.int32)
    )
    circ = np.zeros((0, 3)) if circles is None else np.asarray(circles, dtype=np.float64).reshape(-1, 3)
    circ = np.ascontiguousarray(circ)
    cid = (
        np.arange(1, circ.shape[0] + 1, dtype=np.int32)
        if circle_ids is None
        else np.ascontiguousarray(circle_ids, dtype=np.int32)
    )
    if sid.shape[0] != segs.shape[0] or cid.shape[0] != circ.shape[0]:
        raise ValueError("cast_rays: one id per segment and per circle is required")
    return _cast_kernel(
        float(origin[0]), float(origin[1]), np.cos(angles), np.sin(angles), segs, sid, circ, cid, float(max_dist)
    )


def rect_corners(x: float, y: float, heading: float, length: float, width: float) -> np.ndarray:
    """(4, 2) corners (counter-clockwise) of a rectangle centred at (x, y), m.

    ``length`` runs along the rectangle's heading (its local x axis), ``width``
    across it (local y axis).
    """
    c, s = math.cos(heading), math.sin(heading)
    hl, hw = 0.5 * length, 0.5 * width
    local = np.array([[hl, -hw], [hl, hw], [-hl, hw], [-hl, -hw]])
    return np.column_stack((x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]))


def polyline_segments(points: np.ndarray | list[tuple[float, float]], closed: bool = False) -> np.ndarray:
    """(n−1, 4) segments joining consecutive points (n segments when ``closed``)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    q = np.vstack((p, p[:1])) if closed else p
    return np.column_stack((q[:-1], q[1:]))


def rect_segments(x: float, y: float, heading: float, length: float, width: float) -> np.ndarray:
    """(4, 4) outline segments of an oriented rectangle (see :func:`rect_corners`)."""
    return polyline_segments(rect_corners(x, y, heading, length, width), closed=True)


def transform_segments(segments: np.ndarray, pose: Pose2D) -> np.ndarray:
    """Apply ``pose`` (child → parent) to both end points of (m, 4) segments."""
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    a = pose.transform_points(s[:, :2])
    b = pose.transform_points(s[:, 2:])
    return np.column_stack((a, b))


def point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(n,) distance from each point to the nearest of the (m, 4) segments, m."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
    s = np.asarray(segments, dtype=np.float64).reshape(1, -1, 4)
    a = s[..., :2]
    e = s[..., 2:] - a
    ee = np.maximum((e * e).sum(-1), 1e-300)
    u = np.clip(((p - a) * e).sum(-1) / ee, 0.0, 1.0)
    d = p - (a + u[..., None] * e)
    return np.sqrt((d * d).sum(-1)).min(axis=1)


@dataclass(slots=True)
class World:
    """The static part of a simulated scene, in the world frame.

    Attributes:
        segments: (m, 4) static segments ``x0, y0, x1, y1``, m.
        interior: polygons (each (k, 2), m) whose union is the space inside the
            building. Cells outside all of them are "unknown" (NaN) in
            :meth:`static_map`; empty → everything is free space.
        solids: polygons (each (k, 2), m) of solid obstacles (pillars,
            furniture); their inside is never observable, NaN in the map.
    """

    segments: np.ndarray
    interior: list[np.ndarray] = field(default_factory=list)
    solids: list[np.ndarray] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.segments = np.ascontiguousarray(np.asarray(self.segments, dtype=np.float64).reshape(-1, 4))
        self.interior = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in self.interior]
        self.solids = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in self.solids]

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the static segments, m."""
        xs = self.segments[:, [0, 2]]
        ys = self.segments[:, [1, 3]]
        return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())

    def transformed(self, pose: Pose2D) -> World:
        """This world with every coordinate mapped through ``pose`` (child → parent)."""
        return World(
            transform_segments(self.segments, pose),
            [pose.transform_points(p) for p in self.interior],
            [pose.transform_points(p) for p in self.solids],
        )

    def static_map(self, resolution: float, margin: float = 0.5) -> GridMap:
        """Rasterise the static structure into a :class:`GridMap`, in this world's frame.

        Cells whose interior a static segment passes through are 1.0 (exact
        traversal, :func:`segment_cells`); cells whose centre lies inside
        ``interior`` (or everywhere, if no interior is defined) are 0.0; cells
        outside the building or inside a solid are NaN. The grid covers the
        segments' bounding box plus ``margin`` m; its origin sits half a cell off
        the multiples of ``resolution``, so axis-aligned walls at round
        coordinates run through cell centres (one cell thick, no aliasing).
        """
        if not resolution > 0:
            raise ValueError(f"static_map: resolution must be > 0, got {resolution}")
        xmin, xmax, ymin, ymax = self.bounds()
        x0 = (math.floor((xmin - margin) / resolution) - 0.5) * resolution
        y0 = (math.floor((ymin - margin) / resolution) - 0.5) * resolution
        w = int(math.ceil((xmax + margin - x0) / resolution))
        h = int(math.ceil((ymax + margin - y0) / resolution))
        grid = GridMap(np.zeros((h, w)), resolution, (x0, y0))
        if self.interior or self.solids:
            from matplotlib.path import Path as MplPath  # only for ground-truth maps, not on import

            xc, yc = grid.cell_centers()
            centres = np.column_stack((xc.ravel(), yc.ravel()))
            inside = np.zeros(centres.shape[0], dtype=bool)
            if self.interior:
                for poly in self.interior:
                    inside |= MplPath(poly).contains_points(centres)
            else:
                inside[:] = True
            for poly in self.solids:
                inside &= ~MplPath(poly).contains_points(centres)
            grid.prob[...] = np.where(inside.reshape(h, w), 0.0, np.nan)
        cells = segment_cells(self.segments, resolution, grid.origin)
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < w) & (cells[:, 1] >= 0) & (cells[:, 1] < h)
        grid.prob[cells[ok, 1], cells[ok, 0]] = 1.0
        return grid


def sample_segments(segments: np.ndarray, step: float) -> np.ndarray:
    """(n, 2) points along every segment, spaced at most ``step`` m, end points included."""
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    lengths = np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])
    counts = np.maximum(np.ceil(lengths / step).astype(np.int64), 1) + 1
    seg_idx = np.repeat(np.arange(s.shape[0]), counts)
    starts = np.cumsum(counts) - counts
    u = (np.arange(counts.sum()) - np.repeat(starts, counts)) / np.repeat(counts - 1, counts)
    a = s[seg_idx, :2]
    b = s[seg_idx, 2:]
    return a + u[:, None] * (b - a)


def segment_cells(segments: np.ndarray, resolution: float, origin: tuple[float, float]) -> np.ndarray:
    """(n, 2) integer (col, row) cells whose interior the (m, 4) segments pass through.

    Exact traversal: each segment is cut at every vertical and horizontal grid
    line it crosses; the midpoint of each piece lies in exactly one traversed
    cell. A segment running exactly along a grid line is assigned to one side.
    """
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    ox, oy = origin
    out = []
    for x0, y0, x1, y1 in s:
        us = [np.array([0.0, 1.0])]
        for a, b, o in ((x0, x1, ox), (y0, y1, oy)):
            if a != b:
                ga, gb = (a - o) / resolution, (b - o) / resolution
                lines = np.arange(math.ceil(min(ga, gb)), math.floor(max(ga, gb)) + 1)
                us.append((lines - ga) / (gb - ga))
        u = np.unique(np.clip(np.concatenate(us), 0.0, 1.0))
        mid = 0.5 * (u[:-1] + u[1:]) if u.shape[0] > 1 else u
        pts = np.column_stack((x0 + mid * (x1 - x0), y0 + mid * (y1 - y0)))
        out.append(np.floor((pts - (ox, oy)) / resolution).astype(np.int64))
    return np.vstack(out) if out else np.zeros((0, 2), dtype=np.int64)
