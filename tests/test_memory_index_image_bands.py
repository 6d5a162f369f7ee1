"""Pass mem61 (issue 13 item 3): the figures' index images are drawn on Agg a band of output rows at a time (no
output-sized image) and imshow is never handed the map's indices (no masked copy of them): the same PNG bytes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from test_memory_figure_masks import _overlay_png, saved_png  # noqa: E402

from dynslam2d.viz import mapplot, style  # noqa: E402
from dynslam2d.viz.figure import new_figure  # noqa: E402


def _index_png(idx: np.ndarray, extent: tuple[float, float, float, float], figsize: tuple[float, float],
               stock: bool, limits: tuple[float, float, float, float] | None) -> bytes:
    """PNG bytes of ``idx`` drawn by :func:`mapplot.draw_grey_indices` or, ``stock``, by matplotlib's own imshow."""
    from matplotlib.colors import ListedColormap, NoNorm

    ax = new_figure(figsize).subplots()
    if stock:
        grey = mapplot._grey_colormap()
        ax.imshow(idx, cmap=ListedColormap(grey(np.arange(grey.N))), norm=NoNorm(), origin="lower", extent=extent,
                  interpolation="nearest", interpolation_stage="data")
    else:
        mapplot.draw_grey_indices(ax, idx, extent)
    return saved_png(ax, limits)


@pytest.fixture
def bands(monkeypatch) -> list[tuple[float, float, tuple[int, ...]]]:
    """Small bands (7 output rows) and every ``draw_image`` call of the Agg renderers: (x, y, image shape)."""
    from matplotlib.backends import backend_agg

    monkeypatch.setattr(mapplot, "_DRAW_ROWS", 7)
    calls: list[tuple[float, float, tuple[int, ...]]] = []
    update = backend_agg.RendererAgg._update_methods

    def spy(self):  # type: ignore[no-untyped-def]
        update(self)
        draw = self.draw_image

        def draw_image(gc, x, y, im, *a):  # type: ignore[no-untyped-def]
            calls.append((float(x), float(y), im.shape))
            return draw(gc, x, y, im, *a)

        self.draw_image = draw_image

    monkeypatch.setattr(backend_agg.RendererAgg, "_update_methods", spy)
    return calls


@pytest.mark.parametrize("shape, extent, figsize, limits", [
    ((300, 420), (0.0, 21.0, 0.0, 15.0), (8.0, 6.0), None),  # fewer pixels than cells
    ((40, 60), (0.0, 3.0, 0.0, 2.0), (8.0, 6.0), None),  # more pixels than cells
    ((200, 300), (0.0, 15.0, 0.0, 10.0), (8.0, 6.0), (-2.0, 20.0, 1.5, 9.0)),  # axes wider than the map, and cut
])
def test_index_image_drawn_in_bands_gives_matplotlibs_bytes(bands, shape, extent, figsize, limits) -> None:
    idx = np.random.default_rng(sum(shape)).integers(0, 256, shape).astype(np.uint16)
    ours = _index_png(idx, extent, figsize, False, limits)
    n_ours = len(bands)
    assert ours == _index_png(idx, extent, figsize, True, limits)
    drawn = bands[:n_ours]
    assert len(drawn) > 3 and all(s[0] <= 7 for _x, _y, s in drawn)  # (bands, not one output-sized image)
    assert [y - drawn[0][1] for _x, y, _s in drawn] == [7.0 * k for k in range(len(drawn))]


def test_removed_points_overlay_drawn_in_bands_gives_matplotlibs_bytes(bands) -> None:
    shape, extent = (157, 190), (0.0, 19.0, 0.0, 15.7)
    rng = np.random.default_rng(3)
    n = shape[0] * shape[1] * 2
    xy = np.column_stack((rng.uniform(extent[0], extent[1], n), rng.uniform(extent[2], extent[3], n)))
    img, ext = mapplot.points_overlay(xy, extent, 0.1, style.REMOVED)
    assert _overlay_png(img, ext, (8.0, 6.0), False, None) == _overlay_png(img, ext, (8.0, 6.0), True, None)
    assert len(bands) > 6


def test_imshow_never_gets_the_maps_indices(monkeypatch) -> None:
    """imshow is handed a 1 x 2 stand-in of the indices' type and range (its masked copy is of that), the image draws
    the caller's indices, and the norm's limits are those of the indices."""
    from matplotlib import cbook

    copied: list[tuple[int, ...]] = []
    masked = cbook.safe_masked_invalid

    def spy(x, copy=False):  # type: ignore[no-untyped-def]
        copied.append(np.shape(x))
        return masked(x, copy)

    monkeypatch.setattr(cbook, "safe_masked_invalid", spy)
    idx = np.random.default_rng(2).integers(3, 250, (120, 90)).astype(np.uint16)
    im = mapplot.draw_grey_indices(new_figure((4.0, 4.0)).subplots(), idx, (0.0, 4.5, 0.0, 6.0))
    assert copied and idx.shape not in copied
    assert np.shares_memory(np.ma.getdata(im.get_array()), idx)
    assert (im.norm.vmin, im.norm.vmax) == (idx.min(), idx.max())
