"""map_server PGM + YAML: round trips, the row flip, the origin, bad files, atomicity."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io import mapfile


def _grid() -> GridMap:
    prob = np.full((4, 6), np.nan)
    prob[0, :] = 0.0  # bottom row free
    prob[3, 5] = 1.0  # top-right corner occupied
    prob[1, 2] = 0.9
    return GridMap(prob=prob, resolution=0.05, origin=(-1.25, 2.5))


def test_trinary_round_trip_keeps_cells_origin_and_resolution(tmp_path):
    grid = _grid()
    ypath, ppath = mapfile.write_map(tmp_path / "map.yaml", grid)
    back = mapfile.read_map(ypath)
    assert back.resolution == 0.05
    assert back.origin == (-1.25, 2.5)
    np.testing.assert_array_equal(back.occupied(), grid.occupied())
    np.testing.assert_array_equal(back.free(), grid.free())
    np.testing.assert_array_equal(back.known(), grid.occupied() | grid.free())
    assert ppath.name == "map.pgm"


def test_image_rows_are_top_down(tmp_path):
    """The GridMap's top-right occupied cell is the PGM's first row, last column."""
    _, ppath = mapfile.write_map(tmp_path / "m.yaml", _grid())
    pix = mapfile.decode_pgm(ppath.read_bytes())
    assert pix.shape == (4, 6)
    assert pix[0, 5] == mapfile.OCCUPIED_PIXEL
    assert (pix[3, :] == mapfile.FREE_PIXEL).all()  # bottom row of the world = last image row
    assert pix[1, 1] == mapfile.UNKNOWN_PIXEL


def test_origin_places_cells_in_the_world(tmp_path):
    grid = _grid()
    ypath, _ = mapfile.write_map(tmp_path / "m.yaml", grid)
    meta = yaml.safe_load(ypath.read_text())
    assert meta["origin"] == [-1.25, 2.5, 0.0]
    assert meta["occupied_thresh"] == 0.65 and meta["free_thresh"] == 0.196
    back = mapfile.read_map(ypath)
    col, row = back.world_to_cell(np.array([[-1.25 + 5.5 * 0.05, 2.5 + 3.5 * 0.05]]))[0]
    assert (col, row) == (5, 3) and back.prob[row, col] == 1.0


def test_scale_mode_keeps_probability_to_one_grey_level(tmp_path):
    grid = _grid()
    ypath, _ = mapfile.write_map(tmp_path / "s.yaml", grid, mode="scale")
    back = mapfile.read_map(ypath)
    known = grid.known()
    np.testing.assert_allclose(back.prob[known], grid.prob[known], atol=1 / 255)
    assert np.isnan(back.prob[~known]).all()


def test_ascii_pgm_and_comments_are_read():
    data = b"P2\n# a comment\n3 2\n255\n0 205 254\n254 254 0\n"
    pix = mapfile.decode_pgm(data)
    np.testing.assert_array_equal(pix, [[0, 205, 254], [254, 254, 0]])


@pytest.mark.parametrize(
    "data, message",
    [
        (b"P5\n4 4\n255\n" + bytes(5), "truncated"),
        (b"P6\n1 1\n255\n\x00\x00\x00", "not a PGM"),
        (b"P5\n4", "truncated PGM header"),
    ],
)
def test_bad_pgm_gives_a_clear_error(data, message):
    with pytest.raises(DynSlamError, match=message):
        mapfile.decode_pgm(data, origin="x.pgm")


def test_bad_yaml_names_the_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("image: nothing.pgm\nresolution: 0.05\n")
    with pytest.raises(DynSlamError, match="bad.yaml.*origin"):
        mapfile.read_map(p)
    with pytest.raises(DynSlamError, match="not found"):
        mapfile.read_map(tmp_path / "absent.yaml")


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    def boom(*_a, **_k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(mapfile, "encode_pgm", boom)
    with pytest.raises(RuntimeError):
        mapfile.write_map(tmp_path / "map.yaml", _grid())
    assert list(tmp_path.iterdir()) == []
