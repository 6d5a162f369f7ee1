"""Free-space test: did an earlier scan see *through* the place where a point is now?

An object that moves occupies space the sensor saw as free a moment ago; a wall's points lie
where earlier beams ended, never where they passed through (leg_tracker's free-space test,
Leigh et al., ICRA 2015; the paper's §2.2 "comparison of consecutive frames"). For each point p
(map frame) and each reference scan (a few tenths of a second old, with its own pose) the test
projects p into that scan: bearing φ and range ρ from the reference sensor. p was in free space
if the reference beams at φ (the nearest beam and its two neighbours, so that a grazing wall
cannot pass) all returned farther than ρ + margin, or nothing (within range_max).

Occluded places (a beam ending before ρ) and places outside the reference field of view are
"unknown", not free. Frames: map frame; units m, rad, s.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass

import numpy as np

from dynslam2d.detect.frozen import fast_init
from dynslam2d.detect.kernels import seen_through_refs
from dynslam2d.jitbox import njit  # numba's njit, arrays returned without a per-array unpickle
from dynslam2d.types import Pose2D, Scan, wrap_angle


@dataclass(frozen=True, slots=True, eq=False)
class _Ref:
    stamp: float
    pose: Pose2D
    ranges: np.ndarray  # no return → +inf
    angle_min: float
    increment: float
    full: bool
    reach: float  # a no-return beam saw through everything closer than this, m
    # (7,) its parameters for seen_through_refs: pose.inverse() (x, y, θ: map → reference sensor frame, made once),
    # angle_min, increment, full, reach
    par: np.ndarray


@njit(cache=True)
def _ref_arrays(ranges: np.ndarray, valid: np.ndarray, ix: float, iy: float, ith: float, amin: float, inc: float,
                full: float, reach: float) -> tuple:
    """A reference's ranges (m; +inf where ``valid`` is False: ``np.where(valid, ranges, inf)``) and its (7,)
    parameter row (:attr:`_Ref.par`) in one call."""
    n = ranges.shape[0]
    r = np.empty(n)
    for i in range(n):
        r[i] = ranges[i] if valid[i] else np.inf
    par = np.empty(7)
    par[0] = ix
    par[1] = iy
    par[2] = ith
    par[3] = amin
    par[4] = inc
    par[5] = full
    par[6] = reach
    return r, par


_make_ref = fast_init(_Ref)  # (the frozen dataclass without its __init__'s object.__setattr__, detect/frozen.py)


class FreeSpaceMemory:
    """Keeps recent scans with their poses and answers "was this point seen through?".

    Args:
        ref_ages: ages of the reference scans used, s (the buffered scan nearest each age).
        margin: a reference beam must end at least this far behind the point, m.
        max_age: scans older than this are forgotten, s.
    """

    def __init__(self, ref_ages: tuple[float, ...] = (0.3, 0.8), margin: float = 0.15, max_age: float = 1.5) -> None:
        self.ref_ages = tuple(float(a) for a in ref_ages)
        self.margin = float(margin)
        self.max_age = max(float(max_age), max(self.ref_ages) + 0.5)
        self._buf: deque[_Ref] = deque()
        # the buffered references' stamps (s), in the buffer's order: what :meth:`add` and :meth:`_refs` read, a
        # float list searched by a plain bisection instead of the references' attributes through a key function
        # (docs/speed.md, pass trk71)
        self._stamps: list[float] = []
        self._descents = 0  # neighbours in the buffer whose stamps go back (0: time-ordered, :meth:`_refs` bisects)

    def clear(self) -> None:
        self._buf.clear()
        self._stamps.clear()
        self._descents = 0

    @staticmethod
    def make_ref(scan: Scan, pose: Pose2D, valid: np.ndarray) -> _Ref:
        """A reference built from ``scan`` (taken at ``pose``, map frame; ``valid`` = beams with a return)."""
        ranges = scan.ranges
        inc_abs = abs(scan.angle_increment)
        full = ranges.shape[0] * inc_abs >= 2.0 * math.pi - 1.5 * inc_abs
        # pose.inverse() (Pose2D.inverse's arithmetic, without the Pose2D)
        x, y, th = pose.x, pose.y, pose.theta
        c, s = math.cos(th), math.sin(th)
        amin, inc, reach = float(scan.angle_min), float(scan.angle_increment), float(scan.range_max)
        r, par = _ref_arrays(ranges, valid, -c * x - s * y, s * x - c * y, float(wrap_angle(-th)), amin, inc,
                             1.0 if full else 0.0, reach)
        return _make_ref(float(scan.stamp), pose, r, amin, inc, full, reach, par)

    @staticmethod
    def ref_of(scan: Scan, pose: Pose2D, r: np.ndarray, par: np.ndarray) -> _Ref:
        """The reference :meth:`make_ref` builds from ``scan`` at ``pose``, of its arrays made already (``r``, ``par``:
        :func:`dynslam2d.detect.segment.segment_points`' with ``ref``, in the segmentation's kernel call; docs/speed.md,
        pass trk60): angle_min, increment, the full-circle flag and range_max read back from ``par``."""
        _, _, _, amin, inc, full, reach = par.tolist()
        return _make_ref(float(scan.stamp), pose, r, amin, inc, full != 0.0, reach, par)

    def step(self, scan: Scan, pose: Pose2D, r: np.ndarray, par: np.ndarray, test: bool) -> tuple:
        """The tracker's per-scan use in one call (docs/speed.md, pass det81): (ref, free test) where ref is
        :meth:`ref_of` ``(scan, pose, r, par)`` and the test :meth:`test_at` at the scan's stamp made before the memory
        gains the scan (None where ``test`` is False or there is no reference scan); then :meth:`add` of ``scan``
        with ``ref``. The same references, the same test and the same buffer as the three calls."""
        st = float(scan.stamp)
        ref = self.ref_of(scan, pose, r, par)  # (through the class attribute: benchmarks hook it)
        ft = None
        if test and self._buf and (refs := self._refs(st)):
            ft = object.__new__(FreeTest)
            ft.refs = tuple(refs)
            ft.margin = self.margin
        self.add(scan, pose, r, ref)  # (valid is not read when ref is given)
        return ref, ft

    def add(self, scan: Scan, pose: Pose2D, valid: np.ndarray, ref: _Ref | None = None) -> None:
        """Remember ``scan`` (taken at ``pose``, map frame); ``valid`` marks beams with a return."""
        buf, stamps = self._buf, self._stamps
        new = ref if ref is not None else self.make_ref(scan, pose, valid)
        st = new.stamp
        if stamps and st < stamps[-1]:
            self._descents += 1
        buf.append(new)
        stamps.append(st)
        now, max_age = scan.stamp, self.max_age
        while stamps and now - stamps[0] > max_age:
            if len(stamps) > 1 and stamps[1] < stamps[0]:
                self._descents -= 1
            buf.popleft()
            del stamps[0]

    def _refs(self, now: float) -> list[_Ref]:
        """The buffered scans nearest each of :attr:`ref_ages` before ``now`` (s), each once, older than 0 s."""
        out: list[_Ref] = []
        buf = self._buf
        if not buf:
            return out
        if self._descents:  # (stamps that go back: every buffered age compared)
            ages = [now - x for x in self._stamps]
            for a in self.ref_ages:
                # the buffered scan whose age is nearest a (the first on ties, as np.argmin; ages are finite): min
                # keeps its first item and replaces it only by a smaller one, and index finds that item's first
                # position (an equal item before it would have been kept), so this is the loop "j = i where d <
                # best" in C
                dev = [abs(x - a) for x in ages]
                j = dev.index(min(dev))
                if ages[j] > 0.0 and buf[j] not in out:
                    out.append(buf[j])
            return out
        # time-ordered (pass rest18): the ages now − stamp do not grow along the buffer (a rounded difference is
        # monotone), so |age − a| falls to the last age ≥ a and rises from the first age < a: the first nearest is
        # the first of the equal deviations ending at index k − 1, or index k — the same scan as the scan of every
        # age above, in a bisection
        # The first index whose age is < a, without a key function (pass trk71): the stamps' bisection at now − a,
        # then the exact test (now − stamp < a, the ages' rounded differences) one step back or forward while it
        # disagrees — the test is monotone along the buffer, so this is the first index where it holds, the index
        # ``bisect_right(buf, -a, key=lambda b: -(now - b.stamp))`` gave
        stamps = self._stamps
        n = len(stamps)
        for a in self.ref_ages:
            k = bisect_right(stamps, now - a)
            while k > 0 and now - stamps[k - 1] < a:
                k -= 1
            while k < n and not now - stamps[k] < a:  # (a guard: not seen to change the choice in the tests)
                k += 1
            if k == 0:
                j = 0
            else:
                d = (now - stamps[k - 1]) - a
                if k < n and a - (now - stamps[k]) < d:
                    j = k
                else:
                    j = k - 1
                    while j > 0 and (now - stamps[j - 1]) - a == d:
                        j -= 1
            b = buf[j]
            if now - stamps[j] > 0.0 and b not in out:
                out.append(b)
        return out

    def seen_through(self, points: np.ndarray, now: float) -> np.ndarray:
        """(n,) bool: the (n, 2) map-frame points lay in space that a reference scan saw as free."""
        free = np.zeros(points.shape[0], dtype=bool)
        if points.shape[0] and (test := self.test_at(now)) is not None:
            test.count(points, free)
        return free

    def count_seen_by(self, ref: _Ref, points: np.ndarray) -> int:
        """How many of the (n, 2) map-frame points the scan ``ref`` saw through (module docstring; one kernel call, no
        mask kept: a track's vacated space, read late)."""
        if not points.shape[0]:
            return 0
        return seen_through_refs(np.ascontiguousarray(points, dtype=np.float64), ref.ranges, ref.par, ref.ranges,
                                 ref.par, 1, self.margin, np.zeros(points.shape[0], dtype=bool))

    def test_at(self, now: float) -> FreeTest | None:
        """The free-space test of a scan at ``now`` (s) kept for later: the reference scans it uses now (None when
        there is none: every point is unknown, fraction 0). The memory gains and drops scans afterwards; the
        test keeps its own (:class:`FreeTest`)."""
        refs = self._refs(now)
        return FreeTest(tuple(refs), self.margin) if refs else None


class FreeTest:
    """The free-space test of one scan with the reference scans the memory chose for it
    (:meth:`FreeSpaceMemory.test_at`), so that a detection's fraction can be computed when it is first read, after
    the memory has moved on: the value is that of :meth:`FreeSpaceMemory.seen_through` at the scan's time."""

    __slots__ = ("refs", "margin")

    def __init__(self, refs: tuple[_Ref, ...], margin: float) -> None:
        self.refs = refs
        self.margin = margin

    def count(self, points: np.ndarray, free: np.ndarray) -> int:
        """OR into ``free`` the (n, 2) map-frame ``points`` a reference scan saw through; returns how many ``free``
        holds then. Two references per kernel call (:func:`dynslam2d.detect.kernels.seen_through_refs`: one call
        for the default two reference ages)."""
        pts = np.ascontiguousarray(points, dtype=np.float64)
        refs, margin = self.refs, self.margin
        if not refs:
            return int(np.count_nonzero(free))
        for q in range(0, len(refs), 2):
            two = q + 1 < len(refs)
            a = refs[q]
            b = refs[q + 1] if two else a
            count = seen_through_refs(pts, a.ranges, a.par, b.ranges, b.par, 2 if two else 1, margin, free)
        return count

    def fraction(self, points: np.ndarray) -> float:
        """Fraction of the (n, 2) map-frame ``points`` that a reference scan saw through (0 for none): the count
        over n, as the tracker's per-detection mean (:func:`dynslam2d.detect.kernels.mask_fractions`)."""
        n = points.shape[0]
        if n == 0:
            return 0.0
        return self.count(points, np.zeros(n, dtype=bool)) / n
