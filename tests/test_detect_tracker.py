"""Tracker behaviour on hand-made scans: a moving box, occlusion, frames, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynslam2d.detect import COASTING, CONFIRMED, DetectConfig, Tracker, TrackerConfig
from dynslam2d.sim import cast_rays, rect_segments
from dynslam2d.types import Pose2D, Scan

N = 720
ANGLES = -math.pi + np.arange(N) * 2 * math.pi / N
ROOM = np.vstack([rect_segments(0.0, 0.0, 0.0, 16.0, 12.0)])


def render(pose: Pose2D, boxes: list[tuple[float, float, float, float, float]], stamp: float,
           noise: float = 0.005, seed: int = 0) -> tuple[Scan, np.ndarray]:
    """A 360° scan from ``pose`` (world frame) of a 16×12 m room plus boxes (x, y, θ, l, w);
    returns the scan and the per-beam labels (0 room, k box k, −1 none)."""
    segs = [ROOM] + [rect_segments(*b[:3], b[3], b[4]) for b in boxes]
    ids = np.concatenate([np.zeros(ROOM.shape[0], dtype=np.int32)] +
                         [np.full(4, k + 1, dtype=np.int32) for k in range(len(boxes))])
    dist, lab = cast_rays((pose.x, pose.y), pose.theta + ANGLES, np.vstack(segs), ids, np.zeros((0, 3)),
                          np.zeros(0, dtype=np.int32))
    rng = np.random.default_rng(seed)
    r = dist + rng.normal(0.0, noise, dist.shape)
    r[~np.isfinite(dist)] = np.inf
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=2 * math.pi / N, ranges=r, range_min=0.1,
                range_max=20.0), lab


def run_box(rate: float = 20.0, duration: float = 4.0, omega: float = 0.0, speed: float = 0.8,
            config: DetectConfig | None = None) -> tuple[Tracker, list, list]:
    """A 0.8×0.5 box driving along +x at ``speed`` past a robot at (0, −2) that yaws at ``omega``."""
    tr = Tracker(config)
    out, labels = [], []
    for i in range(int(duration * rate)):
        t = i / rate
        pose = Pose2D(0.0, -2.0, omega * t)
        scan, lab = render(pose, [(-3.0 + speed * t, 1.5, 0.0, 0.8, 0.5)], t, seed=i)
        out.append(tr.update(scan, pose))
        labels.append(lab)
    return tr, out, labels


def _box_track(tracks: list) -> object:
    near = [t for t in tracks if t.state == CONFIRMED and t.n_points > 0]
    return min(near, key=lambda t: abs(t.box.py - 1.5))


def test_moving_box_is_tracked_with_its_speed_size_and_beams() -> None:
    tr, out, labels = run_box()
    t = _box_track(out[-1])
    true_x = -3.0 + 0.8 * (len(out) - 1) / 20.0
    assert math.hypot(t.box.px - true_x, t.box.py - 1.5) < 0.05
    assert abs(t.speed - 0.8) < 0.1
    assert abs(math.atan2(t.velocity[1], t.velocity[0])) < 0.15
    assert abs(abs(math.cos(t.heading)) - 1.0) < 0.02  # heading along the motion (mod π)
    assert sorted(np.round(t.size, 1)) == [0.5, 0.8]
    assert t.in_m and t.m_reason.startswith("in M")
    assert np.all(labels[-1][t.beams] == 1) and t.n_points == int((labels[-1] == 1).sum())
    assert t.covariance.shape == (4, 4) and np.all(np.linalg.eigvalsh(t.covariance) > 0)
    # the walls never enter M and ids of the box never change once confirmed
    ids = {_box_track(ts).id for ts in out[20:]}
    assert len(ids) == 1
    assert not any(tt.in_m for ts, lab in zip(out, labels) for tt in ts
                   if tt.n_points and np.mean(lab[tt.beams] == 0) > 0.5)


def test_rotating_robot_does_not_make_walls_move() -> None:
    """1 rad/s yaw in a static room: tracks in the map frame stay still; none enters M."""
    tr = Tracker()
    for i in range(80):
        t = i / 20.0
        pose = Pose2D(0.3 * math.sin(t), -2.0, 1.0 * t)
        scan, _ = render(pose, [(2.0, 1.0, 0.3, 0.6, 0.6)], t, seed=i)
        tracks = tr.update(scan, pose)
        assert not any(k.in_m for k in tracks)
    pillar = min(tracks, key=lambda k: math.hypot(k.box.px - 2.0, k.box.py - 1.0))
    assert math.hypot(pillar.box.px - 2.0, pillar.box.py - 1.0) < 0.05 and pillar.speed < 0.2


def test_same_scans_in_the_sensor_frame_would_fail() -> None:
    """Control for the test above: feeding identity poses (tracking in the sensor frame) while the
    robot yaws makes the static pillar appear to move fast."""
    tr = Tracker()
    speeds = []
    for i in range(40):
        t = i / 20.0
        scan, _ = render(Pose2D(0.0, -2.0, 1.0 * t), [(2.0, 1.0, 0.3, 0.6, 0.6)], t, seed=i)
        tracks = tr.update(scan, Pose2D())
        speeds += [k.speed for k in tracks if k.state == CONFIRMED]
    assert max(speeds) > 1.0


def test_short_occlusion_keeps_the_id() -> None:
    tr = Tracker()
    ids = []
    for i in range(60):
        t = i / 20.0
        pose = Pose2D(0.0, -2.0, 0.0)
        boxes = [(-2.0 + 0.8 * t, 1.5, 0.0, 0.8, 0.5)]
        scan, lab = render(pose, boxes, t, seed=i)
        if 30 <= i < 36:  # 0.3 s without the box (e.g. occluded): blank its beams
            scan = scan.with_ranges(np.where(lab == 1, np.inf, scan.ranges))
        tracks = tr.update(scan, pose)
        if 30 <= i < 36:
            box = [k for k in tracks if abs(k.box.py - 1.5) < 0.3]
            assert box and box[0].state == COASTING and box[0].n_points == 0
        elif i >= 20:
            ids.append(_box_track(tracks).id)
    assert len(set(ids)) == 1


def test_coasting_track_is_deleted_after_max_coast_time() -> None:
    tr = Tracker(DetectConfig(tracker=TrackerConfig(max_coast_time=0.2)))
    pose = Pose2D(0.0, -2.0, 0.0)
    for i in range(20):
        scan, _ = render(pose, [(-2.0 + 0.8 * i / 20, 1.5, 0.0, 0.8, 0.5)], i / 20, seed=i)
        tr.update(scan, pose)
    before = tr.stats.deleted_coasting
    for i in range(20, 30):
        scan, _ = render(pose, [], i / 20, seed=i)
        tracks = tr.update(scan, pose)
    assert not [k for k in tracks if abs(k.box.py - 1.5) < 0.3]
    assert tr.stats.deleted_coasting > before


def test_bad_input_is_counted_not_raised() -> None:
    tr = Tracker()
    pose = Pose2D(0.0, -2.0, 0.0)
    for i in range(10):
        scan, _ = render(pose, [(-2.0 + 0.08 * i, 1.5, 0.0, 0.8, 0.5)], i / 20, seed=i)
        tr.update(scan, pose)
    assert tr.n_tracks > 0
    empty = scan.with_ranges(np.full(N, np.inf), stamp=0.55)
    assert tr.update(empty, pose) is not None and tr.stats.empty_scans == 1
    nan_scan = scan.with_ranges(np.full(N, np.nan), stamp=0.6)
    tr.update(nan_scan, pose)
    assert tr.stats.empty_scans == 2
    tr.update(scan.with_ranges(scan.ranges, stamp=0.65), Pose2D(math.nan, 0.0, 0.0))
    assert tr.stats.skipped_nonfinite_pose == 1
    n_before = tr.n_tracks
    assert n_before > 0
    tr.update(scan.with_ranges(scan.ranges, stamp=0.7), Pose2D(5.0, -2.0, 0.0))  # 5 m in 0.1 s
    assert tr.stats.pose_jumps == 1
    tr.update(scan.with_ranges(scan.ranges, stamp=0.1), Pose2D(5.0, -2.0, 0.0))  # time goes backwards
    assert tr.stats.time_resets == 1
    tr.update(scan.with_ranges(scan.ranges, stamp=10.0), Pose2D(5.0, -2.0, 0.0))  # long gap
    assert tr.stats.time_resets == 2


def test_covariance_blow_up_deletes_the_track() -> None:
    tr = Tracker(DetectConfig(tracker=TrackerConfig(max_position_sigma=0.05, max_coast_time=5.0)))
    pose = Pose2D(0.0, -2.0, 0.0)
    for i in range(20):
        scan, _ = render(pose, [(-2.0 + 0.04 * i, 1.5, 0.0, 0.8, 0.5)], i / 20, seed=i)
        tr.update(scan, pose)
    for i in range(20, 40):
        scan, _ = render(pose, [], i / 20, seed=i)
        tracks = tr.update(scan, pose)
    assert tr.stats.deleted_covariance >= 1
    assert all(np.all(np.isfinite(k.covariance)) for k in tracks)


@pytest.mark.parametrize("rate", [8.0, 20.0])
def test_real_dt_is_used(rate: float) -> None:
    """Speed is right whatever the scan rate (datmo hard-codes dt = 0.08 s)."""
    _, out, _ = run_box(rate=rate, duration=4.0, speed=1.0)
    assert abs(_box_track(out[-1]).speed - 1.0) < 0.1


def test_config_validation_and_round_trip() -> None:
    from pydantic import ValidationError

    cfg = DetectConfig()
    assert DetectConfig.model_validate(cfg.model_dump(mode="json")) == cfg
    with pytest.raises(ValidationError):
        DetectConfig.model_validate({"segment": {"d_min": 0.5, "d_max": 0.2}})
    with pytest.raises(ValidationError):
        DetectConfig.model_validate({"tracker": {"confirm_hits": 5, "confirm_window": 3}})
    with pytest.raises(ValidationError):
        DetectConfig.model_validate({"tracker": {"no_such_field": 1}})
