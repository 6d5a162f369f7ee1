"""Colours shared by every figure and the animation (exact RGB, so tests can find them).

Colour-blind-safe choices (Okabe–Ito where possible); every overlay colour is far from
the greys of the occupancy map and from each other.
"""

from __future__ import annotations

#: Estimated laser trajectory.
TRAJECTORY = "#d55e00"
#: Ground-truth trajectory.
GROUND_TRUTH = "#009e73"
#: Points of beams the filter removed from the map update.
REMOVED = "#e6007e"
#: Points of beams kept (animation).
KEPT = "#0072b2"
#: Tracks in the dynamic set M (paths in map.png, boxes in the animation).
TRACK_M = "#1a237e"
#: Confirmed tracks outside M.
TRACK_OTHER = "#8c6d1f"
#: Map difference: estimated occupied cells far from any true structure.
GHOST = "#dc143c"
#: Map difference: true structure the estimate observed but did not map.
MISSED = "#1e64ff"
#: Map difference: ground-truth structure (the outline everything is drawn over); a light teal, not
#: a grey, so it stays apart from :data:`UNKNOWN` (issue 15 item 7).
TRUTH_OUTLINE = "#66c2a5"
#: Map difference: estimated occupied cells that match the truth.
MATCHED = "#000000"
#: Unknown / unobserved cells in difference images.
UNKNOWN = "#e4e4e4"
#: Pose confidence: scans matched with low support (trajectory markers, time shading).
LOW_SUPPORT = "#f0a000"
#: Pose confidence: scans while the SLAM was lost.
LOST = "#b40000"
#: Pose confidence: scans where the front end snapped back after a drift (a jump; trajectory markers).
JUMP = "#7a00b4"
#: Loop closures (map.png): segments between the two keyframes of each loop edge.
LOOP_EDGE = "#2ca02c"
#: Pose confidence: degenerate scans (time shading).
DEGENERATE = "#56b4e9"


def rgb255(colour: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` → (r, g, b) in 0 … 255."""
    c = colour.lstrip("#")
    return int(c[0:2], 16), int(c[2:4], 16), int(c[4:6], 16)


def rgb01(colour: str) -> tuple[float, float, float]:
    """``"#rrggbb"`` → (r, g, b) in 0 … 1."""
    r, g, b = rgb255(colour)
    return r / 255.0, g / 255.0, b / 255.0
#: Cells the offline clean-up pass erased from the online map (amber; docs/maps.md).
ERASED = "#ffb000"
#: Cells whose evidence retroactive erasure took out of the online map (a parked object that left;
#: violet; docs/maps.md).
MEMORY_ERASED = "#9b59d0"
