"""The management step's faster per-track loop (issue 13 speed, docs/speed.md passes mgr34, cnt36: the counter tests
on the counter table's columns in one kernel call) against the forms it replaced: the most common reason looked up
by the speed in hundredths instead of formatted (random speeds, ties, neighbours of the rounding boundaries, several
v_min), and ``TrackManage._manage``'s loop split into updated tracks
and tracks without detection against the former single loop (below, as it was) on every scan of simulated scenes
that reach its branches (M, memory, coasting and every deletion, clutter retirement); a birth's state and covariance
written through its rows' views."""

from __future__ import annotations

import copy
import math
import random

import numpy as np

import dynslam2d.detect.tracker as tracker_mod  # (_associate_update calls associate_update there)
from dynslam2d.config import Config
from dynslam2d.detect import kernels_assign as ka
from dynslam2d.detect import trackmanage
from dynslam2d.detect.kernels import manage_rows
from dynslam2d.detect.kernels_update import C_UPD
from dynslam2d.detect.trackmanage import _fast_reason_texts, _slow_reason, _slow_reason_texts
from dynslam2d.detect.tracktable import _NO_BEAMS, COASTING, CONFIRMED, TENTATIVE
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import simulate


def test_slow_reason_is_the_formatted_reason() -> None:
    """``_slow_reason`` gives ``f"not in M: speed {speed:.2f}{tail}"`` for every speed
    from 0 to v_min: random ones, the exact ties (k/8: 0.125 prints 0.12, 0.375 prints 0.38), the floats next to each
    half-hundredth and hundredth, and v_min itself; above _SLOW_TEXTS_MAX there is no table and it formats."""
    rng = random.Random(13)
    looked_up = 0
    for v_min in (0.3, 0.05, 0.125, 1.0, 0.999, 9.99, 10.0, 0.0):
        texts = _slow_reason_texts(v_min)
        tail = f" m/s ≤ v_min {v_min:.2f}"
        assert len(texts) == int(v_min * 100.0) + 2
        speeds = [rng.uniform(0.0, v_min) for _ in range(20000)] + [v_min, 0.0, 5e-324]
        speeds += [k / 8.0 for k in range(int(8 * v_min) + 1)]
        for i in range(int(200 * v_min) + 1):
            for x in (i / 200.0, (i + 0.5) / 200.0):
                speeds += [math.nextafter(x, -1.0), x, math.nextafter(x, 2.0 * v_min + 1.0)]
        for s in speeds:
            if 0.0 <= s <= v_min:
                assert _slow_reason(s, texts, tail) == f"not in M: speed {s:.2f}{tail}", (v_min, s)
                looked_up += 1
    assert looked_up > 150000
    assert _slow_reason_texts(10.5) == () and _slow_reason_texts(math.nan) == ()
    assert _slow_reason(3.14159, (), " m/s ≤ v_min 20.00") == "not in M: speed 3.14 m/s ≤ v_min 20.00"


def _former_manage(self, t: float, updated: set[int]) -> None:
    """``TrackManage._manage`` as it was before pass mgr34 (one loop over all tracks, the reason formatted)."""
    tracks = self._tracks
    if not tracks:
        return
    tc = self.config.tracker
    st = self.stats
    keep = []
    gone: list[int] = []
    mem = self.config.memory.enabled
    merged = self._merged
    window, need_hits = tc.confirm_window, tc.confirm_hits
    max_coast, max_sig, max_speed = tc.max_coast_time, tc.max_position_sigma, tc.max_object_speed
    v_min = tc.v_min
    retire_n = tc.structure_retire_updates if self._map is not None else 0
    retire_s = tc.structure_retire_fraction
    max_ssig, v_exit, nsus = tc.max_speed_sigma, tc.v_exit_ratio * tc.v_min, tc.sustain_updates
    npu = tc.person_sustain_updates
    probe = self._free is not None
    slow_tail = f" m/s ≤ v_min {v_min:.2f}"
    order = self._rows()
    speeds = [math.hypot(self._X[k, 2], self._X[k, 3]) for k in order.tolist()]
    bads, sigs = manage_rows(self._P, self._X, order, np.array(speeds), max_sig)
    bads, sigs = bads.tolist(), sigs.tolist()
    nears = self._WN[:, 2].take(order).tolist()
    MEV, WN = self._MEV, self._WN
    fast_reasons = _fast_reason_texts(nsus)
    for k, speed, sig, bad, near in zip(tracks, speeds, sigs, bads, nears):
        kid = k.id
        is_upd = kid in updated
        if merged and kid in merged and not is_upd and k.in_m:  # (merged: empty in most scans)
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
        if is_upd and retire_n and not k.was_in_m and not k.remembered and (nm := WN.item(k.row, 0)) >= retire_n \
                and speed < v_min and min(MEV[k.row, nm - retire_n:nm, 0].tolist()) >= retire_s:
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
                if near:  # (0: fewer than ride_updates entries, it cannot ride)
                    if near == 1:
                        k.rode = False  # (_rides_with_laser's first test, done: most tracks are far from it)
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
                elif kfast < nsus and sig < max_ssig and k.person_streak < npu:
                    # (_dynamic's outcome for a track not in M, faster than v_min with a certain velocity, not yet
                    # for sustain_updates updates and no person test (person_streak below person_sustain_updates):
                    # the second most common reason, inline; its tests before this one do not apply)
                    k.reason = fast_reasons[kfast]  # (0 ≤ kfast < nsus here)
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


def _track_state(tr) -> list:
    """Every field of every live and dormant track that management writes or reads, the stats, the freed rows."""
    out = []
    for k in tr._tracks + tr._dormant:
        out.append((k.id, k.state, k.hits, k.misses, k.hist_n, k.hist_hits, k.fast, k.in_m, k.reason, k.beams.tolist(),
                    k.rode, k.was_in_m, k.slow_since, k.probation, k.merged, k.remembered, k.m_start_xy, k.m_time,
                    k.m_travel, k.m_last_t, k.row, k.x.tolist(), k.P.tolist(), k.last_hit, k.person_streak))
    return [out, tr.stats.as_dict(), list(tr._free_rows), tr._order is None, tr._maybe_remembered]


def _run_both(cfg: Config, scans) -> dict[str, int]:
    """Run the pipeline over ``scans``; at every management step, the former loop on a deep copy of the tracker and
    the tracker's own ``_manage`` on the tracker, their results compared; returns the branches reached (counts)."""
    pipe = Pipeline(cfg)
    tr = pipe.tracker
    own = tr._manage
    seen = {"steps": 0, "upd_slow": 0, "upd_fast": 0, "in_m": 0, "coasting": 0, "remembered": 0, "in_m_moving": 0,
            "in_m_tracked": 0, "left_on_structure": 0, "in_m_moving_person": 0}

    # (pass trk117: the association's call runs manage_scan, which writes the counter rows, before _manage; the former
    # loop needs them as they were before it: the fused kernel's Python runs, its manage_scan through a wrapper that
    # keeps copies of CI and CL as it receives them)
    pre: list = []

    def manage_scan(P, X, CI, CL, *a):  # noqa: ANN001, ANN202
        pre[:] = [CI.copy(), CL.copy()]
        return kernel_manage(P, X, CI, CL, *a)

    def both(t, updated):
        ref = copy.deepcopy(tr, {id(tr._map): tr._map, id(tr._scan): tr._scan})
        if tr._managed is not None:
            ref._CI[:] = pre[0]
            ref._CL[:] = pre[1]
            seen["fused"] = seen.get("fused", 0) + 1
        pre.clear()
        _former_manage(ref, t, set(updated))
        before = tr.stats.as_dict()
        own(t, updated)
        assert _track_state(ref) == _track_state(tr)
        # (pass cnt36: the counter tests run on the counter table's columns in manage_counters; the updated flags it
        # read are cleared, and the kept updated confirmed tracks it hands to _hosts_of_fragments are those)
        assert not tr._CI[tr._rows(), C_UPD].any()
        firm, n = tr._firm_updated
        assert n == len(tr._tracks)
        assert firm == [k for k in tr._tracks if k.id in updated and k.state == CONFIRMED]
        seen["firm"] = seen.get("firm", 0) + len(firm)
        seen["steps"] += 1
        for k in tr._tracks:
            seen["in_m"] += k.in_m
            seen["coasting"] += k.state == COASTING
            seen["remembered"] += k.remembered
            seen["upd_slow"] += k.id in updated and k.reason.endswith(f"≤ v_min {cfg.detect.tracker.v_min:.2f}")
            seen["upd_fast"] += k.id in updated and k.reason.startswith("not in M: speed > v_min for")
            # (pass trk43: _dynamic's outcome for a moving track in M, inline, with its memory bookkeeping; and the
            # tracks in M that left it on structure instead)
            seen["in_m_moving"] += k.id in updated and k.in_m and k.reason.startswith("in M: speed")
            seen["in_m_tracked"] += k.id in updated and k.in_m and k.m_last_t == t
            seen["in_m_moving_person"] += k.id in updated and k.in_m and k.reason.startswith("in M: speed") and \
                k.person_streak >= cfg.detect.tracker.person_sustain_updates
            seen["left_on_structure"] += k.reason.endswith("of its points on long-occupied map cells (structure)")
        for key, v in tr.stats.as_dict().items():
            if key.startswith("deleted_"):
                seen[key] = seen.get(key, 0) + v - before[key]

    tr._manage = both
    kernel_manage, fused = ka.manage_scan, tracker_mod.associate_update
    ka.manage_scan, tracker_mod.associate_update = manage_scan, fused.py_func
    try:
        for s in scans:
            pipe.process(s)
    finally:
        ka.manage_scan, tracker_mod.associate_update = kernel_manage, fused
    return seen


def test_manage_is_the_former_single_loop_on_simulated_scenes() -> None:
    """On every scan of sim:stop-and-go (its stops: memory, M exits) and of sim:crowd with clutter retirement on
    (dormant tracks), the management step leaves every track, the stats and the freed rows as the former loop did;
    the scenes reach M, memory, coasting, the slow and fast reasons and the tentative, coasting and structure
    deletions."""
    seen = _run_both(Config(), simulate("stop-and-go", duration=40.0).scans)
    cfg = Config()
    cfg.detect.tracker.structure_retire_updates = 2
    cfg.detect.tracker.structure_birth_min = 0.5
    seen2 = _run_both(cfg, simulate("crowd", duration=30.0).scans)
    total = {k: seen.get(k, 0) + seen2.get(k, 0) for k in set(seen) | set(seen2)}
    for key in ("steps", "upd_slow", "upd_fast", "in_m", "coasting", "remembered", "deleted_tentative",
                "deleted_coasting", "deleted_structure", "firm", "in_m_moving", "in_m_tracked",
                "in_m_moving_person", "fused"):
        assert total[key] > 0, (key, total)
    assert trackmanage._SLOW_TEXTS_MAX >= 1.0


def test_manage_is_the_former_single_loop_where_tracks_in_m_leave_it_on_structure() -> None:
    """With ``map_structure_exit`` 0 every track in M with a full map-evidence window leaves it on long-occupied map
    cells (``_dynamic``'s first test), which the management step's inline outcome of a moving track in M must leave
    to ``_dynamic`` (pass trk43): every scan of sim:stop-and-go as the former loop left it."""
    cfg = Config()
    cfg.detect.tracker.map_structure_exit = 0.0  # (every track in M with a full window: its mean is ≥ 0)
    seen = _run_both(cfg, simulate("stop-and-go", duration=25.0).scans)
    assert seen["left_on_structure"] > 0, seen


def test_birth_writes_the_birth_state_into_its_rows() -> None:
    """Every birth of sim:crowd (a scan's births in one batch, ``_births``, pass trk38) writes ``_birth_state``'s
    centre (zero velocity) and covariance into the new track's rows of the state arrays, bit for bit, and the
    track's views ``k.x`` / ``k.P`` are those rows."""
    pipe = Pipeline(Config())
    tr = pipe.tracker
    own = tr._births
    births = 0

    def checked(dets, t, js, updated):
        nonlocal births
        states = [tr._birth_state(dets[j], j)[:2] for j in js]
        own(dets, t, js, updated)
        for k, (z, P) in zip(tr._tracks[len(tr._tracks) - len(js):], states):
            assert tr._X[k.row].tobytes() == np.array([z[0], z[1], 0.0, 0.0]).tobytes()
            assert tr._P[k.row].tobytes() == P.tobytes()
            # (views of those rows: of the row tables' buffer since pass trk129)
            assert np.shares_memory(k.x, tr._X[k.row]) and np.shares_memory(k.P, tr._P[k.row])
            assert k.id in updated
            births += 1

    tr._births = checked
    for s in simulate("crowd", duration=10.0).scans:
        pipe.process(s)
    assert births >= 10
