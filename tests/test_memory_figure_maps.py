"""Memory pass mem40 (issue 13 item 3): the figures' map images drawn from the output pixels' cells only, with the
pixels matplotlib's own image path gives."""

from __future__ import annotations

import io

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.image import AxesImage, imread  # noqa: E402

from dynslam2d.viz import mapplot  # noqa: E402


def _png(idx: np.ndarray, extent: tuple[float, float, float, float], figsize: tuple[float, float], stock: bool,
         limits: tuple[float, float, float, float] | None = None, paint: list | None = None) -> bytes:
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    im = mapplot.draw_grey_indices(ax, idx.copy(), extent, paint=paint or [])
    if stock:
        im.__class__ = AxesImage  # matplotlib's own image path
    if limits is not None:
        ax.set_xlim(limits[0], limits[1])
        ax.set_ylim(limits[2], limits[3])
    ax.set_aspect("equal")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    return buf.getvalue()


@pytest.mark.parametrize("shape, extent, figsize, limits", [
    ((1701, 1121), (0.0, 56.05, 0.0, 85.05), (10.7, 12.6), None),  # MIT CSAIL's cleaned map: fewer pixels than cells
    ((1350, 2422), (0.0, 121.1, 0.0, 67.5), (10.7, 6.0), None),
    ((40, 60), (0.0, 3.0, 0.0, 2.0), (8.0, 6.0), None),  # more pixels than cells
    ((77, 31), (1.3, 2.85, -0.2, 3.65), (5.0, 7.0), None),
    ((200, 300), (0.0, 15.0, 0.0, 10.0), (8.0, 6.0), (-2.0, 20.0, 1.5, 9.0)),  # axes wider than the map, and cut
])
def test_map_image_pixels_equal_matplotlibs(shape, extent, figsize, limits) -> None:
    rng = np.random.default_rng(sum(shape))
    idx = rng.integers(0, 256, shape).astype(np.uint16)
    erased = rng.random(shape) < 0.01
    paint = [(erased, "#ffb000")]
    assert _png(idx, extent, figsize, False, limits, paint) == _png(idx, extent, figsize, True, limits, paint)


def test_map_image_is_the_grid_and_has_no_map_sized_float_copies() -> None:
    """A map of 3 × 3-pixel blocks drawn 1 cell : 1 pixel shows each cell's grey where the cell is (decoded from the
    PNG), and drawing it allocates far less than matplotlib's float32 copies of the whole map."""
    import tracemalloc

    h, w = 600, 798
    rng = np.random.default_rng(3)
    cells = rng.integers(0, 256, (h // 3, w // 3)).astype(np.uint16)
    idx = np.repeat(np.repeat(cells, 3, axis=0), 3, axis=1)
    fig = Figure(figsize=(w / 100, h / 100), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    mapplot.draw_grey_indices(ax, idx.copy(), (0.0, float(w), 0.0, float(h)))
    ax.set_xlim(0, w)
    ax.set_ylim(0, h)
    fig.canvas.draw()  # (the canvas's buffer and the text's caches first: the traced peak below is the image's)
    tracemalloc.start()
    fig.canvas.draw()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    img = imread(io.BytesIO(buf.getvalue()))  # (h, w, 4) float in 0 … 1, row 0 at the top
    assert img.shape[:2] == (h, w)
    grey = np.round(img[::-1, :, 0] * 255).astype(int)  # row 0 at the bottom, as the map's
    centre = grey[1::3, 1::3]  # each block's centre pixel: its cell whatever the edge rounding
    want = mapplot._grey_colormap()(cells, bytes=True)[..., 0].astype(int)
    assert np.array_equal(centre, want)
    assert peak < 10 * h * w  # ≈ 6 bytes a cell here; matplotlib's own path: ≈ 22 (float32 copies of the map)


def test_clean_up_returns_the_freed_count_windows_before_the_cleaned_copies(monkeypatch) -> None:
    """``clean_windows(keep_counts=False)`` hands the count windows' freed memory back to the OS (memtrim) after it
    lets them go and before it copies the map; the cleaned map is the one of ``keep_counts=True``."""
    from dynslam2d.gridmap import GridMap
    from dynslam2d.slam import cleanup
    from dynslam2d.slam.cleanconfig import CleanConfig

    rng = np.random.default_rng(2)
    shape = (40, 50)
    online = GridMap(np.where(rng.random(shape) < 0.2, np.nan, rng.random(shape)), 0.05, (0.0, 0.0))

    def counts() -> cleanup.CountWindows:
        r = np.random.default_rng(4)
        win = [r.integers(0, 30, shape).astype(np.uint16) for _ in range(3)]
        return cleanup.CountWindows(*win, r.random(shape) < 0.5, CleanConfig(), 10, 0, 0.0, 0)

    seen: list[bool] = []
    kept = counts()

    def spy() -> bool:
        seen.append(kept.hits.size == 0)  # the windows were let go before the call
        return True

    monkeypatch.setattr(cleanup, "release_free_memory", spy)
    lean = cleanup.clean_windows(online, kept, keep_counts=False)
    assert seen == [True]
    full = cleanup.clean_windows(online, counts(), keep_counts=True)
    assert seen == [True]  # (nothing to return when the windows are kept)
    assert np.array_equal(lean.grid.prob, full.grid.prob, equal_nan=True)
    assert np.array_equal(lean.erased, full.erased)


def test_figure_maps_are_made_without_importing_matplotlib() -> None:
    """The grey indices of map.png and tracks.png's background are made while the run's float64 maps are alive; they
    need no matplotlib (its import holds ≈ 14 MiB, which then sits on top of those maps)."""
    import subprocess
    import sys

    code = ("import sys, numpy as np\n"
            "from dynslam2d.gridmap import GridMap\n"
            "from dynslam2d.viz.mapplot import GreyMap\n"
            "from dynslam2d.viz.tracksplot import tracks_background\n"
            "g = GridMap(np.random.default_rng(0).random((30, 40)), 0.05, (0.0, 0.0))\n"
            "GreyMap.of(g); tracks_background(g)\n"
            "print('matplotlib' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_grey_levels_are_the_colormaps() -> None:
    """The constant number of greys is the "gray" colormap's (matplotlib's default ``image.lut``): the indices of
    :func:`grey_indices` are the colormap's own lookup."""
    grey = mapplot._grey_colormap()
    v = np.linspace(0.0, 1.0, 1001)
    assert grey.N == mapplot.GREY_LEVELS
    assert np.array_equal(grey(mapplot.grey_indices(v[None, :])[0]), grey(v))
