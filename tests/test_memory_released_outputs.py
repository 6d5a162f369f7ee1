"""Memory pass mem38 (issue 13 item 3): the place index grows by a quarter, the loop closer lets its places go on
request, and ``write_outputs(release=True)`` writes tracks.csv, kept_mask.npz and the summary without the float64
maps and draws tracks.png without the track rows and the erased cells."""

from __future__ import annotations

import numpy as np
from conftest import ScanList
from test_loops import _block_loop_world, _loop_path, _scans

from dynslam2d.config import Config
from dynslam2d.pipeline import run
from dynslam2d.slam.placedesc import PlaceIndex, polar_descriptors
from dynslam2d.types import SourceMeta


def _loop_run():
    gt = _loop_path(step=0.25, laps=1.3)
    scans = _scans(_block_loop_world(), gt, seed=2)
    return scans, SourceMeta(format="sim", origin="test:block-loop", count=len(scans), beams=360)


def test_place_index_grows_by_a_quarter_and_stores_the_same_spectra() -> None:
    rng = np.random.default_rng(3)
    pts = [rng.uniform(-12.0, 12.0, (int(rng.integers(5, 60)), 2)) for _ in range(700)]
    descs = polar_descriptors(pts, 20, 60, 15.0)
    batched, single = PlaceIndex(20, 60, 15.0), PlaceIndex(20, 60, 15.0)
    for a in range(0, 700, 16):
        batched.add_many(list(range(a, min(a + 16, 700))), descs[a:a + 16])
        cap = batched.keys.base.shape[0] if batched.keys.base is not None else len(batched)
        assert cap <= len(batched) + max(16, len(batched) // 4)  # (doubling left up to half of it empty)
    for k in range(700):
        single.add(k, descs[k])
    assert len(batched) == len(single) == 700 and batched.keys.tolist() == list(range(700))
    for name in ("_cols", "_occ", "_count", "_keys"):
        a, b = getattr(batched, name), getattr(single, name)
        assert np.array_equal(a[:700], b[:700]), name
        assert not np.any(a[700:]) and not np.any(b[700:])  # rows past the stored ones are zero
    q = descs[123]
    for x, y in zip(batched.distances(q), single.distances(q)):
        assert np.array_equal(x, y)


def test_release_places_empties_the_index_after_finish() -> None:
    scans, meta = _loop_run()
    from dynslam2d.pipeline import Pipeline

    pipe = Pipeline(Config())
    for s in scans:
        pipe.process(s)
    lc = pipe.loops
    assert lc is not None
    res = lc.finish()
    assert len(lc._places) > 16 and lc._place_pts
    before = lc._places.nbytes
    poses = res.poses.copy()
    lc.release_places()
    empty = PlaceIndex(lc._places.rings, lc._places.sectors, lc._places.max_range)
    assert len(lc._places) == 0 and not lc._place_pts and not lc._place_due
    assert lc._places.nbytes == empty.nbytes < before
    assert np.array_equal(res.poses, poses)


def test_released_outputs_write_files_without_float64_maps_and_tracks_png_without_rows(tmp_path, monkeypatch):
    import dynslam2d.results as R
    import dynslam2d.viz.figures as F
    from dynslam2d.slam.cleanup import CleanupRecorder

    scans, meta = _loop_run()
    cfg = Config()
    rec = CleanupRecorder(cfg.clean, cfg.slam, keep_counts=False)
    res = run(ScanList(scans, meta), cfg, observers=[rec])
    cleaned = rec.result
    assert cleaned is not None and len(res.track_rows) > 0
    seen: dict[str, object] = {}
    csv_fn, tracks_fn = R.tracks_csv, F.plot_tracks

    def csv_spy(run_result):  # type: ignore[no-untyped-def]
        seen["grid_at_csv"] = (run_result.grid, cleaned.grid)
        return csv_fn(run_result)

    def tracks_spy(*a, **k):  # type: ignore[no-untyped-def]
        seen["at_tracks"] = (len(res.track_rows), res.erased, cleaned.erased.size, cleaned.restored.size)
        return tracks_fn(*a, **k)

    monkeypatch.setattr(R, "tracks_csv", csv_spy)
    monkeypatch.setattr(F, "plot_tracks", tracks_spy)
    paths = R.write_outputs(res, tmp_path, cleaned=cleaned, release=True).paths
    assert seen["grid_at_csv"] == (None, None)
    assert seen["at_tracks"] == (0, None, 0, 0)
    assert {"map.png", "tracks.png", "tracks.csv", "summary.json"} <= set(paths)
