"""Steps 6–7 of ``Tracker.update`` (detect/tracker.py): track management (M of N, coasting, deletions) and the
dynamic set M (paper Eq. 3) with its tests (free space, map evidence, people, riding with the laser) and the
track memory (detect.memory). Split out of ``detect/tracker.py`` (docs/speed.md, pass trktable)."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels_update import (
    AUX_EXIT,
    AUX_NEAR,
    AUX_RETIRE,
    AUX_SLOW_SHIFT,
    MC_COAST,
    MC_DEL_COVARIANCE,
    MC_DEL_TENTATIVE,
    MC_KEPT,
    MC_UPD_FIRM,
    MC_UPD_TENTATIVE,
    MC_UPDATED,
    RIDE_FAR,
    RIDE_JUDGE,
    RIDE_OFF_BODY,
    manage_scan,
    ride_window,
)
from dynslam2d.detect.tracktable import _NO_BEAMS, _TWO_PI, TENTATIVE, _Track
from dynslam2d.types import Pose2D, wrap_angle

_NO_BODY = np.zeros(0, dtype=np.bool_)  # (ride_window's body beams when no body was found: never read)


def _fast_reason_texts(nsus: int) -> tuple[str, ...]:
    """The reasons of a track not in M that has been faster than v_min for 0 … ``nsus`` − 1 of the ``nsus``
    (sustain_updates) updates it needs, by that count (the same texts every scan: formatted once per tracker)."""
    return tuple(f"not in M: speed > v_min for {kfast}/{nsus} updates" for kfast in range(nsus))


# the reasons of a track not in M at most v_min by the speed rounded to 0.01 m/s, looked up instead of formatted when
# v_min is at most this (m/s; _slow_reason_texts)
_SLOW_TEXTS_MAX = 10.0


def _slow_reason_texts(v_min: float) -> tuple[str, ...]:
    """The reasons "not in M: speed S m/s ≤ v_min V" of a track not in M whose speed (m/s) prints as S = i / 100 with
    two decimals, by i = 0 … ⌊100·v_min⌋ + 1 (every S a speed ≤ ``v_min`` can print as; formatted once per tracker);
    empty for ``v_min`` above :data:`_SLOW_TEXTS_MAX` or not finite (then the reasons are formatted per track)."""
    if not 0.0 <= v_min <= _SLOW_TEXTS_MAX:
        return ()
    tail = f" m/s ≤ v_min {v_min:.2f}"
    return tuple(f"not in M: speed {i / 100:.2f}{tail}" for i in range(int(v_min * 100.0) + 2))


def _slow_reason(speed: float, texts: tuple[str, ...], tail: str) -> str:
    """``f"not in M: speed {speed:.2f}{tail}"`` for a speed 0 ≤ ``speed`` ≤ v_min (m/s) from ``texts``
    (:func:`_slow_reason_texts` of that v_min; ``tail`` its constant end): the speed rounded to two decimals as
    ``format`` rounds it (to the nearest, ties to even, of the float's exact value) is that of 100·speed, whose float
    product differs from the exact one by far less than 10⁻⁹ — so where its fraction is not within 10⁻⁷ of ½ (a tie,
    or one the product could move across) the nearest integer is the index; there the text is formatted.
    ``TrackManage._manage``'s most common reason (≈ 17 a scan on negative_2)."""
    q = speed * 100.0
    i = int(q)
    f = q - i
    if f < 0.4999999 and texts:
        return texts[i]
    if f > 0.5000001 and texts:
        return texts[i + 1]
    return f"not in M: speed {speed:.2f}{tail}"


class TrackManage:
    """Mixin of :class:`dynslam2d.detect.tracker.Tracker`: management and the test of M (``_manage``, ``_dynamic``)."""

    def _manage(self, t: float, updated: set[int]) -> None:
        """Track management (M of N, deletions, clutter retirement) and the test of M (paper Eq. 3) of the updated
        tracks. The counter tests (M of N, coasting, the covariance and speed deletions) run on the counter table's
        columns in one kernel call with the covariance test, the speed's σ and the speed of all live tracks from their
        state rows (``manage_counters``; the speeds are Python's ``math.hypot`` to the last bit; docs/speed.md pass
        cnt36): what stays per track in Python is what reads a track's objects — the coasting memory, the merged and
        hidden tests of a track without detection, clutter retirement and the test of M, inline up to its common
        outcomes (tentative, not in M and at most v_min, or in M and moving on: pass trk43) with the scan's constants
        read once, the rest in :meth:`_dynamic`; the most common reason is looked up (:func:`_slow_reason`; pass
        mgr34). ``updated``: the ids of the tracks updated in this scan (their counter rows flagged by the update
        kernel, ``C_UPD``)."""
        tracks = self._tracks
        if not tracks:
            self._firm_updated = ([], 0)
            return
        tc = self.config.tracker
        st = self.stats
        keep: list[_Track] = []
        firm: list[_Track] = []  # the kept updated tracks that are confirmed, in their order (fragments' hosts)
        gone: list[int] = []  # the rows of the tracks deleted or retired here, in their order (births reuse them)
        mem = self.config.memory.enabled
        merged = self._merged
        v_min = tc.v_min
        retire_n = tc.structure_retire_updates if self._map is not None else 0
        # (the test of M's constants, the same products as in _dynamic)
        max_ssig, v_exit, nsus = tc.max_speed_sigma, tc.v_exit_ratio * tc.v_min, tc.sustain_updates
        npu = tc.person_sustain_updates
        probe = self._free is not None
        # (_dynamic's first test of a track in M, the structure exit, with the scan's constants: pass trk43; its
        # window mean in the kernel, manage_scan's AUX_EXIT)
        on_map = self._map is not None
        order = self._rows()
        # per track: the counter tests' outcome (MC_*, the new states and counts written into the counter table), σ of
        # its speed along the velocity and its speed (Python's math.hypot bit for bit, as the reasons print it), from
        # its rows in one kernel call
        # (the configuration's values: the tracker's one array, update_params)
        # (and the riding pre-test of each updated track's window (0: fewer than ride_updates entries, it cannot ride;
        # 1: its last laser-frame centre farther than ride_max_range; 2: near), decided when the window was pushed
        # (kernels.shape_update; a track not updated in this scan has its last push's, never read), read from its row
        # in the same call: pass trk41)
        MEV, WN = self._MEV, self._WN
        # (and, in the same call, three values the loop below tested per track in Python, as bits of ``auxs``: the
        # structure exit's window mean, clutter retirement's window minimum and the slow reason's text index:
        # manage_scan, pass upd91)
        # (made by the association's call when it ran, on the same rows at the same t: nothing in Python between
        # writes the rows it reads; pass trk117)
        man, self._managed = self._managed, None
        codes, sigs, speeds, auxs = man if man is not None else \
            manage_scan(self._P, self._X, self._CI, self._CL, WN, MEV, order, self._upd_p, t)
        codes, sigs, speeds, auxs = codes.tolist(), sigs.tolist(), speeds.tolist(), auxs.tolist()
        fast_reasons = self._fast_reasons
        if len(fast_reasons) != nsus:
            fast_reasons = self._fast_reasons = _fast_reason_texts(nsus)
        # (the most common reason's texts and constant part, made again only for another v_min object: pass trk41)
        slow_v, slow_texts, slow_tail = self._slow_reasons
        if slow_v is not v_min:
            slow_texts = _slow_reason_texts(v_min)
            slow_tail = f" m/s ≤ v_min {v_min:.2f}"
            self._slow_reasons = (v_min, slow_texts, slow_tail)
        no_beams = _NO_BEAMS
        for k, code, speed, sig, aux in zip(tracks, codes, speeds, sigs, auxs):
            if code <= MC_UPD_FIRM:  # updated, kept by the counter tests (tentative: MC_UPD_TENTATIVE)
                # (AUX_RETIRE: structure_retire_updates window entries or more, the last that many each at least
                # structure_retire_fraction, min(MEV[k.row, nm - retire_n:nm, 0].tolist()) >= retire_s; manage_scan)
                if retire_n and aux & AUX_RETIRE and speed < v_min and not k.was_in_m and not k.remembered:
                    # clutter retirement: a still track the map already holds as structure (docs/real.md "Speed");
                    # a confirmed one stays as a dormant track while its object is seen (_clutter_detections)
                    st.deleted_structure += 1
                    if code == MC_UPD_TENTATIVE:
                        st.tracks_deleted += 1
                    else:
                        self._retire(k)
                    gone.append(k.row)
                    continue
                # paper Eq. 3 with persistence, certainty and displacement conditions (the start of _dynamic, inline)
                if speed > v_min and sig < max_ssig:
                    k.fast = kfast = k.fast + 1
                else:
                    k.fast = kfast = 0
                if speed < v_exit:
                    if k.slow_since is None:
                        k.slow_since = t
                elif k.remembered and kfast < nsus:
                    pass  # a remembered stop ends only on M's sustained fast test, not on one scan of speed jitter
                else:
                    k.slow_since = None
                in_m = k.in_m
                if in_m and k.probation and probe and len(k.free) >= nsus and self._probation_fails(k):
                    pass  # left M
                else:
                    # (near 0: fewer than ride_updates entries, it cannot ride; 1: far from the laser,
                    # _rides_with_laser's first test done (most tracks); 2: the whole test)
                    near = aux & AUX_NEAR
                    if near == 1:
                        k.rode = False
                    if near > 1 and self._rides_with_laser(k):
                        k.in_m = False
                        k.fast = 0
                        k._reason = "not in M: fixed in the laser frame while the laser moves (the robot's own body)"
                    elif in_m and k.slow_since is None and (k.was_in_m or k.person_streak < npu or not on_map) \
                            and not (on_map and aux & AUX_EXIT):
                        # (_dynamic's outcome for a track in M that is not slow and not leaving M on structure, whose
                        # person test asks no map (seen moving before, no map, or no person test: person_streak below
                        # person_sustain_updates; _person_moved_in's "kinematic", which changes nothing): the most
                        # common outcome of a track in M, inline with its memory bookkeeping; the same floats: the
                        # window's sum in its order, np.hypot's text of the same differences (passes trk43, trk87))
                        k.remembered = False  # moving again
                        x = k.x
                        x0, x1 = x.item(0), x.item(1)
                        bxy = k.birth_xy
                        # (its reason's floats, formatted when read: tracktable.moved_reason, pass trk136)
                        k._reason = (speed, x0 - bxy.item(0), x1 - bxy.item(1))
                        if mem:  # (_memory_bookkeeping of a track in M, inline)
                            if (sxy := k.m_start_xy) is None:
                                k.m_start_xy = sxy = (x0, x1)
                            elif (lt := k.m_last_t) is not None:
                                k.m_time += t - lt
                            k.m_last_t = t
                            k.m_travel = max(k.m_travel, math.hypot(x0 - sxy[0], x1 - sxy[1]))
                        keep.append(k)
                        if code == MC_UPD_FIRM:
                            firm.append(k)
                        continue
                    elif in_m:
                        self._dynamic(k, speed, sig, t)
                    elif code == MC_UPD_TENTATIVE:
                        # (speed: most tracks are short-lived tentative clutter; nothing else changes them)
                        k._reason = "not in M: tentative track"
                    elif speed <= v_min:
                        # (the most common reason: looked up by the speed in hundredths, its text's index + 1 from
                        # the kernel, 0 where _slow_reason formats it: near a rounding tie; manage_scan)
                        k._reason = slow_texts[si - 1] if (si := aux >> AUX_SLOW_SHIFT) and slow_texts \
                            else f"not in M: speed {speed:.2f}{slow_tail}"
                    elif kfast < nsus and sig < max_ssig and k.person_streak < npu:
                        # (_dynamic's outcome for a track not in M, faster than v_min with a certain velocity, not yet
                        # for sustain_updates updates and no person test (person_streak below person_sustain_updates):
                        # the second most common reason, inline; its tests before this one do not apply)
                        k._reason = fast_reasons[kfast]  # (0 ≤ kfast < nsus here)
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
                if code == MC_UPD_FIRM:
                    firm.append(k)
                continue
            if code < MC_UPDATED:  # without detection (the counters' tests done by the kernel, the deletions below)
                if merged and k.in_m and k.id in merged:  # (merged: empty in most scans)
                    k.in_m = False
                    k.merged = True
                    k.fast = 0
                    k._reason = \
                        "left M: merged with long-occupied map structure (its detection joined a wall's cluster)"
                if k.in_m and not k.remembered and k.slow_since is not None and mem and self._hidden(k):
                    # stopped in M and hidden (something in front of it) before m_exit_time: it cannot finish its
                    # stop while unseen, so it is remembered now (if eligible) instead of being deleted after
                    # max_coast_time (a track that just vanishes in plain view, a false one, is not)
                    self._remember(k, t - k.slow_since)
                k.beams = no_beams
                if code >= MC_COAST:  # coasted longer than max_coast_time (was confirmed or coasting)
                    if not (k.remembered and self._remembered_coasts(k, t)):
                        st.deleted_coasting += 1
                        st.tracks_deleted += 1
                        gone.append(k.row)
                        continue
                    code -= MC_COAST
                if code == MC_KEPT:
                    keep.append(k)
                    continue
            # deleted by the counter tests
            code &= ~MC_UPDATED
            if code == MC_DEL_TENTATIVE:
                st.deleted_tentative += 1
            elif code == MC_DEL_COVARIANCE:
                st.deleted_covariance += 1
            else:
                st.deleted_speed += 1
            st.tracks_deleted += 1
            gone.append(k.row)
        if gone:
            self._free_rows.extend(gone)
            self._order = None
        self._tracks = keep
        self._firm_updated = (firm, len(keep))

    # (the updated confirmed tracks the last _manage kept, in their order, and the number of tracks it kept: the
    # candidate hosts of fragments, Tracker._hosts_of_fragments)
    _firm_updated: tuple[list[_Track], int] = ([], 0)

    # (manage_scan's four outputs for this scan's live tracks when Tracker._associate_update's kernel made them, else
    # None: _manage calls it)
    _managed: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    # (_fast_reason_texts(sustain_updates): the tracker's own from its first _manage on)
    _fast_reasons: tuple[str, ...] = ()
    # (v_min, _slow_reason_texts(v_min) and the reasons' tail: the tracker's own from its first _manage on)
    _slow_reasons: tuple[float, tuple[str, ...], str] = (math.nan, (), "")

    def _probation_fails(self, k: _Track) -> bool:
        """End the probation of ``k`` (in M, re-acquired after a gap, with ``sustain_updates`` free-space fractions):
        it leaves M (True) when they show no motion into free space."""
        k.probation = False
        free = self._free_values(k)
        if sum(free) / len(free) < self.config.tracker.free_min_fraction:
            k.in_m = False
            k.fast = 0
            k._reason = "left M: after a gap the detections show no motion into free space (a different, static object)"
            return True
        return False

    def _dynamic(self, k: _Track, speed: float, sig: float, t: float) -> None:
        """Paper Eq. 3 with persistence, certainty and displacement conditions: the rest of the test that
        :meth:`_manage` starts (speed persistence ``k.fast``, slow time, probation and the riding test done there)
        for an updated track in M, or confirmed / coasting with ``speed`` (m/s) > v_min; ``sig``: σ of the speed
        along the velocity, m/s."""
        tc = self.config.tracker
        # the map evidence's columns as lists (the same floats in the same order: the same sums)
        mev = self._mev(k)  # ((n, 3) rows of the window; its columns as Python floats: the former lists' sums)
        ms = mev[:, 0].tolist()
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
            k._reason = (f"left M: {sum(ms) / len(ms):.2f} of its points on long-occupied map cells "
                        "(structure)")
            return
        if k.in_m and have_map and k.slow_since is not None and t - k.slow_since >= tc.map_structure_stop_time \
                and len(ms) >= 2 and \
                0.5 * (ms[-1] + ms[-2]) >= tc.map_structure_stop:
            # a mover that stops where the map has long-standing structure has merged with it (a person
            # reaching a wall): hysteresis would carry M onto the wall
            k.in_m = False
            k.fast = 0
            k._reason = "left M: slowed down on long-occupied map cells (merged with structure)"
            return
        if k.in_m:
            slow_for = 0.0 if k.slow_since is None else t - k.slow_since
            if k.slow_since is not None and slow_for >= tc.m_exit_time and self._remember(k, slow_for):
                pass  # stopped, stays in M (track memory; the reason says why)
            elif k.slow_since is not None and slow_for >= tc.m_exit_time:
                k.in_m = False
                k.remembered = False
                k._reason = (f"left M: speed {speed:.2f} m/s below {tc.v_exit_ratio * tc.v_min:.2f} for "
                            f"{slow_for:.1f} s")
            elif k.slow_since is not None:
                k._reason = f"in M (hysteresis): slow ({speed:.2f} m/s) for {slow_for:.1f} s"
            else:
                k.remembered = False  # moving again
                x, bxy = k.x, k.birth_xy
                k._reason = (speed, x.item(0) - bxy.item(0), x.item(1) - bxy.item(1))  # (tracktable.moved_reason)
            return
        if k.state == TENTATIVE:
            k._reason = "not in M: tentative track"
        elif speed <= tc.v_min:
            k._reason = f"not in M: speed {speed:.2f} m/s ≤ v_min {tc.v_min:.2f}"  # (the most common reason)
        elif sig >= tc.max_speed_sigma:
            k._reason = f"not in M: velocity uncertain (σ {sig:.2f} m/s)"
        elif k.fast < need:
            k._reason = f"not in M: speed > v_min for {k.fast}/{need} updates"
        elif (net := self._net_speed(k, need)) is not None and net < tc.net_speed_ratio * tc.v_min:
            k._reason = (f"not in M: net speed over the last {need} updates {net:.2f} m/s < "
                        f"{tc.net_speed_ratio * tc.v_min:.2f} (jitter, not motion)")
        elif (disp := float(np.hypot(k.x[0] - k.birth_xy[0], k.x[1] - k.birth_xy[1]))) < (
                min_disp := tc.person_min_displacement if person_way == "map" else tc.min_displacement):
            # (the net displacement since birth is computed only here: most tracks stop at a test above)
            k._reason = f"not in M: moved {disp:.2f} m < {min_disp:.2f} m since birth"
        elif self._free is not None and (not (fr := self._free_values(k)) or sum(fr) / len(fr) < tc.free_min_fraction):
            k._reason = (f"not in M: points on free space {sum(fr) / max(len(fr), 1):.2f} < "
                        f"{tc.free_min_fraction:.2f} (static structure)")
        elif use_map and not fast_person and sum(mf := mev[:, 1].tolist()) / len(mf) < tc.map_free_min and not (
                self._is_still() and sum(mu := mev[:, 2].tolist()) / len(mu) >= 1.0 - tc.map_free_min):
            k._reason = (f"not in M: points in observed-free map cells {sum(mf) / len(mf):.2f} < "
                        f"{tc.map_free_min:.2f} (no map evidence of motion)")
        elif use_map and sum(ms) / len(ms) > tc.map_structure_max:
            k._reason = (f"not in M: points on long-occupied map cells {sum(ms) / len(ms):.2f} > "
                        f"{tc.map_structure_max:.2f} (structure)")
        else:
            k.in_m = True
            k.was_in_m = True
            k._reason = (f"in M: speed {speed:.2f} m/s > v_min for {k.fast} updates, moved {disp:.2f} m "
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
        last = self._mev(k)[-n:]
        mf = last[:, 1].tolist()
        if sum(mf) / len(mf) >= tc.person_map_free_min:
            return "map"
        fr, ms, mu = self._free_values(k)[-n:], last[:, 0].tolist(), last[:, 2].tolist()
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
        self._maybe_remembered = True  # (the prediction looks for remembered tracks again: Tracker._predict)
        k._reason = (f"in M (remembered): stopped for {slow_for:.1f} s after moving {k.m_travel:.2f} m in M "
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

    def _net_speed(self, k: _Track, n: int) -> float | None:
        """Net displacement of the track's centre over its last ``n`` updates divided by their time span, m/s
        (None with fewer updates): pose jitter and association noise give a speed but no net motion."""
        ride = self._ride(k)
        if ride.shape[0] < max(n, 2):
            return None
        (x0, y0, t0), (x1, y1, t1) = ride[-n, 2:].tolist(), ride[-1, 2:].tolist()
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
        # (the window's tests and its spread and motion in one kernel call: the former NumPy forms' floats;
        # docs/speed.md, pass mgr32)
        body = self._body_near
        outcome, spread, moved = ride_window(self._RIDE, self._WN, k.row, k.beams,
                                             _NO_BODY if body is None else body, body is not None,
                                             int(tc.ride_updates), float(tc.ride_max_range), float(tc.ride_time))
        if outcome != RIDE_JUDGE:
            if outcome == RIDE_FAR or outcome == RIDE_OFF_BODY:
                k.rode = False  # far from the laser (most tracks), or not where the robot's body was found
            return False
        # with a motionless laser the two frames agree: only motion far beyond the laser-frame spread rides;
        # once found riding, a track keeps riding until its laser-frame spread clearly exceeds the tolerance
        # (a circle fit replacing a rectangle shifts the centre of a body part by a few cm)
        tol = 3.0 * tc.ride_tolerance if k.rode else tc.ride_tolerance
        k.rode = spread < tol and (k.rode or moved > max(tc.ride_tolerance, 4.0 * spread))
        return k.rode
