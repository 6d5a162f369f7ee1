"""BagRecorder: a run written as a ROS bag (ROS 2 MCAP / sqlite3, ROS 1), reopened with rosbags."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io.rosout import MARKER_NAMESPACES, TOPICS, BagRecorder, occupancy_data
from dynslam2d.pipeline import run
from dynslam2d.sim.simulation import SimSource

MAP_PERIOD = 1.0
ROS1_MD5 = {
    "/scan": "90c7ef2dc6895d81024acba2ac42f369",
    "/scan_filtered": "90c7ef2dc6895d81024acba2ac42f369",
    "/map": "3381f2d731d4076ec5c71b0759edbe4e",
    "/slam_pose": "d3812c3cbc69362b77dc0b19b345f8f5",
    "/tf": "94810edda583a504dfda3829e70d7eec",
    "/tracks": "d155b9ce5188fbaf89745847fd5882d7",
}
LAYOUTS = {"mcap": ("run.mcap", None), "sqlite3": ("run_db", "sqlite3"), "ros1": ("run.bag", None)}


class _Collect:
    """Keeps every scan, step and the map the pipeline had after each scan."""

    def __init__(self) -> None:
        self.scans, self.steps, self.maps = [], [], []

    def on_scan(self, scan, step, pipeline) -> None:
        self.scans.append(scan)
        self.steps.append(step)
        self.maps.append(pipeline.gridmap())

    def on_finish(self, result, pipeline) -> None:
        self.result = result


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One pipeline run of 5 s of the paper scene, recorded into all three bag layouts at once."""
    out = tmp_path_factory.mktemp("rosout")
    paths = {name: out / fname for name, (fname, _) in LAYOUTS.items()}
    collect = _Collect()
    recorders = [BagRecorder(paths[name], storage=storage, map_period=MAP_PERIOD)
                 for name, (_, storage) in LAYOUTS.items()]
    run(SimSource("paper", duration=5), observers=[collect, *recorders])
    return paths, collect


def _read(path: Path) -> tuple[dict[str, list], dict[str, object]]:
    """topic → [(bag time ns, message)], and topic → connection."""
    msgs: dict[str, list] = {}
    with AnyReader([path]) as reader:
        conns = {c.topic: c for c in reader.connections}
        for conn, t, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return msgs, conns


def _ns(stamp: float) -> int:
    sec = math.floor(stamp)
    return sec * 1_000_000_000 + round((stamp - sec) * 1e9)


def _hdr_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


@pytest.fixture(scope="module", params=list(LAYOUTS))
def bag(request, recorded):
    paths, collect = recorded
    msgs, conns = _read(paths[request.param])
    return request.param, msgs, conns, collect


def _expected_map_indices(stamps: list[float]) -> list[int]:
    """Scan indices at which /map is due with MAP_PERIOD, plus the end (no duplicate)."""
    out, last = [], None
    for i, s in enumerate(stamps):
        if last is None or s - last >= MAP_PERIOD:
            out.append(i)
            last = s
    if out[-1] != len(stamps) - 1:
        out.append(len(stamps) - 1)
    return out


def test_layouts_on_disk(recorded):
    paths, _ = recorded
    assert paths["mcap"].is_file() and paths["mcap"].read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert paths["ros1"].is_file() and paths["ros1"].read_bytes()[:13] == b"#ROSBAG V2.0\n"
    assert (paths["sqlite3"] / "metadata.yaml").is_file() and list(paths["sqlite3"].glob("*.db3"))
    assert not list(paths["mcap"].parent.glob("*.part"))  # no temporary leftovers


def test_types_counts_and_stamps(bag):
    layout, msgs, conns, collect = bag
    n = len(collect.scans)
    assert n == 100
    assert {t: c.msgtype for t, c in conns.items()} == TOPICS
    stamps = [s.stamp for s in collect.scans]
    map_idx = _expected_map_indices(stamps)
    assert 5 <= len(map_idx) <= 7
    for topic in TOPICS:
        want = [stamps[i] for i in map_idx] if topic == "/map" else stamps
        got = msgs[topic]
        assert len(got) == len(want), topic
        assert [t for t, _ in got] == [_ns(s) for s in want], topic  # bag time = scan stamp
        if topic == "/tf":
            assert [_hdr_ns(m.transforms[0].header) for _, m in got] == [_ns(s) for s in want]
        elif topic == "/tracks":
            assert all(_hdr_ns(mk.header) == t for t, m in got for mk in m.markers)
            assert sum(len(m.markers) for _, m in got) > 0
        else:
            assert [_hdr_ns(m.header) for _, m in got] == [_ns(s) for s in want], topic
    # /map is latched: ROS 1 latching=1, ROS 2 offered QoS transient-local.
    ext = conns["/map"].ext
    if layout == "ros1":
        assert ext.latching == 1 and conns["/scan"].ext.latching is None
        # ROS 1 checks types by md5: these are Noetic's own sums (rosbag play / rviz accept them).
        assert {t: c.digest for t, c in conns.items()} == ROS1_MD5
    else:
        assert [q.durability for q in ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        assert conns["/scan"].ext.offered_qos_profiles == []


def test_scan_and_filtered_scan(bag):
    _, msgs, _, collect = bag
    n_removed = 0
    for (_, raw), (_, filt), scan, step in zip(msgs["/scan"], msgs["/scan_filtered"], collect.scans, collect.steps):
        expected = scan.ranges.astype(np.float32)
        np.testing.assert_array_equal(raw.ranges, expected)
        assert raw.header.frame_id == filt.header.frame_id == scan.frame_id == "laser"
        removed = step.removed
        assert np.all(np.isposinf(filt.ranges[removed]))
        np.testing.assert_array_equal(filt.ranges[~removed], expected[~removed])
        assert filt.angle_min == raw.angle_min and filt.angle_increment == raw.angle_increment
        n_removed += int(removed.sum())
    assert n_removed > 100  # the scene has movers in M: the filter must have removed beams


def test_map_messages(bag):
    _, msgs, _, collect = bag
    stamps = [s.stamp for s in collect.scans]
    idx = _expected_map_indices(stamps)
    grids = [collect.maps[i] for i in idx[:-1]] + [collect.result.grid]
    for (_, m), grid in zip(msgs["/map"], grids):
        h, w = grid.shape
        assert m.header.frame_id == "map"
        assert (m.info.width, m.info.height) == (w, h)
        assert m.info.resolution == pytest.approx(grid.resolution, rel=1e-7)
        assert (m.info.origin.position.x, m.info.origin.position.y) == pytest.approx(grid.origin)
        assert m.info.origin.orientation.w == 1.0 and m.info.origin.orientation.z == 0.0
        data = np.asarray(m.data).reshape(h, w)  # row 0 = bottom, as GridMap
        known = np.isfinite(grid.prob)
        assert np.all(data[~known] == -1)
        np.testing.assert_array_equal(data[known], np.rint(100 * grid.prob[known]).astype(np.int8))
    final = np.asarray(msgs["/map"][-1][1].data)
    grid = collect.result.grid
    assert (final == -1).sum() == (~np.isfinite(grid.prob)).sum() > 0
    assert (final >= 90).sum() == (np.nan_to_num(grid.prob) >= 0.895).sum() > 100  # walls
    # cell (row r, col c) of the message is the world point origin + (c + ½, r + ½)·res
    r, c = np.argwhere(final.reshape(grid.shape) >= 90)[0]
    x = grid.origin[0] + (c + 0.5) * grid.resolution
    y = grid.origin[1] + (r + 0.5) * grid.resolution
    assert tuple(grid.world_to_cell(np.array([[x, y]]))[0]) == (c, r)


def test_pose_and_tf(bag):
    _, msgs, _, collect = bag
    for (_, ps), (_, tf), step in zip(msgs["/slam_pose"], msgs["/tf"], collect.steps):
        assert ps.header.frame_id == "map"
        assert (ps.pose.position.x, ps.pose.position.y, ps.pose.position.z) == pytest.approx(
            (step.pose.x, step.pose.y, 0.0), abs=1e-12)
        assert _yaw(ps.pose.orientation) == pytest.approx(step.pose.theta, abs=1e-9)
        assert len(tf.transforms) == 1
        t = tf.transforms[0]
        assert (t.header.frame_id, t.child_frame_id) == ("map", "laser")
        assert (t.transform.translation.x, t.transform.translation.y) == pytest.approx(
            (step.pose.x, step.pose.y), abs=1e-12)
        assert _yaw(t.transform.rotation) == pytest.approx(step.pose.theta, abs=1e-9)
    thetas = [s.pose.theta for s in collect.steps]
    assert max(thetas) - min(thetas) > 0.3  # the robot yaws: rotation is really checked


def test_track_markers(bag):
    _, msgs, _, collect = bag
    live: set[int] = set()
    n_delete = 0
    for (_, arr), step in zip(msgs["/tracks"], collect.steps):
        ids = {t.id for t in step.tracks}
        gone = live - ids
        assert len(arr.markers) == 3 * len(step.tracks) + 3 * len(gone)
        adds = [m for m in arr.markers if m.action == 0]
        deletes = [m for m in arr.markers if m.action == 2]
        assert {(m.ns, m.id) for m in deletes} == {(ns, i) for i in gone for ns in MARKER_NAMESPACES}
        n_delete += len(deletes)
        by_key = {(m.ns, m.id): m for m in adds}
        assert len(by_key) == len(adds)  # (namespace, id) unique
        for t in step.tracks:
            box, text, arrow = by_key[("boxes", t.id)], by_key[("ids", t.id)], by_key[("velocity", t.id)]
            assert box.type == 4 and text.type == 9 and arrow.type == 0
            assert box.header.frame_id == "map"
            pts = np.array([[p.x, p.y] for p in box.points])
            np.testing.assert_allclose(pts[:4], t.box.corners(), atol=1e-12)
            np.testing.assert_allclose(pts[4], pts[0])
            assert text.text == str(t.id)
            assert (text.pose.position.x, text.pose.position.y) == pytest.approx((t.box.px, t.box.py))
            a0, a1 = arrow.points
            assert (a1.x - a0.x, a1.y - a0.y) == pytest.approx(tuple(t.velocity), abs=1e-12)  # 1 s arrow
            assert (box.color.r > box.color.b) == bool(t.in_m)  # red in M, blue otherwise
        live = ids
    assert n_delete >= 3 * 3  # tracks do disappear in this scene, and their markers are deleted
    assert any(t.in_m for s in collect.steps for t in s.tracks)


def test_occupancy_data_values_and_order():
    prob = np.array([[np.nan, 0.0, 0.004], [0.5, 0.996, 1.0]])  # row 0 = bottom
    data = occupancy_data(GridMap(prob, 0.05, (1.0, 2.0)))
    assert data.dtype == np.int8
    assert data.tolist() == [-1, 0, 0, 50, 100, 100]


class _Boom:
    """A source that fails after three scans."""

    def __init__(self) -> None:
        self.inner = SimSource("paper", duration=1)
        self.meta = self.inner.meta

    def __iter__(self):
        for i, scan in enumerate(self.inner):
            if i == 3:
                raise RuntimeError("input broke")
            yield scan

    def __len__(self) -> int:
        return len(self.inner)


@pytest.mark.parametrize("name", ["fail.mcap", "fail_dir", "fail.bag"])
def test_failed_run_leaves_nothing(tmp_path, name):
    out = tmp_path / name
    with pytest.raises(RuntimeError, match="input broke"):
        with BagRecorder(out) as rec:
            run(_Boom(), observers=[rec])
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments(tmp_path):
    with pytest.raises(DynSlamError, match="storage"):
        BagRecorder(tmp_path / "x.bag", storage="mcap")
    with pytest.raises(DynSlamError, match="map period"):
        BagRecorder(tmp_path / "x.mcap", map_period=-1.0)
    assert list(tmp_path.iterdir()) == []


def test_map_only_at_end_and_every_scan(tmp_path):
    src = SimSource("paper", duration=0.5)
    with BagRecorder(tmp_path / "end.mcap", map_period=None) as end, \
            BagRecorder(tmp_path / "all.mcap", map_period=0.0) as every:
        run(src, observers=[end, every])
    assert end.counts["/map"] == 1 and end.counts["/scan"] == len(src)
    assert every.counts["/map"] == len(src)  # the end adds no duplicate of the last scan's map
    msgs, _ = _read(tmp_path / "end.mcap")
    assert msgs["/map"][0][0] == _ns(list(src)[-1].stamp)
