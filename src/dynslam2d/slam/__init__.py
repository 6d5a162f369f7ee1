"""Hector-style SLAM core: growable multi-resolution log-odds grids, Gauss–Newton /
Levenberg–Marquardt scan-to-map matching with a correlative-search seed, and the per-scan
processor. It follows hector_mapping (Kohlbrecher et al., "A Flexible and Scalable SLAM System with
Full 3D Motion Estimation", SSRR 2011; tu-darmstadt-ros-pkg/hector_slam);
docs/slam.md lists where it differs."""

from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.grid import GridLevel, MultiResMap
from dynslam2d.slam.processor import HectorSlam, MatchResult, SlamStep

__all__ = ["GridLevel", "HectorSlam", "MatchResult", "MultiResMap", "SlamConfig", "SlamStep"]
