"""Evaluation of moving-object detection and tracking against ground truth.

Two sources of truth:

- the simulator (:func:`evaluate_sim`): per-beam labels and exact mover states;
- the datmo bags (:func:`evaluate_datmo_bag`): motion-capture poses of the ego car (which
  carries the laser) and of one or two target cars.

Definitions (simulator, :func:`evaluate_sim`)
---------------------------------------------
Let v_min be the tracker's threshold (paper Eq. 3) and ``warmup`` = 1 s.

- A beam is **dynamic-truth** in scan i if its label is a mover id k, mover k's ground-truth
  speed at scan i exceeds v_min, and mover k has been *visible* (at least ``min_points`` beams,
  the segmentation's minimum) in every scan of the last ``warmup`` seconds (so an object that
  has not existed in the scans for 1 s is not counted).
- A beam is **flagged** if it is assigned to a track that is in M at scan i (``Track.beams`` of
  tracks with ``in_m``).
- **recall** = |flagged ∩ dynamic-truth| / |dynamic-truth|.
- **precision** = |flagged ∩ mover-labelled| / |flagged|, counting flagged beams only in scans
  after ``warmup`` (a mover that is momentarily slow is still an object to remove; beams of
  static structure or of nothing are false positives). ``precision_moving`` uses
  dynamic-truth instead of mover-labelled (strict Eq. 3 reading).
- **fp_beam_rate** = flagged beams labelled static / all beams labelled static.
- A track is **matched** to mover k in scan i if it is confirmed (not coasting), at least 1 s
  old, and more than half of its assigned beams carry label k. Centre error = distance between
  the track's box centre and mover k's true centre; speed error = | |v̂| − |v| |, both in the
  map (first-scan) frame. Medians and 90th percentiles are reported.
- **id_switches**: per mover, the number of times the id of the track matched to it changes
  between successive scans in which it is matched; summed over movers.

Definitions (datmo bags, :func:`evaluate_datmo_bag`)
---------------------------------------------------
The laser pose in the map (motion-capture) frame is the ego pose interpolated at the scan
stamp, composed with the laser offset (−0.12, 0, 0). The target car's position is its mocap
pose interpolated at the scan stamp, its speed the central difference over ±0.1 s. In each
scan the **associated track** is the confirmed (or coasting) track whose box centre is nearest to
the target, if within ``match_radius`` (1 m, docs/tracking.md). Centre error RMSE / median,
speed error median, and **id_switches** = number of times the associated track's id changes
between successive associated scans. Note that the mocap marker need not be at the car's
geometric centre; that offset is part of the error (docs/tracking.md).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.tracker import COASTING, CONFIRMED, Tracker
from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, Track, wrap_angle

if TYPE_CHECKING:
    from dynslam2d.sim.simulation import GroundTruth, Simulation

#: DATMO's own logic (kostaskonkk/datmo, re-implemented) on the datmo bags: centre RMSE, m
#: (the "DATMO's own logic" column of docs/tracking.md).
DATMO_RMSE = {
    "overtakes": 0.125, "overtake_ego": 0.134, "overtake_red": 0.176, "parallel": 0.112, "intersection": 0.463,
}
#: Laser offset in the ego-pose frame of the datmo bags (example.launch static tf), m, m, rad.
DATMO_LASER_OFFSET = (-0.12, 0.0, 0.0)
#: Laser offset in two_robots.bag: its own /tf_static base_link → laser (the /mocap_pose frame).
TWO_ROBOTS_LASER_OFFSET = (-0.1385, 0.0, 0.0)


@dataclass
class SimTrackingResult:
    """Scores of one simulated run (see the module docstring for the definitions)."""

    scene: str
    seed: int
    duration: float
    n_scans: int
    recall: float
    precision: float
    precision_moving: float
    fp_beam_rate: float
    n_dynamic_truth: int
    n_flagged: int
    median_center_error: float
    p90_center_error: float
    median_speed_error: float
    p90_speed_error: float
    n_matched: int
    id_switches: int
    tracks_ever_in_m: int
    static_tracks_in_m: int
    ms_per_scan: float
    stats: dict[str, int] = field(default_factory=dict)

    def row(self) -> dict[str, object]:
        d = asdict(self)
        d.pop("stats")
        return d


@dataclass
class BagTrackingResult:
    """Scores of one datmo bag and one target (see the module docstring)."""

    bag: str
    target: str
    n_scans: int
    n_with_truth: int
    n_matched: int
    rmse_center: float
    median_center_error: float
    median_speed_error: float
    id_switches: int
    mean_tracks: float
    mean_tracks_in_m: float
    datmo_rmse: float | None
    ms_per_scan: float
    stats: dict[str, int] = field(default_factory=dict)

    def row(self) -> dict[str, object]:
        d = asdict(self)
        d.pop("stats")
        return d


def datmo_config() -> DetectConfig:
    """The detection settings used on the datmo bags (360 beams, 1°, scaled RC cars ≈0.38×0.16 m).

    Differences from the defaults, and why: ``segment.min_points = 2`` and ``fit.point_max_points = 3``
    (at 1° a car 3–4 m away returns 2–3 beams; datmo's Datmo::Clustering also keeps 2-point clusters);
    ``tracker.aspect_prior = 0.4`` (the cars move along their long axis and are seen for long
    stretches only from behind or in front; 0.4 ≈ width / length of their side views in the scans);
    ``fit.person_merge = False`` (no people: a car's two visible sides, split into two clusters of
    leg size, would be merged as a pair of legs).
    """
    cfg = DetectConfig()
    cfg.segment.min_points = 2
    cfg.fit.point_max_points = 3
    cfg.tracker.aspect_prior = 0.4
    cfg.fit.person_merge = False
    return cfg


def _nanmedian(a: list[float]) -> float:
    return float(np.median(a)) if a else math.nan


def _nanpct(a: list[float], q: float) -> float:
    return float(np.percentile(a, q)) if a else math.nan


def evaluate_sim(scene: str, seed: int | None = None, duration: float | None = 20.0,
                 config: DetectConfig | None = None, warmup: float = 1.0, pose_source: str = "truth",
                 simulation: object | None = None) -> SimTrackingResult:
    """Run the tracker over a simulated scene and score it against ground truth.

    Args:
        scene: scenario name (``dynslam2d.sim.SCENARIOS``).
        seed, duration: passed to :func:`dynslam2d.sim.simulate` (duration in s).
        config: detection configuration (defaults if None).
        warmup: visibility / track age required before counting, s.
        pose_source: "truth" (ground-truth laser poses in the first-scan frame) or "slam"
            (poses from :class:`dynslam2d.slam.HectorSlam`, scored in the same frame).
        simulation: an already computed :class:`dynslam2d.sim.Simulation` (skips simulating).
    """
    from dynslam2d.sim import simulate

    cfg = config or DetectConfig()
    sim = simulation if simulation is not None else simulate(scene, seed=seed, duration=duration)
    gt = sim.ground_truth
    poses = _sim_poses(sim, pose_source)
    truth = _SimTruth(gt, len(sim.scans), cfg, warmup)
    tally = _SimTally()
    tracker = Tracker(cfg)
    t_proc = 0.0
    for i, scan in enumerate(sim.scans):
        t0 = time.perf_counter()
        tracks = tracker.update(scan, Pose2D.from_array(poses[i]))
        t_proc += time.perf_counter() - t0
        tally.count_beams(i, tracks, truth)
        tally.match_movers(i, tracks, truth)
    n = len(sim.scans)
    return tally.result(
        scene=str(scene), seed=int(sim.scenario.seed), duration=float(sim.scenario.duration), n_scans=n,
        ms_per_scan=1000.0 * t_proc / max(n, 1), stats=tracker.stats.as_dict(),
    )


def _sim_poses(sim: Simulation, pose_source: str) -> np.ndarray:
    """(n, 3) laser poses in the first-scan frame the tracker gets: ground truth or Hector SLAM's."""
    poses = sim.ground_truth.poses_in("first")
    if pose_source == "slam":
        from dynslam2d.slam import HectorSlam

        slam = HectorSlam()
        poses = np.array([slam.process(s).pose.as_array() for s in sim.scans])
    elif pose_source != "truth":
        raise DynSlamError(f"evaluate_sim: pose_source must be 'truth' or 'slam', got {pose_source!r}")
    return poses


class _SimTruth:
    """The simulator's ground truth as :func:`evaluate_sim` reads it, scan by scan (first-scan frame).

    :meth:`dynamic_ids` keeps, per mover, the stamp since which it has been visible without
    a gap, so it must be called once per scan, in order.
    """

    def __init__(self, gt: GroundTruth, n: int, cfg: DetectConfig, warmup: float) -> None:
        self.states = gt.mover_states_in("first")
        self.labels = gt.labels
        self.ids = gt.mover_ids
        self.stamps = gt.stamps
        self.warmup = warmup
        self.v_min = cfg.tracker.v_min
        ids = self.ids
        self.speeds = np.hypot(self.states[..., 3], self.states[..., 4]) if ids.size else np.zeros((n, 0))
        hits = gt.mover_hits if ids.size else np.zeros((n, 0), dtype=np.int32)
        self.visible = hits >= cfg.segment.min_points
        self.run_start = np.full(ids.size, np.nan)
        self.id_index = {int(k): j for j, k in enumerate(ids)}

    def dynamic_ids(self, i: int) -> np.ndarray:
        """Ids of the movers that are dynamic truth in scan ``i``: faster than v_min and visible
        in every scan of the last ``warmup`` s."""
        ids, stamps, run_start = self.ids, self.stamps, self.run_start
        for j in range(ids.size):
            if self.visible[i, j]:
                if math.isnan(run_start[j]):
                    run_start[j] = stamps[i]
            else:
                run_start[j] = math.nan
        seasoned = ~np.isnan(run_start) & (stamps[i] - np.nan_to_num(run_start, nan=np.inf) >= self.warmup - 1e-9)
        return ids[seasoned & (self.speeds[i] > self.v_min)] if ids.size else ids


@dataclass
class _SimTally:
    """Running counts and errors of :func:`evaluate_sim` (module docstring's definitions)."""

    n_truth: int = 0
    n_tp: int = 0
    n_flag: int = 0
    n_flag_mover: int = 0
    n_flag_moving: int = 0
    static_total: int = 0
    static_flag: int = 0
    cerr: list[float] = field(default_factory=list)
    serr: list[float] = field(default_factory=list)
    last_id: dict[int, int] = field(default_factory=dict)
    switches: int = 0
    ever_m: set[int] = field(default_factory=set)
    static_m: set[int] = field(default_factory=set)

    def count_beams(self, i: int, tracks: list[Track], truth: _SimTruth) -> None:
        """Scan ``i``'s beams: dynamic truth, flagged (on a track in M), static; the tracks in M."""
        lab = truth.labels[i]
        ids = truth.ids
        dyn_ids = truth.dynamic_ids(i)
        is_truth = np.isin(lab, dyn_ids) if dyn_ids.size else np.zeros(lab.shape, dtype=bool)
        moving_any = np.isin(lab, ids[truth.speeds[i] > truth.v_min]) if ids.size else np.zeros(lab.shape, dtype=bool)
        flagged = np.zeros(lab.shape, dtype=bool)
        for tr in tracks:
            if tr.in_m:
                self.ever_m.add(tr.id)
                flagged[tr.beams] = True
                if tr.n_points and np.mean(lab[tr.beams] == 0) > 0.5:
                    self.static_m.add(tr.id)
        self.n_truth += int(is_truth.sum())
        self.n_tp += int((is_truth & flagged).sum())
        static = lab == 0
        self.static_total += int(static.sum())
        self.static_flag += int((static & flagged).sum())
        if truth.stamps[i] - truth.stamps[0] >= truth.warmup:
            self.n_flag += int(flagged.sum())
            self.n_flag_mover += int((flagged & (lab > 0)).sum())
            self.n_flag_moving += int((flagged & moving_any).sum())

    def match_movers(self, i: int, tracks: list[Track], truth: _SimTruth) -> None:
        """Match scan ``i``'s seasoned confirmed tracks to movers: centre / speed errors, id switches."""
        lab = truth.labels[i]
        for tr in tracks:
            if tr.state != CONFIRMED or tr.age < truth.warmup - 1e-9 or tr.n_points == 0:
                continue
            lb = lab[tr.beams]
            lb = lb[lb > 0]
            if lb.size * 2 <= tr.n_points:
                continue
            vals, counts = np.unique(lb, return_counts=True)
            k = int(vals[np.argmax(counts)])
            if counts.max() * 2 <= tr.n_points:
                continue
            j = truth.id_index[k]
            sx = truth.states[i, j]
            self.cerr.append(float(math.hypot(tr.box.px - sx[0], tr.box.py - sx[1])))
            self.serr.append(abs(tr.speed - float(truth.speeds[i, j])))
            if k in self.last_id and self.last_id[k] != tr.id:
                self.switches += 1
            self.last_id[k] = tr.id

    def result(self, *, scene: str, seed: int, duration: float, n_scans: int, ms_per_scan: float,
               stats: dict[str, int]) -> SimTrackingResult:
        """The scores (ratios NaN when their denominator is 0)."""
        n_flag, cerr, serr = self.n_flag, self.cerr, self.serr
        return SimTrackingResult(
            scene=scene, seed=seed, duration=duration, n_scans=n_scans,
            recall=self.n_tp / self.n_truth if self.n_truth else math.nan,
            precision=self.n_flag_mover / n_flag if n_flag else math.nan,
            precision_moving=self.n_flag_moving / n_flag if n_flag else math.nan,
            fp_beam_rate=self.static_flag / self.static_total if self.static_total else 0.0,
            n_dynamic_truth=self.n_truth, n_flagged=n_flag,
            median_center_error=_nanmedian(cerr), p90_center_error=_nanpct(cerr, 90),
            median_speed_error=_nanmedian(serr), p90_speed_error=_nanpct(serr, 90), n_matched=len(cerr),
            id_switches=self.switches, tracks_ever_in_m=len(self.ever_m), static_tracks_in_m=len(self.static_m),
            ms_per_scan=ms_per_scan, stats=stats,
        )


# --------------------------------------------------------------------------- datmo bags

def interpolate_poses(stamps: np.ndarray, xy: np.ndarray, yaw: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Linear interpolation of planar poses at times ``at`` (yaw unwrapped first); rows outside
    the pose time span are NaN. Returns (m, 3) x, y, yaw."""
    out = np.full((at.shape[0], 3), np.nan)
    if stamps.shape[0] < 2:
        return out
    order = np.argsort(stamps, kind="stable")
    s, p, y = stamps[order], xy[order], np.unwrap(yaw[order])
    inside = (at >= s[0]) & (at <= s[-1])
    out[inside, 0] = np.interp(at[inside], s, p[:, 0])
    out[inside, 1] = np.interp(at[inside], s, p[:, 1])
    out[inside, 2] = wrap_angle(np.interp(at[inside], s, y))
    return out


def _target_speed(stamps: np.ndarray, xy: np.ndarray, at: np.ndarray, half: float = 0.1) -> np.ndarray:
    a = interpolate_poses(stamps, xy, np.zeros(stamps.shape[0]), at - half)
    b = interpolate_poses(stamps, xy, np.zeros(stamps.shape[0]), at + half)
    return np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]) / (2.0 * half)


def evaluate_datmo_bag(path: str | os.PathLike[str], config: DetectConfig | None = None,
                       ego_topic: str | None = None, target_topics: tuple[str, ...] | None = None,
                       laser_offset: tuple[float, float, float] | None = None,
                       match_radius: float = 1.0) -> list[BagTrackingResult]:
    """Track the cars of one datmo bag with motion-capture ego poses and score each target.

    Args:
        path: the .bag file.
        config: detection configuration (:func:`datmo_config` if None).
        ego_topic: pose topic of the car carrying the laser; default "/ego_pose", or
            "/mocap_pose" when the bag has no /ego_pose (two_robots.bag).
        target_topics: pose topics of the tracked cars; default ("/red_pose",), or
            ("/robot_1", "/robot_2") for two_robots.bag.
        laser_offset: laser pose in the ego frame (x, y m; theta rad); default
            :data:`DATMO_LASER_OFFSET`, or :data:`TWO_ROBOTS_LASER_OFFSET` with /mocap_pose.
        match_radius: largest distance between the target and its associated track, m.

    Returns:
        One :class:`BagTrackingResult` per target topic.
    """
    from dynslam2d.io.rosbag import RosbagSource, list_topics, read_pose_topic

    p = Path(path)
    topics = list_topics(p)
    if ego_topic is None:
        ego_topic = "/ego_pose" if "/ego_pose" in topics else "/mocap_pose"
    if target_topics is None:
        target_topics = ("/red_pose",) if "/red_pose" in topics else tuple(
            t for t in ("/robot_1", "/robot_2") if t in topics)
    if not target_topics:
        raise DynSlamError(f"{p}: no target pose topic (/red_pose, /robot_1, /robot_2) in the bag")
    cfg = config or datmo_config()
    if laser_offset is None:
        laser_offset = TWO_ROBOTS_LASER_OFFSET if ego_topic == "/mocap_pose" else DATMO_LASER_OFFSET
    scans: list[Scan] = list(RosbagSource(p))
    stamps = np.array([s.stamp for s in scans])
    ego = read_pose_topic(p, ego_topic)
    ego_at = interpolate_poses(ego.stamps, ego.xy, ego.yaw, stamps)
    off = Pose2D(*laser_offset)
    targets = {t: read_pose_topic(p, t) for t in target_topics}
    tgt_xy = {t: interpolate_poses(tr.stamps, tr.xy, tr.yaw, stamps)[:, :2] for t, tr in targets.items()}
    tgt_v = {t: _target_speed(tr.stamps, tr.xy, stamps) for t, tr in targets.items()}
    tracker = Tracker(cfg)
    err: dict[str, list[float]] = {t: [] for t in target_topics}
    serr: dict[str, list[float]] = {t: [] for t in target_topics}
    last: dict[str, int | None] = {t: None for t in target_topics}
    sw = {t: 0 for t in target_topics}
    n_truth = {t: 0 for t in target_topics}
    n_tracks = n_m = 0
    n_used = 0
    t_proc = 0.0
    for i, scan in enumerate(scans):
        if not np.all(np.isfinite(ego_at[i])):
            continue
        pose = Pose2D.from_array(ego_at[i]).compose(off)
        t0 = time.perf_counter()
        tracks = tracker.update(scan, pose)
        t_proc += time.perf_counter() - t0
        n_used += 1
        live = [tr for tr in tracks if tr.state in (CONFIRMED, COASTING)]
        n_tracks += len(live)
        n_m += sum(tr.in_m for tr in tracks)
        for t in target_topics:
            g = tgt_xy[t][i]
            if not np.all(np.isfinite(g)):
                continue
            n_truth[t] += 1
            if not live:
                continue
            d = [math.hypot(tr.box.px - g[0], tr.box.py - g[1]) for tr in live]
            j = int(np.argmin(d))
            if d[j] > match_radius:
                continue
            err[t].append(d[j])
            if np.isfinite(tgt_v[t][i]):
                serr[t].append(abs(live[j].speed - float(tgt_v[t][i])))
            if last[t] is not None and last[t] != live[j].id:
                sw[t] += 1
            last[t] = live[j].id
    out = []
    for t in target_topics:
        e = np.array(err[t])
        out.append(BagTrackingResult(
            bag=p.stem, target=t, n_scans=len(scans), n_with_truth=n_truth[t], n_matched=int(e.size),
            rmse_center=float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan,
            median_center_error=_nanmedian(err[t]), median_speed_error=_nanmedian(serr[t]), id_switches=sw[t],
            mean_tracks=n_tracks / max(n_used, 1), mean_tracks_in_m=n_m / max(n_used, 1),
            datmo_rmse=DATMO_RMSE.get(p.stem) if t == "/red_pose" else None,
            ms_per_scan=1000.0 * t_proc / max(n_used, 1), stats=tracker.stats.as_dict()))
    return out


def evaluate_datmo_folder(folder: str | os.PathLike[str], config: DetectConfig | None = None
                          ) -> list[BagTrackingResult]:
    """:func:`evaluate_datmo_bag` on every ``*.bag`` of a folder (sorted by name)."""
    bags = sorted(Path(folder).glob("*.bag"))
    if not bags:
        raise DynSlamError(f"{folder}: no .bag files")
    rows: list[BagTrackingResult] = []
    for b in bags:
        rows.extend(evaluate_datmo_bag(b, config))
    return rows
