"""Where map.png's resident memory goes (issue 13 item 3): RSS and the exact peak between marks inside the figure
phase of one ``dynslam2d run``, and the import / canvas candidates in a fresh process.

    PYTHONPATH=src python benchmarks/bench_mem_figure.py run ../shared/data/mit-csail/mit-csail.clf
    PYTHONPATH=src python benchmarks/bench_mem_figure.py fresh

Candidates for ``run`` (flags, each output byte-identical on MIT CSAIL): ``--small-layout-renderer`` (the layout's
text measured on a 1 x 1 px renderer: what viz/figure.py's ``tight_layout`` does since pass mem55),
``--trim-after-layout`` (``malloc_trim`` once the layout's renderer is dropped), ``--no-predraw`` (savefig without
the draw its layout engine asks for: ``tight_layout`` leaves a placeholder engine).

``run``: the run's own process; at every mark the RSS now and the peak since the previous mark (the kernel's
high-water mark, reset at each mark through ``/proc/self/clear_refs``: no sampler, nothing between marks is missed).
Marks: the figures' start, map.png's start, ``import matplotlib``, ``matplotlib.figure`` + ``backend_agg``, the
``Figure`` on its canvas, the drawing of the artists (``tight_layout``'s start), ``tight_layout`` (its renderer at the
figure's dpi), ``savefig``'s renderer (at the saving dpi), its draw, the PNG encoding, ``clear``, the collection,
the trim, and the same for tracks.png. ``fresh``: in a new process with NumPy and SciPy's ``ndimage`` loaded, what
each import step adds (pyplot included, for comparison), the font manager's cache load and an Agg renderer of
map.png's MIT CSAIL size at 100 and 120 dpi. Not run by pytest; numbers go to docs/speed.md with this command.
"""

from __future__ import annotations

import functools
import gc
import os
import resource
import sys

from scratch import keep_requested, scratch_dir

PAGE = os.sysconf("SC_PAGE_SIZE")
MARKS: list[tuple[str, float, float]] = []
TAG = ["map"]
FLAGS: set[str] = set()
CANDIDATES = ("--no-predraw", "--small-layout-renderer", "--trim-after-layout")


def _status(key: str) -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) / 1024
    return float("nan")


def mark(label: str) -> None:
    """Record RSS now and the peak RSS since the previous mark (MiB), then reset the high-water mark."""
    MARKS.append((label, _status("VmRSS"), _status("VmHWM")))
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def report() -> None:
    prev = None
    for label, rss, hwm in MARKS:
        d = "" if prev is None else f"{rss - prev:+7.1f}"
        print(f"{label:<44} RSS {rss:7.1f} {d:>8}   peak since last {hwm:7.1f}")
        prev = rss


def _wrapped(owner: object, name: str, before: str | None, after: str | None) -> None:
    fn = getattr(owner, name)

    @functools.wraps(fn)
    def marked(*a, **k):
        if before:
            mark(before)
        try:
            return fn(*a, **k)
        finally:
            if after:
                mark(after)

    setattr(owner, name, marked)


def run(args: list[str]) -> None:
    import dynslam2d.cli
    import dynslam2d.viz.figures as F
    import dynslam2d.viz.mapplot as M
    import dynslam2d.viz.tracksplot as T
    from dynslam2d.io.atomic import atomic_path
    from dynslam2d.memtrim import release_free_memory
    from dynslam2d.viz.figure import drop_renderer

    def new_figure(figsize, dpi=None, layout=None):  # viz/figure.py's, with marks between its imports
        tag = TAG[0]
        import matplotlib

        mark(f"{tag}: import matplotlib")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        mark(f"{tag}: + matplotlib.figure, backend_agg")
        if not hasattr(Figure.tight_layout, "__wrapped__"):
            _wrapped(Figure, "tight_layout", None, None)
            tight = Figure.tight_layout.__wrapped__

            def tight_layout(self, *a, **k):
                mark(f"{TAG[0]}: artists made (tight_layout's start)")
                if "--small-layout-renderer" in FLAGS:  # candidate: text measured on a 1 x 1 px Agg renderer
                    from matplotlib.backends.backend_agg import RendererAgg

                    w, h = self.canvas.get_width_height(physical=True)
                    self.canvas.renderer = RendererAgg(1, 1, self.dpi)
                    self.canvas._lastKey = (w, h, self.dpi)
                out = tight(self, *a, **k)
                mark(f"{TAG[0]}: tight_layout (its renderer at the figure's dpi)")
                return out

            tight_layout.__wrapped__ = tight  # type: ignore[attr-defined]
            Figure.tight_layout = tight_layout
        fig = Figure(figsize=figsize, dpi=dpi, layout=layout)
        FigureCanvasAgg(fig)
        mark(f"{tag}: Figure on its canvas")
        print(f"{tag}.png: figsize {figsize[0]:.3f} x {figsize[1]:.3f} in, figure dpi {fig.dpi:g}", file=sys.stderr)
        del matplotlib
        return fig

    def save_png(fig, path, dpi=120):  # viz/figure.py's, with marks between its steps
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        tag = os.path.basename(str(path))[:-4]
        mark(f"{tag}: save_png's start (tight_layout done)")
        drop_renderer(fig)
        mark(f"{tag}: tight_layout's renderer dropped")
        if "--trim-after-layout" in FLAGS:  # candidate: the layout renderer's pages returned before savefig's
            release_free_memory()
            mark(f"{tag}: malloc_trim after the layout")
        # candidate: savefig without its layout engine's draw (tight_layout leaves a placeholder engine)
        if "--no-predraw" in FLAGS:
            from matplotlib.layout_engine import PlaceHolderLayoutEngine

            if isinstance(fig.get_layout_engine(), PlaceHolderLayoutEngine):
                fig.set_layout_engine(None)
        get_renderer = FigureCanvasAgg.get_renderer
        draw = fig.draw

        def renderer(self):
            r = get_renderer(self)
            mark(f"{tag}: savefig: renderer {r.width} x {r.height} px")
            return r

        def drawn(*a, **k):
            out = draw(*a, **k)
            mark(f"{tag}: savefig: artists drawn")
            return out

        FigureCanvasAgg.get_renderer = renderer
        fig.draw = drawn
        try:
            with atomic_path(path) as tmp:
                fig.savefig(tmp, dpi=dpi, format="png")
        finally:
            FigureCanvasAgg.get_renderer = get_renderer
            del fig.draw
        mark(f"{tag}: savefig's PNG encoding")
        fig.clear()
        drop_renderer(fig)
        mark(f"{tag}: clear + renderer dropped")
        gc.collect()
        mark(f"{tag}: gc.collect")
        release_free_memory()
        mark(f"{tag}: malloc_trim")
        return path

    M.new_figure = new_figure
    T.new_figure = new_figure
    M.save_png = save_png
    T.save_png = save_png
    for name, tag in (("plot_map", "map"), ("plot_tracks", "tracks")):
        fn = getattr(F, name)

        def tagged(*a, _fn=fn, _tag=tag, **k):
            TAG[0] = _tag
            mark(f"{_tag}: start")
            out = _fn(*a, **k)
            mark(f"{_tag}: returned")
            return out

        setattr(F, name, tagged)
    _wrapped(F, "write_figures", "figures: start", "figures: end")
    out = scratch_dir("bench-mem-figure-")
    sys.argv = ["dynslam2d", "run", args[0], "--out", out + "/run", "-q", *args[1:]]
    try:
        dynslam2d.cli.main()
    except SystemExit:
        pass
    report()
    # (clear_refs resets ru_maxrss too: the run's peak is the largest "peak since last")
    print(f"{'ru_maxrss since the last mark':<44} {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.1f} MiB")
    print(f"outputs in {out}/run" + ("" if keep_requested() else " (removed at exit: BENCH_KEEP_SCRATCH=1 keeps them)"))


def fresh() -> None:
    import numpy  # noqa: F401
    import scipy.ndimage  # noqa: F401

    mark("numpy + scipy.ndimage")
    import matplotlib

    mark("import matplotlib")
    import matplotlib.font_manager as fm

    mark("+ matplotlib.font_manager (font list loaded)")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    mark("+ matplotlib.figure, backend_agg")
    import matplotlib.pyplot  # noqa: F401

    mark("+ matplotlib.pyplot (not used by the figures)")
    n = len(sys.modules)
    fig = Figure(figsize=(10.7, 9.6))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.set_title("t")
    mark("Figure + axes")
    fm.findfont("DejaVu Sans")
    for dpi in (100, 120):
        fig.set_dpi(dpi)
        fig.canvas.get_renderer()
        mark(f"Agg renderer at {dpi} dpi ({fig.canvas.renderer.width} x {fig.canvas.renderer.height})")
        del fig.canvas.renderer
        fig.canvas._lastKey = None
        mark("renderer dropped")
    print(f"{n} modules", matplotlib.__version__)
    report()


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in ("run", "fresh"):
        raise SystemExit(__doc__)
    if sys.argv[1] == "run":
        if len(sys.argv) < 3:
            raise SystemExit(__doc__)
        FLAGS.update(a for a in sys.argv[2:] if a.startswith("--") and a in CANDIDATES)
        run([a for a in sys.argv[2:] if a not in CANDIDATES])
    else:
        fresh()


if __name__ == "__main__":
    main()
