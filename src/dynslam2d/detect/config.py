"""Configuration of moving-object detection and tracking (``dynslam2d.detect``).

Three stages, one pydantic model each, nested in :class:`DetectConfig`:

- :class:`SegmentConfig` — breakpoint segmentation of a scan (paper Eq. 1; Borges & Aldon
  2004 adaptive breakpoint detector; the fixed gap of kostaskonkk/datmo ``Datmo::Clustering`` for parity).
- :class:`FitConfig` — search-based rectangle fitting (Zhang et al., IV 2017; datmo's
  ``Cluster::rectangleFitting``) and the circle / point models for small or round clusters.
- :class:`TrackerConfig` — constant-velocity Kalman tracking in the map frame, track
  management, and the dynamic set M (paper Eq. 3; confirmation and free-space ideas from leg_tracker,
  Leigh et al., ICRA 2015).

Defaults were tuned on the simulator scenes (720 beams, 20 Hz) and checked on the datmo
bags (360 beams, 12.5 Hz); see ``dynslam2d.eval.tracking``.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from dynslam2d.detect.memoryconfig import MemoryConfig


class SegmentConfig(BaseModel):
    """Parameters of :func:`dynslam2d.detect.segment.segment_scan` (units in each description)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    mode: Literal["adaptive", "fixed"] = Field(
        "adaptive",
        description="'adaptive': breakpoint threshold D = clip(r·sin Δφ / sin(λ − Δφ) + 3σ_r, d_min, d_max) "
        "(paper Eq. 1, Borges & Aldon 2004); 'fixed': datmo's constant gap fixed_gap "
        "(datmo's code, Datmo::Clustering).",
    )
    lambda_deg: float = Field(
        10.0, gt=0.0, lt=90.0,
        description="Worst-case incidence angle λ of the adaptive detector, degrees (Borges & Aldon use ≈10°).",
    )
    sigma_r: float = Field(
        0.01, ge=0.0,
        description="Range noise standard deviation σ_r, m; the adaptive threshold adds 3σ_r.",
    )
    d_min: float = Field(
        0.10, ge=0.0,
        description="Lower clamp of the adaptive threshold, m.",
    )
    d_max: float = Field(
        0.30, gt=0.0,
        description="Upper clamp of the adaptive threshold, m (an unclamped ABD over-merges "
        "small objects with walls).",
    )
    fixed_gap: float = Field(
        0.17, gt=0.0,
        description="Gap of the 'fixed' mode, m (datmo code default 0.2, example.launch 0.17).",
    )
    max_skip_beams: int = Field(
        3, ge=0,
        description="Consecutive valid beams may be linked across at most this many no-return beams "
        "(0 = only adjacent beams link); the threshold uses the real angle difference.",
    )
    wrap_around: Literal["auto", "always", "never"] = Field(
        "auto",
        description="Link the last and first beams: 'auto' when the scan covers 360° (n·|Δφ| ≥ 2π − 1.5|Δφ|).",
    )
    min_points: int = Field(
        3, ge=1,
        description="Clusters with fewer points are dropped (noise, isolated grazing returns).",
    )
    max_points: int = Field(
        400, ge=2,
        description="Clusters with more points are static structure (never tracked).",
    )
    max_extent: float = Field(
        3.0, gt=0.0,
        description="Clusters whose fitted rectangle has a side longer than this are static structure, m "
        "(walls); the largest mover in the simulator is the 2 m bar. Longer clusters up to vehicle_max_extent "
        "are detections only on observed-free map cells (detect/vehicles.py).",
    )
    vehicle_max_extent: float = Field(
        6.0, ge=0.0,
        description="Clusters longer than max_extent and up to this are kept as detections (cars, vans) when "
        "the SLAM map shows they are not structure: at most vehicle_max_structure of their points on "
        "long-occupied cells and at least vehicle_min_free in observed free space, m (≤ max_extent = off).",
    )
    vehicle_max_structure: float = Field(
        0.1, ge=0.0, le=1.0,
        description="Largest share of a long cluster's points on long-occupied map cells (detect/vehicles.py).",
    )
    vehicle_min_free: float = Field(
        0.5, ge=0.0, le=1.0,
        description="Smallest share of a long cluster's points in observed free map cells (detect/vehicles.py).",
    )


class FitConfig(BaseModel):
    """Parameters of the shape fit (:mod:`dynslam2d.detect.shapes`)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    criterion: Literal["variance", "closeness", "area"] = Field(
        "variance",
        description="Zhang et al. 2017 criterion of the search-based rectangle fit "
        "(datmo's Cluster::rectangleFitting): "
        "'variance' (PythonRobotics default), 'closeness' (datmo) or 'area'.",
    )
    angle_step_deg: float = Field(
        1.0, gt=0.0, le=15.0,
        description="Step of the heading search over [0, 90°), degrees (datmo uses ≈3.6°; Zhang 1°).",
    )
    coarse_stride: int = Field(
        5, ge=1,
        description="Coarse-to-fine heading search: score every coarse_stride-th angle, then every angle "
        "within one coarse step of the best (1 = exhaustive search over all angles).",
    )
    closeness_d0: float = Field(
        0.01, gt=0.0,
        description="Floor d0 of the distance in the closeness criterion, m (Zhang 0.01; datmo 0.001).",
    )
    point_max_points: int = Field(
        4, ge=1,
        description="Clusters with at most this many points use the point model (centroid).",
    )
    point_max_extent: float = Field(
        0.08, ge=0.0,
        description="Clusters whose two fitted sides are both below this use the point model, m.",
    )
    circle_min_points: int = Field(
        5, ge=3,
        description="Fewest points for the circle model (people, poles).",
    )
    circle_max_radius: float = Field(
        0.45, gt=0.0,
        description="Largest radius accepted by the circle model, m.",
    )
    circle_min_radius: float = Field(
        0.05, gt=0.0,
        description="Smallest radius accepted by the circle model, m.",
    )
    circle_residual_ratio: float = Field(
        0.6, gt=0.0,
        description="The circle model wins when its RMS residual is below this fraction of the rectangle's.",
    )
    circle_min_depth_ratio: float = Field(
        0.5, ge=0.0,
        description="The circle model needs the arc to be deep: the short side of the cluster's rectangle "
        "≥ this × radius (a half circle gives ≈1; a slightly curved bumper ≈0.1).",
    )
    face_tolerance: float = Field(
        0.04, gt=0.0,
        description="A point lies on a rectangle side when within this distance of it, m (≈3–4σ_r).",
    )
    min_face_span: float = Field(
        0.06, gt=0.0,
        description="A side counts as a visible face when its points span at least this along it, m.",
    )
    edge_line_tolerance: float = Field(
        0.08, gt=0.0,
        description="A cluster end whose outside neighbour lies within this distance of the end face's "
        "line is an artificial break of one surface (grazing wall), not an object edge, m.",
    )
    min_side_points: int = Field(
        3, ge=1,
        description="A side running away from a visible face measures the object's depth only if it has at "
        "least this many points off the face (a grazing side shows one or two).",
    )
    edge_max_gap: float = Field(
        0.12, gt=0.0,
        description="A cluster end is a usable object edge only if the next beam would meet the end face "
        "within this distance (r·Δφ / sin incidence), m: a grazing face may end anywhere in that gap.",
    )
    edge_range_jump: float = Field(
        0.05, ge=0.0,
        description="An outside neighbour closer than the end point by more than this occludes the end "
        "(end not observed), m.",
    )
    fragment_margin: float = Field(
        0.15, ge=0.0,
        description="An unassigned cluster lying entirely within this distance of the box of a confirmed "
        "track updated in the same scan is a fragment of that object: its beams join the track, no new "
        "track is born, m.",
    )
    person_merge: bool = Field(
        True,
        description="Merge two leg-sized clusters close together into one person detection (leg_tracker's leg "
        "pairs, Leigh et al. ICRA 2015), measured at the middle of the two legs.",
    )
    leg_max_extent: float = Field(
        0.25, gt=0.0,
        description="A leg: a cluster whose fitted sides are both at most this, m.",
    )
    leg_pair_distance: float = Field(
        0.45, gt=0.0,
        description="Two legs of one person: their centres lie at most this far apart, m.",
    )
    person_min_radius: float = Field(
        0.1, gt=0.0,
        description="A circle fit of radius within [person_min_radius, person_max_radius] is a person too (legs "
        "merged by the segmentation, or a torso-height scan), m.",
    )
    person_max_radius: float = Field(0.35, gt=0.0, description="See person_min_radius, m.")
    sigma_position: float = Field(
        0.02, gt=0.0,
        description="Standard deviation of an observed face / edge position, m.",
    )
    sigma_point: float = Field(
        0.08, gt=0.0,
        description="Standard deviation of a point-model (centroid) measurement, m.",
    )
    sigma_unobserved: float = Field(
        0.5, gt=0.0,
        description="Standard deviation, for association only, of the centre along an axis where neither "
        "bound is observed (e.g. a wall piece whose ends are grazing breaks), m. The Kalman update gets no "
        "position there, only a zero-velocity pseudo-measurement (sigma_unobserved_speed).",
    )
    sigma_unobserved_speed: float = Field(
        0.2, gt=0.0,
        description="Standard deviation of the zero-velocity pseudo-measurement along an unobserved axis, m/s.",
    )
    default_depth: float = Field(
        0.5, gt=0.0,
        description="Largest size assumed along an axis never fully observed (only its near face seen), m.",
    )
    default_depth_ratio: float = Field(
        0.5, gt=0.0,
        description="Assumed size along a never-observed axis as a fraction of the observed side (capped by "
        "default_depth); 1 = square prior.",
    )


class TrackerConfig(BaseModel):
    """Parameters of :class:`dynslam2d.detect.tracker.Tracker`."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    accel_noise: float = Field(
        2.0, gt=0.0,
        description="White-noise acceleration spectral density q of the constant-velocity model, m²/s³ "
        "(Q = q·[[dt³/3, dt²/2], [dt²/2, dt]] per axis).",
    )
    init_speed_sigma: float = Field(
        2.0, gt=0.0,
        description="Prior standard deviation of a new track's velocity (mean 0), m/s.",
    )
    gate_chi2: float = Field(
        13.8, gt=0.0,
        description="Mahalanobis gate on the centre innovation, χ² with 2 dof (13.8 = 99.9 %).",
    )
    gate_distance: float = Field(
        1.0, gt=0.0,
        description="Euclidean gate between a cluster's centroid and a track's predicted box (distance to "
        "the box outline), m; bounds association along unobserved axes.",
    )
    max_size_jump: float = Field(
        0.8, gt=0.0,
        description="A detection whose longest side exceeds max_size_jump_ratio × the track's longest side plus "
        "this cannot update the track, m (a person track coasting past a wall must not take the wall).",
    )
    max_size_jump_ratio: float = Field(
        2.0, ge=1.0,
        description="See max_size_jump.",
    )
    confirm_hits: int = Field(
        3, ge=1,
        description="M of the M-of-N confirmation rule: hits needed among the first confirm_window updates.",
    )
    confirm_window: int = Field(
        4, ge=1,
        description="N of the M-of-N confirmation rule, scans.",
    )
    max_coast_time: float = Field(
        0.6, ge=0.0,
        description="A confirmed track with no detection for longer than this is deleted, s.",
    )
    max_position_sigma: float = Field(
        1.5, gt=0.0,
        description="A track whose position standard deviation exceeds this is deleted (covariance blow-up), m.",
    )
    size_gain: float = Field(
        0.3, gt=0.0, le=1.0,
        description="Gain of the size filter when a side is fully observed (exponential smoothing).",
    )
    heading_gain: float = Field(
        0.3, gt=0.0, le=1.0,
        description="Gain of the box-axis heading filter (innovation wrapped to ±45°, the 90° ambiguity).",
    )
    v_min: float = Field(
        0.5, ge=0.0,
        description="Speed threshold of the dynamic set M, m/s (paper Eq. 3).",
    )
    v_exit_ratio: float = Field(
        0.5, ge=0.0, le=1.0,
        description="A track leaves M when its speed stays below v_exit_ratio·v_min for m_exit_time "
        "(hysteresis: an object that pauses stays an object to filter); ratio 1 and time 0 = Eq. 3 "
        "applied on every update.",
    )
    m_exit_time: float = Field(
        2.5, ge=0.0,
        description="How long the speed must stay below v_exit_ratio·v_min before a track leaves M, s.",
    )
    sustain_updates: int = Field(
        5, ge=1,
        description="Consecutive updates with speed > v_min needed to enter M (robustness to pose jitter).",
    )
    person_sustain_updates: int = Field(
        3, ge=1,
        description="For a person (merged leg pair, or a person-sized circle) that shows it moved into empty space "
        "(person_map_free_min, or person_free_min) the speed must exceed v_min for this many consecutive updates "
        "instead of sustain_updates: a person who starts walking enters M within 0.5 s.",
    )
    person_map_free_min: float = Field(
        0.6, ge=0.0, le=1.0,
        description="The person's faster confirmation needs this mean fraction of its points in observed-free map "
        "cells over its last person_sustain_updates updates (stronger than map_free_min: small clutter pairs up "
        "like legs)…",
    )
    person_free_min: float = Field(
        0.5, ge=0.0, le=1.0,
        description="…or this mean fraction of its points where an earlier scan saw through (the free-space memory: "
        "free_ref_ages, free_margin), with at most map_structure_max of them on long-occupied map cells: the map "
        "has not seen a place a person just walked into often enough, and the person's own earlier returns mark "
        "the cells next to it, but no earlier beam passes through a wall.",
    )
    person_min_displacement: float = Field(
        0.15, ge=0.0,
        description="Net displacement since birth that a person on the faster way into M needs (instead of "
        "min_displacement), m: a person who stood still for a while was born where it stood.",
    )
    net_speed_ratio: float = Field(
        0.7, ge=0.0,
        description="Entering M also needs the net displacement over the sustained updates, divided by their time "
        "span, to reach net_speed_ratio·v_min (a filtered speed built from jitter has no net motion).",
    )
    min_displacement: float = Field(
        0.3, ge=0.0,
        description="Net displacement of the centre since the track's birth needed to enter M, m.",
    )
    max_speed_sigma: float = Field(
        0.8, gt=0.0,
        description="Entering M needs the velocity standard deviation along its own direction below this, m/s.",
    )
    free_space_check: bool = Field(
        True,
        description="Entering M also needs the track's points to lie where an earlier scan saw through "
        "(free space; leg_tracker's free-space test, Leigh et al. ICRA 2015): walls never do.",
    )
    free_min_fraction: float = Field(
        0.1, ge=0.0, le=1.0,
        description="Mean fraction of a track's points on free cells, over its last sustain_updates updates, "
        "needed to enter M.",
    )
    free_ref_ages: tuple[float, ...] = Field(
        (0.3, 0.8), min_length=1,
        description="Ages of the earlier scans the free-space test looks back to, s (the buffered scan "
        "nearest each age); a point is on free space if one of them saw through its place.",
    )
    free_margin: float = Field(
        0.15, gt=0.0,
        description="An earlier beam must end at least this far behind a point to count as seeing through "
        "it, m.",
    )
    map_evidence: bool = Field(
        True,
        description="Entering M also needs the SLAM map's agreement (docs/tracking.md, 'Static evidence from the "
        "map'): a mean fraction ≥ map_free_min of the track's points in cells earlier scans passed through, and "
        "≤ map_structure_max on long-occupied cells, over its last sustain_updates updates. Only when the tracker "
        "is given a map (the pipeline gives it the finest level).",
    )
    map_occupied_logodds: float = Field(
        6.0, gt=0.0,
        description="A point's cell is long-occupied structure at this log-odds or above (one hit adds 2.2 with "
        "the default SLAM update factors: 6.0 needs three net hits; a mover's own trail, written while it was "
        "not yet in M, rarely gets there).",
    )
    map_free_logodds: float = Field(
        -0.35, lt=0.0,
        description="A point lies in observed free space when every cell within map_free_radius has log-odds at "
        "or below this (one free pass adds −0.405 with the default SLAM update factors).",
    )
    map_free_radius: int = Field(
        1, ge=0,
        description="Neighbourhood of the free-cell test, cells (1 = 3×3).",
    )
    map_free_min: float = Field(
        0.5, ge=0.0, le=1.0,
        description="Mean fraction of a track's points in observed free cells needed to enter M.",
    )
    map_structure_max: float = Field(
        0.2, ge=0.0, le=1.0,
        description="Largest mean fraction of a track's points on long-occupied cells that still allows entering M.",
    )
    map_structure_exit: float = Field(
        1.0, ge=0.0, le=1.0,
        description="A track in M whose mean fraction of points on long-occupied cells reaches this leaves M "
        "(it has become part of the map's structure).",
    )
    structure_retire_updates: int = Field(
        0, ge=0,
        description="Clutter retirement (issue 9 speed; docs/real.md 'Fewer clutter tracks'): a track never in M and "
        "slower than v_min whose points lay at least structure_retire_fraction on long-occupied map cells "
        "(map_occupied_logodds) in each of its last this many updates leaves the Kalman tracking: the map already "
        "holds it as structure (a wall fragment, furniture), so predicting, associating and updating it each scan "
        "only costs time. A confirmed one stays as a dormant track while its object is seen (within half its box's "
        "longer side plus fit.fragment_margin, at least once per max_coast_time): it is reported at rest with its "
        "object's beams, no live track takes its object's detections on structure, and it comes back to life, "
        "with its id and standing history, when a detection of it has left the structure (a parked mover that "
        "drives off keeps its retroactive erasure). Only with map_evidence and a map. 0 = off (the default: on the "
        "real recording negative_2 /right_scan it changed the map enough for the loop closure to reject its correction "
        "and raised the false removals 0.11 -> 0.43 %, for a pipeline CPU gain of 1-9 %); 2 to use it.",
    )
    structure_retire_fraction: float = Field(
        0.5, ge=0.0, le=1.0,
        description="See structure_retire_updates: the fraction of a track's points on long-occupied map cells "
        "that each of its last structure_retire_updates updates must reach for a still track to be retired.",
    )
    structure_birth_min: float = Field(
        1.1, ge=0.0, le=1.1,
        description="No track is born on a detection with at least this fraction of its points on long-occupied "
        "map cells (structure the map already holds; a new mover's points lie mostly on free or unknown cells); "
        "such a detection joins no track as a fragment, and its place (centroid, half its longer side plus "
        "fit.fragment_margin) is kept while it is seen at least once per max_coast_time: no live track takes a "
        "detection on structure there (a walker in M passing a wall piece whose clutter track was retired does "
        "not take it over). Above 1.0 = off (the default; 0.5 with structure_retire_updates 2). Only with "
        "map_evidence and a map.",
    )
    map_vacate_min_cells: int = Field(
        4, ge=0,
        description="Vacated footprints (docs/maps.md): an outline of long-occupied map cells at most "
        "map_vacate_max_extent long that the current scan sees through in at least this many cells (a vehicle "
        "parked since before the robot saw it, now driving off its outline) counts as observed free, not "
        "structure, for this scan's map evidence; only outlines longer than segment.max_extent (vehicle size: "
        "shorter objects are tracked without the rule). 0 = off.",
    )
    map_vacate_min_depth: float = Field(
        1.0, ge=0.0,
        description="A long-occupied cell counts as seen through by a beam (vacated footprints) only when the beam "
        "and both its neighbours clear at least this far beyond it, m: a wall mapped a few cm off by pose error, or "
        "a chair leg the beam slips past, is passed by a beam that ends right behind it.",
    )
    map_vacate_min_share: float = Field(
        0.2, ge=0.0, le=1.0,
        description="…and only when the scan sees through at least this share of the outline's long-occupied "
        "cells (vacated footprints; a car that started to leave shows a fifth to a quarter of its outline at once).",
    )
    map_vacate_scans: int = Field(
        3, ge=1,
        description="…and only when the same outline (half of its cells) qualified in this many consecutive scans "
        "(vacated footprints).",
    )
    map_vacate_max_extent: float = Field(
        6.0, gt=0.0,
        description="Longest side (along the map's axes) of an outline that can yield as a vacated footprint, m; "
        "a wall's outline is longer and never yields.",
    )
    still_time: float = Field(
        1.0, gt=0.0,
        description="The laser counts as motionless when its pose stayed within still_distance / still_angle over "
        "this long, s; then points on never-observed map cells count as free for map_free_min (a motionless "
        "robot does not update its map, and nothing slides into view).",
    )
    still_distance: float = Field(0.05, ge=0.0, description="See still_time, m.")
    still_angle: float = Field(0.03, ge=0.0, description="See still_time, rad.")
    max_accel: float | None = Field(
        4.0, gt=0.0,
        description="Physical acceleration bound: one update changes an established track's velocity by at most "
        "max_accel·dt, m/s² (people reach ≈1–2 m/s², carts and small robots ≈2–3). None = no bound.",
    )
    accel_bound_after: int = Field(
        4, ge=1,
        description="The acceleration bound applies from this many hits on (a new track first converges to the "
        "speed it was seen at).",
    )
    ride_max_range: float = Field(
        1.0, gt=0.0,
        description="A track within this distance of the laser that stays fixed in the laser frame while it moves "
        "in the map frame rides with the robot (its body) and never enters M, m.",
    )
    ride_tolerance: float = Field(
        0.1, gt=0.0,
        description="Largest spread of such a track's laser-frame centre over its last ride_updates updates (and "
        "least map-frame motion over them), m.",
    )
    ride_updates: int = Field(
        3, ge=2,
        description="Fewest updates over which a track riding with the laser is judged.",
    )
    ride_beam_window: int = Field(
        12, ge=0,
        description="With the robot's body found automatically (detect.footprint.auto), only tracks on beams within "
        "this many beams of a body beam can ride with the robot.",
    )
    ride_time: float = Field(
        0.5, gt=0.0,
        description="Time window of the riding test, s (a person overtaking the robot at 1 m/s relative speed "
        "moves 0.5 m in it; a body part stays within the range noise).",
    )
    map_structure_stop: float = Field(
        0.5, ge=0.0, le=1.0,
        description="A track in M slower than v_exit_ratio·v_min for map_structure_stop_time whose last two "
        "detections have at least this fraction of "
        "points on long-occupied map cells leaves M at once (it merged with a wall; no hysteresis).",
    )
    merge_size_jump: float = Field(
        0.5, gt=0.0,
        description="A track in M whose gate holds a detection longer than its own longer side plus this, with at "
        "least map_structure_stop of the detection's points on long-occupied map cells (and its own points not on "
        "structure), has merged with a wall: it is not updated with it and leaves M at once, m.",
    )
    map_structure_stop_time: float = Field(
        0.5, ge=0.0,
        description="See map_structure_stop, s (a box turning a corner of its route slows down for a moment).",
    )
    aspect_prior: float | None = Field(
        None, gt=0.0, le=1.0,
        description="Width / length ratio assumed for a moving box whose other side was never seen: a side "
        "parallel to the motion is the length, one across it the width (vehicles move along their long "
        "axis). None = no prior (the hidden side keeps FitConfig.default_depth_ratio × the seen side).",
    )
    prior_min_speed: float = Field(
        0.3, ge=0.0,
        description="Speed above which the motion direction is trusted for aspect_prior, m/s.",
    )
    max_object_speed: float = Field(
        6.0, gt=0.0,
        description="Tracks faster than this are deleted as association errors, m/s.",
    )
    max_pose_speed: float = Field(
        5.0, gt=0.0,
        description="A laser pose moving faster than this between scans is a pose jump: all tracks are "
        "dropped (counted), m/s.",
    )
    max_pose_rate: float = Field(
        6.0, gt=0.0,
        description="A laser pose turning faster than this between scans is a pose jump, rad/s.",
    )
    max_dt: float = Field(
        1.0, gt=0.0,
        description="A gap between scans longer than this (or time going backwards) drops all tracks, s.",
    )


class FootprintConfig(BaseModel):
    """The robot's own body in the scan (:mod:`dynslam2d.detect.body`): returns dropped before detection,
    matching and mapping."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    polygon: list[tuple[float, float]] | None = Field(
        None,
        description="Footprint polygon in the laser frame (x forward, y left), vertices in order, m; returns "
        "inside it are the robot's body. None = no footprint. Must be simple with a non-zero area.",
    )
    auto: bool = Field(
        True,
        description="Find beams whose range stays fixed while the laser travels and turns (the robot's body) "
        "and drop their returns; summary.json reports them with a suggested footprint.",
    )
    auto_max_range: float = Field(
        1.0, gt=0.0,
        description="Only returns closer than this can be the robot's body, m.",
    )
    auto_tolerance: float = Field(
        0.06, gt=0.0,
        description="A body beam's range stays within this of its first value, m (range noise of short-range "
        "returns on Hokuyo-class sensors reaches ±4 cm).",
    )
    auto_min_travel: float = Field(
        0.3, gt=0.0,
        description="Distance the laser must travel while a beam's range stays fixed, m.",
    )
    auto_min_turn: float = Field(
        0.3, gt=0.0,
        description="Total rotation the laser must make while a beam's range stays fixed, rad (a wall seen "
        "perpendicular keeps its range under translation, not under rotation).",
    )
    auto_min_scans: int = Field(
        20, ge=1,
        description="A body beam has returned its fixed range in at least this many scans.",
    )
    auto_share: float = Field(
        0.9, gt=0.0, le=1.0,
        description="…and in at least this share of all its returns (a wall seen briefly at a fixed range is not "
        "the body).",
    )
    auto_edge_beams: int = Field(
        4, ge=0,
        description="Beams on either side of a body beam whose returns up to the body's range (+ 2 tolerances) "
        "are dropped too (a body edge is seen part of the time).",
    )
    suggest_margin: float = Field(
        0.05, ge=0.0,
        description="The suggested footprint is the hull of the body returns grown by this, m.",
    )

    @model_validator(mode="after")
    def _check_polygon(self) -> FootprintConfig:
        if self.polygon is not None:
            from dynslam2d.detect.body import polygon_problem

            why = polygon_problem(self.polygon)
            if why is not None:
                raise ValueError(f"footprint polygon {why}; give the vertices in order around the robot, laser "
                                 "frame, m")
        return self


class DetectConfig(BaseModel):
    """Detection and tracking of moving objects: segmentation, shape fit, tracker (nest as ``detect``)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    segment: SegmentConfig = Field(default_factory=SegmentConfig, description="Breakpoint segmentation.")
    fit: FitConfig = Field(default_factory=FitConfig, description="Rectangle / circle / point shape fit.")
    tracker: TrackerConfig = Field(default_factory=TrackerConfig, description="Kalman tracking and the set M.")
    footprint: FootprintConfig = Field(
        default_factory=FootprintConfig, description="The robot's own body: footprint polygon, automatic detection."
    )
    memory: MemoryConfig = Field(
        default_factory=MemoryConfig, description="Track memory through stops and retroactive erasure (docs/maps.md)."
    )

    @model_validator(mode="after")
    def _check(self) -> DetectConfig:
        if self.segment.d_min > self.segment.d_max:
            raise ValueError("segment.d_min must be ≤ segment.d_max")
        if self.tracker.confirm_hits > self.tracker.confirm_window:
            raise ValueError("tracker.confirm_hits must be ≤ tracker.confirm_window")
        if self.fit.circle_min_radius >= self.fit.circle_max_radius:
            raise ValueError("fit.circle_min_radius must be < fit.circle_max_radius")
        return self

    @property
    def lambda_rad(self) -> float:
        return math.radians(self.segment.lambda_deg)
