"""dynslam2d: 2D LiDAR SLAM for scenes that move.

Detects and tracks moving objects from the scans alone, removes their points and
maps the rest with Hector-style SLAM. See the README for the command line.
"""

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceMeta

__all__ = ["DynSlamError", "Pose2D", "Scan", "ScanSource", "SourceMeta", "__version__"]
__version__ = "0.1.0"
