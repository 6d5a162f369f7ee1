"""Hector-style SLAM core: growable multi-resolution log-odds grids, Gauss–Newton /
Levenberg–Marquardt scan-to-map matching with a correlative-search seed, and the per-scan
processor. See ``/work/shared/reference/hector_slam.md`` for the reference it follows."""

from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.grid import GridLevel, MultiResMap
from dynslam2d.slam.processor import HectorSlam, MatchResult, SlamStep

__all__ = ["GridLevel", "HectorSlam", "MatchResult", "MultiResMap", "SlamConfig", "SlamStep"]
