"""The figures' tight layout measured on a 1 × 1 px renderer (viz/figure.py ``tight_layout``): the same PNG bytes as
matplotlib's own ``tight_layout``, without its figure-sized pixel buffer (issue 13 item 3)."""

from __future__ import annotations

import io

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402

from dynslam2d.viz.figure import new_figure, tight_layout  # noqa: E402


def _figure(dpi: float | None):
    """A map-like figure: an image, a title over two lines, axis labels, a legend outside the axes, a suptitle."""
    fig = new_figure((7.3, 5.1), dpi=dpi)
    ax = fig.subplots()
    ax.imshow(np.arange(48.0).reshape(6, 8), extent=(0.0, 8.0, 0.0, 6.0), interpolation="nearest")
    ax.plot([0.5, 7.5], [0.5, 5.0], label="a trajectory, its label long enough to move the axes")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("a title\nover two lines")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.suptitle("suptitle")
    return fig


def _png(fig, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    return buf.getvalue()


@pytest.mark.parametrize(("fig_dpi", "save_dpi"), [(None, 120), (72, 120), (100, 100), (150, 80)])
def test_small_renderer_layout_gives_matplotlibs_bytes(fig_dpi, save_dpi):
    ours = _figure(fig_dpi)
    tight_layout(ours)
    theirs = _figure(fig_dpi)
    theirs.tight_layout()
    assert ours.subplotpars.left == theirs.subplotpars.left
    assert ours.subplotpars.right == theirs.subplotpars.right
    assert ours.subplotpars.top == theirs.subplotpars.top
    assert _png(ours, save_dpi) == _png(theirs, save_dpi)


def test_layout_never_makes_a_figure_sized_buffer(monkeypatch):
    made: list[tuple[int, int]] = []
    get_renderer = FigureCanvasAgg.get_renderer

    def spy(self):
        r = get_renderer(self)
        made.append((int(r.width), int(r.height)))
        return r

    monkeypatch.setattr(FigureCanvasAgg, "get_renderer", spy)
    fig = _figure(100)
    tight_layout(fig)
    assert made and set(made) == {(1, 1)}
    # and the small renderer is not left on the canvas for savefig to draw on
    assert not hasattr(fig.canvas, "renderer") or fig.canvas._lastKey is None
