"""CARMEN log reading: record layouts, beam geometry, no-return handling, time order, errors."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_file
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dynslam2d.errors import DynSlamError
from dynslam2d.io.carmen import (
    DEFAULT_NOMINAL_RATE_HZ,
    CarmenSource,
    detect_no_return_threshold,
    flaser_geometry,
)
from dynslam2d.types import ScanSource

DEG = math.pi / 180.0


def flaser(ranges, ipc=1.0, logger=None, pose=(1.0, 2.0, 0.5), odom=(1.5, 2.5, 0.25), host="host"):
    logger = ipc if logger is None else logger
    r = " ".join(repr(float(v)) if isinstance(v, float) else str(v) for v in ranges)
    p = " ".join(str(v) for v in (*pose, *odom))
    return f"FLASER {len(ranges)} {r} {p} {ipc!r} {host} {logger!r}"


def robotlaser1(
    ranges,
    ipc=1.0,
    logger=None,
    start=-1.570796,
    fov=3.141593,
    res=0.017453,
    max_range=50.0,
    remissions=(),
    laser=(1.0, 2.0, 0.5),
    robot=(0.9, 2.0, 0.5),
):
    logger = ipc if logger is None else logger
    r = " ".join(str(v) for v in ranges)
    rem = " ".join(str(v) for v in remissions)
    rem_part = f"{len(remissions)} {rem} " if remissions else "0 "
    poses = " ".join(str(v) for v in (*laser, *robot))
    return (
        f"ROBOTLASER1 0 {start} {fov} {res} {max_range} 0.1 0 {len(ranges)} {r} {rem_part}"
        f"{poses} 0.3 0.1 0.0 0.0 0.0 {ipc!r} x {logger!r}"
    )


def write(tmp_path: Path, lines, name="log.clf", newline_at_end=True) -> Path:
    path = tmp_path / name
    text = "\n".join(lines) + ("\n" if newline_at_end else "")
    path.write_text(text)
    return path


def scans_of(path, **kw):
    src = CarmenSource(path, **kw)
    return src, list(src)


# -- beam geometry ---------------------------------------------------------------


@pytest.mark.parametrize(
    "n, first_deg, last_deg",
    [(180, -90.0, 89.0), (360, -90.0, 89.5), (361, -90.0, 90.0), (181, -90.0, 90.0), (91, -90.0, 90.0)],
)
def test_flaser_beam_angles_follow_from_beam_count(tmp_path, n, first_deg, last_deg):
    path = write(tmp_path, [flaser([3.0] * n, ipc=10.0), flaser([3.0] * n, ipc=10.2)])
    src, scans = scans_of(path)
    a = scans[0].angles
    assert a.shape == (n,)
    assert a[0] == pytest.approx(first_deg * DEG, abs=1e-12)
    assert a[-1] == pytest.approx(last_deg * DEG, abs=1e-9)
    assert np.all(np.diff(a) > 0)  # beam 0 right-most, counter-clockwise
    assert src.meta.fov == pytest.approx(n * abs(scans[0].angle_increment))


def test_flaser_geometry_generic_and_single_beam():
    a0, inc = flaser_geometry(100)
    assert a0 + 99 * inc == pytest.approx(math.pi / 2)
    assert flaser_geometry(1)[0] == 0.0


def test_robotlaser1_angles_come_from_header(tmp_path):
    lines = [
        robotlaser1([2.0] * 180, ipc=5.0),
        robotlaser1([2.0] * 401, ipc=5.1, start=-2.0, fov=4.0, res=0.01),
    ]
    _, scans = scans_of(write(tmp_path, lines))
    assert scans[0].angle_min == pytest.approx(-1.570796)
    assert scans[0].angles[-1] == pytest.approx(-1.570796 + 179 * 0.017453)
    assert scans[1].n_beams == 401
    assert scans[1].angles[0] == pytest.approx(-2.0)
    assert scans[1].angles[-1] == pytest.approx(2.0)


def test_robotlaser1_remissions_become_intensities_when_one_per_beam(tmp_path):
    lines = [
        robotlaser1([1.0, 2.0, 3.0], ipc=1.0, remissions=(10, 20, 30), res=0.1),
        robotlaser1([1.0, 2.0, 3.0], ipc=2.0, remissions=(7,), res=0.1),
    ]
    _, scans = scans_of(write(tmp_path, lines))
    np.testing.assert_array_equal(scans[0].intensities, [10.0, 20.0, 30.0])
    assert scans[1].intensities is None
    np.testing.assert_array_equal(scans[1].ranges, [1.0, 2.0, 3.0])


# -- no return -----------------------------------------------------------------------


def test_sick_no_return_values_are_invalid_and_long_returns_stay_valid(tmp_path):
    ranges = [81.91, 81.83, 35.2, 81.82, 30.0, 0.5] + [4.0] * 174
    src, scans = scans_of(write(tmp_path, [flaser(ranges, ipc=1.0), flaser(ranges, ipc=1.2)]))
    valid = scans[0].valid_mask()
    assert valid[:6].tolist() == [False, False, True, True, True, True]
    assert src.meta.extra["no_return_threshold"] == pytest.approx(81.83)


def test_aces_style_saturation_marker_is_detected(tmp_path):
    # ACES writes 50.0 for no return; 49.91 is a real return.
    ranges = [50.0] * 12 + [49.91, 35.0] + [3.0] * 166
    src, scans = scans_of(write(tmp_path, [flaser(ranges, ipc=1.0), flaser(ranges, ipc=2.0)]))
    valid = scans[0].valid_mask()
    assert not valid[:12].any()
    assert valid[12] and valid[13]
    assert scans[0].range_max < 50.0 < scans[0].range_max + 1e-9
    assert src.meta.extra["no_return_threshold"] == 50.0


def test_constant_short_ranges_are_not_mistaken_for_a_marker(tmp_path):
    _, scans = scans_of(write(tmp_path, [flaser([1.0] * 180, ipc=t) for t in (1.0, 2.0, 3.0)]))
    assert all(s.valid_mask().all() for s in scans)
    threshold, _ = detect_no_return_threshold(np.full(540, 1.0))
    assert threshold == pytest.approx(81.83)


def test_robotlaser1_max_range_field_and_explicit_override(tmp_path):
    ranges = [81.83, 50.0, 49.9, 35.0, 10.0]
    path = write(tmp_path, [robotlaser1(ranges, ipc=1.0, max_range=50.0, res=0.1)])
    _, scans = scans_of(path)
    assert scans[0].valid_mask().tolist() == [False, False, True, True, True]
    _, scans = scans_of(path, max_range=30.0)
    assert scans[0].valid_mask().tolist() == [False, False, False, False, True]


def test_nan_and_negative_readings_parse_and_are_invalid(tmp_path):
    ranges = ["nan", "-1.0", "2.5", "inf", "0.0"]
    _, scans = scans_of(write(tmp_path, [flaser(ranges, ipc=1.0)]))
    r = scans[0].ranges
    assert math.isnan(r[0]) and r[1] == -1.0 and r[2] == 2.5
    assert scans[0].valid_mask().tolist() == [False, False, True, False, False]


# -- poses and odometry ----------------------------------------------------------------


def test_poses_and_odom_records_are_parsed(tmp_path):
    lines = [
        "# a comment",
        "ODOM 0.1 0.2 0.3 0.4 0.5 0.6 2.5 h 2.5",
        flaser([1.0] * 180, ipc=2.0, pose=(1.0, 2.0, 0.5), odom=(1.5, 2.5, 0.25)),
        "ODOM 0.0 0.0 0.0 0.0 0.0 0.0 1.5 h 1.5",
        robotlaser1([1.0] * 180, ipc=3.0, laser=(4.0, 5.0, 0.1), robot=(3.9, 5.0, 0.1)),
        "NEFF 12.5",
        "PARAM robot_x 1 nohost 0",
        "VERTEX2 0 1 2 3",
    ]
    src = CarmenSource(write(tmp_path, lines))
    recs = list(src.records())
    assert [r.kind for r in recs] == ["FLASER", "ROBOTLASER1"]
    assert [r.line for r in recs] == [3, 5]
    assert recs[0].laser_pose.as_array().tolist() == [1.0, 2.0, 0.5]
    assert recs[0].odom.as_array().tolist() == [1.5, 2.5, 0.25]
    assert recs[1].laser_pose.as_array().tolist() == [4.0, 5.0, 0.1]
    assert recs[1].odom.as_array().tolist() == [3.9, 5.0, 0.1]
    odo = src.odometry()
    assert len(odo) == 2
    np.testing.assert_array_equal(odo.stamp, [1.5, 2.5])  # sorted by stamp
    np.testing.assert_array_equal(odo.x, [0.0, 0.1])
    np.testing.assert_array_equal(odo.line, [4, 2])
    assert odo.accel[1] == 0.6
    assert src.meta.extra["ignored_records"] == {"NEFF": 1, "PARAM": 1, "VERTEX2": 1}
    assert src.meta.extra["comments"] == 1
    assert src.meta.topic == "FLASER+ROBOTLASER1"


def test_non_finite_pose_gives_none(tmp_path):
    src = CarmenSource(write(tmp_path, [flaser([1.0] * 4, ipc=1.0, odom=("nan", 0, 0))]))
    rec = next(src.records())
    assert rec.odom is None and rec.laser_pose is not None


def test_crlf_line_endings_and_mixed_beam_counts(tmp_path):
    path = tmp_path / "dos.clf"
    path.write_bytes(("\r\n".join([flaser([2.0] * 180, ipc=1.0), flaser([2.0] * 361, ipc=2.0)]) + "\r\n").encode())
    src = CarmenSource(path)
    assert [s.n_beams for s in src] == [180, 361]
    assert src.meta.beams == 180 and src.meta.extra["beam_counts"] == [180, 361]


# -- files: gzip, empty, missing ------------------------------------------------------


def test_gzip_is_detected_by_magic_not_name(tmp_path):
    text = "\n".join([flaser([2.0] * 180, ipc=1.0), flaser([2.0] * 180, ipc=1.5)]) + "\n"
    hidden = tmp_path / "looks_plain.clf"
    hidden.write_bytes(gzip.compress(text.encode()))
    fake = tmp_path / "not_really.log.gz"
    fake.write_text(text)
    for path in (hidden, fake):
        src = CarmenSource(path)
        assert len(src) == 2 and src.meta.beams == 180


def test_corrupt_gzip_is_a_dynslam_error(tmp_path):
    data = gzip.compress(("\n".join(flaser([2.0] * 180, ipc=float(i)) for i in range(50))).encode())
    path = tmp_path / "broken.gz"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DynSlamError, match="broken.gz"):
        CarmenSource(path)


@pytest.mark.parametrize(
    "lines", [[], ["", "   "], ["# only a comment"], ["ODOM 0 0 0 0 0 0 1 h 1", "NEFF 3"]]
)
def test_files_without_laser_records_are_errors(tmp_path, lines):
    path = write(tmp_path, lines, name="nolaser.clf")
    with pytest.raises(DynSlamError, match="nolaser.clf"):
        CarmenSource(path)


def test_missing_file_is_an_error(tmp_path):
    with pytest.raises(DynSlamError, match="missing.clf"):
        CarmenSource(tmp_path / "missing.clf")


# -- malformed lines -----------------------------------------------------------------------


GOOD = flaser([1.0] * 180, ipc=1.0)


@pytest.mark.parametrize(
    "bad, what",
    [
        (flaser([1.0] * 180, ipc=2.0).replace(" 1.0 ", " 1.0 1.0 ", 1), "needs 191 fields, found 192"),
        (flaser([1.0] * 180, ipc=2.0).replace(" 1.0 ", " abc ", 1), "'abc'"),
        ("FLASER -3 1 2 3 4 5 6 7 8 9 h 10", "negative"),
        ("FLASER x1 1 2", "not an integer"),
        ("FLASER", "line ends before"),
        (flaser([1.0] * 4, ipc=2.0).replace(" 2.0 host", " nan host"), "ipc_timestamp is not finite"),
        (robotlaser1([1.0] * 10, ipc=2.0)[:-30], "ROBOTLASER1"),
        (robotlaser1([1.0] * 10, ipc=2.0, res=0.0), "ang_res"),
        ("ODOM 1 2 3", "ODOM needs 10 fields"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, bad, what):
    path = write(tmp_path, ["# header", GOOD, bad, flaser([1.0] * 180, ipc=3.0)], name="bad_input.clf")
    with pytest.raises(DynSlamError) as info:
        CarmenSource(path)
    msg = str(info.value)
    assert "bad_input.clf:3:" in msg
    assert what in msg
    src = CarmenSource(path, skip_bad=True)
    assert len(src) == 2
    assert src.meta.extra["skipped_lines"] == 1
    assert src.meta.extra["skipped_line_numbers"] == [3]


def test_record_with_impossible_geometry_names_its_line(tmp_path):
    # parses field by field, but the Scan type rejects beams at ±100 rad
    bad = robotlaser1([1.0] * 10, ipc=2.0, start=-100.0)
    path = write(tmp_path, [GOOD, bad, flaser([1.0] * 180, ipc=3.0)], name="geom.clf")
    with pytest.raises(DynSlamError, match=r"geom\.clf:2: malformed ROBOTLASER1"):
        CarmenSource(path)
    src = CarmenSource(path, skip_bad=True)
    assert len(src) == 2 and src.meta.extra["skipped_line_numbers"] == [2]


def test_truncated_last_line_is_reported(tmp_path):
    last = flaser([1.0] * 180, ipc=2.0)[:400]
    path = write(tmp_path, [GOOD, last], name="cut.clf", newline_at_end=False)
    with pytest.raises(DynSlamError, match=r"cut\.clf:2:.*truncated"):
        CarmenSource(path)
    assert len(CarmenSource(path, skip_bad=True)) == 1


def test_skip_bad_counts_many_and_keeps_first_line_numbers(tmp_path):
    lines = []
    for i in range(30):
        lines.append(flaser([1.0] * 10, ipc=float(i)))
        lines.append("FLASER 10 1 2 3")
    src = CarmenSource(write(tmp_path, lines), skip_bad=True)
    assert len(src) == 30
    assert src.meta.extra["skipped_lines"] == 30
    assert src.meta.extra["skipped_line_numbers"] == [2, 4, 6, 8, 10, 12, 14, 16, 18, 20]
    with pytest.raises(DynSlamError):
        CarmenSource(write(tmp_path, ["FLASER 10 1 2 3"], name="allbad.clf"), skip_bad=True)


# -- time -----------------------------------------------------------------------------------


def test_out_of_order_records_are_sorted_stably(tmp_path):
    stamps = [3.0, 1.0, 2.0, 5.0, 4.0]
    src = CarmenSource(write(tmp_path, [flaser([float(i + 1)] * 5, ipc=t) for i, t in enumerate(stamps)]))
    scans = list(src)
    assert [s.stamp for s in scans] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert [s.ranges[0] for s in scans] == [2.0, 3.0, 1.0, 5.0, 4.0]
    assert [r.line for r in src.records()] == [2, 3, 1, 5, 4]
    assert src.meta.extra["backward_steps"] == 2
    assert src.meta.rate_hz == pytest.approx(1.0)


def test_repeated_stamps_are_nudged_strictly_increasing(tmp_path):
    stamps = [1.0, 2.0, 2.0, 2.0, 3.0]
    src = CarmenSource(write(tmp_path, [flaser([float(i + 1)] * 5, ipc=t) for i, t in enumerate(stamps)]))
    got = np.array([s.stamp for s in src])
    assert np.all(np.diff(got) > 0)
    np.testing.assert_allclose(got, [1.0, 2.0, 2.000001, 2.000002, 3.0], atol=1e-9)
    assert [s.ranges[0] for s in src] == [1.0, 2.0, 3.0, 4.0, 5.0]  # stable
    assert src.meta.extra["nudged_stamps"] == 2
    assert any("2 stamps" in w for w in src.meta.extra["warnings"])


def test_constant_ipc_falls_back_to_logger_time(tmp_path):
    lines = [flaser([1.0] * 5, ipc=0.0, logger=t) for t in (0.5, 0.25, 0.75)]
    src = CarmenSource(write(tmp_path, lines))
    assert [s.stamp for s in src] == [0.25, 0.5, 0.75]
    assert src.meta.extra["time_source"] == "logger"
    assert src.meta.extra["warnings"]


def test_all_zero_stamps_are_synthesized_at_nominal_rate(tmp_path):
    lines = [flaser([float(i + 1)] * 5, ipc=0.0, logger=0.0) for i in range(4)]
    src = CarmenSource(write(tmp_path, lines))
    np.testing.assert_allclose([s.stamp for s in src], np.arange(4) / DEFAULT_NOMINAL_RATE_HZ)
    assert [s.ranges[0] for s in src] == [1.0, 2.0, 3.0, 4.0]
    assert src.meta.extra["time_source"] == "synthesized"
    assert any("synthesized" in w for w in src.meta.extra["warnings"])
    src = CarmenSource(write(tmp_path, lines, name="b.clf"), nominal_rate_hz=2.0)
    assert list(src)[-1].stamp == pytest.approx(1.5)


def test_meta_describes_the_source(tmp_path):
    lines = [flaser([1.0] * 361, ipc=100.0 + 0.2 * i) for i in range(6)]
    src = CarmenSource(write(tmp_path, lines, name="m.clf"))
    assert isinstance(src, ScanSource)
    m = src.meta
    assert (m.format, m.topic, m.count, m.beams) == ("carmen", "FLASER", 6, 361)
    assert m.origin.endswith("m.clf")
    assert m.rate_hz == pytest.approx(5.0)
    assert m.fov == pytest.approx(361 * 0.5 * DEG)
    assert m.range_min == pytest.approx(0.01) and m.range_max == pytest.approx(81.83)
    assert len(list(src)) == len(list(src)) == 6  # iterating twice


# -- property tests ------------------------------------------------------------------------

_range = st.floats(min_value=0.02, max_value=80.0, allow_nan=False)
_record = st.tuples(
    st.sampled_from(["FLASER", "ROBOTLASER1"]),
    st.integers(min_value=1, max_value=40),
    st.floats(min_value=0.0, max_value=1e4, allow_nan=False),
)


def _build(records, data) -> tuple[list[str], list[int], list[float]]:
    lines, beams, stamps = [], [], []
    for kind, n, t in records:
        ranges = data.draw(st.lists(_range, min_size=n, max_size=n))
        line = flaser(ranges, ipc=t) if kind == "FLASER" else robotlaser1(ranges, ipc=t)
        lines.append(line)
        beams.append(n)
        stamps.append(t)
    return lines, beams, stamps


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(records=st.lists(_record, min_size=2, max_size=8, unique_by=lambda r: r[2]), data=st.data())
def test_random_valid_records_parse(tmp_path, records, data):
    lines, beams, stamps = _build(records, data)
    src = CarmenSource(write(tmp_path, lines, name="prop.clf"))
    got = list(src.records())
    order = np.argsort(stamps, kind="stable")
    assert [r.scan.n_beams for r in got] == [beams[i] for i in order]
    assert [r.scan.stamp for r in got] == [stamps[i] for i in order]
    assert [r.line for r in got] == [int(i) + 1 for i in order]


_junk = st.sampled_from(["abc", "", "1.2.3", "--", "nan", "-5", "1e999", "0x1F", "\x00", "é"])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(records=st.lists(_record, min_size=1, max_size=4), data=st.data(), skip=st.booleans())
def test_random_corruption_only_raises_dynslam_error(tmp_path, records, data, skip):
    lines, _, _ = _build(records, data)
    target = data.draw(st.integers(0, len(lines) - 1))
    fields = lines[target].split(" ")
    action = data.draw(st.sampled_from(["truncate", "junk", "drop", "chars"]))
    if action == "truncate":
        fields = fields[: data.draw(st.integers(0, len(fields) - 1))]
    elif action == "junk":
        fields[data.draw(st.integers(0, len(fields) - 1))] = data.draw(_junk)
    elif action == "drop":
        del fields[data.draw(st.integers(0, len(fields) - 1))]
    corrupted = " ".join(fields)
    if action == "chars":
        cut = data.draw(st.integers(0, len(corrupted)))
        corrupted = corrupted[:cut]
    lines[target] = corrupted
    path = write(tmp_path, lines, name="corrupt.clf", newline_at_end=data.draw(st.booleans()))
    try:
        src = CarmenSource(path, skip_bad=skip)
    except DynSlamError as exc:
        assert "corrupt.clf" in str(exc)
        return
    stamps = [s.stamp for s in src]
    assert len(stamps) == len(src) >= 1
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    # every untouched line survives; the corrupted one is parsed, skipped, or no longer
    # a laser record at all (e.g. truncated to "FLAS" or to nothing)
    assert len(src) >= len(lines) - 1
    assert len(src) + src.meta.extra["skipped_lines"] <= len(lines)
    if not skip:
        assert src.meta.extra["skipped_lines"] == 0


# -- real data -----------------------------------------------------------------------------


def _stamps(src) -> np.ndarray:
    return np.array([s.stamp for s in src])


def test_real_mit_csail_clf():
    src = CarmenSource(shared_file("mit-csail/mit-csail.clf"))
    st_ = _stamps(src)
    assert len(src) == 1988 and src.meta.beams == 361 and src.meta.topic == "FLASER"
    assert st_[0] == pytest.approx(1134864629.895, abs=1e-3)
    assert st_[-1] == pytest.approx(1134865053.892, abs=1e-3)
    assert np.all(np.diff(st_) > 0)
    assert src.meta.extra["backward_steps"] == 0 and src.meta.extra["comments"] == 3
    first = next(iter(src))
    assert first.ranges[0] == 1.40 and first.ranges[24] == 81.91 and not first.valid_mask()[24]
    all_r = np.concatenate([s.ranges for s in src])
    all_v = np.concatenate([s.valid_mask() for s in src])
    assert not all_v[all_r >= 81.83].any()
    long_real = (all_r > 30.0) & (all_r < 45.0)
    assert long_real.sum() > 100 and all_v[long_real].all()
    rec = next(src.records())
    assert rec.odom == rec.laser_pose  # raw odometry in both triples of this log


@pytest.mark.parametrize(
    "rel, count, beams, topic",
    [
        ("intel/intel-lab.flirtlib.log", 2672, 180, "ROBOTLASER1"),
        ("fr079/fr079.flirtlib.log", 1464, 360, "ROBOTLASER1"),
        ("intel/intel-corrected.log.gz", 910, 180, "FLASER"),
        ("fr079/freiburg-079-corrected.log.gz", 4791, 360, "FLASER"),
        ("aces/aces-corrected.log.gz", 440, 180, "FLASER"),
        ("freiburg-campus/freiburg-campus-corrected.log.gz", 2008, 360, "FLASER"),
    ],
)
def test_real_logs_counts_and_order(rel, count, beams, topic):
    src = CarmenSource(shared_file(rel))
    st_ = _stamps(src)
    assert (len(src), src.meta.beams, src.meta.topic) == (count, beams, topic)
    assert src.meta.extra["beam_counts"] == [beams]
    assert np.all(np.diff(st_) > 0)
    assert src.meta.extra["skipped_lines"] == 0


def test_real_intel_flirtlib_is_sorted_and_no_return_is_invalid():
    src = CarmenSource(shared_file("intel/intel-lab.flirtlib.log"))
    assert src.meta.extra["backward_steps"] == 97
    assert _stamps(src)[0] == pytest.approx(976053557.767368, abs=1e-6)
    first = next(iter(src))
    assert first.ranges[0] == 81.83 and not first.valid_mask()[0] and first.valid_mask()[1]
    assert first.angle_min == pytest.approx(-math.pi / 2, abs=1e-6)
    assert src.meta.extra["ignored_records"] == {"VERTEX2": 2672, "EDGE2": 3901}


def test_real_aces_50m_marker_is_no_return():
    src = CarmenSource(shared_file("aces/aces-corrected.log.gz"))
    all_r = np.concatenate([s.ranges for s in src])
    all_v = np.concatenate([s.valid_mask() for s in src])
    assert np.count_nonzero(all_r == 50.0) == 620 and not all_v[all_r == 50.0].any()
    real = (all_r > 30.0) & (all_r < 49.95)
    assert real.sum() > 500 and all_v[real].all()
    assert len(src.odometry()) == 7814


def test_real_freiburg_campus_stamps_are_synthesized():
    src = CarmenSource(shared_file("freiburg-campus/freiburg-campus-corrected.log.gz"))
    st_ = _stamps(src)
    assert np.all(np.diff(st_) > 0)
    assert st_[-1] == pytest.approx(2007 / DEFAULT_NOMINAL_RATE_HZ)
    assert src.meta.extra["time_source"] == "synthesized"
    assert any("synthesized" in w for w in src.meta.extra["warnings"])
    all_r = np.concatenate([s.ranges for s in src])
    all_v = np.concatenate([s.valid_mask() for s in src])
    assert not all_v[all_r >= 81.83].any() and all_v[(all_r > 80.0) & (all_r < 81.83)].all()
