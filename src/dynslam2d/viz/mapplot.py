"""The map figure: occupancy grid with trajectories on top, axes in metres."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.viz.figure import save_png


def occupancy_image(grid: GridMap) -> np.ndarray:
    """(H, W) grey values for display: free → white, occupied → black, unknown → light grey."""
    img = 1.0 - np.nan_to_num(grid.prob, nan=0.5)
    img[~grid.known()] = 0.8
    return img


def plot_map(
    path: str | os.PathLike[str],
    grid: GridMap,
    trajectory_xy: np.ndarray | None = None,
    *,
    reference_xy: np.ndarray | None = None,
    title: str = "",
    dpi: int = 120,
) -> Path:
    """Write a PNG of ``grid`` with the estimated (and optionally reference) trajectory.

    Args:
        path: PNG to write (atomically).
        grid: the map, in the map frame.
        trajectory_xy: (n, 2) estimated laser positions in the map frame, m.
        reference_xy: (n, 2) ground-truth positions already expressed in the map frame, m.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x0, x1, y0, y1 = grid.extent
    width_m, height_m = x1 - x0, y1 - y0
    aspect = height_m / max(width_m, 1e-9)
    fig_w = 8.0
    fig, ax = plt.subplots(figsize=(fig_w, min(max(fig_w * aspect, 3.0), 12.0) + 0.6))
    ax.imshow(occupancy_image(grid), cmap="gray", vmin=0.0, vmax=1.0, origin="lower",
              extent=grid.extent, interpolation="nearest")
    if reference_xy is not None and len(reference_xy):
        ax.plot(reference_xy[:, 0], reference_xy[:, 1], color="tab:green", lw=1.2, label="ground truth")
    if trajectory_xy is not None and len(trajectory_xy):
        ax.plot(trajectory_xy[:, 0], trajectory_xy[:, 1], color="tab:red", lw=1.0, label="estimated trajectory")
        ax.plot(*trajectory_xy[0], marker="o", color="tab:red", ms=6, label="start")
    # Scale bar: a round length of about a fifth of the map width.
    raw = width_m / 5.0
    bar = float(10 ** np.floor(np.log10(max(raw, 1e-3))))
    for m in (5.0, 2.0):
        if bar * m <= raw:
            bar *= m
            break
    from matplotlib.patches import Rectangle

    bx, by = x0 + 0.04 * width_m, y0 + 0.04 * height_m
    ax.add_patch(Rectangle((bx - 0.02 * width_m, by - 0.025 * height_m), bar + 0.04 * width_m, 0.09 * height_m,
                           facecolor="white", edgecolor="0.3", alpha=0.9, zorder=4))
    ax.plot([bx, bx + bar], [by, by], color="black", lw=3, solid_capstyle="butt", zorder=5)
    ax.text(bx + bar / 2, by + 0.015 * height_m, f"{bar:g} m", color="black", ha="center", va="bottom", zorder=5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title)
    if trajectory_xy is not None or reference_xy is not None:
        ax.legend(loc="upper right", fontsize="small", framealpha=0.8)
    fig.tight_layout()
    return save_png(fig, path, dpi)
