"""Loop closure behind the Hector-style front end (docs/slam.md, "Loop closure").

Design (after Cartographer, Hess et al. ICRA 2016, with the front end's single global map
kept as it is):

* **Keyframes** are the scans the front end writes into its map (every ``map_update_*``
  threshold). Each keyframe is a node of a :class:`~dynslam2d.slam.posegraph.PoseGraph`;
  consecutive keyframes are linked by the front end's relative pose (scan-to-map matching,
  which already carries the odometry prior where the recording has one), with a standard
  deviation that grows with the edge's length and is ten times larger across scans whose pose
  was not backed by a well-supported match.
* **Submaps**: every ``submap_keyframes`` consecutive keyframes form a small multi-resolution
  grid in the frame of its middle keyframe (the *anchor*), built from the keyframes' filtered
  scans (the beams the dynamic filter removed never enter it) at their front-end poses relative
  to the anchor. Grids are built when needed and a few are cached; what is kept for good is
  the keyframes' scans, their ranges packed in the narrowest codes that give them back bit for bit
  (:class:`Keyframe`).
* **Loop search**: on every ``search_every``-th keyframe, finished submaps whose anchor lies
  within a radius of the current pose estimate (grown with the path travelled since the submap:
  the front end's uncertainty) are searched with the correlative branch-and-bound matcher
  (Olson 2009; :func:`~dynslam2d.slam.correlative.correlative_search`) around the predicted pose,
  refined by the multi-resolution Gauss–Newton matcher. A match is a *candidate* if its score,
  its margin over the best pose elsewhere (runner-up), its supporting points and their angular
  spread are all high enough.
* **Far search**: after ``far_after`` m without a loop, a few older submaps beyond the local radius are
  searched over every rotation, within a radius grown with the translation deviations summed along the
  graph's shortest path to them — the ones whose place descriptors (:mod:`dynslam2d.slam.placedesc`, after
  Scan Context) look most like the keyframe's place; a far candidate must imply a correction that uncertainty
  allows (heading: drift per metre plus ``far_weak_turn`` per weak edge) and is verified on the keyframes
  before it, or else on the ones after it (consistent partners spanning some path), then optimised.
* **Weak stretches**: keyframe edges across weak matches are under the loops' robust kernel too, and edges
  across low-scoring matches get larger deviations, so that a loop correction bends the graph where the
  front end broke.
* **Consistency**: a candidate becomes a loop edge once another candidate within a few
  keyframes implies the same pose of the robot relative to the map (both loops and the chain of
  keyframes between them close up); lone candidates are dropped.
* **Optimisation**: during the run after every few accepted loops, and once at the end, with a
  robust kernel on loop edges and pruning of loops the graph does not support.

Every scan's optimised pose is its last keyframe's optimised pose composed with the front end's
relative pose from that keyframe. Poses are laser poses in the map frame (m, rad).
"""

from __future__ import annotations

import copy
import math
import time
from collections import OrderedDict, deque
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.correlative import correlative_search, even_indices
from dynslam2d.slam.graphdist import graph_distances
from dynslam2d.slam.grid import GridLevel, MultiResMap
from dynslam2d.slam.jumps import JumpCheck
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.matcher import degeneracy, evaluate, gated_points, no_drop
from dynslam2d.slam.placedesc import PlaceIndex
from dynslam2d.slam.posegraph import PoseGraph, compose, diag_info, relative
from dynslam2d.slam.rematch import refine_supported, rematch_keyframes
from dynslam2d.slam.secondsearch import run_second_search
from dynslam2d.types import Pose2D, Scan, _copy_scan, ranges_valid, wrap_angle

#: Submap grids kept built at a time (each a few MB).
_SUBMAP_CACHE = 6
#: Largest number of submaps searched per keyframe (nearest first).
_MAX_CANDIDATES = 3
#: Query points used per loop search (evenly sub-sampled).
_QUERY_POINTS = 360
#: Returns per keyframe that enter place descriptors (evenly sub-sampled).
_PLACE_POINTS = 120
_PLACE_BATCH = 16  # places described per call when the due ones are flushed (_place_flush)
#: Turn (rad) beyond a far candidate's heading limit within which its correlative match may lie (the far search
#: first searches only the rotations within limit + this, ``_far_search``; a match beyond them is refused even if
#: the Gauss–Newton refinement turns it back within the limit). The refinement moves a match by a few cells and
#: degrees at most (MIT CSAIL, Freiburg 079, Intel, negative_2: ≤ 2.9° over every far candidate; 0.25 rad = 14°),
#: so the rule refuses nothing the limit itself would not.
_REFINE_TURN = 0.25
#: Keyframe edges across unsupported scans get their deviation multiplied by this.
_WEAK_FACTOR = 10.0
#: Keyframes whose ranges are packed at a time (:meth:`LoopCloser._pack_keyframes`): the packing's NumPy calls are
#: made once per batch, not per keyframe (the loop closer's median scan does no packing).
_PACK_BATCH = 32
#: Decimal scales tried for a keyframe's ranges (ranges = integer codes / scale), the first that gives every range
#: back bit for bit: whole metres, decimetres, centimetres (MIT CSAIL's CARMEN log), millimetres.
_PACK_SCALES = (1.0, 10.0, 100.0, 1000.0)
#: Scans whose front-end poses and nodes the closer keeps in lists before it moves them into an array.
_POSE_CHUNK = 1024
_NO_BEAMS = np.zeros(0, dtype=bool)  # a keyframe's ``removed`` when the filter removed none of its beams
_NO_RANGES = np.zeros(0, dtype=np.float64)  # the ranges of a packed keyframe's scan shell (never read)


def _keep_probabilities(lv: GridLevel) -> None:
    """Let a built submap level's log-odds and update indices go: the loop searches read only its probability
    cache (the correlative search's score table, the matcher's refinement and support). Their place is taken by
    read-only broadcasts of "unknown" of the same shape (no memory), so the level keeps its shape and a write
    to them fails instead of going unnoticed."""
    shape = lv.shape
    lv.logodds = np.broadcast_to(np.zeros((), dtype=np.float32), shape)
    lv.uidx = np.broadcast_to(np.full((), -1, dtype=np.int32), shape)


#: Stored places above which a far search's ranking compares the query with its eligible submaps' places only
#: (LoopCloser._rank_rows): below, choosing the rows (≈ 13 µs) costs about what it saves (≈ 14 µs of 120 for half
#: of 105 places on negative_2 /right_scan, pass neg60); MIT CSAIL's 633 places: ≈ 0.50 → 0.25 ms a ranking.
_RANK_ROWS_MIN = 2 * 64

#: Grids whose rebuilt dense levels the closer keeps while a far candidate is verified (LoopCloser._dense): its
#: partners are matched against submaps s − 1, s and s + 1 in turn.
_DENSE_VERIFY = 3


class _SubmapGrid(MultiResMap):
    """A cached submap grid (:meth:`LoopCloser._submap_grid`) whose levels below the search level — read only by a
    match's refinement and support, not by the correlative searches — may be kept sparse: ``sparse[k]`` = (flat
    indices (int32), uint32 words) of the cells of level ``k``'s probability cache whose word is not 0 (0.5), and
    the level's own ``prob`` a read-only float32 NaN broadcast of its shape (a kernel reading it by mistake fails
    on its type, a write fails). :meth:`dense_level` gives the level back bit for bit. A grid just built holds those
    levels dense until it leaves the recent set of :meth:`LoopCloser._dense` (``late``)."""

    sparse: dict[int, tuple[np.ndarray, np.ndarray]]
    #: levels still dense that are made sparse when the grid leaves the recent set of :meth:`LoopCloser._dense`
    #: (pass lcm50: until then the grid's own caches are its entry's dense levels, never rebuilt)
    late: list[int]

    def dense_level(self, k: int) -> GridLevel:
        """Level ``k`` with its whole probability cache (a shallow copy of a sparse level with the cache rebuilt:
        0 (0.5) everywhere, the stored cells' words written back; the same bits)."""
        return self.dense_level_into(k, None)

    def dense_level_into(self, k: int, buf: np.ndarray | None) -> GridLevel:
        """:meth:`dense_level`, a sparse level's cache rebuilt in the flat uint32 buffer ``buf`` (its first
        cells, reshaped; a new array if ``buf`` is None or too short): no new allocation (nor its first-touch page
        faults) for a caller that owns ``buf`` and no longer reads what it held."""
        lv = self.levels[k]
        sp = self.sparse.get(k)
        if sp is None:
            return lv
        idx, vals = sp
        n = lv.shape[0] * lv.shape[1]
        if buf is None or buf.shape[0] < n:
            prob = np.zeros(lv.shape, dtype=np.uint32)
        else:
            prob = buf[:n].reshape(lv.shape)
            prob.fill(0)
        prob.reshape(-1)[idx] = vals
        out = copy.copy(lv)
        out.prob = prob
        return out


def _make_sparse(grid: _SubmapGrid, k: int) -> None:
    """Keep level ``k`` of ``grid`` sparse (:class:`_SubmapGrid`) if that takes less memory than its float32 cache
    (8 bytes a cell not 0.5 against 4 a cell: MIT CSAIL's submaps hold 6–15 % of such cells at 0.05–0.1 m)."""
    lv = grid.levels[k]
    flat = lv.prob.reshape(-1)
    idx = np.flatnonzero(flat)  # (the cache's words: 0 is 0.5)
    if 2 * idx.shape[0] >= flat.shape[0] or flat.shape[0] >= 2**31:
        return
    grid.sparse[k] = (idx.astype(np.int32), flat[idx])
    lv.prob = np.broadcast_to(np.float32(np.nan), lv.shape)


def _sparsify_late(grid: _SubmapGrid) -> dict[int, np.ndarray]:
    """Make ``grid``'s levels still dense that are due to be sparse (``grid.late``, see
    :meth:`LoopCloser._submap_grid`) sparse now (:func:`_make_sparse`); their former caches (uint32 words), flat, by
    level (only those made sparse and contiguous: they are then no longer the grid's, a buffer to rebuild in)."""
    bufs: dict[int, np.ndarray] = {}
    for k in grid.late:
        prob = grid.levels[k].prob
        _make_sparse(grid, k)
        if k in grid.sparse and prob.flags.c_contiguous:
            bufs[k] = prob.reshape(-1)
    grid.late = []
    return bufs


def _place_points(rel: np.ndarray, pts: list[np.ndarray]) -> np.ndarray:
    """(Σn, 2) float64 points of the keyframes' returns ``pts`` ((n_k, 2) float32 each, laser frame, m) placed
    in one frame with the poses ``rel`` ((k, 3): x, y m, θ rad), in one pass over all keyframes: per point
    ``x + cos θ·p_x − sin θ·p_y``, ``y + sin θ·p_x + cos θ·p_y`` with the products in float32 (``cos θ`` a Python
    float meets a float32 array: NumPy rounds it to float32, NEP 50) and the sums in float64, the operations of
    the per-keyframe expression this replaced, so the place descriptors stay bit-identical."""
    if not pts:
        return np.zeros((0, 2))
    p = np.concatenate(pts) if len(pts) > 1 else pts[0]
    counts = np.fromiter((q.shape[0] for q in pts), dtype=np.int64, count=len(pts))
    th = rel[:, 2].tolist()
    ct = np.repeat(np.array([math.cos(t) for t in th], dtype=np.float32), counts)
    st = np.repeat(np.array([math.sin(t) for t in th], dtype=np.float32), counts)
    x = np.repeat(rel[:, 0], counts)
    y = np.repeat(rel[:, 1], counts)
    px, py = p[:, 0], p[:, 1]
    out = np.empty((p.shape[0], 2), dtype=np.float64)
    out[:, 0] = x + ct * px - st * py
    out[:, 1] = y + st * px + ct * py
    return out


def _chain(a: np.ndarray, b: np.ndarray, e: np.ndarray) -> tuple[list[float], list[float]]:
    """(z, x): z = a⁻¹ ⊕ b and x = e ⊕ z of the (3,) poses ``a``, ``b``, ``e`` (x m, y m, θ rad) as lists of floats,
    with the float64 operations of :func:`~dynslam2d.slam.posegraph.relative` and
    :func:`~dynslam2d.slam.posegraph.compose` (NumPy's cos and sin; sums and products in the same order), so
    the values are the same bit for bit, without their arrays."""
    ax, ay, at = a.tolist()
    bx, by, bt = b.tolist()
    ex, ey, et = e.tolist()
    c, s = float(np.cos(at)), float(np.sin(at))
    dx, dy = bx - ax, by - ay
    zx, zy, zt = c * dx + s * dy, -s * dx + c * dy, wrap_angle(bt - at)
    c, s = float(np.cos(et)), float(np.sin(et))
    return [zx, zy, zt], [ex + c * zx - s * zy, ey + s * zx + c * zy, wrap_angle(et + zt)]


@dataclass(slots=True)
class Keyframe:
    """A scan written into the front end's map: its node, its front-end pose and its beams.

    ``scan`` has the robot's own body removed; ``removed`` marks the beams the dynamic filter
    removed (kept out of submaps and loop queries, and of the re-rendered map; an empty array when it removed none).
    Once packed (:meth:`pack`) the keyframe keeps its ranges as integer codes of a decimal scale (``codes /
    scale`` is every range bit for bit: uint16 centimetres for MIT CSAIL's log, 2 bytes a beam instead of 8) or as
    float32 when every range is a float32 value, and ``scan`` is rebuilt on every read from a shell of the scan's
    other fields (its valid mask is computed again: the same values).
    """

    scan_index: int
    stamp: float
    frontend: np.ndarray
    _scan: Scan  # the scan; once packed, a shell with every field but the ranges
    removed: np.ndarray
    path: float  # path length of the front end up to this keyframe, m
    _codes: np.ndarray | None = None  # packed ranges (None: not packed, ``_scan`` holds them)
    _scale: float = 0.0  # ranges = codes / scale (0: the codes are the ranges' values, float32 or float64)

    @property
    def scan(self) -> Scan:
        """The keyframe's scan (a new :class:`Scan` on each read once packed; its ranges are the scan's, bit for
        bit)."""
        codes = self._codes
        if codes is None:
            return self._scan
        return _copy_scan(self._scan, self.ranges(), None)

    def ranges(self) -> np.ndarray:
        """(n,) float64 ranges of the scan, m (a new array once packed)."""
        codes = self._codes
        if codes is None:
            return self._scan.ranges
        if self._scale:
            return codes.astype(np.float64) / self._scale
        return codes.astype(np.float64)

    @property
    def n_beams(self) -> int:
        codes = self._codes
        return int((self._scan.ranges if codes is None else codes).shape[0])

    def kept(self) -> Scan:
        """The scan with the removed beams set to "no return"."""
        if self.removed.size and self.removed.any():
            return self.scan.without(self.removed)
        return self.scan


def _pack_codes(r: np.ndarray, scales: tuple[float, ...]) -> tuple[np.ndarray, float] | None:
    """(codes, scale) of the (k, n) float64 ranges ``r``: the narrowest unsigned codes (uint16, uint32) of the first
    decimal ``scale`` of ``scales`` (in their order) for which ``codes.astype(float64) / scale`` is ``r`` bit for bit
    (the expression :meth:`Keyframe.ranges` reads them back with; a division is correctly rounded, so a range written
    with at most that many decimals comes back as the float its text was parsed to); else float32 codes (scale 0) if
    every range is a float32 value; None if neither holds."""
    bits = r.view(np.int64)
    if r.size and bool(np.isfinite(r).all()) and float(r.min()) >= 0.0:
        top = float(r.max())
        for s in scales:
            if top * s >= 4294967295.0:
                continue
            codes = np.rint(r * s).astype(np.uint16 if top * s < 65535.0 else np.uint32)
            if np.array_equal((codes.astype(np.float64) / s).view(np.int64), bits):
                return codes, s
    f = r.astype(np.float32)
    if np.array_equal(f.astype(np.float64).view(np.int64), bits):
        return f, 0.0
    return None


@dataclass(slots=True)
class LoopCandidate:
    """A scan-to-submap match: keyframe ``node`` seen from the anchor node ``anchor`` is ``z``."""

    node: int
    anchor: int
    z: np.ndarray
    score: float
    margin: float
    support: int
    accepted: bool = False
    far: bool = False  # found by the far search (uncertainty-grown radius, every rotation)


@dataclass(slots=True)
class LoopResult:
    """What :meth:`LoopCloser.finish` returns.

    Attributes:
        poses: (n, 3) optimised laser pose of every scan given to the closer (m, rad).
        frontend: (n, 3) the front end's poses of the same scans.
        keyframe_scans: (k,) scan index of every keyframe (graph node).
        node_poses: (k, 3) optimised keyframe poses.
        graph: the optimised pose graph.
        loops: accepted loop edges as (node i, node j) pairs that stayed active.
        corrected: the optimisation changed the poses (at least one loop edge stayed active).
        stats: counters (keyframes, submaps, searches, candidates, loops accepted / rejected, ms).
        keyframes: the keyframes (to re-render the map and recount the clean-up pass).
    """

    poses: np.ndarray
    frontend: np.ndarray
    keyframe_scans: np.ndarray
    node_poses: np.ndarray
    graph: PoseGraph
    loops: list[tuple[int, int]]
    corrected: bool
    stats: dict[str, float]
    keyframes: list[Keyframe] = field(default_factory=list, repr=False)


def edge_sigmas(config: LoopConfig, z: np.ndarray, weak: bool, score: float = math.nan) -> tuple[float, float]:
    """(σ_xy m, σ_θ rad) of a keyframe-to-keyframe edge of relative pose ``z``; ``weak``: a scan it spans was not
    backed by a well-supported match (deviation × _WEAK_FACTOR); ``score``: the lowest match score (0 … 1) of the
    scans it spans — below ``weak_score`` the deviation grows linearly up to × _WEAK_FACTOR at
    ``weak_score_floor`` (a match that barely fits is where the front end breaks; the loop corrections
    should bend the graph there, not spread over every edge)."""
    d = math.hypot(float(z[0]), float(z[1]))
    sxy = config.odom_sigma_xy + config.odom_sigma_per_m * d
    sth = config.odom_sigma_theta + config.odom_sigma_theta_per_rad * abs(float(z[2]))
    f = 1.0
    if weak:
        f = _WEAK_FACTOR
    elif config.weak_score > config.weak_score_floor and score < config.weak_score:
        t = min((config.weak_score - score) / (config.weak_score - config.weak_score_floor), 1.0)
        f = 1.0 + (_WEAK_FACTOR - 1.0) * t
    return sxy * f, sth * f


class _EdgeTable:
    """The graph's edges (keyframe chain and accepted loops) with two weights each, in insertion order: the
    translation deviation (m) and the heading deviation (rad) the far search sums along shortest paths. Kept as
    growing arrays beside a key → row map, so that each far search reads them without rebuilding them from
    dicts (the same rows, order and values as the dicts of (i, j) → weight they replace)."""

    def __init__(self) -> None:
        self._row: dict[tuple[int, int], int] = {}
        self._ij = np.zeros((64, 2), dtype=np.int64)
        self._w = np.zeros((64, 2), dtype=np.float64)

    def __len__(self) -> int:
        return len(self._row)

    def set(self, key: tuple[int, int], sigma: float, turn: float, keep_min: bool = False) -> None:
        """Edge ``key`` gets the weights (``sigma`` m, ``turn`` rad); with ``keep_min`` an existing edge keeps
        the smaller of its old and new weight, each on its own."""
        r = self._row.get(key)
        if r is None:
            r = len(self._row)
            if r == self._ij.shape[0]:
                self._ij = np.concatenate((self._ij, np.zeros_like(self._ij)))
                self._w = np.concatenate((self._w, np.zeros_like(self._w)))
            self._row[key] = r
            self._ij[r] = key
        elif keep_min:
            sigma = min(float(self._w[r, 0]), sigma)
            turn = min(float(self._w[r, 1]), turn)
        self._w[r, 0] = sigma
        self._w[r, 1] = turn

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """((n, 2) int64 node pairs, (n, 2) float64 weights [m, rad]), views in insertion order."""
        n = len(self._row)
        return self._ij[:n], self._w[:n]


class LoopCloser:
    """Builds the pose graph scan by scan (:meth:`add`) and returns the optimised trajectory
    (:meth:`finish`)."""

    def __init__(self, config: LoopConfig | None = None, slam: SlamConfig | None = None) -> None:
        self.config = config if config is not None else LoopConfig()
        self.slam = slam if slam is not None else SlamConfig()
        self.graph = PoseGraph()
        self.keyframes: list[Keyframe] = []
        self.candidates: list[LoopCandidate] = []
        self.loop_edges: list[int] = []  # edge indices in the graph
        # per scan: its last keyframe's node (−1 before the first) and its front-end pose (x, y m, θ rad): the last
        # scans' in lists (one append a scan), every _POSE_CHUNK scans moved into (n, 4) float64 arrays (node, x,
        # y, θ; 32 bytes a scan where a tuple of three Python floats and an int took ≈ 170)
        self._scan_node: list[int] = []
        self._frontend: list[tuple[float, float, float]] = []
        self._pose_chunks: list[np.ndarray] = []
        self._n_chunked = 0  # scans moved into _pose_chunks
        # per keyframe, the edge from the one before it: a scan it spans was weak; the lowest match score of
        # those scans (NaN: none given)
        self.kf_weak: list[bool] = []
        self.kf_score: list[float] = []
        self._weak_since_kf = False
        self._score_since_kf = math.inf  # lowest match score since the last keyframe
        sc = self.slam
        self._jumps = JumpCheck(sc.jump_shift, sc.jump_ratio, sc.jump_turn) if self.config.jump_weak else None
        self._path = 0.0
        self._last_pose: tuple[float, float] | None = None  # (x, y) of the last finite pose, m
        self._opt_nodes = 0  # nodes covered by the last optimisation
        self._new_loops = 0
        self._cache: OrderedDict[int, _SubmapGrid] = OrderedDict()
        self._cache_size = _SUBMAP_CACHE  # grids kept built (the second search keeps more: it jumps between places)
        # the cache of rebuilt dense levels (_dense): id(grid) → (grid, its dense levels by level, the flat uint32
        # buffers they are rebuilt in by level), least recently used first; one entry outside a far verification
        self._dense_entries: OrderedDict[int, tuple[_SubmapGrid, dict[int, GridLevel], dict[int, np.ndarray]]] = \
            OrderedDict()
        self._dense_spare: dict[int, np.ndarray] = {}  # the buffers of an entry forgotten, for the next one
        self._verifying = 0  # > 0 inside _verify_far / _pending_far
        self._unpacked: list[int] = []  # keyframes whose ranges are not packed yet (_pack_keyframes), ascending
        self._pack_scales = _PACK_SCALES  # the decimal scales in the order tried: the last one that held first
        # submap → its far-search level (far_level), kept for every submap built (≈ 10–20 kB each at 0.4 m) after its
        # grid leaves the cache: a far search whose correlative match is refused reads nothing else, so it needs
        # no rebuild (the same level: a submap's inputs change only through drop_beams, which drops both)
        self._far_levels: dict[int, GridLevel] = {}
        # translation deviation (m) of every chain edge and accepted loop, keyed (i, j): the far search's
        # uncertainty is their sum along the graph's shortest path; and their heading deviations, rad:
        # drift_rad_per_m × length, plus far_weak_turn across a weak match
        self._edges = _EdgeTable()
        self._far_last: dict[int, int] = {}  # submap → node of its last far search
        # during the second search (slam/secondsearch.py): the (anchor, node) pairs that have a loop edge; else None
        self._second: set[tuple[int, int]] | None = None
        self._second_tried: list[LoopCandidate] | None = None  # … and its far candidates (verified or not)
        # far candidates whose keyframes before them gave too few partners: (candidate, submap, partners so far)
        self._pending: list[tuple[LoopCandidate, int, list[LoopCandidate]]] = []
        self._extent: dict[int, float] = {}  # submap → largest keyframe distance from its anchor, m
        self._loop_path = 0.0  # front-end path length at the last accepted loop's keyframe, m
        c = self.config
        # place descriptors of every place_every-th keyframe: the far search ranks submaps by them
        self._places = (PlaceIndex(c.place_rings, c.place_sectors, c.place_max_range)
                        if c.far_search and c.far_rank == "descriptor" else None)
        #: (node, descriptor, its spectra if stored: :meth:`PlaceIndex.add_many`) of the latest keyframe
        self._query_desc: tuple[int, np.ndarray, tuple | None] | None = None
        # while _far_search ranks places: (node, its eligible submaps), so that _place_ranks compares only their places
        self._rank_need: tuple[int, list[int]] | None = None
        self._rank_min = _RANK_ROWS_MIN
        # (stored places' keys, their distances to the query) of the last ranking (_place_ranks)
        self._place_dist: tuple[np.ndarray, np.ndarray] = (np.zeros(0, np.int64), np.zeros(0))
        # node → its returns for the descriptors (see _place_due): (keyframe, its removed beams at the keyframe) until
        # a descriptor first reads them (_place_returns), then the returns (≤ 1 kB)
        self._place_pts: dict[int, np.ndarray | tuple[Keyframe, np.ndarray]] = {}
        # stored places whose descriptor is not computed yet, ascending: computed when a ranking first needs the
        # index (_place_flush); their keyframes' entries stay in _place_pts until then (references to arrays the
        # keyframe holds, or ≤ 1 kB of returns per keyframe, less than the 5 kB of spectra each stored place then
        # takes: never more memory than describing at once)
        self._place_due: deque[int] = deque()
        self._place_lo = 0  # the oldest node whose returns _place_pts may still hold
        #: while a keyframe is added: (keyframe, its kept scan or None, its points once computed), see _points
        self._kf_points: tuple | None = None
        self.stats: dict[str, float] = {"searches": 0, "candidates": 0, "loops_accepted": 0, "optimisations": 0,
                                        "far_searches": 0, "far_skipped": 0, "far_candidates": 0, "far_loops": 0,
                                        "far_deferred": 0, "rematch_edges": 0, "rematch_checked": 0, "rematch_ms": 0.0,
                                        "second_searches": 0, "second_loops": 0, "second_rounds": 0, "second_ms": 0.0,
                                        "place_ms": 0.0,
                                        "search_ms": 0.0, "optimise_ms": 0.0,
                                        "total_ms": 0.0}

    # ---- input ----------------------------------------------------------------------------
    def add(self, stamp: float, pose: Pose2D, scan: Scan, removed: np.ndarray, keyframe: bool,
            weak: bool = False, score: float = math.nan, kept: Scan | None = None) -> None:
        """One scan of the run in order: its front-end laser pose; ``scan`` with the robot's body
        removed, ``removed`` the beams the dynamic filter removed; ``keyframe``: written into the
        front end's map; ``weak``: its pose was not backed by a well-supported match; ``score``: its match
        score (0 … 1, mean occupancy at the endpoints; NaN = unknown); ``kept``: optional, ``scan`` with the
        ``removed`` beams set to no return, as the caller already built it (saves building it again)."""
        t0 = time.perf_counter()
        # (Python floats of the pose's float64 values; the keyframe's array is made from them, keyframes only)
        x, y, th = float(pose.x), float(pose.y), float(pose.theta)
        finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(th)
        last = self._last_pose
        if last is not None and finite:
            self._path += math.hypot(x - last[0], y - last[1])
        if finite:
            self._last_pose = (x, y)
        self._frontend.append((x, y, th))
        if self._jumps is not None and self._jumps.update(stamp, x, y, th):
            weak = True  # the front end snapped back: the drift before it is for the loops to undo
        self._weak_since_kf |= bool(weak)
        if score == score:  # not NaN
            self._score_since_kf = min(self._score_since_kf, float(score))
        if keyframe and finite:
            self._add_keyframe(self._n_chunked + len(self._frontend) - 1, stamp, np.array([x, y, th], dtype=np.float64),
                               scan, removed, kept)
        self._scan_node.append(len(self.keyframes) - 1)
        if len(self._scan_node) >= _POSE_CHUNK:
            self._chunk_poses()
        self.stats["total_ms"] += (time.perf_counter() - t0) * 1e3

    def _chunk_poses(self) -> None:
        """Move the scans' nodes and front-end poses from the lists into one (n, 4) float64 array (node, x, y, θ):
        the same float64 values, ``np.asarray`` of the tuples as :meth:`finish` made them (a node is an integer
        below 2^53, exact in float64)."""
        if not self._scan_node:
            return
        chunk = np.empty((len(self._scan_node), 4), dtype=np.float64)
        chunk[:, 0] = self._scan_node
        chunk[:, 1:] = np.asarray(self._frontend, dtype=np.float64).reshape(-1, 3)
        self._pose_chunks.append(chunk)
        self._n_chunked += chunk.shape[0]
        self._scan_node.clear()
        self._frontend.clear()

    @property
    def next_index(self) -> int:
        """The scan index the next :meth:`add` call gets (keyframes keep it as ``scan_index``)."""
        return self._n_chunked + len(self._frontend)

    def drop_beams(self, items: list[tuple[int, np.ndarray]]) -> int:
        """Mark beams of earlier keyframes removed after the fact: ``items`` are (scan index, beam indices)
        whose map evidence retroactive erasure took out of the front end's map (slam/erasure.py), so that
        the re-rendered map (:func:`dynslam2d.pipeline.render_map`), the clean-up pass's recount and later
        submaps leave them out too. Scans that are no keyframe are ignored. Returns the beams marked."""
        if not items or not self.keyframes:
            return 0
        index = np.fromiter((kf.scan_index for kf in self.keyframes), dtype=np.int64, count=len(self.keyframes))
        n = 0
        for scan_index, beams in items:
            k = int(np.searchsorted(index, scan_index))
            if k >= index.shape[0] or index[k] != scan_index:
                continue
            kf = self.keyframes[k]
            if kf.removed.shape != (kf.n_beams,):
                kf.removed = np.zeros(kf.n_beams, dtype=bool)
            else:  # a copy: the array may be the caller's (the pipeline's StepResult.removed of that scan)
                kf.removed = kf.removed.copy()
            b = np.asarray(beams, dtype=np.int64)
            b = b[(b >= 0) & (b < kf.removed.shape[0])]
            n += int((~kf.removed[b]).sum())
            kf.removed[b] = True
            gone = self._cache.pop(k // self.config.submap_keyframes, None)  # its submap is rebuilt without them
            if gone is not None:
                self._dense_forget(gone)
            self._far_levels.pop(k // self.config.submap_keyframes, None)
        return n

    def _add_keyframe(self, index: int, stamp: float, p: np.ndarray, scan: Scan, removed: np.ndarray,
                      kept: Scan | None = None) -> None:
        rm = np.asarray(removed, dtype=bool)
        kf = Keyframe(index, stamp, p, scan, rm if rm.shape == scan.ranges.shape else np.zeros(0, bool), self._path)
        # the keyframe's points are read twice below (place returns, loop query): computed once, from ``kept``
        self._kf_points = (kf, kept, None)
        try:
            self._add_keyframe_node(kf, p)
        finally:
            self._kf_points = None
        self._unpacked.append(len(self.keyframes) - 1)
        if len(self._unpacked) >= _PACK_BATCH:
            self._pack_keyframes()

    def _pack_keyframes(self) -> None:
        """Pack the ranges of the keyframes added since the last call (:meth:`Keyframe.ranges` reads them back bit
        for bit; issue 13 item 3: 3.7 MB of float64 ranges on MIT CSAIL become 0.9 MB of uint16 centimetres), one
        batch per beam count, and let a ``removed`` mask without a removed beam go (an empty array reads the
        same everywhere: :meth:`Keyframe.kept`, :meth:`_scan_points`, the clean-up pass's recount)."""
        kfs = [self.keyframes[k] for k in self._unpacked]
        self._unpacked.clear()
        groups: dict[int, list[Keyframe]] = {}
        for kf in kfs:
            if kf.removed.size and not kf.removed.any():
                kf.removed = _NO_BEAMS
            if kf._codes is None:
                groups.setdefault(kf._scan.ranges.shape[0], []).append(kf)
        for group in groups.values():
            packed = _pack_codes(np.stack([kf._scan.ranges for kf in group]), self._pack_scales)
            if packed is None:  # (a keyframe with a range no code holds: each on its own, float64 at worst)
                for kf in group:
                    one = _pack_codes(kf._scan.ranges[None], self._pack_scales)
                    self._pack_one(kf, *(one if one is not None else (kf._scan.ranges[None], 0.0)))
                continue
            codes, scale = packed
            if scale and scale != self._pack_scales[0]:  # (the next batch of a log is likely written alike)
                self._pack_scales = (scale, *(x for x in _PACK_SCALES if x != scale))
            for i, kf in enumerate(group):
                self._pack_one(kf, codes[i:i + 1], scale)

    @staticmethod
    def _pack_one(kf: Keyframe, codes: np.ndarray, scale: float) -> None:
        """Keyframe ``kf`` keeps ``codes`` ((1, n): its row of a batch) and ``scale`` instead of its scan's ranges;
        its scan becomes a shell without ranges and valid mask."""
        kf._codes = codes[0]
        kf._scale = scale
        kf._scan.trig()  # (the shell keeps the scan's (cos, sin): its own ranges are empty)
        kf._scan = _copy_scan(kf._scan, _NO_RANGES, None)

    def _add_keyframe_node(self, kf: Keyframe, p: np.ndarray) -> None:
        c = self.config
        if self.keyframes:
            prev_node = len(self.keyframes) - 1
            g = self.graph
            # the edge from the previous keyframe (z, front-end poses) and the new node's estimate (the previous
            # node's estimate ⊕ z), in floats
            z, est = _chain(self.keyframes[-1].frontend, p, g.poses[prev_node])
            node = g.add_node(est)
            weak = self._weak_since_kf
            sxy, sth = edge_sigmas(c, z, weak, self._score_since_kf)
            g.add_diag_edge(prev_node, node, z, sxy, sth, robust=c.weak_robust and weak)  # (z: a new list)
            self._edges.set((prev_node, node), sxy,
                            c.drift_rad_per_m * math.hypot(z[0], z[1]) + (c.far_weak_turn if weak else 0.0))
        else:
            node = self.graph.add_node(p)
        self.keyframes.append(kf)
        # what the front end said about the edge into this keyframe (the re-match selects keyframes by it)
        self.kf_weak.append(bool(self._weak_since_kf) and len(self.keyframes) > 1)
        self.kf_score.append(self._score_since_kf if math.isfinite(self._score_since_kf) else math.nan)
        self._weak_since_kf = False
        self._score_since_kf = math.inf
        if self._places is not None:
            # what the keyframe's returns for later descriptors are made of: the keyframe and its removed beams as
            # they are now (drop_beams may replace kf.removed later); the returns themselves are computed when a
            # descriptor first needs them (_place_returns): most keyframes of a run never rank far places
            self._place_pts[node] = (kf, kf.removed)
            if node % c.place_every == 0:
                # described lazily (_place_flush), from these same returns and front-end poses: most keyframes
                # of a run never rank far places, and the descriptor is most of a keyframe's cost (docs/slam.md)
                self._place_due.append(node)
            self._place_drop(node)
        recent = self._recent_loop(node)
        every = c.search_every * (c.tracked_search_every if recent is not None else 1)
        if self._pending:
            self._pending_far(node)
            recent = self._recent_loop(node)  # (a far candidate verified by this keyframe is a loop accepted)
        if node % every == 0:
            self._search(node, recent)
        if self.candidates:  # (none: _confirm would only make the empty list again)
            self._confirm(node)
        if self._new_loops >= c.optimise_every or (
                self._new_loops >= 2 and node - self._opt_nodes >= 3 * c.optimise_every):
            self._optimise(final=False)
            self._opt_nodes = node

    # ---- submaps --------------------------------------------------------------------------
    def _submap_range(self, s: int) -> tuple[int, int, int]:
        """(first node, last node, anchor node) of submap ``s``."""
        n = self.config.submap_keyframes
        first = s * n
        last = first + n - 1
        return first, last, first + n // 2

    def _points(self, kf: Keyframe) -> tuple[np.ndarray, np.ndarray]:
        """(returns (n, 2), clearing-ray ends (m, 2)) of the kept beams in the laser frame, m."""
        cur = self._kf_points
        if cur is not None and cur[0] is kf:  # the keyframe being added (read-only: callers copy or index)
            if cur[2] is None:
                pts = self._scan_points(cur[1]) if cur[1] is not None else self._kf_scan_points(kf, kf.removed)
                self._kf_points = cur = (kf, None, pts)
            return cur[2]
        return self._kf_scan_points(kf, kf.removed)

    def _kf_scan_points(self, kf: Keyframe, removed: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_scan_points` of keyframe ``kf``'s scan; of a packed keyframe from its decoded ranges and their valid
        mask (:func:`ranges_valid`, the tests of :meth:`Scan.valid_mask`) without rebuilding its :class:`Scan`."""
        if kf._codes is None:
            return self._scan_points(kf._scan, removed)
        sh = kf._scan
        r = kf.ranges()
        return self._scan_points(sh, removed, r, ranges_valid(r, sh.range_min, sh.range_max))

    def _scan_points(self, scan: Scan, removed: np.ndarray | None = None, ranges: np.ndarray | None = None,
                     valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_points` of a keyframe's kept scan: ``scan`` with the beams ``removed`` ((n,) bool; None or another
        shape: none) taken as without a return (:meth:`Keyframe.kept`'s scan, without its copy). ``ranges`` and
        ``valid``: the scan's ranges and valid mask when ``scan`` is a packed keyframe's shell (its beam geometry and
        limits only)."""
        c = self.slam
        cos_a, sin_a = scan.trig()
        r = scan.ranges if ranges is None else ranges
        n = r.shape[0]
        drop = no_drop(n) if removed is None or removed.shape != (n,) else np.ascontiguousarray(removed, dtype=np.bool_)
        return gated_points(r, cos_a, sin_a, scan.valid_view() if valid is None else valid, float(scan.range_min),
                            float(scan.range_max),
                            float(c.laser_min_dist), float(min(c.laser_max_dist, self.config.submap_max_range)), 0.0,
                            False, drop)[:2]  # (the scan's own valid mask: the kernel only reads it)

    def _submap(self, s: int) -> MultiResMap:
        """Submap ``s``'s grid with every level's probability cache whole (built if not cached; a sparse level of
        the cached grid is given back as a new dense copy: for callers outside the searches)."""
        grid = self._submap_grid(s)
        if not grid.sparse and not grid.late:
            return grid
        out = copy.copy(grid)
        out.levels = [grid.dense_level(k) for k in range(len(grid.levels))]
        for k in grid.late:  # (the grid's own cache, made sparse later and then reused as a buffer: a copy)
            out.levels[k] = copy.copy(out.levels[k])
            out.levels[k].prob = out.levels[k].prob.copy()
        return out

    def _refine_levels(self, s: int) -> list[GridLevel]:
        """The levels a match in submap ``s`` is refined on (``levels[:max(search_level + 1, 2)]``), dense."""
        grid = self._submap_grid(s)
        return [self._dense(grid, k) for k in range(min(max(self.config.search_level + 1, 2), len(grid.levels)))]

    def _dense(self, grid: _SubmapGrid, k: int) -> GridLevel:
        """``grid.dense_level(k)`` for the searches, from a small cache of the dense levels last rebuilt, by grid
        object (a grid rebuilt or dropped from the cache is another object): one grid's entry (on MIT CSAIL 86 of
        250 rebuilds repeat the one before), :data:`_DENSE_VERIFY` grids' while a far candidate is being verified
        (:meth:`_dense_cap`: its partners are matched against submaps ``s − 1``, ``s``, ``s + 1`` in turn, keyframe
        after keyframe; on negative_2 /left_scan 109 rebuilds of each sparse level fall to 24). A new entry rebuilds
        its levels in the buffers of the entry it evicts (:meth:`_SubmapGrid.dense_level_into`, a buffer grown when
        too short): the levels given before for an evicted grid are then no longer valid — the searches
        (:meth:`_match_at`) hold them only within one match, of one submap. A grid just built is an entry of its
        own dense levels (:meth:`_dense_own`, pass lcm50): they are made sparse only when it is evicted, and their
        former caches are then the buffers (on MIT CSAIL 146 rebuilds fall to 76, datmo overtakes 40 to 24)."""
        if k not in grid.sparse:
            if k in grid.late and id(grid) in self._dense_entries:  # its own dense level: the entry used
                self._dense_entries.move_to_end(id(grid))
            return grid.levels[k]
        ent = self._dense_entries.get(id(grid))  # (an entry holds its grid: its id is not reused meanwhile)
        if ent is None:
            ent = self._dense_entries[id(grid)] = (grid, {}, self._dense_take())
        else:
            self._dense_entries.move_to_end(id(grid))
        levels, bufs = ent[1], ent[2]
        lv = levels.get(k)
        if lv is None:
            shape = grid.levels[k].shape
            buf = bufs.get(k)
            if buf is None or buf.shape[0] < shape[0] * shape[1]:
                buf = bufs[k] = np.empty(shape[0] * shape[1], dtype=np.uint32)
            lv = levels[k] = grid.dense_level_into(k, buf)
        return lv

    def _dense_cap(self) -> int:
        """Grids whose dense levels :meth:`_dense` keeps: :data:`_DENSE_VERIFY` while a far candidate is verified
        (inside :meth:`_verify_far` or :meth:`_pending_far`, or while one waits for partners), else one."""
        return _DENSE_VERIFY if self._verifying or self._pending else 1

    def _dense_take(self) -> dict[int, np.ndarray]:
        """Room for one more entry of :meth:`_dense`: the least recently used entries evicted down to
        :meth:`_dense_cap` − 1; the buffers of the first evicted (else those of an entry forgotten) for the new
        one, those of the others freed."""
        bufs = None
        while self._dense_entries and len(self._dense_entries) >= self._dense_cap():
            b = self._dense_evict()
            if bufs is None:
                bufs = b
        if bufs is None:
            bufs, self._dense_spare = self._dense_spare, {}
        return bufs

    def _dense_evict(self) -> dict[int, np.ndarray]:
        """Evict the least recently used entry of :meth:`_dense`; its buffers. An entry of a grid's own dense levels
        (built since it last left the recent set) makes them sparse now if the grid is still cached
        (:func:`_sparsify_late`): their former caches are the buffers."""
        grid, _levels, bufs = self._dense_entries.popitem(last=False)[1]
        if grid.late:
            if any(g is grid for g in self._cache.values()):
                return _sparsify_late(grid)
            return {}  # (a grid no longer cached, e.g. by the second search: its caches go with it)
        return bufs

    def _dense_own(self, grid: _SubmapGrid) -> None:
        """A grid just built, its levels due to be sparse still dense (``grid.late``): the most recent entry of
        :meth:`_dense`, its own caches as its dense levels (no rebuild while it stays recent; made sparse when it
        is evicted). The evicted entry's buffers and the spare ones are freed: one grid's dense levels held
        outside a verification, as before."""
        if not grid.late:
            return
        while self._dense_entries and len(self._dense_entries) >= self._dense_cap():
            self._dense_evict()
        self._dense_spare = {}
        self._dense_entries[id(grid)] = (grid, {k: grid.levels[k] for k in grid.late}, {})

    def _dense_trim(self) -> None:
        """After a far verification: keep only the most recent entry of :meth:`_dense` if no candidate waits (the
        others' buffers freed: the closer holds one grid's dense levels between verifications, pass lcm48's
        memory)."""
        while len(self._dense_entries) > self._dense_cap():
            self._dense_evict()

    def _dense_forget(self, grid: _SubmapGrid | None = None) -> None:
        """Forget ``grid``'s entry of :meth:`_dense` (its buffers kept for the next entry if none are), or every
        entry and buffer if None."""
        if grid is None:
            self._dense_entries.clear()
            self._dense_spare = {}
            return
        ent = self._dense_entries.pop(id(grid), None)
        if ent is not None and ent[0] is grid and not self._dense_spare and not grid.late:
            self._dense_spare = ent[2]

    def _submap_grid(self, s: int) -> _SubmapGrid:
        """Submap ``s``'s cached grid (built if not cached): only the probability caches are kept, those of the
        levels below ``search_level`` (read by a match's refinement only; not the far level) sparse (issue 13
        item 3: on MIT CSAIL 6–15 % of their cells are not 0.5, and they are ≈ 80 % of a grid's cells)."""
        grid = self._cache.get(s)
        if grid is not None:
            self._cache.move_to_end(s)
            return grid
        c = self.slam
        first, last, anchor = self._submap_range(s)
        grid = _SubmapGrid(c.map_resolution, self._n_levels(), c.logodds_free,
                           c.logodds_occupied, c.occupied_logodds_cap, c.map_growth_margin)
        grid.sparse = {}
        grid.late = []
        a = self.keyframes[anchor].frontend
        for k in range(first, last + 1):
            pts, _ = self._points(self.keyframes[k])
            if pts.shape[0]:
                rel = relative(a, self.keyframes[k].frontend)
                grid.integrate(Pose2D(float(rel[0]), float(rel[1]), float(rel[2])), pts)
        for lv in grid.levels:  # the searches read only the probabilities (issue 13 item 3: 2/3 of each grid)
            _keep_probabilities(lv)
        n_lv = len(grid.levels)
        far = min(self.config.far_level, n_lv - 1) if self.config.far_search else -1
        # made sparse when the grid leaves the recent set of _dense (pass lcm50): until then its own caches
        grid.late = [k for k in range(min(self.config.search_level, n_lv - 1)) if k != far]
        if self.config.far_search:
            self._far_levels[s] = grid.levels[far]
        self._cache[s] = grid
        if len(self._cache) > self._cache_size:
            self._dense_forget(self._cache.popitem(last=False)[1])
        self._dense_own(grid)
        return grid

    def _build_far_level(self, s: int) -> GridLevel:
        """Submap ``s``'s far-search level alone (kept in ``_far_levels``, not in the grid cache): what a far search
        reads of a submap unless its match gets as far as the refinement (MIT CSAIL, negative_2: most far searches
        of a submap never built refuse it before that; the level at ``map_resolution·2^far_level`` costs a fraction
        of the whole grid, whose finest level has 64 times its cells). Bit-identical to the level :meth:`_submap`
        builds: a :class:`MultiResMap` updates every level from the full scan at the same pose, each on its own
        (Kohlbrecher et al. 2011, §IV-C), and a one-level map at that resolution (``map_resolution * 2**k``, the
        same float) with the same growth margin gets the same cells, the same scans in the same order."""
        c = self.slam
        k = min(self.config.far_level, self._n_levels() - 1)
        first, last, anchor = self._submap_range(s)
        grid = MultiResMap(c.map_resolution * 2**k, 1, c.logodds_free, c.logodds_occupied, c.occupied_logodds_cap,
                           c.map_growth_margin)
        a = self.keyframes[anchor].frontend
        for j in range(first, last + 1):
            pts, _ = self._points(self.keyframes[j])
            if pts.shape[0]:
                rel = relative(a, self.keyframes[j].frontend)
                grid.integrate(Pose2D(float(rel[0]), float(rel[1]), float(rel[2])), pts)
        lv = grid.levels[0]
        _keep_probabilities(lv)
        self._far_levels[s] = lv
        return lv

    def _n_levels(self) -> int:
        """Levels of a submap grid: the search level and the far search's, at least two."""
        top = max(self.config.search_level, self.config.far_level if self.config.far_search else 0)
        return max(top + 1, 2)

    # ---- loop search ----------------------------------------------------------------------
    def _estimate(self, node: int) -> np.ndarray:
        """Current estimate of a node's pose: optimised, or the last optimised node composed with
        the front end's relative pose."""
        return self.graph.pose(node)

    def _search(self, node: int, recent: LoopCandidate | None) -> None:
        """The loop searches of keyframe ``node``; ``recent``: :meth:`_recent_loop` of it, as the caller found it."""
        c = self.config
        t0 = time.perf_counter()
        kf = self.keyframes[node]
        est = self._estimate(node)
        n_sub = (node + 1) // c.submap_keyframes  # finished submaps
        if node < c.submap_keyframes:
            return
        if recent is not None:
            # a loop a few keyframes ago: it and the keyframe chain since predict this pose well, so the
            # search needs only a small window around that prediction
            est = compose(self._implied(recent), relative(self._estimate(recent.node), est))
        found: list[tuple[float, int, float]] = []
        # every finished submap's anchor estimate as floats at once (rows first + n // 2 of the graph's poses: the
        # values _estimate reads one by one), and the keyframe's estimate: the same differences and hypot
        n = c.submap_keyframes
        anchors = self.graph.poses[n // 2::n][:n_sub, :2].tolist()
        ex, ey = float(est[0]), float(est[1])
        path = kf.path
        keyframes = self.keyframes
        for s in range(n_sub):
            last = s * n + n - 1  # (_submap_range)
            if last >= node:
                continue
            gap = path - keyframes[last].path
            if gap < c.min_path_gap:
                continue
            radius = min(c.search_radius + c.drift_per_m * gap, c.max_search_radius)
            if recent is not None:
                radius = c.search_radius
            ax, ay = anchors[s]
            d = math.hypot(ax - ex, ay - ey)
            if d <= radius:
                found.append((d, s, gap))
        far = (recent is None and c.far_search and c.far_searches > 0
               and kf.path - self._loop_path >= c.far_after)
        if not found and not far:
            return
        found.sort()
        pts = self._query(kf)
        if pts is None:
            return
        local = found[:1 if recent is not None else _MAX_CANDIDATES]
        for _d, s, gap in local:
            cand = self._match(node, s, 0.0 if recent is not None else gap, pts, est, recent is not None)
            self.stats["searches"] += 1
            if cand is not None:
                self.candidates.append(cand)
                self.stats["candidates"] += 1
        if far:
            self._far_search(node, est, pts, {s for _d, s, _g in local})
        self.stats["search_ms"] += (time.perf_counter() - t0) * 1e3

    def _query(self, kf: Keyframe) -> np.ndarray | None:
        """The keyframe's query points (laser frame, m, at most _QUERY_POINTS), None if too few."""
        pts, _ = self._points(kf)
        if pts.shape[0] < max(self.config.min_support, 10):
            return None
        if pts.shape[0] > _QUERY_POINTS:
            pts = pts[even_indices(pts.shape[0], _QUERY_POINTS)]
        return pts

    # ---- far search: the radius grows with the uncertainty accumulated along the graph ------
    def _uncertainty(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        """((n_nodes,) summed translation deviation (m) of the edges on the graph's shortest path from
        ``node`` to every node (keyframe chain and accepted loops; inf beyond the far radius's cap),
        (n_nodes,) summed heading deviation (rad) of the edges on the path that minimises it)."""
        c = self.config
        ij, weights = self._edges.arrays()
        # both sums in one kernel call (the values of scipy.sparse.csgraph.dijkstra on the weights + 1e-9, row 0 up to
        # the far radius's cap: slam/graphdist.py)
        d = graph_distances(ij, weights, self.graph.n_nodes, node,
                            max(c.max_far_radius - c.search_radius, 0.0) / c.far_sigmas)
        return d[0], d[1]

    def _far_search(self, node: int, est: np.ndarray, pts: np.ndarray, skip: set[int],
                    allowed: np.ndarray | None = None, count: int | None = None) -> int:
        """Search the ``count`` (default ``far_searches``) submaps within the uncertainty-grown radius (not already
        searched locally) that look most like this place (or were least recently searched) over every rotation; a
        candidate is verified at once on the keyframes before it. ``allowed``: (n_nodes,) bool, only submaps whose
        anchor it marks (the second search: pairs the graph does not tie yet). Returns the number of submaps that
        were eligible."""
        c = self.config
        kf = self.keyframes[node]
        unc, heading = self._uncertainty(node)
        elig: list[tuple[float, float, int, float, float]] = []
        for s in range((node + 1) // c.submap_keyframes):
            _first, last, anchor = self._submap_range(s)
            if last >= node or s in skip or kf.path - self.keyframes[last].path < c.min_path_gap:
                continue
            if allowed is not None and not allowed[anchor]:
                continue
            r = min(c.search_radius + c.far_sigmas * float(unc[anchor]), c.max_far_radius)
            a = self._estimate(anchor)
            d = math.hypot(a[0] - est[0], a[1] - est[1])
            if d <= r:
                elig.append((self._far_last.get(s, -1), d / r, s, r, float(heading[anchor])))
        if self._places is not None and elig:
            # the submaps that look most like this place first (Scan Context ranking), not the least recently searched;
            # only the eligible submaps' places (and those _place_cover reads for them) are compared with the query
            self._rank_need = (node, [e[2] for e in elig])
            try:
                rank = self._place_ranks(node)
            finally:
                self._rank_need = None
            elig = [(rank.get(s, 2.0), d, s, r, dth) for _last, d, s, r, dth in elig]
        elig.sort()
        for _last, _d, s, r, dth in self._far_pick(node, elig, c.far_searches if count is None else count):
            self._far_last[s] = node
            self.stats["far_searches"] += 1
            _first, _l, anchor = self._submap_range(s)
            pred = relative(self._estimate(anchor), est)
            ext = self._submap_extent(s)
            dist = math.hypot(pred[0], pred[1])
            if dist > ext:  # the robot must be near the submap's keyframes to see what they saw
                pred = np.array([pred[0] * ext / dist, pred[1] * ext / dist, pred[2]])
            turn = c.angular_window + c.far_sigmas * dth
            # the search covers every rotation (the margin counts rotated look-alikes), but a candidate must turn
            # the estimate by at most ``turn``: the rotations within turn + _REFINE_TURN are searched first, and
            # when they show that no pose can pass, the rest is not searched (correlative_search, accept_turn)
            cand = self._match_at(node, s, pts, pred, min(r, ext + c.far_margin), math.pi, c.far_min_margin,
                                  c.far_level, turn + _REFINE_TURN)
            if cand is None:
                continue
            implied = self._implied(cand)
            jump = math.hypot(implied[0] - est[0], implied[1] - est[1])
            if jump > r or abs(math.remainder(implied[2] - est[2], math.tau)) > turn:
                continue  # a correction larger than the uncertainty allows: a look-alike place, not a loop
            cand.far = True
            self.stats["far_candidates"] += 1
            self._verify_far(cand, s)
            if self._second_tried is not None:
                self._second_tried.append(cand)
        return len(elig)

    def _far_pick(self, node: int, elig: list[tuple[float, float, int, float, float]],
                  count: int) -> list[tuple[float, float, int, float, float]]:
        """The far searches keyframe ``node`` runs of the sorted eligible submaps ``elig`` (rows (place-descriptor
        distance, or the node of the last far search with ``far_rank: oldest``; distance / far radius; submap; far
        radius m; heading deviation rad)): the first ``count``, of which the run's far search (not the second
        search) skips those whose place distance (:meth:`_place_cover`) is above ``far_max_place_distance`` — the
        first of them, the best-ranked, only above ``far_best_place_distance`` if that is larger. On the recordings
        measured every far search above these caps found nothing (docs/slam.md, "Place descriptor");
        ``stats["far_skipped"]`` counts the skipped ones."""
        c = self.config
        picked = elig[:count]
        if self._places is None or self._second is not None or not picked or c.far_max_place_distance >= 2.0:
            return picked
        best = max(c.far_best_place_distance, c.far_max_place_distance)
        kept = [e for i, e in enumerate(picked)
                if self._place_cover(node, e[2]) <= (best if i == 0 else c.far_max_place_distance)]
        self.stats["far_skipped"] += len(picked) - len(kept)
        return kept

    def _place_cover(self, node: int, s: int) -> float:
        """Submap ``s``'s place distance for the caps of :meth:`_far_pick`: the smallest distance to keyframe
        ``node``'s place, in the last ranking (:meth:`_place_ranks`), of the places stored at the submap's
        keyframes and of those after it whose descriptor window (the ``place_keyframes`` keyframes up to the
        place) still holds the submap's anchor — they saw what the far search matches against — but not the
        query's own window (places up to ``node − place_keyframes``: a place sharing keyframes with the query
        looks alike for that reason alone). 2.0 = no such place. Never above the submap's rank."""
        keys, d = self._place_dist
        pk = self.config.place_keyframes
        first, last, anchor = self._submap_range(s)
        hi = max(last, min(anchor + pk - 1, node - pk))
        lo = int(np.searchsorted(keys, first, side="left"))  # (keys: stored nodes, ascending)
        hi = int(np.searchsorted(keys, hi, side="right"))
        return float(d[lo:hi].min()) if hi > lo else 2.0

    def _describe(self, node: int, store: bool) -> None:
        """The place descriptor of keyframe ``node`` (:meth:`_describe_many`)."""
        self._describe_many([node], store)

    def _describe_many(self, nodes: list[int], store: bool) -> None:
        """The place descriptors of keyframes ``nodes``, in one batch (:meth:`PlaceIndex.describe_many`): each the
        returns of the last ``place_keyframes`` keyframes (at most _PLACE_POINTS each) in its laser frame, placed
        with the front end's relative poses; stored in the index in order if ``store``; the last one kept for its
        node's search."""
        c = self.config
        t0 = time.perf_counter()
        clouds = []
        for node in nodes:
            window = [k for k in range(max(node - c.place_keyframes + 1, 0), node + 1) if k in self._place_pts]
            base = self.keyframes[node].frontend
            rel = relative(base, np.array([self.keyframes[k].frontend for k in window]).reshape(-1, 3))
            clouds.append(_place_points(rel, [self._place_returns(k) for k in window]))
        descs = self._places.describe_many(clouds)
        spectra = self._places.add_many(nodes, descs) if store else None
        self._query_desc = (nodes[-1], descs[-1], spectra)
        self.stats["place_ms"] += (time.perf_counter() - t0) * 1e3

    def _place_returns(self, node: int) -> np.ndarray:
        """(n, 2) float32 returns of keyframe ``node`` for the place descriptors (laser frame, m; at most
        _PLACE_POINTS, evenly sub-sampled): the kept beams' points of its scan with the beams that were removed when
        it was added (not those :meth:`drop_beams` marked since), computed at the first call and then kept in
        ``_place_pts`` until :meth:`_place_drop` frees them."""
        v = self._place_pts[node]
        if isinstance(v, np.ndarray):
            return v
        kf, rm = v
        cur = self._kf_points
        if cur is not None and cur[0] is kf:  # the keyframe being added: its points are shared with its query
            pts, _ = self._points(kf)
        else:  # (Keyframe.kept with the removed beams of that time)
            pts, _ = self._kf_scan_points(kf, rm)
        if pts.shape[0] > _PLACE_POINTS:
            pts = pts[even_indices(pts.shape[0], _PLACE_POINTS)]
        pts = self._place_pts[node] = pts.astype(np.float32)
        return pts

    def _place_drop(self, node: int) -> None:
        """Free the returns no descriptor needs any more: those before the window (``place_keyframes``) of the
        oldest place still due, or of keyframe ``node`` (the latest) if none is due."""
        lo = (self._place_due[0] if self._place_due else node) - self.config.place_keyframes + 1
        while self._place_lo < lo:
            self._place_pts.pop(self._place_lo, None)
            self._place_lo += 1

    def _place_flush(self) -> None:
        """Describe and store every place still due, oldest first (the index's rows in the order the eager
        description gave them); their inputs — the keyframes' returns and front-end poses — never change after
        the keyframe, so the descriptors are bit-identical to those computed at keyframe time."""
        last = len(self.keyframes) - 1
        while self._place_due:
            # _PLACE_BATCH places per call (one pass of NumPy over all their points): the returns of a batch's
            # windows are all still held, since _place_drop frees only those before the oldest due place's window
            batch = [self._place_due[i] for i in range(min(_PLACE_BATCH, len(self._place_due)))]
            self._describe_many(batch, True)
            for _ in batch:
                self._place_due.popleft()
            self._place_drop(last)  # each batch's returns freed as soon as described: memory never above eager

    def release_places(self) -> None:
        """Let the stored place descriptors and the keyframes' place returns go, for a caller done with the closer
        after :meth:`finish` (which ran the last search that reads them): 5 MB on MIT CSAIL that the re-render and
        the clean-up pass need not hold (issue 13 item 3). The index is empty afterwards: the closer must take no
        further scan."""
        if self._places is not None:
            p = self._places
            self._places = PlaceIndex(p.rings, p.sectors, p.max_range)
        self._place_pts.clear()
        self._place_due.clear()
        self._query_desc = None
        self._place_dist = (np.zeros(0, np.int64), np.zeros(0))

    def _place_ranks(self, node: int) -> dict[int, float]:
        """Submap → smallest place-descriptor distance of its stored keyframes to keyframe ``node``'s place: of every
        submap with a stored place, or while :meth:`_far_search` ranks its eligible submaps (``_rank_need``) and more
        than :data:`_RANK_ROWS_MIN` places are stored, of those submaps only (``_place_dist`` then holds only the
        places :meth:`_place_cover` reads for them: :meth:`_rank_rows`). Each place's distance is computed on its
        own, so the values are those of the whole ranking."""
        c = self.config
        self._place_flush()
        t0 = time.perf_counter()
        need = self._rank_need
        rows = (self._rank_rows(node, need[1])
                if need is not None and need[0] == node and len(self._places) > self._rank_min else None)
        if self._query_desc is not None and self._query_desc[0] == node:
            keys, d, _shift = self._places.distances(self._query_desc[1], rows=rows, spectra=self._query_desc[2])
        elif node in self._places:  # a stored place (the second search: older keyframes' returns are gone)
            keys, d, _shift = self._places.distances_of(node, rows=rows)
        else:
            self._describe(node, False)
            keys, d, _shift = self._places.distances(self._query_desc[1], rows=rows)
        self._place_dist = (keys, d)
        sub = keys // c.submap_keyframes
        best = np.full(int(sub.max()) + 1 if sub.size else 0, np.inf)
        np.minimum.at(best, sub, d)
        self.stats["place_ms"] += (time.perf_counter() - t0) * 1e3
        # (Python floats from tolist: the same values, without a NumPy scalar and np.isfinite call per submap)
        return {s: v for s, v in enumerate(best.tolist()) if math.isfinite(v)}

    def _rank_rows(self, node: int, subs: list[int]) -> np.ndarray:
        """Ascending rows of the place index (its stored keys ascend) that a ranking of submaps ``subs`` for keyframe
        ``node`` reads: for each submap the places :meth:`_place_cover` reads — keys ``first`` … ``max(last,
        min(anchor + place_keyframes − 1, node − place_keyframes))``, which hold the submap's own places (``first`` …
        ``last``, its rank)."""
        keys = self._places.keys
        n = self.config.submap_keyframes
        pk = self.config.place_keyframes
        s = np.asarray(subs, dtype=np.int64)
        first = s * n
        hi = np.maximum(first + n - 1, np.minimum(first + n // 2 + pk - 1, node - pk))
        lo = np.searchsorted(keys, first, side="left")
        up = np.searchsorted(keys, hi, side="right")
        mark = np.zeros(keys.shape[0] + 1, dtype=np.int64)  # +1 where a range starts, −1 past its end
        np.add.at(mark, lo, 1)
        np.add.at(mark, up, -1)
        return np.flatnonzero(np.cumsum(mark[:-1]) > 0)

    def _submap_extent(self, s: int) -> float:
        """Largest distance of submap ``s``'s keyframes from its anchor (front-end poses), m."""
        e = self._extent.get(s)
        if e is None:
            first, last, anchor = self._submap_range(s)
            a = self.keyframes[anchor].frontend
            e = max(math.hypot(*relative(a, self.keyframes[k].frontend)[:2]) for k in range(first, last + 1))
            self._extent[s] = e
        return e

    def _verify_far(self, cand: LoopCandidate, s: int) -> None:
        """Accept a far candidate only if the keyframes just before it, matched against the same and the
        neighbouring submaps around the pose the candidate implies for them, give at least
        ``far_partners`` candidates consistent with it; then optimise at once (the correction is large).
        Without enough partners before it (the front end may have broken just before the candidate, so that
        the chain to the earlier keyframes is wrong), the next ``consistency_window`` keyframes are tried as
        they arrive (:meth:`_pending_far`)."""
        c = self.config
        node = cand.node
        partners: list[LoopCandidate] = []
        self._verifying += 1
        try:
            for k in range(node - 1, max(node - 1 - max(c.consistency_window, 1), -1), -1):
                o = self._far_partner(cand, s, k)
                if o is not None:
                    partners.append(o)
            if not self._far_verified(cand, partners) and c.consistency_window > 0:
                self._pending.append((cand, s, partners))
        finally:
            self._verifying -= 1
        self._dense_trim()

    def _far_partner(self, cand: LoopCandidate, s: int, k: int) -> LoopCandidate | None:
        """Keyframe ``k`` matched against submap ``s`` and its neighbours around the pose far candidate ``cand``
        implies for it (through the keyframe chain); the best match if it is consistent with ``cand``."""
        c = self.config
        pts = self._query(self.keyframes[k])
        if pts is None:
            return None
        n_sub = (max(k, cand.node) + 1) // c.submap_keyframes
        guess = compose(self._implied(cand), relative(self._estimate(cand.node), self._estimate(k)))
        best: LoopCandidate | None = None
        for s2 in (s - 1, s, s + 1):
            if s2 < 0 or s2 >= n_sub or self._submap_range(s2)[1] >= k:
                continue
            pred = relative(self._estimate(self._submap_range(s2)[2]), guess)
            o = self._match_at(k, s2, pts, pred, c.linear_window, c.angular_window, c.min_margin)
            self.stats["searches"] += 1
            if o is not None and (best is None or o.score > best.score):
                best = o
        return best if best is not None and self._consistent(cand, best) else None

    def _far_verified(self, cand: LoopCandidate, partners: list[LoopCandidate]) -> bool:
        """Accept ``cand`` and its partners if there are ``far_partners`` of them spanning ``far_partner_span`` of
        path; then optimise at once. Returns whether they were accepted."""
        c = self.config
        paths = [self.keyframes[o.node].path for o in [cand, *partners]]
        span = c.far_partner_span if self._second is None else c.second_partner_span
        if len(partners) < c.far_partners or max(paths) - min(paths) < span:
            return False
        accepted = 0
        for o in [cand, *partners]:
            o.far = True
            if self._second is not None:  # the second search: a pair the graph already has a loop for adds nothing
                if (o.anchor, o.node) in self._second:
                    continue
                self._second.add((o.anchor, o.node))
            self.candidates.append(o)
            self._accept(o)
            accepted += 1
        self.stats["far_loops"] += accepted
        if self._second is None or self.config.second_optimise_each:
            self._optimise(final=False)
        self._opt_nodes = len(self.keyframes) - 1
        return True

    def _pending_far(self, node: int) -> None:
        """Try the new keyframe ``node`` as a partner of far candidates not yet verified (within
        ``consistency_window`` keyframes after them)."""
        keep = []
        self._verifying += 1
        try:
            for cand, s, partners in self._pending:
                if node - cand.node > self.config.consistency_window:
                    continue
                o = self._far_partner(cand, s, node)
                if o is not None:
                    partners.append(o)
                    if self._far_verified(cand, partners):
                        self.stats["far_deferred"] += 1
                        continue
                keep.append((cand, s, partners))
        finally:
            self._verifying -= 1
        self._pending = keep
        self._dense_trim()

    def _recent_loop(self, node: int) -> LoopCandidate | None:
        """The latest accepted loop candidate within ``consistency_window`` keyframes of ``node``."""
        w = max(self.config.consistency_window, 1)
        best = None
        for cand in self.candidates:
            if cand.accepted and node - cand.node <= w and (best is None or cand.node > best.node):
                best = cand
        return best

    def _match(self, node: int, s: int, gap: float, pts: np.ndarray, est: np.ndarray,
               tracked: bool = False) -> LoopCandidate | None:
        c = self.config
        _first, _last, anchor = self._submap_range(s)
        pred = relative(self._estimate(anchor), est)
        lin = min(c.linear_window + c.drift_per_m * gap, c.max_linear_window)
        ang = min(c.angular_window + c.drift_rad_per_m * gap, c.max_angular_window)
        if tracked:
            lin, ang = min(lin, c.tracked_linear_window), min(ang, c.tracked_angular_window)
        return self._match_at(node, s, pts, pred, lin, ang, c.min_margin)

    def _match_at(self, node: int, s: int, pts: np.ndarray, pred: np.ndarray, lin: float, ang: float,
                  min_margin: float, level: int | None = None,
                  accept_turn: float | None = None) -> LoopCandidate | None:
        """Correlative search of submap ``s`` for keyframe ``node``'s points ``pts`` within ±``lin`` m /
        ±``ang`` rad of ``pred`` (the keyframe in the anchor's frame), refined by Gauss–Newton; a candidate
        if score, margin over the runner-up, support and spread pass. ``accept_turn`` (rad): the caller refuses a
        candidate whose correlative match turns ``pred`` by more than this (:func:`correlative_search`)."""
        c = self.config
        sc = self.slam
        _first, _last, anchor = self._submap_range(s)
        grid = self._cache.get(s)
        lvl = None
        if grid is None and level is not None and c.far_search \
                and min(level, self._n_levels() - 1) == min(c.far_level, self._n_levels() - 1):
            # the far level of a submap built before: no rebuild unless the match gets as far as its refinement;
            # of a submap never built (or dropped by drop_beams), that level alone (_build_far_level)
            lvl = self._far_levels.get(s)
            if lvl is None:
                lvl = self._build_far_level(s)
        if lvl is None:
            grid = self._submap_grid(s)
            lvl = self._dense(grid, min(c.search_level if level is None else level, len(grid.levels) - 1))
        # one search: below min_score it returns None (and prunes what cannot reach it), the runner-up pass runs only
        # for a match good enough to become a candidate and stops once the margin is lost (the same candidates as
        # a search without the bounds followed by a second search with the runner-up)
        cr = correlative_search(lvl, pts, pred, lin, ang, None, c.search_points, sc.correlative_max_height, 0.0, 0.0,
                                runner_up_distance=c.runner_up_distance, runner_up_angle=c.runner_up_angle,
                                runner_up_wrap=c.runner_up_wrap, min_score=c.min_score, min_margin=min_margin,
                                accept_turn=accept_turn)
        if cr is None or cr.score < c.min_score:
            return None
        margin = cr.score - (cr.runner_up or 0.0)
        if margin < min_margin:
            return None
        if accept_turn is not None and abs(math.remainder(float(cr.pose[2]) - float(pred[2]), math.tau)) > accept_turn:
            # the match itself must lie within the rotations searched first (a refinement that turned it back
            # within the caller's limit from beyond them is refused too): correlative_search's accept_turn then
            # refuses exactly what this would
            return None
        levels = self._refine_levels(s)  # the refinement as without the far search's level
        refined = refine_supported(levels, pts, cr.pose, 2 * lvl.resolution, c, sc)
        if refined is None:
            return None
        p, n_sup = refined
        if c.max_degeneracy > 0.0:
            fit = evaluate(levels[0], pts, p)
            if degeneracy(fit.hessian, levels[0].resolution, pts, sc.degeneracy_threshold).ratio < c.max_degeneracy:
                return None
        return LoopCandidate(node, anchor, np.asarray(p, dtype=np.float64), float(cr.score), float(margin), int(n_sup))

    # ---- consistency ----------------------------------------------------------------------
    def _implied(self, cand: LoopCandidate) -> np.ndarray:
        """The pose of the candidate's keyframe implied by the loop: anchor estimate ⊕ z."""
        return compose(self._estimate(cand.anchor), cand.z)

    def _consistent(self, a: LoopCandidate, b: LoopCandidate) -> bool:
        c = self.config
        # the two loops and the keyframe chain between them must close up
        implied = relative(self._implied(a), self._implied(b))
        chain = relative(self._estimate(a.node), self._estimate(b.node))
        d = relative(chain, implied)
        return math.hypot(d[0], d[1]) <= c.consistency_distance and abs(d[2]) <= c.consistency_angle

    def _confirm(self, node: int) -> None:
        c = self.config
        keep: list[LoopCandidate] = []
        for cand in self.candidates:
            if cand.accepted:
                continue
            if c.consistency_window == 0:
                self._accept(cand)
                continue
            partners = [o for o in self.candidates if o is not cand and o.node != cand.node
                        and abs(o.node - cand.node) <= c.consistency_window and self._consistent(cand, o)]
            if partners:
                self._accept(cand)
                for o in partners:
                    if not o.accepted:
                        self._accept(o)
            elif node - cand.node <= c.consistency_window:
                keep.append(cand)
        # accepted candidates stay as partners for the next ones within the window
        self.candidates = [o for o in self.candidates if (o.accepted and node - o.node <= c.consistency_window)] + [
            o for o in keep if not o.accepted]

    def _accept(self, cand: LoopCandidate) -> None:
        c = self.config
        cand.accepted = True
        k = self.graph.add_edge(cand.anchor, cand.node, cand.z, diag_info(c.loop_sigma_xy, c.loop_sigma_theta),
                                loop=True)
        key = (min(cand.anchor, cand.node), max(cand.anchor, cand.node))
        self._edges.set(key, c.loop_sigma_xy, c.drift_rad_per_m * math.hypot(*cand.z[:2]), keep_min=True)
        self.loop_edges.append(k)
        self.stats["loops_accepted"] += 1
        self._loop_path = max(self._loop_path, self.keyframes[cand.node].path)
        self._new_loops += 1

    # ---- optimisation ---------------------------------------------------------------------
    def _optimise(self, final: bool) -> None:
        c = self.config
        t0 = time.perf_counter()
        # during the run the optimisation only has to improve the search's predictions: fewer iterations
        self.graph.optimise(c.kernel, c.kernel_scale, c.iterations if final else max(c.iterations // 3, 1),
                            c.outlier_chi2)
        self._new_loops = 0
        self.stats["optimisations"] += 1
        self.stats["optimise_ms"] += (time.perf_counter() - t0) * 1e3

    def finish(self) -> LoopResult:
        """Final full optimisation; every scan's optimised pose."""
        t0 = time.perf_counter()
        if self._unpacked:
            self._pack_keyframes()
        self._chunk_poses()
        rows = np.concatenate(self._pose_chunks) if self._pose_chunks else np.zeros((0, 4))
        frontend = np.ascontiguousarray(rows[:, 1:])
        scan_node = rows[:, 0].astype(np.int64)
        active = [k for k in self.loop_edges if self.graph.edges[k].active]
        if self.loop_edges:
            self._optimise(final=True)
            active = [k for k in self.loop_edges if self.graph.edges[k].active]
            if active and self.config.rematch:
                t1 = time.perf_counter()
                self.stats["rematch_edges"], self.stats["rematch_checked"] = rematch_keyframes(self)
                self.stats["rematch_ms"] = (time.perf_counter() - t1) * 1e3
                if self.stats["rematch_edges"]:
                    self._optimise(final=True)
                    active = [k for k in self.loop_edges if self.graph.edges[k].active]
            if active and self.config.second_search and self.config.far_search:
                run_second_search(self)
                active = [k for k in self.loop_edges if self.graph.edges[k].active]
        corrected = bool(active)
        nodes = self.graph.poses.copy()
        poses = frontend.copy()
        if corrected and nodes.shape[0]:
            poses = scan_poses(frontend, scan_node,
                               np.array([k.frontend for k in self.keyframes]).reshape(-1, 3), nodes)
        loops = [(self.graph.edges[k].i, self.graph.edges[k].j) for k in active]
        self._cache.clear()  # no search after the last one: its submap grids go before the map is re-rendered
        self._dense_forget()
        self._far_levels.clear()
        self.stats["total_ms"] += (time.perf_counter() - t0) * 1e3
        stats = dict(self.stats)
        stats.update({"keyframes": len(self.keyframes), "submaps": len(self.keyframes) // self.config.submap_keyframes,
                      "loops_active": len(active), "loops_rejected": len(self.loop_edges) - len(active)})
        return LoopResult(poses, frontend, np.array([k.scan_index for k in self.keyframes], dtype=np.int64),
                          nodes, self.graph, loops, corrected, stats, self.keyframes)


def scan_poses(frontend: np.ndarray, scan_node: np.ndarray, node_frontend: np.ndarray,
               node_poses: np.ndarray) -> np.ndarray:
    """(n, 3) poses of every scan: its last keyframe's pose in ``node_poses`` composed with the front
    end's relative pose from that keyframe (``scan_node`` (n,) keyframe of each scan, −1 = none yet:
    the front end's pose is kept)."""
    out = np.array(frontend, dtype=np.float64, copy=True)
    has = scan_node >= 0
    out[has] = compose(node_poses[scan_node[has]], relative(node_frontend[scan_node[has]], frontend[has]))
    return out
