"""Figures that never touch pyplot, and saving them: PNG, atomically.

Figures are plain :class:`matplotlib.figure.Figure` objects on an Agg canvas, so drawing one
neither switches the backend of a user's own program nor registers it with pyplot's global
figure manager (nothing to close, nothing leaks when a caller forgets).
"""

from __future__ import annotations

import gc
import os
from pathlib import Path
from typing import Any

from dynslam2d.io.atomic import atomic_path
from dynslam2d.memtrim import release_free_memory


def new_figure(figsize: tuple[float, float], dpi: float | None = None, layout: str | None = None) -> Any:
    """A matplotlib ``Figure`` of ``figsize`` inches at ``dpi`` (``layout`` as matplotlib's), drawn by Agg."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def drop_renderer(fig: Any) -> None:
    """Free the Agg renderer ``fig``'s canvas caches and its pixel buffer (width × height × 4 bytes); the next
    draw makes a new one."""
    canvas = getattr(fig, "canvas", None)
    if canvas is not None and hasattr(canvas, "renderer"):
        del canvas.renderer
        canvas._lastKey = None  # (FigureCanvasAgg reuses its renderer when this key matches)


def tight_layout(fig: Any) -> None:
    """``fig.tight_layout()`` with the text measured on a 1 × 1 px Agg renderer at the figure's dpi.

    matplotlib's own call measures it on the canvas's renderer, whose pixel buffer is the whole figure at its dpi
    (width × height × 4 bytes: 5.1 MiB for MIT CSAIL's map.png at 100 dpi), made only to measure text and never
    drawn on. The text's extents depend on the dpi, not on the buffer's size: the layout, hence the PNG, is the same
    (docs/speed.md, pass mem55). The small renderer is dropped afterwards, as savefig makes its own at its dpi."""
    from matplotlib.backends.backend_agg import RendererAgg

    canvas = fig.canvas
    width, height = canvas.get_width_height(physical=True)
    canvas.renderer = RendererAgg(1, 1, fig.dpi)
    canvas._lastKey = (width, height, fig.dpi)  # FigureCanvasAgg.get_renderer hands out its renderer on this key
    try:
        fig.tight_layout()
    finally:
        drop_renderer(fig)


def save_png(fig: Any, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """Write matplotlib figure ``fig`` as a PNG at ``path`` (atomically), then empty it: its artists (the map
    images and their resampled copies) and the canvas's Agg pixel buffer are freed now, not when the garbage
    collector next finds the figure's reference cycles (collected here: pass mem48), so the next figure of a run is
    not drawn on top of them (docs/speed.md, memory). The renderer a layout step left on the canvas goes before
    savefig makes its own. The figure is not drawn again after this."""
    path = Path(path)
    # a layout step (tight_layout) measured the text on an Agg renderer at the figure's dpi, which the canvas keeps
    # with its pixel buffer; savefig draws on a new one at ``dpi`` (or clears and redraws that one): dropped first,
    # the two buffers are never held together (docs/speed.md, pass mem46)
    drop_renderer(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    fig.clear()
    drop_renderer(fig)
    # the artists ``clear`` let go are reference cycles (an axes and its children point at each other): the cyclic
    # collector frees them, with the map images' resampled copies and caches, now rather than when it next runs a
    # full collection (not before the next figure: MIT CSAIL's tracks.png was drawn on top of map.png's ≈ 13 MiB;
    # docs/speed.md, pass mem48)
    gc.collect()
    release_free_memory()  # and what they held back to the OS (memtrim.py)
    return path
