"""Memory pass mem49 (issue 13 item 3): map.png's erased cells painted into its grey indices before the figure (the
masks let go), the map image drawing the caller's indices instead of imshow's copy of them, and tracks.png's faint
map one byte per cell, all with the same PNG bytes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from conftest import ScanList  # noqa: E402
from test_memory_released_outputs import _loop_run  # noqa: E402

from dynslam2d.config import Config  # noqa: E402
from dynslam2d.gridmap import GridMap  # noqa: E402
from dynslam2d.pipeline import run  # noqa: E402
from dynslam2d.viz import mapplot, style  # noqa: E402
from dynslam2d.viz.figure import new_figure  # noqa: E402
from dynslam2d.viz.tracksplot import MAP_FADE, tracks_background  # noqa: E402


def _grey(shape: tuple[int, int], seed: int) -> tuple[mapplot.GreyMap, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, 256, shape).astype(np.uint16)
    memory = rng.random(shape) < 0.03
    erased = rng.random(shape) < 0.03  # (some cells in both: the clean-up's colour must be drawn over)
    assert (memory & erased).any()
    return mapplot.GreyMap(idx, (0.0, shape[1] * 0.05, 0.0, shape[0] * 0.05), 0.05), memory, erased


def test_painted_grey_map_draws_the_same_png_as_the_masks(tmp_path) -> None:
    """A map whose erased cells :func:`paint_grey` painted in (the masks then let go) gives map.png's bytes of the
    same map drawn with the masks, legend counts included; painting a uint8 map makes uint16 indices."""
    grey, memory, erased = _grey((300, 420), 7)
    want = mapplot.plot_map(tmp_path / "masks.png", mapplot.GreyMap(grey.indices.copy(), grey.extent, grey.resolution),
                            erased=erased, memory_erased=memory).read_bytes()
    painted = mapplot.paint_grey(mapplot.GreyMap(grey.indices.copy(), grey.extent, grey.resolution),
                                 [(memory, style.MEMORY_ERASED), (erased, style.ERASED), (None, "#000000"),
                                  (np.zeros((2, 2), dtype=bool), "#000000")])
    assert painted.painted == ((style.MEMORY_ERASED, int(memory.sum())), (style.ERASED, int(erased.sum())))
    assert mapplot.plot_map(tmp_path / "painted.png", painted).read_bytes() == want
    small = mapplot.GreyMap(grey.indices.astype(np.uint8), grey.extent, grey.resolution)
    small = mapplot.paint_grey(small, [(memory, style.MEMORY_ERASED), (erased, style.ERASED)])
    assert small.indices.dtype == np.uint16
    np.testing.assert_array_equal(small.indices, painted.indices)


def test_map_image_draws_the_callers_indices_and_a_uint8_map_is_painted_in_uint16() -> None:
    idx = np.random.default_rng(2).integers(0, 256, (120, 90)).astype(np.uint8)
    ax = new_figure((4.0, 4.0)).subplots()
    im = mapplot.draw_grey_indices(ax, idx, (0.0, 4.5, 0.0, 6.0))
    assert np.shares_memory(np.ma.getdata(im.get_array()), idx)  # (imshow's masked copy let go)
    mask = np.zeros(idx.shape, dtype=bool)
    mask[10:20, 5:9] = True
    im2 = mapplot.draw_grey_indices(ax, idx, (0.0, 4.5, 0.0, 6.0), paint=[(mask, style.ERASED)])
    got = np.ma.getdata(im2.get_array())
    assert got.dtype == np.uint16 and (got[mask] == mapplot.GREY_LEVELS).all() and idx.max() < 256


def test_tracks_background_is_one_byte_per_cell_with_the_same_greys() -> None:
    prob = np.random.default_rng(4).uniform(0.0, 1.0, (50, 70))
    prob[::7, ::5] = np.nan
    grid = GridMap(prob, 0.05, (0.0, 0.0))
    bg = tracks_background(grid)
    assert bg.indices.dtype == np.uint8
    np.testing.assert_array_equal(bg.indices, mapplot.occupancy_indices(grid, fade=MAP_FADE))


def test_released_figures_let_the_erased_masks_go_before_map_png(tmp_path, monkeypatch) -> None:
    import dynslam2d.results as R
    import dynslam2d.viz.figures as F
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    res = run(ScanList(scans, meta), cfg, observers=[rec])
    cleaned = rec.result
    assert cleaned is not None
    n_erased = int(cleaned.erased.sum())
    seen: dict[str, object] = {}
    plot_fn = F.plot_map

    def map_spy(path, grid, *a, **k):  # type: ignore[no-untyped-def]
        seen["at_map"] = (res.erased, cleaned.erased.size, k["erased"], k["memory_erased"], grid.painted)
        return plot_fn(path, grid, *a, **k)

    monkeypatch.setattr(F, "plot_map", map_spy)
    R.write_outputs(res, tmp_path, cleaned=cleaned, release=True)
    painted = ((style.ERASED, n_erased),) if n_erased else ()
    assert seen["at_map"] == (None, 0, None, None, painted)


def _overlay_png(img: np.ndarray, extent: tuple[float, float, float, float], figsize: tuple[float, float],
                 stock: bool, limits: tuple[float, float, float, float] | None) -> bytes:
    ax = new_figure(figsize).subplots()
    mapplot.draw_grey_indices(ax, np.full((10, 10), 200, dtype=np.uint16), extent)
    im = ax.imshow(img, origin="lower", extent=extent, interpolation="nearest", zorder=2)
    if not stock:
        im.__class__ = mapplot._index_image_class()  # as plot_map draws points_overlay's image
    return saved_png(ax, limits)


def saved_png(ax, limits: tuple[float, float, float, float] | None) -> bytes:  # type: ignore[no-untyped-def]
    """PNG bytes (120 dpi) of ``ax``'s figure with its axes limited to ``limits`` (xmin, xmax, ymin, ymax), equal
    aspect."""
    import io

    if limits is not None:
        ax.set_xlim(limits[0], limits[1])
        ax.set_ylim(limits[2], limits[3])
    ax.set_aspect("equal")
    buf = io.BytesIO()
    ax.figure.savefig(buf, format="png", dpi=120)
    return buf.getvalue()


@pytest.mark.parametrize("shape, extent, figsize, limits", [
    ((557, 490), (0.0, 49.0, 0.0, 55.7), (10.7, 9.7), None),  # negative_2's removed points: fewer pixels than cells
    ((40, 60), (0.0, 3.0, 0.0, 2.0), (8.0, 6.0), None),  # more pixels than cells
    ((77, 31), (1.3, 2.85, -0.2, 3.65), (5.0, 7.0), None),
    ((200, 300), (0.0, 15.0, 0.0, 10.0), (8.0, 6.0), (-2.0, 20.0, 1.5, 9.0)),  # axes wider than the map, and cut
])
def test_points_overlay_pixels_equal_matplotlibs(shape, extent, figsize, limits) -> None:
    """The removed points' RGBA overlay drawn from the output pixels' cells gives matplotlib's own PNG bytes, its
    premultiplied-alpha arithmetic included (opacities between the overlay's 0.35 and 1)."""
    rng = np.random.default_rng(sum(shape))
    n = shape[0] * shape[1] * 2  # (counts of 1 to ~8 a cell: opacities between 0.35 and 1)
    xy = np.column_stack((rng.uniform(extent[0], extent[1], n), rng.uniform(extent[2], extent[3], n)))
    cell = (extent[1] - extent[0]) / shape[1]
    img, ext = mapplot.points_overlay(xy, extent, cell, style.REMOVED)
    assert len(np.unique(img[..., 3])) > 3
    assert _overlay_png(img, ext, figsize, False, limits) == _overlay_png(img, ext, figsize, True, limits)
