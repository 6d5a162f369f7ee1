"""Legibility of map.png / tracks.png / errors.png (issue 15 item 7): legends, scale bar, boxes, labels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dynslam2d.eval.trajectory import ate
from dynslam2d.gridmap import GridMap
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import Box, Pose2D
from dynslam2d.viz import errorsplot, mapplot, style, tracksplot
from dynslam2d.viz.trackpaths import MAX_LABELS, TrackPath, boxes_to_draw, label_tracks


def _track(tid: int, xy: np.ndarray, in_m: bool, states: str = "confirmed", t0: float = 0.0) -> TrackPath:
    n = len(xy)
    return TrackPath(tid, t0 + np.arange(n, dtype=float), np.asarray(xy, dtype=float), np.zeros((n, 2)),
                     np.full(n, in_m), np.array([states] * n), Box(float(xy[-1][0]), float(xy[-1][1]), 0.0, 0.6, 0.4))


def _room(n: int = 120, res: float = 0.05) -> GridMap:
    """A square room: walls occupied, inside free, a band along the left side unobserved."""
    p = np.full((n, n), 0.1)
    p[[0, -1], :] = 0.95
    p[:, [0, -1]] = 0.95
    p[:, :10] = np.nan
    return GridMap(p, res, (-n * res / 2, -n * res / 2))


def _spy(monkeypatch, module) -> dict:
    """Replace ``module.save_png`` with one that draws the figure, writes it and keeps it for inspection (the
    real one empties the figure after writing it: tests/test_memory_lean.py)."""
    seen: dict = {}

    def spy(fig, path, dpi):
        fig.canvas.draw()
        seen["fig"] = fig
        fig.savefig(path, dpi=dpi, format="png")
        return Path(path)

    monkeypatch.setattr(module, "save_png", spy)
    return seen


def _scale_bar(ax):
    bars = [a for a in ax.artists if a.get_gid() == "scale_bar"]
    assert len(bars) == 1
    return bars[0]


def _outside(ax, artist) -> bool:
    """True when ``artist``'s drawn box does not overlap the axes' map area (pixels)."""
    r = ax.figure.canvas.get_renderer()
    a, b = ax.get_window_extent(r), artist.get_window_extent(r)
    return b.y1 <= a.y0 or b.x1 <= a.x0 or b.x0 >= a.x1 or b.y0 >= a.y1


def test_map_legend_names_the_greys_the_true_removed_count_and_the_boxes(tmp_path, monkeypatch):
    seen = _spy(monkeypatch, mapplot)
    grid = _room()
    # a robot turning in place: every position within 2 cm of the start
    ang = np.linspace(0, 6, 50)
    traj = 0.02 * np.c_[np.cos(ang), np.sin(ang)]
    removed = np.random.default_rng(1).uniform(-2, 2, (300, 2))
    tracks = [_track(1, [[0.0, 0.0], [1.0, 1.0]], True), _track(2, [[-1.0, -1.0], [-1.5, -1.0]], False)]
    mapplot.plot_map(tmp_path / "map.png", grid, traj, reference_xy=traj + 0.001, tracks=tracks,
                     boxes=[(1, tracks[0].last_box)], removed_xy=removed, removed_count=1234, dpi=50)
    ax = seen["fig"].axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for name in ("occupied", "free", "not observed", "ground truth", "estimated trajectory", "start"):
        assert name in labels, labels
    # the legend counts the removed beams of the run, not the 300 points drawn
    assert "removed beams (1,234; 300 drawn)" in labels
    assert "final boxes of tracks in M (1)" in labels
    # start marker: hollow, smaller, under both trajectory lines
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    start = lines["start"]
    assert start.get_markerfacecolor() == "none" and start.get_markersize() <= 4
    assert start.get_zorder() < min(lines["ground truth"].get_zorder(), lines["estimated trajectory"].get_zorder())
    # the scale bar sits outside the map area
    assert _outside(ax, _scale_bar(ax))


def test_removed_label_without_subsample():
    assert mapplot.removed_label(56547, 44950) == "removed beams (56,547; 44,950 drawn)"
    assert mapplot.removed_label(12, 12) == "removed beams (12)"


def test_boxes_only_for_tracks_ever_in_m():
    last = 9.0
    wall = _track(3, np.zeros((10, 2)), False)  # confirmed at the end, never in M: a static wall piece
    mover = _track(4, np.c_[np.arange(10.0), np.zeros(10)], True)
    gone = _track(5, np.zeros((4, 2)), True)  # in M, but its last report is before the last scan
    paths = {p.id: p for p in (wall, mover, gone)}
    assert [i for i, _ in boxes_to_draw(paths, last)] == [4]
    assert boxes_to_draw(paths, None) == []


def test_labels_are_thinned_and_capped():
    rng = np.random.default_rng(0)
    # 50 tracks ending within 0.2 m of each other in a 40 m map: one label, the one in M
    cluster = [_track(i, rng.uniform(0, 0.2, (3, 2)), i == 17) for i in range(50)]
    out = label_tracks(cluster, span=40.0)
    assert [t.id for t in out] == [17]
    # spread out: capped at MAX_LABELS, no two within the gap
    spread = [_track(i, np.array([[0.0, 0.0], [x, y]]), False) for i, (x, y) in enumerate(rng.uniform(0, 40, (500, 2)))]
    out = label_tracks(spread, span=40.0)
    assert len(out) == MAX_LABELS
    ends = np.array([t.xy[-1] for t in out])
    d = np.hypot(*(ends[:, None] - ends[None]).transpose(2, 0, 1))
    assert d[~np.eye(len(ends), dtype=bool)].min() >= 0.04 * 40.0


def test_tracks_figure_labels_a_cluster_once_and_keeps_the_scale_bar_outside(tmp_path, monkeypatch):
    seen = _spy(monkeypatch, tracksplot)
    rng = np.random.default_rng(2)
    tracks = [_track(i, rng.uniform(0, 0.3, (4, 2)) + 5.0, False) for i in range(80)]
    tracks.append(_track(999, np.array([[-5.0, -5.0], [-4.0, -5.0]]), True))
    tracksplot.plot_tracks(tmp_path / "t.png", tracks, _room(200), dpi=40)
    ax = seen["fig"].axes[0]
    ids = sorted(t.get_text() for t in ax.texts if t.get_text().isdigit())
    assert len(ids) == 2 and "999" in ids
    assert _outside(ax, _scale_bar(ax)) and _outside(ax, ax.get_legend())


def test_truth_colour_is_not_a_grey_and_far_from_not_observed():
    t, u = np.array(style.rgb255(style.TRUTH_OUTLINE)), np.array(style.rgb255(style.UNKNOWN))
    assert t.max() - t.min() > 60  # a colour, not a grey
    assert np.abs(t - u).max() > 60
    # and not the grey of unobserved cells in map.png either
    g = round(mapplot.UNKNOWN_GREY * 255)
    assert np.abs(t - g).max() > 60


def test_errors_scale_bar_outside_and_free_in_legend(tmp_path, monkeypatch):
    seen = _spy(monkeypatch, errorsplot)
    truth = _room()
    est = GridMap(truth.prob.copy(), truth.resolution, truth.origin)
    stamps = np.arange(20, dtype=float)
    xy = np.c_[np.linspace(-1, 1, 20), np.zeros(20)]
    tr = Trajectory(stamps, np.c_[xy, np.zeros(20)])
    res = ate(tr, tr, align=True)
    diff = errorsplot.map_difference(est, truth, Pose2D(0.0, 0.0, 0.0))
    errorsplot.plot_errors(tmp_path / "e.png", res, diff, dpi=40)
    ax = seen["fig"].axes[1]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "observed, free" in labels and "not observed" in labels
    assert _outside(ax, _scale_bar(ax)) and _outside(ax, ax.get_legend())


if __name__ == "__main__":  # pragma: no cover
    pytest.main([__file__, "-q"])
