"""tracks.png: every track's path coloured by speed, membership in M shown."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.viz.figure import new_figure, save_png, tight_layout
from dynslam2d.viz.mapplot import GreyMap, draw_grey_indices, frame_metric_axes, map_figure_size, occupancy_indices
from dynslam2d.viz.trackpaths import MAX_LABELS, TrackPath, label_tracks

#: Colour map of the speed (m/s): plasma without its pale-yellow end (unreadable on white).
SPEED_CMAP = "plasma"
_CMAP_TOP = 0.85
#: Paths with more reports are drawn through this many evenly spaced ones.
MAX_POINTS_PER_PATH = 400
#: At most this many path segments per figure (beyond, every path is thinned evenly).
MAX_SEGMENTS = 60_000
#: The map under the paths is faded towards white by this factor (occupied cells light grey).
MAP_FADE = 0.35


class SegmentPaths(Sequence):  # type: ignore[type-arg]
    """A line collection's paths made on demand from one (n, 2, 2) array of segments (m): the ``Path`` of
    segment i is built when the renderer asks for item i and dropped once drawn.

    matplotlib's ``LineCollection`` keeps one ``Path`` object with its own vertex view per segment (≈ 9 MiB for
    :data:`MAX_SEGMENTS` segments); Agg draws a collection path by path, asking its sequence for each
    (``draw_path_collection``, ``get_path_collection_extents``), so this sequence draws the same pixels from
    the one array (docs/speed.md, pass mem46)."""

    def __init__(self, segments: np.ndarray) -> None:
        self.segments = segments

    def __len__(self) -> int:
        return len(self.segments)

    def __getitem__(self, i):  # type: ignore[no-untyped-def]
        from matplotlib.path import Path as MplPath

        if isinstance(i, slice):
            return [MplPath(s) for s in self.segments[i]]
        return MplPath(self.segments[i])


def _line_collection(segments: np.ndarray, **kwargs):  # type: ignore[no-untyped-def]
    """A ``LineCollection`` of ``segments`` ((n, 2, 2) float64, m) whose paths are a :class:`SegmentPaths`."""
    from matplotlib.collections import LineCollection

    class _Lines(LineCollection):  # type: ignore[misc]
        def set_segments(self, segments):  # type: ignore[no-untyped-def]
            if segments is None:
                return
            self._paths = SegmentPaths(np.asarray(segments, dtype=float))
            self.stale = True

        set_verts = set_paths = set_segments

    return _Lines(segments, **kwargs)


def tracks_background(grid: GridMap) -> GreyMap:
    """The faint map :func:`plot_tracks` draws under the paths, as grey indices: what it keeps of ``grid``. One byte
    per cell (never painted: uint8 holds its :data:`~dynslam2d.viz.mapplot.GREY_LEVELS` greys; it lives through
    map.png, 1.8 MiB on MIT CSAIL; pass mem49)."""
    return GreyMap(occupancy_indices(grid, fade=MAP_FADE, dtype=np.uint8), grid.extent)


def _speed_cmap():  # type: ignore[no-untyped-def]
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    return ListedColormap(colormaps[SPEED_CMAP](np.linspace(0.0, _CMAP_TOP, 256)), name="speed")


def display_speed(track: TrackPath, window: int = 5) -> np.ndarray:
    """(n,) speed for display, m/s: running median over ``window`` reports (tames filter jitter)."""
    s = track.speed
    if len(s) < 3 or window < 2:
        return s
    from scipy.ndimage import median_filter

    return median_filter(s, size=min(window, len(s)), mode="nearest")


def speed_limit(tracks: Sequence[TrackPath]) -> float:
    """Upper end of the speed colour scale, m/s: the 95th percentile of the drawn speeds,
    rounded up to 0.5 m/s (at least 0.5), so one outlier does not wash out the scale."""
    speeds = np.concatenate([t.speed for t in tracks]) if tracks else np.zeros(0)
    if speeds.size == 0:
        return 1.0
    return max(0.5, math.ceil(float(np.percentile(speeds, 95)) * 2.0) / 2.0)


def plot_tracks(
    path: str | os.PathLike[str],
    tracks: Sequence[TrackPath],
    grid: GridMap | GreyMap | None = None,
    *,
    title: str = "",
    dpi: int = 120,
) -> Path:
    """Write a PNG of the track paths (map frame, m) coloured by speed (m/s).

    Segments where the track is in the dynamic set M are solid and thick, the others
    dashed and faint; up to :data:`MAX_LABELS` paths are labelled with their id at their last
    position; each starts with a small circle. ``grid`` (optional) is drawn faintly underneath for context (or
    :func:`tracks_background` of it, computed before).
    """
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    if grid is not None:
        extent = grid.extent
    elif tracks:
        allxy = np.concatenate([t.xy for t in tracks])
        lo, hi = allxy.min(axis=0) - 1.0, allxy.max(axis=0) + 1.0
        extent = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
    else:
        extent = (-1.0, 1.0, -1.0, 1.0)
    w, h = map_figure_size(extent)
    fig = new_figure((w + 1.2, h))
    ax = fig.subplots()
    if grid is not None:
        # Faint map: occupied cells light grey, everything else white.
        bg = grid if isinstance(grid, GreyMap) else tracks_background(grid)
        draw_grey_indices(ax, bg.indices, extent)
        del bg
    vmax = speed_limit(tracks)
    norm = Normalize(0.0, vmax)
    cmap = _speed_cmap()
    span = max(extent[1] - extent[0], extent[3] - extent[2])
    # All paths go into two collections (in M / not in M) and one scatter of start points:
    # one artist per kind, not per track, so tens of thousands of tracks draw in seconds.
    segs: dict[bool, list[np.ndarray]] = {False: [], True: []}
    vals: dict[bool, list[np.ndarray]] = {False: [], True: []}
    starts = np.array([t.xy[0] for t in tracks]).reshape(-1, 2)
    # Simplify: at most MAX_SEGMENTS segments in all (every path keeps every stride-th report
    # and its last one) and MAX_POINTS_PER_PATH reports per path.
    total = sum(max(len(t.xy) - 1, 0) for t in tracks)
    stride = max(1, math.ceil(total / MAX_SEGMENTS))
    for t in tracks:
        if len(t.xy) < 2:
            continue
        xy, in_m_pts = t.xy, t.in_m
        sp = display_speed(t) if stride == 1 else t.speed  # the running median is per-report detail
        n = len(xy)
        step = max(stride, math.ceil(n / MAX_POINTS_PER_PATH))
        if step > 1:
            keep = np.unique(np.r_[np.arange(0, n, step), n - 1])
            xy, sp, in_m_pts = xy[keep], sp[keep], in_m_pts[keep]
        seg = np.stack([xy[:-1], xy[1:]], axis=1)
        spd = 0.5 * (sp[:-1] + sp[1:])
        in_m = in_m_pts[1:] & in_m_pts[:-1]
        for flag in (False, True):
            sel = in_m if flag else ~in_m
            if sel.any():
                segs[flag].append(seg[sel])
                vals[flag].append(spd[sel])
    for flag, lw, alpha, ls in ((False, 1.0, 0.45, (0, (2, 2))), (True, 2.6, 1.0, "solid")):
        if segs[flag]:
            lc = _line_collection(np.concatenate(segs[flag]), cmap=cmap, norm=norm, linewidths=lw, alpha=alpha,
                                linestyles=ls, zorder=4 if flag else 3, capstyle="round" if flag else "butt")
            lc.set_array(np.concatenate(vals[flag]))
            ax.add_collection(lc)
        segs[flag] = vals[flag] = []  # (the collection holds its own copies; these go before the drawing)
    if len(starts):
        ax.scatter(starts[:, 0], starts[:, 1], s=12, c="white", edgecolors="0.2", linewidths=0.8, zorder=5)
    # Labels: tracks in M first, then the longest paths, thinned (trackpaths.label_tracks).
    for t in label_tracks(tracks, span):
        ax.annotate(str(t.id), t.xy[-1], xytext=(3, 3), textcoords="offset points",
                    fontsize=8 if t.ever_in_m else 6.5, fontweight="bold" if t.ever_in_m else "normal",
                    color="0.05" if t.ever_in_m else "0.35", zorder=6, annotation_clip=True,
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7})
    from matplotlib.cm import ScalarMappable

    sm = ScalarMappable(norm=norm, cmap=cmap)
    cb = fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02, extend="max")
    cb.set_label("speed [m/s]")
    frame_metric_axes(ax, extent)
    handles = [
        Line2D([], [], color="0.2", lw=2.6, label="in M (removed from the map)"),
        Line2D([], [], color="0.2", lw=1.0, ls=(0, (2, 2)), alpha=0.6, label="not in M"),
        Line2D([], [], marker="o", ms=3.5, mfc="white", mec="0.2", ls="none", label="first report"),
    ]
    # below the map (under the axis label and the scale bar), so it hides no path
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=3, fontsize="small",
              framealpha=0.9).set_zorder(20)
    ax.set_title(title or f"{len(tracks)} tracks, coloured by speed")
    tight_layout(fig)
    return save_png(fig, path, dpi)


__all__ = ["MAP_FADE", "MAX_LABELS", "SPEED_CMAP", "plot_tracks", "speed_limit", "tracks_background"]
