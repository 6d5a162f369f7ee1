"""Pass mem61 (issue 13 item 3): the run's online map is an :class:`~dynslam2d.pipeline.ExportGridMap` whose float64
probabilities are made when first read, the clean-up pass reads it a band of rows at a time without making it, and
the front end's export is held packed while the loop closure re-renders the map (its arrays let go)."""

from __future__ import annotations

import gc
import pickle

import numpy as np
from conftest import ScanList
from test_memory_released_outputs import _loop_run

from dynslam2d import pipeline
from dynslam2d.config import Config
from dynslam2d.gridmap import GridMap
from dynslam2d.pipeline import ExportGridMap, _MapExport, _PackedExport, run
from dynslam2d.slam import cleanup
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.grid import logistic_map


def _export(shape: tuple[int, int] = (300, 70), seed: int = 4, share: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    unknown = rng.random(shape) < share  # (never-updated cells)
    lo = np.where(unknown, 0.0, rng.normal(0.0, 2.0, shape)).astype(np.float32)
    return lo, unknown


def test_export_grid_is_made_on_read_with_the_exports_values() -> None:
    lo, unknown = _export()
    g = ExportGridMap(lo, unknown, 0.05, (1.5, -2.0))
    want = logistic_map(lo, unknown)
    assert g.shape == lo.shape and not g.made  # (its shape does not make it)
    for r0, r1 in ((0, 256), (256, 512), (7, 9)):
        assert np.array_equal(g.prob_rows(r0, r1), want[r0:r1], equal_nan=True)
    assert not g.made  # (nor do its rows)
    assert np.array_equal(g.prob, want, equal_nan=True) and g.made and g.prob is g.prob
    assert np.array_equal(g.prob_rows(3, 50), want[3:50], equal_nan=True)
    copy = pickle.loads(pickle.dumps(ExportGridMap(lo, unknown, 0.05, (1.5, -2.0))))
    assert np.array_equal(copy.prob, want, equal_nan=True) and copy.origin == (1.5, -2.0)


def _counts(shape: tuple[int, int]) -> cleanup.CountWindows:
    r = np.random.default_rng(6)
    win = [r.integers(0, 30, shape).astype(np.uint16) for _ in range(3)]
    return cleanup.CountWindows(*win, r.random(shape) < 0.5, CleanConfig(restore_min_hits=5), 10, 0, 0.0, 0)


def test_clean_pass_reads_the_online_map_by_rows_without_making_it(tmp_path) -> None:
    """Across several bands of rows (300 rows: 256 + 44), the pass on an online map made on read erases and restores
    the cells the pass on the plain map does, and leaves the online map unmade (fails when the pass reads
    ``online.prob`` whole)."""
    from dynslam2d.io.mapfile import write_map

    lo, unknown = _export()
    lazy = ExportGridMap(lo, unknown, 0.05, (1.5, -2.0))
    plain = GridMap(logistic_map(lo, unknown), 0.05, (1.5, -2.0))
    a = cleanup.clean_windows(lazy, _counts(lo.shape), lo, keep_counts=False)
    b = cleanup.clean_windows(plain, _counts(lo.shape), lo, keep_counts=False)
    assert not lazy.made
    assert a.erased.any() and a.restored.any()
    assert np.array_equal(a.erased, b.erased) and np.array_equal(a.restored, b.restored)
    assert {k: v for k, v in a.stats.items() if k != "pass_time_s"} == {
        k: v for k, v in b.stats.items() if k != "pass_time_s"}
    write_map(tmp_path / "a.yaml", a.grid)
    write_map(tmp_path / "b.yaml", b.grid)
    assert (tmp_path / "a.pgm").read_bytes() == (tmp_path / "b.pgm").read_bytes()


def test_packed_export_unpacks_to_the_same_arrays() -> None:
    lo, unknown = _export((37, 53), 9, 0.85)  # (MIT CSAIL: 87 % never updated)
    e = _MapExport(lo, unknown, 0.05, (0.5, 1.0))
    p = _PackedExport.of(e)
    assert p is not None and p.bits.nbytes + p.values.nbytes < (lo.nbytes + unknown.nbytes) / 2
    u = p.unpack()
    assert u.logodds.dtype == np.float32 and np.array_equal(u.logodds, lo) and np.array_equal(u.unknown, unknown)
    assert (u.resolution, u.origin) == (0.05, (0.5, 1.0))
    lo[unknown.nonzero()[0][0], unknown.nonzero()[1][0]] = 0.5  # a never-updated cell's log-odds not 0: not packed
    assert _PackedExport.of(_MapExport(lo, unknown, 0.05, (0.5, 1.0))) is None


def test_run_lets_the_front_export_go_while_re_rendering_and_keeps_its_map_unmade(monkeypatch) -> None:
    """While the loop closure re-renders, no full-size export of the front end's map is alive (only its packed form);
    the run's map comes out the same values, and the clean-up pass does not make it (fails when the front end's export
    is kept through the render, or when the pass reads the whole online map)."""
    scans, meta = _loop_run()
    render = pipeline.render_map
    seen: list[tuple[int, int]] = []

    def spy(loop, *a, **k):  # type: ignore[no-untyped-def]
        gc.collect()  # (type(o): isinstance on a dead weak proxy among the objects raises ReferenceError)
        exports = [o for o in gc.get_objects() if issubclass(type(o), _MapExport)]
        packed = [o for o in gc.get_objects() if issubclass(type(o), _PackedExport)]
        seen.append((len(exports), len(packed)))
        return render(loop, *a, **k)

    recorder = cleanup.CleanupRecorder(keep_counts=False)
    monkeypatch.setattr(pipeline, "render_map", spy)
    res = run(ScanList(scans, meta), Config(), observers=[recorder])
    assert res.loop is not None and seen and seen[0] == (0, 1)
    assert isinstance(res.grid, ExportGridMap) and not res.grid.made  # through the clean-up pass
    assert recorder.result is not None
    monkeypatch.setattr(pipeline, "render_map", render)
    plain = run(ScanList(scans, meta), Config())
    assert np.array_equal(res.grid.prob, plain.grid.prob, equal_nan=True)
    assert np.array_equal(res.logodds, plain.logodds)


def test_packed_export_grid_makes_the_same_map_by_rows() -> None:
    lo, unknown = _export((300, 70), 11, 0.85)
    g = ExportGridMap(lo, unknown, 0.05, (1.5, -2.0))
    want = logistic_map(lo, unknown)
    assert g.pack() and not g.made and g.shape == lo.shape and not g.pack()
    for r0, r1 in ((0, 256), (256, 512), (7, 9), (3, 4)):  # (bands not starting on a whole byte of the mask)
        assert np.array_equal(g.prob_rows(r0, r1), want[r0:r1], equal_nan=True)
    assert np.array_equal(g.prob, want, equal_nan=True) and g.made


def test_released_results_make_the_online_map_from_its_packed_log_odds(tmp_path, monkeypatch) -> None:
    """The command line's results pack the run's log-odds once written: the online float64 map is then made a band of
    rows at a time (fails when ``write_outputs`` does not pack: the whole map made at once beside its log-odds), with
    the same files as the results of a run whose map is made at once."""
    from dynslam2d import results

    scans, meta = _loop_run()
    files = {}
    for name, rows in (("whole", None), ("bands", 8)):
        recorder = cleanup.CleanupRecorder(keep_counts=False)
        res = run(ScanList(scans, meta), Config(), observers=[recorder])
        made: list[int] = []
        logistic = pipeline.logistic_map

        def spy(lo, unknown, _made=made, _logistic=logistic):  # type: ignore[no-untyped-def]
            _made.append(lo.shape[0])
            return _logistic(lo, unknown)

        monkeypatch.setattr(pipeline, "logistic_map", spy)
        if rows is None:
            res.grid.prob  # noqa: B018  (made at once, as before)
        else:
            monkeypatch.setattr(pipeline, "_PROB_ROWS", rows)
        out = tmp_path / name
        results.write_outputs(res, out, cleaned=recorder.result, release=True)
        monkeypatch.undo()
        if rows is not None:
            assert len(made) > 10 and max(made) <= rows
        files[name] = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix in (".pgm", ".npy", ".png")}
    assert files["whole"] == files["bands"] and len(files["whole"]) == 6
