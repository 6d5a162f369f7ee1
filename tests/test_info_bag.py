"""``dynslam2d info`` on a bag with several LaserScan topics: every topic described, and ``run`` asks for one."""

from __future__ import annotations

import json
import math
import zipfile

import numpy as np
import pytest
from conftest import run_cli

from dynslam2d.io.odombag import IMU, ODOMETRY, TFMESSAGE, imu_message, odometry_message, transform_message
from dynslam2d.io.rosbag import LASERSCAN, laserscan_message, open_bag_writer
from dynslam2d.types import Pose2D, Scan

FRONT_T = 100.0 + 0.1 * np.arange(40)  # 10 Hz, 3.9 s
REAR_T = 100.05 + 0.2 * np.arange(25)  # 5 Hz, 4.8 s


def _front(i: int) -> Scan:
    """181 beams over 181°, ranges 2.00 + 0.01·i m, every 4th beam no return (inf)."""
    r = np.full(181, 2.0 + 0.01 * i)
    r[::4] = np.inf
    return Scan(stamp=float(FRONT_T[i]), angle_min=-math.pi / 2, angle_increment=math.pi / 180, ranges=r,
                range_min=0.1, range_max=10.0, frame_id="front_laser")


def _rear(i: int, stamp: float | None = None) -> Scan:
    """90 beams over 90°, ranges 1.0 … 4.56 m (none missing), sensor limit 5 m."""
    return Scan(stamp=float(REAR_T[i]) if stamp is None else stamp, angle_min=-math.pi / 4,
                angle_increment=math.pi / 180, ranges=np.linspace(1.0, 4.56, 90), range_min=0.05, range_max=5.0,
                frame_id="rear_laser")


def _write(path):
    """Two LaserScan topics (/rear_scan repeats one stamp), /odom, /tf, /tf_static, /imu, a pose topic."""
    events = [(float(t), "front", i) for i, t in enumerate(FRONT_T)] + [(float(t), "rear", i) for i, t in
                                                                          enumerate(REAR_T)]
    events.append((float(REAR_T[10]) + 0.01, "rear-repeat", 10))  # header stamp = the previous scan's
    odom_t = 99.95 + 0.1 * np.arange(50)
    events += [(float(t), "odom", i) for i, t in enumerate(odom_t)]
    events += [(float(t), "imu", i) for i, t in enumerate(99.95 + 0.05 * np.arange(100))]
    events += [(99.95 + 0.5 * i, "gt", i) for i in range(10)]
    events.sort()
    with open_bag_writer(path) as bag:
        for topic, kind in (("/front_scan", LASERSCAN), ("/rear_scan", LASERSCAN), ("/odom", ODOMETRY),
                            ("/tf", TFMESSAGE), ("/imu", IMU), ("/gt_pose", "geometry_msgs/msg/PoseStamped")):
            bag.add_topic(topic, kind)
        bag.add_topic("/tf_static", TFMESSAGE, latched=True)
        bag.write("/tf_static", transform_message(bag, 99.9, "base_link", "front_laser", Pose2D(0.2, 0, 0)), 99.9)
        pose_cls = bag.msg_class("geometry_msgs/msg/PoseStamped")
        for t, kind, i in events:
            if kind == "front":
                bag.write("/front_scan", laserscan_message(bag, _front(i), i), t)
            elif kind == "rear":
                bag.write("/rear_scan", laserscan_message(bag, _rear(i), i), t)
            elif kind == "rear-repeat":
                bag.write("/rear_scan", laserscan_message(bag, _rear(i, float(REAR_T[i])), 99), t)
            elif kind == "odom":
                p = np.array([0.05 * i, 0.0, 0.0])
                bag.write("/odom", odometry_message(bag, t, "odom", "base_link", p, seq=i), t)
                bag.write("/tf", transform_message(bag, t, "odom", "base_link", Pose2D.from_array(p), i), t)
            elif kind == "imu":
                bag.write("/imu", imu_message(bag, t, "imu_link", 0.0, i), t)
            else:
                point = bag.msg_class("geometry_msgs/msg/Point")(x=float(i), y=0.0, z=0.0)
                quat = bag.msg_class("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0)
                pose = bag.msg_class("geometry_msgs/msg/Pose")(position=point, orientation=quat)
                bag.write("/gt_pose", pose_cls(header=bag.header(t, "map", i), pose=pose), t)
    return path


@pytest.mark.parametrize("name", ["two.bag", "two.mcap"])
def test_info_describes_every_scan_topic_of_a_bag(tmp_path, capsys, name):
    bag = _write(tmp_path / name)
    code, out, err = run_cli(capsys, "info", str(bag), "--json", "--body-scans", "0")
    assert code == 0, err
    data = json.loads(out)
    assert data["run_needs_topic"] == ["/front_scan", "/rear_scan"]
    front, rear = data["scans"]["/front_scan"], data["scans"]["/rear_scan"]
    assert front["scans"] == 40 and data["topics"]["/front_scan"]["messages"] == 40
    assert front["rate_hz"] == pytest.approx(10.0) and front["duration"] == pytest.approx(3.9)
    assert front["beams_max"] == 181 and front["fov"] == pytest.approx(math.radians(181), rel=1e-6)
    assert front["range_max"] == 10.0 and front["frame_id"] == "front_laser"
    assert front["valid_range_min"] == pytest.approx(2.0) and front["valid_range_max"] == pytest.approx(2.39)
    assert front["no_return_share"] == pytest.approx(46 / 181)  # beams 0, 4, …, 180
    # the repeated stamp: in the bag's index, dropped from the figures and counted
    assert data["topics"]["/rear_scan"]["messages"] == 26 and rear["scans"] == 25
    assert rear["extra"]["skipped_scans"] == 1
    assert rear["rate_hz"] == pytest.approx(5.0) and rear["beams_max"] == 90
    assert rear["fov"] == pytest.approx(math.pi / 2, rel=1e-6) and rear["range_max"] == 5.0
    assert rear["valid_range_max"] == pytest.approx(4.56) and rear["no_return_share"] == 0.0
    roles = {t: (v["role"], v["messages"]) for t, v in data["topics"].items()}
    assert roles["/odom"] == ("odometry", 50) and roles["/tf"] == ("TF", 50) and roles["/tf_static"] == ("static TF", 1)
    assert roles["/imu"] == ("IMU", 100) and roles["/gt_pose"] == ("poses", 10)
    assert data["odometry"]["odometry"] == ["/odom (nav_msgs/Odometry)", "tf"] and data["odometry"]["imu"] == "/imu"
    # the same figures as describing one topic (the rear one needs --skip-bad there: its stamps repeat once)
    for topic, extra in (("/front_scan", ()), ("/rear_scan", ("--skip-bad",))):
        code, out, err = run_cli(capsys, "info", str(bag), "--topic", topic, "--json", "--body-scans", "0", *extra)
        assert code == 0, err
        one = json.loads(out)
        for key in ("scans", "beams_max", "fov", "rate_hz", "duration", "range_min", "range_max", "valid_range_min",
                    "valid_range_median", "valid_range_max", "no_return_share", "max_gap", "first_stamp"):
            assert one[key] == data["scans"][topic][key], (topic, key)
    assert run_cli(capsys, "info", str(bag), "--topic", "/rear_scan", "--json")[0] == 2  # stops at the repeat


def test_info_bag_overview_as_text_and_run_asks_for_a_topic(tmp_path, capsys):
    bag = _write(tmp_path / "two.bag")
    code, out, err = run_cli(capsys, "info", str(bag), "--body-scans", "0")
    assert code == 0, err
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith("/")}
    assert "10.00 Hz" in rows["/front_scan"] and "181" in rows["/front_scan"] and "25.4 %" in rows["/front_scan"]
    assert rows["/rear_scan"].split()[1] == "26"
    assert "/rear_scan: 1 of 26 stamps do not increase (left out above; 'run' needs --skip-bad)" in out
    assert "5.00 Hz" in rows["/rear_scan"] and "90.0°" in rows["/rear_scan"] and "0.05–5.00 m" in rows["/rear_scan"]
    assert "odometry: /odom (nav_msgs/Odometry, 50)" in out and "IMU: /imu (sensor_msgs/Imu, 100)" in out
    assert "--odom auto: /odom (nav_msgs/Odometry) else tf; --imu auto: /imu" in out
    assert "--topic /front_scan | /rear_scan" in out
    code, out, err = run_cli(capsys, "run", str(bag), "--out", str(tmp_path / "r"))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "2 LaserScan topics (/front_scan, /rear_scan)" in err and "--topic" in err
    assert not (tmp_path / "r").exists()


def test_info_bag_overview_inside_a_zip(tmp_path, capsys):
    bag = _write(tmp_path / "two.bag")
    archive = tmp_path / "two.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.write(bag, "inner/two.bag")
    code, out, err = run_cli(capsys, "info", str(archive), "--json", "--body-scans", "0")
    assert code == 0, err
    data = json.loads(out)
    assert data["format"] == "zip" and data["origin"] == str(archive)
    assert data["scans"]["/front_scan"]["scans"] == 40 and data["scans"]["/rear_scan"]["scans"] == 25


def test_info_bag_overview_skips_a_malformed_message_only_with_skip_bad(tmp_path, capsys):
    bag = tmp_path / "bad.mcap"
    with open_bag_writer(bag) as w:
        for i in range(6):
            w.write("/a", laserscan_message(w, _front(i), i), float(FRONT_T[i]))
            msg = laserscan_message(w, _rear(i), i)
            if i == 3:
                msg.angle_increment = 0.0  # no valid LaserScan: 90 beams over no angle
            w.write("/b", msg, float(REAR_T[i]))
    code, _, err = run_cli(capsys, "info", str(bag), "--body-scans", "0")
    assert code == 2 and "message index 3" in err and "/b" in err and "--skip-bad" in err
    code, out, err = run_cli(capsys, "info", str(bag), "--body-scans", "0", "--skip-bad", "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["scans"]["/a"]["scans"] == 6 and data["scans"]["/b"]["scans"] == 5
    assert data["scans"]["/b"]["extra"] == {"skipped_messages": 1} and data["scans"]["/a"]["extra"] == {}


def test_info_negative_2_describes_its_three_lasers(capsys):
    from conftest import shared_file

    bag = shared_file("dynamic/leg_tracker/negative_2.bag")
    code, out, err = run_cli(capsys, "info", str(bag), "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["run_needs_topic"] == ["/left_scan", "/rear_scan", "/right_scan"]
    assert {t: s["scans"] for t, s in data["scans"].items()} == {"/left_scan": 435, "/rear_scan": 435,
                                                                  "/right_scan": 434}
    assert data["odometry"]["odometry"] == [] and data["odometry"]["imu"] is None  # laser only
    for s in data["scans"].values():
        assert s["beams_max"] == 768 and math.degrees(s["fov"]) == pytest.approx(270.0, abs=0.1)
        assert s["rate_hz"] == pytest.approx(7.51, abs=0.01) and s["range_max"] == 11.0
    # every laser sees part of the robot; the body beams found per topic are those of 'info --topic'
    bodies = {t: s["body"]["auto_body_beams"] for t, s in data["scans"].items()}
    assert bodies == {"/left_scan": 18, "/rear_scan": 46, "/right_scan": 19}
    code, out, err = run_cli(capsys, "info", str(bag), "--topic", "/right_scan", "--json")
    assert code == 0, err
    one = json.loads(out)
    right = data["scans"]["/right_scan"]
    assert one["body"]["suggested_footprint"] == right["body"]["suggested_footprint"]
    assert one["no_return_share"] == right["no_return_share"] and one["max_gap"] == right["max_gap"]
