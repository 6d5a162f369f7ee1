"""ROS bag reading and writing (ROS 1, ROS 2 sqlite3/MCAP folders, bare .mcap/.db3)."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from conftest import shared_file
from hypothesis import given, settings
from hypothesis import strategies as st

from dynslam2d.errors import DynSlamError
from dynslam2d.io.rosbag import (
    LASERSCAN,
    RosbagSource,
    laserscan_message,
    list_topics,
    open_bag_writer,
    read_pose_topic,
    ros_time_to_stamp,
    stamp_to_ros_time,
    write_scan_bag,
)
from dynslam2d.types import Scan, ScanSource

# (name under tmp_path, storage argument, expected meta.format)
LAYOUTS = [
    ("scans.bag", None, "ros1-bag"),
    ("bag_mcap", None, "ros2-bag"),
    ("bag_sqlite", "sqlite3", "ros2-bag"),
    ("scans.mcap", None, "mcap"),
    ("scans.db3", None, "ros2-bag"),
]
LAYOUT_IDS = ["ros1", "ros2-mcap-folder", "ros2-sqlite3-folder", "bare-mcap", "bare-db3"]


def f32(x: float) -> float:
    return float(np.float32(x))


def make_scans(n: int = 12, beams: int = 90, seed: int = 0, frame_id: str = "laser") -> list[Scan]:
    """Scans as a bag holds them: float32-exact fields, ns-exact stamps, NaN/±inf ranges."""
    rng = np.random.default_rng(seed)
    inc = f32(2 * math.pi / beams)
    amin = f32(-math.pi)
    scans = []
    for i in range(n):
        ranges = rng.uniform(0.1, 12.0, beams).astype(np.float32)
        ranges[rng.integers(0, beams, 5)] = np.inf
        ranges[rng.integers(0, beams, 3)] = np.nan
        ranges[rng.integers(0, beams, 2)] = -np.inf
        inten = None if i % 3 == 0 else rng.uniform(0, 1000, beams).astype(np.float32)
        scans.append(
            Scan(
                stamp=ros_time_to_stamp(1_600_000_000 + i // 10, (i % 10) * 100_000_000 + 123_457),
                angle_min=amin,
                angle_increment=inc,
                ranges=ranges,
                range_min=f32(0.15),
                range_max=f32(8.0),
                frame_id=frame_id,
                intensities=inten,
                angle_max=f32(amin + (beams - 1) * inc),
                time_increment=f32(1e-4),
                scan_time=f32(0.1),
            )
        )
    return scans


def storage_file(path):
    """The file holding a bag's messages (the bag itself, or the storage file in a folder)."""
    if path.is_file():
        return path
    return next(p for p in path.iterdir() if p.name != "metadata.yaml")


# --------------------------------------------------------------------------- time


@settings(max_examples=300, deadline=None)
@given(sec=st.integers(0, 2**31 - 1), nsec=st.integers(0, 999_999_999))
def test_ros_time_float_round_trip_is_exact(sec, nsec):
    t = ros_time_to_stamp(sec, nsec)
    s2, n2 = stamp_to_ros_time(t)
    assert 0 <= n2 < 1_000_000_000
    assert ros_time_to_stamp(s2, n2) == t
    assert abs((s2 - sec) * 1_000_000_000 + (n2 - nsec)) <= 1000  # within float precision


def test_stamp_to_ros_time_values():
    assert stamp_to_ros_time(1.5) == (1, 500_000_000)
    assert stamp_to_ros_time(0.9999999999) == (1, 0)  # carries into seconds
    assert stamp_to_ros_time(12.000000001) == (12, 1)
    assert ros_time_to_stamp(3, 250_000_000) == 3.25


# --------------------------------------------------------------------------- round trip


@pytest.mark.parametrize("name,storage,fmt", LAYOUTS, ids=LAYOUT_IDS)
def test_round_trip_is_lossless(tmp_path, name, storage, fmt):
    scans = make_scans()
    path = write_scan_bag(tmp_path / name, scans, storage=storage)
    assert path == tmp_path / name
    src = RosbagSource(path)
    assert isinstance(src, ScanSource)
    assert src.meta.format == fmt
    assert src.meta.topic == "/scan"
    assert src.meta.count == len(src) == len(scans)
    assert src.meta.beams == 90
    assert src.meta.frame_id == "laser"
    assert src.meta.range_min == f32(0.15) and src.meta.range_max == f32(8.0)
    assert src.meta.fov == pytest.approx(2 * math.pi, rel=1e-6)
    # stamps are 0.1 s apart (12 scans over 1.1 s)
    assert src.meta.rate_hz == pytest.approx(10.0, rel=1e-6)
    back = list(src)
    assert len(back) == len(scans)
    for a, b in zip(scans, back):
        assert b.same_as(a)
    assert back[0].intensities is None and back[1].intensities is not None
    assert np.isnan(back[0].ranges).any() and np.isposinf(back[0].ranges).any() and np.isneginf(back[0].ranges).any()
    # read → write → read again: still identical
    again = list(RosbagSource(write_scan_bag(tmp_path / ("again_" + name), back, storage=storage)))
    assert all(a.same_as(b) for a, b in zip(scans, again))


@pytest.mark.parametrize("name,storage,fmt", LAYOUTS, ids=LAYOUT_IDS)
def test_layout_on_disk(tmp_path, name, storage, fmt):
    path = write_scan_bag(tmp_path / name, make_scans(3), storage=storage)
    head = storage_file(path).read_bytes()[:16]
    if name.endswith(".bag"):
        assert path.is_file() and head.startswith(b"#ROSBAG V2.0")
    elif name.endswith(".mcap"):
        assert path.is_file() and head.startswith(b"\x89MCAP0\r\n")  # bare file, no metadata.yaml
    elif name.endswith(".db3"):
        assert path.is_file() and head.startswith(b"SQLite format 3")
    else:
        assert (path / "metadata.yaml").is_file()
        inner = storage_file(path)
        assert inner.suffix == (".db3" if storage == "sqlite3" else ".mcap")
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary left over
    assert list_topics(path) == {"/scan": LASERSCAN}


def test_float64_values_are_rounded_to_float32(tmp_path):
    scan = Scan(stamp=5.0, angle_min=0.1, angle_increment=0.01, ranges=[1.1, 2.2, 1e40], range_min=0.05, range_max=30.0)
    back = next(iter(RosbagSource(write_scan_bag(tmp_path / "r.mcap", [scan]))))
    assert back.angle_min == f32(0.1) != 0.1
    assert back.angle_increment == f32(0.01)
    assert back.ranges[0] == f32(1.1) and np.isposinf(back.ranges[2])  # beyond float32 → inf
    assert back.angle_max == f32(0.1 + 2 * 0.01)


def test_messages_come_in_time_order(tmp_path):
    scans = make_scans(5)
    shuffled = [scans[i] for i in (3, 0, 4, 1, 2)]
    for name in ("t.bag", "t.mcap", "t.db3"):
        back = list(RosbagSource(write_scan_bag(tmp_path / name, shuffled)))
        assert [s.stamp for s in back] == [s.stamp for s in scans]


def test_existing_output_is_replaced(tmp_path):
    for name in ("o.bag", "o.mcap", "o_dir"):
        write_scan_bag(tmp_path / name, make_scans(4))
        write_scan_bag(tmp_path / name, make_scans(7))
        assert len(RosbagSource(tmp_path / name)) == 7


def test_content_decides_not_suffix(tmp_path):
    write_scan_bag(tmp_path / "a.bag", make_scans(4))
    write_scan_bag(tmp_path / "b.mcap", make_scans(5))
    shutil.copy(tmp_path / "a.bag", tmp_path / "a.log")
    shutil.copy(tmp_path / "b.mcap", tmp_path / "b.bin")
    ros1 = RosbagSource(tmp_path / "a.log")
    assert ros1.meta.format == "ros1-bag" and len(list(ros1)) == 4
    mcap = RosbagSource(tmp_path / "b.bin")
    assert mcap.meta.format == "mcap" and len(list(mcap)) == 5
    folder = write_scan_bag(tmp_path / "c", make_scans(3), storage="sqlite3")
    folder.rename(tmp_path / "c.bag")  # a ROS 2 bag folder named like a ROS 1 bag
    ros2 = RosbagSource(tmp_path / "c.bag")
    assert ros2.meta.format == "ros2-bag" and len(list(ros2)) == 3
    shutil.copy(tmp_path / "b.mcap", tmp_path / "d.db3")  # MCAP content under a sqlite3 name
    assert len(list(RosbagSource(tmp_path / "d.db3"))) == 5


def test_folder_without_metadata_reads_its_storage_file(tmp_path):
    path = write_scan_bag(tmp_path / "bag", make_scans(6))
    (path / "metadata.yaml").unlink()
    src = RosbagSource(path)
    assert src.meta.format == "mcap" and len(list(src)) == 6


def test_empty_scan_topic(tmp_path):
    src = RosbagSource(write_scan_bag(tmp_path / "e.bag", []))
    assert src.meta.count == 0 and src.meta.beams is None and src.meta.rate_hz is None
    assert list(src) == []


# --------------------------------------------------------------------------- topics


def write_two_scan_topics(path):
    with open_bag_writer(path) as bag:
        for i, s in enumerate(make_scans(4, beams=90)):
            bag.write("/front_scan", laserscan_message(bag, s, i), s.stamp)
        for i, s in enumerate(make_scans(3, beams=45, frame_id="rear")):
            bag.write("/rear_scan", laserscan_message(bag, s, i), s.stamp)
        pose = bag.msg_class("geometry_msgs/msg/PoseStamped")
        point = bag.msg_class("geometry_msgs/msg/Point")
        quat = bag.msg_class("geometry_msgs/msg/Quaternion")
        pose_cls = bag.msg_class("geometry_msgs/msg/Pose")
        msg = pose(header=bag.header(1.0, "map"), pose=pose_cls(position=point(x=1.0, y=2.0, z=0.0),
                                                                orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0)))
        bag.write("/pose", msg, 1.0)
    return path


@pytest.mark.parametrize("name", ["two.bag", "two.mcap", "two_dir"])
def test_several_scan_topics_need_a_choice(tmp_path, name):
    path = write_two_scan_topics(tmp_path / name)
    with pytest.raises(DynSlamError) as err:
        RosbagSource(path)
    text = str(err.value)
    assert "/front_scan" in text and "/rear_scan" in text and "--topic" in text and name in text
    rear = RosbagSource(path, topic="/rear_scan")
    assert rear.meta.count == 3 and rear.meta.beams == 45 and rear.meta.frame_id == "rear"
    assert [s.n_beams for s in rear] == [45, 45, 45]
    assert RosbagSource(path, topic="front_scan").meta.topic == "/front_scan"  # slash tolerated
    with pytest.raises(DynSlamError) as err:
        RosbagSource(path, topic="/nope")
    assert "/nope does not exist" in str(err.value)
    assert "/front_scan" in str(err.value) and "/rear_scan" in str(err.value)
    with pytest.raises(DynSlamError, match="/pose is geometry_msgs/msg/PoseStamped, not a LaserScan"):
        RosbagSource(path, topic="/pose")
    assert list_topics(path) == {
        "/front_scan": LASERSCAN,
        "/pose": "geometry_msgs/msg/PoseStamped",
        "/rear_scan": LASERSCAN,
    }


def write_poses(bag, topic, stamps, xy, yaw, kind="geometry_msgs/msg/PoseStamped"):
    point = bag.msg_class("geometry_msgs/msg/Point")
    quat = bag.msg_class("geometry_msgs/msg/Quaternion")
    pose_cls = bag.msg_class("geometry_msgs/msg/Pose")
    for i, (t, (x, y), a) in enumerate(zip(stamps, xy, yaw)):
        # quaternion of a rotation by a about +z
        p = pose_cls(position=point(x=x, y=y, z=0.3), orientation=quat(x=0.0, y=0.0, z=math.sin(a / 2),
                                                                       w=math.cos(a / 2)))
        if kind == "geometry_msgs/msg/PoseStamped":
            msg = bag.msg_class(kind)(header=bag.header(t, "map", i), pose=p)
        else:  # nav_msgs/msg/Odometry
            pwc = bag.msg_class("geometry_msgs/msg/PoseWithCovariance")(pose=p, covariance=np.zeros(36))
            vec = bag.msg_class("geometry_msgs/msg/Vector3")
            tw = bag.msg_class("geometry_msgs/msg/Twist")(linear=vec(x=0.0, y=0.0, z=0.0),
                                                          angular=vec(x=0.0, y=0.0, z=0.0))
            twc = bag.msg_class("geometry_msgs/msg/TwistWithCovariance")(twist=tw, covariance=np.zeros(36))
            msg = bag.msg_class(kind)(header=bag.header(t, "odom", i), child_frame_id="base_link", pose=pwc, twist=twc)
        bag.write(topic, msg, t)


@pytest.mark.parametrize("name", ["p.bag", "p.mcap"])
def test_no_scan_topic_lists_what_is_there_and_poses_read_back(tmp_path, name):
    rng = np.random.default_rng(3)
    stamps = [ros_time_to_stamp(100, 0) + k / 8 for k in range(20)]
    xy = rng.uniform(-5, 5, (20, 2))
    yaw = rng.uniform(-math.pi, math.pi, 20)
    yaw[0] = math.pi - 1e-9
    path = tmp_path / name
    with open_bag_writer(path) as bag:
        write_poses(bag, "/red_pose", stamps, xy, yaw)
        write_poses(bag, "/odom", stamps[:5], xy[:5], yaw[:5], kind="nav_msgs/msg/Odometry")
    with pytest.raises(DynSlamError) as err:
        RosbagSource(path)
    text = str(err.value)
    assert "no sensor_msgs/LaserScan topic" in text and name in text
    assert "/red_pose (geometry_msgs/msg/PoseStamped)" in text and "/odom (nav_msgs/msg/Odometry)" in text

    track = read_pose_topic(path, "/red_pose")
    assert len(track) == 20 and track.frame_id == "map"
    assert np.array_equal(track.stamps, np.array(stamps))
    assert np.array_equal(track.xy, xy)
    assert np.allclose(np.angle(np.exp(1j * (track.yaw - yaw))), 0.0, atol=1e-12)
    assert track.pose(3).theta == track.yaw[3]
    odom = read_pose_topic(path, "odom")
    assert len(odom) == 5 and odom.frame_id == "odom" and np.allclose(odom.yaw, yaw[:5], atol=1e-12)
    with pytest.raises(DynSlamError, match=r"/blue_pose does not exist; pose topics: /odom"):
        read_pose_topic(path, "/blue_pose")


def test_ros1_bag_can_hold_types_missing_from_noetic_store(tmp_path):
    """The writer helper adds tf2_msgs/TFMessage (absent from rosbags' Noetic store) with
    the md5 real ROS 1 uses, so /tf can later be written into .bag files."""
    from rosbags.rosbag1 import Reader

    path = tmp_path / "tf.bag"
    with open_bag_writer(path) as bag:
        ts = bag.msg_class("geometry_msgs/msg/TransformStamped")
        tr = bag.msg_class("geometry_msgs/msg/Transform")
        vec = bag.msg_class("geometry_msgs/msg/Vector3")
        quat = bag.msg_class("geometry_msgs/msg/Quaternion")
        t = ts(header=bag.header(2.0, "map"), child_frame_id="laser",
               transform=tr(translation=vec(x=1.0, y=0.0, z=0.0), rotation=quat(x=0.0, y=0.0, z=0.0, w=1.0)))
        bag.write("/tf", bag.msg_class("tf2_msgs/msg/TFMessage")(transforms=[t]), 2.0)
    with Reader(path) as reader:
        (conn,) = reader.connections
        assert conn.msgtype == "tf2_msgs/msg/TFMessage"
        assert conn.digest == "94810edda583a504dfda3829e70d7eec"


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("name,storage,fmt", LAYOUTS, ids=LAYOUT_IDS)
@pytest.mark.parametrize("keep", [0.6, 0.25])
def test_truncated_bag_raises_dynslam_error(tmp_path, name, storage, fmt, keep):
    path = write_scan_bag(tmp_path / name, make_scans(40), storage=storage)
    target = storage_file(path)
    data = target.read_bytes()
    target.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(DynSlamError, match=target.name if path.is_file() else path.name):
        list(RosbagSource(path))


def test_not_a_bag(tmp_path):
    (tmp_path / "empty.bag").write_bytes(b"")
    (tmp_path / "junk.mcap").write_bytes(b"hello world, not a bag at all")
    (tmp_path / "hdr_only.bag").write_bytes(b"#ROSBAG V2.0\n\x00\x01")
    (tmp_path / "folder").mkdir()
    with pytest.raises(DynSlamError, match="empty.bag: file is empty"):
        RosbagSource(tmp_path / "empty.bag")
    with pytest.raises(DynSlamError, match="junk.mcap: not a ROS bag"):
        RosbagSource(tmp_path / "junk.mcap")
    with pytest.raises(DynSlamError, match="hdr_only.bag: cannot open ros1-bag"):
        RosbagSource(tmp_path / "hdr_only.bag")
    with pytest.raises(DynSlamError, match="folder: folder is not a ROS 2 bag"):
        list_topics(tmp_path / "folder")
    with pytest.raises(DynSlamError, match="missing.bag: no such file"):
        read_pose_topic(tmp_path / "missing.bag", "/x")


@pytest.mark.parametrize("name", ["c.bag", "c.mcap", "c.db3"])
def test_corruption_mid_bag_names_file_and_message(tmp_path, name):
    scans = make_scans(10)
    path = write_scan_bag(tmp_path / name, scans)
    data = bytearray(path.read_bytes())
    # the ranges of message 6 are stored as uint32 length + float32 LE data: break the length
    pos = bytes(data).find(scans[6].ranges.astype("<f4").tobytes())
    assert pos > 4
    data[pos - 4 : pos] = (0xFFFFFF00).to_bytes(4, "little")
    path.write_bytes(bytes(data))
    src = RosbagSource(path)  # index and first message are intact
    got = []
    with pytest.raises(DynSlamError) as err:
        for s in src:
            got.append(s)
    assert len(got) == 6
    assert name in str(err.value) and "message index 6" in str(err.value)


@pytest.mark.parametrize("name", ["m.bag", "m.mcap"])
def test_angle_metadata_mismatch_names_message_index(tmp_path, name):
    scans = make_scans(6)
    path = tmp_path / name
    with open_bag_writer(path) as bag:
        for i, s in enumerate(scans):
            msg = laserscan_message(bag, s, i)
            if i == 3:
                msg.angle_max = float(s.angle_min + 3 * len(s.ranges) * s.angle_increment)
            bag.write("/scan", msg, s.stamp)
    got = []
    with pytest.raises(DynSlamError) as err:
        for s in RosbagSource(path):
            got.append(s)
    assert len(got) == 3
    text = str(err.value)
    assert name in text and "message index 3" in text and "angle metadata implies" in text


@pytest.mark.parametrize("name,storage,fmt", LAYOUTS, ids=LAYOUT_IDS)
def test_interrupted_write_leaves_nothing(tmp_path, name, storage, fmt):
    scans = make_scans(8)

    def three_then_fail():
        yield from scans[:3]
        raise RuntimeError("source broke")

    with pytest.raises(RuntimeError, match="source broke"):
        write_scan_bag(tmp_path / name, three_then_fail(), storage=storage)
    assert list(tmp_path.iterdir()) == []
    # an existing bag survives a failed overwrite untouched
    write_scan_bag(tmp_path / name, scans[:5], storage=storage)
    with pytest.raises(RuntimeError):
        write_scan_bag(tmp_path / name, three_then_fail(), storage=storage)
    assert [p.name for p in tmp_path.iterdir()] == [name]
    assert len(list(RosbagSource(tmp_path / name))) == 5


def test_writer_rejects_bad_requests(tmp_path):
    with pytest.raises(DynSlamError, match="storage='mcap' does not apply"):
        write_scan_bag(tmp_path / "a.bag", make_scans(2), storage="mcap")
    with pytest.raises(DynSlamError, match="unknown bag storage 'zip'"):
        write_scan_bag(tmp_path / "a", make_scans(2), storage="zip")
    with pytest.raises(DynSlamError, match="contradicts"):
        write_scan_bag(tmp_path / "a.mcap", make_scans(2), storage="sqlite3")
    early = Scan(stamp=-1.0, angle_min=0.0, angle_increment=0.1, ranges=[1.0, 2.0], range_min=0.1, range_max=5.0)
    with pytest.raises(DynSlamError, match=r"a\.mcap: topic /scan message 2: stamp -1\.0"):
        write_scan_bag(tmp_path / "a.mcap", [*make_scans(2), early])
    huge = Scan(stamp=1.0, angle_min=0.0, angle_increment=0.1, ranges=[1.0, 2.0], range_min=0.1, range_max=1e300)
    with pytest.raises(DynSlamError, match=r"a\.bag: cannot write message 0 on /scan"):
        write_scan_bag(tmp_path / "a.bag", [huge])
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- real data

REAL_BAGS = [
    ("dynamic/datmo/intersection.bag", "/scan", 85, 360, 13.0),
    ("dynamic/datmo/overtake_ego.bag", "/scan", 135, 360, 13.0),
    ("dynamic/datmo/overtake_red.bag", "/scan", 130, 360, 13.0),
    ("dynamic/datmo/overtakes.bag", "/scan", 339, 360, 12.8),
    ("dynamic/datmo/parallel.bag", "/scan", 219, 360, 12.9),
    ("dynamic/datmo/two_robots.bag", "/scan", 388, 360, 11.8),
    ("dynamic/leg_tracker/demo_stationary_simple_environment.bag", "/scan", 1265, 512, 10.0),
    ("dynamic/leg_tracker/positive_1.bag", "right_scan", 400, 768, 7.5),
    ("dynamic/leg_tracker/positive_1_extracted.bag", "/training_scan", 197, 768, 3.8),
]


@pytest.mark.shared_data
@pytest.mark.parametrize("rel,topic,count,beams,rate", REAL_BAGS, ids=[r[0].split("/")[-1] for r in REAL_BAGS])
def test_real_bags(rel, topic, count, beams, rate):
    src = RosbagSource(shared_file(rel))
    assert src.meta.format == "ros1-bag"
    assert src.meta.topic == topic
    assert src.meta.count == count and src.meta.beams == beams
    assert src.meta.rate_hz == pytest.approx(rate, rel=0.02)
    scans = list(src)
    assert len(scans) == count
    assert all(s.n_beams == beams for s in scans)
    stamps = np.array([s.stamp for s in scans])
    assert np.all(np.diff(stamps) > 0) and stamps[0] > 1.3e9


@pytest.mark.shared_data
def test_real_bag_details_and_lossless_copy(tmp_path):
    path = shared_file("dynamic/datmo/intersection.bag")
    src = RosbagSource(path)
    assert src.meta.frame_id == "laser"
    assert src.meta.range_min == pytest.approx(0.15) and src.meta.range_max == 8.0
    scans = list(src)
    first = scans[0]
    assert first.stamp == ros_time_to_stamp(1575811857, 955902638)
    assert first.angle_min == pytest.approx(-3.1241, abs=1e-4) and first.angle_max == pytest.approx(math.pi, abs=1e-6)
    assert first.intensities is not None and first.intensities.shape == (360,)
    inf_share = np.mean([np.isinf(s.ranges).mean() for s in scans])
    assert 0.45 < inf_share < 0.7  # README: 50–63 % of beams are inf
    assert "/red_pose" in src.meta.extra["topics"]
    for name in ("copy.bag", "copy.mcap"):
        back = list(RosbagSource(write_scan_bag(tmp_path / name, scans)))
        assert len(back) == 85 and all(a.same_as(b) for a, b in zip(scans, back))


@pytest.mark.shared_data
def test_real_red_pose_ground_truth():
    path = shared_file("dynamic/datmo/intersection.bag")
    track = read_pose_topic(path, "/red_pose")
    assert len(track) == 780 and track.frame_id == "map"
    assert np.isfinite(track.xy).all() and np.isfinite(track.yaw).all()
    rate = (len(track) - 1) / (track.stamps[-1] - track.stamps[0])
    assert rate == pytest.approx(120.0, rel=0.02)
    assert np.all(np.diff(track.stamps) > 0)
    assert np.all(np.abs(track.yaw) <= math.pi)
    # a scaled RC car on a lab floor: it moves, but stays within a few metres
    extent = track.xy.max(axis=0) - track.xy.min(axis=0)
    assert 0.5 < extent.max() < 10.0
    with pytest.raises(DynSlamError, match=r"/scan is sensor_msgs/msg/LaserScan, not a pose type"):
        read_pose_topic(path, "/scan")
