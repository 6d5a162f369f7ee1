"""Configuration of the offline map clean-up pass (docs/maps.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class CleanConfig(BaseModel):
    """Parameters of :mod:`dynslam2d.slam.cleanup` (units in each description)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    enabled: bool = Field(
        True,
        description="Run the clean-up pass: map.pgm is the cleaned static map, map_online.pgm the online one "
        "(CLI --clean on|off).",
    )
    scans: Literal["all", "map_updates"] = Field(
        "all",
        description="Scans whose beams are counted: every matched scan (all) or only those written into the "
        "online map (map_updates). 'all' also sees objects leave while the robot stands still.",
    )
    min_interval_s: float = Field(
        0.1, ge=0.0,
        description="Count at most one scan per this many seconds of scan time (map updates are always "
        "counted), s: consecutive scans of a fast sensor see nearly the same, and the pass's cost scales "
        "with the scans counted. 0 = every scan.",
    )
    margin_m: float = Field(
        0.10, ge=0.0,
        description="A beam passes through cells only up to this distance before its endpoint, m.",
    )
    grazing_cells: float = Field(
        1.5, ge=0.0,
        description="At grazing incidence the margin grows so that the ray stays this many cells away from "
        "the surface it hits: margin ≥ grazing_cells·resolution / sin(incidence), cells.",
    )
    min_incidence_deg: float = Field(
        5.0, gt=0.0, le=90.0,
        description="Incidence angles below this are treated as this angle when the margin is computed, deg.",
    )
    ray_core: float = Field(
        0.4, gt=0.0, le=0.5,
        description="A cell counts as passed through only where the ray runs within this distance of its "
        "centre (across the ray's major axis), cells (0.5 = every cell the line touches on that axis).",
    )
    min_through: int = Field(
        3, ge=1,
        description="A cell is erased only if at least this many scans passed through it.",
    )
    through_ratio: float = Field(
        0.2, gt=0.0,
        description="… and if scans passing through it ≥ this × scans hitting it (dimensionless).",
    )
    max_switches: int = Field(
        2, ge=0,
        description="… and if its scans changed between hit and pass at most this many times "
        "(+ switch_share·min(hits, passes)): a parked object is hit in one block and seen through in "
        "another; glass, railings and wall copies of a drifted pass alternate.",
    )
    switch_share: float = Field(
        0.15, ge=0.0,
        description="Extra switches allowed per scan of the rarer kind (hit or pass), dimensionless.",
    )
    rehit_min_hits: int = Field(
        6, ge=0,
        description="Never erase a cell hit by at least this many counted scans whose first and latest counted "
        "touches were both hits (hit, seen through, hit again): the structure was there before and after the "
        "scans that saw through it, so those scans disagree with the others about where it is — pose error "
        "between visits, not a mover (docs/maps.md, 'What the erased cells are'). 6 = two visits of min_through "
        "scans; a cell that two people walking past crossed is hit 2–5 times. 0 = off (the rule before it).",
    )
    revert_neighbors: int = Field(
        3, ge=0, le=9,
        description="An erased cell with at least this many kept occupied cells among its 8 neighbours is "
        "kept after all (it is the edge of a structure that stays: a pillar corner, the face of a wall); "
        "0 = off.",
    )
    restore_min_hits: int = Field(
        3, ge=0,
        description="Put back as occupied a cell the online map holds free (observed) that at least this many "
        "counted scans hit with a kept beam and that beams were (almost) never seen to pass through beyond "
        "their incidence-scaled margin: a wall cell that rays running along the wall cleared in the online "
        "map (docs/maps.md, 'Walls that grazing rays cleared'). 0 = off.",
    )
    restore_through_ratio: float = Field(
        0.1, ge=0.0,
        description="… and only if scans passing through it ≤ this × scans hitting it (dimensionless).",
    )
