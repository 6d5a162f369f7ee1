"""Detection and tracking of moving objects from 2D scans, in the map frame.

Quick use::

    from dynslam2d.detect import Tracker, DetectConfig
    tracker = Tracker(DetectConfig())
    for scan, pose in zip(scans, poses):          # pose: laser pose of that scan, map frame
        tracks = tracker.update(scan, pose)
        movers = [t for t in tracks if t.in_m]    # the dynamic set M (paper Eq. 3)
        beams = [t.beams for t in movers]         # scan beams to filter out

Modules: :mod:`~dynslam2d.detect.segment` (breakpoint segmentation, paper Eq. 1),
:mod:`~dynslam2d.detect.shapes` (rectangle / circle fits, paper Eq. 2),
:mod:`~dynslam2d.detect.measure` (the detection and measurement types),
:mod:`~dynslam2d.detect.reference` (which sides of a cluster are real → centre measurement, as readable
per-detection Python: the reference the kernels are tested against, not public API),
:mod:`~dynslam2d.detect.tracker` (Kalman tracking, track management, set M),
:mod:`~dynslam2d.detect.kernels` (the tracker's per-scan numba batches),
:mod:`~dynslam2d.detect.layout` (names of the kernels' packed array columns and kind codes),
:mod:`~dynslam2d.detect.config` (parameters).
"""

from dynslam2d.detect.config import DetectConfig, FitConfig, SegmentConfig, TrackerConfig
from dynslam2d.detect.measure import Detection, Measurement
from dynslam2d.detect.segment import Segmentation, is_full_circle, segment_scan
from dynslam2d.detect.shapes import RectFit, fit_circle, fit_clusters, fit_rectangle, search_angles
from dynslam2d.detect.tracker import COASTING, CONFIRMED, TENTATIVE, Tracker, TrackerStats

__all__ = [
    "COASTING",
    "CONFIRMED",
    "TENTATIVE",
    "DetectConfig",
    "Detection",
    "FitConfig",
    "Measurement",
    "RectFit",
    "SegmentConfig",
    "Segmentation",
    "Tracker",
    "TrackerConfig",
    "TrackerStats",
    "fit_circle",
    "fit_clusters",
    "fit_rectangle",
    "is_full_circle",
    "search_angles",
    "segment_scan",
]
