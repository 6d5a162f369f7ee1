"""Memory pass mem48 (issue 13 item 3): a saved figure's artists are collected before the next figure is drawn,
and ``write_outputs(release=True)`` lets the log-odds go as soon as they are written (the log-odds files first), writes
the online map's files and then the cleaned map's, made over the online map's array (pass mem53), which goes before
map.png; the restored cells go before map.png."""

from __future__ import annotations

import gc
import weakref

import numpy as np
from conftest import ScanList
from test_memory_released_outputs import _loop_run

from dynslam2d.config import Config
from dynslam2d.pipeline import run


def test_saved_figure_frees_its_axes_without_waiting_for_the_collector(tmp_path) -> None:
    """``save_png`` empties the figure and collects the reference cycles its axes form with their children (ticks,
    spines, the image): with the automatic collector off, nothing of them is left after the call."""
    from dynslam2d.viz.figure import new_figure, save_png

    enabled = gc.isenabled()
    gc.disable()
    try:
        fig = new_figure((4.0, 3.0))
        ax = fig.subplots()
        ax.imshow(np.arange(40_000, dtype=np.uint16).reshape(200, 200))
        ax.set_title("a title")
        refs = [weakref.ref(ax), weakref.ref(ax.xaxis), weakref.ref(ax.images[0])]
        del ax
        path = save_png(fig, tmp_path / "f.png", dpi=50)
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert [r() is None for r in refs] == [True, True, True]
    finally:
        if enabled:
            gc.enable()


def test_released_outputs_let_the_cleaned_map_go_before_the_online_map_is_written(tmp_path, monkeypatch) -> None:
    import dynslam2d.results as R
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    res = run(ScanList(scans, meta), cfg, observers=[rec])
    cleaned = rec.result
    assert cleaned is not None and cleaned.logodds is not None
    online_ref = weakref.ref(res.grid.prob)  # (the online float64 probabilities: the cleaned map is made over them)
    expect_summary = res.summary()
    seen: list[tuple[str, bool, bool, bool, int]] = []
    write_map = R.write_map

    def spy(path, grid):  # type: ignore[no-untyped-def]
        seen.append((path.name, cleaned.grid is None, cleaned.logodds is None, grid.prob is online_ref(),
                     res.logodds.size))
        return write_map(path, grid)

    import dynslam2d.viz.figures as F

    plot_map = F.plot_map

    def map_spy(*a, **k):  # type: ignore[no-untyped-def]
        seen.append(("map.png", cleaned.grid is None, cleaned.logodds is None, cleaned.restored.size == 0,
                     res.logodds.size))
        return plot_map(*a, **k)

    monkeypatch.setattr(R, "write_map", spy)
    monkeypatch.setattr(F, "plot_map", map_spy)
    out = R.write_outputs(res, tmp_path, cleaned=cleaned, release=True)
    # both log-odds written and gone before the maps; the online map's files first, then the cleaned map made over
    # the online map's array (pass mem53), gone before map.png (and the restored cells, never drawn, before it)
    assert seen == [("map_online.yaml", False, True, True, 0), ("map.yaml", False, True, True, 0),
                    ("map.png", True, True, True, 0)]
    assert online_ref() is None
    drop = ("wall_time_s", "scans_per_s")
    assert {k: v for k, v in out.summary.items() if k not in drop and k in expect_summary} == \
        R.json.loads(R.metrics_json({k: v for k, v in expect_summary.items() if k not in drop}))
