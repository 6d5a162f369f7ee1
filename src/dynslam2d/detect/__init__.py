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
:mod:`~dynslam2d.detect.measure` (which sides of a cluster are real → centre measurement),
:mod:`~dynslam2d.detect.tracker` (Kalman tracking, track management, set M),
:mod:`~dynslam2d.detect.kernels` (the tracker's per-scan numba batches),
:mod:`~dynslam2d.detect.config` (parameters).
"""

from dynslam2d.detect.config import DetectConfig, FitConfig, SegmentConfig, TrackerConfig
from dynslam2d.detect.measure import Detection, Measurement, classify_and_bound, measure
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
    "classify_and_bound",
    "fit_circle",
    "fit_clusters",
    "fit_rectangle",
    "is_full_circle",
    "measure",
    "search_angles",
    "segment_scan",
]
