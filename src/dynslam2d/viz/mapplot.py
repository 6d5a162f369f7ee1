"""The map figure: occupancy grid with trajectories, tracks and removed points, axes in metres."""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.types import Box
from dynslam2d.viz import style
from dynslam2d.viz.figure import new_figure, save_png, tight_layout
from dynslam2d.viz.trackpaths import TrackPath, label_tracks


def occupancy_image(grid: GridMap) -> np.ndarray:
    """(H, W) grey values for display: free → white, occupied → black, unknown → light grey."""
    img = 1.0 - np.nan_to_num(grid.prob, nan=0.5)
    img[~grid.known()] = UNKNOWN_GREY
    return img


#: Grey value of unobserved cells in :func:`occupancy_image` (0 black … 1 white).
UNKNOWN_GREY = 0.8


def removed_label(n_removed: int, n_drawn: int) -> str:
    """Legend text of the removed points: the removed beams of the run, and how many are drawn."""
    if n_drawn >= n_removed:
        return f"removed beams ({n_removed:,})"
    return f"removed beams ({n_removed:,}; {n_drawn:,} drawn)"


def draw_grey(ax: Any, img: np.ndarray, extent: tuple[float, float, float, float],
              erased: np.ndarray | None = None, erased_colour: str | None = None,
              paint: Sequence[tuple[np.ndarray | None, str]] = (), **kw: Any) -> Any:
    """``imshow`` of the grey values ``img`` ((H, W), 0 … 1, row 0 at the bottom) through matplotlib's
    "gray" colormap, with the cells of ``erased`` ((H, W) bool) painted in ``erased_colour`` and
    those of each ``(mask, colour)`` of ``paint`` in its colour (later layers over earlier ones;
    ``erased`` last).

    Draws the same pixels as ``imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="nearest")``
    with an opaque overlay of ``erased``, with a fraction of the memory: the image is handed over as
    (H, W) uint16 indices into the colormap's 256 greys (+ the erased colour) and resampled as data,
    where matplotlib would otherwise colour the whole grid into float RGBA copies before resampling
    (about 200 MiB for MIT CSAIL's 1699 × 1122 cells; issue 13 item 3).
    """
    return draw_grey_indices(ax, grey_indices(img), extent, erased, erased_colour, paint, **kw)


#: Rows of the map converted at a time by :func:`grey_indices` / :func:`occupancy_indices` (bounds the
#: float64 temporaries to a few MB whatever the map's size; issue 13 item 3).
_ROWS_PER_CHUNK = 256


#: Greys of the figures' maps: the "gray" colormap with this many colours (matplotlib's default ``image.lut``).
#: A constant, so the maps become grey indices without importing matplotlib (≈ 14 MiB, while the run's float64 maps
#: are still alive; issue 13 item 3).
GREY_LEVELS = 256


def _grey_colormap() -> Any:
    """matplotlib's "gray" colormap with :data:`GREY_LEVELS` colours (itself unless ``image.lut`` is changed)."""
    from matplotlib import colormaps

    grey = colormaps["gray"]
    return grey if grey.N == GREY_LEVELS else grey.resampled(GREY_LEVELS)


def grey_indices(img: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(H, W) uint16 index of each grey value of ``img`` (0 … 1) into the "gray" colormap's N = :data:`GREY_LEVELS`
    colours: the colormap's own lookup, floor(v·N) with 1.0 → N − 1 (values outside [0, 1] clipped)."""
    n = GREY_LEVELS
    if out is None:
        out = np.empty(img.shape, dtype=np.uint16)
    for r0 in range(0, img.shape[0], _ROWS_PER_CHUNK):
        part = img[r0:r0 + _ROWS_PER_CHUNK]
        out[r0:r0 + _ROWS_PER_CHUNK] = np.clip((np.clip(part, 0.0, 1.0) * n).astype(np.int64), 0, n - 1)
    return out


def occupancy_indices(grid: GridMap, fade: float | None = None, dtype: type = np.uint16) -> np.ndarray:
    """:func:`grey_indices` of :func:`occupancy_image` (optionally faded towards white,
    ``1 − fade·(1 − grey)``), computed a block of rows at a time: the same values without the map-sized
    float64 copies. ``dtype``: the indices' (uint8 holds the :data:`GREY_LEVELS` greys but no painted colour)."""
    prob = grid.prob
    out = np.empty(prob.shape, dtype=dtype)
    for r0 in range(0, prob.shape[0], _ROWS_PER_CHUNK):
        part = prob[r0:r0 + _ROWS_PER_CHUNK]
        img = 1.0 - np.nan_to_num(part, nan=0.5)
        img[~np.isfinite(part)] = UNKNOWN_GREY
        if fade is not None:
            img = 1.0 - fade * (1.0 - img)
        grey_indices(img, out[r0:r0 + _ROWS_PER_CHUNK])
    return out


@dataclass(frozen=True, eq=False)
class GreyMap:
    """A map already converted to the grey indices a figure draws (:func:`occupancy_indices`), with its extent
    (xmin, xmax, ymin, ymax), m, and cell size, m (0 when not given): 2 bytes per cell where the :class:`GridMap`
    takes 8 (issue 13 item 3)."""

    indices: np.ndarray  # (H, W) uint16 (uint8: tracks.png's faint map, never painted), row 0 at the bottom
    extent: tuple[float, float, float, float]
    resolution: float = 0.0
    #: Colours already painted into ``indices`` (:func:`paint_grey`), in order (index GREY_LEVELS + k for the k-th),
    #: each with its number of cells.
    painted: tuple[tuple[str, int], ...] = ()

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) cells."""
        return self.indices.shape  # type: ignore[return-value]

    @classmethod
    def of(cls, grid: GridMap, fade: float | None = None) -> GreyMap:
        """:func:`occupancy_indices` of ``grid`` (``fade`` as there) with its extent and resolution."""
        return cls(occupancy_indices(grid, fade), grid.extent, float(grid.resolution))


def paint_grey(grey: GreyMap, paint: Sequence[tuple[np.ndarray | None, str]]) -> GreyMap:
    """``grey`` with the cells of each ``(mask, colour)`` of ``paint`` ((H, W) bool masks on its cells; later layers
    over earlier ones; empty or differently shaped masks skipped) painted into its indices (in place; a uint16 copy
    of uint8 indices), as :func:`draw_grey_indices` paints them, and the colours with their cell counts recorded in
    ``painted``: the masks are not needed to draw it (they go before matplotlib's import; issue 13 item 3, pass
    mem49). Needs no matplotlib."""
    idx = grey.indices
    painted = list(grey.painted)
    for mask, colour in paint:
        done = _paint_cells(idx, mask, GREY_LEVELS + len(painted))
        if done is not None:
            idx = done
            painted.append((colour, int(np.count_nonzero(mask))))
    return GreyMap(idx, grey.extent, grey.resolution, tuple(painted))


def _paint_cells(idx: np.ndarray, mask: np.ndarray | None, index: int) -> np.ndarray | None:
    """``idx`` with the cells of ``mask`` set to ``index`` (in place, or in a uint16 copy when ``index`` does not
    fit ``idx``'s type); None, ``idx`` untouched, when ``mask`` is None, shaped otherwise or empty."""
    if mask is None or mask.shape != idx.shape or not mask.any():
        return None
    if index > np.iinfo(idx.dtype).max:  # (a uint8 map's 256 greys leave no index for a colour)
        idx = idx.astype(np.uint16)
    idx[mask] = index
    return idx


def draw_grey_indices(ax: Any, idx: np.ndarray, extent: tuple[float, float, float, float],
                      erased: np.ndarray | None = None, erased_colour: str | None = None,
                      paint: Sequence[tuple[np.ndarray | None, str]] = (), painted: Sequence[str] = (),
                      **kw: Any) -> Any:
    """:func:`draw_grey` of grey indices already computed (:func:`grey_indices`, :func:`occupancy_indices`;
    ``idx`` is painted over in place, or a uint16 copy of a uint8 ``idx`` when a painted colour needs an index past
    255). ``painted``: the colours :func:`paint_grey` painted into ``idx`` already (``GreyMap.painted``'s)."""
    from matplotlib.colors import ListedColormap, NoNorm, to_rgba

    grey = _grey_colormap()
    colours = grey(np.arange(grey.N))
    for colour in painted:
        colours = np.vstack((colours, to_rgba(colour)))
    layers = list(paint) + ([(erased, erased_colour)] if erased_colour is not None else [])
    for mask, colour in layers:
        done = _paint_cells(idx, mask, len(colours))
        if done is not None:
            idx = done
            colours = np.vstack((colours, to_rgba(colour)))
    # imshow keeps a masked copy of its array (matplotlib's ``safe_masked_invalid(copy=True)``; no cell is masked, the
    # indices being integers): the image draws ``idx`` itself instead, so the figure holds the map's indices once, not
    # twice, while it is saved (MIT CSAIL: 3.6 MiB; issue 13 item 3, pass mem49). imshow is given a 1 × 2 stand-in of
    # ``idx``'s type and range (the norm's limits, as of ``idx``), so the copy is not even made (pass mem61: it
    # stayed in the heap's pages). The caller does not change ``idx`` after this.
    stand_in = np.array([[idx.min(), idx.max()]], dtype=idx.dtype) if idx.size and extent is not None else idx
    im = ax.imshow(stand_in, cmap=ListedColormap(colours), norm=NoNorm(), origin="lower", extent=extent,
                   interpolation="nearest", interpolation_stage="data", **kw)
    im.__class__ = _index_image_class()  # the same pixels, sampled without map-sized float32 copies
    im._A = np.ma.array(idx, copy=False)
    im._imcache = None
    return im


def _picked(image: Any, n: int, out_len: int, t: Any, axis: int) -> np.ndarray:
    """(out_len,) int64: the cell along ``axis`` (1: columns, 0: rows) of an ``n``-cell image that matplotlib's
    nearest resampling under transform ``t`` (cells → output pixels) puts in each output column (row), −1 where the
    pixel is outside the image. Found by resampling a one-cell-thick probe of the cell numbers (+1, so 0 marks
    outside) stretched over the other axis: nearest resampling of an axis-aligned affine map picks columns and
    rows independently, so the probe's picks are the image's."""
    from matplotlib.image import _resample
    from matplotlib.transforms import Affine2D

    cells = np.arange(1, n + 1, dtype=np.float32)  # exact in float32 up to 2**24
    if axis == 1:
        got = _resample(image, cells[None, :], (1, out_len), Affine2D().scale(1.0, image._A.shape[0]) + t)[0]
    else:
        got = _resample(image, cells[:, None], (out_len, 1), Affine2D().scale(image._A.shape[1], 1.0) + t)[:, 0]
    return got.astype(np.int64) - 1


#: Output rows of an index image made and drawn at a time (:func:`_index_image_class`): bounds the image's pixels
#: held while a figure is saved to a band of rows (≈ 0.3 MiB at map.png's width; issue 13 item 3, pass mem61).
_DRAW_ROWS = 64


@functools.cache
def _index_image_class() -> type:
    """A matplotlib ``AxesImage`` for :func:`draw_grey_indices`' (H, W) colour indices (``NoNorm``,
    ``interpolation="nearest"``, ``interpolation_stage="data"``, ``origin="lower"``, no alpha) that makes the
    same RGBA pixels as ``AxesImage`` from the output pixels' cells only: matplotlib's own path converts the whole
    image to float32, makes a float32 mask of it and a flipped contiguous copy of each to resample them (≈ 16 bytes
    per cell: ≈ 30 MiB for MIT CSAIL's cleaned map while map.png is saved; issue 13 item 3). Here the picked column
    and row of each output pixel come from matplotlib's resampler itself (:func:`_picked`), and the pixels are the
    colormap's bytes of those cells. Drawn on an Agg canvas, the pixels are made and blended :data:`_DRAW_ROWS`
    output rows at a time (Agg blends each pixel of an image placed at whole pixels on its own: the same canvas
    bytes; pass mem61), not as one output-sized image (MIT CSAIL's map.png: ≈ 5 MiB)."""
    from matplotlib.artist import allow_rasterization
    from matplotlib.colors import NoNorm
    from matplotlib.image import AxesImage
    from matplotlib.transforms import Affine2D, Bbox, TransformedBbox

    class IndexImage(AxesImage):
        def _own_path(self, A, unsampled):  # type: ignore[no-untyped-def]
            """None when matplotlib's own path makes this image's pixels, else whether ``A`` holds indices."""
            indexed = A.ndim == 2 and self._interpolation_stage == "data" and isinstance(self.norm, NoNorm)
            rgba = A.ndim == 3 and A.shape[-1] == 4 and A.dtype == np.float32  # (points_overlay's)
            if (unsampled or not (indexed or rgba) or self.get_interpolation() != "nearest" or self.origin != "lower"
                    or self.get_alpha() is not None):
                return None
            return indexed

        def _pixel_bands(self, A, in_bbox, out_bbox, clip_bbox, magnification, round_to_pixel_border,  # type: ignore[no-untyped-def]
                         indexed):
            """(x0, y0, t, h, w, bands): ``_make_image``'s offset and transform, the output's size and an iterator
            of (first output row, that band's (n, w, 4) uint8 pixels); None when nothing is drawn."""
            clipped = Bbox.intersection(out_bbox, clip_bbox)
            if clipped is None:
                return None
            # matplotlib's own output box and transform (AxesImage._make_image): rounded to the output pixels
            e = clipped.extents * magnification
            if round_to_pixel_border:
                e = np.array([np.floor(e[0] + 0.5), np.ceil(e[1] - 0.5 - 1e-8), np.floor(e[2] + 0.5 + 1e-8),
                              np.ceil(e[3] - 0.5)])
            box = Bbox.from_extents(e)
            if box.width == 0 or box.height == 0:
                return None
            t = (Affine2D().scale(in_bbox.width / A.shape[1], in_bbox.height / A.shape[0])
                 .translate(in_bbox.x0, in_bbox.y0) + self.get_transform()
                 + Affine2D().scale(magnification).translate(-box.x0, -box.y0))
            h, w = int(box.height), int(box.width)
            cols = _picked(self, A.shape[1], w, t, 1)
            rows = _picked(self, A.shape[0], h, t, 0)
            rows_in, cols_in = np.maximum(rows, 0), np.maximum(cols, 0)
            if indexed:  # the colormap's bytes (what ``cmap(idx, bytes=True)`` takes them from), per output pixel
                lut, cells = self.cmap(np.arange(self.cmap.N), bytes=True), np.asarray(A)
            else:  # an RGBA image: each cell's bytes as matplotlib's RGBA path makes them (_cell_bytes)
                lut, cells = _cell_bytes(self, np.asarray(A)), None
            cols_out = cols < 0

            def bands():  # type: ignore[no-untyped-def]
                # a block of output rows at a time: no (h, w) array of the picked indices (pass mem49)
                for r0 in range(0, h, _DRAW_ROWS):
                    rr = rows_in[r0:r0 + _DRAW_ROWS]
                    band = (lut[cells[np.ix_(rr, cols_in)]] if cells is not None
                            else lut[rr[:, None] * A.shape[1] + cols_in[None, :]])
                    rows_out = rows[r0:r0 + _DRAW_ROWS] < 0
                    if rows_out.any() or cols_out.any():  # pixels outside the image: matplotlib's value 0, transparent
                        outside = rows_out[:, None] | cols_out[None, :]
                        band[outside] = lut[0] if indexed else 0
                        band[outside, 3] = 0
                    yield r0, band

            return box.x0 / magnification, box.y0 / magnification, t, h, w, bands()

        def _make_image(self, A, in_bbox, out_bbox, clip_bbox, magnification=1.0,  # type: ignore[no-untyped-def]
                        unsampled=False, round_to_pixel_border=True):
            indexed = self._own_path(A, unsampled)
            if indexed is None:
                return super()._make_image(A, in_bbox, out_bbox, clip_bbox, magnification, unsampled,
                                           round_to_pixel_border)
            plan = self._pixel_bands(A, in_bbox, out_bbox, clip_bbox, magnification, round_to_pixel_border, indexed)
            if plan is None:
                return None, 0, 0, None
            x0, y0, t, h, w, bands = plan
            output = np.empty((h, w, 4), dtype=np.uint8)
            for r0, band in bands:
                output[r0:r0 + len(band)] = band
            return output, x0, y0, t

        @allow_rasterization
        def draw(self, renderer):  # type: ignore[no-untyped-def]
            """``AxesImage.draw``; on a renderer that places images at whole pixels (Agg), a band of
            :data:`_DRAW_ROWS` output rows at a time: the image's row r at ``y0 + r`` (``draw_image`` puts the
            image's first row at its ``y``, the bottom), each pixel blended as in the whole image."""
            if (not self.get_visible() or self.get_array().size == 0 or not hasattr(renderer, "_renderer")
                    or (renderer.option_scale_image() and self._check_unsampled_image())):
                return super().draw(renderer)
            magnification = renderer.get_image_magnification()
            indexed = self._own_path(self._A, False)
            if indexed is None or magnification != 1.0:
                return super().draw(renderer)
            # AxesImage.make_image's boxes
            x1, x2, y1, y2 = self.get_extent()
            bbox = Bbox(np.array([[x1, y1], [x2, y2]]))
            clip = ((self.get_clip_box() or self.axes.bbox) if self.get_clip_on()
                    else self.get_figure(root=True).bbox)
            plan = self._pixel_bands(self._A, bbox, TransformedBbox(bbox, self.get_transform()), clip,
                                     magnification, True, indexed)
            if plan is None or plan[0] != int(plan[0]) or plan[1] != int(plan[1]):
                return super().draw(renderer)
            x0, y0, _t, _h, _w, bands = plan
            gc = renderer.new_gc()
            self._set_gc_clip(gc)
            gc.set_alpha(self._get_scalar_alpha())
            gc.set_url(self.get_url())
            gc.set_gid(self.get_gid())
            for r0, band in bands:
                renderer.draw_image(gc, x0, y0 + r0, band)
            gc.restore()
            self.stale = False
            return None

    return IndexImage


def _cell_bytes(image: Any, A: np.ndarray) -> np.ndarray:
    """(H·W, 4) uint8: the pixel matplotlib's RGBA path (``_ImageBase._make_image``, matplotlib 3.11: premultiplied by
    its alpha, resampled, divided by the resampled alpha, ``to_rgba(bytes=True)``) makes of each cell of the (H, W, 4)
    float32 image ``A`` under ``image``'s nearest resampling: a pixel takes one cell's value through the same
    arithmetic whatever the scale, so the cells resampled one to one give every pixel's bytes (pass mem49)."""
    from matplotlib.image import _resample
    from matplotlib.transforms import Affine2D

    alpha_in = A[..., 3]
    if (alpha_in != 1).any():
        A = A * alpha_in[..., None]
        A[..., 3] = alpha_in
    res = _resample(image, A, A.shape[:2], Affine2D())
    alpha_out = res[..., 3].copy()
    res /= np.where(alpha_out != 0, alpha_out, 1)[..., None]
    res[..., 3] = alpha_out
    return np.asarray(image.to_rgba(res, bytes=True, norm=False)).reshape(-1, 4)


def points_overlay(
    xy: np.ndarray, extent: tuple[float, float, float, float], cell: float, colour: str,
    min_alpha: float = 0.35,
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """An RGBA density image (row 0 at the bottom) of the points ``xy`` in ``colour``.

    Every ``cell``-sized square hit by a point gets ``colour`` with an opacity that grows
    with its count, from ``min_alpha`` (one point) to 1 (at and above the 90th percentile
    of the counts), so busy places stand out and the exact colour appears there. Drawn with
    ``imshow(origin="lower", interpolation="nearest")``. Args: ``xy`` (n, 2) map-frame
    points, m; ``extent`` (xmin, xmax, ymin, ymax), m; ``cell`` square side, m.
    Returns the image and its extent.
    """
    x0, x1, y0, y1 = extent
    w = max(1, int(np.ceil((x1 - x0) / cell)))
    h = max(1, int(np.ceil((y1 - y0) / cell)))
    img = np.zeros((h, w, 4), dtype=np.float32)
    if len(xy):
        c = np.floor((xy[:, 0] - x0) / cell).astype(np.int64)
        r = np.floor((xy[:, 1] - y0) / cell).astype(np.int64)
        ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        counts = np.bincount(r[ok] * w + c[ok], minlength=h * w).reshape(h, w).astype(np.float64)
        hit = counts > 0
        if hit.any():
            sat = max(float(np.percentile(counts[hit], 90)), 1.0)
            alpha = np.clip(min_alpha + (1.0 - min_alpha) * (counts - 1.0) / max(sat - 1.0, 1e-9), min_alpha, 1.0)
            img[hit, :3] = style.rgb01(colour)
            img[hit, 3] = alpha[hit] if sat > 1.0 else 1.0
    return img, (x0, x0 + w * cell, y0, y0 + h * cell)


def scale_bar_length(width_m: float) -> float:
    """A round length (1, 2 or 5 × 10^k m) of at most a fifth of ``width_m``."""
    raw = width_m / 5.0
    bar = float(10 ** np.floor(np.log10(max(raw, 1e-3))))
    for m in (5.0, 2.0):
        if bar * m <= raw:
            return bar * m
    return bar


def frame_metric_axes(ax: Any, extent: tuple[float, float, float, float]) -> None:
    """Axes in metres over ``extent`` (xmin, xmax, ymin, ymax), equal aspect, with a scale bar
    outside the map area (below its lower-right corner, so it hides no cell)."""
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    draw_scale_bar(ax, extent)


def draw_scale_bar(ax: Any, extent: tuple[float, float, float, float]) -> float:
    """Draw a labelled scale bar of a round length (:func:`scale_bar_length` of ``extent``'s width,
    m) below the lower-right corner of the axes, outside the map area (at the height of the
    x-axis label, which is centred); return its length, m. The artist carries ``gid="scale_bar"``."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    x0, x1, y0, y1 = extent
    bar = scale_bar_length(x1 - x0)
    # upper-right corner anchored at the axes' lower-right corner, moved in by ``borderpad`` font
    # sizes (down, under the tick labels, and left): beside the centred axis label
    sb = AnchoredSizeBar(ax.transData, bar, f"{bar:g} m", loc="upper right", bbox_to_anchor=(1.0, 0.0),
                         bbox_transform=ax.transAxes, borderpad=2.2, pad=0.0, sep=2, frameon=False,
                         size_vertical=0.008 * (y1 - y0), color="black", fontproperties={"size": "small"})
    sb.set_gid("scale_bar")
    sb.set_clip_on(False)
    ax.add_artist(sb)
    return bar


def map_figure_size(extent: tuple[float, float, float, float], width_in: float = 8.0) -> tuple[float, float]:
    """Figure size (in) for a map of ``extent`` (m) with an equal-aspect axes ``width_in`` wide."""
    x0, x1, y0, y1 = extent
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    return width_in, min(max(width_in * aspect, 3.0), 12.0) + 0.6


def draw_box(ax: Any, box: Box, colour: str, lw: float = 1.5, zorder: float = 5, **kw: Any) -> None:
    """Outline of an oriented box (map frame, m)."""
    c = box.corners()
    ax.plot(np.r_[c[:, 0], c[0, 0]], np.r_[c[:, 1], c[0, 1]], color=colour, lw=lw, zorder=zorder, **kw)


def plot_map(
    path: str | os.PathLike[str],
    grid: GridMap | GreyMap,
    trajectory_xy: np.ndarray | None = None,
    *,
    reference_xy: np.ndarray | None = None,
    title: str = "",
    dpi: int = 120,
    tracks: Sequence[TrackPath] | None = None,
    boxes: Sequence[tuple[int, Box]] | None = None,
    removed_xy: np.ndarray | None = None,
    erased: np.ndarray | None = None,
    low_support: np.ndarray | None = None,
    lost: np.ndarray | None = None,
    jumps: np.ndarray | None = None,
    warning: str | None = None,
    loop_edges: np.ndarray | None = None,
    memory_erased: np.ndarray | None = None,
    removed_count: int | None = None,
) -> Path:
    """Write a PNG of ``grid`` with trajectories, track paths and removed points.

    Args:
        path: PNG to write (atomically).
        grid: the map, in the map frame, or its :meth:`GreyMap.of` (with its resolution; its indices are
            painted over).
        trajectory_xy: (n, 2) estimated laser positions in the map frame, m.
        reference_xy: (n, 2) ground-truth positions already expressed in the map frame, m.
        tracks: track paths (map frame) to draw; tracks ever in M in :data:`style.TRACK_M`,
            others in :data:`style.TRACK_OTHER` (dashed); ids at the end of each path.
        boxes: (id, box) of the tracks to outline (map frame): write_figures passes the final
            boxes of the tracks confirmed at the end that were ever in M (a box on a static
            wall, a track never in M, is not drawn).
        removed_xy: (k, 2) endpoints of removed beams in the map frame, m, drawn in
            :data:`style.REMOVED` (exact colour, one square per map cell hit); may be a subsample.
        removed_count: the number of removed beams of the whole run, named in the legend (the
            points drawn may be a subsample of them); default ``len(removed_xy)``.
        erased: (H, W) bool, same cells as ``grid``: cells the clean-up pass erased
            (docs/maps.md), drawn in :data:`style.ERASED`.
        low_support, lost: (n,) bool per trajectory pose: poses matched with low support are
            marked in :data:`style.LOW_SUPPORT`, poses while lost in :data:`style.LOST`.
        jumps: (n,) bool per trajectory pose: scans where the front end snapped back after drifting
            (``pose_confidence.jumps`` of summary.json), marked with a cross in :data:`style.JUMP`.
        warning: a line drawn in a red box over the map (the pose cannot be trusted).
        loop_edges: (k, 2, 2) loop closures as segments between the two keyframe positions (map
            frame, m), drawn in :data:`style.LOOP_EDGE`.
        memory_erased: (H, W) bool, same cells as ``grid``: cells whose evidence retroactive erasure
            took out during the run (what a parked object wrote before it left, docs/maps.md), drawn in
            :data:`style.MEMORY_ERASED` (under the clean-up's cells).
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    extent = grid.extent
    fw, fh = map_figure_size(extent)
    fig = new_figure((fw + 2.7, fh))
    ax = fig.subplots()
    handles: list[Any] = []
    # the cells a GreyMap has painted in already (paint_grey: the masks let go before the figure), by colour
    pre = dict(grid.painted) if isinstance(grid, GreyMap) else {}
    has_erased = style.ERASED in pre or (erased is not None and erased.shape == grid.shape and bool(erased.any()))
    has_mem = style.MEMORY_ERASED in pre or (memory_erased is not None and memory_erased.shape == grid.shape
                                             and bool(memory_erased.any()))
    # one image with the erased cells painted in (opaque, so the same pixels as an overlay); the
    # clean-up's cells over retroactive erasure's
    paint = [(m, c) for m, c, on in ((memory_erased, style.MEMORY_ERASED, has_mem), (erased, style.ERASED, has_erased))
             if on and c not in pre]
    draw_grey_indices(ax, grid.indices if isinstance(grid, GreyMap) else occupancy_indices(grid), extent,
                      paint=paint, painted=list(pre))
    # the three greys of occupancy_image
    handles += [Patch(facecolor="black", edgecolor="0.3", label="occupied"),
                Patch(facecolor="white", edgecolor="0.3", label="free"),
                Patch(facecolor=str(UNKNOWN_GREY), edgecolor="0.3", label="not observed")]
    if has_mem:
        n_me = pre[style.MEMORY_ERASED] if style.MEMORY_ERASED in pre else int(memory_erased.sum())  # type: ignore[union-attr]
        handles.append(Patch(color=style.MEMORY_ERASED,
                             label=f"erased when a parked\nobject left ({n_me * grid.resolution ** 2:.2f} m²)"))
    if has_erased:
        n_er = pre[style.ERASED] if style.ERASED in pre else int(erased.sum())  # type: ignore[union-attr]
        handles.append(Patch(color=style.ERASED, label=f"erased by clean-up ({n_er * grid.resolution ** 2:.2f} m²)"))
    if removed_xy is not None and len(removed_xy):
        # At least ~1.5 px per square at 8 in × dpi so that single points stay visible.
        cell = max(grid.resolution, (extent[1] - extent[0]) / (8.0 * dpi / 1.5))
        img, ext = points_overlay(np.asarray(removed_xy, dtype=np.float64), extent, cell, style.REMOVED)
        im = ax.imshow(img, origin="lower", extent=ext, interpolation="nearest", zorder=2)
        # the same pixels from the output pixels' cells only: matplotlib resamples the whole overlay into output-sized
        # float32 RGBA copies (negative_2's map.png: ≈ 25 MiB while it is saved; pass mem49)
        im.__class__ = _index_image_class()
        n_rm = len(removed_xy) if removed_count is None else int(removed_count)
        handles.append(Patch(color=style.REMOVED, label=removed_label(n_rm, len(removed_xy))))
    if reference_xy is not None and len(reference_xy):
        handles += ax.plot(reference_xy[:, 0], reference_xy[:, 1], color=style.GROUND_TRUTH, lw=1.2,
                           label="ground truth", zorder=3)
    if trajectory_xy is not None and len(trajectory_xy):
        handles += ax.plot(trajectory_xy[:, 0], trajectory_xy[:, 1], color=style.TRAJECTORY, lw=1.2,
                           label="estimated trajectory", zorder=4)
        # small and hollow, under both lines: a robot turning in place keeps them visible
        handles += ax.plot(*trajectory_xy[0], marker="o", mfc="none", mec=style.TRAJECTORY, mew=1.0, ms=4,
                           ls="none", label="start", zorder=2.9)
    if loop_edges is not None and len(loop_edges):
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(np.asarray(loop_edges, dtype=np.float64), colors=style.LOOP_EDGE,
                                         linewidths=0.6, alpha=0.8, zorder=4.2))
        handles.append(Line2D([], [], color=style.LOOP_EDGE, lw=0.8, label=f"loop closures ({len(loop_edges)})"))
    if trajectory_xy is not None and len(trajectory_xy):
        for mask, colour, label in ((low_support, style.LOW_SUPPORT, "low-support poses"),
                                    (lost, style.LOST, "poses while lost")):
            if mask is not None and len(mask) == len(trajectory_xy) and np.any(mask):
                m = np.asarray(mask, dtype=bool)
                handles += ax.plot(trajectory_xy[m, 0], trajectory_xy[m, 1], marker=".", ms=3, ls="none",
                                   color=colour, label=f"{label} ({int(m.sum())})", zorder=4.5)
        if jumps is not None and len(jumps) == len(trajectory_xy) and np.any(jumps):
            m = np.asarray(jumps, dtype=bool)
            handles += ax.plot(trajectory_xy[m, 0], trajectory_xy[m, 1], marker="X", ms=9, mew=0.8, mec="white",
                               ls="none", color=style.JUMP, label=f"front-end jumps ({int(m.sum())})", zorder=4.6)
    if tracks:
        any_m = any_other = False
        for tp in tracks:
            colour = style.TRACK_M if tp.ever_in_m else style.TRACK_OTHER
            any_m |= tp.ever_in_m
            any_other |= not tp.ever_in_m
            ax.plot(tp.xy[:, 0], tp.xy[:, 1], color=colour, lw=1.3, ls="-" if tp.ever_in_m else "--",
                    alpha=0.9, zorder=5)
        span = max(extent[1] - extent[0], extent[3] - extent[2])
        for tp in label_tracks(tracks, span):
            colour = style.TRACK_M if tp.ever_in_m else style.TRACK_OTHER
            ax.text(tp.xy[-1, 0], tp.xy[-1, 1], f" {tp.id}", color=colour, fontsize=7, fontweight="bold",
                    ha="left", va="bottom", zorder=8, clip_on=True)
        if any_m:
            handles.append(Line2D([], [], color=style.TRACK_M, lw=1.3, label="track path (in M)"))
        if any_other:
            handles.append(Line2D([], [], color=style.TRACK_OTHER, lw=1.3, ls="--", label="track path (never in M)"))
    if boxes:
        for _tid, box in boxes:
            draw_box(ax, box, "black", lw=1.2, zorder=6)
        handles.append(Line2D([], [], color="black", lw=1.2, label=f"final boxes of tracks in M ({len(boxes)})"))
    frame_metric_axes(ax, extent)
    if warning:
        import textwrap

        ax.text(0.5, 0.98, textwrap.fill(warning, 60), transform=ax.transAxes, ha="center", va="top",
                fontsize="small", color="white", zorder=20,
                bbox={"facecolor": style.LOST, "edgecolor": "none", "boxstyle": "round,pad=0.3"})
    if title:
        ax.set_title(title)
    if handles:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small",
                  framealpha=0.9, borderaxespad=0.0)
    tight_layout(fig)
    return save_png(fig, path, dpi)
