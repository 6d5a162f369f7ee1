"""Format sniffing, the stream checks every source goes through, and atomic writes."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.io.sources import CheckedSource, sniff_format
from dynslam2d.types import Scan, SourceMeta


class ListSource:
    def __init__(self, stamps):
        self.stamps = stamps
        self.meta = SourceMeta(format="test", origin="list", count=len(stamps))

    def __iter__(self):
        for t in self.stamps:
            yield Scan(stamp=t, angle_min=0.0, angle_increment=0.1, ranges=np.ones(3), range_min=0.0, range_max=5.0)

    def __len__(self):
        return len(self.stamps)


def test_sniff_by_content_not_name(tmp_path):
    (tmp_path / "a.log").write_bytes(b"#ROSBAG V2.0\n....")
    (tmp_path / "b.bag").write_bytes(b"\x89MCAP0\r\n....")
    (tmp_path / "c.txt").write_text("# comment\nPARAM robot_x 0\nFLASER 2 1.0 2.0 0 0 0 0 0 0 1.5 host 0.1\n")
    with gzip.open(tmp_path / "d.clf", "wb") as fh:
        fh.write(b"FLASER 1 1.0 0 0 0 0 0 0 1.5 host 0.1\n")
    bag2 = tmp_path / "bag2"
    bag2.mkdir()
    (bag2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert sniff_format(tmp_path / "a.log") == "ros1-bag"
    assert sniff_format(tmp_path / "b.bag") == "mcap"
    assert sniff_format(tmp_path / "c.txt") == "carmen"
    assert sniff_format(tmp_path / "d.clf") == "carmen"
    assert sniff_format(bag2) == "ros2-bag"
    assert sniff_format("sim:paper") == "sim"


def test_sniff_errors_name_the_path(tmp_path):
    (tmp_path / "empty.bag").write_bytes(b"")
    (tmp_path / "x.csv").write_text("a,b,c\n")
    (tmp_path / "dir").mkdir()
    with pytest.raises(DynSlamError, match="empty.bag: file is empty"):
        sniff_format(tmp_path / "empty.bag")
    with pytest.raises(DynSlamError, match="x.csv: unknown format"):
        sniff_format(tmp_path / "x.csv")
    with pytest.raises(DynSlamError, match="no metadata.yaml"):
        sniff_format(tmp_path / "dir")
    with pytest.raises(DynSlamError, match="no such file"):
        sniff_format(tmp_path / "missing.bag")


def test_checked_source_rejects_backwards_and_repeated_stamps():
    with pytest.raises(DynSlamError, match="scan 2 stamp 0.500000 goes backwards"):
        list(CheckedSource(ListSource([0.0, 1.0, 0.5])))
    with pytest.raises(DynSlamError, match="scan 1 .* repeats"):
        list(CheckedSource(ListSource([0.0, 0.0])))


def test_checked_source_skip_bad_counts_what_it_drops():
    src = CheckedSource(ListSource([0.0, 1.0, 0.5, 1.0, 2.0]), skip_bad=True)
    assert [s.stamp for s in src] == [0.0, 1.0, 2.0]
    assert src.skipped == 2 and src.meta.extra["skipped_scans"] == 2
    assert len(src) == 5


def test_checked_source_rejects_empty_input():
    with pytest.raises(DynSlamError, match="no usable laser scans"):
        list(CheckedSource(ListSource([])))


def test_atomic_path_leaves_nothing_on_failure_and_replaces_on_success(tmp_path):
    final = tmp_path / "out.txt"
    write_text_atomic(final, "old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(final) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert final.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
    write_text_atomic(final, "new")
    assert final.read_text() == "new"


def test_atomic_directory_replaces_an_existing_folder(tmp_path):
    final = tmp_path / "bag"
    for content in ("one", "two"):
        with atomic_path(final, directory=True) as tmp:
            tmp.mkdir()
            (tmp / "f").write_text(content)
    assert (final / "f").read_text() == "two"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
