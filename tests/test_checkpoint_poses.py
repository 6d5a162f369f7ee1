"""The checkpointer's trajectory: every scan's stamp and laser pose, in order, as the run gave them (pass cln113 keeps
them in ``array("d")`` buffers instead of NumPy rows)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dynslam2d.io.checkpoint import Checkpointer
from dynslam2d.io.trajectory import Trajectory, read_tum, write_tum
from dynslam2d.types import Pose2D


def test_checkpoint_trajectory_is_every_scans_pose(tmp_path) -> None:
    rng = np.random.default_rng(3)
    n = 137
    stamps = np.cumsum(rng.uniform(0.02, 0.1, n)) + 1.7e9
    poses = rng.normal(0.0, 30.0, (n, 3))
    poses[:, 2] = rng.uniform(-np.pi, np.pi, n)
    ckpt = Checkpointer(tmp_path / "ckpt", every_s=0.0, every_scans=50)
    for k in range(n):
        # (NumPy scalars as well as floats: the steps give either)
        x = np.float64(poses[k, 0]) if k % 2 else float(poses[k, 0])
        ckpt.on_scan(None, SimpleNamespace(stamp=float(stamps[k]), pose=Pose2D(x, poses[k, 1], poses[k, 2])), None)
    assert ckpt.n_scans == n and ckpt.written == 2  # (at scans 50 and 100)
    ckpt.write()
    got = read_tum(tmp_path / "ckpt" / "trajectory.tum")
    write_tum(tmp_path / "expected.tum", Trajectory(stamps, poses))
    want = read_tum(tmp_path / "expected.tum")
    assert np.array_equal(got.stamps, want.stamps) and np.array_equal(got.poses, want.poses)
    assert got.poses.shape == (n, 3)
