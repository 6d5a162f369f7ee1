"""Step 5 of ``Tracker.update`` (detect/tracker.py): the Kalman and shape updates of the associated pairs, the
acceleration bound, the per-track bookkeeping (counters, map evidence, riding window, stored points) and the
free-space values read late (the vacated-space test). Split out of ``detect/tracker.py`` (docs/speed.md, pass
trktable)."""

from __future__ import annotations

import bisect
import math

import numpy as np

from dynslam2d.detect.kernels import G_SIZE0
from dynslam2d.detect.measure import Detection, ScanDetection
from dynslam2d.detect.tracktable import _HALF_PI, _PAST_COMPACT, TENTATIVE, _past_points, _Track


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


class TrackUpdate:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: the update step (``_updated_pairs``, ``_update_tracks``;
    its kernel, ``update_pairs``, runs in the association's call: ``Tracker._associate_update``)."""

    def _accel_limits(self) -> tuple[bool, float, float]:
        """The physical acceleration bound of this scan's updates (``update_pairs``' ``bound``, ``lim``, ``lim2``):
        whether it applies (``max_accel`` set and the scan's dt > 0), the largest change of a velocity in one update,
        ``max_accel``·dt (m/s), and (0.999·lim)² ((m/s)²); (False, 0, 0) without it."""
        tc = self.config.tracker
        if tc.max_accel is not None and self._dt > 0.0:
            lim = tc.max_accel * self._dt
            return True, float(lim), (0.999 * lim) ** 2
        return False, 0.0, 0.0

    def _updated_pairs(self, applied: np.ndarray, dets: list[Detection], t: float, nb: int, top: int) -> None:
        """After ``update_pairs`` (``Tracker._associate_update``'s call) ran at the scan's stamp ``t`` (s): its count
        ``nb`` of bounded rows into the stats, the riding window grown when its longest row ``top`` filled it, then
        the per-track bookkeeping (:meth:`_update_tracks`) of the pairs whose update applied (``applied``: the
        kernel's rows, ``kernels_assign.applied_pairs``)."""
        if nb:
            self.stats.accel_bounded += nb
        if top >= self._RIDE.shape[1]:  # (the next push could overflow a full window)
            self._grow_ride()
        if applied.shape[0]:
            self._update_tracks(applied.tolist(), dets, t)

    def _update_tracks(self, applied: list[list[int]], dets: list[ScanDetection], t: float) -> None:
        """The bookkeeping update of the tracks whose Kalman and shape results are already in their rows (k.x, k.P,
        k.g, k.gi); ``applied``: per pair whose update applied, in the pairs' order, [track index, detection index,
        1 (or 2: the track is re-acquired, it had missed scans before this update), the detection's first point in
        the batch, its point count, 1 if it is a circle of a person's radius] (``kernels_assign.applied_pairs``' rows
        of ``update_pairs``' ``info``, one conversion per scan: the pairs that did not apply are left out there, and
        the detections' own properties (ScanDetection) would read these values one by one); the scan's constants are
        read once (one loop over the pairs: the update of one track is a few µs of Python). The riding and
        map-evidence windows are pushed before, for all pairs in the same kernel call, and a re-acquired track's
        restarted there to that push's entries; so are the counters (hits, misses, last hit, M of N: columns of the
        counter table, pass cnt36).

        Per pair, in this order: the track's id into the updated set (the detections taken: the kernel's unused list,
        pass trk138); the free-space entry (for a re-acquired track its window, speed count and probation restarted
        first) made of the stored points as they were before this update; the flags and the beams; then, with a
        free-space memory, the detection's points stored (the entries older than its max age skipped, the list
        started anew every ``_PAST_COMPACT`` of them; a re-acquired track's on a new list). The loop is written for
        the common case (an applied update of a tracked object, the free-space memory on): the re-acquired and the
        no-memory cases are the branches (docs/speed.md, pass trk71)."""
        nsus = self.config.tracker.sustain_updates
        fm = self._free
        ref = self._cur_ref if fm is not None else None  # (the vacated-space test's reference: this scan)
        max_age = fm.max_age if fm is not None else 0.0
        tracks = self._tracks
        upd_add = self._updated.add
        # (row di of the batch, read by the kernel for info, is detection di's row, copied by the leg merge)
        for ti, di, ok, start, npt, circle_person in applied:
            k = tracks[ti]
            det = dets[di]
            upd_add(k.id)
            # (the detection's rows of its scan's beams and points: ScanDetection.beams / points, from the batch)
            arrays = det._s
            a0 = start - arrays.off
            # (the stored points before this update: their vacated-space fraction is computed when first read)
            # ((the list, first, end): the entries are never changed in place, so this is their snapshot)
            past = k.past
            pa = k.past_a
            np0 = len(past)
            free = k.free
            if ok == 2:
                # re-acquired after a gap: the free-space evidence must be rebuilt from this object
                k.past = []  # (a new list: the snapshots of earlier updates may hold the old one)
                k.past_a = 0
                free.clear()  # (the riding and map-evidence windows: restarted by the kernel, update_pairs)
                k.fast = 0
                k.probation = k.in_m and not k.remembered  # a remembered track re-acquired where it stopped
            # (vacated: this scan sees through its old points; computed when the entry is read, _free_values)
            # (the detection's own fraction too: det.free_fraction, computed when read)
            free.append((det, ref, t, past, pa, np0) if np0 > pa and ref is not None
                        else max(det.free_fraction, 0.0))
            if len(free) > nsus:
                del free[0]
            k.merged = False
            # (k.person, the last detection a merged pair of legs or a person's circle: person_streak > 0)
            k.person_streak = k.person_streak + 1 if det.person or circle_person == 1 else 0
            k.beams = arrays.beams[a0:a0 + npt]
            if fm is None:
                continue
            if ok == 2:
                past = k.past
                pa = np0 = 0
            past.append((t, arrays.pts, a0, npt))  # (_past_entry of a scan detection, inline)
            # (np0 + 1 entries now: the guard pa ≤ np0)
            while pa <= np0 and t - past[pa][0] > max_age:
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
            return entry.free_fraction if isinstance(entry, (Detection, ScanDetection)) else entry
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
