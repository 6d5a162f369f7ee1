"""Tracks that follow the sensor: the robot's own body (or something it carries) taken for a mover.

Issue 9's target on a robot driving through an empty room is "no track in M that
follows the robot". A track *follows the sensor* when, over the scans where it is in
M, its centre stays within ``radius`` (default 0.5 m) of the laser: the median
distance between the track centre (tracks.csv, map frame) and the laser position
(trajectory.tum, same stamp) is at most ``radius``. People walking beside the robot
keep more than half a metre; returns from the robot's body lie at 0.1–0.3 m.
"""

from __future__ import annotations

import numpy as np

#: Default distance from the laser within which an M track counts as following it, m.
FOLLOW_RADIUS = 0.5


def tracks_following_sensor(tracks: np.ndarray, traj_stamps: np.ndarray, traj_poses: np.ndarray,
                            radius: float = FOLLOW_RADIUS) -> list[int]:
    """Ids of tracks in M whose centre stays (median over their in-M scans) within ``radius`` m
    of the laser.

    Args:
        tracks: tracks.csv rows (:data:`dynslam2d.io.runfolder.TRACK_DTYPE`).
        traj_stamps, traj_poses: the run's laser poses, (k,) s and (k, 3) x, y, yaw (map frame).
    """
    in_m = tracks[tracks["in_M"]] if tracks.shape[0] else tracks
    if in_m.shape[0] == 0 or len(traj_stamps) == 0:
        return []
    st = np.asarray(traj_stamps, dtype=np.float64)
    order = np.argsort(st, kind="stable")
    srt = st[order]
    pos = np.clip(np.searchsorted(srt, in_m["stamp"]), 0, srt.shape[0] - 1)
    left = np.clip(pos - 1, 0, None)
    pos = np.where(np.abs(srt[left] - in_m["stamp"]) < np.abs(srt[pos] - in_m["stamp"]), left, pos)
    ok = np.abs(srt[pos] - in_m["stamp"]) <= 1e-6
    laser = np.asarray(traj_poses, dtype=np.float64)[order[pos]]
    dist = np.where(ok, np.hypot(in_m["x"] - laser[:, 0], in_m["y"] - laser[:, 1]), np.nan)
    out = []
    for tid in np.unique(in_m["id"]):
        d = dist[(in_m["id"] == tid) & ok]
        if d.shape[0] and float(np.median(d)) <= radius:
            out.append(int(tid))
    return out


__all__ = ["FOLLOW_RADIUS", "tracks_following_sensor"]
