"""Configuration of the Hector-style SLAM core.

Field names follow the ``hector_mapping`` ROS parameters where one exists
(``map_resolution``, ``map_multi_res_levels`` → ``map_levels``, ``update_factor_free``, …);
the reference defaults are those of hector_mapping's ``HectorMappingRos.cpp`` (``private_nh.param``)
and ``mapping_default.launch``; docs/slam.md maps the names.
Everything that the reference hard-codes (iteration counts, the ±0.2 rad step clamp)
is a parameter here; everything the reference lacks (damped steps, correlative
search, bad-match rejection, bad-input handling) has its own group of fields.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class SlamConfig(BaseModel):
    """Parameters of :class:`dynslam2d.slam.HectorSlam` (units in each description)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    # --- map (hector_mapping map/GridMapLogOdds.h) -------------------------------------
    map_resolution: float = Field(
        0.05, gt=0.0, le=10.0,
        description="Cell side of the finest map level r0, m. hector_mapping node default 0.025, "
        "mapping_default.launch 0.05.",
    )
    map_levels: int = Field(
        3, ge=1, le=8,
        description="Number of map levels (hector 'map_multi_res_levels', node default 3); level k has "
        "resolution map_resolution·2^k and is updated directly from the scan.",
    )
    update_factor_free: float = Field(
        0.4, gt=0.0, lt=0.5,
        description="Occupancy probability of a free observation (reference 0.4 → log-odds −0.405 per "
        "observation), dimensionless.",
    )
    update_factor_occupied: float = Field(
        0.9, gt=0.5, lt=1.0,
        description="Occupancy probability of a hit (reference ROS default 0.9 → log-odds +2.197), "
        "dimensionless.",
    )
    occupied_logodds_cap: float = Field(
        50.0, gt=0.0,
        description="A hit is added only while the cell's log-odds is below this value (reference 50); "
        "the free side is unbounded as in the reference.",
    )
    map_growth_margin: float = Field(
        5.0, gt=0.0,
        description="Extra border added on the side where the map grows, m (the map grows as the robot "
        "explores; no fixed map size). At least 25 % of the current size is added.",
    )
    max_map_memory_mb: float = Field(
        2048.0, gt=0.0,
        description="Memory limit of all map levels, MB. A scan whose integration would grow the map "
        "beyond it is not integrated (counted as 'map_too_large') instead of exhausting memory.",
    )
    clear_no_return_dist: float = Field(
        0.0, ge=0.0,
        description="If > 0, beams without a return mark cells free along the beam up to this distance, m. "
        "The reference never traces no-return beams (0 = off, the reference behaviour).",
    )
    grazing_stop_cells: float = Field(
        0.0, ge=0.0,
        description="If > 0, a return's free-space update stops grazing_stop_cells / sin(α) cells before its "
        "endpoint, α = incidence on the surface it hit (estimated from the neighbouring returns): rays "
        "running along a wall do not clear the wall cells other rays hit (docs/maps.md, 'Walls seen at "
        "grazing incidence'). 0 = the reference's update (every cell before the endpoint free).",
    )
    written_grazing_stop_cells: float = Field(
        0.0, ge=0.0,
        description="If > 0, the written maps (map.pgm, map_online.pgm, map_logodds.npy, metrics) are rendered "
        "again after the run from the loop closure's keyframes at their final poses with the free-space "
        "update stopped written_grazing_stop_cells / sin(α) cells before each return (as grazing_stop_cells), "
        "while the map the matcher used during the run keeps grazing_stop_cells: the trajectory does not "
        "change (docs/maps.md, 'Walls seen at grazing incidence'). Needs loop closure (its keyframes); with "
        "--loop-closure off the written map is the online map. 0 (default) = the online map as the matcher "
        "built it; 1 lifts stop-and-go's map F1 0.9765 -> 0.9901 but leaves a few more people's cells.",
    )
    grazing_min_incidence_deg: float = Field(
        5.0, gt=0.0, le=90.0,
        description="Incidence below this counts as this in grazing_stop_cells, degrees (bounds the stop at "
        "grazing_stop_cells / sin(5°) ≈ 11.5 · grazing_stop_cells cells).",
    )

    # --- range gates (HectorMappingRos.cpp) ------------------------------------------
    laser_min_dist: float = Field(
        0.4, ge=0.0,
        description="Returns closer than this are dropped, m (reference 0.4).",
    )
    laser_max_dist: float = Field(
        30.0, gt=0.0,
        description="Returns farther than this are dropped, m (reference 30.0; also the projectLaser cut-off).",
    )

    # --- map update thresholds (HectorSlamProcessor::update) ---------------------------
    map_update_distance_thresh: float = Field(
        0.4, ge=0.0,
        description="Translation since the last map update needed before a scan is integrated, m "
        "(reference 0.4).",
    )
    map_update_angle_thresh: float = Field(
        0.06, ge=0.0,
        description="Rotation since the last map update needed before a scan is integrated, rad "
        "(mapping_default.launch 0.06; the bare node uses 0.9).",
    )

    # --- scan matcher (hector_mapping matcher/ScanMatcher.h) ---------------------------
    iterations_coarse: int = Field(
        4, ge=0, le=100,
        description="Gauss–Newton steps on every coarse level (reference: 1 + 3 = 4).",
    )
    iterations_finest: int = Field(
        6, ge=0, le=100,
        description="Gauss–Newton steps on the finest level (reference: 1 + 5 = 6).",
    )
    hector_gradient_bug: bool = Field(
        False,
        description="Reproduce the reference's swapped bilinear gradient weights (OccGridMapUtil::"
        "interpMapValueWithDerivatives, hector_slam issue #16) for bit-faithful comparison; "
        "False = the mathematically correct gradient.",
    )
    step_mode: Literal["lm", "gauss_newton"] = Field(
        "lm",
        description="'lm': Levenberg–Marquardt with a bounded step, accepted only if the cost drops; "
        "'gauss_newton': the reference's raw H⁻¹g step (still with the step bounds below).",
    )
    max_rotation_step: float = Field(
        0.2, gt=0.0,
        description="Clamp of the rotation part of one step, rad (reference 0.2).",
    )
    max_translation_step: float = Field(
        2.0, gt=0.0,
        description="Bound on the translation part of one step, in cells of the level being matched "
        "(the reference has none; GN only sees about ±1 cell).",
    )
    lm_lambda_init: float = Field(
        0.1, gt=0.0,
        description="Initial Levenberg–Marquardt damping, relative to diag(H), dimensionless (÷10 after "
        "an accepted step, ×10 after a rejected one). 0.1 converges within the reference's 4/4/6 steps "
        "where 1e-3 (nearly plain GN) oscillates around the optimum.",
    )
    lm_lambda_max: float = Field(
        1e4, gt=0.0,
        description="Damping above which the LM iterations on a level stop, dimensionless.",
    )
    covariance_sigma: float | None = Field(
        None, gt=0.0,
        description="Scale σ of the covariance σ²·H⁻¹ (probability units). None = estimated from the "
        "residuals of the final match (Σr²/(n−3)).",
    )

    # --- correlative search (Olson 2009, real-time correlative scan matching) ---------
    correlative_mode: Literal["auto", "always", "never"] = Field(
        "auto",
        description="When to seed Gauss–Newton with a correlative search: 'auto' = after large motion, "
        "a time gap, a rejected scan or a poor match; 'always'; 'never' (the reference).",
    )
    correlative_level: int = Field(
        1, ge=0,
        description="Map level searched by the correlative matcher (0 = finest); clipped to map_levels−1.",
    )
    correlative_linear_window: float = Field(
        0.6, ge=0.0,
        description="Half-width of the translation search window around the start estimate, m.",
    )
    correlative_angular_window: float = Field(
        0.9, ge=0.0, le=math.pi,
        description="Half-width of the rotation search window around the start estimate, rad "
        "(the MIT CSAIL log turns up to 0.8 rad between scans).",
    )
    correlative_angular_step: float | None = Field(
        None, gt=0.0,
        description="Rotation step of the search, rad. None = Olson's rule: the farthest used point moves "
        "at most one cell of the searched level.",
    )
    correlative_max_points: int = Field(
        240, ge=10,
        description="Points used by the correlative search (evenly subsampled), count.",
    )
    correlative_max_height: int = Field(
        4, ge=0, le=10,
        description="Number of branch-and-bound levels (translation blocks of 2^h cells).",
    )
    correlative_translation_weight: float = Field(
        0.05, ge=0.0,
        description="Penalty on the searched translation offset, score per m² (breaks ties towards the "
        "start estimate).",
    )
    correlative_rotation_weight: float = Field(
        0.05, ge=0.0,
        description="Penalty on the searched rotation offset, score per rad².",
    )
    correlative_trigger_distance: float = Field(
        0.15, ge=0.0,
        description="'auto' mode: search when the previous inter-scan motion exceeded this translation, m.",
    )
    correlative_trigger_angle: float = Field(
        0.08, ge=0.0,
        description="'auto' mode: search when the previous inter-scan motion exceeded this rotation, rad.",
    )
    search_on_motion_with_odometry: bool = Field(
        False,
        description="'auto' mode: keep the motion trigger (correlative_trigger_distance / _angle) when the start "
        "estimate is the odometry's prediction. False (default): odometry already predicts the motion, so a "
        "large previous motion alone is no sign the start is wrong (MIT CSAIL: 1794 of 1988 scans searched, 43 "
        "moved by > 2 cm or 1°); the other triggers — a poor match (poor_match_ratio), a time gap, a rejected "
        "or skipped previous scan, the first matches, and the large-motion recovery — still fire. Laser-only, "
        "IMU and motion-model starts always keep the motion trigger.",
    )
    poor_match_ratio: float = Field(
        0.85, ge=0.0, le=1.0,
        description="'auto' mode: search when the match score falls below this fraction of the running "
        "score average.",
    )

    # --- prediction -------------------------------------------------------------------
    constant_velocity: bool = Field(
        False,
        description="Start estimate = previous pose advanced by the last velocity (constant-velocity model). "
        "False = the reference's previous pose (zero-motion model).",
    )

    # --- bad match / bad input --------------------------------------------------------
    min_points: int = Field(
        20, ge=2,
        description="Scans with fewer valid returns after the range gates are skipped (counted), count.",
    )
    reject_score_ratio: float = Field(
        0.35, ge=0.0, le=1.0,
        description="A match whose score is below this fraction of the running score average is not "
        "written into the map (score collapse). Unknown cells score 0.5 and free cells ≤ 0.4, so "
        "exploring new space alone does not trigger it.",
    )
    reject_score_min: float = Field(
        0.05, ge=0.0, le=1.0,
        description="A match whose score (mean occupancy probability at the endpoints, finest level) is "
        "below this is not written into the map.",
    )
    reject_free_fraction: float = Field(
        0.5, ge=0.0, le=1.0,
        description="A match is not written into the map when more than this fraction of its endpoints "
        "fall in space the map knows to be free (interpolated p < 0.45 on level 1). Good matches "
        "measured: ≤ 0.27 on MIT CSAIL, ≤ 0.15 in the simulated crowd.",
    )
    max_jump_distance: float = Field(
        1.5, gt=0.0,
        description="A match further than this from its start estimate is rejected (pose = start estimate), m.",
    )
    max_jump_angle: float = Field(
        1.3, gt=0.0,
        description="A match rotated more than this from its start estimate is rejected, rad.",
    )
    max_time_gap: float = Field(
        1.0, gt=0.0,
        description="A gap between scan stamps above this (or a stamp going backwards) is counted as a "
        "time gap: the velocity is reset and a correlative search is run, s.",
    )
    score_average_rate: float = Field(
        0.1, gt=0.0, le=1.0,
        description="Rate of the exponential running average of accepted match scores, dimensionless.",
    )

    # --- motion prior, degeneracy, gating, lost / found ------------------------------
    use_odometry: bool = Field(
        True,
        description="Use the scans' odometry (Scan.odom: the odometry delta between consecutive scans "
        "seeds the match and is the prior along degenerate directions) and IMU yaw rate (Scan.yaw_rate: "
        "the rotation prior) when they carry them. False = laser only.",
    )
    degeneracy_threshold: float = Field(
        0.045, ge=0.0, le=1.0,
        description="A direction of the match Hessian is degenerate (the scan cannot constrain it, e.g. a "
        "corridor's axis) when its eigenvalue is below this fraction of the largest: translation and "
        "rotation (scaled by the RMS point range) each with the other marginalized. Dimensionless; "
        "measured: ≤ 0.037 in a corridor seeing only its side walls, ≥ 0.058 on every MIT CSAIL scan. 0 = never.",
    )
    prior_weight: float = Field(
        1.0, ge=0.0,
        description="Stiffness of the motion prior along degenerate directions, in units of the largest "
        "Hessian eigenvalue (the prior holds there; along well-constrained directions the scan "
        "decides). 0 = no prior.",
    )
    odometry_prior: Literal["degenerate", "all"] = Field(
        "degenerate",
        description="How odometry enters the match: 'degenerate' = only along directions the scan cannot "
        "constrain (stiffness prior_weight); 'all' = on every direction, weighted by the odometry noise "
        "model (odometry_noise_*) against the scan's own information.",
    )
    odometry_noise_translation: float = Field(
        0.05, gt=0.0,
        description="Odometry noise model: standard deviation of the translation per metre travelled (m/m).",
    )
    odometry_noise_rotation: float = Field(
        0.05, gt=0.0,
        description="Odometry noise model: standard deviation of the heading per radian turned (rad/rad).",
    )
    odometry_noise_floor_xy: float = Field(
        0.01, gt=0.0,
        description="Odometry noise model: translation standard deviation per step at rest, m.",
    )
    odometry_noise_floor_theta: float = Field(
        0.005, gt=0.0,
        description="Odometry noise model: heading standard deviation per step at rest, rad.",
    )
    motion_prior: bool = Field(
        True,
        description="Without odometry, the constant-velocity prediction is the prior along degenerate "
        "directions (and the IMU yaw rate along rotation). False = degenerate directions follow the scan alone.",
    )
    velocity_window: float = Field(
        0.5, gt=0.0,
        description="The motion model's velocity is the motion between accepted poses over the last this "
        "many seconds, s.",
    )
    max_linear_accel: float = Field(
        1.5, gt=0.0,
        description="Motion model: largest linear acceleration of the robot, m/s². A match that deviates "
        "from the prediction by more than max_linear_accel·dt·(velocity_window/2 + dt) + gate_distance "
        "must be backed by enough structure.",
    )
    max_angular_accel: float = Field(
        3.0, gt=0.0,
        description="Motion model: largest angular acceleration, rad/s² (gate: "
        "max_angular_accel·dt·(velocity_window/2 + dt) + gate_angle).",
    )
    gate_distance: float = Field(
        0.05, ge=0.0,
        description="Deviation from the predicted position always allowed (velocity estimate noise), m.",
    )
    gate_angle: float = Field(
        0.05, ge=0.0,
        description="Deviation from the predicted heading always allowed, rad.",
    )
    support_min_points: int = Field(
        30, ge=0,
        description="A match is well supported with at least this many endpoints on occupied map cells "
        "(p > support_probability), count. The datmo car's scans (100–130 returns) confirm 30–60.",
    )
    support_min_spread: float = Field(
        1.0, ge=0.0, le=2.0 * math.pi,
        description="… whose bearings cover at least this angle (5° bins), rad.",
    )
    support_probability: float = Field(
        0.6, gt=0.5, lt=1.0,
        description="Interpolated occupancy probability above which an endpoint counts as matched.",
    )
    too_close_fraction: float = Field(
        0.5, ge=0.0, le=1.0,
        description="A scan whose returns are more than this fraction closer than laser_min_dist (something "
        "pressed against the sensor) never moves the pose: the pose is predicted, the map not updated.",
    )
    min_sector: float = Field(
        0.6, ge=0.0, le=2.0 * math.pi,
        description="A scan whose gated returns cover less than this angle (5° bins) never moves the pose, rad.",
    )
    lost_after: float = Field(
        1.0, gt=0.0,
        description="After this long without a supported match the processor is lost: it predicts, keeps "
        "the scans out of the map and relocalises with a wide search once structure returns, s.",
    )
    relocalise_linear_window: float = Field(
        2.0, ge=0.0,
        description="Half-width of the relocalisation search window (translation), m.",
    )
    relocalise_angular_window: float = Field(
        math.pi, ge=0.0, le=math.pi,
        description="Half-width of the relocalisation search window (rotation), rad.",
    )
    relocalise_interval: float = Field(
        0.3, ge=0.0,
        description="While lost, a relocalisation search is tried at most once per this interval, s "
        "(the wide search costs tens of ms).",
    )
    relocalise_margin: float = Field(
        0.08, ge=0.0, le=1.0,
        description="A relocalisation is accepted only if its correlative score beats the best pose "
        "farther than 0.5 m / 0.3 rad from it by this much (score units 0 … 1).",
    )
    relocalise_min_score: float = Field(
        0.35, ge=0.0, le=1.0,
        description="… and its correlative score is at least this (score units 0 … 1).",
    )
    relocalise_runner_up_wrap: bool = Field(
        True,
        description="The relocalisation's runner-up neighbourhood (0.3 rad) wraps around the circle: its ±π search "
        "holds the best pose turned by 2π, which without the wrap is its own runner-up (margin 0) whenever the "
        "answer lies within 0.3 rad of the prediction ± π; false = the behaviour before (docs/slam.md, "
        "\"Large motion between scans\").",
    )
    low_confidence_share: float = Field(
        0.05, ge=0.0, le=1.0,
        description="Runs where more than this share of the scans is matched with low support (or lost), or "
        "with a stretch longer than low_confidence_stretch, are reported as not trustworthy.",
    )
    low_confidence_stretch: float = Field(
        2.0, gt=0.0,
        description="Longest tolerated stretch of low-support or lost scans before the warning, s.",
    )
    jump_shift: float = Field(
        0.25, ge=0.0,
        description="A scan whose front-end step from the previous scan exceeds the motion of the three steps before "
        "it by this much, and by jump_ratio × that motion's step, is a jump: the front end snapped back after "
        "drifting (slam/jumps.py; not max_jump_distance, which rejects a match). The motion is predicted twice, as "
        "their median velocity × its time step and as their median step (for logs whose stamps do not follow the "
        "motion), and the step must exceed both. Jumps make the run not trustworthy and, with loop.jump_weak, "
        "weaken the keyframe edge across them; m, map frame (0 = off). Largest excess on the real recordings "
        "without a jump: 0.23 m = 2.0 steps (datmo overtakes), 0.35 m = 1.9 steps (MIT CSAIL); negative_2's snap "
        "back: 0.55 m = 5.3 steps.",
    )
    jump_ratio: float = Field(
        3.0, ge=0.0,
        description="… and at least this many times the length of the step the motion before it predicts.",
    )
    jump_turn: float = Field(
        0.0, ge=0.0,
        description="A scan whose rotation step exceeds the rotation before it by this much is a jump too, rad (0 = "
        "off: at MIT CSAIL's 4.8 Hz the robot's own turning changes by up to 26° from one scan to the next).",
    )

    # --- large-motion recovery (slam/recovery.py; docs/slam.md "Large motion between scans") ---
    recovery: bool = Field(
        True,
        description="Large-motion recovery: after a stamp gap or a weak match, search a window grown with the gap "
        "around the last pose and around the velocity kept across the gap (correlative branch and bound, best and "
        "runner-up refined by Gauss–Newton); switch only on a clear score margin, keep an ambiguous match out of "
        "the map, and floor the motion gate's dt at the median scan period (docs/slam.md).",
    )
    recovery_min_gap: float = Field(
        0.25, gt=0.0,
        description="Recovery runs when the previous scan is more than this far back in time, s.",
    )
    recovery_score_ratio: float = Field(
        0.0, ge=0.0, le=1.0,
        description="… or when the match score is below this fraction of the running score average (0: stamp gaps "
        "only, the default: at 0.6 weak matches on the datmo parallel bag triggered it and its ATE rose from 0.163 "
        "to 0.183 m, while the Intel result is the same either way).",
    )
    recovery_linear_window: float = Field(
        0.5, ge=0.0,
        description="Translation half-width of the recovery search at no gap, m.",
    )
    recovery_linear_speed: float = Field(
        1.0, ge=0.0,
        description="The translation window grows by this × the gap (largest speed), m/s.",
    )
    recovery_max_linear_window: float = Field(
        1.2, ge=0.0,
        description="Cap of the translation window, m.",
    )
    recovery_angular_window: float = Field(
        0.9, ge=0.0, le=math.pi,
        description="Rotation half-width of the recovery search at no gap, rad.",
    )
    recovery_angular_speed: float = Field(
        1.0, ge=0.0,
        description="The rotation window grows by this × the gap (largest turn rate), rad/s.",
    )
    recovery_max_angular_window: float = Field(
        math.pi, ge=0.0, le=math.pi,
        description="Cap of the rotation window, rad.",
    )
    recovery_margin: float = Field(
        0.03, ge=0.0, le=1.0,
        description="A recovered match is ambiguous (pose kept, scan out of the map) unless its refined score "
        "beats the best distinct alternative by this much (mean occupancy probability, 0 … 1).",
    )
    recovery_switch_margin: float = Field(
        0.1, ge=0.0, le=1.0,
        description="The recovery replaces the front end's own match only by a distinct pose whose refined score is "
        "higher by this much (mean occupancy probability, 0 … 1).",
    )
    recovery_motion_weight: float = Field(
        0.2, ge=0.0,
        description="With a velocity, a recovery candidate's score is lowered by this × its squared distance from "
        "the velocity's prediction, score per m².",
    )
    recovery_motion_angle_weight: float = Field(
        0.05, ge=0.0,
        description="… and by this × its squared heading deviation, score per rad².",
    )
    recovery_distinct_distance: float = Field(
        0.3, gt=0.0,
        description="Alternatives farther than this from the winner count as distinct, m.",
    )
    recovery_distinct_angle: float = Field(
        0.2, gt=0.0,
        description="… or rotated more than this, rad.",
    )
    recovery_runner_up_wrap: bool = Field(
        True,
        description="The recovery search's runner-up neighbourhood wraps around the circle: a window grown to ±π "
        "(gaps above 2.2 s) or just short of it holds the best pose (nearly) turned by 2π, which without the wrap "
        "is taken as the runner-up and refines back onto the best pose, so the real alternative is never seeded "
        "and the margin is overstated; false = the behaviour before (docs/slam.md, \"Large motion between scans\").",
    )

    @model_validator(mode="after")
    def _check(self) -> SlamConfig:
        if self.laser_max_dist <= self.laser_min_dist:
            raise ValueError(
                f"laser_max_dist ({self.laser_max_dist}) must exceed laser_min_dist ({self.laser_min_dist})"
            )
        return self

    @property
    def logodds_free(self) -> float:
        """Log-odds added per free observation: logit(update_factor_free) (hector_mapping GridMapLogOdds.h)."""
        p = self.update_factor_free
        return math.log(p / (1.0 - p))

    @property
    def logodds_occupied(self) -> float:
        """Log-odds added per hit: logit(update_factor_occupied) (hector_mapping GridMapLogOdds.h)."""
        p = self.update_factor_occupied
        return math.log(p / (1.0 - p))
