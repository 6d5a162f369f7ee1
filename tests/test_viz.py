"""Figures and animation of a run: map.png, tracks.png, errors.png, run.gif (dynslam2d.viz)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from dynslam2d.config import Config, with_overrides
from dynslam2d.pipeline import Pipeline, run
from dynslam2d.results import ground_truth_for, write_results
from dynslam2d.sim import SimSource
from dynslam2d.viz import style
from dynslam2d.viz.animate import Animator
from dynslam2d.viz.collect import RemovedPointsCollector
from dynslam2d.viz.errorsplot import map_difference
from dynslam2d.viz.gif import GifStream, fixed_palette
from dynslam2d.viz.trackpaths import track_paths, tracks_to_draw
from dynslam2d.viz.tracksplot import plot_tracks, speed_limit

FRAME_STEP = 5


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """sim:paper, 8 s (160 scans), with the default filter (plus the animation) and without filter."""
    source = SimSource("paper", duration=8.0)
    sim = source.simulation
    gt = ground_truth_for(source, None, 0.05)
    out = {}
    for mode in ("default", "none"):
        d = tmp_path_factory.mktemp(f"viz-{mode}")
        col = RemovedPointsCollector()
        observers: list = [col]
        anim = None
        if mode == "default":
            anim = Animator(d / "run.gif", frame_step=FRAME_STEP)
            observers.append(anim)
        res = run(sim.source(), with_overrides(Config(), {"filter": {"mode": mode}}), observers=observers)
        paths = write_results(res, d, gt, col)
        out[mode] = {"result": res, "paths": paths, "collector": col, "animator": anim, "dir": d}
    return sim, gt, out


def _rgb(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def _count(img: np.ndarray, colour: str, tol: int = 0) -> int:
    ref = np.array(style.rgb255(colour))
    return int((np.abs(img.astype(int) - ref).max(axis=2) <= tol).sum())


def test_results_folder_holds_every_figure(runs):
    _, _, out = runs
    for mode in ("default", "none"):
        paths = out[mode]["paths"]
        for name in ("map.png", "tracks.png", "errors.png"):
            assert paths[name].exists() and paths[name].stat().st_size > 10_000, (mode, name)
            img = Image.open(paths[name])
            assert img.format == "PNG"
        # 8 in map + 2.7 in legend (the map greys, the removed-beam count; issue 15 item 7) at 120 dpi;
        # the paper room is about square.
        w, h = Image.open(paths["map.png"]).size
        assert w == 1284 and 700 <= h <= 1300
        w, h = Image.open(paths["errors.png"]).size
        assert w == 960 and h > 1000
    assert "run.gif" not in out["none"]["paths"]


def test_map_png_shows_removed_points_only_when_the_filter_removed_beams(runs):
    _, _, out = runs
    assert out["default"]["result"].removed.sum() > 100
    assert out["none"]["result"].removed.sum() == 0
    with_filter = _count(_rgb(out["default"]["paths"]["map.png"]), style.REMOVED)
    without = _count(_rgb(out["none"]["paths"]["map.png"]), style.REMOVED)
    assert with_filter > 200  # busy cells are drawn in the exact colour
    assert without == 0
    # Tracks that were in M are drawn (their colour appears) in both runs.
    assert _count(_rgb(out["default"]["paths"]["map.png"]), style.TRACK_M, tol=10) > 50


def test_collector_points_are_the_removed_beams_in_the_map_frame(runs):
    sim, _, _ = runs
    pipe = Pipeline()
    col = RemovedPointsCollector(per_scan=10_000)
    checked = 0
    for scan in sim.scans[:120]:
        step = pipe.process(scan)
        before = len(col.per_scan)
        col.on_scan(scan, step, pipe)
        mask = step.removed & scan.valid_mask()
        if mask.any():
            assert len(col.per_scan) == before + 1
            want = step.pose.transform_points(scan.points(mask))
            np.testing.assert_allclose(col.per_scan[-1], want, atol=1e-4)
            checked += 1
        else:
            assert len(col.per_scan) == before
    assert checked > 10
    assert col.points().shape == (sum(len(p) for p in col.per_scan), 2)


def test_collector_memory_is_bounded(runs):
    sim, _, out = runs
    full = out["default"]["collector"]
    pipe = Pipeline()
    small = RemovedPointsCollector(per_scan=8, max_points=100)
    for scan in sim.scans:
        small.on_scan(scan, pipe.process(scan), pipe)
    assert small.n_removed == full.n_removed > 500
    assert 50 <= len(small.points()) <= 100
    assert all(len(p) <= 8 for p in small.per_scan)


def test_tracks_png_draws_coloured_paths(runs, tmp_path):
    _, _, out = runs
    res = out["default"]["result"]
    paths = track_paths(res.track_rows)
    assert set(paths) == {r[1] for r in res.track_rows}
    tid = next(iter(paths))
    rows = [r for r in res.track_rows if r[1] == tid]
    p = paths[tid]
    assert len(p.stamps) == len(rows) and np.all(np.diff(p.stamps) > 0)
    np.testing.assert_allclose(p.speed, [np.hypot(r[8], r[9]) for r in rows])
    assert list(p.in_m) == [r[10] for r in rows]
    drawn = [q for q in paths.values() if q.ever_confirmed]
    assert any(q.ever_in_m for q in drawn)
    assert all(q.ever_in_m or q.states[-1] == "confirmed"
               for q in tracks_to_draw(paths, float(res.trajectory.stamps[-1])))
    assert 0.5 <= speed_limit(drawn) <= 3.0

    def colourful(path) -> int:
        img = _rgb(path).astype(int)
        return int(((img.max(axis=2) - img.min(axis=2)) > 80).sum())

    empty = plot_tracks(tmp_path / "empty.png", [], res.grid)
    with_tracks = out["default"]["paths"]["tracks.png"]
    assert Image.open(empty).size == Image.open(with_tracks).size
    # Only the colour bar is colourful without tracks; the speed-coloured paths add many pixels.
    assert colourful(with_tracks) > colourful(empty) + 2000


def test_errors_png_shows_ghosts_of_the_unfiltered_run(runs):
    _, gt, out = runs
    counts = {}
    for mode in ("default", "none"):
        res = out[mode]["result"]
        from dynslam2d.results import compute_metrics

        m = compute_metrics(res, gt)
        al = m["alignment"]
        from dynslam2d.types import Pose2D

        diff = map_difference(res.grid, gt.static_map, Pose2D(al["x"], al["y"], al["theta"]))
        # Same sets as the metrics.
        assert diff.n_ghost == m["map"]["ghost_cells"]
        assert diff.classes.shape[0] > 100
        counts[mode] = (diff.n_ghost, _count(_rgb(out[mode]["paths"]["errors.png"]), style.GHOST))
    assert counts["none"][0] > 20 and counts["none"][1] > 100
    assert counts["none"][1] > 3 * counts["default"][1]


def test_gif_has_one_frame_per_step_and_shows_kept_and_removed_points(runs):
    _, _, out = runs
    n = out["default"]["result"].n_scans
    anim = out["default"]["animator"]
    gif = out["default"]["dir"] / "run.gif"
    assert anim.written == gif and gif.exists()
    expected = len(range(0, n, FRAME_STEP)) + (1 if (n - 1) % FRAME_STEP else 0)
    im = Image.open(gif)
    assert im.n_frames == expected == anim.n_frames
    assert im.size == (720, 600)
    assert im.info.get("loop") == 0 and im.info.get("duration") == 100
    counts = []
    for k in range(0, im.n_frames, 4):
        im.seek(k)
        f = np.asarray(im.convert("RGB"))
        counts.append((_count(f, style.KEPT), _count(f, style.REMOVED)))
    counts = np.array(counts)
    # Frame 0 (first scan): nothing removed yet, so only the legend swatch has the removed colour.
    legend_removed = counts[0, 1]
    assert 0 < legend_removed < 100
    assert counts[0, 0] > 5 * legend_removed  # the scan points kept, besides their legend swatch
    assert (counts[1:, 1] - legend_removed).max() > 40  # later frames show removed points
    assert (counts[:, 0] > 500).all()


def test_gif_stream_palette_and_frame_size(tmp_path):
    pal = {tuple(c) for c in fixed_palette()}
    for c in (style.REMOVED, style.KEPT, style.TRACK_M, style.GHOST, style.MISSED):
        assert style.rgb255(c) in pal
    g = GifStream(tmp_path / "a.gif", duration_ms=50)
    frame = np.full((20, 30, 3), 255, np.uint8)
    frame[5:10, 5:10] = style.rgb255(style.REMOVED)
    g.add(frame)
    with pytest.raises(ValueError):
        g.add(np.zeros((21, 30, 3), np.uint8))
    g.add(frame[::-1].copy())
    assert g.close() == tmp_path / "a.gif"
    im = Image.open(tmp_path / "a.gif")
    assert im.n_frames == 2
    im.seek(1)
    back = np.asarray(im.convert("RGB"))
    np.testing.assert_array_equal(back, frame[::-1])
    assert GifStream(tmp_path / "none.gif").close() is None and not (tmp_path / "none.gif").exists()


def test_figures_leave_the_callers_matplotlib_backend_alone(runs, tmp_path):
    """A program that draws with its own backend keeps it after the library writes figures."""
    import matplotlib

    _, gt, out = runs
    before = matplotlib.get_backend()
    matplotlib.use("svg")
    try:
        d = out["default"]
        paths = write_results(d["result"], tmp_path, gt, d["collector"])
        assert matplotlib.get_backend() == "svg"
        assert all(paths[n].stat().st_size > 10_000 for n in ("map.png", "tracks.png", "errors.png"))
    finally:
        matplotlib.use(before)


def test_figure_counts_match_summary(runs):
    """map.png names the removed beams of the run (summary.json's share × beams, not the drawn
    subsample) and tracks.png names summary.json's track counts (issue 15 item 7)."""
    import json

    from dynslam2d.viz.figures import removed_beams, tracks_title

    _, _, out = runs
    d = out["default"]
    res, col = d["result"], d["collector"]
    summary = json.loads((d["dir"] / "summary.json").read_text())
    n = removed_beams(res)
    assert n > 100 and n == int(res.removed.sum()) == round(summary["removed_beam_share"] * res.removed.size)
    assert n >= len(col.points())
    title = tracks_title(track_paths(res.track_rows))
    assert f"{summary['tracks']} tracks" in title and f"{summary['tracks_in_M']} in M" in title
