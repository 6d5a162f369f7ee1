"""Configuration of loop closure and pose-graph optimisation (docs/slam.md, "Loop closure")."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class LoopConfig(BaseModel):
    """Parameters of :mod:`dynslam2d.slam.loops` and :mod:`dynslam2d.slam.posegraph` (units in each
    description)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    enabled: bool = Field(
        True,
        description="Close loops and optimise the pose graph behind the front end: trajectory.tum and the map "
        "come from the optimised poses, trajectory_frontend.tum keeps the front end's (CLI --loop-closure on|off; "
        "off = the front end alone, unchanged).",
    )
    submap_keyframes: int = Field(
        10, ge=2,
        description="Keyframes (scans written into the map) per submap; loops are searched against finished submaps.",
    )
    submap_max_range: float = Field(
        20.0, gt=0.0,
        description="Returns farther than this are left out of the submaps and of the loop queries, m.",
    )
    search_every: int = Field(
        2, ge=1,
        description="Search for loops on every this-many-th keyframe.",
    )
    min_path_gap: float = Field(
        6.0, ge=0.0,
        description="A submap is a loop candidate only if the robot travelled at least this far since the "
        "submap's last keyframe, m (closer ones are linked by the keyframe chain already).",
    )
    search_radius: float = Field(
        2.0, gt=0.0,
        description="Submaps whose centre keyframe lies within this distance of the current pose estimate are "
        "searched, m, grown by drift_per_m × the path travelled since the submap.",
    )
    drift_per_m: float = Field(
        0.02, ge=0.0,
        description="Position uncertainty of the front end per metre travelled (grows the search), m/m.",
    )
    max_search_radius: float = Field(
        6.0, gt=0.0,
        description="Cap of the grown search radius, m.",
    )
    linear_window: float = Field(
        1.0, gt=0.0,
        description="Translation window of the correlative (branch-and-bound) search around the predicted "
        "pose, m, grown like the search radius up to max_linear_window.",
    )
    max_linear_window: float = Field(
        3.0, gt=0.0,
        description="Cap of the grown translation window, m.",
    )
    angular_window: float = Field(
        0.35, gt=0.0,
        description="Rotation window of the correlative search, rad (plus drift_rad_per_m × path).",
    )
    drift_rad_per_m: float = Field(
        0.002, ge=0.0,
        description="Heading uncertainty of the front end per metre travelled, rad/m.",
    )
    max_angular_window: float = Field(
        0.8, gt=0.0,
        description="Cap of the grown rotation window, rad.",
    )
    far_search: bool = Field(
        True,
        description="Also search older submaps beyond the local radius, within a radius grown with the pose "
        "uncertainty accumulated along the graph's shortest path to them (docs/slam.md, 'Loop search').",
    )
    far_after: float = Field(
        20.0, ge=0.0,
        description="Far searches only once the robot travelled this far since the last accepted loop, m "
        "(while loops keep being found the local search suffices).",
    )
    far_level: int = Field(
        3, ge=0,
        description="Submap level of the far search (coarser than search_level: it covers every rotation).",
    )
    far_sigmas: float = Field(
        3.0, gt=0.0,
        description="The far radius is search_radius + this × the summed translation deviations of the edges "
        "on the graph's shortest path (keyframe chain and accepted loops) from the submap to the keyframe "
        "(dimensionless).",
    )
    far_weak_turn: float = Field(
        0.2, ge=0.0,
        description="Heading deviation a keyframe edge across a weak match (predicted, relocalised, weakly supported "
        "or after a time gap) adds to the far search's heading uncertainty, rad; elsewhere drift_rad_per_m × "
        "length. A far candidate may correct the heading by angular_window + far_sigmas × the smallest sum of "
        "these deviations along the graph.",
    )
    max_far_radius: float = Field(
        80.0, gt=0.0, description="Cap of the far radius, m."
    )
    far_searches: int = Field(
        4, ge=0,
        description="Far submaps searched per searched keyframe (the first far_searches by far_rank), count.",
    )
    far_max_place_distance: float = Field(
        0.66, ge=0.0, le=2.0,
        description="The far search during the run skips a submap (of the far_searches it would search) whose place "
        "distance to the keyframe's place is above this (place-descriptor distance, 0 … 2, smaller = more alike; the "
        "smallest over the places stored at the submap's keyframes and those after it whose window still holds its "
        "anchor): such searches found nothing on the recordings measured (docs/slam.md, 'Place descriptor'). 2 = off "
        "(every one searched, as before). Only with far_rank: descriptor; the second search is not capped.",
    )
    far_best_place_distance: float = Field(
        0.74, ge=0.0, le=2.0,
        description="… except the best-ranked of them (the most alike), searched up to this place distance (or "
        "far_max_place_distance if larger): a true loop to a place that looks unlike every stored one is still the "
        "most alike of them (negative_2 /left_scan: 0.686).",
    )
    far_margin: float = Field(
        3.0, ge=0.0,
        description="A far search covers the submap's keyframes' extent around its anchor plus this much, m "
        "(over every rotation).",
    )
    far_rank: Literal["descriptor", "oldest"] = Field(
        "descriptor",
        description="Which far_searches submaps a keyframe searches among those within the far radius: "
        "'descriptor' = the submaps whose keyframes' place descriptors (slam/placedesc.py, after Scan Context) "
        "look most like this keyframe's, 'oldest' = the least recently searched ones (round robin).",
    )
    place_keyframes: int = Field(
        20, ge=1,
        description="A keyframe's place descriptor describes the returns of this many keyframes up to it (itself "
        "included), placed with the front end's relative poses in its laser frame (count).",
    )
    place_every: int = Field(
        2, ge=1,
        description="Every this-many-th keyframe stores its place descriptor (a submap's distance to a query is "
        "the smallest over its stored keyframes).",
    )
    place_rings: int = Field(20, ge=1, description="Range rings of the place descriptor (count).")
    place_sectors: int = Field(60, ge=4, description="Bearing sectors of the place descriptor (count).")
    place_max_range: float = Field(
        15.0, gt=0.0, description="Returns farther than this from the keyframe are left out of its descriptor, m."
    )
    far_min_margin: float = Field(
        0.15, ge=0.0,
        description="Score margin over the runner-up a far candidate needs (instead of min_margin).",
    )
    far_partner_span: float = Field(
        1.0, ge=0.0,
        description="… and the far candidate's and its partners' keyframes must span at least this much path, m "
        "(scans taken turning on the spot are not independent evidence: a corner matches another corner "
        "turned by 90°).",
    )
    far_partners: int = Field(
        2, ge=1,
        description="Consistent partner candidates (within consistency_window keyframes) a far candidate needs.",
    )
    tracked_linear_window: float = Field(
        0.3, gt=0.0,
        description="Translation window when a loop was accepted within consistency_window keyframes (its "
        "prediction is good), m.",
    )
    tracked_search_every: int = Field(
        3, ge=1,
        description="While loops keep being found (one within consistency_window keyframes), search only every "
        "this-many-th keyframe, and only the nearest submap.",
    )
    tracked_angular_window: float = Field(
        0.1, gt=0.0, description="Rotation window in that case, rad."
    )
    search_level: int = Field(
        2, ge=0,
        description="Submap level of the correlative search (0 = finest, each level doubles the cell size).",
    )
    search_points: int = Field(
        180, ge=10,
        description="Query points used by the correlative search (evenly sub-sampled; all of them, up to 360, "
        "refine the match and count the support), count.",
    )
    min_score: float = Field(
        0.55, ge=0.0, le=1.0,
        description="Smallest correlative score (mean smeared hit value of the query points, 0 … 1) of a loop.",
    )
    min_margin: float = Field(
        0.08, ge=0.0,
        description="The best pose must beat the best pose farther than runner_up_distance / runner_up_angle "
        "by this much score (a corridor gives two equal answers).",
    )
    runner_up_distance: float = Field(
        0.6, gt=0.0, description="Distance beyond which another pose counts as the runner-up, m."
    )
    runner_up_angle: float = Field(
        0.25, gt=0.0, description="Rotation beyond which another pose counts as the runner-up, rad."
    )
    runner_up_wrap: bool = Field(
        True,
        description="The runner-up's rotation neighbourhood wraps around the circle (a far search covers every "
        "rotation, and the best pose turned by 2π is no runner-up); false = the behaviour before (the margin of "
        "every far match was then ~0).",
    )
    min_support: int = Field(
        80, ge=0,
        description="Query points that must land on occupied submap cells at the refined pose (count).",
    )
    min_support_share: float = Field(
        0.55, ge=0.0, le=1.0,
        description="… and at least this share of the query points.",
    )
    min_spread: float = Field(
        2.0, ge=0.0,
        description="Bearings of the supporting points must cover at least this angle, rad.",
    )
    max_degeneracy: float = Field(
        0.0, ge=0.0,
        description="Refuse loops whose match Hessian has a smallest/largest eigenvalue ratio below this "
        "(0 = off; a corridor constrains only one direction).",
    )
    consistency_window: int = Field(
        8, ge=0,
        description="A loop candidate is accepted once another candidate within this many keyframes implies "
        "the same correction of the front end's pose (0 = accept single candidates).",
    )
    consistency_distance: float = Field(
        0.15, gt=0.0, description="… the same correction within this translation, m."
    )
    consistency_angle: float = Field(
        0.03, gt=0.0, description="… and this rotation, rad."
    )
    odom_sigma_xy: float = Field(
        0.01, gt=0.0, description="Standard deviation of a keyframe-to-keyframe edge, m, plus odom_sigma_per_m × its "
                                  "length."
    )
    odom_sigma_per_m: float = Field(
        0.02, ge=0.0, description="Growth of that deviation with the edge's length, m/m."
    )
    odom_sigma_theta: float = Field(
        0.004, gt=0.0, description="Standard deviation of a keyframe edge's rotation, rad, plus "
                                   "odom_sigma_theta_per_rad × |Δθ|."
    )
    odom_sigma_theta_per_rad: float = Field(
        0.02, ge=0.0, description="Growth of the rotation deviation with the edge's rotation, rad/rad."
    )
    weak_score: float = Field(
        0.6, ge=0.0, le=1.0,
        description="A keyframe edge across a scan whose match score (mean occupancy at the endpoints) is below this "
        "gets a larger deviation, growing linearly to ten times at weak_score_floor (0 = off): the loop corrections "
        "bend the graph where the front end matched poorly.",
    )
    weak_robust: bool = Field(
        True,
        description="Keyframe edges across a weak match (predicted, relocalised, weakly supported, after a time gap) "
        "are under the loops' robust kernel too: where the loops say the front end broke, the graph bends there "
        "instead of spreading the correction over every edge.",
    )
    jump_weak: bool = Field(
        False,
        description="A keyframe edge across a front-end jump (slam.jump_shift, jump_ratio, jump_turn: the front end "
        "snapped back after drifting) is weak like one across a weakly supported match, so loops can undo the drift "
        "before it instead of keeping the jump as motion. Off by default: on negative_2 /right_scan it brings the "
        "drifted keyframes from 0.36–0.61 m to ≤ 0.09 m, but spreads 2° into an earlier visit and the clean-up "
        "then erases more (docs/slam.md, \"negative_2: the stretch that maps walls twice\").",
    )
    weak_score_floor: float = Field(
        0.3, ge=0.0, le=1.0, description="Match score at which a keyframe edge's deviation is ten times larger."
    )
    rematch: bool = Field(
        True,
        description="After the final optimisation (when a loop stayed active), re-match every keyframe against the "
        "map of the rematch_window keyframes before it at their optimised poses and add an edge where the match "
        "disagrees with the chain: repairs local breaks of the front end that no loop spans (slam/rematch.py).",
    )
    rematch_window: int = Field(10, ge=1, description="Keyframes before a keyframe that its re-match map holds.")
    rematch_all: bool = Field(
        False, description="Re-match every keyframe (else only those near where the front end was unsure or the "
        "optimisation bent the chain: rematch_score, rematch_bend_shift / rematch_bend_turn, rematch_neighbours).")
    rematch_reuse: int = Field(
        0, ge=0, description="Keyframes by which the re-match's local map may grow (kept for the next keyframe, with "
        "the keyframes in between added) before it is rebuilt from rematch_window keyframes; 0: rebuilt for each.")
    rematch_score: float = Field(
        0.6, ge=0.0, le=1.0, description="A keyframe edge across a weak match, or a scan whose match score is below "
        "this (or not given), marks its keyframe for the re-match.")
    rematch_bend_shift: float = Field(
        0.05, ge=0.0, description="… as does an edge whose optimised relative pose differs from the front end's by "
        "more than this, m …")
    rematch_bend_turn: float = Field(0.02, ge=0.0, description="… or this, rad.")
    rematch_neighbours: int = Field(
        2, ge=0, description="Keyframes before and after a marked one that are re-matched with it.")
    rematch_linear_window: float = Field(
        1.0, gt=0.0, description="Half-width of the re-match's correlative search around the chain's pose, m.")
    rematch_angular_window: float = Field(
        0.3, gt=0.0, description="Half-width of the re-match's correlative search in rotation, rad.")
    rematch_min_shift: float = Field(
        0.1, ge=0.0, description="A re-match becomes an edge only if it moves the keyframe by more than this, m …")
    rematch_min_turn: float = Field(0.05, ge=0.0, description="… or turns it by more than this, rad.")
    rematch_replace: bool = Field(
        True, description="A re-match edge switches off the chain edge it disagrees with (else both stay, robust).")
    second_search: bool = Field(
        True,
        description="After the final optimisation and the re-match, search far once more from every stored place "
        "against the older submaps the graph does not tie yet (every path along the graph crosses a weak or "
        "low-scoring front-end match), from the improved poses; verified loops are added and the graph optimised "
        "again (slam/secondsearch.py).",
    )
    second_searches: int = Field(
        4, ge=0, description="Submaps searched per keyframe by the second search (the most alike places first).")
    second_partner_span: float = Field(
        0.8, ge=0.0,
        description="far_partner_span of the second search, m (its candidates have passed the place ranking against "
        "a graph whose poses the loops already corrected).",
    )
    second_optimise_each: bool = Field(
        False,
        description="The second search optimises the graph after each loop it verifies, as the run's far search does "
        "(false: only after the round).",
    )
    second_cache: int = Field(
        24, ge=1,
        description="Submap grids kept built during the second search (count; each a few MB; the search jumps between "
        "places, so fewer are rebuilt than with the run's six).",
    )
    second_rematch: bool = Field(
        False, description="After a second-search round that added loops, re-match the keyframes again (rematch_*).")
    second_rounds: int = Field(
        2, ge=1, description="Rounds of the second search at most: the first from every stored place, each next one "
        "(only after a round that added loops) from the keyframes whose far candidates the round before could not "
        "verify.")
    loop_sigma_xy: float = Field(0.03, gt=0.0, description="Standard deviation of a loop edge's translation, m.")
    loop_sigma_theta: float = Field(0.006, gt=0.0, description="Standard deviation of a loop edge's rotation, rad.")
    kernel: Literal["dcs", "cauchy", "none"] = Field(
        "dcs",
        description="Robust kernel of loop edges: dcs (dynamic covariance scaling, the closed form of switchable "
        "constraints), cauchy, or none.",
    )
    kernel_scale: float = Field(
        5.0, gt=0.0, description="Φ of dcs / c of cauchy, in χ² (dcs) or χ (cauchy) units of the loop edge."
    )
    outlier_chi2: float = Field(
        30.0, gt=0.0,
        description="After optimising, loop edges whose χ² (eᵀΩe) is still above this are switched off and the "
        "graph optimised again.",
    )
    optimise_every: int = Field(
        20, ge=1,
        description="Optimise during the run after this many newly accepted loops (a final full optimisation "
        "always runs).",
    )
    map_check: bool = Field(
        True,
        description="Keep the optimised poses only if the map re-rendered from them is sharper than the front "
        "end's map (lower total occupancy entropy); otherwise trajectory.tum and the map stay the front end's. "
        "A Hector-style front end that matched every revisit against its global map is often already as "
        "consistent as the loops can make it.",
    )
    min_correction: float = Field(
        0.05, ge=0.0,
        description="Keep the front end's poses when the optimisation moves no keyframe by more than this, m: a "
        "correction below the loops' own accuracy is noise, not drift.",
    )
    map_check_margin: float = Field(
        0.0, ge=0.0,
        description="… sharper by at least this fraction of the front end map's entropy (dimensionless).",
    )
    iterations: int = Field(30, ge=1, description="Largest number of Gauss–Newton/LM iterations per optimisation.")
