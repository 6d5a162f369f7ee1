"""Odometry input: interpolation, bags (topic, TF + tf_static, IMU, wheel speeds), CARMEN, bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_file

from dynslam2d.errors import DynSlamError
from dynslam2d.inputs import open_source
from dynslam2d.io.odombag import (
    ENCODER,
    TFMESSAGE,
    imu_message,
    odometry_message,
    read_bag_odometry,
    transform_message,
)
from dynslam2d.io.odometry import ImuTrack, OdometryTrack, compose_mount, interpolate_poses, parse_laser_offset
from dynslam2d.io.rosbag import LASERSCAN, laserscan_message, open_bag_writer
from dynslam2d.types import Pose2D, Scan

# --------------------------------------------------------------------------- helpers


def _scan(t: float, frame: str = "laser") -> Scan:
    return Scan(stamp=t, angle_min=-1.0, angle_increment=0.1, ranges=np.full(21, 3.0), range_min=0.1,
                range_max=10.0, frame_id=frame)


def _circle(t: np.ndarray, v: float = 0.5, w: float = 0.25) -> np.ndarray:
    """Base poses on a circle from the origin heading +x: speed v m/s, yaw rate w rad/s."""
    r = v / w
    return np.column_stack((r * np.sin(w * t), r * (1 - np.cos(w * t)), w * t))


def _write_bag(path: Path, *, scan_stamps, odom=None, odom_topic="/odom", tf=None, tf_static=None,
               imu=None, imu_topic="/imu", frame="laser", base="base_link", extra=None) -> Path:
    """A bag with scans and optional /odom (stamps, poses), /tf (stamps, poses odom→base),
    /tf_static (Pose2D base→laser), IMU (stamps, rates); ``extra(bag)`` writes more."""
    with open_bag_writer(path) as bag:
        bag.add_topic("/scan", LASERSCAN)
        if tf_static is not None:
            bag.add_topic("/tf_static", TFMESSAGE, latched=True)
            bag.write("/tf_static", transform_message(bag, scan_stamps[0], base, frame, tf_static), scan_stamps[0])
        for i, t in enumerate(scan_stamps):
            bag.write("/scan", laserscan_message(bag, _scan(t, frame), i), t)
        if odom is not None:
            for i, (t, p) in enumerate(zip(*odom)):
                bag.write(odom_topic, odometry_message(bag, t, "odom", base, p, seq=i), max(t, 0.0))
        if tf is not None:
            for t, p in zip(*tf):
                bag.write("/tf", transform_message(bag, t, "odom", base, Pose2D.from_array(p)), t)
        if imu is not None:
            for t, w in zip(*imu):
                bag.write(imu_topic, imu_message(bag, t, "imu_link", w), t)
        if extra is not None:
            extra(bag)
    return path


SCAN_T = np.arange(100.0, 104.0, 0.1)
ODOM_T = np.arange(99.9, 104.2, 0.02)


# --------------------------------------------------------------------------- interpolation


def test_interpolation_on_a_known_circle_and_across_the_yaw_wrap():
    t = np.arange(0.0, 30.0, 0.05)
    poses = _circle(t)
    poses[:, 2] = (poses[:, 2] + math.pi) % (2 * math.pi) - math.pi  # wraps at t ≈ 12.6 s
    q = np.linspace(0.01, 29.9, 777)
    got, ok = interpolate_poses(t, poses, q)
    assert ok.all()
    exact = _circle(q)
    assert np.abs(got[:, :2] - exact[:, :2]).max() < 2e-4  # chord error of 0.05 s steps on a 2 m circle
    dyaw = (got[:, 2] - exact[:, 2] + math.pi) % (2 * math.pi) - math.pi
    assert np.abs(dyaw).max() < 1e-9  # yaw is linear in time here: exact, also across ±π
    # exactly between two samples straddling the wrap: the mean heading, not the long way round
    mid, _ = interpolate_poses(np.array([0.0, 1.0]), np.array([[0, 0, 3.1], [0, 0, -3.1]]), 0.5, max_gap=2.0)
    assert abs(abs(mid[0, 2]) - math.pi) < 1e-9


def test_interpolation_never_extrapolates_beyond_the_tolerance_or_across_gaps():
    s = np.array([0.0, 1.0, 2.0, 5.0, 6.0])
    p = np.column_stack((s, np.zeros(5), np.zeros(5)))  # 1 m/s along x
    q = np.array([-0.2, -0.05, 0.5, 3.0, 5.5, 6.05, 6.2, 2.0])
    got, ok = interpolate_poses(s, p, q, tolerance=0.1, max_gap=1.5)
    assert ok.tolist() == [False, True, True, False, True, True, False, True]
    assert got[1, 0] == pytest.approx(-0.05)  # first segment extended within the tolerance
    assert got[5, 0] == pytest.approx(6.05)
    assert np.isnan(got[0]).all() and np.isnan(got[3]).all()


def test_tracks_drop_nan_samples_and_reject_all_nan():
    t = OdometryTrack([0.0, 1.0, 2.0, 2.0], [[0, 0, 0], [np.nan, 0, 0], [2, 0, 0], [3, 0, 0]], source="x")
    assert len(t) == 2 and t.dropped == 2 and t.nonfinite == 1
    with pytest.raises(DynSlamError, match="no usable odometry"):
        OdometryTrack([0.0, 1.0], [[np.nan, 0, 0], [0, np.inf, 0]], source="x")
    imu = ImuTrack([0.0, 0.01, 0.02, 0.5], [1.0, 2.0, 3.0, 10.0])
    assert imu.at(0.01, window=0.03) == pytest.approx(2.0)  # mean of the window
    assert imu.at(0.26, window=0.01) == pytest.approx(3.0 + 7.0 * 0.24 / 0.48)  # interpolated
    assert imu.at(1.0) is None


def test_parse_laser_offset():
    assert parse_laser_offset("-0.12,0,0") == Pose2D(-0.12, 0.0, 0.0)
    assert parse_laser_offset("0.1 0.2 0.3") == Pose2D(0.1, 0.2, 0.3)
    with pytest.raises(DynSlamError, match="--laser-offset"):
        parse_laser_offset("1,2")


# --------------------------------------------------------------------------- bags


@pytest.mark.parametrize("suffix", [".bag", ".mcap"])
def test_odometry_topic_with_tf_static_mount_and_imu(tmp_path, suffix):
    mount = Pose2D(0.25, 0.05, 0.1)
    base = _circle(ODOM_T - ODOM_T[0])
    imu_t = np.arange(99.9, 104.2, 0.01)
    bag = _write_bag(tmp_path / f"b{suffix}", scan_stamps=SCAN_T, odom=(ODOM_T, base), tf_static=mount,
                     imu=(imu_t, np.full(imu_t.shape, 0.25)))
    src = open_source(bag)
    scans = list(src)
    assert src.meta.odometry == "/odom (nav_msgs/Odometry); IMU /imu"
    expect = compose_mount(_circle(SCAN_T - ODOM_T[0]), mount)
    got = np.array([s.odom.as_array() for s in scans])
    assert np.abs(got[:, :2] - expect[:, :2]).max() < 1e-4
    assert np.abs(got[:, 2] - expect[:, 2]).max() < 1e-6
    # the laser pose differs from the base pose by the static transform
    base_at = _circle(SCAN_T - ODOM_T[0])
    assert np.allclose(np.hypot(*(got[:, :2] - base_at[:, :2]).T), math.hypot(0.25, 0.05), atol=1e-4)
    assert all(s.yaw_rate == pytest.approx(0.25) for s in scans)
    assert src.meta.extra["odometry"]["with_odom"] == len(SCAN_T)


def test_tf_odometry_ros1_style_frames_and_laser_offset_option(tmp_path):
    mount = Pose2D(-0.12, 0.0, 0.0)
    base = _circle(ODOM_T - ODOM_T[0])

    def tf_static_on_tf(bag):
        # ROS 1 static_transform_publisher republishes a constant transform on /tf, with '/' prefixes
        for t in SCAN_T[::5]:
            bag.write("/tf", transform_message(bag, t, "/base_link", "/laser", mount), t)

    bag = _write_bag(tmp_path / "tf.bag", scan_stamps=SCAN_T, tf=(ODOM_T, base), extra=tf_static_on_tf)
    src = open_source(bag)
    got = np.array([s.odom.as_array() for s in src])
    assert src.meta.odometry == "tf odom→base_link"
    expect = compose_mount(_circle(SCAN_T - ODOM_T[0]), mount)
    assert np.abs(got - expect).max() < 1e-4
    # --laser-offset overrides TF, and says so
    src2 = open_source(bag, laser_offset=Pose2D(0.3, 0.0, 0.0))
    got2 = np.array([s.odom.as_array() for s in src2])
    assert np.abs(got2 - compose_mount(_circle(SCAN_T - ODOM_T[0]), Pose2D(0.3, 0, 0))).max() < 1e-4
    assert any("overrides TF" in w for w in src2.meta.extra["warnings"])


def test_tf_tree_without_the_laser_frame(tmp_path):
    base = _circle(ODOM_T - ODOM_T[0])
    bag = _write_bag(tmp_path / "nolaser.bag", scan_stamps=SCAN_T, tf=(ODOM_T, base), frame="front_laser")
    with pytest.raises(DynSlamError, match="TF has no frame 'front_laser'.*odom"):
        open_source(bag, odom="tf")
    src = open_source(bag)  # auto: a clear warning, laser only
    assert all(s.odom is None for s in src)
    assert src.meta.odometry is None
    assert any("TF has no frame 'front_laser'" in w and "laser only" in w for w in src.meta.extra["warnings"])


def test_odometry_stamps_that_do_not_cover_the_scans(tmp_path):
    base = _circle(ODOM_T - ODOM_T[0])
    late = _write_bag(tmp_path / "late.bag", scan_stamps=SCAN_T, odom=(ODOM_T + 1000.0, base))
    with pytest.raises(DynSlamError, match="no scan lies within the odometry's stamps"):
        list(open_source(late, odom="/odom"))
    early = _write_bag(tmp_path / "early.bag", scan_stamps=SCAN_T, odom=(ODOM_T - 1000.0, base))
    with pytest.raises(DynSlamError, match="end before the first scan"):
        list(open_source(early, odom="/odom"))
    # partly covered (odometry starts 2 s late): counted, warned, those scans carry no odom
    part = _write_bag(tmp_path / "part.bag", scan_stamps=SCAN_T, odom=(ODOM_T[ODOM_T >= 102.0], base[ODOM_T >= 102.0]))
    src = open_source(part)
    scans = list(src)
    missing = sum(s.odom is None for s in scans)
    assert missing == int(np.count_nonzero(SCAN_T < 102.0 - 0.1)) and missing > 0
    assert src.meta.extra["odometry"]["without_odom"] == missing
    assert any("outside the odometry's time span" in w for w in src.meta.extra["warnings"])


def test_imu_stamps_that_do_not_cover_the_scans_and_nan_yaw_rates(tmp_path):
    late = _write_bag(tmp_path / "late.bag", scan_stamps=SCAN_T, imu=(ODOM_T + 1000.0, np.full(ODOM_T.shape, 0.25)))
    with pytest.raises(DynSlamError, match="no scan lies within the IMU's stamps"):
        list(open_source(late, odom="none", imu="/imu"))
    early = _write_bag(tmp_path / "early.bag", scan_stamps=SCAN_T, imu=(ODOM_T - 50.0, np.full(ODOM_T.shape, 0.25)))
    with pytest.raises(DynSlamError, match="IMU stamps .* end before the first scan"):
        list(open_source(early, odom="none", imu="/imu"))
    src = open_source(late, odom="none")  # auto: every scan without a yaw rate is warned about, never silent
    assert all(s.yaw_rate is None for s in src)
    assert any("40 of 40 scans outside the IMU's time span" in w for w in src.meta.extra["warnings"])
    rates = np.full(ODOM_T.shape, 0.25)
    rates[5:8] = np.nan
    nan = _write_bag(tmp_path / "nan.bag", scan_stamps=SCAN_T, imu=(ODOM_T, rates))
    src = open_source(nan, odom="none", imu="/imu")
    assert all(s.yaw_rate == pytest.approx(0.25) for s in src)
    assert any("3 non-finite yaw rates dropped (first at message index 5)" in w for w in src.meta.extra["warnings"])


def test_nan_in_odometry(tmp_path):
    base = _circle(ODOM_T - ODOM_T[0])
    base[10:13, 0] = np.nan
    bag = _write_bag(tmp_path / "nan.bag", scan_stamps=SCAN_T, odom=(ODOM_T, base))
    src = open_source(bag, odom="/odom")
    scans = list(src)
    assert all(s.odom is not None and s.odom.is_finite() for s in scans)
    assert any("3 messages with NaN/inf dropped (first at message index 10)" in w for w in src.meta.extra["warnings"])
    allnan = _write_bag(tmp_path / "allnan.bag", scan_stamps=SCAN_T, odom=(ODOM_T, np.full_like(base, np.nan)))
    with pytest.raises(DynSlamError, match="no usable odometry samples"):
        open_source(allnan, odom="/odom")


def test_wrong_topics(tmp_path):
    base = _circle(ODOM_T - ODOM_T[0])
    bag = _write_bag(tmp_path / "t.bag", scan_stamps=SCAN_T, odom=(ODOM_T, base), imu=(ODOM_T, np.zeros(ODOM_T.shape)))
    with pytest.raises(DynSlamError, match="--imu /odom: topic is nav_msgs/Odometry, not sensor_msgs/Imu; IMU topics: "
                                           "/imu"):
        open_source(bag, imu="/odom")
    with pytest.raises(DynSlamError, match="--odom /imu: topic is sensor_msgs/Imu"):
        open_source(bag, odom="/imu")
    with pytest.raises(DynSlamError, match="--odom /wheel_odom: topic does not exist; .*candidates: /odom"):
        open_source(bag, odom="/wheel_odom")
    assert list(open_source(bag, odom="none", imu="none"))[0].odom is None


def test_ground_truth_topic_is_not_taken_for_odometry(tmp_path):
    base = _circle(ODOM_T - ODOM_T[0])
    bag = _write_bag(tmp_path / "gt.bag", scan_stamps=SCAN_T, odom=(ODOM_T, base), odom_topic="/base_pose_ground_truth")
    assert open_source(bag).meta.odometry is None
    assert open_source(bag, odom="/base_pose_ground_truth").meta.odometry.startswith("/base_pose_ground_truth")


def test_wheel_speed_dead_reckoning_with_imu(tmp_path):
    """barc/Encoder wheel speeds (rad/s) + IMU yaw rate → a known circle; gyro bias estimated at rest."""
    from rosbags.typesys import get_types_from_msg

    r, v, w, bias = 0.0312, 0.5, 0.25, 0.01
    wheel_t = np.arange(99.0, 104.2, 0.02)
    imu_t = np.arange(99.0, 104.2, 0.01)

    def wheels(bag):
        bag.typestore.register(get_types_from_msg("float32 FL\nfloat32 FR\nfloat32 BL\nfloat32 BR", ENCODER))
        cls = bag.msg_class(ENCODER)
        for t in wheel_t:
            s = v / r if t >= 100.0 else 0.0
            bag.write("/wheel_speeds", cls(FL=s, FR=s, BL=1.1 * s, BR=1.1 * s), t)  # rear wheels slip

    rates = np.where(imu_t >= 100.0, w, 0.0) + bias
    bag = _write_bag(tmp_path / "wheels.bag", scan_stamps=SCAN_T, imu=(imu_t, rates), imu_topic="/imu/data",
                     extra=wheels)
    src = open_source(bag, laser_offset=Pose2D(-0.12, 0.0, 0.0))
    scans = list(src)
    assert src.meta.odometry.startswith("dead reckoning: /wheel_speeds (barc/Encoder) + /imu/data yaw rate")
    got = np.array([s.odom.as_array() for s in scans])
    expect = compose_mount(_circle(SCAN_T - 100.0, v, w), Pose2D(-0.12, 0.0, 0.0))
    assert np.abs(got[:, :2] - expect[:, :2]).max() < 0.01
    assert np.abs(got[:, 2] - expect[:, 2]).max() < 0.005
    # without a mount: the laser at the base origin, and a warning that says how to fix it
    plain = open_source(bag)
    list(plain)
    assert any("--laser-offset" in x for x in plain.meta.extra["warnings"])
    with pytest.raises(DynSlamError, match="needs an IMU yaw rate"):
        open_source(bag, odom="/wheel_speeds", imu="none")
    quiet = open_source(bag, imu="none")  # auto without an IMU: not used, and it says why
    assert quiet.meta.odometry is None
    assert any("are not used: dead reckoning needs an IMU yaw rate (--imu "
               "none)" in x for x in quiet.meta.extra["warnings"])


# --------------------------------------------------------------------------- CARMEN


def _carmen_log(path: Path, mount: Pose2D, with_flaser_pose: bool = True) -> Path:
    lines = []
    for k in range(21):  # ODOM at 10 Hz over 0..2 s: 0.5 m/s along x
        t = 1000.0 + 0.1 * k
        lines.append(f"ODOM {0.05 * k:.6f} 0.0 0.0 0.5 0.0 0.0 {t:.6f} host {t:.6f}")
    for k in range(8):  # FLASER at 4 Hz, 181 beams
        t = 1000.05 + 0.25 * k
        odom = Pose2D(0.5 * (t - 1000.0), 0.0, 0.0)
        laser = odom.compose(mount) if with_flaser_pose else Pose2D(0.0, 0.0, 0.0)
        ranges = " ".join(["4.0"] * 181)
        lines.append(f"FLASER 181 {ranges} {laser.x:.6f} {laser.y:.6f} {laser.theta:.6f} "
                     f"{odom.x:.6f} {odom.y:.6f} {odom.theta:.6f} {t:.6f} host {t:.6f}")
    lines.sort(key=lambda ln: float(ln.split()[-3]))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_carmen_flaser_pose_fields_and_odom_records(tmp_path):
    mount = Pose2D(0.2, 0.0, 0.0)
    log = _carmen_log(tmp_path / "a.clf", mount)
    src = open_source(log)
    scans = list(src)
    assert src.meta.odometry == "CARMEN FLASER pose fields"
    assert src.meta.extra["odometry"]["mount"] == pytest.approx([0.2, 0.0, 0.0], abs=1e-6)
    for s in scans:  # exactly the record's laser pose
        assert s.odom.x == pytest.approx(0.5 * (s.stamp - 1000.0) + 0.2, abs=1e-6)
    # ODOM records, interpolated at the scan stamps, composed with the estimated mount
    src2 = open_source(log, odom="ODOM")
    got = np.array([s.odom.x for s in src2])
    assert src2.meta.odometry == "CARMEN ODOM records"
    assert np.abs(got - (0.5 * (np.array([s.stamp for s in scans]) - 1000.0) + 0.2)).max() < 1e-6
    with pytest.raises(DynSlamError, match="FLASER.*ODOM"):
        open_source(log, odom="/odom")
    with pytest.raises(DynSlamError, match="no IMU"):
        open_source(log, imu="/imu")
    # FLASER pose fields that carry nothing (all zero): auto falls back to the ODOM records
    zero = _carmen_log(tmp_path / "z.clf", mount, with_flaser_pose=False)
    src3 = open_source(zero)
    assert src3.meta.odometry == "CARMEN ODOM records"
    with pytest.raises(DynSlamError, match="constant"):
        open_source(zero, odom="FLASER")


# --------------------------------------------------------------------------- real recordings


def test_mit_csail_flaser_odometry_attaches_to_every_scan():
    log = shared_file("mit-csail/mit-csail.clf")
    src = open_source(log)
    scans = list(src)
    assert len(scans) == 1988
    assert all(s.odom is not None for s in scans)
    assert src.meta.odometry == "CARMEN FLASER pose fields"
    # raw odometry: x y θ == odom_x odom_y odom_θ, so the mount is the identity
    assert src.meta.extra["odometry"]["mount"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)
    steps = np.hypot(np.diff([s.odom.x for s in scans]), np.diff([s.odom.y for s in scans]))
    assert steps.max() < 1.0 and steps.sum() > 100.0  # a real path, no jumps


def test_datmo_dead_reckoning_path_length_against_motion_capture():
    """Wheel speeds + IMU on the datmo bags: path length vs /ego_pose (docs/slam.md quotes the ratios)."""
    from dynslam2d.io.rosbag import read_pose_topic

    ratios = {}
    for name in ("intersection", "overtake_ego", "overtake_red", "overtakes", "parallel"):
        bag = shared_file(f"dynamic/datmo/{name}.bag")
        info = read_bag_odometry(bag, "laser")
        assert info.track is not None and info.description.startswith("dead reckoning")
        track = info.track
        mocap = read_pose_topic(bag, "/ego_pose")
        a, b = track.span
        keep = (mocap.stamps >= a) & (mocap.stamps <= b)
        # motion capture at 120 Hz carries jitter that adds length: compare at the wheel rate
        xy = np.column_stack([np.interp(track.stamps, mocap.stamps[keep], mocap.xy[keep, j]) for j in (0, 1)])
        mocap_len = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
        ratios[name] = track.path_length() / mocap_len
    # the wheel radius (0.0312 m) was set on two_robots.bag, not on these bags
    assert all(0.95 < r < 1.06 for r in ratios.values()), ratios


def test_unreadable_odometry_fails_only_when_asked_for(tmp_path, monkeypatch):
    import dynslam2d.io.odombag as odombag

    bag = _write_bag(tmp_path / "x.bag", scan_stamps=SCAN_T, odom=(ODOM_T, _circle(ODOM_T - ODOM_T[0])))

    def broken(*args, **kwargs):
        raise DynSlamError("x.bag: cannot read a message of /tf (struct.error)")

    monkeypatch.setattr(odombag, "read_bag_odometry", broken)
    src = open_source(bag)  # auto: the run goes on, laser only, and says why
    assert all(s.odom is None for s in src)
    assert any("cannot read a message of /tf" in w and "laser only" in w for w in src.meta.extra["warnings"])
    with pytest.raises(DynSlamError, match="cannot read"):
        open_source(bag, odom="/odom")


def test_corrected_carmen_logs_are_not_odometry(tmp_path):
    log = _carmen_log(tmp_path / "run.clf", Pose2D(0.2, 0.0, 0.0))
    text = log.read_text()
    gfs = tmp_path / "run2.clf"
    gfs.write_text(text + "NEFF 28.3\n")  # GMapping writes its effective particle count
    src = open_source(gfs)
    assert src.meta.odometry is None and all(s.odom is None for s in src)
    assert any("SLAM-corrected" in w and "1 NEFF" in w for w in src.meta.extra["warnings"])
    assert open_source(gfs, odom="FLASER").meta.odometry == "CARMEN FLASER pose fields"
    named = tmp_path / "intel-corrected.log"
    named.write_text(text)
    assert open_source(named).meta.odometry is None
