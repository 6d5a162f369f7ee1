"""A one-picture overview of a simulated run (headless matplotlib, PNG).

Shows, in metres with equal aspect: the static segments, each mover's path and
its footprint at one scan, the robot's path and pose, and that scan's points
coloured by their ground-truth label. Uses the Agg canvas directly (no pyplot,
no global backend switch), and writes through :func:`atomic_path`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dynslam2d.io.atomic import atomic_path
from dynslam2d.sim.simulation import Simulation
from dynslam2d.sim.world import rect_corners, transform_segments
from dynslam2d.types import Pose2D

#: Mover colours (blue is static hits, grey the robot).
MOVER_COLORS = ("tab:red", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                "tab:cyan")


def default_scan_index(sim: Simulation) -> int:
    """The scan that sees the most *moving* movers (ties: most movers seen, then
    most mover beams, then earliest)."""
    gt = sim.ground_truth
    if not gt.movers:
        return 0
    hits = gt.mover_hits
    seen = hits > 0
    moving = np.hypot(gt.mover_states[..., 3], gt.mover_states[..., 4]) > 0.05
    score = (seen & moving).sum(axis=1) * 10**8 + seen.sum(axis=1) * 10**6 + hits.sum(axis=1)
    return int(np.argmax(score))


def plot_overview(sim: Simulation, path: str | os.PathLike[str], scan_index: int | None = None,
                  frame: str = "world", dpi: int = 120) -> Path:
    """Write a PNG overview of ``sim`` to ``path`` and return the path.

    Args:
        sim: a finished :class:`~dynslam2d.sim.simulation.Simulation`.
        path: output PNG file (written atomically).
        scan_index: the scan whose points and mover footprints are drawn
            (default: :func:`default_scan_index`).
        frame: "world" (the scenario frame) or "first" (first-scan laser frame).
        dpi: output resolution.
    """
    gt = sim.ground_truth
    n = gt.n_scans
    i = default_scan_index(sim) if scan_index is None else int(scan_index)
    if not -n <= i < n:
        raise IndexError(f"plot_overview: scan_index {i} out of range for {n} scans")
    i %= n
    tf = gt.frame_transform(frame)
    segs = transform_segments(gt.scenario.world.segments, tf)
    xmin, xmax, ymin, ymax = _bounds(segs)
    pad = 0.5
    dx, dy = xmax - xmin + 2 * pad, ymax - ymin + 2 * pad
    scale = min(8.0 / dx, 7.0 / dy)  # inches per metre of the axes box
    legend_below = dx / dy > 1.6
    if legend_below:
        figsize = (max(dx * scale + 1.0, 8.0), dy * scale + 2.6)
    else:
        figsize = (dx * scale + 4.2, max(dy * scale + 1.0, 4.5))
    # matplotlib on use, not on import: `import dynslam2d.sim` is on every simulated run's path (issue 13)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle as CirclePatch
    from matplotlib.patches import Polygon

    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.add_collection(LineCollection(segs.reshape(-1, 2, 2), colors="black", linewidths=1.6, label="static walls",
                                     zorder=3))

    poses = gt.poses_in(frame)
    ax.plot(poses[:, 0], poses[:, 1], color="0.45", ls="--", lw=1.0, label="robot path", zorder=4)

    states = gt.mover_states_in(frame)
    for j, m in enumerate(gt.movers):
        col = MOVER_COLORS[j % len(MOVER_COLORS)]
        ax.plot(states[:, j, 0], states[:, j, 1], color=col, lw=0.9, alpha=0.55, zorder=2)
        x, y, h, vx, vy = states[i, j, :5]
        if m.kind == "circle":
            patch = CirclePatch((x, y), m.shape.radius, fc=col, ec=col, alpha=0.35, lw=1.5, zorder=5)
        else:
            patch = Polygon(rect_corners(x, y, h, m.shape.length, m.shape.width), closed=True, fc=col, ec=col,
                            alpha=0.35, lw=1.5, zorder=5)
        ax.add_patch(patch)
        speed = float(np.hypot(vx, vy))
        size = f"⌀{m.shape.length:.2g}" if m.kind == "circle" else f"{m.shape.length:.2g}×{m.shape.width:.2g}"
        ax.plot([], [], color=col, lw=6, alpha=0.6, label=f"{m.id}: {m.name} ({size} m, {speed:.2f} m/s)")
        if speed > 1e-6:
            ax.annotate("", xy=(x + 0.6 * vx, y + 0.6 * vy), xytext=(x, y), zorder=6,
                        arrowprops=dict(arrowstyle="->", color=col, lw=1.5))

    scan = sim.scans[i]
    labels = gt.labels[i]
    valid = labels >= 0
    pose = Pose2D.from_array(poses[i])
    pts = pose.transform_points(scan.points(valid))
    lab = labels[valid]
    static = lab == 0
    ax.scatter(pts[static, 0], pts[static, 1], s=4, color="tab:blue", label="scan: static hits", zorder=7,
               linewidths=0)
    for j, m in enumerate(gt.movers):
        sel = lab == m.id
        if np.any(sel):
            ax.scatter(pts[sel, 0], pts[sel, 1], s=9, color=MOVER_COLORS[j % len(MOVER_COLORS)], zorder=8,
                       edgecolors="black", linewidths=0.3)
    if np.any(~static):
        ax.scatter([], [], s=9, color="white", edgecolors="black", linewidths=0.5, label="scan: mover hits")
    ax.plot(pose.x, pose.y, marker="o", ms=7, color="0.2", zorder=9, label="laser pose")
    ax.annotate("", xy=(pose.x + 0.8 * np.cos(pose.theta), pose.y + 0.8 * np.sin(pose.theta)),
                xytext=(pose.x, pose.y), zorder=9, arrowprops=dict(arrowstyle="-|>", color="0.2", lw=1.8))

    ax.set_aspect("equal")
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_xlabel(f"x [m] ({frame} frame)")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    n_none = int((~valid).sum())
    ax.set_title(f"{gt.scenario.name}: scan {i}/{n} at t = {scan.stamp:.2f} s — "
                 f"{int(valid.sum())} returns, {n_none} none, {int((lab > 0).sum())} on movers", fontsize=10)
    if legend_below:
        fig.legend(loc="outside lower center", ncols=3, fontsize=8, framealpha=0.9, markerscale=1.5)
    else:
        fig.legend(loc="outside right upper", fontsize=8, framealpha=0.9, markerscale=1.5)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return Path(path)


def _bounds(segs: np.ndarray) -> tuple[float, float, float, float]:
    xs = segs[:, [0, 2]]
    ys = segs[:, [1, 3]]
    return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())
