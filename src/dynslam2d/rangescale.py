"""A lidar's range scale: multiply every range by k before anything else sees the scan.

A lidar whose ranges read a few percent short maps a uniformly shrunk world, and laser-only
SLAM inherits that scale: its path comes out k times too short (the datmo bags, k ≈ 1.05;
docs/slam.md "Why the datmo path is short"). The scan alone cannot see this — a uniformly
scaled world is as self-consistent as the true one — but odometry can: its displacements
have their own, independent scale (the wheel radius).

* ``laser.range_scale: K`` (``--range-scale K``): ranges × K (and the sensor's range limits
  × K, so a beam's return / no-return status does not change).
* ``laser.range_scale: auto`` (``--range-scale auto``): K is estimated before the run by
  :func:`estimate_range_scale` from the recording's own odometry, ``K = Σ|Δodom| / Σ|Δslam|``
  over windows of ``window_s`` where the odometry moved, with a laser-only SLAM pass over the
  first ``max_scans`` scans. Its accuracy is the odometry's scale accuracy.

``summary.json`` reports the scale used and, for ``auto``, the estimate's evidence
(``range_scale`` block).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.laserconfig import SCALE_MAX, SCALE_MIN, LaserConfig
from dynslam2d.types import Scan, ScanSource, SourceWrapper

__all__ = ["LaserConfig", "RangeScaleEstimate", "RangeScaleSource", "apply_range_scale", "estimate_range_scale",
           "scale_ranges"]

def scale_ranges(scan: Scan, k: float) -> Scan:
    """``scan`` with ranges and the range limits × ``k`` (odometry, IMU and geometry kept)."""
    out = Scan(
        stamp=scan.stamp, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
        ranges=scan.ranges * k, range_min=scan.range_min * k, range_max=scan.range_max * k,
        frame_id=scan.frame_id, intensities=scan.intensities, angle_max=scan.angle_max,
        time_increment=scan.time_increment, scan_time=scan.scan_time,
    )
    return out.with_odometry(scan.odom, scan.yaw_rate)


class RangeScaleSource(SourceWrapper):
    """Wraps a scan source; yields its scans with the ranges × ``scale``."""

    def __init__(self, inner: ScanSource, scale: float) -> None:
        super().__init__(inner)
        self.scale = float(scale)

    def __iter__(self) -> Iterator[Scan]:
        k = self.scale
        for scan in self.inner:
            yield scale_ranges(scan, k)


@dataclass(frozen=True)
class RangeScaleEstimate:
    """Evidence of an automatic range-scale estimate.

    Attributes:
        scale: the estimate Σ|Δodom| / Σ|Δslam| (NaN when there was too little motion).
        windows: windows where the odometry moved (count).
        odom_distance, slam_distance: summed displacements over those windows, m.
        scans: scans of the laser-only SLAM pass.
        window_ratio_iqr: interquartile range of the per-window ratios (a spread, not an error bar).
    """

    scale: float
    windows: int
    odom_distance: float
    slam_distance: float
    scans: int
    window_ratio_iqr: tuple[float, float]


def estimate_range_scale(source: ScanSource, laser: LaserConfig,
                         slam_config: object | None = None) -> RangeScaleEstimate:
    """Range scale of ``source`` from its odometry: a laser-only SLAM pass (detection off) over the
    first ``laser.range_scale_scans`` scans; over windows of ``laser.range_scale_window`` s in which the
    odometry moved by more than 2 cm, ``scale = Σ|Δodom| / Σ|Δslam|`` (both laser-point displacements).

    Raises:
        DynSlamError: the scans carry no odometry.
    """
    from dynslam2d.slam import HectorSlam, SlamConfig

    cfg = slam_config if isinstance(slam_config, SlamConfig) else SlamConfig()
    slam = HectorSlam(cfg.model_copy(update={"use_odometry": False}))
    stamps, est, odo = [], [], []
    for i, scan in enumerate(source):
        if i >= laser.range_scale_scans:
            break
        step = slam.process(scan.with_odometry(None, None))
        if scan.odom is None or not scan.odom.is_finite() or step.rejected:
            continue
        stamps.append(scan.stamp)
        est.append((step.pose.x, step.pose.y))
        odo.append((scan.odom.x, scan.odom.y))
    n = slam.n_scans
    if not odo:
        raise DynSlamError(f"{source.meta.origin}: --range-scale auto needs odometry, and no scan carries any "
                           "(see --odom; or give the scale as a number)")
    t = np.asarray(stamps)
    e = np.asarray(est)
    o = np.asarray(odo)
    # window ends: for each start i, the first scan at least window_s later
    j = np.searchsorted(t, t + laser.range_scale_window)
    ok = j < t.size
    i_idx, j_idx = np.nonzero(ok)[0], j[ok]
    do = np.hypot(*(o[j_idx] - o[i_idx]).T)
    de = np.hypot(*(e[j_idx] - e[i_idx]).T)
    moved = do > 0.02
    # non-overlapping windows: every k-th start, k = scans per window
    step = max(1, int(np.median(j_idx - i_idx))) if i_idx.size else 1
    sel = moved & (np.arange(i_idx.size) % step == 0)
    od, sd = float(do[sel].sum()), float(de[sel].sum())
    ratios = do[sel] / np.maximum(de[sel], 1e-9)
    iqr = (float(np.percentile(ratios, 25)), float(np.percentile(ratios, 75))) if ratios.size else (math.nan, math.nan)
    scale = od / sd if od >= laser.range_scale_min_distance and sd > 0.0 else math.nan
    return RangeScaleEstimate(scale, int(sel.sum()), od, sd, n, iqr)


def _json_safe(v: object) -> object:
    """NaN → None (summary.json stays valid JSON); tuples → lists."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, tuple):
        return [_json_safe(x) for x in v]
    return v


def apply_range_scale(source: ScanSource, laser: LaserConfig, slam_config: object | None = None) -> ScanSource:
    """``source`` with ``laser.range_scale`` applied (module docstring); records the scale (and for
    ``auto`` the estimate) in ``source.meta.extra["range_scale"]``; warnings go to
    ``meta.extra["warnings"]``. Returns ``source`` itself for a scale of 1."""
    extra = source.meta.extra
    if laser.range_scale == "auto":
        est = estimate_range_scale(source, laser, slam_config)
        info: dict[str, object] = {k: _json_safe(v) for k, v in {"mode": "auto", **asdict(est)}.items()}
        if not math.isfinite(est.scale):
            extra.setdefault("warnings", []).append(
                f"range scale: the odometry covered only {est.odom_distance:.2f} m in the first {est.scans} scans "
                f"(at least {laser.range_scale_min_distance} m needed); range scale 1 used")
            info["used"] = 1.0
            extra["range_scale"] = info
            return source
        if not SCALE_MIN <= est.scale <= SCALE_MAX:
            raise DynSlamError(f"{source.meta.origin}: --range-scale auto estimated {est.scale:.3f} (odometry "
                               f"{est.odom_distance:.2f} m vs laser {est.slam_distance:.2f} m): the odometry's scale "
                               "or the laser mount is wrong; give the range scale as a number")
        k = est.scale
        info["used"] = k
    else:
        k = float(laser.range_scale)
        info = {"mode": "fixed", "used": k}
    extra["range_scale"] = info
    if k == 1.0:
        return source
    return RangeScaleSource(source, k)
