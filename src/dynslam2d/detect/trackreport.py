"""The output of ``Tracker.update`` (detect/tracker.py): one :class:`dynslam2d.types.Track` per live (and dormant)
track, map frame. Split out of ``detect/tracker.py`` (docs/speed.md, pass trktable)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from itertools import compress, repeat
from operator import and_, attrgetter
from typing import TYPE_CHECKING

import numpy as np

from dynslam2d.detect.frozen import _layout_twin_ok, fast_init
from dynslam2d.detect.kernels_update import report_rows
from dynslam2d.detect.layout import KIND_CIRCLE, KIND_NAMES
from dynslam2d.detect.tracktable import _HALF_PI, COASTING, CONFIRMED, STATE_NAMES, moved_reason
from dynslam2d.types import Box, Track, wrap_angle

if TYPE_CHECKING:
    from dynslam2d.records import TrackRows

_make_track = fast_init(Track)  # Track(...) / Box(...) without the frozen dataclass __init__ (detect/frozen.py)
_make_box = fast_init(Box)

# A report is built in place, fast_init's way without its two calls: an instance of an unfrozen twin class with the
# same slots, its fields stored by plain attribute stores, then made an instance of Track / Box by ``__class__``
# assignment (the same objects, frozen afterwards; docs/speed.md, pass mgr32). Only while the two classes have
# exactly the slots TrackReports._build_many stores (every field, none left unset) and Python allows the assignment;
# otherwise it calls the constructors above.
_TRACK_SLOTS = ("id", "state", "stamp", "box", "velocity", "covariance", "age", "hits", "misses", "kind", "in_m",
                "m_reason", "beams", "n_points", "remembered")
_BOX_SLOTS = ("px", "py", "theta", "length", "width")
_INLINE = (_make_track is not Track and _make_box is not Box and tuple(Track.__slots__) == _TRACK_SLOTS
           and tuple(Box.__slots__) == _BOX_SLOTS and _layout_twin_ok(Track) and _layout_twin_ok(Box))
_TrackTwin = type("_TrackTwin", (), {"__slots__": _TRACK_SLOTS})
_BoxTwin = type("_BoxTwin", (), {"__slots__": _BOX_SLOTS})


#: The per-track Python fields a report snapshots at report time (the next ``update`` mutates the ``_Track``s):
#: id, birth stamp (s), in M, reason, remembered, beams (one C-level ``map`` over the live tracks, a tuple each,
#: transposed into six columns by ``zip``). The reason as stored (``_Track._reason``): a text, or a moving track's
#: three floats, formatted by ``moved_reason`` when its ``Track`` is built (docs/speed.md, pass trk136).
_SNAP = attrgetter("id", "born", "in_m", "_reason", "remembered", "beams")
_new = object.__new__
_NO_BEAMS = np.zeros(0, dtype=np.int64)  # (the movers' beams when none has any; read only)
_NO_BOXES = np.zeros((0, 5))
_NO_X = np.zeros((0, 4))
_NO_P = np.zeros((0, 4, 4))
_NO_COLS: tuple[tuple, ...] = ((),) * 6
_SAME_CODES = list(range(len(STATE_NAMES)))  # (the tracker's state codes where TrackRows codes them alike)


class TrackReports(Sequence):
    """The reports of one ``Tracker.update``: a sequence of :class:`dynslam2d.types.Track` (map frame), kept as
    the arrays of ``report_rows`` and the live tracks' Python fields snapshotted at report time, each ``Track`` built
    when first read (then the same object on every read). The reports of the dormant tracks (never in M), built by
    the tracker, follow the live ones (:meth:`extend`).

    The built objects are those the tracker built eagerly before (docs/speed.md, passes trk70 and trk90): the box's
    five floats from ``boxes``' row, velocity / covariance rows of ``report_rows``' copies (never views of the
    tracker's state), the state / kind names, the age ``t - born``, beams only for the tracks updated in this scan,
    ``remembered`` only while in M. The pipeline, the filter and the erasure ledger read the columns
    (:meth:`moving_index`, :meth:`mover_pack`, :attr:`arrays`, :meth:`records`, :attr:`ids`, :meth:`with_beams`,
    :meth:`state_of`, :meth:`box_key`, :meth:`sight`) without building a ``Track``. :meth:`of_tracks` wraps a plain
    sequence of ``Track`` (its objects kept) for the same readers."""

    __slots__ = ("_t", "_boxes", "_Xo", "_P", "_kinds", "_states", "_hits", "_misses", "_cols", "_updated", "_n",
                 "_built", "_extra", "_no_beams", "_snames", "_bs", "_bn", "_dets")

    def __init__(self, t: float | None, boxes: np.ndarray, Xo: np.ndarray, P: np.ndarray, ints: list[list[int]],
                 cols: tuple[tuple, ...], updated: set[int] | frozenset[int], dets: list | None = None) -> None:
        """``t``: the scan's stamp, s (None: every report is given built, :meth:`of_tracks`); ``boxes`` (n, 5)
        [p_x, p_y, θ, l, w] (m, rad), ``Xo`` (n, 4) states [x, y, v_x, v_y] (m, m/s), ``P`` (n, 4, 4) covariances,
        map frame: ``report_rows``' arrays, not written afterwards; ``ints``: its kinds, states, hits, misses, beam
        segments' first points and counts (−1: not a segment) as lists; ``dets``: this scan's detections (their
        arrays hold the segments' beams), None for none; ``cols``: :data:`_SNAP`'s six fields of the live tracks as
        six tuples (ids, births, in M, reasons, remembered, beams); ``updated``: ids of the tracks updated in this
        scan (their beams are reported)."""
        self._t = t
        self._boxes, self._Xo, self._P = boxes, Xo, P
        self._kinds, self._states, self._hits, self._misses, self._bs, self._bn = ints
        self._dets = dets
        self._cols = cols
        self._updated = updated
        self._n = n = len(cols[0])
        self._built: list[Track | None] = [None] * n
        self._extra: list[Track] = []
        self._no_beams: np.ndarray | None = None  # (the one empty beams array of this scan's reports, made when read)
        self._snames = STATE_NAMES

    @classmethod
    def of_tracks(cls, tracks: Sequence[Track]) -> TrackReports:
        """``tracks`` (a sequence of ``Track``; a ``TrackReports`` is returned as it is) with the columns the
        readers take made from the objects (the same floats: float64 arrays of their fields); its items are the
        given objects."""
        if isinstance(tracks, TrackReports):
            return tracks
        objs = list(tracks)
        n = len(objs)
        boxes = np.array([(b.px, b.py, b.theta, b.length, b.width) for b in (t.box for t in objs)],
                         dtype=np.float64).reshape(n, 5)
        Xo = np.zeros((n, 4))
        if n:
            Xo[:, :2] = boxes[:, :2]
            Xo[:, 2:] = np.array([np.asarray(t.velocity, dtype=np.float64).reshape(2) for t in objs])
        snames = list(STATE_NAMES)
        states = []
        for t in objs:
            if t.state not in snames:
                snames.append(t.state)
            states.append(snames.index(t.state))
        beams = tuple(t.beams if t.beams is not None else _NO_BEAMS for t in objs)
        cols = (tuple(t.id for t in objs), (None,) * n, tuple(bool(t.in_m) for t in objs),
                tuple(t.m_reason for t in objs), tuple(bool(t.remembered) for t in objs), beams)
        out = cls(None, boxes, Xo, _NO_P, [[0] * n, states, [0] * n, [0] * n, [0] * n, [-1] * n], cols,
                  frozenset(cols[0]))
        out._built = objs
        out._snames = tuple(snames)
        return out

    def __len__(self) -> int:
        return self._n + len(self._extra)

    def __getitem__(self, i: int | slice) -> Track | list[Track]:
        if isinstance(i, slice):
            n, extra = self._n, self._extra
            js = range(*i.indices(n + len(extra)))
            if js.step == 1 and js.start >= n:  # (the dormant reports only: built already)
                return extra[js.start - n:js.stop - n]
            return [self[j] for j in js]
        n = self._n
        if i < 0:
            i += n + len(self._extra)
        if 0 <= i < n:
            r = self._built[i]
            return r if r is not None else self._build_many([i])[0]
        if i < 0:
            raise IndexError("track report index out of range")
        return self._extra[i - n]

    def __iter__(self) -> Iterator[Track]:
        built = self._built
        if None in built:
            self._build_many([i for i, r in enumerate(built) if r is None])
        yield from built
        yield from self._extra

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (TrackReports, list, tuple)):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]  (mutable by extend, like a list)

    def __add__(self, other: Sequence[Track]) -> list[Track]:
        """``reports + other``: a list, as with the list ``Tracker.update`` returned before."""
        return [*self, *other]

    def __radd__(self, other: Sequence[Track]) -> list[Track]:
        return [*other, *self]

    def __repr__(self) -> str:
        return f"TrackReports({list(self)!r})"

    def extend(self, reports: list[Track]) -> None:
        """Append built reports of tracks not in M (the dormant tracks')."""
        self._extra.extend(reports)

    @property
    def n_live(self) -> int:
        """The number of live tracks' reports (the first ones; the dormant ones' follow)."""
        return self._n

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The live reports' (n, 5) boxes [p_x, p_y, θ, l, w] and (n, 4) states [x, y, v_x, v_y] (columns 2, 3: the
        reports' velocities), map frame, m, rad, m/s: read only."""
        return self._boxes, self._Xo

    @property
    def ids(self) -> Sequence[int]:
        """The reports' track ids, in order (the snapshot's tuple while there are no dormant reports)."""
        extra = self._extra
        return self._cols[0] if not extra else [*self._cols[0], *[r.id for r in extra]]

    @property
    def dormant(self) -> list[Track]:
        """The dormant tracks' reports (built, after the live ones; read only)."""
        return self._extra

    @property
    def live_built(self) -> list[Track | None]:
        """The live reports' ``Track`` where built, else None, in order (read only): :meth:`sight` of a live report
        ``i`` is ``live_built[i]`` if not None, else ``(self, i)``."""
        return self._built

    def _object(self, i: int) -> Track | None:
        """Report ``i``'s ``Track`` if it is built (every dormant one is), else None."""
        n = self._n
        return self._built[i] if i < n else self._extra[i - n]

    def box_key(self, i: int) -> tuple[float, float, float]:
        """Report ``i``'s box centre x, y and half its longer side (m, map frame), without building its ``Track``:
        ``(float(b.px), float(b.py), 0.5 * float(max(b.length, b.width)))`` of its box ``b``."""
        if i < self._n:
            px, py, _, length, width = self._boxes[i].tolist()
            return px, py, 0.5 * max(length, width)
        b = self._extra[i - self._n].box
        return float(b.px), float(b.py), 0.5 * float(max(b.length, b.width))

    def stamp_of(self, i: int) -> float:
        """Report ``i``'s stamp, s."""
        t = self._t
        return t if t is not None and i < self._n else self._object(i).stamp

    def state_of(self, i: int) -> str:
        """Report ``i``'s state name, without building its ``Track``."""
        return self._snames[self._states[i]] if i < self._n else self._extra[i - self._n].state

    def sight(self, i: int) -> Track | tuple[TrackReports, int]:
        """Report ``i`` as something to keep and read later: its ``Track`` if built, else ``(self, i)`` (its box
        read by :meth:`box_key`)."""
        r = self._built[i] if i < self._n else self._extra[i - self._n]
        return r if r is not None else (self, i)

    def with_beams(self) -> tuple[list[int], list[np.ndarray], list[int]]:
        """The indices, beam arrays and ids of the reports with beams (the live tracks updated in this scan with a
        non-empty beam array, then the dormant reports'), without building a ``Track``."""
        upd = self._updated
        ids, bms = self._cols[0], self._cols[5]
        at = [i for i, tid, b in zip(range(self._n), ids, bms) if tid in upd and len(b)]
        blist = [bms[i] for i in at]
        tids = [ids[i] for i in at]
        n = self._n
        for j, r in enumerate(self._extra):
            if r.beams is not None and len(r.beams):
                at.append(n + j)
                blist.append(r.beams)
                tids.append(r.id)
        return at, blist, tids

    def moving_index(self) -> list[int]:
        """The indices of the reports in M (live tracks only), in order."""
        return list(compress(range(self._n), self._cols[2]))

    def mover_pack(self, idx: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
        """For the live reports ``idx``: one int64 array of their k indices, k ids, the k first places and k counts of
        their beams in ``beams`` (a report without beams, or not updated in this scan, has none) and last a split
        point ``n0``; ``beams`` and ``more``: place ``q`` holds ``beams[q]`` where ``q < n0``, else ``more[q − n0]``;
        their ids. What ``filter.mover_exclusions`` takes.

        A track updated by a detection holds that detection's beams, one segment of the scan's detection points
        (``report_rows``' columns from the counter table, written by the update's kernel; pass rep149): the beams are
        those of the detection arrays, the scan's clusters' (``beams``) and, after ``n0`` points, the merged persons'
        (``more``) — no array made. Where a mover's are not one segment (a birth, a revival, a fragment's host: count
        −1) its beams are concatenated instead (``more`` empty)."""
        ids = self._cols[0]
        upd = self._updated
        mids = [ids[i] for i in idx]
        bs, bn = self._bs, self._bn
        starts = []
        counts = []
        for i, tid in zip(idx, mids):
            if tid in upd:
                c = bn[i]
                if c < 0:
                    return self._mover_pack_copy(idx, mids)
                starts.append(bs[i])
                counts.append(c)
            else:
                starts.append(0)
                counts.append(0)
        dets = self._dets
        if not dets:  # (no detection in this scan: no mover has beams)
            return np.array(idx + mids + starts + counts + [0], dtype=np.int64), _NO_BEAMS, _NO_BEAMS, mids
        a, b = dets[0]._s, dets[-1]._s  # (the scan's clusters' arrays; the persons' last when a pair merged)
        if b.off:
            beams = _NO_BEAMS if a.off else a.beams
            return np.array(idx + mids + starts + counts + [b.off], dtype=np.int64), beams, b.beams, mids
        beams = a.beams
        return np.array(idx + mids + starts + counts + [beams.shape[0]], dtype=np.int64), beams, _NO_BEAMS, mids

    def _mover_pack_copy(self, idx: list[int], mids: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                           list[int]]:
        """:meth:`mover_pack` with the movers' beams concatenated (int64), each mover's a segment of them."""
        bms = self._cols[5]
        upd = self._updated
        blist = []
        starts = []
        counts = []
        total = 0
        for i, tid in zip(idx, mids):
            starts.append(total)
            nb = 0
            if tid in upd:
                b = bms[i]
                nb = len(b)
                if nb:
                    blist.append(b)
                    total += nb
            counts.append(nb)
        # (the int64 concatenation in one call: no astype after it, pass mov133)
        beams = np.concatenate(blist, dtype=np.int64) if blist else _NO_BEAMS
        return np.array(idx + mids + starts + counts + [total], dtype=np.int64), beams, _NO_BEAMS, mids

    def _build_many(self, idx: list[int]) -> list[Track]:
        """The ``Track`` of each live report ``idx`` (built once, then the same object), in one loop with its reads
        hoisted: the values the eager loop gave (the class docstring)."""
        if not idx:
            return []
        boxes = self._boxes
        # (a few rows one by one: a fancy index with a list costs ≈ 1.5 µs, a row's tolist ≈ 0.3; many: all rows)
        if len(idx) <= 4:
            rows = [boxes[i].tolist() for i in idx]
        else:
            every = boxes.tolist()
            rows = [every[i] for i in idx]
        ids, borns, in_ms, reasons, rems, bms = self._cols
        upd, built, t, V, P = self._updated, self._built, self._t, self._Xo[:, 2:], self._P
        states, hits, misses, kinds = self._states, self._hits, self._misses, self._kinds
        snames, knames, track_twin, box_twin, track_cls, box_cls = \
            self._snames, KIND_NAMES, _TrackTwin, _BoxTwin, Track, Box
        out = []
        for i, (px, py, theta, length, width) in zip(idx, rows):
            r = built[i]
            if r is None:
                tid = ids[i]
                beams = bms[i]
                if tid not in upd:
                    beams = self._no_beams
                    if beams is None:
                        beams = self._no_beams = np.zeros(0, dtype=np.int64)
                in_m = in_ms[i]
                reason = reasons[i]
                if reason.__class__ is not str:
                    reason = moved_reason(*reason)
                if not _INLINE:
                    built[i] = r = _make_track(tid, snames[states[i]], t, _make_box(px, py, theta, length, width),
                                               V[i], P[i], t - borns[i], hits[i], misses[i], knames[kinds[i]], in_m,
                                               reason, beams, len(beams), rems[i] and in_m)
                    out.append(r)
                    continue
                # (every slot of _TRACK_SLOTS / _BOX_SLOTS stored, in order)
                b = _new(box_twin)
                b.px = px
                b.py = py
                b.theta = theta
                b.length = length
                b.width = width
                b.__class__ = box_cls
                r = _new(track_twin)
                r.id = tid
                r.state = snames[states[i]]
                r.stamp = t
                r.box = b
                r.velocity = V[i]
                r.covariance = P[i]
                r.age = t - borns[i]
                r.hits = hits[i]
                r.misses = misses[i]
                r.kind = knames[kinds[i]]
                r.in_m = in_m
                r.m_reason = reason
                r.beams = beams
                r.n_points = len(beams)
                r.remembered = rems[i] and in_m
                r.__class__ = track_cls
                built[i] = r
            out.append(r)
        return out

    def add_rows(self, stamp: float, rows: TrackRows) -> bool:
        """Append the reports to ``rows`` (``dynslam2d.records.TrackRows``) from the columns, one call per column
        (:meth:`TrackRows.add_columns`): the rows :meth:`records` gives, without a tuple per track. Returns False, with
        nothing added, when they are not all live reports of a scan, a state name has no code in ``rows`` yet (it gets
        one in the reports' order from :meth:`records`) or ``rows`` refuses a value: the caller then adds
        :meth:`records`."""
        if self._t is None or self._extra or not self._n:
            return False
        codes = rows.state_codes
        sc = [codes.get(s) for s in self._snames]
        if sc == _SAME_CODES[:len(sc)]:
            states: list[int] = self._states
        elif None in sc:
            return False
        else:
            states = [sc[i] for i in self._states]
        ids, _, in_ms, _, rems, _ = self._cols
        return rows.add_columns(stamp, ids, states, self._boxes, self._Xo, in_ms, rems)

    def records(self, stamp: float, codes: dict[str, int], code: Callable[[str], int]) -> list[tuple]:
        """The reports as ``TrackRows.extend_records`` rows (stamp, id, state code, box, velocity, in M, remembered),
        the values the pipeline's per-object loop gave: ``codes`` / ``code`` the state names' codes."""
        out: list[tuple] = []
        if self._t is not None and self._n:
            ids, _, in_ms, _, rems, _ = self._cols
            sc = [codes.get(s) for s in self._snames]
            if None not in sc:
                states = [sc[i] for i in self._states]
            else:  # (a new name gets its code in the reports' order, as the per-object loop gave it)
                states = [code(self._snames[i]) for i in self._states]
            # (in M and remembered-and-in-M: the tracker's bools, ``&`` of two bools the ``and`` of the objects)
            out = list(zip(repeat(stamp, self._n), ids, states, *self._boxes.T.tolist(), *self._Xo[:, 2:].T.tolist(),
                           in_ms, map(and_, rems, in_ms)))
            objs = self._extra
        else:
            objs = self._built + self._extra if self._n else self._extra
        append = out.append
        for t in objs:
            b = t.box
            st = t.state
            vx, vy = t.velocity.tolist()
            append((stamp, t.id, codes[st] if st in codes else code(st), b.px, b.py, b.theta, b.length, b.width, vx,
                    vy, bool(t.in_m), bool(t.remembered)))
        return out


class TrackReport:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the reports (``_report``)."""

    def _report(self, t: float, updated: set[int]) -> TrackReports:
        tracks = self._tracks
        if not tracks:
            return TrackReports(t, _NO_BOXES, _NO_X, _NO_P, [[], [], [], [], [], []], _NO_COLS, updated)
        slow = 0.5 * self.config.tracker.v_min
        # (speed: the boxes of all tracks, their states, covariances and kinds from their rows in one kernel call —
        # the moving test on Python's math.hypot bit for bit —; every report's velocity / covariance a row of the
        # copies, its own memory apart from the tracker's; docs/speed.md, pass trk24)
        # (and the kinds, states, hits and misses as four lists: the shape rows' and the counter table's columns, pass
        # cnt36)
        boxes, Xo, P, ints = report_rows(self._G, self._Gi, self._X, self._P, self._CI, self._rows(), slow)
        # the reports kept as these arrays and each live track's Python fields as of this scan; a Track built when
        # read, the pipeline's movers never (TrackReports; docs/speed.md, passes trk70, trk90)
        return TrackReports(t, boxes, Xo, P, ints.tolist(), tuple(zip(*map(_SNAP, tracks))), updated,
                            self.last_detections)

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
