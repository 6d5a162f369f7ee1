"""RerunViewer: the optional live viewer (issue 6). Streams to an .rrd file, never a window."""

from __future__ import annotations

import importlib.util
import sys
from collections import Counter

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.viz.live import INSTALL_HINT, RerunViewer, map_image

HAVE_RERUN = importlib.util.find_spec("rerun") is not None
needs_rerun = pytest.mark.skipif(not HAVE_RERUN, reason='rerun-sdk not installed (pip install "dynslam2d[viewer]")')


def test_without_rerun_the_error_says_how_to_install(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "rerun", None)  # makes `import rerun` raise ImportError
    with pytest.raises(DynSlamError) as info:
        RerunViewer(save=tmp_path / "x.rrd")
    msg = str(info.value)
    assert msg == INSTALL_HINT == 'the live viewer needs the viewer extra: pip install "dynslam2d[viewer]"'
    assert "\n" not in msg
    assert not (tmp_path / "x.rrd").exists()


def test_map_image_shades_and_orientation():
    prob = np.array([[np.nan, 0.0], [0.5, 1.0]])  # row 0 = bottom
    img = map_image(GridMap(prob, 0.1))
    assert img.dtype == np.uint8
    assert img.tolist() == [[127, 0], [205, 254]]  # top row first: north up


@needs_rerun
def test_stream_a_run_to_rrd(tmp_path):
    from dynslam2d.pipeline import run
    from dynslam2d.sim.simulation import SimSource

    out = tmp_path / "run.rrd"
    src = SimSource("paper", duration=2)
    with RerunViewer(save=out, map_period=1.0) as viewer:
        assert not out.exists()  # atomic: appears only when the stream is complete (on_finish)
        run(src, observers=[viewer])
        assert out.exists()
    data = out.read_bytes()
    assert len(data) > 10_000 and data[:3] == b"RRF"
    chunk = pytest.importorskip("rerun.chunk", reason="this rerun-sdk cannot read .rrd files back")
    if not hasattr(chunk, "RrdReader"):
        pytest.skip("this rerun-sdk has no RrdReader to check the content")
    rows: Counter[str] = Counter()
    for ch in chunk.RrdReader(out).stream():
        rows[str(ch.entity_path)] += ch.num_rows
    n = len(src)
    for entity in ("/world/scan/kept", "/world/scan/removed", "/world/tracks", "/world/tracks/velocity",
                   "/world/laser", "/stats/score"):
        assert rows[entity] == n, entity
    # map at t = 0 and 1 s (period 1 s) and once at the end (t = 1.95 s)
    assert rows["/map"] == rows["/world/map"] == rows["/world/trajectory"] == 3


@needs_rerun
def test_failed_run_leaves_no_recording(tmp_path):
    out = tmp_path / "fail.rrd"
    with pytest.raises(RuntimeError, match="broke"):
        with RerunViewer(save=out):
            raise RuntimeError("broke")
    assert list(tmp_path.iterdir()) == []


@needs_rerun
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display check is for Linux")
def test_no_display_is_a_clear_error_not_a_hang():
    with pytest.raises(DynSlamError, match="no display"):
        RerunViewer(env={})  # spawn mode: refused before any viewer process is started
