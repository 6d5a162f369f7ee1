"""The direct ROS 1 LaserScan decoder (io/rosraw.py) gives the scans rosbags' generic deserializer gives."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import shared_file

import dynslam2d.io.rosbag as rb
from dynslam2d.io.rosraw import LASERSCAN_MD5, is_ros1_laserscan, laserscan_ros1
from dynslam2d.sim import simulate
from dynslam2d.sim.export import write_simulation

FIELDS = ("stamp", "angle_min", "angle_increment", "range_min", "range_max", "frame_id", "angle_max",
          "time_increment", "scan_time")


def _generic_scans(path, topic, monkeypatch):
    """The scans of ``path`` read with rosbags' deserializer only (the direct decoder switched off)."""
    with monkeypatch.context() as m:
        m.setattr(rb, "laserscan_ros1", lambda raw: None)
        return list(rb.RosbagSource(path, topic))


def _same_bits(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def _assert_identical(direct, generic):
    assert len(direct) == len(generic) > 0
    for a, b in zip(direct, generic):
        for name in FIELDS:
            va, vb = getattr(a, name), getattr(b, name)
            assert type(va) is type(vb), name
            assert va == vb if isinstance(va, str) else _same_bits(va, vb), (name, va, vb)
        assert a.ranges.dtype == b.ranges.dtype == np.float64
        assert a.ranges.tobytes() == b.ranges.tobytes()  # bit for bit, NaN and inf included
        assert (a.intensities is None) == (b.intensities is None)
        if a.intensities is not None:
            assert a.intensities.tobytes() == b.intensities.tobytes()


def _count_direct(path, topic, monkeypatch):
    """How many messages the direct decoder decoded while reading ``path``."""
    calls = []

    def counting(raw):
        out = laserscan_ros1(raw)
        calls.append(out is not None)
        return out

    with monkeypatch.context() as m:
        m.setattr(rb, "laserscan_ros1", counting)
        n = len(list(rb.RosbagSource(path, topic)))
    return n, sum(calls)


@pytest.mark.parametrize("rel,topic", [
    ("dynamic/leg_tracker/negative_2.bag", "/right_scan"),
    ("dynamic/leg_tracker/positive_1.bag", None),
    ("dynamic/datmo/overtakes.bag", None),
])
def test_real_bags_decode_as_rosbags_does(rel, topic, monkeypatch):
    path = shared_file(rel)
    direct = list(rb.RosbagSource(path, topic))
    _assert_identical(direct, _generic_scans(path, topic, monkeypatch))
    n, fast = _count_direct(path, topic, monkeypatch)
    assert fast == n  # every scan of a real ROS 1 bag took the direct path


def test_simulator_ros1_bag_decodes_as_rosbags_does(tmp_path, monkeypatch):
    sim = simulate("paper", duration=2.0)
    path = write_simulation(sim, tmp_path, map_resolution=0.1, storage="ros1")["scans"]
    direct = list(rb.RosbagSource(path))
    _assert_identical(direct, _generic_scans(path, None, monkeypatch))
    n, fast = _count_direct(path, None, monkeypatch)
    assert n == len(sim.scans) and fast == n
    # and they are the simulated scans, rounded to float32 as a bag stores them
    for a, s in zip(direct, sim.scans):
        assert a.ranges.tobytes() == s.ranges.astype(np.float32).astype(np.float64).tobytes()


def test_ros2_bags_keep_the_generic_decoder(tmp_path, monkeypatch):
    sim = simulate("paper", duration=1.0)
    path = write_simulation(sim, tmp_path, map_resolution=0.1, storage="mcap")["scans"]
    n, fast = _count_direct(path, None, monkeypatch)
    assert n == len(sim.scans) and fast == 0


def _one_raw_message(path):
    with rb._open_bag(path) as (reader, _):
        conns = reader.topics[rb.RosbagSource(path).topic].connections
        assert all(is_ros1_laserscan(c) for c in conns) and conns[0].digest == LASERSCAN_MD5
        _, _, raw = next(reader.messages(connections=conns))
        return bytes(raw), reader.deserialize(raw, rb.LASERSCAN)


def test_cut_or_padded_message_is_left_to_rosbags(tmp_path):
    sim = simulate("paper", duration=0.5)
    path = write_simulation(sim, tmp_path, map_resolution=0.1, storage="ros1")["scans"]
    raw, msg = _one_raw_message(path)
    got = laserscan_ros1(raw)
    assert got is not None
    assert (got.sec, got.nanosec, got.frame_id) == (msg.header.stamp.sec, msg.header.stamp.nanosec,
                                                    msg.header.frame_id)
    assert got.ranges.tobytes() == msg.ranges.tobytes() and got.scan_time == msg.scan_time
    assert laserscan_ros1(raw[:-1]) is None
    assert laserscan_ros1(raw + b"\0") is None
    assert laserscan_ros1(raw[:30]) is None
