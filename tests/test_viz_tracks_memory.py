"""tracks.png drawn with less memory, the same bytes (docs/speed.md, pass mem46): the path collections keep one
array of segments instead of one ``Path`` per segment, and tight_layout's renderer is gone before savefig."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from dynslam2d.viz import tracksplot
from dynslam2d.viz.trackpaths import TrackPath


def _tracks(n_tracks: int = 60, seed: int = 3) -> list[TrackPath]:
    """Random walks that cross each other many times, half of their reports in M (so both collections, the
    faint dashed one semi-transparent, have overlapping segments of different colours)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_tracks):
        n = int(rng.integers(2, 300))
        xy = np.cumsum(rng.normal(0.0, 0.3, (n, 2)), axis=0) + rng.uniform(-4.0, 4.0, 2)
        out.append(TrackPath(id=i, stamps=np.arange(n, dtype=float), xy=xy, velocity=rng.normal(0.0, 1.0, (n, 2)),
                             in_m=rng.random(n) < 0.5, states=np.array(["confirmed"] * n), last_box=None))
    return out


def test_tracks_png_same_bytes_as_one_path_per_segment(tmp_path, monkeypatch):
    tracks = _tracks()
    made: list = []
    lazy_maker = tracksplot._line_collection

    def lazy(segments, **kw):
        made.append(lazy_maker(segments, **kw))
        return made[-1]

    monkeypatch.setattr(tracksplot, "_line_collection", lazy)
    new = tracksplot.plot_tracks(tmp_path / "new.png", tracks, title="t", dpi=60).read_bytes()
    assert len(made) == 2 and all(isinstance(c.get_paths(), tracksplot.SegmentPaths) for c in made)
    assert sum(len(c.get_paths()) for c in made) == sum(len(t.xy) - 1 for t in tracks)
    # matplotlib's own collection: one Path per segment
    monkeypatch.setattr(tracksplot, "_line_collection", lambda segments, **kw: LineCollection(segments, **kw))
    eager = tracksplot.plot_tracks(tmp_path / "eager.png", tracks, title="t", dpi=60).read_bytes()
    assert new == eager


def test_segment_paths_items_and_slices():
    segs = np.arange(24, dtype=float).reshape(6, 2, 2)
    paths = tracksplot.SegmentPaths(segs)
    assert len(paths) == 6
    np.testing.assert_array_equal(paths[4].vertices, segs[4])
    np.testing.assert_array_equal(paths[-1].vertices, segs[5])
    assert [p.vertices.tolist() for p in paths[1:3]] == segs[1:3].tolist()


def test_no_layout_renderer_held_while_saving(tmp_path, monkeypatch):
    held: list[bool] = []
    save = Figure.savefig

    def savefig(self, *a, **k):
        held.append(getattr(self.canvas, "renderer", None) is not None)
        return save(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", savefig)
    tracksplot.plot_tracks(tmp_path / "t.png", _tracks(5), title="t", dpi=40)
    assert held == [False]
