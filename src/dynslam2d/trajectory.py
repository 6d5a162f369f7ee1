"""Planar trajectories in memory.

A :class:`Trajectory` is a time-stamped sequence of 2D poses: stamps in s, poses
``[x, y, yaw]`` in m and rad, each the laser's pose in ``frame`` (the map frame
unless said otherwise; docs/architecture.md "Conventions"). A core value type:
the pipeline returns one, the metrics read them; reading and writing them as TUM
files is :mod:`dynslam2d.io.trajectory`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, wrap_angle


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A planar trajectory: ``n`` stamped poses.

    Attributes:
        stamps: (n,) float64 times, s (Unix time for real logs). Kept in the order
            given; readers and metrics do not require them to be sorted.
        poses: (n, 3) float64 ``[x, y, yaw]``: position in m, heading in rad, of
            the laser in ``frame``.
        frame: name of the frame the poses are expressed in ("map").
    """

    stamps: np.ndarray
    poses: np.ndarray
    frame: str = "map"

    def __post_init__(self) -> None:
        stamps = np.ascontiguousarray(self.stamps, dtype=np.float64)
        poses = np.ascontiguousarray(self.poses, dtype=np.float64)
        if stamps.ndim != 1:
            raise DynSlamError(f"trajectory: stamps must be 1-D, got shape {stamps.shape}")
        if poses.size == 0 and stamps.shape[0] == 0:
            poses = poses.reshape(0, 3)
        if poses.ndim != 2 or poses.shape[1] != 3:
            raise DynSlamError(f"trajectory: poses must have shape (n, 3) [x, y, yaw], got {poses.shape}")
        if poses.shape[0] != stamps.shape[0]:
            raise DynSlamError(
                f"trajectory: {stamps.shape[0]} stamps for {poses.shape[0]} poses"
            )
        if not np.all(np.isfinite(stamps)):
            i = int(np.flatnonzero(~np.isfinite(stamps))[0])
            raise DynSlamError(f"trajectory: stamp of pose {i} is not finite ({stamps[i]})")
        if not np.all(np.isfinite(poses)):
            i = int(np.flatnonzero(~np.all(np.isfinite(poses), axis=1))[0])
            raise DynSlamError(f"trajectory: pose {i} is not finite ({poses[i].tolist()})")
        object.__setattr__(self, "stamps", stamps)
        object.__setattr__(self, "poses", poses)

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    def pose(self, i: int) -> Pose2D:
        """Pose ``i`` as a :class:`Pose2D` (m, m, rad)."""
        return Pose2D.from_array(self.poses[i])

    @property
    def xy(self) -> np.ndarray:
        """(n, 2) positions, m (a view)."""
        return self.poses[:, :2]

    @property
    def yaw(self) -> np.ndarray:
        """(n,) headings, rad (a view)."""
        return self.poses[:, 2]

    def subset(self, indices: np.ndarray | Sequence[int]) -> Trajectory:
        """The poses at ``indices`` (any integer index array), same frame."""
        idx = np.asarray(indices, dtype=np.intp)
        return Trajectory(self.stamps[idx], self.poses[idx], self.frame)

    @classmethod
    def from_poses(
        cls, stamps: Sequence[float] | np.ndarray, poses: Sequence[Pose2D], frame: str = "map"
    ) -> Trajectory:
        """Build from stamps (s) and a list of :class:`Pose2D`."""
        arr = np.array([(p.x, p.y, p.theta) for p in poses], dtype=np.float64).reshape(-1, 3)
        return cls(np.asarray(stamps, dtype=np.float64), arr, frame)

    def same_as(self, other: Trajectory, atol: float = 0.0) -> bool:
        """Equal stamps and poses within ``atol`` (yaw compared modulo 2π), same frame."""
        if len(self) != len(other) or self.frame != other.frame:
            return False
        dyaw = np.abs(wrap_angle(self.yaw - other.yaw))
        return bool(
            np.all(np.abs(self.stamps - other.stamps) <= atol)
            and np.all(np.abs(self.xy - other.xy) <= atol)
            and np.all(dyaw <= atol)
        )
