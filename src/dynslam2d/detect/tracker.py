"""Tracking of moving objects in the map frame: ``Tracker(config).update(scan, pose)``.

Per scan (after DATMO's loop, Konstantinidis et al. 2020 and ``Datmo::callback`` in
kostaskonkk/datmo, with prediction, exclusive association and track confirmation added;
see docs/tracking.md):

1. bad input: a non-finite pose skips the scan; time going backwards, a gap > ``max_dt`` or a
   pose jump (faster than ``max_pose_speed`` / ``max_pose_rate``) drops every track; all counted
   in :attr:`Tracker.stats`, no exception;
2. predict every track to the scan stamp with the real dt (constant-velocity Kalman filter on
   the box centre, white-noise-acceleration Q(dt));
3. segment the scan (paper Eq. 1), transform the points into the map frame with the pose of
   the same scan, fit rectangle / circle / point models (paper Eq. 2);
4. exclusive association: Hungarian (``scipy.optimize.linear_sum_assignment``) on the
   Mahalanobis distance of the centre innovation, gated by χ² and a Euclidean distance;
5. Kalman update with the measurement of :func:`dynslam2d.detect.kernels.measure_batch` (which carries the
   track's size and heading: 90° ambiguity resolved against the track's axis), size and heading
   smoothing;
6. management: tentative → confirmed (M of N hits) → coasting (no detection, prediction only)
   → deleted (coasted longer than ``max_coast_time``, covariance blow-up, absurd speed);
7. the dynamic set M (paper Eq. 3): speed > v_min for ``sustain_updates`` consecutive
   updates, velocity well determined, and a net displacement ≥ ``min_displacement`` since
   birth; a track leaves M after ``sustain_updates`` updates below ``v_exit_ratio``·v_min.

Frames: the pose given with a scan is the laser pose in the map frame; every reported
quantity is in the map frame (m, rad, m/s).

Speed: steps 3–5 run as one numba kernel call per scan each (:mod:`dynslam2d.detect.kernels`:
classification and bounds of all clusters, the measurements, the gate, the Kalman updates, the
free-space and fragment tests); only the per-track bookkeeping stays in Python (≈0.8 ms per
720-beam scan with 10 movers, ``benchmarks/bench_detect.py``). The Kalman states and covariances of
all live tracks are two arrays owned by the tracker (``_X``, ``_P``; each track keeps one row for
life, its ``x`` / ``P`` are views of it): the prediction, the association and the reports read
them as whole arrays, the Kalman results are written back in one scatter per scan. The shape state
(box axis angle, sizes, radius, largest partial views, kind, heading and known-size flags) lives in two
more arrays on the same rows (``_G``, ``_Gi``; ``g`` / ``gi`` views per track, properties such as
``theta_box`` or ``size`` read them one track at a time): the measurement priors, the shape update, the
association's inputs and the reported boxes are one kernel call each over all pairs / tracks.
"""

from __future__ import annotations

import bisect
import copy
import math
from collections import deque
from dataclasses import asdict, dataclass, field
from itertools import chain as _chain
from itertools import starmap as _starmap

import numpy as np

from dynslam2d.detect.config import DetectConfig
from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.detect.frozen import fast_init
from dynslam2d.detect.kernels import (
    G_LB0,
    G_LB1,
    G_RADIUS,
    G_SIZE0,
    G_SIZE1,
    G_THETA,
    GI_HEADING,
    GI_KIND,
    GI_KNOWN0,
    GI_KNOWN1,
    N_G,
    N_GI,
    accel_candidates,
    association_rows,
    classify_batch,
    cv_predict,
    fit_params,
    fragment_hosts,
    gate_costs,
    kalman_update_batch,
    leg_pairs,
    manage_rows,
    measure_batch,
    merge_leg_pairs,
    pair_priors,
    report_boxes,
    select_detections,
    shape_update,
    size_jump_gate,
    world_points,
)
from dynslam2d.detect.layout import (
    F_THETA,
    FIT_CENTROID,
    FIT_CIRCLE,
    KIND_CIRCLE,
    KIND_CODES,
    KIND_NAMES,
    KIND_POINT,
    KIND_RECT,
    SIZE_MEASURED,
    DetectionBatch,
    MeasureRows,
)
from dynslam2d.detect.lsap import linear_sum_assignment  # scipy's solver without all of scipy.optimize
from dynslam2d.detect.mapevidence import MapView
from dynslam2d.detect.measure import Detection, ScanDetection, scan_detections
from dynslam2d.detect.segment import Segmentation, segment_scan
from dynslam2d.detect.shapes import CRITERIA, fit_clusters, search_angles
from dynslam2d.detect.vehicles import _NO_MAP, extent_limit
from dynslam2d.types import Box, Pose2D, Scan, Track, wrap_angle

TENTATIVE = "tentative"
CONFIRMED = "confirmed"
COASTING = "coasting"
_HALF_PI = 0.5 * math.pi
_TWO_PI = 2.0 * math.pi
_BIG = 1e12
_make_track = fast_init(Track)  # Track(...) / Box(...) without the frozen dataclass __init__ (detect/frozen.py)
_make_box = fast_init(Box)
_NO_BEAMS = np.zeros(0, dtype=np.int64)  # the beams of a track without detection (shared, never written)
_NO_STATE = np.zeros(0)  # placeholder x / P of a _Track before _add_row gives it its row
# a track's stored-points list starts anew once this many of its entries are out of date (_Track.past, past_a)
_PAST_COMPACT = 8
_ROWS0 = 64  # initial rows of the tracker's state arrays (doubled when full)
_any_of = np.logical_or.reduce  # (ndarray.any without the Python wrapper)


@dataclass
class TrackerStats:
    """Counters of what the tracker saw and did (bad input is counted here, never raised)."""

    scans: int = 0
    skipped_nonfinite_pose: int = 0
    empty_scans: int = 0
    time_resets: int = 0
    pose_jumps: int = 0
    clusters: int = 0
    structure_clusters: int = 0
    dropped_small_clusters: int = 0
    detections: int = 0
    tracks_born: int = 0
    tracks_deleted: int = 0
    deleted_coasting: int = 0
    deleted_covariance: int = 0
    deleted_speed: int = 0
    deleted_tentative: int = 0
    deleted_structure: int = 0  # still clutter on long-occupied map cells (structure_retire_updates)
    unborn_structure: int = 0  # detections on map structure given no track (structure_birth_min)
    revived_structure: int = 0  # dormant (retired) tracks back to life when their object left the structure
    rejected_updates: int = 0
    merged_fragments: int = 0
    merged_leg_pairs: int = 0
    accel_bounded: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass(eq=False, slots=True)  # (slots: faster attribute access in the per-track loops)
class _Track:
    id: int
    x: np.ndarray  # [px, py, vx, vy], map frame
    P: np.ndarray  # 4×4
    born: float
    last_hit: float
    birth_xy: np.ndarray
    # the shape state: views of the track's rows of the tracker's arrays (Tracker._G, _Gi; columns G_* / GI_* of
    # detect/kernels.py), read and written by the per-scan kernels; the properties below read them one track at a time
    g: np.ndarray  # (N_G,) float: axis angle, sizes, circle radius, largest partial views (rad, m)
    gi: np.ndarray  # (N_GI,) int8: kind code, has heading, known-size flags (both tuples until _add_row)
    state: str = TENTATIVE
    hits: int = 1
    misses: int = 0
    # the M-of-N rule's counts over the first confirm_window updates (all that it reads): how many updates (hits and
    # misses) and how many hits; two ints instead of a list of bools per track (docs/speed.md, pass trk16)
    hist_n: int = 1
    hist_hits: int = 1
    fast: int = 0
    in_m: bool = False
    reason: str = "not in M: tentative track"
    beams: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    # free-space fraction per update; an entry may be a detection (a birth's) or a tuple (det, ref, t, past) until it
    # is read, its value not yet computed (Tracker._free_values)
    free: list[float] = field(default_factory=list)
    # map evidence per update (mapevidence.py): (the detection's fractions of points on long-occupied, observed-free,
    # never-observed map cells) as one tuple per update in one list (was three lists: fewer objects touched per scan)
    mev: list[tuple[float, float, float]] = field(default_factory=list)
    person: bool = False  # the last detection was a merged pair of legs
    person_streak: int = 0  # consecutive updates with a merged pair of legs
    rode: bool = False  # judged riding with the laser (its body) at the last check
    was_in_m: bool = False  # has been in M before (seen moving): the map's word is not needed again
    # (laser-frame x, y, map-frame x, y of its centre (m), stamp (s)) per update of the riding test's window: one list
    # of one tuple per update (was three lists), fewer objects touched per scan (docs/speed.md, pass trk15)
    ride: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    # (stamp s, points array, a0, n) per update within the free-space memory's max age: the detection's (n, 2) points,
    # rows a0 … a0 + n − 1 of the array (its scan's), or the whole array for a0 < 0 (_past_entry, _past_points).
    # Append-only: the live entries are past[past_a:] (older ones are skipped by moving past_a, and dropped by
    # starting a new list every _PAST_COMPACT of them), so an update's snapshot of the entries before it is
    # (past, past_a, len(past)) instead of a copy (docs/speed.md, pass trk16); a new list, never a cleared one
    past: list[tuple[float, np.ndarray, int, int]] = field(default_factory=list)
    past_a: int = 0
    slow_since: float | None = None
    probation: bool = False  # in M, re-acquired after a gap: must show free-space evidence again
    merged: bool = False  # left M when its detection joined long-standing structure (refuses such detections)
    # track memory (detect.memory, docs/maps.md): kept in M through a stop
    remembered: bool = False  # in M only because it moved before (stopped for m_exit_time or longer)
    m_start_xy: tuple[float, float] | None = None  # centre where it last entered M, m
    m_time: float = 0.0  # time spent in M over its updates, s
    m_travel: float = 0.0  # largest distance of its centre from m_start_xy while in M, m
    m_last_t: float | None = None  # stamp of its last update in M, s
    row: int = -1  # its row of the tracker's state arrays (Tracker._X / _P / _G / _Gi; x, P, g, gi are views of it)

    # (the shape state as Python values, read from the rows: the tuples cannot be written in place by mistake)
    @property
    def theta_box(self) -> float:
        """Axis angle of size[0], rad (map frame)."""
        return self.g.item(G_THETA)

    @theta_box.setter
    def theta_box(self, value: float) -> None:
        self.g[G_THETA] = value

    @property
    def size(self) -> tuple[float, float]:
        """Sizes along theta_box and theta_box + π/2, m."""
        g = self.g
        return g.item(G_SIZE0), g.item(G_SIZE1)

    @size.setter
    def size(self, value) -> None:
        self.g[G_SIZE0], self.g[G_SIZE1] = value

    @property
    def size_lb(self) -> tuple[float, float]:
        """Largest partial views per axis, m."""
        g = self.g
        return g.item(G_LB0), g.item(G_LB1)

    @property
    def size_known(self) -> tuple[bool, bool]:
        """The sizes along each axis were measured (both bounds seen)."""
        gi = self.gi
        return gi.item(GI_KNOWN0) != 0, gi.item(GI_KNOWN1) != 0

    @size_known.setter
    def size_known(self, value) -> None:
        self.gi[GI_KNOWN0], self.gi[GI_KNOWN1] = value

    @property
    def radius(self) -> float:
        """Circle radius, m (0: none)."""
        return self.g.item(G_RADIUS)

    @radius.setter
    def radius(self, value: float) -> None:
        self.g[G_RADIUS] = value

    @property
    def kind(self) -> str:
        """Shape model of the last detection: "rect", "circle" or "point"."""
        return KIND_NAMES[self.gi.item(GI_KIND)]

    @kind.setter
    def kind(self, value: str) -> None:
        self.gi[GI_KIND] = KIND_CODES[value]

    @property
    def has_heading(self) -> bool:
        """theta_box comes from a rectangle fit."""
        return self.gi.item(GI_HEADING) != 0

    @has_heading.setter
    def has_heading(self, value: bool) -> None:
        self.gi[GI_HEADING] = value


def _new_track(tid: int, t: float, birth_xy: np.ndarray, g: tuple, gi: tuple, beams: np.ndarray, free: list,
               mev: list, past: list, _new=object.__new__) -> _Track:
    """``_Track(id=tid, x=_NO_STATE, P=_NO_STATE, born=t, last_hit=t, birth_xy=…, g=…, gi=…, beams=…, free=…, mev=…,
    past=…)`` with every other field at its default (a birth, :meth:`Tracker._birth`):
    the slots set directly, about a quarter of the dataclass ``__init__``'s cost with its keyword binding and default
    factories (``tests/test_detect_birth_fast.py`` compares every field with the dataclass's)."""
    k = _new(_Track)
    k.id = tid
    k.x = _NO_STATE
    k.P = _NO_STATE
    k.born = t
    k.last_hit = t
    k.birth_xy = birth_xy
    k.g = g
    k.gi = gi
    k.state = TENTATIVE
    k.hits = 1
    k.misses = 0
    k.hist_n = 1
    k.hist_hits = 1
    k.fast = 0
    k.in_m = False
    k.reason = "not in M: tentative track"
    k.beams = beams
    k.free = free
    k.mev = mev
    k.person = False
    k.person_streak = 0
    k.rode = False
    k.was_in_m = False
    k.ride = []
    k.past = past
    k.past_a = 0
    k.slow_since = None
    k.probation = False
    k.merged = False
    k.remembered = False
    k.m_start_xy = None
    k.m_time = 0.0
    k.m_travel = 0.0
    k.m_last_t = None
    k.row = -1
    return k


# (_shape_rows builds the rows in this column order)
assert (G_THETA, G_SIZE0, G_SIZE1, G_RADIUS, G_LB0, G_LB1, N_G) == (0, 1, 2, 3, 4, 5, 6)
assert (GI_KIND, GI_HEADING, GI_KNOWN0, GI_KNOWN1, N_GI) == (0, 1, 2, 3, 4)


def _shape_rows(theta_box: float, size, known, radius: float, kind: str, has_heading: bool) -> tuple:
    """A new track's (g, gi) shape values as tuples in the columns of detect/kernels.py (size_lb 0): what
    ``Tracker._add_row`` writes into its rows of the tracker's arrays (then g / gi become views of them)."""
    return (theta_box, size[0], size[1], radius, 0.0, 0.0), (KIND_CODES[kind], has_heading, known[0], known[1])


def _cv_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity transition F and white-noise-acceleration Q for state [x, y, vx, vy]."""
    q11, q12, q22 = q * dt ** 3 / 3.0, q * dt ** 2 / 2.0, q * dt
    # (flat lists reshaped: the same values, half the cost of nested lists)
    F = np.array([1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]).reshape(4, 4)
    Q = np.array([q11, 0.0, q12, 0.0, 0.0, q11, 0.0, q12, q12, 0.0, q22, 0.0, 0.0, q12, 0.0, q22]).reshape(4, 4)
    return F, Q


def _nearest_age(stamps: list[float], n: int, t: float, a: float, bisect_left=bisect.bisect_left) -> int:
    """Index of the entry of ``stamps`` (increasing, s; ``n`` = its length ≥ 1) whose age at ``t`` is nearest ``a``
    (s), looked for among ``stamps[ins − 3:ins + 3]`` around the insertion point ``ins`` of t − a, the first one on
    ties (as ``np.argmin`` of that window); −1 when no age is comparable (NaN).

    t − stamps[q] − a falls with q, so its magnitude falls, then rises: the search starts at ins − 1, goes forward
    while it falls and then back while it does not rise (to the earliest of equal ones) — the window's argmin in
    two or three steps instead of six."""
    ins = bisect_left(stamps, t - a)
    lo = ins - 3 if ins > 3 else 0
    q0 = ins - 1 if ins > 0 else 0
    j, best = -1, math.inf
    for q in range(q0, ins + 3 if ins + 3 < n else n):
        dev = abs((t - stamps[q]) - a)
        if dev < best:
            j, best = q, dev
        elif dev > best:
            break
    q = q0 - 1
    while q >= lo:
        dev = abs((t - stamps[q]) - a)
        if not dev <= best:  # (NaN stops too: never chosen)
            break
        j, best = q, dev
        q -= 1
    return j


def _past_entry(t: float, det: Detection) -> tuple[float, np.ndarray, int, int]:
    """A track's stored-points entry (``_Track.past``) for detection ``det`` at stamp ``t`` (s): its points as the
    array and row span a scan detection keeps (no view made; :func:`_past_points` makes it when read, the late
    vacated-space test), or a plain detection's own points."""
    if type(det) is ScanDetection:
        return t, det._pts, det._a0, det.n_points
    return t, det.points, -1, 0


def _past_points(entry: tuple[float, np.ndarray, int, int]) -> np.ndarray:
    """The (n, 2) map-frame points of a stored-points entry (:func:`_past_entry`)."""
    _, pts, a0, n = entry
    return pts if a0 < 0 else pts[a0:a0 + n]


def _default_sizes(lohi: list[float], rel: list[list[bool]], fit) -> list[float]:
    """:meth:`Detection.default_sizes` as a list of floats (the same arithmetic on the same values), from the
    detection's row of the scan's ``lohi`` (lo1, lo2, hi1, hi2) and ``rel`` as lists."""
    lo0, lo1, hi0, hi1 = lohi
    (r00, r01), (r10, r11) = rel
    e0, e1 = hi0 - lo0, hi1 - lo1
    o0 = e0 if r00 and r01 else max(e0, min(fit.default_depth, fit.default_depth_ratio * max(e1, 0.0)))
    o1 = e1 if r10 and r11 else max(e1, min(fit.default_depth, fit.default_depth_ratio * max(e0, 0.0)))
    return [o0, o1]


class Tracker:
    """Detect and track moving objects from 2D scans in the map frame.

    ``update(scan, pose)`` takes a scan and the laser pose **of that scan** in the map frame and
    returns the live tracks (tentative, confirmed, coasting). See the module docstring.
    """

    def __init__(self, config: DetectConfig | None = None) -> None:
        self.config = config or DetectConfig()
        self.stats = TrackerStats()
        self._tracks: list[_Track] = []
        # the Kalman states and covariances of the live tracks (struct of arrays: the prediction runs on all of
        # them at once, the reports copy them in one go); each _Track keeps its row for life (k.row; rows of
        # deleted tracks are reused by births) and its x / P are views of that row (re-pointed only when the
        # arrays grow, by doubling)
        self._X = np.zeros((_ROWS0, 4))
        self._P = np.zeros((_ROWS0, 4, 4))
        # … and their shape state (the same rows; columns G_* / GI_* of detect/kernels.py): the association, the shape
        # update and the reports read and write it for all tracks in one kernel call or gather each
        self._G = np.zeros((_ROWS0, N_G))
        self._Gi = np.zeros((_ROWS0, N_GI), dtype=np.int8)
        self._rows_used = 0  # rows 0 … _rows_used − 1 have been handed out
        self._free_rows: list[int] = []  # rows of deleted tracks, reused first
        self._order: np.ndarray | None = None  # the rows of self._tracks in their order (None: to be built)
        self._next_id = 1
        self._last_stamp: float | None = None
        self._last_pose: Pose2D | None = None
        self._angles = search_angles(self.config.fit.angle_step_deg)
        tc = self.config.tracker
        self._free = FreeSpaceMemory(tc.free_ref_ages, tc.free_margin) if tc.free_space_check else None
        self._ref_ages = np.array(self._free.ref_ages if self._free is not None else (), dtype=np.float64)
        self._ref_ages_l = self._ref_ages.tolist()  # (the same ages as floats: the one-track search, _vacated_one)
        self._cur_ref = None
        self._map: MapView | None = None  # the SLAM map given with the current scan (read only)
        self._pose: Pose2D | None = None
        self._pose_cs: tuple[float, float] = (1.0, 0.0)  # cos / sin of self._pose.theta
        self._scan: Scan | None = None
        self._pose_hist: deque = deque()  # (stamp, x, y, θ) of the last still_time seconds
        self._laser_still: bool | None = False  # (None: not compared yet in this scan, _is_still)
        self._dt = 0.0
        self._body_near: np.ndarray | None = None
        self._body_key: np.ndarray | None = None  # body beams the grown mask below was made from
        self._body_grown: np.ndarray = np.zeros(0, dtype=bool)
        self._fit_p = fit_params(self.config.fit)
        self._trig_key: tuple | None = None
        self._trig: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))
        self._batch: DetectionBatch | None = None  # per-detection arrays of the current scan (kernels)
        self._default: MeasureRows | None = None  # default measurements of the current scan's detections
        self._no_prior: dict[int, tuple] = {}  # measure_batch's "no track prior" arguments for m detections, by m
        self._size_sigma: dict[int, np.ndarray] = {}  # measure_batch's size σ of n associated pairs (m), by n
        self._stacked: tuple[np.ndarray, np.ndarray] | None = None  # predicted X, P of all tracks
        self._merged: set[int] = set()  # ids of tracks in M merged with structure in this scan (_associate)
        # this scan's ids of the updated tracks and indices of the detections they took (update, _update_tracks)
        self._upd_sets: tuple[set[int], set[int]] = (set(), set())
        # the last association's pairs (the list it returned) with their track and detection index arrays (int64)
        self._pair_arrays: tuple[list, np.ndarray, np.ndarray] | None = None
        # clutter retirement (structure_retire_updates): confirmed still tracks on map structure, out of the
        # Kalman tracking but kept (and reported) while their object is seen, so that a parked mover keeps
        # its id and standing history until it leaves (_clutter_detections)
        self._dormant: list[_Track] = []
        # … and the places of detections on structure that got no track: (m, 4) centre x, y (m, map frame), reach
        # (m) and the stamp last seen (s); like a dormant track, such a place keeps its detection from live tracks
        self._marks = np.zeros((0, 4))
        #: Segmentation and detections of the last processed scan (for inspection / plots).
        self.last_segmentation: Segmentation | None = None
        self.last_detections: list[Detection] = []

    # ------------------------------------------------------------------ public
    def reset(self) -> None:
        """Forget every track and the free-space evidence (ids keep counting up)."""
        self._tracks.clear()
        self._dormant.clear()
        self._marks = self._marks[:0]
        self._rows_used = 0
        self._free_rows.clear()
        self._order = None
        if self._free is not None:
            self._free.clear()

    @property
    def n_tracks(self) -> int:
        return len(self._tracks)

    def update(self, scan: Scan, pose: Pose2D, map_view: MapView | None = None,
               body_beams: np.ndarray | None = None) -> list[Track]:
        """Process one scan with the laser pose of the same scan (map frame); return the live tracks.

        ``map_view``: the SLAM map built from earlier scans (finest level, read only); with it and
        ``tracker.map_evidence`` the set M also needs the map's agreement (docs/tracking.md).
        ``body_beams``: (beams,) bool, the beams found to look at the robot's own body
        (:class:`dynslam2d.detect.body.BodyFilter`); given, only tracks on beams within
        ``tracker.ride_beam_window`` of them can be taken as riding with the robot (a car or a person
        keeping pace elsewhere is not the body). None: every near track can."""
        st = self.stats
        self._body_near = None
        if body_beams is not None and body_beams.shape[0] == scan.n_beams:
            # the body beams rarely change: the grown mask is kept while they stay the same
            key = self._body_key
            # (np.array_equal's answer for the bool masks, without its Python wrapper: the same dtype, shape and bytes)
            if key is None or key.dtype != body_beams.dtype or key.shape != body_beams.shape or \
                    key.tobytes() != body_beams.tobytes():
                w = self.config.tracker.ride_beam_window
                near = body_beams.astype(bool).copy()
                for d in range(1, w + 1):
                    near[d:] |= body_beams[:-d]
                    near[:-d] |= body_beams[d:]
                self._body_key = body_beams.copy()
                self._body_grown = near
            self._body_near = self._body_grown
        self._map = map_view if self.config.tracker.map_evidence else None
        self._pose = pose
        self._pose_cs = ((math.cos(pose.theta), math.sin(pose.theta)) if pose is not None
                         and math.isfinite(pose.theta) else (1.0, 0.0))
        self._scan = scan
        self._laser_still = self._still(float(scan.stamp), pose)
        st.scans += 1
        t = float(scan.stamp)
        if pose is None or not pose.is_finite():
            st.skipped_nonfinite_pose += 1
            return self._report(t, updated=set())
        dt = 0.0
        if self._last_stamp is not None:
            dt = t - self._last_stamp
            tc = self.config.tracker
            if dt < 0.0 or dt > tc.max_dt:
                st.time_resets += 1
                self.reset()
                dt = 0.0
            elif self._last_pose is not None and self._is_jump(self._last_pose, pose, dt):
                st.pose_jumps += 1
                self.reset()
        self._last_stamp, self._last_pose = t, pose
        self._dt = dt
        self._predict(dt)
        if self.config.tracker.aspect_prior is not None:  # (without it _motion_prior changes nothing)
            for k in self._tracks:
                if k.has_heading and k.kind == KIND_RECT and k.state != TENTATIVE:  # (_motion_prior skips tentative)
                    self._motion_prior(k)
        dets = self._detect(scan, pose)
        self._merged = set()
        if not dets and not scan.valid_mask().any():
            st.empty_scans += 1
        pairs = self._associate(dets)
        # (the ids of the updated tracks and the detections they took: filled by _update_tracks in its loop over the
        # pairs, in the pairs' order)
        updated: set[int] = set()
        used: set[int] = set()
        self._upd_sets = (updated, used)
        if pairs:
            st.rejected_updates += self._update_pairs(pairs, dets, t).count(False)
        self._manage(t, updated)
        unused = [di for di in range(len(dets)) if di not in used]
        if (self._map is not None and self.config.tracker.structure_birth_min <= 1.0) or self._dormant or \
                self._marks.shape[0]:
            unused = self._clutter_detections(dets, unused, t, updated)
        if self.config.tracker.confirm_hits > 1:  # births stay tentative: hosts can be found in one batch
            hosts = self._hosts_of_fragments(unused, updated)
        else:
            hosts = [None] * len(unused)
        for di, host in zip(unused, hosts):
            det = dets[di]
            if self.config.tracker.confirm_hits <= 1:
                host = self._host_of_fragment(det, updated)
            if host is not None:  # a piece of an object already updated: its beams belong to it
                host.beams = np.concatenate((host.beams, det.beams))
                st.merged_fragments += 1
                continue
            self._birth(det, t, di)
            updated.add(self._tracks[-1].id)
        out = self._report(t, updated)
        if self._dormant:
            out.extend(self._dormant_reports(t))
        return out

    def _host_of_fragment(self, det: Detection, updated: set[int]) -> _Track | None:
        """The updated confirmed track whose box (grown by fit.fragment_margin) holds the detection."""
        margin = self.config.fit.fragment_margin
        best, best_d = None, math.inf
        for k in self._tracks:
            if k.id not in updated or k.state != CONFIRMED:
                continue
            c, s = math.cos(k.theta_box), math.sin(k.theta_box)
            rel = det.points - k.x[:2]
            u = np.abs(rel[:, 0] * c + rel[:, 1] * s) - 0.5 * k.size[0]
            v = np.abs(-rel[:, 0] * s + rel[:, 1] * c) - 0.5 * k.size[1]
            d = float(np.max(np.maximum(u, v)))
            if d < margin and d < best_d:
                best, best_d = k, d
        return best

    def _hosts_of_fragments(self, dets: list[int], updated: set[int]) -> list[_Track | None]:
        """:meth:`_host_of_fragment` for several of this scan's detections (indices) in one kernel call."""
        if not dets:
            return []
        cand = [k for k in self._tracks if k.id in updated and k.state == CONFIRMED]
        if not cand:
            return [None] * len(dets)
        rows = np.array([k.row for k in cand], dtype=np.int64)
        X, G = self._X, self._G  # (the candidates' centres and shapes: one contiguous gather per column)
        b = self._batch
        idx = fragment_hosts(b.px, b.py, b.start, b.npts, np.array(dets, dtype=np.int64), X[rows, 0], X[rows, 1],
                             G[rows, G_THETA], G[rows, G_SIZE0], G[rows, G_SIZE1],
                             float(self.config.fit.fragment_margin))
        return [cand[i] if i >= 0 else None for i in idx.tolist()]

    # ------------------------------------------------------------------ steps
    def _is_jump(self, a: Pose2D, b: Pose2D, dt: float) -> bool:
        tc = self.config.tracker
        d = math.hypot(b.x - a.x, b.y - a.y)
        r = abs(float(wrap_angle(b.theta - a.theta)))
        if dt <= 1e-9:
            return d > 1e-3 or r > 1e-3
        return d / dt > tc.max_pose_speed or r / dt > tc.max_pose_rate

    def _predict(self, dt: float) -> None:
        self._stacked = None
        if not self._tracks or dt <= 0.0:
            return
        F, Q = _cv_matrices(dt, self.config.tracker.accel_noise)
        order = self._rows()
        tracks = self._tracks
        # coasting through a stop: it stays where it stood (from k.x / k.P, before the rows are written)
        still = [(i, self._stationary_prediction(tracks[i], F, dt)) for i in
                 [i for i, k in enumerate(tracks) if k.remembered and k.misses > 0]] \
            if self.config.memory.enabled else ()
        if order.shape[0] >= 2:
            # numpy's products bit for bit, the rows written in the kernel (the tracks' x / P are views of them)
            X, P = cv_predict(self._X, self._P, order, F, Q)
            for i, (x, p) in still:
                X[i], P[i] = x, p
                self._X[order[i]], self._P[order[i]] = x, p
        else:  # (one track: numpy's matrix-vector product, whose sums the kernel does not reproduce)
            X = self._X[order] @ F.T
            P = F @ self._P[order] @ F.T + Q
            for i, (x, p) in still:
                X[i], P[i] = x, p
            self._X[order] = X
            self._P[order] = P
        self._stacked = (X, P)

    def _stationary_prediction(self, k: _Track, F: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Prediction of a remembered (stopped) track that is not detected, with a stationary motion model
        (detect.memory): the centre stays, the velocity is 0, the position covariance grows by a small random walk and
        is kept at most ``memory.max_position_sigma``, the velocity covariance at most ``memory.max_speed_sigma``
        (it may start again: the velocity keeps some uncertainty and its coupling to the position)."""
        mc = self.config.memory
        x = k.x.copy()
        x[2:] = 0.0
        P = F @ k.P @ F.T
        P[0, 0] += mc.stationary_noise * dt
        P[1, 1] += mc.stationary_noise * dt
        sp = math.sqrt(max(P[0, 0], P[1, 1], 0.0))
        sv = math.sqrt(max(P[2, 2], P[3, 3], 0.0))
        a = min(1.0, mc.max_position_sigma / sp) if sp > 0.0 else 1.0
        b = min(1.0, mc.max_speed_sigma / sv) if sv > 0.0 else 1.0
        S = np.array([a, a, b, b])
        return x, P * S[:, None] * S[None, :]  # S P S: still a covariance

    def _stack(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, 4) states and (n, 4, 4) covariances of the live tracks (from the prediction when it ran)."""
        if self._stacked is None:
            order = self._rows()
            self._stacked = (self._X[order], self._P[order])
        return self._stacked

    def _rows(self) -> np.ndarray:
        """The state-array rows of the live tracks, in their order (int64)."""
        if self._order is None:
            self._order = np.array([k.row for k in self._tracks], dtype=np.int64)
        return self._order

    def _add_row(self, k: _Track, x, P: np.ndarray | None) -> None:
        """Append ``k`` to the live tracks with state ``x`` (4,) and covariance ``P`` (4, 4) (None: written by the
        caller into ``k.row`` afterwards): it gets a row of
        the state arrays (a deleted track's, else a new one; the arrays double when full) holding the values and
        its own shape rows ``k.g`` / ``k.gi``, and ``k.x`` / ``k.P`` / ``k.g`` / ``k.gi`` become views of it."""
        if self._free_rows:
            row = self._free_rows.pop()
        else:
            row = self._rows_used
            self._rows_used += 1
            if row == self._X.shape[0]:
                X = np.zeros((2 * row, 4))
                P2 = np.zeros((2 * row, 4, 4))
                X[:row] = self._X[:row]
                P2[:row] = self._P[:row]
                G = np.zeros((2 * row, N_G))
                Gi = np.zeros((2 * row, N_GI), dtype=np.int8)
                G[:row] = self._G[:row]
                Gi[:row] = self._Gi[:row]
                self._X, self._P, self._G, self._Gi = X, P2, G, Gi
                self._repoint()
        if x is not None:  # (None: the caller writes the state and covariance rows, _birth)
            self._X[row] = x
            self._P[row] = P
        self._G[row] = k.g
        self._Gi[row] = k.gi
        k.row = row
        k.x = self._X[row]
        k.P = self._P[row]
        k.g = self._G[row]
        k.gi = self._Gi[row]
        self._tracks.append(k)
        self._order = None

    def _repoint(self) -> None:
        """Make the x / P / g / gi of the live tracks views of their rows of the (new) state arrays."""
        X, P, G, Gi = self._X, self._P, self._G, self._Gi
        for k in self._tracks:
            row = k.row
            k.x = X[row]
            k.P = P[row]
            k.g = G[row]
            k.gi = Gi[row]

    def __deepcopy__(self, memo: dict) -> Tracker:
        """A deep copy whose tracks' x / P / g / gi are views of the copy's own state arrays (a plain deep copy would
        make them arrays of their own)."""
        new = object.__new__(type(self))
        memo[id(self)] = new
        for name, value in self.__dict__.items():
            setattr(new, name, copy.deepcopy(value, memo))
        new._repoint()
        new._stacked = None
        return new

    def _beam_trig(self, scan: Scan) -> tuple[np.ndarray, np.ndarray]:
        """cos / sin of the beam angles, cached per beam geometry (sensor frame)."""
        key = (scan.n_beams, float(scan.angle_min), float(scan.angle_increment))
        if self._trig_key != key:
            a = scan.angles
            self._trig = (np.cos(a), np.sin(a))
            self._trig_key = key
        return self._trig

    def _detect(self, scan: Scan, pose: Pose2D) -> list[Detection]:
        cfg = self.config
        st = self.stats
        ranges = scan.ranges
        valid = scan.valid_mask()  # (a copy)
        valid &= ranges > 0.0
        seg = segment_scan(scan, cfg.segment, valid, checked=True)
        self.last_segmentation = seg
        st.clusters += seg.n_clusters
        st.dropped_small_clusters += seg.n_dropped
        self._batch = None
        if seg.n_clusters == 0:
            self.last_detections = []
            if self._free is not None:
                self._free.add(scan, pose, valid)
            return []
        cos_a, sin_a = self._beam_trig(scan)
        # pose.transform_points of the beams (invalid ones at the pose), all beams and the clusters' ones
        beams = seg.beams
        ct, st_ = math.cos(pose.theta), math.sin(pose.theta)
        ax, ay, px, py, pts = world_points(ranges, valid, cos_a, sin_a, ct, st_, float(pose.x),
                                           float(pose.y), beams)
        offsets = seg.offsets
        fits = fit_clusters(px, py, offsets, ~seg.structure, self._angles, CRITERIA[cfg.fit.criterion],
                            cfg.fit.closeness_d0, cfg.fit.circle_min_points, cfg.fit.coarse_stride)
        # classify and bound every cluster (reference.classify_and_bound); then the vehicle-size clusters' map test
        # (detect/vehicles.py), the kept clusters' rows and their points' map evidence in one call. The map test is
        # per point, so only the detections' points are tested (structure clusters, most of the points, are not
        # detections)
        view = self._map
        sc, tc = cfg.segment, cfg.tracker
        if view is None:
            lo, i0, j0, res = _NO_MAP, 0, 0, 1.0
        else:
            lo, i0, j0, res = view.logodds, int(view.i0), int(view.j0), float(view.resolution)
        keep, kinds, lohi, rel = classify_batch(px, py, beams, offsets, fits, seg.structure, float(pose.x),
                                                float(pose.y), ranges, valid, ax, ay, seg.wrapped,
                                                int(sc.max_skip_beams), float(scan.range_max),
                                                abs(float(scan.angle_increment)), extent_limit(cfg), self._fit_p)
        starts, npts, kinds, lohi, rel, fits, mfr = select_detections(
            keep, kinds, lohi, rel, fits, offsets, px, py, sc.vehicle_max_extent > sc.max_extent,
            float(sc.max_extent), float(sc.vehicle_max_structure), float(sc.vehicle_min_free), view is not None, lo,
            i0, j0, res, float(tc.map_occupied_logodds), float(tc.map_free_logodds), int(tc.map_free_radius))
        nd = starts.shape[0]
        st.structure_clusters += seg.n_clusters - nd
        # free-space evidence per detection (0 where unknown). The free-space fraction is read for few detections
        # (births, updates whose entry is read: Tracker._free_values): each detection keeps this scan's test (the
        # memory's references now, before it gains this scan) and computes its fraction when first read
        # (ScanDetection.free_fraction)
        frac = 0.0
        fs = ff = fu = [0.0] * nd
        free = self._free
        if free is not None:
            self._cur_ref = free.make_ref(scan, pose, valid)
            if nd and (test := free.test_at(float(scan.stamp))) is not None:
                frac = test
            free.add(scan, pose, valid, self._cur_ref)
        if view is not None:
            fs, ff, fu = mfr.tolist()
        # (their centroid, bounds, flags and circle stay rows of fits / lohi / rel until read, their points rows of pts:
        # ScanDetection; all made in one loop, scan_detections)
        dets = scan_detections(beams, pts, starts.tolist(), npts.tolist(), kinds.tolist(), fits[:, F_THETA].tolist(),
                               frac, fs, ff, fu, fits, lohi, rel)
        if cfg.fit.person_merge and len(dets) > 1:
            dets, kinds, fits, lohi, rel, starts, npts, px, py = self._merge_legs(dets, kinds, fits, lohi, rel, starts,
                                                                                 npts, px, py, beams)
        st.detections += len(dets)
        self.last_detections = dets
        if dets:
            m = len(dets)
            self._batch = DetectionBatch(kind=kinds, theta=fits[:, F_THETA].copy(), lohi=lohi, rel=rel,
                                         centroid=fits[:, FIT_CENTROID].copy(), circle=fits[:, FIT_CIRCLE].copy(),
                                         px=px, py=py, start=starts, npts=npts)
            no_prior = self._no_prior.get(m)
            if no_prior is None:
                # (no track prior: the same arrays for every scan with m detections; the kernel only reads them)
                if len(self._no_prior) >= 64:
                    self._no_prior.clear()
                no_prior = self._no_prior[m] = (np.arange(m), np.zeros((m, 2)), np.zeros(m, dtype=bool),
                                                np.full(m, -1.0), np.zeros(m))
            self._default = self._measure_rows(*no_prior)
            # (the detections' bounds and real-bound flags: read as Python lists by row, for births and detections on
            # structure only (_birth_state, _clutter_detections): one row's tolist each, not the whole arrays' per scan)
        return dets

    def _merge_legs(self, dets: list[Detection], kinds: np.ndarray, fits: np.ndarray, lohi: np.ndarray,
                    rel: np.ndarray, starts: np.ndarray, npts: np.ndarray, px: np.ndarray, py: np.ndarray,
                    beams: np.ndarray) -> tuple:
        """People (leg_tracker, Leigh et al. ICRA 2015, pairs legs): two leg-sized detections (both sides
        ≤ ``fit.leg_max_extent``) whose centres lie within ``fit.leg_pair_distance`` become one person
        detection, measured at the middle of the two legs with the point model. A leg swinging forward while
        the other stands does not move the person's centre by a full stride, so its speed does not jump.
        Returns the detection list and the per-detection batch arrays, merged pairs appended at the end (the
        arrays by :func:`dynslam2d.detect.kernels.merge_leg_pairs`; ``beams``: the beams of ``px``, ``py``)."""
        fc = self.config.fit
        first, second = leg_pairs(lohi, npts, fits, float(fc.leg_max_extent), float(fc.leg_pair_distance))
        m = first.shape[0]
        if m == 0:
            return dets, kinds, fits, lohi, rel, starts, npts, px, py
        ki, kinds, fits, lohi, rel, starts, npts, px, py, mbeams = merge_leg_pairs(
            first, second, px, py, beams, starts, npts, kinds, fits, lohi, rel)
        new_dets = [dets[j] for j in ki.tolist()]
        row = len(new_dets)
        n0 = px.shape[0] - mbeams.shape[0]
        pts = np.empty((px.shape[0] - n0, 2))  # the persons' points, (n, 2) (np.column_stack's values)
        pts[:, 0] = px[n0:]
        pts[:, 1] = py[n0:]
        o = 0
        for a, b in zip(first.tolist(), second.tolist()):
            da, db = dets[a], dets[b]
            na, nb = da.n_points, db.n_points
            n = na + nb
            # (centroid = circle centre = the legs' middle, lo / hi their box, no real bound, theta 0: rows of the
            # merged arrays, as a scan detection's)
            det = ScanDetection(mbeams[o:o + n], pts, KIND_POINT, 0.0, n, (da, db),  # (free: when read)
                                (na * da.map_structure + nb * db.map_structure) / n,
                                (na * da.map_free + nb * db.map_free) / n,
                                (na * da.map_unknown + nb * db.map_unknown) / n, fits, lohi, rel, row, o)
            det.person = True
            new_dets.append(det)
            row += 1
            o += n
        self.stats.merged_leg_pairs += m
        return new_dets, kinds, fits, lohi, rel, starts, npts, px, py

    def _measure_rows(self, det: np.ndarray, sizes: np.ndarray, has_sizes: np.ndarray, radius: np.ndarray,
                      size_sigma: np.ndarray) -> MeasureRows:
        """:func:`dynslam2d.detect.reference.measure` of this scan's detections ``det`` with the given track
        priors, batched (see :func:`dynslam2d.detect.kernels.measure_batch`)."""
        return MeasureRows(*measure_batch(det, *self._batch, sizes, has_sizes, radius, size_sigma, self._fit_p))

    def _associate(self, dets: list[Detection]) -> list[tuple[int, int]]:
        n, m = len(self._tracks), len(dets)
        if n == 0 or m == 0:
            return []
        tc = self.config.tracker
        tracks = self._tracks
        Xs, Ps = self._stack()
        firm_r, tent_r, missed = [], [], []
        for i, k in enumerate(tracks):  # (the state and misses: Python attributes)
            (firm_r if k.state != TENTATIVE else tent_r).append(i)
            missed.append(k.misses > 0)
        # the tracks' sizes, flags and axis angles from their shape rows in one call ("known": a coasting track's size
        # is known if all(size_known) or it is not a rectangle)
        tsize, tmax, rect, theta, known = association_rows(self._G, self._Gi, self._rows(), np.array(missed))
        reach = 0.5 * tmax
        # Mahalanobis gate and distance gate; a rectangle is measured again with the track's own sizes
        # (a side the detection "measured" too short, e.g. a grazing side, must not break the association)
        d2, near, ok = gate_costs(Xs, Ps, reach, rect, theta, tsize,
                                  self._default.z, self._default.R, float(tc.gate_distance), float(tc.gate_chi2),
                                  *self._batch, self._fit_p)
        # a tracked object does not double its size from one scan to the next: a person track coasting
        # past a wall must not take the wall's cluster (it would carry M onto the wall)
        # (only for coasting tracks whose size is known: a bar first seen end-on may show its full length
        # later, a tracked object may touch another for a scan)
        ok, det_ext = size_jump_gate(ok, self._batch.lohi, tmax, known, float(tc.max_size_jump_ratio),
                                     float(tc.max_size_jump))
        if self._map is not None:
            ok = self._veto_merged(ok, dets, det_ext, tsize)
        if not _any_of(ok, axis=None):
            return []
        cost = np.where(ok, d2, _BIG)
        # established tracks choose first; tentative ones share what is left
        pairs: list[tuple[int, int]] = []
        taken: np.ndarray | None = None  # detections taken by the established tracks
        sel: list[tuple[np.ndarray, np.ndarray]] = []  # each group's (track, detection) index arrays
        for group in (firm_r, tent_r):
            if not group:
                continue
            rows_idx = np.array(group, dtype=np.int64)
            if taken is None:
                cols_idx = None
                sub = cost[rows_idx]  # (nothing taken yet: every column)
            else:
                cols_idx = (~taken).nonzero()[0]
                sub = cost[rows_idx[:, None], cols_idx]  # (one gather of the rows' free columns)
            if sub.size == 0:
                continue
            rr, cc = linear_sum_assignment(sub)
            ii = rows_idx[rr]
            jj = cc if cols_idx is None else cols_idx[cc]
            good = ok[ii, jj]
            ii, jj = ii[good], jj[good]
            pairs.extend(zip(ii.tolist(), jj.tolist()))
            sel.append((ii, jj))
            if group is firm_r and tent_r:  # (the columns left matter only to the tentative group)
                taken = np.zeros(m, dtype=bool)
                taken[jj] = True
        # (the pairs as index arrays too, for _update_pairs: kept with the list they belong to)
        if pairs:
            self._pair_arrays = (pairs, *(sel[0] if len(sel) == 1 else
                                          (np.concatenate((sel[0][0], sel[1][0])),
                                           np.concatenate((sel[0][1], sel[1][1])))))
        return pairs

    def _veto_merged(self, ok: np.ndarray, dets: list[Detection], det_ext: np.ndarray,
                     tsize: np.ndarray) -> np.ndarray:
        """``ok`` without the pairs in which a detection is a track in M merged with long-standing structure: at
        least ``map_structure_stop`` of its points on long-occupied map cells and its longer side more than
        ``merge_size_jump`` beyond the track's, while the track's own points were not on structure (mean ≤
        ``map_structure_max``). A person walking up to a wall joins the wall's cluster; updating the person's track
        with it would carry M onto the wall. A track in M left with no detection leaves M (:meth:`_manage`) and
        keeps refusing such detections (``merged``) until a detection of its own size updates it."""
        tc = self.config.tracker
        if self._dormant or self._marks.shape[0]:
            # a dormant track, or the place of a detection on structure that got no track, keeps its object's
            # detections on structure (_clutter_detections): no live track takes them, as the clutter track would
            # have kept them before it was retired (or without the rule, born on them)
            claimed = self._claims(dets)
            if claimed.any():
                ok = ok & ~claimed[None, :]
        rows = [i for i, k in enumerate(self._tracks) if k.in_m or k.merged]
        if not rows:
            return ok
        cand = np.array([d.map_structure >= tc.map_structure_stop for d in dets])
        if not cand.any():
            return ok
        ok = ok.copy()
        for i in rows:
            k = self._tracks[i]
            hit = ok[i] & cand & (det_ext > float(tsize[i].max()) + tc.merge_size_jump)
            if hit.any() and (not (mev := k.mev) or sum([e[0] for e in mev]) / len(mev) <= tc.map_structure_max):
                ok[i] &= ~hit
                self._merged.add(k.id)
        return ok

    def _update_pairs(self, pairs: list[tuple[int, int]], dets: list[Detection], t: float) -> list[bool]:
        """Kalman and shape updates of the associated (track, detection) pairs; True where applied.

        The track priors of the measurements (each track's sizes / radius), the measurements, the Kalman updates and
        the shape updates run as one kernel call each on the tracks' rows (:mod:`dynslam2d.detect.kernels`); the
        bookkeeping stays per track (:meth:`_update_tracks`)."""
        npair = len(pairs)
        pa = self._pair_arrays
        if pa is not None and pa[0] is pairs:  # (the association's index arrays of these pairs)
            sel, dis = pa[1], pa[2]
        else:
            sel = np.fromiter(_chain.from_iterable(pairs), np.int64, 2 * npair).reshape(npair, 2)
            dis = sel[:, 1].copy()
            sel = sel[:, 0].copy()
        self._pair_arrays = None
        b = self._batch
        trows = self._rows()[sel]
        swaps, sizes, has, radius = pair_priors(self._G, self._Gi, trows, dis, b.kind, b.theta)
        sig = self._size_sigma.get(npair)
        if sig is None:  # (the measurements' size σ, the same array for every scan with npair pairs: only read)
            if len(self._size_sigma) >= 64:
                self._size_sigma.clear()
            sig = self._size_sigma[npair] = np.full(npair, 0.05)
        mr = self._measure_rows(dis, sizes, has, radius, sig)
        Xs, Ps = self._stack()
        X_prior = Xs[sel]  # (kalman_update_batch works on copies: the prior stays as it is)
        Xn, Pn, ok = kalman_update_batch(X_prior, Ps[sel], mr.H, mr.zm, mr.Rm)
        self._bound_acceleration(X_prior, Xn, self._tracks, pairs)
        self._stacked = None  # the tracks change below
        out = ok.tolist()
        # the new states and covariances into the tracks' rows of the state arrays, all at once (every update applied,
        # the usual case: without the boolean selections)
        if all(out):
            self._X[trows] = Xn
            self._P[trows] = Pn
        else:
            rows = trows[ok]
            self._X[rows] = Xn[ok]
            self._P[rows] = Pn[ok]
        fc, tc = self.config.fit, self.config.tracker
        shape_update(self._G, self._Gi, self._X, trows, dis, ok, b.kind, b.theta, b.lohi, b.rel, b.circle,
                     mr.size_obs, mr.size_kind, swaps, float(fc.default_depth), float(fc.default_depth_ratio),
                     float(tc.heading_gain), float(tc.size_gain))
        self._update_tracks(pairs, dets, t, out, trows)
        return out

    def _bound_acceleration(self, X_prior: np.ndarray, X_new: np.ndarray, tracks: list[_Track],
                            pairs: list[tuple[int, int]]) -> None:
        """Physical acceleration bound (in place on ``X_new``): once a track's velocity is established
        (``accel_bound_after`` updates), one update may change it by at most ``max_accel``·dt — speeds no
        longer jump from scan to scan with the shape of a partial view or a leg swinging. Row r of the
        states belongs to ``tracks[pairs[r][0]]``."""
        tc = self.config.tracker
        if tc.max_accel is None or self._dt <= 0.0:
            return
        lim = tc.max_accel * self._dt
        # (speed: only rows whose velocity change comes near the bound go through the exact test below)
        near = accel_candidates(X_prior, X_new, (0.999 * lim) ** 2)
        if near.shape[0] == 0:
            return
        # (the candidates' velocities as Python floats in one gather each, the bounded ones written in one scatter)
        after, hypot = tc.accel_bound_after, math.hypot
        nb = 0
        for r, (pvx, pvy), (nvx, nvy) in zip(near.tolist(), X_prior[near, 2:].tolist(), X_new[near, 2:].tolist()):
            if tracks[pairs[r][0]].hits < after:
                continue
            dvx = nvx - pvx
            dvy = nvy - pvy
            d = hypot(dvx, dvy)
            if d > lim:
                # (written one element at a time: cheaper than a scatter of a few rows from a list of tuples)
                X_new[r, 2] = pvx + dvx * lim / d
                X_new[r, 3] = pvy + dvy * lim / d
                nb += 1
        if nb:
            self.stats.accel_bounded += nb

    def _update_tracks(self, pairs: list[tuple[int, int]], dets: list[Detection], t: float,
                       applied: list[bool], trows: np.ndarray) -> None:
        """The bookkeeping update of the tracks of ``pairs`` (track index, detection index; ``trows``: their rows of
        the state arrays) whose Kalman and shape results are already in their rows (k.x, k.P, k.g, k.gi) where
        ``applied``; the scan's constants are read once (one loop over the pairs: the update of one track is a few µs
        of Python)."""
        cfg = self.config
        tc, fc = cfg.tracker, cfg.fit
        pmin_r, pmax_r = fc.person_min_radius, fc.person_max_radius
        window, nsus, ride_time = tc.confirm_window, tc.sustain_updates, tc.ride_time
        p = self._pose
        if p is not None:
            pose_x, pose_y = p.x, p.y
            c, s = self._pose_cs  # cos / sin of the pose's heading (once per scan)
        use_map = self._map is not None
        max_age = self._free.max_age if self._free is not None else None
        ref = self._cur_ref if self._free is not None else None  # (the vacated-space test's reference: this scan)
        tracks = self._tracks
        upd, used = self._upd_sets
        upd_add, used_add = upd.add, used.add
        # (the detections' circle radii as floats, one conversion per scan: row di of the batch is detection di's fit
        # row, copied by the leg merge; float(det.circle[2]) would make a view per circle detection)
        radii = self._batch.circle[:, 2].tolist()
        if p is not None:
            # the centres in the map frame, one gather (their laser-frame centres below, on the floats one by one:
            # the roundings of the former elementwise numpy products and sums)
            centres = self._X[trows, :2].tolist()
            ns = -s
        else:
            centres = [None] * len(pairs)
        for (ti, di), ok, cen in zip(pairs, applied, centres):
            if not ok:
                continue
            k, det = tracks[ti], dets[di]
            upd_add(k.id)
            used_add(di)
            dkind = det.kind
            # (the stored points before this update: their vacated-space fraction is computed when first read)
            # ((the list, first, end): the entries are never changed in place, so this is their snapshot)
            past = k.past
            pa = k.past_a
            np0 = len(past)
            past0 = (past, pa, np0) if ref is not None and np0 > pa else None
            if k.misses > 0:
                # re-acquired after a gap: the free-space evidence must be rebuilt from this object
                k.past = []  # (a new list: the snapshots of earlier updates may hold the old one)
                k.past_a = 0
                k.free.clear()
                k.mev.clear()
                k.ride.clear()
                k.fast = 0
                k.probation = k.in_m and not k.remembered  # a remembered track re-acquired where it stopped
                k.misses = 0
            k.merged = False
            person = det.person or (dkind == KIND_CIRCLE and pmin_r <= radii[di] <= pmax_r)
            k.person = person
            k.person_streak = k.person_streak + 1 if person else 0
            k.hits += 1
            k.last_hit = t
            if k.hist_n < window:  # (the M-of-N counts: only the first window is read)
                k.hist_n += 1
                k.hist_hits += 1
            k.beams = det.beams
            free = k.free
            # (vacated: this scan sees through its old points; computed when the entry is read, _free_values)
            # (the detection's own fraction too: det.free_fraction, computed when read)
            free.append((det, ref, t, *past0) if past0 is not None else max(det.free_fraction, 0.0))
            if len(free) > nsus:
                del free[0]
            if p is not None:
                x0, x1 = cen
                dx = x0 - pose_x
                dy = x1 - pose_y
                ride = k.ride
                ride.append((c * dx + s * dy, ns * dx + c * dy, x0, x1, t))
                while len(ride) > nsus and t - ride[0][4] > ride_time:
                    del ride[0]
            if use_map:
                mev = k.mev
                mev.append((det.map_structure, det.map_free, det.map_unknown))
                if len(mev) > nsus:
                    del mev[0]
            if max_age is not None:
                past = k.past
                past.append((t, det._pts, det._a0, det.n_points))  # (_past_entry of a scan detection, inline)
                pa = k.past_a
                n = len(past)
                while pa < n and t - past[pa][0] > max_age:
                    pa += 1
                if pa >= _PAST_COMPACT:  # (a new list of the live entries: the old one stays with its snapshots)
                    k.past = past[pa:]
                    pa = 0
                k.past_a = pa

    def _motion_prior(self, k: _Track) -> None:
        """Hidden side of a moving box whose other side is measured: a side parallel to the motion is
        the length, one across it the width (``aspect_prior`` = width / length; cars and carts move
        along their long axis). Moves the hidden size by ``size_gain`` per update, never below the
        largest partial view."""
        tc = self.config.tracker
        kn0, kn1 = k.size_known
        if tc.aspect_prior is None or k.state == TENTATIVE or (kn0 and kn1) or not (kn0 or kn1):
            return
        speed = math.hypot(k.x[2], k.x[3])
        if speed < tc.prior_min_speed:
            return
        a = 0 if not k.size_known[0] else 1  # the hidden axis
        ax = k.theta_box + a * _HALF_PI
        c = abs(math.cos(ax) * k.x[2] + math.sin(ax) * k.x[3]) / speed
        if c > 0.9:  # hidden axis along the motion: it is the length
            prior = k.size[1 - a] / tc.aspect_prior
        elif c < 0.45:  # across the motion: the width
            prior = k.size[1 - a] * tc.aspect_prior
        else:
            return
        prior = min(max(prior, k.size_lb[a]), self.config.segment.max_extent)
        s = k.size[a]
        k.g[G_SIZE0 + a] = s + tc.size_gain * (prior - s)

    def _free_values(self, k: _Track) -> list[float]:
        """``k.free`` with every entry a float. A birth appends its detection instead of its free-space fraction, and an
        update whose track had stored points appends a tuple (det, ref, t, past, a, b): the detection (its own fraction
        is the floor), the free-space reference of the scan at ``t`` (s) and the track's stored (stamp, points) before
        the update (``past[a:b]``: ``_Track.past`` is append-only); its value, max(det.free_fraction, the vacated
        fraction of :meth:`_vacated_one` in that scan), is computed here when first read and replaces the entry (the
        detection's own fraction, too, is computed when first read: ScanDetection.free_fraction). Most entries are
        never read (the free-space condition of M is reached by few tracks; ≈ 3 % on negative_2), so most free-space
        tests never run."""
        free = k.free
        for q, v in enumerate(free):
            if type(v) is not float:
                free[q] = self._free_value(v)
        return free

    def _free_value(self, entry: float | Detection | tuple) -> float:
        """The free-space fraction of one entry of a track's ``free`` list (:meth:`_free_values`): a float, a detection
        (a birth's: its fraction) or a tuple (an update's, its floor the detection)."""
        if type(entry) is not tuple:
            return entry.free_fraction if isinstance(entry, Detection) else entry
        det, ref, t, past, a, b = entry
        return max(det.free_fraction, self._vacated_one(ref, t, past[a:b]))

    def _vacated_one(self, ref, t: float, past: tuple) -> float:
        """The vacated space of one track: the largest fraction of its stored points (``past``: ≥ 1 entries of
        ``_Track.past``, each a detection's (n, 2) map points, :func:`_past_points`) that the scan at ``t`` (s) sees
        through, against that scan's free-space reference ``ref`` — a receding object leaves free space behind its
        visible face. For each reference
        age the stored scan nearest it (:func:`_nearest_age`, −1 standing for the last entry; only scans older than
        ``t``) is tested once; the fraction is the count over n (0 for none)."""
        stamps = [e[0] for e in past]
        n = len(stamps)
        best, last = 0.0, -2
        for a in self._ref_ages_l:
            j = _nearest_age(stamps, n, t, a)
            if j < 0:
                j = n - 1
            if j == last or not t - stamps[j] > 0.0:
                continue
            last = j
            pts = _past_points(past[j])
            npt = pts.shape[0]
            f = self._free.count_seen_by(ref, pts) / npt if npt else 0.0
            best = max(best, f)
        return best

    def _birth(self, det: Detection, t: float, j: int) -> None:
        """A new tentative track from detection ``det`` (index ``j`` of this scan's detections)."""
        cfg = self.config
        size, known = self._birth_shape(det, j)
        kind = det.kind
        g, gi = _shape_rows(det.theta, size, known, self._batch.circle.item(j, 2) if kind == KIND_CIRCLE else 0.0,
                            kind, kind == KIND_RECT)
        has_map, has_free = self._map is not None, self._free is not None
        d = self._default  # reference.measure(det, None, None, cfg.fit) of every detection
        z = d.z[j]
        k = _new_track(self._next_id, t, z.copy(), g, gi, det.beams, [det],
                       [(det.map_structure, det.map_free, det.map_unknown)] if has_map else [],
                       [_past_entry(t, det)] if has_free else [])
        if cfg.tracker.confirm_hits <= 1:
            k.state = CONFIRMED
        self._next_id += 1
        self._add_row(k, None, None)
        # (the state and the initial covariance written into the new rows directly: _birth_state's values, without
        # the (4, 4) temporary it copies from)
        row = k.row
        X, P = self._X, self._P
        X[row, :2] = z
        X[row, 2:] = 0.0
        Pr = P[row]
        Pr.fill(0.0)
        Pr[:2, :2] = d.R[j]
        Pr[2, 2] = Pr[3, 3] = cfg.tracker.init_speed_sigma ** 2
        self.stats.tracks_born += 1

    def _birth_state(self, det: Detection, j: int) -> tuple[np.ndarray, np.ndarray, list[float], list[bool]]:
        """The measured centre z (2,), initial covariance P (4, 4), sizes and known-size flags of a track started
        from detection ``det`` (index ``j`` of this scan's detections), map frame, m."""
        cfg = self.config
        d = self._default  # reference.measure(det, None, None, cfg.fit) of every detection
        z = d.z[j]
        P = np.zeros((4, 4))
        P[:2, :2] = d.R[j]
        P[2, 2] = P[3, 3] = cfg.tracker.init_speed_sigma ** 2
        size, known = self._birth_shape(det, j)
        return z, P, size, known

    def _birth_shape(self, det: Detection, j: int) -> tuple[list[float], list[bool]]:
        """The sizes (m) and known-size flags of a track started from detection ``det`` (index ``j`` of this scan's
        detections)."""
        kind = det.kind
        if kind == KIND_RECT:
            b = self._batch
            size = _default_sizes(b.lohi[j].tolist(), b.rel[j].tolist(), self.config.fit)
            sk0, sk1 = self._default.size_kind[j].tolist()
            return size, [sk0 == SIZE_MEASURED, sk1 == SIZE_MEASURED]
        if kind == KIND_CIRCLE:
            return [float(2.0 * det.circle[2])] * 2, [True, True]
        lo0, lo1, hi0, hi1 = self._batch.lohi[j].tolist()
        return [max(hi0 - lo0, 0.05), max(hi1 - lo1, 0.05)], [False, False]  # (np.maximum(det.extent, 0.05))

    def _manage(self, t: float, updated: set[int]) -> None:
        """Track management (M of N, deletions, clutter retirement) and the test of M (paper Eq. 3) of the updated
        tracks. The covariance test and the speed's σ of all live tracks come from their state rows in one kernel
        call (``manage_rows``; the speeds are Python's ``math.hypot``, given to it); the test of M runs inline up to
        its common outcomes (tentative, or not in M and at most v_min) with the scan's constants read once, the rest
        in :meth:`_dynamic`."""
        tracks = self._tracks
        if not tracks:
            return
        tc = self.config.tracker
        st = self.stats
        keep: list[_Track] = []
        gone: list[int] = []  # the rows of the tracks deleted or retired here, in their order (births reuse them)
        mem = self.config.memory.enabled
        merged = self._merged
        window, need_hits = tc.confirm_window, tc.confirm_hits
        max_coast, max_sig, max_speed = tc.max_coast_time, tc.max_position_sigma, tc.max_object_speed
        hypot = math.hypot
        v_min = tc.v_min
        retire_n = tc.structure_retire_updates if self._map is not None else 0
        retire_s = tc.structure_retire_fraction
        # (the test of M's constants, the same products as in _dynamic)
        max_ssig, v_exit, nsus = tc.max_speed_sigma, tc.v_exit_ratio * tc.v_min, tc.sustain_updates
        ride_n, ride_r2 = tc.ride_updates, tc.ride_max_range * tc.ride_max_range
        probe = self._free is not None
        slow_tail = f" m/s ≤ v_min {v_min:.2f}"  # (the most common reason's constant part)
        order = self._rows()
        # per track: its speed (Python's math.hypot, as the reasons print it), whether its covariance fails (tested on
        # the rows as they are, instead of a flag kept in step wherever P changes) and σ of its speed along the
        # velocity, from the state rows in one kernel call
        speeds = list(_starmap(hypot, self._X[order, 2:].tolist()))
        bads, sigs = manage_rows(self._P, self._X, order, np.array(speeds), max_sig)
        bads, sigs = bads.tolist(), sigs.tolist()
        for k, speed, sig, bad in zip(tracks, speeds, sigs, bads):
            kid = k.id
            is_upd = kid in updated
            if kid in merged and not is_upd and k.in_m:
                k.in_m = False
                k.merged = True
                k.fast = 0
                k.reason = "left M: merged with long-occupied map structure (its detection joined a wall's cluster)"
            if not is_upd:
                k.misses += 1
                if k.in_m and not k.remembered and k.slow_since is not None and mem and self._hidden(k):
                    # stopped in M and hidden (something in front of it) before m_exit_time: it cannot finish its
                    # stop while unseen, so it is remembered now (if eligible) instead of being deleted after
                    # max_coast_time (a track that just vanishes in plain view, a false one, is not)
                    self._remember(k, t - k.slow_since)
                if k.hist_n < window:  # (the M-of-N counts: only the first window is read)
                    k.hist_n += 1
                k.beams = _NO_BEAMS
                if k.state == CONFIRMED:
                    k.state = COASTING
            elif k.state == COASTING:
                k.state = CONFIRMED
            if k.state == TENTATIVE:
                nh, n = k.hist_hits, k.hist_n  # (hits and updates among its first confirm_window updates)
                if nh >= need_hits:
                    k.state = CONFIRMED
                elif nh + (window - n) < need_hits or k.misses > 0 and n >= window:
                    st.deleted_tentative += 1
                    st.tracks_deleted += 1
                    gone.append(k.row)
                    continue
            if k.state == COASTING and t - k.last_hit > max_coast and not (
                    k.remembered and self._remembered_coasts(k, t)):
                st.deleted_coasting += 1
                st.tracks_deleted += 1
                gone.append(k.row)
                continue
            if bad:
                st.deleted_covariance += 1
                st.tracks_deleted += 1
                gone.append(k.row)
                continue
            if speed > max_speed:
                st.deleted_speed += 1
                st.tracks_deleted += 1
                gone.append(k.row)
                continue
            if is_upd and retire_n and not k.was_in_m and not k.remembered and len(mev := k.mev) >= retire_n \
                    and speed < v_min and min([e[0] for e in mev[-retire_n:]]) >= retire_s:
                # clutter retirement: a still track the map already holds as structure (docs/real.md "Speed");
                # a confirmed one stays as a dormant track while its object is seen (_clutter_detections)
                st.deleted_structure += 1
                if k.state == TENTATIVE:
                    st.tracks_deleted += 1
                else:
                    self._retire(k)
                gone.append(k.row)
                continue
            if is_upd:
                # paper Eq. 3 with persistence, certainty and displacement conditions (the start of _dynamic, inline)
                kfast = k.fast + 1 if speed > v_min and sig < max_ssig else 0
                k.fast = kfast
                if speed < v_exit:
                    if k.slow_since is None:
                        k.slow_since = t
                elif k.remembered and kfast < nsus:
                    pass  # a remembered stop ends only on M's sustained fast test, not on one scan of speed jitter
                else:
                    k.slow_since = None
                if k.in_m and k.probation and probe and len(k.free) >= nsus and self._probation_fails(k):
                    pass  # left M
                else:
                    rides = False
                    if len(ride := k.ride) >= ride_n:  # (fewer: it cannot ride)
                        lx, ly = ride[-1][:2]
                        if lx * lx + ly * ly > ride_r2:
                            k.rode = False  # (_rides_with_laser's first test, inline: most tracks are far from it)
                        else:
                            rides = self._rides_with_laser(k)
                    if rides:
                        k.in_m = False
                        k.fast = 0
                        k.reason = "not in M: fixed in the laser frame while the laser moves (the robot's own body)"
                    elif k.in_m:
                        self._dynamic(k, speed, sig, t)
                    elif k.state == TENTATIVE:
                        # (speed: most tracks are short-lived tentative clutter; nothing else changes them)
                        k.reason = "not in M: tentative track"
                    elif speed <= v_min:
                        k.reason = f"not in M: speed {speed:.2f}{slow_tail}"  # (the most common reason)
                    else:
                        self._dynamic(k, speed, sig, t)
                if mem:
                    if k.in_m:
                        self._memory_bookkeeping(k, t)
                    elif k.m_start_xy is not None or k.remembered:  # (_memory_bookkeeping of a track not in M, inline;
                        # with m_start_xy None, m_last_t is None, m_time and m_travel 0.0: set after it, reset with it)
                        k.m_start_xy, k.m_last_t, k.remembered = None, None, False
                        k.m_time = k.m_travel = 0.0
            keep.append(k)
        if gone:
            self._free_rows.extend(gone)
            self._order = None
        self._tracks = keep

    def _retire(self, k: _Track) -> None:
        """Make ``k`` (a confirmed track being retired as structure in :meth:`_manage`) dormant: out of the live
        tracks (its state-array row is freed, so its state becomes its own copy, at rest), kept in
        ``_dormant``."""
        x = k.x.copy()
        x[2:] = 0.0
        k.x, k.P, k.g, k.gi = x, k.P.copy(), k.g.copy(), k.gi.copy()
        k.fast = 0
        k.slow_since = None
        k.reason = "not in M: still, on long-occupied map cells (retired as structure)"
        self._dormant.append(k)

    def _clutter_detections(self, dets: list[Detection], unused: list[int], t: float,
                            updated: set[int]) -> list[int]:
        """Clutter retirement's handling of the detections no track took (docs/real.md "Fewer clutter tracks").

        A dormant track (:meth:`_retire`) keeps the unused detections whose centroid lies within half its box's
        longer side plus ``fit.fragment_margin`` of its centre: their beams are its beams in this scan's report
        (the map's evidence ledger keeps recording what it writes, slam/erasure.py). Such a detection with fewer
        than ``structure_birth_min`` of its points on long-occupied cells has left the structure: its object
        moves, and the dormant track comes back to life with it (:meth:`_revive`; it keeps its id, its birth
        place and its standing history, which the retroactive erasure needs). Other detections with at least
        ``structure_birth_min`` on long-occupied cells get no track and join no track as a fragment (an
        unassociated piece of wall beside a mover in M is not part of it); their places are kept (``_marks``) so
        that no live track takes them in later scans either. Dormant tracks and places unseen for
        ``max_coast_time`` are deleted. Returns the detections left for births and fragments."""
        tc = self.config.tracker
        st = self.stats
        dorm = self._dormant
        if dorm:
            n0 = len(dorm)
            dorm[:] = [k for k in dorm if t - k.last_hit <= tc.max_coast_time]
            st.tracks_deleted += n0 - len(dorm)
            for k in dorm:
                if k.last_hit != t:  # (retired in this scan: it keeps the beams of its last update)
                    k.beams = _NO_BEAMS
                    k.misses += 1
        marks = self._marks
        if marks.shape[0]:
            marks = marks[t - marks[:, 3] <= tc.max_coast_time]
        birth_max = tc.structure_birth_min if self._map is not None else 1.1
        nd = len(dorm)
        if (nd or marks.shape[0]) and unused:
            gaps = self._claim_gaps(unused, marks)
            best, gap = gaps.argmin(axis=1).tolist(), gaps.min(axis=1).tolist()  # nearest dormant track / place
        else:
            best = gap = None
        revived: set[int] = set()
        new_marks = []
        margin = self.config.fit.fragment_margin
        out = []
        for r, di in enumerate(unused):
            det = dets[di]
            on_structure = det.map_structure >= birth_max
            if on_structure:
                lo0, lo1, hi0, hi1 = self._batch.lohi[di].tolist()
                reach = 0.5 * max(hi0 - lo0, hi1 - lo1) + margin
            if gap is not None and gap[r] <= 0.0:
                i = best[r]
                if i >= nd:  # a place of structure without a track
                    if on_structure:
                        marks[i - nd] = (det.centroid[0], det.centroid[1], reach, t)
                        st.unborn_structure += 1
                        continue
                elif i not in revived:
                    k = dorm[i]
                    if on_structure:
                        k.beams = det.beams if k.last_hit != t else np.concatenate((k.beams, det.beams))
                        k.last_hit = t
                        k.misses = 0
                        continue
                    self._revive(k, det, t, di)
                    updated.add(k.id)
                    revived.add(i)
                    continue
            if on_structure:
                new_marks.append((det.centroid[0], det.centroid[1], reach, t))
                st.unborn_structure += 1
                continue
            out.append(di)
        if revived:
            dorm[:] = [k for i, k in enumerate(dorm) if i not in revived]
        self._marks = np.vstack((marks, new_marks)) if new_marks else marks
        return out

    def _claim_gaps(self, sel: list[int], marks: np.ndarray) -> np.ndarray:
        """(len(sel), dormant + len(marks)) distance from the centroid of each detection ``sel`` to the centre of
        each dormant track, then of each place ``marks``, minus its reach (half the dormant track's longer side
        plus ``fit.fragment_margin``; a place's own reach), m (≤ 0: the detection is that object)."""
        dorm = self._dormant
        margin = self.config.fit.fragment_margin
        cen = np.concatenate((np.array([(k.x.item(0), k.x.item(1)) for k in dorm]).reshape(-1, 2), marks[:, :2]))
        reach = np.concatenate((np.array([0.5 * max(k.size) + margin for k in dorm]), marks[:, 2]))
        c = self._batch.centroid[sel]  # (the detections' centroids, this scan's batch)
        return np.hypot(c[:, 0, None] - cen[None, :, 0], c[:, 1, None] - cen[None, :, 1]) - reach[None, :]

    def _claims(self, dets: list[Detection]) -> np.ndarray:
        """(n,) bool: the detection has at least ``structure_birth_min`` of its points on long-occupied cells and
        is a dormant track's object or that of a kept place (:meth:`_claim_gaps`)."""
        out = np.zeros(len(dets), dtype=bool)
        sel = [di for di, d in enumerate(dets) if d.map_structure >= self.config.tracker.structure_birth_min]
        if sel:
            out[sel] = (self._claim_gaps(sel, self._marks) <= 0.0).any(axis=1)
        return out

    def _revive(self, k: _Track, det: Detection, t: float, j: int) -> None:
        """A dormant track whose object left the structure (detection ``det``, index ``j``) back among the live
        tracks: restarted at the detection like a birth (state, covariance, shape, evidence lists), keeping its
        id, birth time and place, hits and state (docs/real.md "Fewer clutter tracks")."""
        z, P, size, known = self._birth_state(det, j)
        self.stats.revived_structure += 1
        k.theta_box, k.size, k.size_known, k.kind = det.theta, size, known, det.kind
        k.radius = float(det.circle[2]) if det.kind == KIND_CIRCLE else 0.0
        k.has_heading = det.kind == KIND_RECT
        k.hits += 1
        k.misses = 0
        k.last_hit = t
        k.beams = det.beams
        k.free = [det.free_fraction]
        if self._map is not None:
            k.mev = [(det.map_structure, det.map_free, det.map_unknown)]
        k.past = [_past_entry(t, det)] if self._free is not None else []
        k.past_a = 0
        k.ride = []
        k.person, k.person_streak, k.rode = False, 0, False
        k.reason = "not in M: left the map structure it was retired on"
        self._add_row(k, (z[0], z[1], 0.0, 0.0), P)

    def _dormant_reports(self, t: float) -> list[Track]:
        """Reports of the dormant tracks (at rest, not in M; beams only where seen in this scan)."""
        out = []
        zero = np.zeros(2)
        for k in self._dormant:
            if k.kind == KIND_CIRCLE:
                theta, length, width = 0.0, 2.0 * k.radius, 2.0 * k.radius
            elif k.size[1] > k.size[0]:
                theta, length, width = float(wrap_angle(k.theta_box + _HALF_PI)), k.size[1], k.size[0]
            else:
                theta, length, width = float(wrap_angle(k.theta_box)), k.size[0], k.size[1]
            out.append(_make_track(k.id, CONFIRMED if k.misses == 0 else COASTING, t,
                                   _make_box(float(k.x[0]), float(k.x[1]), theta, float(length), float(width)),
                                   zero.copy(), k.P.copy(), t - k.born, k.hits, k.misses, k.kind, False, k.reason,
                                   k.beams, len(k.beams), False))
        return out

    def _probation_fails(self, k: _Track) -> bool:
        """End the probation of ``k`` (in M, re-acquired after a gap, with ``sustain_updates`` free-space fractions):
        it leaves M (True) when they show no motion into free space."""
        k.probation = False
        free = self._free_values(k)
        if sum(free) / len(free) < self.config.tracker.free_min_fraction:
            k.in_m = False
            k.fast = 0
            k.reason = "left M: after a gap the detections show no motion into free space (a different, static object)"
            return True
        return False

    def _dynamic(self, k: _Track, speed: float, sig: float, t: float) -> None:
        """Paper Eq. 3 with persistence, certainty and displacement conditions: the rest of the test that
        :meth:`_manage` starts (speed persistence ``k.fast``, slow time, probation and the riding test done there)
        for an updated track in M, or confirmed / coasting with ``speed`` (m/s) > v_min; ``sig``: σ of the speed
        along the velocity, m/s."""
        tc = self.config.tracker
        # the map evidence's columns as lists (the same floats in the same order: the same sums)
        mev = k.mev
        ms = [e[0] for e in mev]
        # a track seen moving before re-enters M on the kinematic test: where it paused, the map wrote it
        use_map = self._map is not None and len(mev) > 0 and not k.was_in_m
        npu = tc.person_sustain_updates
        person_way = self._person_moved_in(k, npu, use_map) if k.person_streak >= npu else None
        fast_person = person_way is not None
        need = tc.person_sustain_updates if fast_person else tc.sustain_updates
        have_map = self._map is not None and len(mev) > 0
        if k.in_m and have_map and len(ms) >= tc.sustain_updates and \
                sum(ms) / len(ms) >= tc.map_structure_exit:
            k.in_m = False
            k.fast = 0
            k.reason = (f"left M: {sum(ms) / len(ms):.2f} of its points on long-occupied map cells "
                        "(structure)")
            return
        if k.in_m and have_map and k.slow_since is not None and t - k.slow_since >= tc.map_structure_stop_time \
                and len(ms) >= 2 and \
                0.5 * (ms[-1] + ms[-2]) >= tc.map_structure_stop:
            # a mover that stops where the map has long-standing structure has merged with it (a person
            # reaching a wall): hysteresis would carry M onto the wall
            k.in_m = False
            k.fast = 0
            k.reason = "left M: slowed down on long-occupied map cells (merged with structure)"
            return
        if k.in_m:
            slow_for = 0.0 if k.slow_since is None else t - k.slow_since
            if k.slow_since is not None and slow_for >= tc.m_exit_time and self._remember(k, slow_for):
                pass  # stopped, stays in M (track memory; the reason says why)
            elif k.slow_since is not None and slow_for >= tc.m_exit_time:
                k.in_m = False
                k.remembered = False
                k.reason = (f"left M: speed {speed:.2f} m/s below {tc.v_exit_ratio * tc.v_min:.2f} for "
                            f"{slow_for:.1f} s")
            elif k.slow_since is not None:
                k.reason = f"in M (hysteresis): slow ({speed:.2f} m/s) for {slow_for:.1f} s"
            else:
                k.remembered = False  # moving again
                disp = float(np.hypot(k.x[0] - k.birth_xy[0], k.x[1] - k.birth_xy[1]))
                k.reason = f"in M: speed {speed:.2f} m/s, moved {disp:.2f} m since birth"
            return
        if k.state == TENTATIVE:
            k.reason = "not in M: tentative track"
        elif speed <= tc.v_min:
            k.reason = f"not in M: speed {speed:.2f} m/s ≤ v_min {tc.v_min:.2f}"  # (the most common reason)
        elif sig >= tc.max_speed_sigma:
            k.reason = f"not in M: velocity uncertain (σ {sig:.2f} m/s)"
        elif k.fast < need:
            k.reason = f"not in M: speed > v_min for {k.fast}/{need} updates"
        elif (net := self._net_speed(k, need)) is not None and net < tc.net_speed_ratio * tc.v_min:
            k.reason = (f"not in M: net speed over the last {need} updates {net:.2f} m/s < "
                        f"{tc.net_speed_ratio * tc.v_min:.2f} (jitter, not motion)")
        elif (disp := float(np.hypot(k.x[0] - k.birth_xy[0], k.x[1] - k.birth_xy[1]))) < (
                min_disp := tc.person_min_displacement if person_way == "map" else tc.min_displacement):
            # (the net displacement since birth is computed only here: most tracks stop at a test above)
            k.reason = f"not in M: moved {disp:.2f} m < {min_disp:.2f} m since birth"
        elif self._free is not None and (not (fr := self._free_values(k)) or sum(fr) / len(fr) < tc.free_min_fraction):
            k.reason = (f"not in M: points on free space {sum(fr) / max(len(fr), 1):.2f} < "
                        f"{tc.free_min_fraction:.2f} (static structure)")
        elif use_map and not fast_person and sum(mf := [e[1] for e in mev]) / len(mf) < tc.map_free_min and not (
                self._is_still() and sum(mu := [e[2] for e in mev]) / len(mu) >= 1.0 - tc.map_free_min):
            k.reason = (f"not in M: points in observed-free map cells {sum(mf) / len(mf):.2f} < "
                        f"{tc.map_free_min:.2f} (no map evidence of motion)")
        elif use_map and sum(ms) / len(ms) > tc.map_structure_max:
            k.reason = (f"not in M: points on long-occupied map cells {sum(ms) / len(ms):.2f} > "
                        f"{tc.map_structure_max:.2f} (structure)")
        else:
            k.in_m = True
            k.was_in_m = True
            k.reason = (f"in M: speed {speed:.2f} m/s > v_min for {k.fast} updates, moved {disp:.2f} m "
                        "since birth")

    def _person_moved_in(self, k: _Track, n: int, use_map: bool) -> str | None:
        """How a person-shaped track shows that it moved into space that was empty, over its last ``n`` updates
        (the person's faster way into M, docs/tracking.md "People"); None = it does not.

        ``"kinematic"``: no map to ask (or the track was in M before); the general ``min_displacement`` applies.
        ``"map"``: a mean ≥ ``person_map_free_min`` of its points in observed-free map cells; then
        ``person_min_displacement`` since birth is enough. ``"free"``: where the map has not seen the place
        often enough, or the person's own earlier returns still mark the cells next to it, a mean ≥
        ``person_free_min`` of its points where an earlier scan saw through (or this scan sees through where it
        was: the free-space memory), with at most ``map_structure_max`` of them on long-occupied cells and at
        least half in cells the map has either seen free or never seen (not on cells it saw occupied); then
        the full ``min_displacement`` is needed. No earlier beam passes through a wall."""
        tc = self.config.tracker
        if not use_map:
            return "kinematic"  # no map to ask (or seen moving before): the general displacement applies
        last = k.mev[-n:]
        mf = [e[1] for e in last]
        if sum(mf) / len(mf) >= tc.person_map_free_min:
            return "map"
        fr, ms, mu = self._free_values(k)[-n:], [e[0] for e in last], [e[2] for e in last]
        if len(fr) < n or sum(fr) / len(fr) < tc.person_free_min or sum(ms) / len(ms) > tc.map_structure_max:
            return None
        return "free" if (sum(mf) + sum(mu)) / len(mf) >= 0.5 else None
    def _remember(self, k: _Track, slow_for: float) -> bool:
        """Track memory (detect.memory, docs/maps.md): a track in M that has stopped (slow for
        ``m_exit_time``) stays in M if it earned it — in M for ``min_m_time``, travelled ``min_travel`` from
        where it entered M, box no longer than ``max_size`` — until it has stood for ``expiry_s``. Sets
        ``remembered`` and the reason; False = the track leaves M as without memory."""
        mc = self.config.memory
        if not mc.enabled:
            return False
        if not k.remembered:
            eligible = (k.m_time >= mc.min_m_time and k.m_travel >= mc.min_travel
                        and float(max(k.size[0], k.size[1])) <= mc.max_size)
            if not eligible:
                return False
        if mc.expiry_s is not None and slow_for > mc.expiry_s:
            k.remembered = False
            return False
        k.remembered = True
        k.reason = (f"in M (remembered): stopped for {slow_for:.1f} s after moving {k.m_travel:.2f} m in M "
                    f"for {k.m_time:.1f} s")
        return True

    def _memory_bookkeeping(self, k: _Track, t: float) -> None:
        """Time in M and the largest distance from where the track entered M (the memory's evidence)."""
        if not k.in_m:
            k.m_start_xy, k.m_last_t, k.remembered = None, None, False
            k.m_time = k.m_travel = 0.0
            return
        x0, x1 = float(k.x[0]), float(k.x[1])
        if k.m_start_xy is None:
            k.m_start_xy = (x0, x1)
        elif k.m_last_t is not None:
            k.m_time += t - k.m_last_t
        k.m_last_t = t
        k.m_travel = max(k.m_travel, math.hypot(x0 - k.m_start_xy[0], x1 - k.m_start_xy[1]))

    def _remembered_coasts(self, k: _Track, t: float) -> bool:
        """A remembered track without detection is kept at its stopped place for ``memory.coast_time``
        unless this scan sees through its box (``memory.seen_through_share`` of the beams towards it pass
        beyond it: the object is gone)."""
        mc = self.config.memory
        if t - k.last_hit > mc.coast_time:
            return False
        return not self._seen_through(k)

    def _hidden(self, k: _Track) -> bool:
        """This scan's beams towards the track's box mostly return in front of its near side (occluded)."""
        scan, p = self._scan, self._pose
        if scan is None or p is None or not p.is_finite():
            return False
        dx, dy = float(k.x[0]) - p.x, float(k.x[1]) - p.y
        d = math.hypot(dx, dy)
        near = d - 0.5 * float(max(k.size[0], k.size[1])) - 0.1
        if near <= 0.0:
            return False
        diff = (scan.angles - (math.atan2(dy, dx) - p.theta) + math.pi) % _TWO_PI - math.pi
        sel = np.abs(diff) <= math.atan2(max(0.5 * float(min(k.size[0], k.size[1])), 0.05), d)
        n = int(np.count_nonzero(sel))
        if n < 3:
            return False
        with np.errstate(invalid="ignore"):  # (only valid returns: a beam without one hides nothing)
            return int(np.count_nonzero(scan.valid_mask()[sel] & (scan.ranges[sel] < near))) >= 0.5 * n

    def _seen_through(self, k: _Track) -> bool:
        """This scan's beams towards the track's box pass beyond its far side (laser frame of this scan)."""
        scan, p = self._scan, self._pose
        if scan is None or p is None or not p.is_finite():
            return False
        dx, dy = float(k.x[0]) - p.x, float(k.x[1]) - p.y
        d = math.hypot(dx, dy)
        half = 0.5 * float(max(k.size[0], k.size[1]))
        inner = 0.5 * float(min(k.size[0], k.size[1]))
        if d <= half + 0.1:
            return False
        bearing = math.atan2(dy, dx) - p.theta
        hw = math.atan2(max(inner, 0.05), d)
        diff = (scan.angles - bearing + math.pi) % _TWO_PI - math.pi
        sel = np.abs(diff) <= hw
        n = int(np.count_nonzero(sel))
        if n < 3:
            return False
        far = d + half + 0.2
        if far >= scan.range_max:
            return False
        r = scan.ranges[sel]
        with np.errstate(invalid="ignore"):
            beyond = ~np.isfinite(r) | (r > far)
        return float(np.count_nonzero(beyond)) / n >= self.config.memory.seen_through_share

    def _still(self, t: float, pose: Pose2D | None) -> bool | None:
        """The laser has stayed within ``still_distance`` / ``still_angle`` of its pose over the last
        ``still_time`` seconds (then walls cannot slide into view, and a map that a motionless robot does
        not update leaves the places people walk into unknown: unknown counts like free). Keeps the poses of
        the last ``still_time`` s; None: not decided yet, :meth:`_is_still` compares them with ``pose`` when asked."""
        tc = self.config.tracker
        if pose is None or not pose.is_finite():
            return False
        h = self._pose_hist
        h.append((t, pose.x, pose.y, pose.theta))
        while len(h) > 2 and t - h[1][0] >= tc.still_time:
            h.popleft()
        if t - h[0][0] < tc.still_time:
            return False
        return None  # (the poses are compared when asked: _is_still)

    def _is_still(self) -> bool:
        """:meth:`_still` of this scan; its comparison of the kept poses with this scan's runs when first asked in the
        scan (few tracks reach the test that asks)."""
        if self._laser_still is None:
            tc, pose = self.config.tracker, self._pose
            self._laser_still = all(math.hypot(x - pose.x, y - pose.y) <= tc.still_distance
                                    and abs(float(wrap_angle(th - pose.theta))) <= tc.still_angle
                                    for _, x, y, th in self._pose_hist)
        return self._laser_still

    @staticmethod
    def _net_speed(k: _Track, n: int) -> float | None:
        """Net displacement of the track's centre over its last ``n`` updates divided by their time span, m/s
        (None with fewer updates): pose jitter and association noise give a speed but no net motion."""
        ride = k.ride
        if len(ride) < max(n, 2):
            return None
        (_, _, x0, y0, t0), (_, _, x1, y1, t1) = ride[-n], ride[-1]
        dt = t1 - t0
        if dt <= 0.0:
            return None
        return math.hypot(x1 - x0, y1 - y0) / dt

    def _rides_with_laser(self, k: _Track) -> bool:
        """The track stays put in the LASER frame (spread below ``ride_tolerance``) within
        ``ride_max_range`` of the laser while its map-frame centre moves more than that and more than 4×
        the spread, over its updates of the last ``ride_time`` seconds (at least ``ride_updates`` of them,
        spanning at least half of it): it moves with the robot (its body)."""
        tc = self.config.tracker
        ride = k.ride
        if len(ride) < tc.ride_updates:
            return False
        lx_last, ly_last = ride[-1][:2]
        if lx_last * lx_last + ly_last * ly_last > tc.ride_max_range * tc.ride_max_range:
            k.rode = False
            return False  # far from the laser (most tracks): no arrays built
        nb = k.beams.shape[0]
        if self._body_near is not None and (nb == 0 or np.count_nonzero(self._body_near[k.beams]) / nb < 0.5):
            k.rode = False
            return False  # not where the robot's body was found
        t_end = ride[-1][4]
        n = sum(1 for e in ride if t_end - e[4] <= tc.ride_time)
        if n < tc.ride_updates or t_end - ride[-n][4] < 0.5 * tc.ride_time:
            return False
        lx = np.array([e[:2] for e in ride[-n:]])
        if float(np.hypot(lx[:, 0], lx[:, 1]).max()) > tc.ride_max_range:
            return False
        spread = float(np.hypot(*(lx - lx.mean(axis=0)).T).max())
        mx = np.array([e[2:4] for e in ride[-n:]])
        moved = float(np.hypot(*(mx[-1] - mx[0])))
        # with a motionless laser the two frames agree: only motion far beyond the laser-frame spread rides;
        # once found riding, a track keeps riding until its laser-frame spread clearly exceeds the tolerance
        # (a circle fit replacing a rectangle shifts the centre of a body part by a few cm)
        tol = 3.0 * tc.ride_tolerance if k.rode else tc.ride_tolerance
        k.rode = spread < tol and (k.rode or moved > max(tc.ride_tolerance, 4.0 * spread))
        return k.rode

    # ------------------------------------------------------------------ output
    def _report(self, t: float, updated: set[int]) -> list[Track]:
        tracks = self._tracks
        if not tracks:
            return []
        slow = 0.5 * self.config.tracker.v_min
        # (speed: the boxes of all tracks from their rows in one kernel call; states and covariances stacked in one copy
        # each, every report's velocity / covariance a row of them, its own memory apart from the tracker's)
        order = self._rows()
        n = order.shape[0]
        fast = np.empty(n, dtype=np.int8)  # (np.full without its Python wrapper)
        fast.fill(-1)
        boxes, undecided = report_boxes(self._G, self._Gi, self._X, order, slow, fast)
        if _any_of(undecided):  # (a speed within an ulp of the limit: decided by math.hypot, as the reports were)
            for i in undecided.nonzero()[0].tolist():
                vx, vy = self._X[order[i], 2:].tolist()
                fast[i] = math.hypot(vx, vy) > slow
            boxes, _ = report_boxes(self._G, self._Gi, self._X, order, slow, fast)
        X = self._X[order]  # (copies: the reports' own memory)
        P = self._P[order]
        V = X[:, 2:]
        kinds = self._Gi[order, GI_KIND].tolist()
        no_beams = np.zeros(0, dtype=np.int64)
        out = []
        append, make_track, make_box, names = out.append, _make_track, _make_box, KIND_NAMES  # (locals: per track)
        for k, (px, py, theta, length, width), kd, vel, cov in zip(tracks, boxes.tolist(), kinds, V, P):
            beams = k.beams if k.id in updated else no_beams
            in_m = k.in_m
            append(make_track(k.id, k.state, t, make_box(px, py, theta, length, width), vel, cov, t - k.born, k.hits,
                              k.misses, names[kd], in_m, k.reason, beams, len(beams), k.remembered and in_m))
        return out
