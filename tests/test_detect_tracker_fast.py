"""The tracker's faster per-track loops (issue 9 speed) against the plain computations they replace: the
vacated-space search (the stored scan whose age is nearest each free-space reference age) on random stamp
lists and on a simulated box driving away from the laser; the free-space entries and the detections' free-space
fractions computed when read."""

from __future__ import annotations

import bisect
import math
import random

import numpy as np
from conftest import room_box_scan

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.freespace import FreeTest
from dynslam2d.detect.kernels import segment_means
from dynslam2d.detect.kernels_assign import veto_merged
from dynslam2d.detect.layout import F_CENTROID_X, F_CENTROID_Y, N_FIT_COLS
from dynslam2d.detect.tracker import _nearest_age, _past_points
from dynslam2d.types import Pose2D, Scan

N = 360


def _window_argmin(stamps: list[float], t: float, a: float) -> int:
    """The search as first written: np.argmin of |age − a| over the six entries around the insertion point."""
    ins = bisect.bisect_left(stamps, t - a)
    lo, hi = max(ins - 3, 0), min(ins + 3, len(stamps))
    dev = np.abs((t - np.asarray(stamps[lo:hi])) - a)
    return -1 if np.isnan(dev).all() else lo + int(np.nanargmin(dev))


def test_nearest_age_is_the_window_argmin_on_random_stamp_lists() -> None:
    """Scan periods of 0.03-0.5 s, repeated stamps (dt = 0), stamps 1e-7 s apart, epoch-sized stamps and ages
    before / inside / after the stored span: always the same entry as the six-wide argmin, first one on ties."""
    rng = random.Random(7)
    ties = 0
    for _ in range(20000):
        base = rng.choice([0.0, 1000.0, 1.3e9])
        stamps, x = [], base
        for _ in range(rng.randint(1, 25)):
            x += rng.choice([0.0, 0.0, 1e-7, 0.033, 0.0667, 0.1, 0.3, 0.5])
            stamps.append(x)
        t = x + rng.choice([0.0, 0.03, 0.0667, 0.3, 0.8, 3.0])
        for a in (0.3, 0.8, rng.random()):
            j = _nearest_age(stamps, len(stamps), t, a)
            assert j == _window_argmin(stamps, t, a), (stamps, t, a)
            ties += j + 1 < len(stamps) and stamps[j + 1] == stamps[j]
    assert ties > 100  # repeated stamps were exercised: the first of equal entries is taken
    assert _nearest_age([1.0, 2.0], 2, math.nan, 0.3) == -1  # nothing comparable


def _scan(pose: Pose2D, box_x: float, stamp: float, seed: int) -> Scan:
    return room_box_scan(pose, (box_x, 0.0, 0.6, 0.6), stamp, seed, N)


def _vacated_reference(tr: Tracker, t: float) -> dict[int, float]:
    """The vacated space of every track with the plain window argmin and one batched test (the code before the
    faster search and the one-track path, Tracker._vacated_one)."""
    chunks, owners, counts = [], [], [0]
    for k in tr._tracks:
        for a in tr._free.ref_ages:
            live = k.past[k.past_a:]  # (append-only: the live entries from past_a on)
            if not live:
                continue
            stamps = [e[0] for e in live]
            j = _window_argmin(stamps, t, a)
            if t - stamps[j] > 0.0:
                chunks.append(_past_points(live[j]))
                owners.append(k.id)
                counts.append(_past_points(live[j]).shape[0])
    out: dict[int, float] = {}
    if chunks:
        pts = np.concatenate(chunks)
        free = np.zeros(pts.shape[0], dtype=bool)
        FreeTest((tr._cur_ref,), tr._free.margin).count(pts, free)  # (the runtime test, this scan's reference)
        for tid, f in zip(owners, segment_means(free.astype(np.float64), np.cumsum(counts)).tolist()):
            out[tid] = max(out.get(tid, 0.0), f)
    return out


def test_vacated_space_of_a_receding_box_matches_the_plain_search() -> None:
    """A box driving straight away from the laser at 1.2 m/s: the laser sees through where its face was (the
    vacated fraction is high), and the faster search picks the same stored scans as the plain one every step."""
    tr = Tracker(DetectConfig())
    pose = Pose2D(-5.0, 0.0, 0.0)
    checked, high = 0, 0
    for i in range(45):
        t = i / 15.0
        tr.update(_scan(pose, -3.5 + 1.2 * t, t, i), pose)
        if i >= 10:
            want = _vacated_reference(tr, t)
            got = {k.id: tr._vacated_one(tr._cur_ref, t, tuple(k.past[k.past_a:])) for k in tr._tracks
                   if len(k.past) > k.past_a}
            assert got == {tid: want.get(tid, 0.0) for tid in got}
            checked += len(want)
            high += any(v > 0.5 for v in got.values())
    assert checked >= 30 and high >= 20  # the box's track had vacated space at almost every step


def _leg_pairs_numpy(lohi: np.ndarray, npts: np.ndarray, cen: np.ndarray, lmax: float, dmax: float) -> list:
    """The leg pairing as first written with numpy (Tracker._merge_legs before the kernel)."""
    ext = np.maximum(lohi[:, 2] - lohi[:, 0], lohi[:, 3] - lohi[:, 1])
    sel = np.flatnonzero((npts >= 2) & (ext <= lmax))
    if sel.shape[0] < 2:
        return []
    small = sel.tolist()
    c = cen[sel]
    d2 = np.hypot(c[:, None, 0] - c[None, :, 0], c[:, None, 1] - c[None, :, 1])
    np.fill_diagonal(d2, np.inf)
    dflat = d2.ravel()
    cand = np.flatnonzero(dflat <= dmax)
    pairs, used = [], set()
    for flat in cand[np.argsort(dflat[cand], kind="stable")].tolist():
        a, b = divmod(flat, len(small))
        if a in used or b in used or a > b:
            continue
        used.update((a, b))
        pairs.append((small[a], small[b]))
    return pairs


def test_leg_pairs_kernel_matches_the_numpy_pairing() -> None:
    """leg_pairs against the numpy pairing it replaced on random scenes of legs, walls and clutter, with centres
    anywhere (numba's np.hypot is libm's, as numpy's) or on a coarse grid (equal distances: the stable order
    decides), and NaN extents."""
    from dynslam2d.detect.kernels import leg_pairs

    rng = np.random.default_rng(5)
    merged = 0
    for _ in range(2000):
        m = int(rng.integers(0, 25))
        lo = rng.uniform(-5, 5, (m, 2))
        ext = rng.choice([0.05, 0.1, 0.2, 0.3, 1.5], (m, 2))
        lohi = np.column_stack((lo, lo + ext))
        if m and rng.random() < 0.1:
            lohi[rng.integers(m), rng.integers(4)] = np.nan
        npts = rng.integers(1, 12, m)
        cen = rng.uniform(-2, 2, (m, 2))
        if rng.random() < 0.5:
            cen = np.round(cen * 5) / 5  # (a 0.2 m grid: equal distances, the order decides)
        want = _leg_pairs_numpy(lohi, npts, cen, 0.25, 0.5)
        fits = np.zeros((m, N_FIT_COLS))
        fits[:, F_CENTROID_X], fits[:, F_CENTROID_Y] = cen[:, 0], cen[:, 1]
        a, b = leg_pairs(lohi, npts, fits, 0.25, 0.5)
        assert list(zip(a.tolist(), b.tolist())) == want
        merged += len(want)
    assert merged > 500


def test_size_jump_gate_and_accel_candidates_match_numpy() -> None:
    """The association's size-jump gate and the acceleration bound's candidate rows against the numpy
    expressions they replaced (NaN extents and sizes included)."""
    from dynslam2d.detect.kernels import accel_candidates, size_jump_gate

    rng = np.random.default_rng(3)
    for _ in range(500):
        n, m = int(rng.integers(1, 30)), int(rng.integers(1, 30))
        ok = rng.random((n, m)) < 0.7
        lohi = rng.uniform(-1, 1, (m, 4))
        lohi[:, 2:] = lohi[:, :2] + rng.choice([0.0, 0.1, 0.5, 3.0], (m, 2))
        tmax = rng.choice([0.05, 0.3, 1.0, np.nan], n)
        known = rng.random(n) < 0.5
        det_ext = np.maximum(lohi[:, 2] - lohi[:, 0], lohi[:, 3] - lohi[:, 1])
        want = ok & ((det_ext[None, :] <= 2.0 * tmax[:, None] + 0.3) | ~known[:, None])
        got, ext = size_jump_gate(ok, lohi, tmax, known, 2.0, 0.3)
        assert np.array_equal(got, want) and ext.tobytes() == det_ext.tobytes()
        Xp, Xn = rng.normal(size=(n, 4)), rng.normal(size=(n, 4))
        lim2 = (0.999 * float(rng.uniform(0.1, 2.0))) ** 2
        dvx, dvy = Xn[:, 2] - Xp[:, 2], Xn[:, 3] - Xp[:, 3]
        assert accel_candidates(Xp, Xn, lim2).tolist() == np.flatnonzero(dvx * dvx + dvy * dvy > lim2).tolist()


def test_scan_detections_read_the_rows_of_their_scans_fit_arrays() -> None:
    """The tracker's per-cluster detections (ScanDetection) give the centroid, bounds, real-bound flags and circle of
    their row of the scan's fit arrays — the values a Detection built with those rows holds — and copy to a plain
    Detection with the same fields. Checked on a simulated box seen from a moving laser: every detection's centroid
    is the mean of its own points, and its bounds are ordered."""
    import copy
    import dataclasses
    import pickle

    from dynslam2d.detect.measure import Detection, ScanArrays, ScanDetection

    tr = Tracker(DetectConfig())
    seen = 0
    for i in range(20):
        pose = Pose2D(0.02 * i, -2.0, 0.01 * i)
        tr.update(_scan(pose, -1.0 + 0.05 * i, i / 15.0, i), pose)
        for det in tr.last_detections:
            if det.person:
                continue  # (a merged pair of legs: its centroid is the legs' middle, not its points' mean)
            assert isinstance(det, ScanDetection)
            seen += 1
            pts = det.points
            assert det.n_points == pts.shape[0] == det.beams.shape[0]
            assert np.allclose(det.centroid, pts.mean(axis=0), rtol=0.0, atol=1e-12)
            assert (det.lo <= det.hi).all() and det.extent.tolist() == (det.hi - det.lo).tolist()
            assert det.rel.shape == (2, 2) and det.rel.dtype == bool and det.circle.shape == (3,)
            for c in (copy.deepcopy(det), pickle.loads(pickle.dumps(det))):
                assert type(c) is Detection
                for f in dataclasses.fields(Detection):
                    assert np.array_equal(getattr(c, f.name), getattr(det, f.name)), f.name
    assert seen >= 20
    fits = np.arange(2 * N_FIT_COLS, dtype=np.float64).reshape(2, N_FIT_COLS)
    lohi = np.array([[0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 7.0]])
    rel = np.array([[[True, False], [False, True]], [[False, False], [True, True]]])
    mev = np.array([[0.0, 0.2], [0.0, 0.3], [0.0, 0.4]])
    s = ScanArrays(np.arange(3), np.zeros((3, 2)), 0, np.array([0, 1]), np.array([1, 2]),
                   np.array([2, 2], dtype=np.int8), fits, lohi, rel, mev)
    d = ScanDetection(s, 1, 0.1)
    assert d.centroid.tolist() == [fits[1, F_CENTROID_X], fits[1, F_CENTROID_Y]]
    assert d.lo.tolist() == [4.0, 5.0] and d.hi.tolist() == [6.0, 7.0] and d.rel.tolist() == rel[1].tolist()
    assert d.extent.tolist() == [2.0, 2.0] and d.person is False and d.map_unknown == 0.4
    assert d.theta == fits[1, 0] and d.map_structure == 0.2 and d.free_fraction == 0.1


def test_free_space_entries_read_late_hold_the_vacated_fraction_of_their_scan() -> None:
    """A track's free-space history gets the vacated-space part of an update's entry only when the entry is read
    (Tracker._free_values): on a box driving away from the laser, hidden twice for a few scans (re-acquisition
    clears the stored points), every entry read after the whole run equals what the update's own scan gave when it
    was computed at once: max(the detection's free fraction, the track's vacated space in that scan)."""
    expected: list[tuple[float | tuple, float]] = []

    class Eager(Tracker):
        def _update_tracks(self, applied, dets, t):
            vac = _vacated_reference(self, t)  # (this scan, before the update)
            super()._update_tracks(applied, dets, t)
            for ti, di, *_info in applied:  # (the pairs whose update applied: pass trk138)
                k = self._tracks[ti]
                expected.append((k.free[-1], max(dets[di].free_fraction, vac.get(k.id, 0.0))))

    tr = Eager(DetectConfig())
    pose = Pose2D(-5.0, 0.0, 0.0)
    for i in range(60):
        t = i / 15.0
        hidden = 20 <= i < 24 or 40 <= i < 43
        tr.update(_scan(pose, 100.0 if hidden else -3.5 + 1.0 * t, t, i), pose)
    lazy = [(e, want) for e, want in expected if type(e) is tuple]
    assert len(lazy) >= 40  # entries left to be read
    for entry, want in expected:
        assert tr._free_value(entry) == want
    assert sum(want > entry[0].free_fraction for entry, want in lazy) >= 20  # the vacated space decided those entries
    for k in tr._tracks:
        assert all(type(v) is float for v in tr._free_values(k))


def _track_rows(tracks: list) -> list[tuple]:
    return [(r.id, r.state, r.in_m, r.m_reason, r.box.px, r.box.py, r.box.theta, r.box.length, r.box.width,
             r.velocity.tolist(), r.hits, r.misses, r.kind) for r in tracks]


def test_detection_free_fractions_read_late_equal_the_test_of_their_scan() -> None:
    """A detection's free-space fraction is computed when first read (ScanDetection.free_fraction), after the tracker's
    free-space memory has gained later scans and dropped old ones: on a simulated crowd and on two people walking /
    standing on legs (merged into person detections) seen from a moving laser, every fraction read after the whole
    run equals the count over n of its points that a memory fed the same scans saw through at the detection's own
    scan, before gaining it (a merged pair of legs: the legs' fractions weighted by their point counts), and a
    tracker that reads every fraction at once reports the same tracks, scan by scan, as one that leaves them."""
    from test_detect_people import RATE, render, scene

    from dynslam2d.detect.freespace import FreeSpaceMemory
    from dynslam2d.sim import simulate

    sim = simulate("crowd", duration=4.0)
    runs = [list(zip(sim.scans, [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]))]
    legs = []
    for i in range(int(6.0 * RATE)):
        pose = Pose2D(0.2 * i / RATE, 0.0, 0.0)
        legs.append((render(pose, i / RATE, *scene(i / RATE, 2.0, 1.2), i)[0], pose))
    runs.append(legs)
    cfg = DetectConfig()

    class Forced(Tracker):
        def _detect(self, scan, pose):
            dets = super()._detect(scan, pose)
            for d in dets:
                d.free_fraction  # noqa: B018  (read at once)
            return dets

    class Lazy(Tracker):
        def _merge_legs(self, *args):
            out = super()._merge_legs(*args)
            self.legs.update({id(d): d._ff for d in out[0] if d.person})  # (the legs, merged away: not yet read)
            return out

    recorded: list[tuple] = []
    persons = 0
    for run in runs:
        shadow = FreeSpaceMemory(cfg.tracker.free_ref_ages, cfg.tracker.free_margin)

        def eager(points: np.ndarray, now: float, shadow: FreeSpaceMemory = shadow) -> float:
            return int(np.count_nonzero(shadow.seen_through(points, now))) / points.shape[0]

        lazy_tr, forced_tr = Lazy(cfg), Forced(cfg)
        for scan, pose in run:
            now = float(scan.stamp)
            lazy_tr.legs = {}
            rows = _track_rows(lazy_tr.update(scan, pose))
            assert rows == _track_rows(forced_tr.update(scan, pose))
            for d in lazy_tr.last_detections:
                if d.person:
                    da, db = lazy_tr.legs[id(d)]
                    na, nb = da.n_points, db.n_points
                    want = (na * eager(da.points, now) + nb * eager(db.points, now)) / (na + nb)
                    persons += 1
                else:
                    want = eager(d.points, now)
                recorded.append((d, want))
            shadow.add(scan, pose, scan.valid_mask() & (scan.ranges > 0.0))
    unread = sum(type(d._ff) is not float for d, _ in recorded)
    assert unread > 0.8 * len(recorded)  # most were never read during the run
    for d, want in recorded:
        assert d.free_fraction == want
    assert persons >= 40 and sum(w > 0.0 for _, w in recorded) >= 50  # merged legs and free space occurred


def test_free_entries_snapshot_the_stored_points_and_the_m_of_n_counts_follow_the_hits() -> None:
    """Pass trk16: an update's free-space entry refers to the track's stored points before it as (list, first, end)
    of the append-only ``_Track.past`` instead of a copy — it must hold the very entries (the same objects, in order)
    that were live before the update, also after later updates moved ``past_a``, started a new list or re-acquired
    the track after a gap; and the M-of-N counts ``hist_n`` / ``hist_hits`` must be the length and the hit count of
    the first ``confirm_window`` entries of the hit / miss sequence (the list they replace)."""
    cfg = DetectConfig()
    window = cfg.tracker.confirm_window
    tr = Tracker(cfg)
    pose = Pose2D(-5.0, 0.0, 0.0)
    seq: dict[int, list[bool]] = {}  # per track id: hit / miss per scan since its birth (the reference list)
    held = []  # (entry, the live entries before its update) of every snapshot made
    compacted = gaps = 0
    for i in range(80):
        t = i / 15.0
        hidden = i in (50, 51)  # (the box leaves the scan for two scans: misses, then a re-acquisition)
        before = {k.id: tuple(k.past[k.past_a:]) for k in tr._tracks}
        lists = {k.id: k.past for k in tr._tracks}
        x = 30.0 if hidden else -3.5 + 0.9 * t
        tr.update(_scan(pose, x, t, i), pose)
        for k in tr._tracks:
            if k.id not in seq:
                seq[k.id] = [True]
                continue
            hit = k.misses == 0
            seq[k.id].append(hit)
            gaps += hit and k.past is not lists[k.id] and len(k.past) == 1
            compacted += k.past is not lists[k.id] and len(k.past) > 1
            if hit and k.free and type(k.free[-1]) is tuple and len(before[k.id]):
                e = k.free[-1]
                assert len(e) == 6 and e[3][e[4]:e[5]] == list(before[k.id])
                held.append((e, before[k.id]))
            assert 0 <= k.past_a < 8 and (not hit or all(t - s[0] <= tr._free.max_age for s in k.past[k.past_a:]))
        for k in tr._tracks:
            h = seq[k.id][:window]
            assert (k.hist_n, k.hist_hits) == (len(h), sum(h)), (k.id, seq[k.id])
    # every snapshot still reads its entries after all the later updates (the lists are never changed in place)
    assert len(held) > 30 and compacted > 0 and gaps > 0
    for e, want in held:
        got = e[3][e[4]:e[5]]
        assert len(got) == len(want) and all(a is b for a, b in zip(got, want))


def _veto_merged_reference(tr: Tracker, ok: np.ndarray, dets: list, det_ext: np.ndarray, tsize: np.ndarray,
                           rows: list[int]) -> tuple[np.ndarray, set[int]]:
    """``Tracker._veto_merged`` as it was before pass trk22 (one row's array test after another), without dormant
    tracks or marks: the pairs left and the ids it adds to ``_merged``."""
    tc = tr.config.tracker
    merged: set[int] = set()
    cand = np.array([d.map_structure >= tc.map_structure_stop for d in dets])
    if not cand.any():
        return ok, merged
    ok = ok.copy()
    for i in rows:
        k = tr._tracks[i]
        hit = ok[i] & cand & (det_ext > float(tsize[i].max()) + tc.merge_size_jump)
        if hit.any() and (not (mev := k.mev) or sum([e[0] for e in mev]) / len(mev) <= tc.map_structure_max):
            ok[i] &= ~hit
            merged.add(k.id)
    return ok, merged


def test_merged_detection_veto_matches_the_row_by_row_test() -> None:
    """The veto of detections merged with structure (``kernels_assign.veto_merged``, inlined in ``associate_scan``
    since pass trk75; before, ``Tracker._veto_merged``: each row's pairs found on Python floats and bools, the row's
    larger size from its two floats) refuses the same pairs and marks the same tracks as the
    row-by-row array test, on random gates, extents on the thresholds, sizes with NaN, NaN extents and tracks whose
    own points were or were not on structure."""
    from types import SimpleNamespace

    rng = random.Random(5)
    tr = Tracker(DetectConfig())
    tc = tr.config.tracker
    hits = 0
    for case in range(400):
        n, m = rng.randint(1, 8), rng.randint(1, 10)
        tr._tracks = [SimpleNamespace(id=100 + i, row=i, mev=[(rng.random(), 0.0, 0.0)
                                                              for _ in range(rng.randint(0, 3))]) for i in range(n)]
        for k in tr._tracks:  # (the windows' rows that _veto_merged reads: Tracker._mev; the reference reads k.mev)
            tr._start_windows(k.row, k.mev)
        dets = [SimpleNamespace(map_structure=rng.choice([0.0, tc.map_structure_stop, 1.0, rng.random()]))
                for _ in range(m)]
        tsize = np.array([[rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0)] for _ in range(n)])
        det_ext = np.array([rng.uniform(0.1, 4.0) for _ in range(m)])
        det_ext[rng.randrange(m)] = float(tsize.max()) + tc.merge_size_jump  # (a tie with a threshold)
        if case % 7 == 0:
            tsize[rng.randrange(n), rng.randrange(2)] = math.nan
        if case % 11 == 0:
            det_ext[rng.randrange(m)] = math.nan
        ok = np.array([[rng.random() < 0.6 for _ in range(m)] for _ in range(n)])
        rows = sorted(rng.sample(range(n), rng.randint(1, n)))
        want, want_merged = _veto_merged_reference(tr, ok, dets, det_ext, tsize, rows)
        got = ok.copy()
        vetoed = veto_merged(got, tsize, det_ext, np.array([k.row for k in tr._tracks], dtype=np.int64),
                             np.array(rows, dtype=np.int64), np.array([d.map_structure for d in dets]), tr._MEV,
                             tr._WN, tc.map_structure_stop, tc.merge_size_jump, tc.map_structure_max)
        assert np.array_equal(got, want) and {tr._tracks[i].id for i in vetoed.tolist()} == want_merged, case
        hits += len(want_merged)
    assert hits > 50  # (the cases refuse pairs, not only pass them)
