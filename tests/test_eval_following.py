"""Tracks in M that follow the sensor (the robot's own body taken for a mover)."""

from __future__ import annotations

import numpy as np

from dynslam2d.eval.following import tracks_following_sensor
from dynslam2d.io.runfolder import TRACK_DTYPE


def test_only_m_tracks_that_stay_by_the_laser_follow_it():
    stamps = np.arange(20) * 0.1
    poses = np.column_stack((stamps * 1.0, np.zeros(20), np.zeros(20)))  # laser driving at 1 m/s
    rows = []
    for i, t in enumerate(stamps):
        x = poses[i, 0]
        rows.append((t, 1, "confirmed", x - 0.2, 0.1, 0, 0.2, 0.2, 1.0, 0, True))   # rides along: follows
        rows.append((t, 2, "confirmed", 5.0, 2.0, 0, 0.4, 0.4, 0.0, 0, True))       # far away
        rows.append((t, 3, "confirmed", x + 0.1, 0.0, 0, 0.2, 0.2, 1.0, 0, False))  # rides along, never in M
        # passes by the laser once (close for 3 of 20 scans): the median keeps it out
        rows.append((t, 4, "confirmed", 1.0 + (i - 10) * 0.3 if i else 9.0, 0.3, 0, 0.4, 0.4, 3.0, 0, True))
    tracks = np.array(rows, dtype=TRACK_DTYPE)
    assert tracks_following_sensor(tracks, stamps, poses) == [1]
    assert tracks_following_sensor(tracks, stamps, poses, radius=0.1) == []
    assert tracks_following_sensor(tracks[:0], stamps, poses) == []
