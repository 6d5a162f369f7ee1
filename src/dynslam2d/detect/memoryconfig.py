"""Configuration of track memory through stops and of retroactive erasure (docs/maps.md).

Nested as ``detect.memory`` (:class:`MemoryConfig`). Track memory is read by
:class:`dynslam2d.detect.tracker.Tracker`; retroactive erasure by
:class:`dynslam2d.slam.erasure.EvidenceLedger` in the pipeline.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class MemoryConfig(BaseModel):
    """Memory of what moved (units in each description)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    enabled: bool = Field(
        True,
        description="A track that has been in M stays in M when it stops (a 'remembered' track): its points "
        "keep being removed while the track lives, it coasts with a stationary motion model and keeps its "
        "identity when it starts again.",
    )
    min_m_time: float = Field(
        1.0, ge=0.0,
        description="Only a track that was in M for at least this long is remembered when it stops, s "
        "(a false track that enters M for a moment is not).",
    )
    min_travel: float = Field(
        1.0, ge=0.0,
        description="… and whose centre moved at least this far from where it entered M, m (pose jitter and "
        "a sliding wall fragment do not travel).",
    )
    max_size: float = Field(
        6.0, gt=0.0,
        description="… and whose box's longer side is at most this, m.",
    )
    expiry_s: float | None = Field(
        300.0, gt=0.0,
        description="A remembered track stopped for longer than this leaves M and is mapped where it stands, s "
        "(None = never). Trade-off: a door that swings and rests, a chair moved once, are kept out of the "
        "map while remembered; a long expiry keeps a car parked for minutes out of the map.",
    )
    coast_time: float = Field(
        60.0, ge=0.0,
        description="A remembered track that is not detected (occluded, out of view) is kept this long at its "
        "stopped position, s; it is dropped earlier when scans see through its place.",
    )
    stationary_noise: float = Field(
        0.002, gt=0.0,
        description="Position random-walk density of the stationary motion model of a remembered track, m²/s.",
    )
    max_position_sigma: float = Field(
        0.3, gt=0.0,
        description="Position standard deviation of a remembered track is kept at most this while it coasts, m.",
    )
    max_speed_sigma: float = Field(
        0.5, gt=0.0,
        description="Velocity standard deviation of a remembered track is kept at most this, m/s (it can start "
        "again: the velocity keeps some uncertainty).",
    )
    seen_through_share: float = Field(
        0.6, gt=0.0, le=1.0,
        description="A coasting remembered track is dropped when this share of the beams towards its box pass "
        "beyond it (the object is gone).",
    )
    erase: bool = Field(
        True,
        description="Retroactive erasure: the map evidence a track's points wrote while it was not in M is "
        "taken out of the online map when it enters M and has left its place.",
    )
    erase_min_travel: float = Field(
        0.5, ge=0.0,
        description="Erase a track's evidence only once it moved this far from where it entered M, m.",
    )
    erase_min_share: float = Field(
        0.5, ge=0.0,
        description="A cell's evidence is erased only where what the track wrote is at least this share of the "
        "cell's log-odds (a wall cell that many scans hit keeps the few hits a false track added to it).",
    )
    link_margin: float = Field(
        0.3, ge=0.0,
        description="The evidence of an ended track (lost while parked; only tracks that were confirmed) is "
        "erased with a track entering M that was first seen within this distance of its box, m.",
    )
    link_min_stand: float = Field(
        1.0, ge=0.0,
        description="A track's evidence is erased, and ended tracks' evidence linked to it, only if it stood "
        "(slower than stand_speed, within link_margin + 0.5 m) for at least this long before it entered M and "
        "entered M within link_margin + 1 m of that place, s: a person born walking past a chair leg neither "
        "takes the chair leg with it nor has its own first steps erased.",
    )
    stand_speed: float = Field(
        0.25, ge=0.0,
        description="A track slower than this stands (for link_min_stand: only evidence written while a track "
        "stood for link_min_stand is erased, and only such a track takes ended tracks' evidence with it), m/s.",
    )
    ledger_keep_s: float = Field(
        600.0, gt=0.0,
        description="The evidence record of an ended track is kept this long for linking, s.",
    )
    max_ledger_cells: int = Field(
        20000, ge=1,
        description="At most this many cells are recorded per track and map level (memory bound); later "
        "writes beyond it are not recorded.",
    )
