"""The per-scan pipeline and whole-log runs (docs/architecture.md, "One scan through the pipeline").

For every scan, in time order:

1. predict the laser pose (previous pose, or constant velocity);
2. remove the points of the objects already known to move (tracks in M, advanced
   to this scan's stamp with their velocity) and match the rest against the map;
3. segment, fit and track in the MAP frame with the pose of this same scan
   (a rotating robot must not make walls look like movers);
4. build the dynamic set M (paper Eq. 3) and the exclusion zones of paper
   Eq. 5–8 from the tracks' boxes at this stamp;
5. update the map with the filtered scan only.

``Pipeline(config).process(scan) -> StepResult`` is the live API for any robot
framework; :func:`run` drives it over a whole :class:`ScanSource`.
"""

from __future__ import annotations

import math
import struct
import time
from array import array
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from dynslam2d.collector import SCAN_LOOP_GC_THRESHOLD0, scan_loop_gc
from dynslam2d.config import Config
from dynslam2d.detect.body import BodyFilter
from dynslam2d.detect.mapevidence import MapView, map_evidence
from dynslam2d.detect.tracker import Tracker
from dynslam2d.detect.trackreport import TrackReports
from dynslam2d.filter import filter_active, filter_scan_ids, mover_beams, mover_exclusions, observed_boxes_kernel
from dynslam2d.gridmap import GridMap
from dynslam2d.jitcache import compile_seconds
from dynslam2d.memtrim import release_free_memory
from dynslam2d.rangescale import apply_range_scale
from dynslam2d.records import BitRows, PackedGrowArray, TrackRows
from dynslam2d.slam import HectorSlam
from dynslam2d.slam.confidence import FLAGS
from dynslam2d.slam.confidence import summarize as summarize_confidence
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.erasure import EvidenceLedger
from dynslam2d.slam.grid import MultiResMap, logistic_map
from dynslam2d.slam.jumps import jump_flags
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.loops import LoopCloser, LoopResult
from dynslam2d.trajectory import Trajectory
from dynslam2d.types import Pose2D, Scan, ScanSource, SourceMeta, Track
from dynslam2d.vacated import VacatedTrace

try:  # np.count_nonzero(a) without axis is this C function behind a Python wrapper and its dispatch (per-scan tests)
    from numpy._core.multiarray import count_nonzero as _count_nonzero
except ImportError:  # pragma: no cover - another NumPy layout
    _count_nonzero = np.count_nonzero


@dataclass(slots=True)
class StepResult:
    """What one scan produced.

    Attributes:
        index: 0-based scan index in this pipeline.
        stamp: the scan's stamp, s.
        pose: laser pose in the map frame (m, rad); the map frame is the first scan's laser pose.
        score: match quality, mean occupancy probability at the scan endpoints (0 … 1).
        map_updated: the (filtered) scan was written into the map.
        rejected: the match was judged bad and kept out of the map (``reason`` says why).
        skipped: the scan held too little to match (``reason`` says why).
        reason: skip / reject reason, or None.
        tracks: live tracks after this scan (map frame), each with ``in_m``: a sequence of ``Track`` built when read
            (the tracker's :class:`dynslam2d.detect.trackreport.TrackReports`).
        removed: (beams,) bool, True where the filter removed the beam from the map update.
        removed_by: (beams,) int, id of the track whose exclusion zone removed the beam (−1 = kept).
        timings: wall time per stage, ms ("match", "track", "filter", "map_update", "loops" = the loop
            closure's keyframes and searches, "total" = all of them).
        degeneracy: smallest / largest normalized eigenvalue of the match Hessian (NaN if not matched).
        degenerate: the scan left some direction of the pose unconstrained (a corridor's axis).
        support_points, support_spread: endpoints confirmed by the map (count) and the angle their
            bearings cover (rad).
        low_support: the pose is not backed by a well-supported match.
        pose_source: "scan", "scan+prior", "prediction" or "relocalised".
        slam_state: "tracking" or "lost".
        body: (beams,) bool, True where the return was the robot's own body (footprint or found
            automatically, :mod:`dynslam2d.detect.body`): dropped before matching, tracking and
            mapping, and not counted in ``removed``.
    """

    index: int
    stamp: float
    pose: Pose2D
    score: float
    map_updated: bool
    rejected: bool
    skipped: bool
    reason: str | None
    tracks: Sequence[Track] = field(default_factory=list)
    removed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    removed_by: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    timings: dict[str, float] = field(default_factory=dict)
    degeneracy: float = math.nan
    degenerate: bool = False
    support_points: int = 0
    support_spread: float = 0.0
    low_support: bool = False
    pose_source: str = "scan"
    slam_state: str = "tracking"
    body: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def _box_rows(tracks: list[Track]) -> tuple[np.ndarray, np.ndarray]:
    """(k, 7) rows [p_x, p_y, θ, l, w, v_x, v_y] of the boxes and velocities of ``tracks`` (map frame; m, rad,
    m/s) and their (k,) int64 ids: what :func:`dynslam2d.filter.filter_scan_ids` takes."""
    rows, ids, _, _ = _track_rows(tracks)
    return rows, ids


def _track_rows(tracks: list[Track]) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[int]]:
    """:func:`_box_rows` of ``tracks`` and, in the same pass, their non-empty beam index arrays and the running
    count of beams after each track (a track without beams adds none)."""
    vals: list[float] = []
    ids: list[int] = []
    beams: list[np.ndarray] = []
    ends: list[int] = []
    total = 0
    for t in tracks:
        b = t.box
        v = t.velocity
        vals += (b.px, b.py, b.theta, b.length, b.width, v[0], v[1])  # (one flat list: half the time of tuples)
        ids.append(t.id)
        tb = t.beams
        if tb is not None and len(tb):
            beams.append(tb)
            total += len(tb)
        ends.append(total)
    return np.array(vals, dtype=np.float64).reshape(-1, 7), np.array(ids, dtype=np.int64), beams, ends


#: :func:`_box_rows` of no tracks.
_NO_ROWS = (np.zeros((0, 7)), np.zeros(0, dtype=np.int64))


def _observed_rows(tracks: list[Track], scan: Scan, pose: Pose2D,
                   keep: list[tuple[np.ndarray, np.ndarray]] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_box_rows` of ``tracks`` with each box grown to enclose the points assigned to it in ``scan``
    (``keep``: receives :func:`_box_rows` of ``tracks`` itself, ungrown).

    The paper's exclusion box is the rectangle fitted to the object's cluster in this scan
    (§2.2, Eq. 2), which encloses the cluster by construction; a tracked box is smoothed
    over time and may sit a little inside the object's surface. The union of the two keeps
    the tracked extent where part of the object is hidden and every observed point inside
    (:func:`dynslam2d.filter.observed_boxes_kernel`, one call for every track).
    """
    rows, ids, beams, ends = _track_rows(tracks)
    if not tracks:
        return rows, ids
    if keep is not None:
        keep.append((rows.copy(), ids))  # the rows before growing (the next scan's exclusion before matching)
    if beams:  # (a track without beams keeps its box)
        idx = np.concatenate(beams).astype(np.int64, copy=False)  # (a new array: the kernel's one signature)
        cos_a, sin_a = scan.trig()
        observed_boxes_kernel(scan.ranges, cos_a, sin_a, math.cos(pose.theta), math.sin(pose.theta),
                              float(pose.x), float(pose.y), idx, np.array(ends, dtype=np.int64), rows)
    return rows, ids


def _vehicle_ids(ids: list[int], rows: np.ndarray, lim: float) -> list[int]:
    """The ids ``ids[j]`` of the rows ``rows`` ((k, ≥ 5) [p_x, p_y, θ, l, w, …], m) whose longer box side exceeds
    ``lim``, m: Python's ``max(l, w) > lim`` (``w if w > l else l``: a NaN length wins, a NaN width loses), from
    one ``tolist`` of the whole rows (no column slice)."""
    return [tid for tid, r in zip(ids, rows.tolist()) if (r[4] if r[4] > r[3] else r[3]) > lim]


class Pipeline:
    """Scans in; poses, tracks, removed beams and a map out. One :meth:`process` call per scan."""

    def __init__(self, config: Config | None = None) -> None:
        self.config = config if config is not None else Config()
        self.slam = HectorSlam(self.config.slam)
        self.tracker = Tracker(self.config.detect)
        self.body = BodyFilter(self.config.detect.footprint)
        self._moving: list[int] = []  # the ids of the tracks in M after the previous scan
        #: :func:`_box_rows` of the tracks in M after the previous scan, before their boxes were grown
        self._moving_rows: tuple[np.ndarray, np.ndarray] = _NO_ROWS
        self._last_stamp: float | None = None
        self._no_remover = np.zeros(0, dtype=np.int64)  # −1 per beam, copied by _nothing_removed
        # loop closure behind the front end (slam/loops.py); it never changes the front end's poses or map
        self.loops = LoopCloser(self.config.loop, self.config.slam) if self.config.loop.enabled else None
        mem = self.config.detect.memory
        tc = self.config.detect.tracker
        #: the vacated-footprint trace and its history of recent scans' outlines (_evidence_view; read once, here)
        self._vacated = VacatedTrace(self.config.clean, occupied_logodds=tc.map_occupied_logodds,
                                     min_cells=tc.map_vacate_min_cells, max_extent=tc.map_vacate_max_extent,
                                     min_depth_m=tc.map_vacate_min_depth,
                                     min_extent=self.config.detect.segment.max_extent,
                                     min_share=tc.map_vacate_min_share, scans=tc.map_vacate_scans)
        if tc.map_vacate_min_cells > 0 and tc.map_evidence:  # (the finest level's long-occupied cells, for the trace)
            self.slam.map.keep_long_occupied(tc.map_occupied_logodds)
        #: the last :class:`MapView` of the finest level (a new one only when the level's array or offset changes)
        self._view: MapView | None = None
        #: the front end's final map once :func:`run` has freed its levels (``_release_map``): what
        #: :meth:`gridmap` returns from then on, so a checkpoint written during the loop closure's finish
        #: (Ctrl-C) still writes the real map, not the freed 1 × 1 one
        self._released_grid: GridMap | _MapExport | None = None
        #: retroactive erasure of what tracks wrote while they stood (slam/erasure.py; None = off)
        self.ledger: EvidenceLedger | None = EvidenceLedger(
            mem, self.config.slam.laser_min_dist, self.config.slam.laser_max_dist,
            keep_beams=self.loops is not None) if (mem.erase and self.config.filter.mode != "none") else None

    def _exclude(self, scan: Scan, pose: Pose2D, rows: tuple[np.ndarray, np.ndarray],
                 dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Beams of ``scan`` (at ``pose``) inside the exclusion zones of the boxes ``rows``
        (:func:`_box_rows`) advanced by ``dt``, s: (removed, id of the remover or −1)."""
        if not rows[0].shape[0]:  # nothing to exclude (filter_scan_ids would return the same)
            return self._nothing_removed(scan.ranges.shape[0])
        return filter_scan_ids(self.config.filter, scan, pose, rows[0], rows[1], dt)

    def _nothing_removed(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(removed, removed_by) of an ``n``-beam scan from which nothing is removed: all False and all −1, new
        arrays each call (the −1 row kept and copied, not filled again)."""
        kept = self._no_remover
        if kept.shape[0] != n:
            kept = self._no_remover = np.full(n, -1, dtype=np.int64)
        return np.zeros(n, dtype=bool), kept.copy()

    def _spare_structure(self, scan: Scan, pose: Pose2D, own_beams: np.ndarray, removed: np.ndarray,
                         removed_by: np.ndarray, only_ids: np.ndarray | None = None) -> None:
        """In place: beams inside an exclusion region that are not the object's own (not among ``own_beams``, the
        beams of the tracks in M in this scan) and whose point lies on long-occupied map structure stay in the scan
        (``filter.spare_structure``; the same structure test as the tracker's map evidence,
        ``detect.tracker.map_occupied_logodds``). The region's margin is for range noise and box-fit error; a
        walker passing close to a wall seen at a grazing angle would otherwise take a strip of the wall with it.
        ``only_ids``: only beams removed by these tracks are candidates (``filter.spare_structure_vehicles``)."""
        view = MapView.of_level(self.slam.map.levels[0])
        if view is None:
            return
        own = np.zeros(removed.shape[0], dtype=bool)
        own[own_beams] = True
        cand = np.flatnonzero(removed & ~own & (np.isin(removed_by, only_ids) if only_ids is not None else True))
        if cand.shape[0] == 0:
            return
        r = scan.ranges[cand]
        cos_a, sin_a = scan.trig()
        pts = pose.transform_points(np.column_stack((r * cos_a[cand], r * sin_a[cand])))
        tc = self.config.detect.tracker
        structure, _, _ = map_evidence(pts, view, tc.map_occupied_logodds, tc.map_free_logodds, tc.map_free_radius)
        spare = cand[structure]
        removed[spare] = False
        removed_by[spare] = -1

    def _evidence_view(self, scan: Scan, pose: Pose2D) -> MapView | None:
        """The finest map level as the tracker's map evidence sees it for ``scan`` at ``pose``: outlines of
        long-occupied cells that this scan sees through (a parked vehicle driving off) count as observed free
        (``detect.tracker.map_vacate_min_cells``; docs/maps.md, "Vacated footprints"; :class:`VacatedTrace`). The SLAM
        map itself is not changed."""
        lv = self.slam.map.levels[0]
        view = self._view
        if view is None or view.logodds is not lv.logodds or view.i0 != lv.i0 or view.j0 != lv.j0:
            view = self._view = MapView.of_level(lv)  # (the map grew or was released; None while it is empty)
        tc = self.config.detect.tracker
        if view is None or tc.map_vacate_min_cells <= 0 or not tc.map_evidence:
            return view
        return self._vacated.view(view, scan, pose)

    def process(self, scan: Scan) -> StepResult:
        """Run every stage on ``scan`` (scans must come in time order) and return the result."""
        t0 = time.perf_counter()
        # 0. the robot's own body is never structure nor a mover (detect/body.py)
        raw = scan
        body, scan = self.body.apply(scan)  # (``scan`` itself when nothing is dropped)
        # 2. match with the known movers removed (their boxes advanced to this stamp).
        drop = None  # (the matcher takes these beams as without a return: ``scan.without(drop)``, not copied)
        if self._moving and self.config.filter.mode != "none":
            dt = scan.stamp - self._last_stamp if self._last_stamp is not None else 0.0
            pre_removed, _ = self._exclude(scan, self.slam.predict(scan.stamp), self._moving_rows, dt)
            if _count_nonzero(pre_removed):
                drop = pre_removed
        res = self.slam.match(scan, drop=drop)
        self.body.observe(raw, res.pose)
        t1 = time.perf_counter()
        # 3. track in the map frame with this scan's pose.
        tracks = self.tracker.update(scan, res.pose, self._evidence_view(scan, res.pose),
                                     self.body.body if self.config.detect.footprint.auto else None)
        t2 = time.perf_counter()
        # 4. the dynamic set M and its exclusion zones (paper Eq. 3, 5-8), from the reports' columns: no Track
        # object built for them (docs/speed.md, pass trk90)
        if type(tracks) is not TrackReports:  # (a tracker returning plain Track objects: its columns made from them)
            tracks = TrackReports.of_tracks(tracks)
        moving = tracks.moving_index()  # (indices of the reports in M)
        fc = self.config.filter
        if moving and res.low_support and fc.trusted_pose_only:
            # an untrusted pose makes structure look like motion: only movers removed before stay removed
            known, ids = set(self._moving), tracks.ids
            moving = [i for i in moving if ids[i] in known]
        if not moving:  # (most scans: nothing removed; _exclude's arrays without its call, pass neg112)
            mrows, mids = _NO_ROWS
            removed, removed_by = self._nothing_removed(scan.ranges.shape[0])
            any_removed = False
        else:
            # (the movers' boxes and velocities as rows, grown to their beams' points and their exclusion, one kernel)
            # (their beams read by the kernel from the scan's detection arrays: pass rep149)
            packed, beams, more, moving = tracks.mover_pack(moving)  # (moving: now the movers' ids)
            # (with the count of removed beams and the movers' longest side, from the kernel: pass neg112)
            mrows, mids, removed, removed_by, count, side = mover_exclusions(fc, scan, res.pose, *tracks.arrays,
                                                                             packed, beams, more)
            any_removed = count > 0
            if any_removed and fc.mode == "box":
                if fc.spare_structure:
                    self._spare_structure(scan, res.pose, mover_beams(packed, beams, more), removed, removed_by)
                    any_removed = bool(_count_nonzero(removed))
                elif fc.spare_structure_vehicles:
                    lim = self.config.detect.segment.max_extent  # (read once, not per track)
                    big = _vehicle_ids(moving, mrows, lim) if side > lim else None  # (no vehicle: no list)
                    if big:
                        self._spare_structure(scan, res.pose, mover_beams(packed, beams, more), removed, removed_by,
                                              np.array(big))
                        any_removed = bool(_count_nonzero(removed))
        t3 = time.perf_counter()
        # 5. map update with the filtered scan only.
        updated = False
        led = self.ledger
        if led is not None:  # what a track wrote while it stood is taken out once it moves (slam/erasure.py)
            removing = set(moving) if moving and filter_active(fc, len(moving)) else set()
            # (the tracker's state rows of its live reports: the ledger's standing test reads them in one kernel call)
            trk = self.tracker
            led.observe(tracks, removing, scan.stamp, trk.report_states())
            if removing:  # (without a removal set erase_entering returns at once: no call, pass neg112)
                led.erase_entering(tracks, removing, scan.stamp, self.slam.map, (moving, mrows))
            if led.erased_beams:  # the loop closure's keyframes leave them out too (re-render, clean-up recount)
                if self.loops is not None:
                    self.loops.drop_beams(led.erased_beams)
                led.erased_beams.clear()
        # the thresholds are tested once: a scan that will not update the map builds no kept copy
        need = not res.rejected and self.slam.needs_map_update(res.pose)
        kept = None  # (the scan without the removed beams, for the loop closer: None = it makes its own when needed)
        if need or not (res.rejected or res.pose.is_finite()):  # (update_map counts a refused non-finite pose)
            kept = None if any_removed else scan
            pending = None
            if led is not None and tracks and need:
                pending = led.before_update(scan, res.pose, tracks, removed, self.slam.map,
                                            self.loops.next_index if self.loops is not None else -1)
            # (the removed beams as no return: the map of ``scan.without(removed)``, without the copy)
            updated = self.slam.update_map(scan, res.pose, force=need, drop=removed if any_removed else None)
            if pending is not None and updated:
                led.after_update(pending, self.slam.map)
        t4 = time.perf_counter()
        if self.loops is not None:  # (also in the loop closure's own counters, summary.json loop_closure)
            self.loops.add(scan.stamp, res.pose, scan, removed, updated,
                           res.low_support or res.pose_source in ("prediction", "relocalised") or res.time_gap,
                           res.score, kept)
        t5 = time.perf_counter()
        self._moving = moving
        self._moving_rows = (mrows, mids)
        self._last_stamp = scan.stamp
        # (positional, in StepResult's field order — the keywords' parsing was a third of its cost; the fields named
        # in the comments, tests/test_match_inlined_glue.py checks the order)
        return StepResult(
            self.slam.n_scans - 1, scan.stamp, res.pose, res.score,  # index, stamp, pose, score
            updated, res.rejected, res.skipped, res.reason,  # map_updated, rejected, skipped, reason
            tracks, removed, removed_by,  # tracks, removed, removed_by
            {  # timings
                "match": (t1 - t0) * 1e3,
                "track": (t2 - t1) * 1e3,
                "filter": (t3 - t2) * 1e3,
                "map_update": (t4 - t3) * 1e3,
                "loops": (t5 - t4) * 1e3,
                "total": (t5 - t0) * 1e3,
            },
            res.degeneracy, res.degenerate, res.support_points, res.support_spread,  # degeneracy … support_spread
            res.low_support, res.pose_source, res.state, body,  # low_support, pose_source, slam_state, body
        )

    def gridmap(self) -> GridMap:
        """The finest map level as occupancy probabilities (NaN = never observed); after :func:`run` freed the
        front end's levels, the map they held then."""
        if isinstance(self._released_grid, _MapExport):
            return self._released_grid.gridmap()
        if self._released_grid is not None:
            return self._released_grid
        return self.slam.gridmap(0)


def find_body(scans: Iterable[Scan], config: Config | None = None, max_scans: int = 600) -> dict[str, object]:
    """The robot's own body found in the first ``max_scans`` scans, without detection: what ``dynslam2d info``
    reports (docs/tracking.md, "The robot's own body").

    Runs what :meth:`Pipeline.process` runs before and after detection — footprint / body mask, scan matching
    (with the recording's odometry where the scans carry it), map update — and the automatic body detection
    of :class:`~dynslam2d.detect.body.BodyFilter` on the laser poses; about 1 ms per scan. Returns
    :meth:`BodyFilter.report` (``auto_body_beams``, ``suggested_footprint`` in the laser frame, m, …) plus
    ``scans_used``, ``travel_m`` (the laser's path length, m), ``turn_rad`` (its summed absolute turning, rad),
    ``body_range_m`` ([min, max] range of the body beams, m; None without any) and ``enough_motion``: whether
    the laser moved ``auto_min_travel`` and turned ``auto_min_turn`` (a motionless laser cannot tell its body
    from a wall).
    """
    cfg = config if config is not None else Config()
    slam = HectorSlam(cfg.slam)
    body = BodyFilter(cfg.detect.footprint)
    last: Scan | None = None
    prev: Pose2D | None = None
    n, travel, turn = 0, 0.0, 0.0
    for scan in scans:
        if n >= max_scans:
            break
        drop = body.mask(scan)
        masked = scan.without(drop) if drop.any() else scan
        res = slam.match(masked)
        body.observe(scan, res.pose)
        if not res.rejected:
            slam.update_map(masked, res.pose)
        if prev is not None and res.pose.is_finite() and prev.is_finite():
            travel += math.hypot(res.pose.x - prev.x, res.pose.y - prev.y)
            turn += abs(math.remainder(res.pose.theta - prev.theta, 2.0 * math.pi))
        prev = res.pose
        last = scan
        n += 1
    out = body.report(last)
    fc = cfg.detect.footprint
    rng = body.body_ranges[body.body] if body.body.shape[0] else np.zeros(0)
    out.update(scans_used=n, travel_m=round(travel, 3), turn_rad=round(turn, 3),
               body_range_m=[round(float(rng.min()), 3), round(float(rng.max()), 3)] if rng.size else None,
               enough_motion=bool(travel >= fc.auto_min_travel and turn >= fc.auto_min_turn))
    return out


#: Columns of :attr:`RunResult.track_rows` and of tracks.csv.
TRACK_COLUMNS = ("stamp", "id", "state", "x", "y", "heading", "length", "width", "vx", "vy", "in_M")
#: tracks.csv's columns: :data:`TRACK_COLUMNS` and ``remembered`` (1 = in M only by track memory: it
#: moved before and has stopped, docs/maps.md).
TRACK_CSV_COLUMNS = TRACK_COLUMNS + ("remembered",)


def _steady_speed(total_ms: np.ndarray, warmup: int = 10) -> dict[str, float | None]:
    """Speed without the start: the first scan's processing time (it includes compiling the
    numba kernels on a first run) and the median per-scan time after the first ``warmup``
    scans (at most half of them), ms, with the scans/s it implies (processing only: reading
    the input and writing outputs are in the wall time, not here)."""
    if not total_ms.size:
        return {"first_scan_ms": None, "steady_ms_median": None, "steady_scans_per_s": None}
    rest = total_ms[min(warmup, total_ms.size // 2):]
    med = float(np.median(rest))
    return {"first_scan_ms": round(float(total_ms[0]), 3), "steady_ms_median": round(med, 3),
            "steady_scans_per_s": round(1e3 / med, 2) if med > 0 else None}


@dataclass(eq=False)
class RunResult:
    """A whole run: trajectory, map, tracks, removed beams, per-scan flags and timings.

    Attributes:
        source: metadata of the input.
        config: the effective configuration.
        trajectory: one pose per processed scan, stamped with the scan's stamp (map frame).
        scores, map_updated, rejected, skipped: (n,) per-scan match score and flags.
        removed: (n, beams) bool, True where the filter removed the beam (all False when
            scans differ in beam count: see ``removed_rows``).
        removed_rows: one (beams,) bool array per scan (any beam count); a packed
            :class:`~dynslam2d.records.BitRows` when built by :func:`run`.
        track_rows: one tuple per (scan, live track), fields :data:`TRACK_COLUMNS` (map frame);
            a compact :class:`~dynslam2d.records.TrackRows` when built by :func:`run`.
        timings_ms: per-stage (n,) arrays of wall time, ms.
        grid: the final finest-level map.
        logodds: (H, W) raw log-odds of the finest level, same cells and origin as ``grid``.
        wall_time_s: wall time of the whole run, s (includes reading the input).
        reasons: count of each skip / reject reason.
        memory_bytes: memory held by the map levels at the end.
        tracker_stats: counters of the tracker (bad input, resets).
        confidence: per-scan (n,) arrays "low_support", "degenerate", "lost" (bool) and
            "degeneracy" (float) — the pose confidence of every scan.
        slam_stats: counters of the SLAM processor ("lost_events", "relocalisations").
        body: the robot's own returns (:meth:`dynslam2d.detect.body.BodyFilter.report`): footprint and
            automatically found body beams, with a suggested footprint (laser frame, m).
    """

    source: SourceMeta
    config: Config
    trajectory: Trajectory
    scores: np.ndarray
    map_updated: np.ndarray
    rejected: np.ndarray
    skipped: np.ndarray
    removed_rows: Sequence[np.ndarray]  # BitRows (packed) from run(); any sequence of bool rows
    track_rows: Sequence[tuple]  # TrackRows (structured array) from run(); any sequence of tuples
    timings_ms: dict[str, np.ndarray]
    grid: GridMap
    logodds: np.ndarray
    wall_time_s: float
    reasons: dict[str, int]
    memory_bytes: int
    tracker_stats: dict[str, int] = field(default_factory=dict)
    confidence: dict[str, np.ndarray] = field(default_factory=dict)
    slam_stats: dict[str, int] = field(default_factory=dict)

    def pose_confidence(self) -> dict[str, object]:
        """The ``pose_confidence`` block of summary.json (see :func:`dynslam2d.slam.confidence.summarize`)."""
        n = self.n_scans
        c = self.config.slam
        flags = {k: self.confidence.get(k, np.zeros(n, dtype=bool)) for k in FLAGS}
        return summarize_confidence(self.trajectory.stamps, flags,
                                    self.confidence.get("degeneracy", np.full(n, np.nan)),
                                    self.slam_stats.get("lost_events", 0), self.slam_stats.get("relocalisations", 0),
                                    c.low_confidence_share, c.low_confidence_stretch, self.front_end_jumps())

    def front_end_jumps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(flag, shift m, turn rad), each (n,) per scan: the front end's snaps back after a drift
        (:func:`dynslam2d.slam.jumps.jump_flags` on the front end's trajectory, ``slam.jump_*``)."""
        c = self.config.slam
        front = self.frontend_trajectory if self.frontend_trajectory is not None else self.trajectory
        return jump_flags(front.stamps, front.poses, c.jump_shift, c.jump_ratio, c.jump_turn)
    body: dict[str, object] = field(default_factory=dict)
    #: the front end's trajectory when loop closure replaced ``trajectory`` by the optimised one (else None)
    frontend_trajectory: Trajectory | None = None
    #: the loop closure's result (graph, loops, counters), None with loop closure off
    loop: LoopResult | None = None
    #: wall time numba spent compiling kernels during the run, s (0 when every kernel came from the
    #: cache; :func:`dynslam2d.jitcache.compile_seconds`) — inside ``wall_time_s`` and the first scans' times.
    kernel_compile_s: float = 0.0
    #: track memory and retroactive erasure (docs/maps.md): counters for summary.json's ``memory`` block
    memory: dict[str, object] = field(default_factory=dict)
    #: (H, W) bool over ``grid``: cells whose evidence retroactive erasure took out (None = erasure off)
    erased: np.ndarray | None = None

    @property
    def n_scans(self) -> int:
        return len(self.trajectory)

    @property
    def removed(self) -> np.ndarray:
        if not len(self.removed_rows):
            return np.zeros((0, 0), dtype=bool)
        if isinstance(self.removed_rows, BitRows):
            if not self.removed_rows.uniform:
                return np.zeros((len(self.removed_rows), 0), dtype=bool)
            return self.removed_rows.stack()
        widths = {r.shape[0] for r in self.removed_rows}
        if len(widths) != 1:
            return np.zeros((len(self.removed_rows), 0), dtype=bool)
        return np.stack(self.removed_rows)

    def summary(self) -> dict[str, object]:
        """Numbers for summary.json and the terminal: scans, time, scans/s, failures, tracks, memory."""
        n = self.n_scans
        total = self.timings_ms.get("total", np.zeros(0))
        if isinstance(self.removed_rows, BitRows):
            beams, removed = self.removed_rows.total_bits, self.removed_rows.total_set
        else:
            beams = sum(r.shape[0] for r in self.removed_rows)
            removed = sum(int(r.sum()) for r in self.removed_rows)
        if isinstance(self.track_rows, TrackRows):
            arr = self.track_rows.array()
            ids = set(np.unique(arr["id"]).tolist())
            ids_m = set(np.unique(arr["id"][arr["in_M"]]).tolist())
        else:
            ids = {row[1] for row in self.track_rows}
            ids_m = {row[1] for row in self.track_rows if row[-1]}
        stage_ms = {k: float(np.median(v)) for k, v in self.timings_ms.items() if v.size}
        return {
            "input": self.source.origin,
            "format": self.source.format,
            "filter": self.config.filter.mode,
            "scans": n,
            "wall_time_s": round(self.wall_time_s, 3),
            "scans_per_s": round(n / self.wall_time_s, 2) if self.wall_time_s > 0 else None,
            "processing_ms_median": float(np.median(total)) if total.size else None,
            "processing_ms_p95": float(np.percentile(total, 95)) if total.size else None,
            **_steady_speed(total),
            "kernel_compile_s": round(self.kernel_compile_s, 3),
            "stage_ms_median": stage_ms,
            "map_updates": int(self.map_updated.sum()),
            "match_failures": int(self.rejected.sum()),
            "skipped_scans": int(self.skipped.sum()),
            "reasons": dict(self.reasons),
            "tracks": len(ids),
            "tracks_in_M": len(ids_m),
            "removed_beam_share": removed / beams if beams else 0.0,
            "tracker": dict(self.tracker_stats),
            "body": dict(self.body),
            "memory_bytes": int(self.memory_bytes),
            "map_cells": list(self.grid.shape),
            "map_resolution_m": self.grid.resolution,
            "map_origin_m": list(self.grid.origin),
            "odometry": self.source.odometry,
            "odometry_detail": self.source.extra.get("odometry"),
            "range_scale": self.source.extra.get("range_scale"),
            "trajectory_frame": "laser",
            "pose_confidence": self.pose_confidence(),
            **({"loop_closure": self.loop_summary()} if self.loop is not None else {}),
            **({"memory": dict(self.memory)} if self.memory else {}),
        }

    def loop_summary(self) -> dict[str, object]:
        """The ``loop_closure`` block of summary.json: counters of the loop closure and whether it
        changed the trajectory (docs/slam.md, "Loop closure")."""
        if self.loop is None:
            return {"enabled": False}
        st = self.loop.stats
        out: dict[str, object] = {"enabled": True, "corrected": self.loop.corrected}
        for k in ("map_entropy_frontend", "map_entropy_optimised", "max_keyframe_correction_m"):
            if k in st:
                out[k] = st[k]
        for k in ("keyframes", "submaps", "searches", "candidates", "loops_accepted", "loops_active", "loops_rejected",
                  "optimisations", "far_searches", "far_skipped", "far_candidates", "far_loops"):
            out[k] = int(st.get(k, 0))
        for k in ("total_ms", "render_ms"):
            out[k] = round(float(st.get(k, 0.0)), 1)
        if "written_render_ms" in st:  # the written map's render with the grazing stop (docs/maps.md)
            out["written_render_ms"] = round(float(st["written_render_ms"]), 1)
        out["search_ms"] = round(float(st.get("search_ms", 0.0)), 1)
        out["optimise_ms"] = round(float(st.get("optimise_ms", 0.0)), 1)
        out["place_ms"] = round(float(st.get("place_ms", 0.0)), 1)  # place descriptors (far search ranking)
        out["rematch_edges"] = int(st.get("rematch_edges", 0))  # keyframes re-matched after the loops (slam/rematch.py)
        out["rematch_ms"] = round(float(st.get("rematch_ms", 0.0)), 1)
        out["rematch_checked"] = int(st.get("rematch_checked", 0))  # keyframes the re-match selected and matched
        # the second far search after the re-match (slam/secondsearch.py): far searches, loops, rounds, wall time
        for k in ("second_searches", "second_loops", "second_rounds"):
            out[k] = int(st.get(k, 0))
        out["second_ms"] = round(float(st.get("second_ms", 0.0)), 1)
        if self.frontend_trajectory is not None:
            d = self.trajectory.poses[:, :2] - self.frontend_trajectory.poses[:, :2]
            out["max_correction_m"] = round(float(np.max(np.hypot(d[:, 0], d[:, 1]))), 4) if d.size else 0.0
        return out


def render_map(loop: LoopResult, slam_config: SlamConfig, poses: np.ndarray | None = None,
               grazing_stop_cells: float | None = None) -> tuple[GridMap, np.ndarray]:
    """The map re-rendered from the optimised keyframe poses: every keyframe's kept beams (the
    dynamic filter's removed beams stay out) integrated in order, as the front end did at its own
    poses. ``poses``: (k, 3) keyframe laser poses to render at instead of ``loop.node_poses`` (m, rad,
    map frame); ``grazing_stop_cells``: the free-space update's grazing stop instead of the config's
    (docs/maps.md). Returns (finest level as probabilities, its raw log-odds)."""
    update: dict[str, object] = {"map_levels": 1}  # only the finest level is returned
    if grazing_stop_cells is not None:
        update["grazing_stop_cells"] = float(grazing_stop_cells)
    slam = HectorSlam(slam_config.model_copy(update=update))
    at = loop.node_poses if poses is None else poses
    _presize_render(slam, loop, at)
    for kf, p in zip(loop.keyframes, at):
        slam.update_map(kf.kept(), Pose2D(float(p[0]), float(p[1]), float(p[2])), force=True)
    out = _MapExport.of(slam.map, take=True)  # (each of the level's arrays let go once read)
    del slam  # (the rest of the renderer goes before the float64 map is made: issue 13 item 3)
    # the float64 map made when read: a render the map check refuses never makes it (MIT CSAIL: 14.5 MiB; pass mem61)
    return ExportGridMap(out.logodds, out.unknown, out.resolution, out.origin), out.logodds


def render_written_map(loop: LoopResult, slam_config: SlamConfig) -> tuple[GridMap, np.ndarray] | None:
    """The written map (docs/maps.md, "Walls seen at grazing incidence"): the keyframes rendered at their
    final poses (the optimised ones when loop closure kept them, else the front end's) with the free-space
    update stopped ``slam_config.written_grazing_stop_cells / sin α`` cells before each return, so rays
    running along a wall do not clear it. The matcher's map is not touched. None when the option is 0 or
    there are no keyframes."""
    g = float(slam_config.written_grazing_stop_cells)
    if g <= 0.0 or not loop.keyframes:
        return None
    poses = loop.node_poses if loop.corrected else np.array([kf.frontend for kf in loop.keyframes], dtype=np.float64)
    return render_map(loop, slam_config, poses, grazing_stop_cells=g)


def _presize_render(slam: HectorSlam, loop: LoopResult, poses: np.ndarray | None = None) -> None:
    """Allocate the re-render's map once at the bounds of every cell it will touch, instead of growing it
    keyframe by keyframe (each growth copies the arrays and leaves the old ones to the allocator: tens of MB
    on MIT CSAIL). Cells are absolute, so the map's values are the same (issue 13 item 3). ``poses``: the
    keyframe poses rendered at (default ``loop.node_poses``)."""
    lv = slam.map.levels[0]
    b: list[int] | None = None
    for kf, p in zip(loop.keyframes, loop.node_poses if poses is None else poses):
        pose = Pose2D(float(p[0]), float(p[1]), float(p[2]))
        if not pose.is_finite():
            continue
        pts, clear = slam.scan_points(kf.kept())
        ends = np.vstack((pts, clear)) if clear.shape[0] else pts
        if ends.shape[0] < slam.config.min_points:
            continue
        c = lv.cell_bounds(np.array([pose.x, pose.y]), pose.transform_points(np.asarray(ends, dtype=np.float64)))
        b = list(c) if b is None else [min(b[0], c[0]), min(b[1], c[1]), max(b[2], c[2]), max(b[3], c[3])]
    if b is not None and (slam.map.max_bytes is None or lv.bytes_after_growth(*b) <= slam.map.max_bytes):
        lv.ensure(*b)


def map_entropy(logodds: np.ndarray) -> float:
    """Total binary entropy of the observed cells of a log-odds map, nats: Σ −p ln p − (1−p) ln(1−p)
    over cells with log-odds ≠ 0. Scans put at wrong poses blur walls into more, less certain cells,
    so a more consistent set of poses gives a lower total (the occupancy-grid form of the mean map
    entropy of Droeschel et al. / Razlaw et al., ECMR 2015)."""
    lo = np.asarray(logodds)
    vals = lo[lo != 0.0]
    if not vals.size:
        return 0.0
    # the terms p ln p + (1 − p) ln(1 − p), p = clip(σ(l)), with the same float64 operations as the whole-array
    # expression, a block of cells at a time into one array, summed once as before: no float64 copy of the
    # map and no map-sized temporary per operation (the loop closure's map check ran at the run's memory
    # peak; docs/speed.md)
    terms = np.empty(vals.shape[0], dtype=np.float64)
    for i0 in range(0, vals.shape[0], _ENTROPY_BLOCK):
        p = vals[i0:i0 + _ENTROPY_BLOCK].astype(np.float64)
        np.negative(p, out=p)
        np.exp(p, out=p)
        p += 1.0
        np.divide(1.0, p, out=p)
        np.clip(p, 1e-12, 1.0 - 1e-12, out=p)
        a = terms[i0:i0 + _ENTROPY_BLOCK]
        np.log(p, out=a)
        a *= p
        b = np.negative(p)
        np.log1p(b, out=b)
        np.subtract(1.0, p, out=p)
        b *= p
        a += b
    return float(-np.sum(terms))


#: Cells per block of :func:`map_entropy` (a few MB of temporaries).
_ENTROPY_BLOCK = 1 << 16


def keep_optimised(loop: LoopResult, front_logodds: np.ndarray, opt_logodds: np.ndarray,
                   config: LoopConfig) -> bool:
    """Whether the optimised poses replace the front end's (``loop.map_check``); records the decision
    and both entropies in ``loop.stats`` and sets ``loop.corrected`` accordingly."""
    h_front, h_opt = map_entropy(front_logodds), map_entropy(opt_logodds)
    loop.stats["map_entropy_frontend"] = round(h_front, 1)
    loop.stats["map_entropy_optimised"] = round(h_opt, 1)
    d = loop.node_poses[:, :2] - loop.frontend[loop.keyframe_scans, :2]
    moved = float(np.max(np.hypot(d[:, 0], d[:, 1]))) if d.size else 0.0
    loop.stats["max_keyframe_correction_m"] = round(moved, 4)
    keep = moved >= config.min_correction and (
        not config.map_check or h_opt < h_front * (1.0 - config.map_check_margin))
    loop.stats["kept_optimised"] = float(keep)
    loop.corrected = keep
    return keep


def _memory_report(result: RunResult, pipe: Pipeline) -> None:
    """Fill ``result.memory`` / ``result.erased`` from the tracker's memory and the erasure ledger."""
    mc = pipe.config.detect.memory
    rows = result.track_rows
    remembered = 0
    if isinstance(rows, TrackRows) and len(rows):
        remembered = len(np.unique(rows.array()["id"][rows.remembered()]))
    result.memory = {"enabled": mc.enabled, "erase": pipe.ledger is not None, "remembered_tracks": int(remembered)}
    if pipe.ledger is not None:
        result.memory.update(pipe.ledger.summary())
        g = result.grid
        result.erased = pipe.ledger.erased_mask(g.origin, g.shape, g.resolution)


@dataclass(eq=False)
class _MapExport:
    """The finest level of a map, cropped to its observed cells (:meth:`MultiResMap.to_gridmap`'s crop), as its
    float32 log-odds and a mask of the never-updated cells: 5 bytes per cell where the float64
    :class:`GridMap` and the log-odds take 12. ``run`` keeps the front end's map so until it knows whether the
    loop closure's re-render replaces it (issue 13 item 3)."""

    logodds: np.ndarray  # (H, W) float32, row 0 at the bottom
    unknown: np.ndarray  # (H, W) bool, never updated
    resolution: float  # m
    origin: tuple[float, float]  # world (x, y) of the lower-left corner of cell (0, 0), m

    @classmethod
    def of(cls, hmap: MultiResMap, take: bool = False) -> _MapExport:
        """The export of ``hmap``'s finest level. ``take``: let go of the level's arrays as they are read — its
        update indices once the unknown mask is made, then its log-odds once copied (the level is left empty) —
        so the export's copies are not made beside the whole level (issue 13 item 3: the end of the run loop and
        of the loop closure's re-render). Only frees memory no one else holds a view of."""
        lv = hmap.levels[0]
        if lv.empty:
            return cls(np.zeros((1, 1), dtype=np.float32), np.ones((1, 1), dtype=bool), lv.resolution,
                       lv.corner_origin())
        b = lv.known_bounds()
        r0, r1, c0, c1 = b if b is not None else (0, lv.shape[0], 0, lv.shape[1])
        origin = lv.corner_origin(r0, c0)
        unknown = lv.uidx[r0:r1, c0:c1] < 1
        if take:
            lv.release("uidx", "prob")
        logodds = lv.logodds[r0:r1, c0:c1].copy()
        if take:
            lv.release()
        return cls(logodds, unknown, lv.resolution, origin)

    def gridmap(self) -> GridMap:
        """The map as probabilities, NaN = never observed: the values of :meth:`MultiResMap.to_gridmap`."""
        return GridMap(logistic_map(self.logodds, self.unknown), self.resolution, self.origin)


class ExportGridMap(GridMap):
    """A map exported as float32 log-odds and a mask of its never-updated cells (:class:`_MapExport`) whose float64
    probabilities (``logistic_map``'s, NaN = never observed) are made when ``prob`` is first read: the run's online
    map goes through the loop closure's map check and the clean-up pass (which reads it a band of rows at a time,
    :meth:`prob_rows`) without its 8 bytes a cell (14.5 MiB on MIT CSAIL; issue 13 item 3, pass mem61). Once its
    log-odds are written, :meth:`pack` holds them packed, so the float64 map is made without them beside it. The
    log-odds and the mask must not change before; afterwards it is a plain :class:`GridMap`."""

    __slots__ = ("_export",)

    def __init__(self, logodds: np.ndarray, unknown: np.ndarray, resolution: float,  # noqa: D107
                 origin: tuple[float, float]) -> None:
        self._export: _MapExport | _PackedExport | None = _MapExport(logodds, unknown, resolution, origin)
        self.resolution = resolution
        self.origin = origin

    @property  # type: ignore[override]
    def prob(self) -> np.ndarray:
        export = self._export
        if isinstance(export, _MapExport):
            _GRID_PROB.__set__(self, logistic_map(export.logodds, export.unknown))
        elif export is not None:  # (packed: made a band of rows at a time)
            prob = np.empty(export.shape, dtype=np.float64)
            for r0 in range(0, export.shape[0], _PROB_ROWS):
                prob[r0:r0 + _PROB_ROWS] = self.prob_rows(r0, r0 + _PROB_ROWS)
            _GRID_PROB.__set__(self, prob)
        self._export = None
        return _GRID_PROB.__get__(self)

    @prob.setter
    def prob(self, value: np.ndarray) -> None:
        _GRID_PROB.__set__(self, np.asarray(value, dtype=np.float64))
        self._export = None

    @property
    def made(self) -> bool:
        """Whether the float64 probabilities exist (were read or set)."""
        return self._export is None

    @property
    def shape(self) -> tuple[int, int]:
        export = self._export
        if export is None:
            return _GRID_PROB.__get__(self).shape  # type: ignore[no-any-return]
        return export.shape if isinstance(export, _PackedExport) else export.unknown.shape  # type: ignore[return-value]

    def prob_rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0`` … ``r1`` − 1 of ``prob`` (the same values), without making the whole map when not made."""
        export = self._export
        if export is None:
            return _GRID_PROB.__get__(self)[r0:r1]
        if isinstance(export, _PackedExport):
            return logistic_map(*export.rows(r0, r1))
        return logistic_map(export.logodds[r0:r1], export.unknown[r0:r1])

    def pack(self) -> bool:
        """Hold the log-odds and the mask packed (:class:`_PackedExport`) until the map is made: for a caller whose
        other references to the log-odds are gone (the results, once the log-odds files are written; MIT CSAIL:
        9.1 → ≈ 1.3 MiB beside the float64 map as it is made). True if packed now."""
        if isinstance(self._export, _MapExport):
            packed = _PackedExport.of(self._export)
            if packed is not None:
                self._export = packed
                return True
        return False


#: :class:`GridMap`'s own storage of ``prob`` (a slot), under :class:`ExportGridMap`'s property
_GRID_PROB = GridMap.__dict__["prob"]
#: Rows of a packed :class:`ExportGridMap` made into probabilities at a time (float64 temporaries of a few MB).
_PROB_ROWS = 256


@dataclass(eq=False)
class _PackedExport:
    """A :class:`_MapExport` held small: its never-updated mask as bits and its log-odds at the updated cells only
    (every other cell's log-odds is 0, checked when packing), with each row's first updated cell. While the loop
    closure re-renders the map the front end's export no longer lies beside the re-render's level (MIT CSAIL: 9.1 →
    ≈ 1.3 MiB; pass mem61), nor the run's log-odds beside its float64 map as the results make it."""

    bits: np.ndarray  # np.packbits of the never-updated mask, C order
    values: np.ndarray  # float32 log-odds of the updated cells, C order
    starts: np.ndarray  # (H + 1,) int64: index in ``values`` of each row's first updated cell
    shape: tuple[int, int]
    resolution: float
    origin: tuple[float, float]

    @classmethod
    def of(cls, export: _MapExport) -> _PackedExport | None:
        """``export`` packed; None when a never-updated cell holds a log-odds other than 0 (not packed then)."""
        lo, unknown = export.logodds, export.unknown
        if _count_nonzero(lo[unknown]):
            return None
        known = ~unknown
        starts = np.zeros(unknown.shape[0] + 1, dtype=np.int64)
        np.cumsum(np.count_nonzero(known, axis=1), out=starts[1:])
        return cls(np.packbits(unknown, axis=None), lo[known], starts, unknown.shape, export.resolution,
                   export.origin)

    def rows(self, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
        """(log-odds, never-updated mask) of rows ``r0`` … ``r1`` − 1, as packed."""
        r1 = min(r1, self.shape[0])
        w = self.shape[1]
        # the band's bits: whole bytes around its cells, cut to them
        b0, b1 = (r0 * w) // 8, -(-(r1 * w) // 8)
        bits = np.unpackbits(self.bits[b0:b1])[r0 * w - 8 * b0:r0 * w - 8 * b0 + (r1 - r0) * w]
        unknown = bits.view(bool).reshape(r1 - r0, w)
        lo = np.zeros(unknown.shape, dtype=np.float32)
        lo[~unknown] = self.values[self.starts[r0]:self.starts[r1]]
        return lo, unknown

    def unpack(self) -> _MapExport:
        """The export as it was packed (the same arrays' values)."""
        lo, unknown = self.rows(0, self.shape[0])
        return _MapExport(lo, unknown, self.resolution, self.origin)


def _release_unexported(hmap: MultiResMap) -> None:
    """Free what :meth:`_MapExport.of` does not read: the coarser levels and the finest level's probability
    cache. The end of the run loop, where the export's copies are made beside every level, was the loop's
    second-highest point on MIT CSAIL (docs/speed.md "Memory, eighth pass")."""
    for k, lv in enumerate(hmap.levels):
        if k == 0:
            lv.release("prob")
        else:
            lv.release()


def _drop_views(pipe: Pipeline) -> None:
    """Let go of the views of the finest level held outside the map, so that freeing the level's arrays frees
    their memory: the tracker keeps the last scan's view of it (its log-odds array, 12.5 MB on MIT CSAIL), which
    would keep that level alive through the export, the re-render and the clean-up pass."""
    pipe.tracker._map = None
    pipe._view = None  # (the pipeline's own view of it, _evidence_view)


def _release_map(pipe: Pipeline, front: _MapExport) -> None:
    """Replace the front end's map arrays by empty ones (after the run, once the results hold their own
    copies): memory for the loop closure's re-render and the results (docs/speed.md). ``front`` is the
    front end's exported map, which :meth:`Pipeline.gridmap` returns from now on."""
    pipe._released_grid = front
    for lv in pipe.slam.map.levels:
        lv.release()
    _drop_views(pipe)
    if pipe.ledger is not None:
        pipe.ledger.release()  # its per-track records (tens of MB on MIT CSAIL); the summary stays
    release_free_memory()


ProgressFn = Callable[[int, StepResult], None]
#: One scan's scalars in :func:`run`: stamp (s), laser pose (x, y m; θ rad), score, flags (map_updated, rejected,
#: skipped) and pose confidence (:attr:`RunResult.confidence`).
_SCAN_RECORD = np.dtype([("stamp", np.float64), ("pose", np.float64, (3,)), ("score", np.float64),
                         ("flags", np.bool_, (3,)), ("low_support", np.bool_), ("degenerate", np.bool_),
                         ("lost", np.bool_), ("degeneracy", np.float64)])
#: One :data:`_SCAN_RECORD` row's bytes from its twelve fields (native order, no padding: the dtype's layout).
_PACK_SCAN = struct.Struct("=5d6?d").pack
assert struct.calcsize("=5d6?d") == _SCAN_RECORD.itemsize
#: :func:`run` returns the allocator's free heap memory to the OS every this many scans (memtrim.py).
TRIM_EVERY_SCANS = 1000


def _track_records(stamp: float, tracks: list[Track], track_rows: TrackRows) -> list[tuple]:
    """One scan's live tracks as :meth:`TrackRows.extend_records` rows (stamp, id, state code, box, velocity, in M,
    remembered): the velocity's two floats from one ``tolist`` (``float(v[0])``, ``float(v[1])``'s values), the
    flags as ``bool``."""
    codes, code = track_rows.state_codes, track_rows.code
    if type(tracks) is TrackReports:  # (from the reports' columns, no Track object built; passes trk70, trk90)
        return tracks.records(stamp, codes, code)
    out = []
    append = out.append
    for t in tracks:
        b = t.box
        st = t.state
        vx, vy = t.velocity.tolist()
        append((stamp, t.id, codes[st] if st in codes else code(st), b.px, b.py, b.theta, b.length, b.width, vx, vy,
                bool(t.in_m), bool(t.remembered)))
    return out


class _StageTimings:
    """:attr:`StepResult.timings` of every scan of a run, the values of each scan appended to one C float64 array of the
    standard library (one C call a scan, where six ``GrowArray.append`` calls cost a Python method and a NumPy item
    assignment each); :meth:`arrays` gives :attr:`RunResult.timings_ms`: per stage, in first-seen order, the values
    of the scans that had it. The stages are the first scan's; a scan with other stages (never from
    :meth:`Pipeline.process`) turns the rows into per-stage lists."""

    def __init__(self) -> None:
        self._keys: list[str] | None = None
        self._vals = array("d")  # the scans' values, row after row (len(_keys) per scan)
        self._other: dict[str, list[float]] | None = None  # per stage, once a scan's stages differed

    def add(self, timings: dict[str, float]) -> None:
        """Record one scan's stage timings (ms)."""
        keys = self._keys
        if keys is None:
            keys = self._keys = list(timings)
        other = self._other
        if other is None:
            if list(timings) == keys:
                self._vals.extend(timings.values())
                return
            rows = self._rows()  # (the rows so far as per-stage lists)
            other = self._other = {k: rows[:, i].tolist() for i, k in enumerate(keys)}
        for k, v in timings.items():
            col = other.get(k)
            if col is None:
                col = other[k] = []
            col.append(v)

    def _rows(self) -> np.ndarray:
        """(scans, stages) float64 copy of the values."""
        k = len(self._keys or ())
        return np.array(self._vals, dtype=np.float64).reshape(-1, k) if k else np.zeros((0, 0))

    def arrays(self) -> dict[str, np.ndarray]:
        """Stage name → float64 ms of the scans that had that stage (empty before any scan)."""
        if self._other is not None:
            return {k: np.array(v, dtype=np.float64) for k, v in self._other.items()}
        if self._keys is None:
            return {}
        rows = self._rows()
        return {k: rows[:, i].copy() for i, k in enumerate(self._keys)}


#: :func:`run` writes the scans' records (:class:`_RunRecords`) this many scans at a time.
RECORD_BATCH = 32


class _RunRecords:
    """The per-scan records of :func:`run` in compact growable arrays (:mod:`dynslam2d.records`: a few hundred bytes
    a scan instead of Python objects, so long logs do not exhaust memory): :attr:`per_scan` the scans' scalars
    (:data:`_SCAN_RECORD`), :attr:`removed` the removed-beam masks, :attr:`tracks` the live tracks' rows,
    :attr:`stages` the stage timings (ms).

    :meth:`add` writes the records of several scans at once (:data:`RECORD_BATCH` in :func:`run`): the same rows in
    the same order as one scan at a time, but the loop over the scans runs with its code and data in the CPU caches,
    where one scan's records right after ``Pipeline.process`` (whose arrays pushed them out) cost 3–6 times as much
    (docs/speed.md, pass rec110). A :class:`StepResult` is not changed after ``process`` returns it (the late
    observers read it later too: :class:`RunObserver`)."""

    def __init__(self) -> None:
        self.per_scan = PackedGrowArray(_SCAN_RECORD)
        self.removed = BitRows()
        self.tracks = TrackRows()
        self.stages = _StageTimings()

    def add(self, steps: list[StepResult]) -> None:
        """Record ``steps`` (in scan order) and empty the list. A scan's scalars go in one structured row given as
        its packed bytes (one ``struct`` call), its live tracks from the tracker's report columns
        (``TrackReports.add_rows``: one C call per column; a list of ``Track`` objects: one ``struct`` call per track,
        ``TrackRows.add_tracks``); NumPy converts neither (docs/speed.md, passes pip92, rec105). The rest — a
        value only NumPy converts (a ``None`` stored as NaN), dormant reports, a state name not coded yet — the NumPy
        way (``extend_records`` of :func:`_track_records`' tuples)."""
        # (record by record, each loop over the scans: its code stays in the first cache levels)
        add_row = self.per_scan.add_raw
        for step in steps:
            pose = step.pose
            try:
                add_row(_PACK_SCAN(step.stamp, pose.x, pose.y, pose.theta, step.score, step.map_updated, step.rejected,
                                   step.skipped, step.low_support, step.degenerate, step.slam_state == "lost",
                                   step.degeneracy))
            except (TypeError, ValueError, OverflowError, struct.error):  # (a value only NumPy converts: None → NaN)
                self.per_scan.append((step.stamp, (pose.x, pose.y, pose.theta), step.score,
                                      (step.map_updated, step.rejected, step.skipped), step.low_support,
                                      step.degenerate, step.slam_state == "lost", step.degeneracy))
        add_bits = self.removed.append
        for step in steps:
            add_bits(step.removed)
        track_rows = self.tracks
        for step in steps:
            tracks = step.tracks
            if tracks and not (tracks.add_rows(step.stamp, track_rows) if type(tracks) is TrackReports
                               else type(tracks) is list and track_rows.add_tracks(step.stamp, tracks)):
                track_rows.extend_records(_track_records(step.stamp, tracks, track_rows))
        add_stages = self.stages.add
        for step in steps:
            add_stages(step.timings)
        steps.clear()


class RunObserver(Protocol):
    """Something that watches a run scan by scan: a bag writer, an animation, a live viewer.

    ``on_scan`` is called after every scan with the input scan, its result and the pipeline
    (whose ``slam.gridmap()`` is the current map); ``on_finish`` once at the end, before
    :func:`run` returns. Observers must not change the pipeline.

    An observer that reads nothing of the pipeline but its ``config`` (only the scan and its result) may set
    ``scan_batch`` (int, class or instance attribute) to more than 1: :func:`run` then makes its ``on_scan`` calls
    late, for up to that many scans at a time, in scan order and all before ``on_finish`` (calls still pending
    when the loop raises are dropped). The scan loop then runs that observer's work before one ``process`` call in
    ``scan_batch`` instead of before each: its arrays no longer push the pipeline's out of the CPU caches every
    scan (docs/speed.md, pass wall38).
    """

    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None: ...

    def on_finish(self, result: RunResult, pipeline: Pipeline) -> None: ...


def _split_observers(observers: Sequence[RunObserver]) -> tuple[list[RunObserver], list[RunObserver], int]:
    """``observers`` as (called after every scan, called late in batches, the batch in scans): an observer is late
    when its ``scan_batch`` is more than 1; the batch is the smallest of theirs (each order kept)."""
    now: list[RunObserver] = []
    late: list[RunObserver] = []
    for obs in observers:
        (late if getattr(obs, "scan_batch", 1) > 1 else now).append(obs)
    return now, late, min((int(getattr(obs, "scan_batch", 1)) for obs in late), default=1)


def _feed(late: list[RunObserver], pending: list[tuple[Scan, StepResult]], pipe: Pipeline) -> None:
    """The pending ``on_scan`` calls of the ``late`` observers, scan after scan (each scan: the observers in their
    order, as :func:`run` calls the others); empties ``pending``."""
    for scan, step in pending:
        for obs in late:
            obs.on_scan(scan, step, pipe)
    pending.clear()


def run(
    source: ScanSource,
    config: Config | None = None,
    progress: ProgressFn | None = None,
    observers: Sequence[RunObserver] = (),
    gc_threshold0: int | None = SCAN_LOOP_GC_THRESHOLD0,
) -> RunResult:
    """Run the pipeline over every scan of ``source``.

    ``progress(n_done, step)`` is called after every scan (the CLI draws its progress bar
    from it); every observer sees every scan (see :class:`RunObserver`). During the per-scan loop
    Python's cyclic garbage collector collects its youngest generation every ``gc_threshold0``
    allocations instead of CPython's 700 (:func:`dynslam2d.collector.scan_loop_gc`; the previous
    thresholds come back when the loop ends or raises); None leaves the collector as it is.
    """
    pipe = Pipeline(config)
    source = apply_range_scale(source, pipe.config.laser, pipe.config.slam)
    # Per-scan records in compact growable arrays (dynslam2d.records), written RECORD_BATCH scans at a time
    # (_RunRecords; docs/speed.md, passes pip92, rec105, rec110).
    records = _RunRecords()
    waiting: list[StepResult] = []  # the scans whose records are not written yet, in scan order
    t0 = time.perf_counter()
    compile0 = compile_seconds()
    last_scan: Scan | None = None
    n_done = 0
    now, late, batch = _split_observers(observers)
    pending: list[tuple[Scan, StepResult]] = []  # the late observers' calls not made yet, in scan order
    with scan_loop_gc(gc_threshold0):  # fewer young collections while the scans run (collector.py)
        for scan in source:
            step = pipe.process(scan)
            last_scan = scan
            n_done += 1
            waiting.append(step)
            if len(waiting) >= RECORD_BATCH:
                records.add(waiting)
            for obs in now:
                obs.on_scan(scan, step, pipe)
            if late:
                pending.append((scan, step))
                if len(pending) >= batch:
                    _feed(late, pending, pipe)
            if progress is not None:
                progress(n_done, step)
            if n_done % TRIM_EVERY_SCANS == 0:
                release_free_memory()  # a long log's freed temporaries back to the OS (memtrim.py; ~ms per call)
        _feed(late, pending, pipe)  # (the last scans' late calls, before the map is released)
        records.add(waiting)  # (the last scans' records)
    compile_s = compile_seconds() - compile0
    release_free_memory()  # the loop's freed temporaries, before the observers' end-of-run work (memtrim.py)
    per_scan, removed_rows, track_rows, stage_ms = records.per_scan, records.removed, records.tracks, records.stages
    rec = per_scan.view()
    flag_arr = rec["flags"].copy()
    summary = pipe.slam.summary()
    memory_bytes = pipe.slam.memory_bytes
    _release_unexported(pipe.slam.map)  # the export below reads only the finest level's log-odds and indices
    _drop_views(pipe)  # (no view then keeps the level's arrays alive when the export lets them go)
    front = _MapExport.of(pipe.slam.map, take=True)  # (its float64 map is made once the run knows it keeps it)
    logodds = front.logodds
    # the front end's map is in ``front`` now: free its levels before the loop closure's final optimisation and
    # re-render build theirs (issue 13 item 3; observers' on_finish get the pipeline without its map arrays)
    _release_map(pipe, front)
    trajectory = Trajectory(rec["stamp"].copy(), rec["pose"].copy())
    frontend_trajectory = None
    grid: GridMap | None = None  # the written map; the front end's unless a render replaces it
    loop = pipe.loops.finish() if pipe.loops is not None else None
    if pipe.loops is not None:  # (its last search is done: the place descriptors go before the re-render)
        pipe.loops.release_places()
    if loop is not None and loop.corrected:
        # the front end's export packed while the re-render's level is built beside it, unpacked for the map check
        # (the same values; issue 13 item 3, pass mem61)
        packed = _PackedExport.of(front)
        if packed is not None:
            front = logodds = pipe._released_grid = None  # type: ignore[assignment]
            release_free_memory()  # (the packing's temporaries, in the heap's pages, before the render's level)
        t_render = time.perf_counter()
        grid_opt, lo_opt = render_map(loop, pipe.config.slam)
        loop.stats["render_ms"] = (time.perf_counter() - t_render) * 1e3
        if packed is not None:
            front = pipe._released_grid = packed.unpack()
            logodds = front.logodds
            del packed
        if keep_optimised(loop, logodds, lo_opt, pipe.config.loop):
            frontend_trajectory = trajectory
            trajectory = Trajectory(trajectory.stamps, loop.poses)
            grid, logodds = grid_opt, lo_opt
        del grid_opt, lo_opt  # a refused render goes before the written map's render below
    if loop is not None and pipe.config.slam.written_grazing_stop_cells > 0.0 and loop.keyframes:
        # the written map with the grazing stop, from the final poses; the matcher's map stays as it was
        # (docs/maps.md, "Walls seen at grazing incidence"); the front end's levels were freed above
        t_render = time.perf_counter()
        written = render_written_map(loop, pipe.config.slam)
        loop.stats["written_render_ms"] = (time.perf_counter() - t_render) * 1e3
        if written is not None:
            grid, logodds = written
    if grid is None:  # (its float64 map made when first read: not through the clean-up pass; pass mem61)
        grid = ExportGridMap(front.logodds, front.unknown, front.resolution, front.origin)
        pipe._released_grid = grid  # (the same map: Pipeline.gridmap returns it)
    del front
    wall = time.perf_counter() - t0
    result = RunResult(
        source=source.meta,
        config=pipe.config,
        trajectory=trajectory,
        scores=rec["score"].copy(),
        map_updated=flag_arr[:, 0],
        rejected=flag_arr[:, 1],
        skipped=flag_arr[:, 2],
        removed_rows=removed_rows,
        track_rows=track_rows,
        timings_ms=stage_ms.arrays(),
        grid=grid,
        logodds=logodds,
        wall_time_s=wall,
        reasons=dict(summary.get("reasons", {})),  # type: ignore[arg-type]
        memory_bytes=memory_bytes,
        tracker_stats=pipe.tracker.stats.as_dict(),
        confidence={k: rec[k].copy() for k in ("low_support", "degenerate", "lost", "degeneracy")},
        slam_stats={"lost_events": pipe.slam.lost_events, "relocalisations": pipe.slam.relocalisations},
        body=pipe.body.report(last_scan),
        frontend_trajectory=frontend_trajectory,
        loop=loop,
        kernel_compile_s=compile_s,
    )
    _memory_report(result, pipe)
    for obs in observers:
        obs.on_finish(result, pipe)
    return result
