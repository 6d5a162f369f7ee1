"""dynslam2d: 2D LiDAR SLAM for scenes that move.

Detects and tracks moving objects from the scans alone, removes their points and
maps the rest with Hector-style SLAM. See the README for the command line.
"""

from dynslam2d.jitcache import use_default_cache_dir

use_default_cache_dir()  # before any kernel module imports numba: a cache that survives reinstalls

from dynslam2d.errors import DynSlamError  # noqa: E402
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceMeta  # noqa: E402

__all__ = ["DynSlamError", "Pose2D", "Scan", "ScanSource", "SourceMeta", "__version__"]
__version__ = "0.1.0"
