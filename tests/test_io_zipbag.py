"""A bag inside a .zip archive reads like the bag itself; wrong archives give one-line errors."""

from __future__ import annotations

import gc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.errors import DynSlamError
from dynslam2d.inputs import open_source
from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.io.sources import sniff_format
from dynslam2d.io.zipbag import ExtractedBag, ZipBagSource, bag_file
from dynslam2d.sim import simulate


@pytest.fixture(scope="module")
def scans():
    return list(simulate("paper", duration=1.0).scans)


def _zip(path: Path, members: dict[str, bytes | Path]) -> Path:
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, content in members.items():
            if isinstance(content, Path):
                zf.write(content, name)
            else:
                zf.writestr(name, content)
    return path


def test_zip_with_one_bag_reads_like_the_bag(tmp_path, scans):
    bag = write_scan_bag(tmp_path / "run.bag", scans, topic="/scan_base2")
    # content decides, not names: a readme and a folder entry beside a bag with no suffix
    archive = _zip(tmp_path / "run.data", {"README.txt": b"hello", "inner/recording": bag})
    assert sniff_format(archive) == "zip"
    source = open_source(archive)
    got = list(source)
    assert len(got) == len(scans) == len(source)
    assert all(a.same_as(b) for a, b in zip(got, list(open_source(bag))))
    assert source.meta.topic == "/scan_base2" and source.meta.format == "ros1-bag"
    assert source.meta.origin == f"{archive}:inner/recording"


def test_extracted_bag_is_removed_on_close_and_on_collection(tmp_path, scans):
    bag = write_scan_bag(tmp_path / "run.bag", scans[:3])
    archive = _zip(tmp_path / "a.zip", {"run.bag": bag})
    src = ZipBagSource(archive)
    extracted = src._bag.path
    assert extracted.is_file() and extracted.stat().st_size == bag.stat().st_size
    src.close()
    assert not extracted.exists()
    src = ZipBagSource(archive)
    extracted = src._bag.path
    del src
    gc.collect()
    assert not extracted.exists()
    with bag_file(archive) as inside:
        assert inside.read_bytes() == bag.read_bytes()
    assert not inside.exists()
    with bag_file(bag) as same:  # not a zip: the path itself
        assert same == bag


def test_zip_with_zero_or_several_bags_is_a_one_line_error(tmp_path, scans):
    bag = write_scan_bag(tmp_path / "run.bag", scans[:2])
    none = _zip(tmp_path / "none.zip", {"notes.txt": b"#ROSBAG is not at the start"})
    two = _zip(tmp_path / "two.zip", {"a.bag": bag, "b.bag": bag})
    with pytest.raises(DynSlamError, match=r"none.zip: zip archive holds no bag; it must hold exactly one") as e:
        open_source(none)
    assert "\n" not in str(e.value)
    with pytest.raises(DynSlamError, match=r"two.zip: zip archive holds 2 bags \(a.bag, b.bag\)"):
        ExtractedBag(two)
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    with pytest.raises(DynSlamError, match="broken.zip: cannot read zip archive"):
        open_source(broken)


def test_errors_inside_the_zipped_bag_name_the_archive(tmp_path, scans):
    bag = write_scan_bag(tmp_path / "run.bag", scans[:2], topic="/scan")
    archive = _zip(tmp_path / "a.zip", {"run.bag": bag})
    with pytest.raises(DynSlamError, match=r"a.zip:run.bag: topic /nope does not exist") as e:
        open_source(archive, topic="/nope")
    assert "dynslam2d-zip-" not in str(e.value)


def test_real_person_following_zip():
    archive = shared_file("dynamic/leg_tracker/person_following_outdoor_1.bag.zip")
    source = open_source(archive)
    assert source.meta.topic == "/scan_base2" and source.meta.count == 7170
    first = next(iter(source))
    assert first.n_beams == source.meta.beams and np.isfinite(first.ranges).any()
