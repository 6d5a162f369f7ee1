"""The output of ``Tracker.update`` (detect/tracker.py): one :class:`dynslam2d.types.Track` per live (and dormant)
track, map frame. Split out of ``detect/tracker.py`` (docs/speed.md, pass trktable)."""

from __future__ import annotations

import numpy as np

from dynslam2d.detect.frozen import _layout_twin_ok, fast_init
from dynslam2d.detect.kernels_update import report_rows
from dynslam2d.detect.layout import KIND_CIRCLE, KIND_NAMES
from dynslam2d.detect.tracktable import _HALF_PI, COASTING, CONFIRMED, STATE_NAMES
from dynslam2d.types import Box, Track, wrap_angle

_make_track = fast_init(Track)  # Track(...) / Box(...) without the frozen dataclass __init__ (detect/frozen.py)
_make_box = fast_init(Box)

# The live tracks' reports are built in _report's loop itself, fast_init's way without its two calls per track: an
# instance of an unfrozen twin class with the same slots, its fields stored by plain attribute stores, then made an
# instance of Track / Box by ``__class__`` assignment (the same objects, frozen afterwards; docs/speed.md, pass
# mgr32). Only while the two classes have exactly the slots that loop stores (every field, none left unset) and
# Python allows the assignment; otherwise the loop calls the constructors above.
_TRACK_SLOTS = ("id", "state", "stamp", "box", "velocity", "covariance", "age", "hits", "misses", "kind", "in_m",
                "m_reason", "beams", "n_points", "remembered")
_BOX_SLOTS = ("px", "py", "theta", "length", "width")
_INLINE = (_make_track is not Track and _make_box is not Box and tuple(Track.__slots__) == _TRACK_SLOTS
           and tuple(Box.__slots__) == _BOX_SLOTS and _layout_twin_ok(Track) and _layout_twin_ok(Box))
_TrackTwin = type("_TrackTwin", (), {"__slots__": _TRACK_SLOTS})
_BoxTwin = type("_BoxTwin", (), {"__slots__": _BOX_SLOTS})


class TrackReport:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the reports (``_report``)."""

    def _report(self, t: float, updated: set[int]) -> list[Track]:
        tracks = self._tracks
        if not tracks:
            return []
        slow = 0.5 * self.config.tracker.v_min
        # (speed: the boxes of all tracks, their states, covariances and kinds from their rows in one kernel call —
        # the moving test on Python's math.hypot bit for bit —; every report's velocity / covariance a row of the
        # copies, its own memory apart from the tracker's; docs/speed.md, pass trk24)
        # (and the kinds, states, hits and misses as four lists: the shape rows' and the counter table's columns, pass
        # cnt36)
        boxes, Xo, P, ints = report_rows(self._G, self._Gi, self._X, self._P, self._CI, self._rows(), slow)
        V = Xo[:, 2:]
        kinds, states, hits, misses = ints.tolist()
        no_beams = np.zeros(0, dtype=np.int64)
        out = []
        append, names = out.append, KIND_NAMES  # (locals: per track)
        # (the boxes' columns as five lists: the same floats as boxes.tolist()'s rows, without a list per track)
        snames = STATE_NAMES
        columns = zip(tracks, *boxes.T.tolist(), kinds, V, P, states, hits, misses)
        if not _INLINE:
            make_track, make_box = _make_track, _make_box
            for k, px, py, theta, length, width, kd, vel, cov, sc, nh, nm in columns:
                beams = k.beams if k.id in updated else no_beams
                in_m = k.in_m
                append(make_track(k.id, snames[sc], t, make_box(px, py, theta, length, width), vel, cov, t - k.born,
                                  nh, nm, names[kd], in_m, k.reason, beams, len(beams), k.remembered and in_m))
            return out
        # the same objects built in place (_INLINE above): every slot of _TRACK_SLOTS / _BOX_SLOTS stored, in order
        new, track_twin, box_twin, track_cls, box_cls = object.__new__, _TrackTwin, _BoxTwin, Track, Box
        for k, px, py, theta, length, width, kd, vel, cov, sc, nh, nm in columns:
            b = new(box_twin)
            b.px = px
            b.py = py
            b.theta = theta
            b.length = length
            b.width = width
            b.__class__ = box_cls
            r = new(track_twin)
            r.id = kid = k.id
            r.state = snames[sc]
            r.stamp = t
            r.box = b
            r.velocity = vel
            r.covariance = cov
            r.age = t - k.born
            r.hits = nh
            r.misses = nm
            r.kind = names[kd]
            r.in_m = in_m = k.in_m
            r.m_reason = k.reason
            if kid in updated:
                r.beams = beams = k.beams
                r.n_points = len(beams)
            else:
                r.beams = no_beams
                r.n_points = 0
            r.remembered = k.remembered and in_m
            r.__class__ = track_cls
            append(r)
        return out

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
