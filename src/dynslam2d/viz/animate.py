"""``run.gif``: an animation of a run, rendered while it runs (a RunObserver)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.types import Scan, Track
from dynslam2d.viz import style
from dynslam2d.viz.figure import new_figure
from dynslam2d.viz.gif import GifStream
from dynslam2d.viz.mapplot import occupancy_image

_MARGINS = {"left": 0.09, "right": 0.98, "bottom": 0.08, "top": 0.93}


class Animator:
    """A :class:`~dynslam2d.pipeline.RunObserver` that writes an animated GIF of the run.

    Every ``frame_step``-th scan (scan indices 0, step, 2·step, …) and the last scan become
    a frame showing, in the map frame (m): the map built so far (grey), the scan's points
    kept (:data:`style.KEPT`) and removed by the filter (:data:`style.REMOVED`), the
    non-tentative tracks as boxes with their ids and a velocity arrow (the motion of the
    next ``arrow_s`` seconds; tracks in M in :data:`style.TRACK_M`, others in
    :data:`style.TRACK_OTHER`), the estimated trajectory and the laser pose.

    Frames are rendered as the run goes and streamed into the GIF encoder
    (:class:`~dynslam2d.viz.gif.GifStream`): memory does not grow with the run length.
    The view only ever grows (it covers the map seen so far), so the picture does not jump.
    The file is written atomically in :meth:`on_finish`.

    Args:
        path: the GIF to write (``run.gif`` in the results folder).
        frame_step: render every this many scans (≥ 1).
        fps: frames per second of the GIF.
        size_px: (width, height) of the frames, pixels.
        arrow_s: length of the velocity arrows, s of motion.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        frame_step: int = 5,
        *,
        fps: float = 10.0,
        size_px: tuple[int, int] = (720, 600),
        arrow_s: float = 1.0,
    ) -> None:
        if frame_step < 1:
            raise ValueError(f"frame_step must be >= 1, got {frame_step}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        self.path = Path(path)
        self.frame_step = int(frame_step)
        self.arrow_s = float(arrow_s)
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self._gif = GifStream(self.path, duration_ms=round(1000.0 / fps))
        self._traj: list[tuple[float, float]] = []
        self._t0: float | None = None
        self._view: np.ndarray | None = None  # xmin, xmax, ymin, ymax, m
        self._fig: Any = None
        self._artists: dict[str, Any] = {}
        self._dynamic: list[Any] = []
        self._pending: tuple[Scan, Any, Any] | None = None  # last scan not rendered yet
        self.written: Path | None = None

    @property
    def n_frames(self) -> int:
        """Frames rendered so far."""
        return self._gif.n_frames

    # ---- RunObserver ---------------------------------------------------------------------
    def on_scan(self, scan: Scan, step: Any, pipeline: Any) -> None:
        self._traj.append((float(step.pose.x), float(step.pose.y)))
        if self._t0 is None:
            self._t0 = float(step.stamp)
        if step.index % self.frame_step == 0:
            self._render(scan, step, pipeline)
            self._pending = None
        else:
            self._pending = (scan, step, pipeline)

    def on_finish(self, result: Any, pipeline: Any) -> None:
        if self._pending is not None:
            self._render(*self._pending)
            self._pending = None
        self.close()

    def close(self) -> Path | None:
        """Write the GIF (if any frame) and release the figure; returns the path written."""
        self._fig = None
        self.written = self._gif.close()
        return self.written

    # ---- drawing -------------------------------------------------------------------------
    def _setup(self) -> None:
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        dpi = 100
        w, h = self.size_px
        fig = new_figure((w / dpi, h / dpi), dpi=dpi)
        ax = fig.subplots()
        fig.subplots_adjust(**_MARGINS)
        a = self._artists
        a["ax"] = ax
        a["map"] = ax.imshow(np.full((2, 2), 0.8), cmap="gray", vmin=0.0, vmax=1.0, origin="lower",
                             extent=(0, 1, 0, 1), interpolation="nearest", zorder=0)
        (a["traj"],) = ax.plot([], [], color=style.TRAJECTORY, lw=1.2, zorder=3)
        a["kept"] = ax.scatter([], [], s=4, c=style.KEPT, marker="s", linewidths=0, zorder=4)
        a["removed"] = ax.scatter([], [], s=9, c=style.REMOVED, marker="s", linewidths=0, zorder=5)
        (a["robot"],) = ax.plot([], [], marker="o", ms=7, color=style.TRAJECTORY, mec="black", zorder=7)
        (a["heading"],) = ax.plot([], [], color="black", lw=1.5, zorder=7)
        a["title"] = ax.set_title("", fontsize=10)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        handles = [
            Line2D([], [], marker="s", ls="none", color=style.KEPT, ms=4, label="scan points kept"),
            Line2D([], [], marker="s", ls="none", color=style.REMOVED, ms=4, label="removed (moving)"),
            Patch(facecolor="none", edgecolor=style.TRACK_M, lw=1.8, label="track in M"),
            Patch(facecolor="none", edgecolor=style.TRACK_OTHER, lw=1.0, label="other track"),
            Line2D([], [], color=style.TRAJECTORY, lw=1.2, label="trajectory"),
        ]
        leg = ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.85)
        leg.set_zorder(20)
        self._fig = fig

    def _grow_view(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        pad = 0.5
        box = np.array([lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad])
        if self._view is None:
            self._view = box
        else:
            v = self._view
            self._view = np.array([min(v[0], box[0]), max(v[1], box[1]), min(v[2], box[2]), max(v[3], box[3])])
        return self._view

    def _equal_scale(self, v: np.ndarray) -> np.ndarray:
        """Widen ``v`` (xmin, xmax, ymin, ymax) about its centre so that 1 m is as long in x as in y."""
        w_px = self.size_px[0] * (_MARGINS["right"] - _MARGINS["left"])
        h_px = self.size_px[1] * (_MARGINS["top"] - _MARGINS["bottom"])
        w, h = v[1] - v[0], v[3] - v[2]
        if w / h < w_px / h_px:
            w = h * w_px / h_px
        else:
            h = w * h_px / w_px
        cx, cy = 0.5 * (v[0] + v[1]), 0.5 * (v[2] + v[3])
        return np.array([cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2])

    def _render(self, scan: Scan, step: Any, pipeline: Any) -> None:
        if self._fig is None:
            self._setup()
        a = self._artists
        ax = a["ax"]
        for art in self._dynamic:
            art.remove()
        self._dynamic = []
        pose = step.pose
        valid = scan.valid_mask()
        removed = np.asarray(step.removed, dtype=bool)
        if removed.shape != valid.shape:
            removed = np.zeros_like(valid)
        kept_xy = pose.transform_points(scan.points(valid & ~removed))
        rem_xy = pose.transform_points(scan.points(valid & removed))
        grid = pipeline.gridmap()
        if grid.prob.size and grid.known().any():
            a["map"].set_data(occupancy_image(grid))
            a["map"].set_extent(grid.extent)
            x0, x1, y0, y1 = grid.extent
            lo, hi = np.array([x0, y0]), np.array([x1, y1])
        else:
            lo = hi = np.array([pose.x, pose.y])
        pts = np.vstack([kept_xy, rem_xy, [[pose.x, pose.y]]])
        # Far outliers (max-range returns) should not blow the view up: use the map and the pose.
        lo = np.minimum(lo, [pose.x, pose.y])
        hi = np.maximum(hi, [pose.x, pose.y])
        if not (grid.prob.size and grid.known().any()):
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        v = self._equal_scale(self._grow_view(lo, hi))
        ax.set_xlim(v[0], v[1])
        ax.set_ylim(v[2], v[3])
        a["kept"].set_offsets(kept_xy if len(kept_xy) else np.zeros((0, 2)))
        a["removed"].set_offsets(rem_xy if len(rem_xy) else np.zeros((0, 2)))
        tr = np.array(self._traj)
        a["traj"].set_data(tr[:, 0], tr[:, 1])
        a["robot"].set_data([pose.x], [pose.y])
        span = max(v[1] - v[0], v[3] - v[2])
        hl = 0.03 * span
        a["heading"].set_data([pose.x, pose.x + hl * np.cos(pose.theta)], [pose.y, pose.y + hl * np.sin(pose.theta)])
        n_m = 0
        for t in step.tracks:
            if t.state == "tentative":
                continue
            n_m += bool(t.in_m)
            self._draw_track(ax, t, span)
        a["title"].set_text(
            f"t = {step.stamp - (self._t0 or 0.0):.1f} s   scan {step.index}   removed {int(removed.sum())} beams   "
            f"tracks in M: {n_m}"
        )
        self._fig.canvas.draw()
        rgba = np.asarray(self._fig.canvas.buffer_rgba())
        self._gif.add(rgba[..., :3])

    def _draw_track(self, ax: Any, t: Track, span: float) -> None:
        colour = style.TRACK_M if t.in_m else style.TRACK_OTHER
        lw = 1.8 if t.in_m else 1.0
        c = t.box.corners()
        (line,) = ax.plot(np.r_[c[:, 0], c[0, 0]], np.r_[c[:, 1], c[0, 1]], color=colour, lw=lw, zorder=6)
        self._dynamic.append(line)
        v = np.asarray(t.velocity, dtype=float)
        if float(np.hypot(*v)) > 0.05:
            d = v * self.arrow_s
            arr = ax.annotate("", xy=(t.box.px + d[0], t.box.py + d[1]), xytext=(t.box.px, t.box.py),
                              arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.4, "shrinkA": 0, "shrinkB": 0,
                                              "mutation_scale": 9}, zorder=6, annotation_clip=True)
            self._dynamic.append(arr)
        txt = ax.text(t.box.px + 0.012 * span, t.box.py + 0.012 * span, str(t.id), color=colour, fontsize=7,
                      fontweight="bold", zorder=8, clip_on=True,
                      bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.6})
        self._dynamic.append(txt)


__all__ = ["Animator"]
