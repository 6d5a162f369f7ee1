"""Kümmerle relation files: parsing, errors, and matching relation stamps to scans."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.errors import DynSlamError
from dynslam2d.io.carmen import CarmenSource
from dynslam2d.io.relations import match_relation_stamps, read_relations
from dynslam2d.types import Pose2D

TEXT = """\
1134864645.90321 1134864646.32420 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198
# a comment

1134864648.67354 1134864648.46323 -0.15130 0.00248 0.00000  0.00000 0.00000 -0.07966
"""


def test_read_relations_columns(tmp_path):
    path = tmp_path / "a.relations"
    path.write_text(TEXT)
    rel = read_relations(path)
    assert len(rel) == 2
    np.testing.assert_array_equal(rel.t1, [1134864645.90321, 1134864648.67354])
    np.testing.assert_array_equal(rel.t2, [1134864646.32420, 1134864648.46323])
    np.testing.assert_array_equal(rel.dx, [0.31293, -0.15130])
    np.testing.assert_array_equal(rel.dy, [0.02935, 0.00248])
    np.testing.assert_array_equal(rel.dyaw, [0.24198, -0.07966])  # 8th column, not z/roll/pitch
    np.testing.assert_array_equal(rel.line, [1, 4])
    assert rel.origin.endswith("a.relations")


def test_read_relations_gzipped(tmp_path):
    path = tmp_path / "b.relations"
    path.write_bytes(gzip.compress(TEXT.encode()))
    assert len(read_relations(path)) == 2


@pytest.mark.parametrize(
    "line, what",
    [
        ("1 2 3 4 5 6 7", "found 7 fields"),
        ("1 2 3 4 5 6 7 8 9", "found 9 fields"),
        ("1 2 x 4 5 6 7 8", "'x'"),
        ("1 2 nan 4 0 0 0 8", "non-finite"),
    ],
)
def test_malformed_relation_names_file_and_line(tmp_path, line, what):
    path = tmp_path / "bad.relations"
    path.write_text(TEXT + line + "\n")
    with pytest.raises(DynSlamError) as info:
        read_relations(path)
    assert "bad.relations:5:" in str(info.value) and what in str(info.value)


def test_empty_or_missing_relations_are_errors(tmp_path):
    path = tmp_path / "empty.relations"
    path.write_text("# nothing\n\n")
    with pytest.raises(DynSlamError, match="empty.relations"):
        read_relations(path)
    with pytest.raises(DynSlamError, match="nope.relations"):
        read_relations(tmp_path / "nope.relations")


def test_match_nearest_within_tolerance(tmp_path):
    path = tmp_path / "m.relations"
    path.write_text(
        "10.0004 11.0 0 0 0 0 0 0\n"  # both within 1 ms
        "12.0 10.0 0 0 0 0 0 0\n"  # t2 < t1 is fine
        "10.0 11.5 0 0 0 0 0 0\n"  # t2 between scans: 0.5 s off
        "9.9985 13.0 0 0 0 0 0 0\n"  # t1 1.5 ms before the first scan
        "10.001 12.001 0 0 0 0 0 0\n"  # exactly at the tolerance (inclusive)
    )
    rel = read_relations(path)
    stamps = np.array([10.0, 11.0, 12.0, 13.0])
    i1, i2, ok = match_relation_stamps(rel, stamps)
    assert i1.tolist() == [0, 2, 0, 0, 0]
    assert i2.tolist() == [1, 0, 1, 3, 2]
    assert ok.tolist() == [True, True, False, False, True]
    _, _, ok_wide = match_relation_stamps(rel, stamps, tol=0.6)
    assert ok_wide.all()
    with pytest.raises(DynSlamError, match="sorted"):
        match_relation_stamps(rel, stamps[::-1])
    with pytest.raises(DynSlamError, match="non-empty"):
        match_relation_stamps(rel, np.empty(0))


def test_real_mit_csail_relations_match_the_log_and_odometry():
    rel = read_relations(shared_file("mit-csail/mit-csail.relations"))
    src = CarmenSource(shared_file("mit-csail/mit-csail.clf"))
    assert len(rel) == 1172
    assert len(np.unique(np.concatenate([rel.t1, rel.t2]))) == 1045
    recs = list(src.records())
    stamps = np.array([r.scan.stamp for r in recs])
    i1, i2, ok = match_relation_stamps(rel, stamps, tol=1e-3)
    assert ok.all()
    # convention check: x_t1⁻¹ ⊕ x_t2 from raw odometry is close to the relation
    # (median translation error far below the median relation length 0.41 m)
    err = [
        math.hypot(d.x - rel.dx[k], d.y - rel.dy[k])
        for k in range(len(rel))
        for d in [recs[i1[k]].odom.between(recs[i2[k]].odom)]
    ]
    rev = [
        math.hypot(d.x - rel.dx[k], d.y - rel.dy[k])
        for k in range(len(rel))
        for d in [recs[i2[k]].odom.between(recs[i1[k]].odom)]
    ]
    assert np.median(err) < 0.1 < np.median(rev)
    assert float(np.median(np.hypot(rel.dx, rel.dy))) == pytest.approx(0.41, abs=0.01)


@pytest.mark.parametrize(
    "rel_path, count, distinct",
    [
        ("intel/intel.relations", 2984, 1791),
        ("fr079/fr079.relations", 1685, 989),
        ("mit-killian/mit-killian.relations", 4677, 3838),
    ],
)
def test_real_relation_files_parse(rel_path, count, distinct):
    rel = read_relations(shared_file(rel_path))
    assert len(rel) == count
    assert len(np.unique(np.concatenate([rel.t1, rel.t2]))) == distinct
    assert np.all(np.isfinite(rel.dx)) and np.all(np.abs(rel.dyaw) <= math.pi + 1e-6)


def test_real_intel_relations_span_and_flirtlib_matches():
    rel = read_relations(shared_file("intel/intel.relations"))
    ts = np.concatenate([rel.t1, rel.t2])
    assert ts.min() == pytest.approx(976052896.8, abs=0.1)
    assert ts.max() == pytest.approx(976055541.1, abs=0.1)
    assert np.any(rel.t2 < rel.t1)
    src = CarmenSource(shared_file("intel/intel-lab.flirtlib.log"))
    stamps = np.array([s.stamp for s in src])
    _, _, ok = match_relation_stamps(rel, stamps, tol=1e-3)
    # data README: "352 relations match both ends at 1 ms"; two of them are 1.00005 ms off,
    # so a strict 1 ms tolerance gives 350
    assert ok.sum() == 350
    _, _, ok_loose = match_relation_stamps(rel, stamps, tol=1.0001e-3)
    assert ok_loose.sum() == 352
    _, _, ok2 = match_relation_stamps(rel, stamps, tol=2e-3)
    assert ok2.sum() == 473


def test_real_fr079_relations_match_flirtlib_log():
    rel = read_relations(shared_file("fr079/fr079.relations"))
    src = CarmenSource(shared_file("fr079/fr079.flirtlib.log"))
    _, _, ok = match_relation_stamps(rel, np.array([s.stamp for s in src]))
    assert ok.sum() == 136  # data README: 136 relations match exactly


def test_pose_between_is_the_relation_convention():
    a = Pose2D(1.0, 2.0, math.pi / 2)
    b = Pose2D(1.0, 3.0, math.pi / 2)
    d = a.between(b)  # one metre straight ahead of a
    assert (d.x, d.y, d.theta) == pytest.approx((1.0, 0.0, 0.0))
