"""The lidar's own configuration (config group ``laser``): its range scale.

Applied by :mod:`dynslam2d.rangescale` (docs/slam.md, "Range scale").
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

__all__ = ["LaserConfig", "SCALE_MAX", "SCALE_MIN"]

#: Bounds of a plausible range scale (anything outside is an error of the input, not of the lidar).
SCALE_MIN, SCALE_MAX = 0.5, 2.0


class LaserConfig(BaseModel):
    """The lidar itself (config group ``laser``)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    range_scale: float | Literal["auto"] = Field(
        1.0,
        description="Every range is multiplied by this before detection and SLAM (a lidar that reads short: "
        "> 1). 'auto' = estimated from the recording's odometry (odometry / laser-only SLAM displacement "
        "over the first range_scale_scans scans; needs odometry). Dimensionless.",
    )
    range_scale_scans: int = Field(
        1500, ge=10,
        description="'auto': scans of the laser-only SLAM pass that estimates the range scale, count.",
    )
    range_scale_window: float = Field(
        0.5, gt=0.0,
        description="'auto': displacements are compared over windows of this length, s.",
    )
    range_scale_min_distance: float = Field(
        2.0, gt=0.0,
        description="'auto': the odometry must cover at least this distance (in windows where it moved) for "
        "an estimate; otherwise the scale stays 1 with a warning, m.",
    )

    @field_validator("range_scale")
    @classmethod
    def _check_scale(cls, v: float | str) -> float | str:
        if isinstance(v, str):
            return v
        if not (math.isfinite(v) and SCALE_MIN <= v <= SCALE_MAX):
            raise ValueError(f"must be 'auto' or a number in [{SCALE_MIN}, {SCALE_MAX}], got {v}")
        return v
