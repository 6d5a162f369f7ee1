"""The tracker's per-update windows as rows of arrays (docs/speed.md, pass trk26): the riding window and the map
evidence, pushed for all updated tracks in the shape update's kernel call (``kernels.shape_update``) and read through
``Tracker._ride`` / ``_mev``, against the per-track lists of tuples they replace (the list code kept here as the
reference): on random pushes (trims by age, full windows, growth, re-acquisitions, merged legs' point-weighted
evidence) and over whole pipeline runs with clutter retirement (births, re-acquisitions, dormant tracks revived)."""

from __future__ import annotations

import random

import numpy as np

from dynslam2d.config import Config
from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.kernels import N_G, N_GI, shape_update
from dynslam2d.detect.layout import K_CIRCLE
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import simulate


def _push_lists(ride: list, mev: list, x0: float, x1: float, pose: tuple, t: float, ev: tuple | None, nsus: int,
                ride_time: float) -> None:
    """The former pushes of ``Tracker._update_tracks`` (before pass trk26) into one track's lists."""
    px, py, c, s = pose
    ns = -s
    dx = x0 - px
    dy = x1 - py
    ride.append((c * dx + s * dy, ns * dx + c * dy, x0, x1, t))
    while len(ride) > nsus and t - ride[0][4] > ride_time:
        del ride[0]
    if ev is not None:
        mev.append(ev)
        if len(mev) > nsus:
            del mev[0]


def _near(ride: list, ride_n: int, r2: float) -> int:
    """``Tracker._manage``'s former riding pre-test on the list: 0 too few entries, 1 far, 2 near."""
    if len(ride) < ride_n:
        return 0
    lx, ly = ride[-1][:2]
    return 1 if lx * lx + ly * ly > r2 else 2


def _push_windows(tr: Tracker, rows: np.ndarray, det: np.ndarray, applied: np.ndarray, X: np.ndarray, mfr: np.ndarray,
                  kept: np.ndarray, first: np.ndarray, second: np.ndarray, npts: np.ndarray, use_map: bool,
                  px: float, py: float, c: float, s: float, t: float, ride_time: float, ride_n: int,
                  r2: float) -> int:
    """The windows' push of ``shape_update`` into ``tr``'s rows, its shape part on circle detections (which write
    only the shape rows G / Gi, never the centres in ``X`` the windows read)."""
    m = int(det.max()) + 1 if det.shape[0] else 1
    G = np.zeros((X.shape[0], N_G))
    Gi = np.zeros((X.shape[0], N_GI), dtype=np.int8)
    n = rows.shape[0]
    return shape_update(G, Gi, X, rows, det, applied, np.full(m, K_CIRCLE, dtype=np.int8), np.zeros(m),
                        np.zeros((m, 4)), np.zeros((m, 2, 2), dtype=bool), np.ones((m, 3)), np.zeros((n, 2)),
                        np.zeros((n, 2), dtype=np.int8), np.zeros(n, dtype=bool), 0.5, 0.5, 0.3, 0.3, mfr, kept,
                        first, second, npts, tr._MEV, tr._RIDE, tr._WN, use_map, px, py, c, s, t, ride_time, ride_n,
                        r2)


def test_push_windows_keeps_the_entries_of_the_former_lists() -> None:
    """Random updates of 12 rows over 600 scans (stamps 0-0.2 s apart, repeated ones too; ride_time 0.05-1 s, so
    windows are trimmed by age, stay full at sustain_updates or grow past the arrays' first length), random
    re-acquisitions (the lists cleared before the push, the rows restarted after it), with and without a map, and
    scans whose detections include merged leg pairs (their map evidence the point-weighted mean, in Python's order):
    after every scan each row's window holds exactly the list's entries (bit for bit, in order) and the riding
    pre-test is the list's. A window keeping one wrong entry, an entry too many or too few fails."""
    rng = random.Random(3)
    tr = Tracker(DetectConfig())
    nsus = tr.config.tracker.sustain_updates
    rows = 12
    ride_l: list[list] = [[] for _ in range(rows)]
    mev_l: list[list] = [[] for _ in range(rows)]
    X = np.zeros((rows, 4))
    t = 100.0
    grown = trims = merged = full = longest = 0
    r0 = tr._RIDE.shape[1]
    for step in range(600):
        long = 200 <= step < 320  # (a long ride_time: the windows outgrow the arrays' first length)
        t += rng.choice([0.0, 0.005, 0.01, 0.03] if long else [0.0, 0.005, 0.01, 0.03, 0.1, 0.2])
        ride_time = 5.0 if long else rng.choice([0.05, 0.3, 1.0])
        ride_n = rng.choice([2, 3, 5])
        r2 = rng.choice([0.25, 4.0, 100.0])
        use_map = step % 9 != 0
        pose = (rng.uniform(-5, 5), rng.uniform(-5, 5), *(lambda a: (np.cos(a).item(), np.sin(a).item()))(
            rng.uniform(-3.2, 3.2)))
        nd = rng.randint(1, 8)
        mfr = np.array([[rng.random() for _ in range(nd)] for _ in range(3)])
        npts = np.array([rng.randint(1, 40) for _ in range(nd)], dtype=np.int64)
        if nd >= 3 and step % 3 == 0:  # a leg merge: detections kept (reordered), then merged pairs
            idx = list(range(nd))
            rng.shuffle(idx)
            first, second, kept = [idx[0]], [idx[1]], idx[2:]
            srcs = [("k", j) for j in kept] + [("m", 0)]
        else:
            first = second = kept = []
            srcs = [("k", j) for j in range(nd)]
        m = len(srcs)
        sel = rng.sample(range(rows), rng.randint(0, rows))
        det = [rng.randrange(m) for _ in sel]
        applied = [rng.random() < 0.9 for _ in sel]
        reacq = [rng.random() < 0.05 for _ in sel]
        for r in sel:
            X[r] = [rng.uniform(-8, 8), rng.uniform(-8, 8), 0.0, 0.0]
        for r, j, ok, again in zip(sel, det, applied, reacq):
            if not ok:
                continue
            if again:
                ride_l[r].clear()
                mev_l[r].clear()
            kind, src = srcs[j]
            if kind == "k":
                ev = tuple(mfr[:, src].tolist())
            else:
                a, b = first[src], second[src]
                na, nb = int(npts[a]), int(npts[b])
                n = na + nb
                fa, fb = mfr[:, a].tolist(), mfr[:, b].tolist()
                ev = tuple((na * u + nb * v) / n for u, v in zip(fa, fb))
                merged += 1
            n0 = len(ride_l[r])
            _push_lists(ride_l[r], mev_l[r], X[r, 0].item(), X[r, 1].item(), pose, t, ev if use_map else None, nsus,
                        ride_time)
            trims += len(ride_l[r]) <= n0
            longest = max(longest, len(ride_l[r]))
        top = _push_windows(tr, np.array(sel, dtype=np.int64), np.array(det, dtype=np.int64),
                            np.array(applied, dtype=bool), X, mfr, np.array(kept, dtype=np.int64),
                            np.array(first, dtype=np.int64), np.array(second, dtype=np.int64), npts, use_map, *pose, t,
                            ride_time, ride_n, r2)
        if top >= tr._RIDE.shape[1]:
            tr._grow_ride()
            grown += 1
        for r, ok, again in zip(sel, applied, reacq):
            if ok and again:
                tr._restart_windows(r, use_map)
        for r in range(rows):
            n, nm = tr._WN.item(r, 1), tr._WN.item(r, 0)
            assert tr._RIDE[r, :n].tolist() == [list(e) for e in ride_l[r]], (step, r)
            assert tr._MEV[r, :nm].tolist() == [list(e) for e in mev_l[r]], (step, r)
            full += nm == nsus
        for r, ok in zip(sel, applied):
            if ok:
                assert tr._WN.item(r, 2) == _near(ride_l[r], ride_n, r2), (step, r)
    assert grown >= 1 and tr._RIDE.shape[1] > r0 and longest > r0  # windows outgrew the first length
    assert trims > 100 and merged > 20 and full > 500


class _Shadow(Tracker):
    """A tracker that keeps the former lists of tuples beside its windows (``_Track.ride`` / ``.mev`` before pass
    trk26, by track id, with the list code of ``_update_tracks``, ``_births``, ``_revive``) and compares them after
    every update."""

    def __init__(self, config: DetectConfig) -> None:
        super().__init__(config)
        self.lists: dict[int, tuple[list, list]] = {}
        self.seen = {"reacq": 0, "trimmed": 0, "full": 0, "revived": 0, "compared": 0}

    def _update_tracks(self, applied, dets, t) -> None:
        # (the pairs whose update applied, pass trk138: track, detection, then update_pairs' info row, its applied
        # flag first, pass upd34; 2: the track had missed scans before the update kernel reset its misses, pass trk71)
        again = {self._tracks[ti].id for ti, _di, ok, *_r in applied if ok == 2}
        super()._update_tracks(applied, dets, t)
        nsus, ride_time = self.config.tracker.sustain_updates, self.config.tracker.ride_time
        p = self._pose
        c, s = self._pose_cs
        for ti, di, ok, *_r in applied:
            if not ok:
                continue
            k, det = self._tracks[ti], dets[di]
            ride, mev = self.lists[k.id]
            if k.id in again:
                ride.clear()
                mev.clear()
                self.seen["reacq"] += 1
            n0 = len(ride)
            ev = (det.map_structure, det.map_free, det.map_unknown) if self._map is not None else None
            _push_lists(ride, mev, k.x.item(0), k.x.item(1), (p.x, p.y, c, s), t, ev, nsus, ride_time)
            self.seen["trimmed"] += len(ride) <= n0

    def _births(self, dets, t, js, updated) -> None:  # (the births of a scan in one batch, pass trk38)
        super()._births(dets, t, js, updated)
        for k, j in zip(self._tracks[len(self._tracks) - len(js):], js):
            det = dets[j]
            self.lists[k.id] = ([], [(det.map_structure, det.map_free, det.map_unknown)]
                                if self._map is not None else [])

    def _revive(self, k, det, t, j) -> None:
        super()._revive(k, det, t, j)
        ride, mev = self.lists[k.id]
        ride.clear()
        if self._map is not None:
            mev[:] = [(det.map_structure, det.map_free, det.map_unknown)]
        self.seen["revived"] += 1

    def update(self, *args, **kwargs):
        out = super().update(*args, **kwargs)
        nsus = self.config.tracker.sustain_updates
        for k in self._tracks:
            ride, mev = self.lists[k.id]
            assert self._ride(k).tolist() == [list(e) for e in ride], k.id
            assert self._mev(k).tolist() == [list(e) for e in mev], k.id
            self.seen["compared"] += 1
            self.seen["full"] += len(mev) == nsus
        return out


def test_windows_over_pipeline_runs_hold_the_former_lists() -> None:
    """sim:drive (seed 11) with clutter retirement (dormant tracks retired and revived, as tests/test_detect_clutter.py
    runs it) and sim:crowd with the defaults, through the whole pipeline (SLAM map, so the map evidence is pushed):
    after every scan every live track's riding and map-evidence windows equal the former lists."""
    seen = []
    for name, seed, retire in (("drive", 11, True), ("crowd", None, False)):
        cfg = Config()
        if retire:
            cfg.detect.tracker.structure_retire_updates = 2
            cfg.detect.tracker.structure_birth_min = 0.5
        pipe = Pipeline(cfg)
        pipe.tracker = _Shadow(cfg.detect)
        sim = simulate(name, seed=seed, duration=None if retire else 8.0)
        for scan in sim.scans:
            pipe.process(scan)
        seen.append(pipe.tracker.seen)
    drive, crowd = seen
    assert drive["revived"] > 0 and pipe.tracker.stats.merged_leg_pairs >= 0
    for s in seen:
        assert s["compared"] > 500 and s["full"] > 200 and s["trimmed"] > 100
    assert drive["reacq"] + crowd["reacq"] > 5
