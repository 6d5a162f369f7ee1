"""The tracker's track records and their rows of the state arrays (``Tracker._X``, ``_P``, ``_G``, ``_Gi``).

A live track is a :class:`_Track` whose ``x`` / ``P`` / ``g`` / ``gi`` are views of its row (map frame, m, m/s,
rad); :class:`TrackRows` hands out the rows (a deleted track's first, the arrays doubled when full), keeps the
live rows in list order and re-points the views. Split out of ``detect/tracker.py`` (docs/speed.md, pass
trktable); the columns of the plan's track table (docs/speed.md, "Tracker rewrite: the plan") go here."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

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
)
from dynslam2d.detect.kernels_update import (
    C_BN,
    C_BS,
    C_HIST_HITS,
    C_HIST_N,
    C_HITS,
    C_MISSES,
    C_STATE,
    C_UPD,
    N_C,
    ST_COASTING,
    ST_CONFIRMED,
    ST_TENTATIVE,
    row_tables,
)
from dynslam2d.detect.layout import KIND_CODES, KIND_NAMES
from dynslam2d.detect.measure import Detection, ScanDetection

# (row_tables' Python function: the tracker's views of its row buffers, made by NumPy)
_row_views = row_tables.py_func
_HALF_PI = 0.5 * math.pi
_TWO_PI = 2.0 * math.pi


def _hypot_2f(dx: float, dy: float, hypot=math.hypot, np_hypot=np.hypot) -> str:
    """``f"{float(np.hypot(dx, dy)):.2f}"`` (a distance in m, as the reasons print it) from Python's ``math.hypot``,
    without NumPy's scalar ufunc call (≈ 1 µs; docs/speed.md, pass trk87). Both are within 1 ulp of the exact
    distance (math.hypot: CPython's ``vector_norm``; np.hypot: the C library's ``hypot``), so they can differ by
    2 ulp at most: the two-decimal text (the exact value of the float rounded to the nearest hundredth, ties to
    even) is the same unless 100·d lies within far less than 10⁻⁷ of a tie (an odd multiple of ½) — there, and for
    any distance of 10 km or more or not finite, the text is NumPy's own. The moving tracks' reasons in
    M (:func:`moved_reason`)."""
    d = hypot(dx, dy)
    q = d * 100.0
    if 0.0 <= q < 1e6:
        f = q - int(q)
        if f < 0.4999999 or f > 0.5000001:
            return f"{d:.2f}"
    return f"{float(np_hypot(dx, dy)):.2f}"


def moved_reason(speed: float, dx: float, dy: float) -> str:
    """The reason of a track in M that moves: ``speed`` (m/s) and its centre's displacement since birth (``dx``,
    ``dy``: the state's x, y minus ``birth_xy``, m, map frame) as ``TrackManage._manage`` / ``_dynamic`` printed it
    every scan; now stored as these three floats (``_Track._reason``) and formatted only when the reason is read
    (``_Track.reason``, ``TrackReports``' ``m_reason``): the same floats, the same text (docs/speed.md, pass trk136)."""
    return f"in M: speed {speed:.2f} m/s, moved {_hypot_2f(dx, dy)} m since birth"


TENTATIVE = "tentative"
CONFIRMED = "confirmed"
COASTING = "coasting"
# the states by their code in the counter table (column C_STATE of Tracker._CI), and the codes by state
STATE_NAMES = (TENTATIVE, CONFIRMED, COASTING)
STATE_CODES = {TENTATIVE: ST_TENTATIVE, CONFIRMED: ST_CONFIRMED, COASTING: ST_COASTING}
assert tuple(STATE_CODES[n] for n in STATE_NAMES) == (0, 1, 2)
assert (C_STATE, C_HITS, C_MISSES, C_HIST_N, C_HIST_HITS, C_UPD, C_BS, C_BN, N_C) == (0, 1, 2, 3, 4, 5, 6, 7, 8)
# a new track's counter row (_new_track): tentative, one hit, no miss, M of N 1 / 1, not flagged updated, its beams
# not a segment of the batch's (C_BN −1: the reports' movers take them from the track, pass rep149) (an array: ≈ 0.3 µs
# less to write into its row than a tuple)
_CI_BIRTH = np.array((ST_TENTATIVE, 1, 0, 1, 1, 0, 0, -1), dtype=np.int64)
_NO_BEAMS = np.zeros(0, dtype=np.int64)  # the beams of a track without detection (shared, never written)
_NO_IDX = np.zeros(0, dtype=np.int64)  # no leg merge in this scan (Tracker._mev_src; shared, never written)
_NO_STATE = np.zeros(0)  # placeholder x / P of a _Track before _add_row gives it its row
# a track's stored-points list starts anew once this many of its entries are out of date (_Track.past, past_a)
_PAST_COMPACT = 8
_ROWS0 = 64  # initial rows of the tracker's state arrays (doubled when full)
_RIDE0 = 16  # initial length of the riding windows (TrackRows._RIDE; doubled when one could overflow)


@dataclass(eq=False, slots=True)  # (slots: faster attribute access in the per-track loops)
class _Track:
    id: int
    x: np.ndarray  # [px, py, vx, vy], map frame
    P: np.ndarray  # 4×4
    born: float
    birth_xy: np.ndarray
    # the shape state: views of the track's rows of the tracker's arrays (Tracker._G, _Gi; columns G_* / GI_* of
    # detect/kernels.py), read and written by the per-scan kernels; the properties below read them one track at a time
    g: np.ndarray  # (N_G,) float: axis angle, sizes, circle radius, largest partial views (rad, m)
    gi: np.ndarray  # (N_GI,) int8: kind code, has heading, known-size flags (both tuples until _add_row)
    # the counters: views of the track's rows of the tracker's counter table (Tracker._CI, columns C_* of
    # detect/kernels_update.py: state code, hits, misses, and the M-of-N rule's counts over the first confirm_window
    # updates, all it reads) and of its last hit's stamp (Tracker._CL, s), read and written as columns by the update
    # kernel and the management step (docs/speed.md, pass cnt36); the properties below read them one track at a time
    ci: np.ndarray  # (N_C,) int64 (a tuple until _add_row)
    cl: np.ndarray  # (1,) float64: the stamp of the last update, s (a tuple until _add_row)
    fast: int = 0
    in_m: bool = False
    # why it is or is not in M: the text, or for a moving track in M the three floats of :func:`moved_reason` (formatted
    # when read: the ``reason`` property, the reports' ``m_reason``; docs/speed.md, pass trk136)
    _reason: str | tuple[float, float, float] = "not in M: tentative track"
    beams: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    # free-space fraction per update; an entry may be a detection (a birth's) or a tuple (det, ref, t, past) until it
    # is read, its value not yet computed (Tracker._free_values)
    free: list[float] = field(default_factory=list)
    # consecutive updates with a merged pair of legs or a person's circle (``person``: the last one was, > 0)
    person_streak: int = 0
    rode: bool = False  # judged riding with the laser (its body) at the last check
    was_in_m: bool = False  # has been in M before (seen moving): the map's word is not needed again
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
    # a dormant track's map-evidence window, (n, 3), copied from its row when retired (Tracker._retire; its revival
    # without a map keeps it); None for a live track, whose windows are rows of the tracker's arrays (TrackRows)
    mev_kept: np.ndarray | None = None

    @property
    def reason(self) -> str:
        """Why it is or is not in M (the report's ``m_reason``): the stored text, or :func:`moved_reason` of the
        stored floats."""
        r = self._reason
        return r if r.__class__ is str else moved_reason(*r)

    @reason.setter
    def reason(self, value: str) -> None:
        self._reason = value

    @property
    def person(self) -> bool:
        """The last detection was a merged pair of legs or a circle of a person's radius (``person_streak`` > 0: the
        update sets both, so only the streak is stored; docs/speed.md, pass trk71)."""
        return self.person_streak > 0

    @person.setter
    def person(self, value: bool) -> None:
        if not value:
            self.person_streak = 0
        elif self.person_streak == 0:
            self.person_streak = 1

    # (the counters as Python values, read from the counter rows)
    @property
    def state(self) -> str:
        """"tentative", "confirmed" or "coasting"."""
        return STATE_NAMES[self.ci.item(C_STATE)]

    @state.setter
    def state(self, value: str) -> None:
        self.ci[C_STATE] = STATE_CODES[value]

    @property
    def hits(self) -> int:
        """Updates since birth."""
        return self.ci.item(C_HITS)

    @hits.setter
    def hits(self, value: int) -> None:
        self.ci[C_HITS] = value

    @property
    def misses(self) -> int:
        """Consecutive scans without detection."""
        return self.ci.item(C_MISSES)

    @misses.setter
    def misses(self, value: int) -> None:
        self.ci[C_MISSES] = value

    @property
    def hist_n(self) -> int:
        """Scans (hits and misses) among the first confirm_window since birth (M of N)."""
        return self.ci.item(C_HIST_N)

    @hist_n.setter
    def hist_n(self, value: int) -> None:
        self.ci[C_HIST_N] = value

    @property
    def hist_hits(self) -> int:
        """Hits among them (M of N)."""
        return self.ci.item(C_HIST_HITS)

    @hist_hits.setter
    def hist_hits(self, value: int) -> None:
        self.ci[C_HIST_HITS] = value

    @property
    def last_hit(self) -> float:
        """Stamp of the last update, s."""
        return self.cl.item(0)

    @last_hit.setter
    def last_hit(self, value: float) -> None:
        self.cl[0] = value

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
               past: list, _new=object.__new__) -> _Track:
    """``_Track(id=tid, x=_NO_STATE, P=_NO_STATE, born=t, birth_xy=…, g=…, gi=…, ci=(tentative, 1 hit, 0 misses, 1, 1),
    cl=(t,), beams=…, free=…, past=…)`` with every other field at its default (a birth, :meth:`Tracker._birth`; its
    counters written into its row by ``_add_row``):
    the slots set directly, about a quarter of the dataclass ``__init__``'s cost with its keyword binding and default
    factories (``tests/test_detect_birth_fast.py`` compares every field with the dataclass's)."""
    k = _new(_Track)
    k.id = tid
    k.x = _NO_STATE
    k.P = _NO_STATE
    k.born = t
    k.birth_xy = birth_xy
    k.g = g
    k.gi = gi
    k.ci = _CI_BIRTH  # (shared, never written: _add_row copies it into the track's row and makes ci a view of that)
    k.cl = (t,)
    k.fast = 0
    k.in_m = False
    k._reason = "not in M: tentative track"
    k.beams = beams
    k.free = free
    k.person_streak = 0
    k.rode = False
    k.was_in_m = False
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
    k.mev_kept = None
    return k


# (_shape_rows builds the rows in this column order)
assert (G_THETA, G_SIZE0, G_SIZE1, G_RADIUS, G_LB0, G_LB1, N_G) == (0, 1, 2, 3, 4, 5, 6)
assert (GI_KIND, GI_HEADING, GI_KNOWN0, GI_KNOWN1, N_GI) == (0, 1, 2, 3, 4)


def _shape_rows(theta_box: float, size, known, radius: float, kind: str, has_heading: bool) -> tuple:
    """A new track's (g, gi) shape values as tuples in the columns of detect/kernels.py (size_lb 0): what
    ``Tracker._add_row`` writes into its rows of the tracker's arrays (then g / gi become views of them)."""
    return (theta_box, size[0], size[1], radius, 0.0, 0.0), (KIND_CODES[kind], has_heading, known[0], known[1])


def _past_entry(t: float, det: Detection) -> tuple[float, np.ndarray, int, int]:
    """A track's stored-points entry (``_Track.past``) for detection ``det`` at stamp ``t`` (s): its points as the
    array and row span a scan detection keeps (no view made; :func:`_past_points` makes it when read, the late
    vacated-space test), or a plain detection's own points."""
    if type(det) is ScanDetection:
        s = det._s
        j = det._j
        return t, s.pts, s.starts.item(j) - s.off, s.npts.item(j)
    return t, det.points, -1, 0


def _past_points(entry: tuple[float, np.ndarray, int, int]) -> np.ndarray:
    """The (n, 2) map-frame points of a stored-points entry (:func:`_past_entry`)."""
    _, pts, a0, n = entry
    return pts if a0 < 0 else pts[a0:a0 + n]


class TrackRows:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the live tracks' rows of the state arrays and of the
    per-update windows.

    The windows (docs/speed.md, pass trk26; were lists of tuples on each ``_Track``) are rows of arrays on the same
    rows as the states, left-aligned (entries 0 … n − 1, oldest first), pushed for all the updated tracks by the
    shape update's kernel call (:func:`dynslam2d.detect.kernels.shape_update`) and read through :meth:`_mev` /
    :meth:`_ride`:

    * ``_MEV`` (rows, sustain_updates, 3): the map evidence per update (the detection's fractions of points on
      long-occupied, observed-free, never-observed map cells, mapevidence.py), the last sustain_updates;
    * ``_RIDE`` (rows, R, 5): the riding test's window (laser-frame x, y, map-frame x, y of the centre (m), stamp (s))
      per update of the last ride_time s (at least sustain_updates of them); R doubles when a window could outgrow it;
    * ``_WN`` (rows, 3) int64: per row the entries of ``_MEV``, the entries of ``_RIDE``, and the riding pre-test of
      the window's last push (one array: one kernel argument).

    ``_X``, ``_P``, ``_G``, ``_CL``, ``_MEV`` are views of one float64 buffer ``_F``, ``_CI`` and ``_WN`` of one
    int64 buffer ``_Fi`` (``kernels_update.row_tables``' layout, pass trk129): the association's kernel takes the
    two buffers. Whatever replaces one of these tables must replace the buffers (:meth:`_alloc_tables`)."""

    def _init_rows(self, rows: int, nsus: int) -> None:
        """The row tables for ``rows`` rows and windows of ``nsus`` (sustain_updates) updates, all zero (the windows
        empty): the shape flags ``_Gi`` and riding windows ``_RIDE`` as arrays of their own, the rest in the two flat
        buffers (:meth:`_alloc_tables`)."""
        self._Gi = np.zeros((rows, N_GI), dtype=np.int8)
        self._RIDE = np.zeros((rows, max(_RIDE0, nsus + 1), 5))
        self._alloc_tables(rows, nsus)

    def _alloc_tables(self, rows: int, nsus: int) -> None:
        """New zero buffers ``_F`` (float64) and ``_Fi`` (int64) for ``rows`` rows and ``nsus`` map-evidence entries,
        and the tables ``_X``, ``_P``, ``_G``, ``_CL``, ``_MEV``, ``_CI``, ``_WN`` as their views (``row_tables``'
        layout: the association's kernel takes the two buffers instead of the seven tables; pass trk129)."""
        self._F = np.zeros(rows * (20 + N_G + 1 + 3 * nsus))
        self._Fi = np.zeros(rows * (N_C + 3), dtype=np.int64)
        self._table_views()

    def _table_views(self) -> None:
        """``_X`` … ``_WN`` made again as views of ``_F`` and ``_Fi`` (after a copy of the tracker, whose arrays
        a deep copy makes separately)."""
        self._X, self._P, self._G, self._CL, self._MEV, self._CI, self._WN = \
            _row_views(self._F, self._Fi, self._Gi.shape[0])

    def _mev(self, k: _Track) -> np.ndarray:
        """(n, 3) map evidence of the live track ``k``'s last n ≤ sustain_updates updates, oldest first (a view)."""
        row = k.row
        return self._MEV[row, :self._WN.item(row, 0)]

    def _ride(self, k: _Track) -> np.ndarray:
        """(n, 5) riding window of the live track ``k`` (laser-frame x, y, map-frame x, y (m), stamp (s) per update),
        oldest first (a view)."""
        row = k.row
        return self._RIDE[row, :self._WN.item(row, 1)]

    def _start_windows(self, row: int, mev) -> None:
        """Row ``row``'s windows for a track starting (a birth, a revival): no riding entry, the map evidence
        ``mev`` (a sequence of (structure, free, unknown) rows, possibly empty)."""
        n = len(mev)
        if n == 1:  # (a birth's: its three values written one by one, cheaper than a row assigned from a tuple)
            M = self._MEV
            M[row, 0, 0], M[row, 0, 1], M[row, 0, 2] = mev[0]
        elif n:
            self._MEV[row, :n] = mev
        W = self._WN
        W[row, 0] = n
        W[row, 1] = 0
        W[row, 2] = 0

    def _restart_windows(self, row: int, use_map: bool) -> None:
        """Row ``row``'s windows after a re-acquisition (the track had missed scans): only the entries pushed in this
        update are kept — the riding one and, with a map (``use_map``), the map evidence (the former lists cleared
        before the append)."""
        W = self._WN
        n = W.item(row, 1)
        if n > 1:
            self._RIDE[row, 0] = self._RIDE[row, n - 1]
        W[row, 1] = 1
        W[row, 2] = 0  # (one entry: fewer than ride_updates ≥ 2)
        if use_map:
            n = W.item(row, 0)
            if n > 1:
                self._MEV[row, 0] = self._MEV[row, n - 1]
            W[row, 0] = 1
        else:
            W[row, 0] = 0

    def _grow_ride(self) -> None:
        """Double the length of the riding windows (their entries kept)."""
        R = self._RIDE
        new = np.zeros((R.shape[0], 2 * R.shape[1], 5))
        new[:, :R.shape[1]] = R
        self._RIDE = new

    def report_states(self) -> tuple[np.ndarray, np.ndarray]:
        """``(X, rows)``: the tracker's Kalman state array ``X`` (m, 4) — [x, y, vx, vy] in the map frame, m and
        m/s — and the int64 row of each live track in the order of the last :meth:`update`'s live reports, so that
        ``X[rows[i]]`` is report i's centre and velocity. ``X`` is the tracker's own array, not a copy: read it
        before the next update and do not write it (the ledger's standing test reads it in one kernel call)."""
        return self._X, self._rows()

    def _rows(self) -> np.ndarray:
        """The state-array rows of the live tracks, in their order (int64)."""
        if self._order is None:
            self._order = np.array([k.row for k in self._tracks], dtype=np.int64)
        return self._order

    def _take_row(self) -> int:
        """A row of the state arrays for a new live track: a deleted track's (the last freed first), else the next
        unused one, the arrays (and the windows') doubled when full with the live tracks' views re-pointed."""
        if self._free_rows:
            row = self._free_rows.pop()
        else:
            row = self._grow_row()
        # (a new track's beams: not a segment of the batch's, and not the deleted track's; pass rep149)
        self._CI[row, C_BS] = 0
        self._CI[row, C_BN] = -1
        return row

    def _grow_row(self) -> int:
        """The next unused row of the state arrays, the arrays (and the windows') doubled when full with the live
        tracks' views re-pointed."""
        row = self._rows_used
        self._rows_used += 1
        if row == self._Gi.shape[0]:
            old = (self._X, self._P, self._G, self._CL, self._MEV, self._CI, self._WN)
            for name in ("_Gi", "_RIDE"):  # (the arrays of their own)
                a = getattr(self, name)
                b = np.zeros((2 * row,) + a.shape[1:], dtype=a.dtype)
                b[:row] = a[:row]
                setattr(self, name, b)
            self._alloc_tables(2 * row, self._MEV.shape[1])
            for a, b in zip(old, (self._X, self._P, self._G, self._CL, self._MEV, self._CI, self._WN)):
                b[:row] = a[:row]
            self._repoint()
        return row

    def _add_row(self, k: _Track, x, P: np.ndarray | None) -> None:
        """Append ``k`` to the live tracks with state ``x`` (4,) and covariance ``P`` (4, 4) (None: written by the
        caller into ``k.row`` afterwards): it gets a row of
        the state arrays (a deleted track's, else a new one; the arrays double when full) holding the values and
        its own shape rows ``k.g`` / ``k.gi``, and ``k.x`` / ``k.P`` / ``k.g`` / ``k.gi`` become views of it."""
        row = self._take_row()
        if x is not None:  # (None: the caller writes the state and covariance rows, _birth)
            self._X[row] = x
            self._P[row] = P
        self._G[row] = k.g
        self._Gi[row] = k.gi
        self._CI[row] = k.ci
        self._CI[row, C_BS] = 0  # (a revived track's beams are its detection's: not a segment of the batch's)
        self._CI[row, C_BN] = -1
        self._CL[row] = k.cl[0]
        k.row = row
        k.x = self._X[row]
        k.P = self._P[row]
        k.g = self._G[row]
        k.gi = self._Gi[row]
        k.ci = self._CI[row]
        k.cl = self._CL[row:row + 1]
        self._tracks.append(k)
        self._order = None

    def _repoint(self) -> None:
        """Make the x / P / g / gi / ci / cl of the live tracks views of their rows of the (new) state arrays."""
        X, P, G, Gi, CI, CL = self._X, self._P, self._G, self._Gi, self._CI, self._CL
        for k in self._tracks:
            row = k.row
            k.x = X[row]
            k.P = P[row]
            k.g = G[row]
            k.gi = Gi[row]
            k.ci = CI[row]
            k.cl = CL[row:row + 1]
