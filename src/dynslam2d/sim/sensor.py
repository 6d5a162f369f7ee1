"""The simulated 2D LiDAR: beam geometry and the range measurement model.

Beams are evenly spaced, counter-clockwise, centred on the laser's x axis. A
full circle (fov = 2π) has ``angle_increment = 2π / beams`` (no duplicated
beam); a partial fan has ``angle_increment = fov / (beams − 1)`` so that the
first and last beams sit at ±fov/2, like a Hokuyo. The whole scan is taken at
its stamp (no motion skew within a scan; ``time_increment`` = 0).

Range model per beam: ``r = r_true + N(0, σ²)``; the beam returns nothing
(``inf``, REP-117) when nothing lies within reach, when ``r > range_max``, when
``r < range_min`` (too close for the sensor), or with probability ``dropout``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynslam2d.types import Scan


@dataclass(frozen=True, slots=True)
class LidarModel:
    """A 2D laser scanner.

    Attributes:
        beams: number of beams per scan.
        fov: field of view, rad (2π for a full circle).
        rate_hz: scans per second, Hz.
        range_min, range_max: valid range interval, m.
        noise_sigma: standard deviation of the Gaussian range noise, m.
        dropout: probability that a beam returns nothing, in [0, 1).
        frame_id: frame name written into each Scan.
    """

    beams: int = 720
    fov: float = 2.0 * math.pi
    rate_hz: float = 20.0
    range_min: float = 0.1
    range_max: float = 20.0
    noise_sigma: float = 0.01
    dropout: float = 0.0
    frame_id: str = "laser"

    def __post_init__(self) -> None:
        if self.beams < 2:
            raise ValueError(f"LidarModel: beams must be ≥ 2, got {self.beams}")
        if not 0 < self.fov <= 2.0 * math.pi + 1e-9:
            raise ValueError(f"LidarModel: fov must be in (0, 2π], got {self.fov}")
        if not self.rate_hz > 0:
            raise ValueError(f"LidarModel: rate_hz must be > 0, got {self.rate_hz}")
        if not 0 <= self.range_min < self.range_max:
            raise ValueError(f"LidarModel: need 0 ≤ range_min < range_max, got [{self.range_min}, {self.range_max}]")
        if self.noise_sigma < 0 or not 0 <= self.dropout < 1:
            raise ValueError("LidarModel: need noise_sigma ≥ 0 and dropout in [0, 1)")

    @property
    def full_circle(self) -> bool:
        return self.fov >= 2.0 * math.pi - 1e-9

    @property
    def angle_increment(self) -> float:
        """Angle between consecutive beams, rad."""
        return self.fov / self.beams if self.full_circle else self.fov / (self.beams - 1)

    @property
    def angle_min(self) -> float:
        """Angle of beam 0 in the laser frame, rad."""
        return -math.pi if self.full_circle else -0.5 * self.fov

    @property
    def angles(self) -> np.ndarray:
        """(beams,) beam angles in the laser frame, rad."""
        return self.angle_min + np.arange(self.beams) * self.angle_increment

    @property
    def period(self) -> float:
        """Time between scans, s."""
        return 1.0 / self.rate_hz

    def measure(self, true_ranges: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Noisy ranges from true ranges (m, ``inf`` = nothing hit).

        Returns ``(ranges, valid)``: (beams,) float64 measured ranges with
        ``inf`` for no return, and the (beams,) bool mask of beams with a return.
        The random draws are the same whatever the geometry (one normal and one
        uniform per beam), so a seed fixes the noise independently of the scene.
        """
        noise = rng.standard_normal(true_ranges.shape[0]) * self.noise_sigma
        drop = rng.random(true_ranges.shape[0]) < self.dropout
        with np.errstate(invalid="ignore"):
            r = true_ranges + noise
            valid = np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max) & ~drop
        return np.where(valid, r, np.inf), valid

    def make_scan(self, stamp: float, ranges: np.ndarray) -> Scan:
        """Wrap measured ranges into a :class:`Scan` with this sensor's metadata."""
        return Scan(
            stamp=float(stamp),
            angle_min=self.angle_min,
            angle_increment=self.angle_increment,
            ranges=ranges,
            range_min=self.range_min,
            range_max=self.range_max,
            frame_id=self.frame_id,
            time_increment=0.0,
            scan_time=self.period,
        )
