"""errors.png: trajectory error over time and where the map differs from the ground truth."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynslam2d.eval.maps import CellSets, cell_sets
from dynslam2d.eval.trajectory import AteResult
from dynslam2d.gridmap import GridMap
from dynslam2d.types import Pose2D
from dynslam2d.viz import style
from dynslam2d.viz.figure import new_figure, save_png, tight_layout
from dynslam2d.viz.mapplot import draw_scale_bar, map_figure_size

# Classes of :attr:`MapDifference.classes`, painted in this order.
UNOBSERVED, FREE, TRUTH, ESTIMATE, MISSED, GHOST = range(6)
CLASS_COLOURS = (style.UNKNOWN, "#ffffff", style.TRUTH_OUTLINE, style.MATCHED, style.MISSED, style.GHOST)


@dataclass(frozen=True, eq=False)
class MapDifference:
    """Per-cell comparison of an estimated map with the ground truth (ground-truth frame).

    Attributes:
        classes: (H, W) uint8, row 0 at the bottom: UNOBSERVED (estimate unknown), FREE
            (observed, not occupied), TRUTH (true structure, estimate agrees or did not
            see it), ESTIMATE (estimated occupied within ``ghost_distance`` of the truth),
            MISSED (observable true structure with no estimated occupied cell within
            ``tolerance``), GHOST (estimated occupied farther than ``ghost_distance`` from
            any true structure).
        resolution: cell side, m.
        origin: world (x, y) of the lower-left corner of cell (0, 0), GT frame, m.
        n_ghost, n_missed: cell counts of the two error classes.
    """

    classes: np.ndarray
    resolution: float
    origin: tuple[float, float]
    n_ghost: int
    n_missed: int

    @property
    def extent(self) -> tuple[float, float, float, float]:
        h, w = self.classes.shape
        x0, y0 = self.origin
        return (x0, x0 + w * self.resolution, y0, y0 + h * self.resolution)


def map_difference(
    estimate: GridMap,
    truth: GridMap,
    transform: Pose2D | None = None,
    tolerance: float = 0.10,
    ghost_distance: float = 0.20,
    occupied_threshold: float = 0.65,
) -> MapDifference:
    """Classify every cell of the comparison grid (the sets of :func:`dynslam2d.eval.maps.map_metrics`).

    Uses :func:`dynslam2d.eval.maps.comparison_grids` for the resampling, and the same
    definitions and defaults as ``map_metrics``: ``n_ghost`` equals its ``ghost_cells``;
    MISSED cells are the observable true cells its ``recall`` counts as unmatched.
    ``transform`` is the pose of the estimate frame in the GT frame (the ATE alignment).
    """
    return map_difference_of(cell_sets(estimate, truth, transform, tolerance, ghost_distance, occupied_threshold))


def map_difference_of(cs: CellSets) -> MapDifference:
    """The :class:`MapDifference` of cell sets already built by :func:`dynslam2d.eval.maps.cell_sets` (the
    same sets the map metrics count: a run's evaluation builds them once for both)."""
    est, A, B, known, ghost = cs.estimate, cs.truth_occupied, cs.estimate_occupied, cs.known, cs.ghost
    res, origin = cs.resolution, cs.origin
    missed = cs.observable & ~cs.truth_matched
    cls = np.full(est.shape, UNOBSERVED, dtype=np.uint8)
    cls[known] = FREE
    cls[A] = TRUTH
    cls[B & ~ghost] = ESTIMATE
    cls[missed] = MISSED
    cls[ghost] = GHOST
    return MapDifference(cls, res, origin, int(ghost.sum()), int(missed.sum()))


def plot_errors(
    path: str | os.PathLike[str],
    ate_result: AteResult,
    diff: MapDifference,
    *,
    title: str = "",
    dpi: int = 120,
    map_note: str = "",
    intervals: dict[str, list[tuple[float, float]]] | None = None,
) -> Path:
    """Write errors.png: ATE (m) against time (s) on top, the map difference below (GT frame, m).

    Args:
        ate_result: :func:`dynslam2d.eval.trajectory.ate` of the run against the GT
            trajectory (aligned); its per-pose ``errors`` are plotted.
        diff: :func:`map_difference` of the run's map against the GT map, with the same alignment.
        map_note: appended to the map panel's title (e.g. ghost area and F1 of the cleaned and online maps).
        intervals: (start, end) stamps (s, same clock as the ATE stamps) to shade on the time axis,
            by kind: "degenerate", "low_support", "lost".
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    extent = diff.extent
    w, h = map_figure_size(extent)
    fig = new_figure((w, h + 2.6))
    gs = fig.add_gridspec(2, 1, height_ratios=(2.2, h))
    ax_t = fig.add_subplot(gs[0])
    ax_m = fig.add_subplot(gs[1])

    e = ate_result.errors
    t = ate_result.stamps - ate_result.stamps[0] if len(ate_result.stamps) else ate_result.stamps
    t_origin = float(ate_result.stamps[0]) if len(ate_result.stamps) else 0.0
    shade = {"degenerate": (style.DEGENERATE, 0.25, "degenerate"),
             "low_support": (style.LOW_SUPPORT, 0.35, "low support"),
             "lost": (style.LOST, 0.35, "lost")}
    for kind, spans in (intervals or {}).items():
        if kind not in shade or not spans:
            continue
        colour, alpha, label = shade[kind]
        for k, (a, b) in enumerate(spans):
            ax_t.axvspan(a - t_origin, max(b, a + 1e-3) - t_origin, color=colour, alpha=alpha, lw=0,
                         label=f"{label} ({len(spans)}×)" if k == 0 else None)
    ax_t.plot(t, e, color=style.TRAJECTORY, lw=1.0, label="translation error")
    if len(e):
        ax_t.axhline(ate_result.rmse, color="0.3", ls="--", lw=1.0, label=f"RMSE {ate_result.rmse:.3f} m")
        ax_t.set_xlim(t[0], max(t[-1], t[0] + 1e-6))
    ax_t.set_ylim(0.0, max(float(e.max()) * 1.15 if len(e) else 0.0, 1e-3))
    ax_t.set_xlabel("time since first scan [s]")
    ax_t.set_ylabel("ATE [m]")
    ax_t.grid(True, alpha=0.3)
    ax_t.legend(loc="upper left", fontsize="small", framealpha=0.85)
    ax_t.set_title(f"absolute trajectory error (SE(2)-aligned, {ate_result.n} poses)", fontsize="medium")

    cmap = ListedColormap(CLASS_COLOURS)
    ax_m.imshow(diff.classes, cmap=cmap, vmin=-0.5, vmax=len(CLASS_COLOURS) - 0.5, origin="lower",
                extent=extent, interpolation="nearest")
    res = diff.resolution
    handles = [
        Patch(color=style.TRUTH_OUTLINE, label="ground-truth structure"),
        Patch(color=style.MATCHED, label="mapped structure"),
        Patch(color=style.GHOST, label=f"ghost cells ({diff.n_ghost}, {diff.n_ghost * res * res:.2f} m²)"),
        Patch(color=style.MISSED, label=f"missed structure ({diff.n_missed} cells)"),
        Patch(facecolor="#ffffff", edgecolor="0.6", label="observed, free"),
        Patch(facecolor=style.UNKNOWN, edgecolor="0.6", label="not observed"),
    ]
    ax_m.set_xlabel("x [m] (ground-truth frame)")
    ax_m.set_ylabel("y [m]")
    ax_m.set_aspect("equal")
    draw_scale_bar(ax_m, extent)
    # below the map (under the axis label and the scale bar), so it hides no cell
    ax_m.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=3, fontsize="small",
                framealpha=0.9)
    ax_m.set_title("map difference" + (f"\n{map_note}" if map_note else ""), fontsize="medium")
    if title:
        fig.suptitle(title)
    tight_layout(fig)
    return save_png(fig, path, dpi)


__all__ = ["CLASS_COLOURS", "MapDifference", "map_difference", "map_difference_of", "plot_errors"]
