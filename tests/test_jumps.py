"""Front-end jumps (slam/jumps.py): flagged in the pose confidence, and the keyframe edge across them weakened so
loops undo the drift before them (docs/slam.md, "negative_2: the stretch that maps walls twice")."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam.confidence import summarize
from dynslam2d.slam.jumps import JumpCheck, jump_flags, model_excess, step_excess


def _drive(n: int = 120, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A robot on a circle of 3 m at 0.75 m/s, scans at 7.5 Hz, 5 mm / 0.2° pose noise: (stamps s, poses (n, 3))."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 7.5
    a = 0.25 * t
    poses = np.column_stack((3 * np.cos(a), 3 * np.sin(a), a + math.pi / 2))
    poses[:, :2] += rng.normal(0, 0.005, (n, 2))
    poses[:, 2] += rng.normal(0, math.radians(0.2), n)
    return t, poses


def _snap(poses: np.ndarray, start: int, end: int, offset: tuple[float, float, float]) -> np.ndarray:
    """``poses`` drifting linearly by up to ``offset`` (m, m, rad) over scans ``start`` … ``end``-1 and snapping
    back at scan ``end``: a front end that followed its own map and then saw the old one again."""
    w = np.clip((np.arange(len(poses)) - start) / float(end - start), 0.0, 1.0)
    w[end:] = 0.0
    return poses + w[:, None] * np.asarray(offset)


def _velocity_alone(t: np.ndarray, poses: np.ndarray) -> int:
    """How many steps the constant-velocity prediction alone (the rule before the constant-step one) flags at
    0.25 m and 3 predicted steps."""
    shift, _, expected = model_excess(t, poses)["velocity"]
    return int(((shift >= 0.25) & (shift >= 3.0 * expected)).sum())


def test_only_the_snap_back_is_a_jump() -> None:
    """A front end drifting by up to 0.5 m and 8° over scans 40–79 and snapping back at scan 80: the drift itself
    (smooth) is no jump, the snap is, and nothing else is; the one-scan-at-a-time check gives the same flags."""
    t, poses = _drive()
    drifted = _snap(poses, 40, 80, (0.4, 0.3, math.radians(8.0)))
    flag, shift, turn = jump_flags(t, drifted, 0.25, 3.0)
    assert np.flatnonzero(flag).tolist() == [80]
    assert 0.45 < shift[80] < 0.55 and math.degrees(turn[80]) > 7.0
    assert shift[np.arange(len(t)) != 80].max() < 0.05
    check = JumpCheck(0.25, 3.0)
    online = [check.update(float(s), *map(float, p)) for s, p in zip(t, drifted)]
    assert online == flag.tolist()
    # without the snap (the smooth truth) nothing is flagged
    assert not jump_flags(t, poses, 0.25, 3.0)[0].any()
    # the snap is 5 steps of 0.1 m: with a bound of 6 steps it is taken as motion; a rotation bound alone finds it
    assert not jump_flags(t, drifted, 0.25, 6.0)[0].any()
    assert np.flatnonzero(jump_flags(t, drifted, 0.0, 0.0, math.radians(6.0))[0]).tolist() == [80]
    # a gap of 0.9 s between scans at the same speed is no jump either: the prediction scales with the time step
    # (the excess left, 0.15 m, is the circle's curvature over 0.7 m of path)
    keep = np.r_[0:60, 67:len(t)]
    excess = step_excess(t[keep], poses[keep])[0]
    assert excess.max() < 0.2 and excess[60] > 0.1


def test_a_jump_makes_the_run_untrustworthy() -> None:
    t, poses = _drive()
    poses[60:, 0] += 0.5
    n = len(t)
    flags = {"low_support": np.zeros(n, bool), "degenerate": np.zeros(n, bool), "lost": np.zeros(n, bool)}
    out = summarize(t, flags, np.full(n, 0.5), 0, 0, 0.05, 2.0, jump_flags(t, poses, 0.25, 3.0))
    assert out["jumps"] == 1 and out["trustworthy"] is False and "jumped" in str(out["warning"])
    assert abs(out["jump_stamps_s"][0] - t[60]) < 1e-9 and 0.45 < out["largest_jump_m"] < 0.55
    clean = summarize(t, flags, np.full(n, 0.5), 0, 0, 0.05, 2.0, jump_flags(t, _drive()[1], 0.25, 3.0))
    assert clean["jumps"] == 0 and clean["trustworthy"] is True


def _logged(n: int = 200, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A log sub-sampled by distance whose stamps do not follow the motion (as Intel's ``intel-lab.flirtlib.log``):
    a robot on a circle of 4 m, one scan per 0.15 m of path (0.3 m where a scan was dropped, one step in ten),
    5 mm / 0.2° pose noise; time steps of 3 ms (10 %), 0.3–1.0 s (80 %) or 2–3 s (10 %) whatever the step:
    (stamps s, poses (n, 3))."""
    rng = np.random.default_rng(seed)
    steps = np.full(n - 1, 0.15)
    steps[rng.choice(n - 1, n // 10, replace=False)] = 0.3
    a = np.r_[0.0, np.cumsum(steps)] / 4.0
    poses = np.column_stack((4 * np.sin(a), 4 * (1 - np.cos(a)), a))
    poses[:, :2] += rng.normal(0, 0.005, (n, 2))
    poses[:, 2] += rng.normal(0, math.radians(0.2), n)
    kind = rng.random(n - 1)
    dt = np.where(kind < 0.1, 0.003, np.where(kind < 0.9, rng.uniform(0.3, 1.0, n - 1), rng.uniform(2.0, 3.0, n - 1)))
    return np.r_[0.0, np.cumsum(dt)], poses


def test_irregular_stamps_no_false_jump_and_the_snap_back_kept() -> None:
    """Stamps that do not follow the motion: the constant-velocity prediction alone (the rule before) flags steps
    the robot made (a 0.15 m step 3 ms after a scan), the two predictions together flag none; a drift of 0.57 m
    and 8° over scans 100–139 snapping back at scan 140 is still the one jump, online as on the trajectory."""
    t, poses = _logged()
    assert _velocity_alone(t, poses) >= 3
    flag, shift, _ = jump_flags(t, poses, 0.25, 3.0)
    assert not flag.any() and shift.max() < 0.2
    drifted = _snap(poses, 100, 140, (0.45, 0.35, math.radians(8.0)))
    flag, shift, turn = jump_flags(t, drifted, 0.25, 3.0)
    assert np.flatnonzero(flag).tolist() == [140]
    assert 0.45 < shift[140] < 0.65 and math.degrees(turn[140]) > 7.0
    check = JumpCheck(0.25, 3.0)
    assert [check.update(float(s), *map(float, p)) for s, p in zip(t, drifted)] == flag.tolist()


def test_largest_jump_is_one_jump() -> None:
    """Two jumps, the larger shift with the smaller turn: ``largest_jump_m`` / ``_deg`` / ``_s`` and the warning
    all describe the jump with the larger shift (before, ``largest_jump_deg`` was the other jump's turn)."""
    t, poses = _drive()
    poses[40:, 0] += 0.6
    poses[40:, 2] += math.radians(3.0)
    poses[90:, 1] += 0.35
    poses[90:, 2] += math.radians(20.0)
    n = len(t)
    flags = {"low_support": np.zeros(n, bool), "degenerate": np.zeros(n, bool), "lost": np.zeros(n, bool)}
    jumps = jump_flags(t, poses, 0.25, 3.0)
    assert np.flatnonzero(jumps[0]).tolist() == [40, 90]
    out = summarize(t, flags, np.full(n, 0.5), 0, 0, 0.05, 2.0, jumps)
    assert 0.55 < out["largest_jump_m"] < 0.65 and 2.0 < out["largest_jump_deg"] < 4.0
    assert abs(out["largest_jump_s"] - t[40]) < 1e-3
    assert (f"largest {out['largest_jump_m']:.2f} m / {out['largest_jump_deg']:.1f}° beyond the motion before it, "
            f"at {t[40]:.1f} s") in str(out["warning"])


def test_carmen_corrected_poses_irregular_stamps() -> None:
    """The robot's own motion (the logs' corrected poses) with the logs' stamps: on Intel's
    ``intel-lab.flirtlib.log`` (steps of ~0.17 m whose stamps are 3 ms to seconds apart) the constant-velocity
    prediction alone flags 43 steps, both predictions together 16; on fr079 (a steady 0.24 s) both flag its
    1 (docs/slam.md, "Intel, Freiburg 079 and ACES")."""
    from conftest import shared_file

    from dynslam2d.io.carmen import CarmenSource

    for log, before, after in (("intel/intel-lab.flirtlib.log", 43, 16), ("fr079/freiburg-079-corrected.log.gz", 1, 1)):
        recs = list(CarmenSource(shared_file(log)).records())
        t = np.array([r.scan.stamp for r in recs])
        p = np.array([[r.laser_pose.x, r.laser_pose.y, r.laser_pose.theta] for r in recs])
        assert _velocity_alone(t, p) == before, log
        assert int(jump_flags(t, p, 0.25, 3.0)[0].sum()) == after, log


def _icp_shift(src: np.ndarray, dst: np.ndarray, at: np.ndarray) -> float:
    """How far the 2D point-to-point ICP registering ``src`` onto ``dst`` ((n, 2), m; SVD step of Arun, Huang &
    Blostein, IEEE TPAMI 1987; pairs beyond 0.3 m left out; 30 iterations) moves the point ``at``, m."""
    from scipy.spatial import cKDTree

    tree = cKDTree(dst)
    R, tr = np.eye(2), np.zeros(2)
    for _ in range(30):
        p = src @ R.T + tr
        d, i = tree.query(p)
        m = d < 0.3
        assert m.sum() >= 20
        a, b = p[m], dst[i[m]]
        ac, bc = a.mean(0), b.mean(0)
        u, _s, vt = np.linalg.svd((a - ac).T @ (b - bc))
        ri = vt.T @ np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
        R, tr = ri @ R, ri @ tr + bc - ri @ ac
    return float(np.hypot(*(R @ at + tr - at)))


def test_negative_2_jump_flagged_and_the_drift_before_it_undone() -> None:
    """leg_tracker negative_2.bag, /right_scan (laser only): the front end drifts over keyframes ~165–204 (scans
    ~330–403) and snaps back by 0.55 m and 10° at scan 404 (53.8 s). The summary flags that one jump (computed
    from the front end: whatever the loop settings), and with the edge across it weak (``loop.jump_weak``, off by
    default) the loops to the start pull the drifted keyframes back: registered onto the scans of keyframes 0–24,
    keyframes 187–202 move by at most 0.15 m (0.36–0.61 m with ``loop.jump_weak: false``)."""
    from conftest import shared_file

    from dynslam2d.config import Config, with_assignments
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run

    src = open_source(shared_file("dynamic/leg_tracker/negative_2.bag"), "/right_scan")
    cfg = with_assignments(Config(), ["loop.jump_weak=true"])
    result = run(src, cfg)
    pc = result.pose_confidence()
    assert pc["jumps"] == 1 and abs(pc["jump_stamps_s"][0] - 53.8) < 0.2 and pc["largest_jump_m"] > 0.4
    assert pc["trustworthy"] is False
    loop = result.loop
    assert loop is not None and loop.corrected
    sc = cfg.slam

    def world(k: int) -> np.ndarray:
        s = loop.keyframes[k].kept()
        r = s.ranges
        ok = s.valid_mask() & (r > sc.laser_min_dist) & (r < sc.laser_max_dist)
        ca, sa = s.trig()
        x, y, th = loop.node_poses[k]
        lx, ly = r[ok] * ca[ok], r[ok] * sa[ok]
        return np.column_stack((x + math.cos(th) * lx - math.sin(th) * ly, y + math.sin(th) * lx + math.cos(th) * ly))

    ref = np.vstack([world(k) for k in range(25)])
    shifts = [_icp_shift(world(k), ref, loop.node_poses[k, :2]) for k in range(187, 203, 3)]
    assert max(shifts) <= 0.15, shifts


def test_map_png_marks_the_jump(tmp_path) -> None:
    """map.png draws a cross in style.JUMP at each flagged pose (the terminal's warning says map.png marks the
    poses): the jump colour covers pixels with the flags and none without."""
    from PIL import Image

    from dynslam2d.gridmap import GridMap
    from dynslam2d.viz import style
    from dynslam2d.viz.mapplot import plot_map

    t, poses = _drive()
    drifted = _snap(poses, 40, 80, (0.4, 0.3, math.radians(8.0)))
    flag = jump_flags(t, drifted, 0.25, 3.0)[0]
    grid = GridMap(np.full((160, 160), 0.5), 0.05, (-4.0, -4.0))
    colour = np.array(style.rgb255(style.JUMP))

    def jump_pixels(jumps: np.ndarray | None) -> int:
        path = plot_map(tmp_path / "map.png", grid, drifted[:, :2], jumps=jumps)
        img = np.asarray(Image.open(path).convert("RGB")).astype(int)
        return int((np.abs(img - colour).max(axis=2) <= 2).sum())

    assert jump_pixels(flag) > 40
    assert jump_pixels(None) == 0 and jump_pixels(np.zeros_like(flag)) == 0
