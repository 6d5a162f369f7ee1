"""The association as one kernel call (``kernels_assign.associate_scan``, docs/speed.md pass trk75) gives the results
of the calls it replaced, bit for bit: ``association_gates``, the claimed detections taken out, the Python veto of
detections merged with structure (``Tracker._veto_merged`` of pass trk72), the count of the pairs allowed and
``assign_groups``."""

from __future__ import annotations

import math
import random

import numpy as np

import dynslam2d.detect.tracker as tracker_mod  # (_associate_update calls associate_update there)
from dynslam2d.config import Config
from dynslam2d.detect import kernels_assign as ka
from dynslam2d.detect import kernels_update as ku
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import Pipeline


def _former_veto(ok: np.ndarray, tsize: np.ndarray, det_ext: np.ndarray, rows: np.ndarray, vrows: list[int],
                 ms: list[float], MEV: np.ndarray, WN: np.ndarray, stop: float, jump: float,
                 smax: float) -> tuple[np.ndarray, list[int]]:
    """``Tracker._veto_merged``'s per-row loop as pass trk72 left it (Python floats and lists; the track's map evidence
    ``Tracker._mev``: its row's window): the pairs left and the vetoed tracks' indices in order."""
    cand = [j for j, v in enumerate(ms) if v >= stop]
    vetoed: list[int] = []
    if not cand or not vrows:
        return ok, vetoed
    ext = det_ext.tolist()
    copied = False
    for i in vrows:
        a, b = tsize[i].tolist()
        thr = (a if a >= b or a != a else b) + jump
        row = ok[i].tolist()
        hit = [j for j in cand if row[j] and ext[j] > thr]
        r = int(rows[i])
        mev = MEV[r, :WN.item(r, 0)]
        if hit and (not (nm := mev.shape[0]) or sum(mev[:, 0].tolist()) / nm <= smax):
            if not copied:
                ok = ok.copy()
                copied = True
            ok[i, hit] = False
            vetoed.append(i)
    return ok, vetoed


def _former_chain(*args) -> tuple:
    """``Tracker._associate``'s calls before pass trk75 on ``associate_scan``'s arguments: (status, ii, jj, missed,
    vetoed)."""
    gates, (claimed, vrows, ms, MEV, WN, stop, jump, smax, big) = args[:19], args[19:]
    rows = args[2]
    tsize, d2, ok, det_ext, firm, missed = ku.association_gates(*gates)
    if claimed.shape[0] and claimed.any():
        ok = ok & ~claimed[None, :]
    ok, vetoed = _former_veto(ok, tsize, det_ext, rows, vrows.tolist(), ms.tolist(), MEV, WN, stop, jump, smax)
    if not np.count_nonzero(ok):
        return 0, np.zeros(0, np.int64), np.zeros(0, np.int64), missed, vetoed
    status, ii, jj = ka.assign_groups(ok, d2, firm, big)
    return status, ii, jj, missed, vetoed


def _same(got: tuple, want: tuple) -> bool:
    status, ii, jj, missed, vetoed = got
    return (status == want[0] and ii.tolist() == want[1].tolist() and jj.tolist() == want[2].tolist()
            and missed.dtype == want[3].dtype and missed.tobytes() == want[3].tobytes()
            and vetoed.tolist() == want[4])


def _checked_runs(fused) -> dict[str, int]:
    """Pipelines (with their maps: the veto runs) over two short simulated runs, every ``associate_scan`` call of the
    tracker replaced by ``fused`` and compared with :func:`_former_chain`; each call compared again with the veto's
    thresholds loosened (every track in M or merged, a detection on structure a candidate, any size jump; a random
    detection claimed) so that it refuses pairs. Returns counts of what the calls exercised."""
    seen = {"calls": 0, "rows": 0, "vetoed": 0, "vetoed_loose": 0, "pairs": 0}
    rng = random.Random(3)

    def checked(*a):
        got = fused(*a)
        want = _former_chain(*a)
        assert _same(got, want)
        seen["calls"] += 1
        seen["rows"] += a[20].shape[0] > 0
        seen["vetoed"] += len(want[4])
        seen["pairs"] += want[1].shape[0]
        n, m = a[4].shape[0], a[6].shape[0]
        claimed = np.array([rng.random() < 0.15 for _ in range(m)], dtype=np.bool_)
        ms = np.array([rng.choice((0.0, 0.3, 1.0, math.nan)) for _ in range(m)])
        loose = a[:19] + (claimed, np.arange(n, dtype=np.int64), ms, a[22], a[23], 0.3, -0.5, 0.6, a[27])
        got2, want2 = fused(*loose), _former_chain(*loose)
        assert _same(got2, want2)
        seen["vetoed_loose"] += len(want2[4])
        return got

    # (since pass trk108 the tracker calls associate_update, which calls associate_scan: its Python runs instead, its
    # calls through kernels_assign's names)
    saved = tracker_mod.associate_update, ka.associate_scan
    tracker_mod.associate_update, ka.associate_scan = ka.associate_update.py_func, checked
    try:
        for name, seed in (("sim:crowd", 5), ("sim:drive", 11)):
            pipe = Pipeline(Config())
            for scan in open_source(name, seed=seed, duration=6.0):
                pipe.process(scan)
    finally:
        tracker_mod.associate_update, ka.associate_scan = saved
    return seen


def test_associate_scan_is_the_former_calls_in_pipeline_runs() -> None:
    """Every association of two simulated pipeline runs: the fused kernel's pairs, missed flags and vetoed tracks are
    those of the former calls, as the runs have them and with the veto loosened so that it refuses pairs."""
    seen = _checked_runs(ka.associate_scan)
    assert seen["calls"] > 200 and seen["pairs"] > 1000 and seen["rows"] > 20 and seen["vetoed_loose"] > 100, seen



#: associate_update's arguments that the update writes: the row tables' buffers F and Fi, Gi and RIDE
_WRITTEN = (0, 1, 2, 20)


def _former_pair_calls(Xs: np.ndarray, Ps: np.ndarray):
    """``Tracker._associate`` then ``Tracker._update_pairs`` as they called their kernels before pass trk108 (main at
    5d1894d), on ``associate_update``'s arguments ``a``, with the predicted rows ``Xs`` / ``Ps`` the tracker passed
    then (its ``_stack()``) and the merge veto's thresholds and the cost outside the gates as the floats it passed
    then (before pass trk129): ``associate_scan``, then, with pairs and status 0, ``update_pairs`` with the pairs'
    index arrays as ``sel`` / ``dis`` and the association's missed flags; then (status 0) ``manage_scan`` as
    ``TrackManage._manage`` called it before pass trk117."""

    def calls(*a: object) -> tuple:
        F, Fi, Gi, rows, Z, R = a[:6]
        X, P, G, CL, MEV, CI, WN = ku.row_tables.py_func(F, Fi, Gi.shape[0])  # (views: the update writes F, Fi)
        batch, q = a[6:16], a[16]
        claimed, vrows, ms, RIDE, bound, lim, lim2 = a[17:24]
        mev, (use_map, lx, ly, c, s, t) = a[24:29], a[29:35]
        tc = Config().detect.tracker
        status, ii, jj, missed, vetoed = ka.associate_scan(
            G, Gi, rows, CI, Xs, Ps, Z, R, *batch, q, claimed, vrows, ms, MEV, WN, float(tc.map_structure_stop),
            float(tc.merge_size_jump), float(tc.map_structure_max), 1e12)
        none = np.empty((0, 4), dtype=np.int64)
        if status:
            man0 = (np.empty(0, dtype=np.int8), np.empty(0), np.empty(0), np.empty(0, dtype=np.int64))
            return status, vetoed, 0, 0, np.empty((0, 6), dtype=np.int64), np.empty(0, dtype=np.int64), 0, man0
        nb, top, info, nrej = 0, 0, none, 0
        if ii.shape[0]:
            nb, top, info, nrej = ku.update_pairs(G, Gi, X, P, Xs, Ps, ii, rows, jj, missed, *batch, q, bound, CI,
                                                  CL, lim, lim2, *mev, MEV, RIDE, WN, use_map, lx, ly, c, s, t)
        # (then TrackManage._manage's kernel call, with the rows and stamp of the scan: pass trk117)
        man = ku.manage_scan(P, X, CI, CL, WN, MEV, rows, q, t)
        # (then the tracker's Python before pass trk138: the pairs whose info flag is not 0, their rows, and the
        # detections no such pair took — _update_tracks' loop test and used set, update's list of the unused)
        applied = [[ti, di, *row] for ti, di, row in zip(ii.tolist(), jj.tolist(), info.tolist()) if row[0]]
        used = {r[1] for r in applied}
        unused = [di for di in range(batch[0].shape[0]) if di not in used]
        return (status, vetoed, nb, top, np.array(applied, dtype=np.int64).reshape(-1, 6),
                np.array(unused, dtype=np.int64), nrej, man)

    return calls


def _outcome(f, a: list) -> tuple:
    """``f``'s results on copies of the arrays the update writes, and those arrays' bytes after the call."""
    c = list(a)
    for i in _WRITTEN:
        c[i] = c[i].copy()
    got = f(*c)
    out = [v.tobytes() if isinstance(v, np.ndarray) else v for v in got[:-1]]
    out.append([(v.dtype.str, v.tobytes()) for v in got[-1]])  # (the management's four arrays)
    return out, [c[i].tobytes() for i in _WRITTEN]


def _with_map_evidence(on: bool) -> Config:
    """The default configuration with the tracker's map evidence ``on`` or off."""
    cfg = Config()
    cfg.detect.tracker.map_evidence = on
    return cfg


def test_associate_update_is_the_two_former_calls_in_pipeline_runs() -> None:
    """``associate_update`` (pass trk108) against ``associate_scan`` then ``update_pairs`` as the tracker called them
    before, on every call of two simulated pipeline runs (sim:drive with the map evidence, sim:crowd without): the
    pairs, vetoed tracks, bounded and rejected counts, ``info`` rows, the management's four arrays (pass trk117) and
    the bytes of every array the update writes; each call also with a limit 30 × tighter (most established rows
    bounded). The former calls get the predicted rows as the tracker stacked them before pass trk129 (the arrays
    ``cv_predict`` returned in this scan, with the stationary predictions written into them; ``X.take(rows)`` where
    it did not run), the fused kernel gathers them from the state rows itself."""
    seen = {"calls": 0, "pairs": 0, "unused": 0, "bounded": 0, "use_map": 0, "predicted": 0, "still": 0,
            "in_kernel": 0}
    stacked: list = []
    former_predict, former_cv = tracker_mod.Tracker._predict, tracker_mod.cv_predict

    def cv(X, P, order, F, Q):
        out = former_cv(X, P, order, F, Q)
        stacked[:] = [out]
        return out

    def predict(self, dt: float) -> None:
        stacked.clear()
        # (the tracks _predict gives a stationary prediction, which the former _predict wrote into its stacked arrays
        # too: its own test)
        still = [i for i, k in enumerate(self._tracks) if k.remembered and k.misses > 0] \
            if self._maybe_remembered and self.config.memory.enabled else []
        former_predict(self, dt)
        if stacked:
            order, (Xs, Ps) = self._rows(), stacked[0]
            for i in still:
                Xs[i], Ps[i] = self._X[order[i]], self._P[order[i]]
            seen["still"] += len(still)

    def checked(*a):
        a = list(a)
        tight = list(a)
        tight[21], tight[22], tight[23] = True, a[22] / 30.0, (0.999 * a[22] / 30.0) ** 2
        fcase = {}
        if a[36]:  # (the prediction left to the fused kernel, pass trk145: the former calls ran it first)
            Fp = a[0].copy()
            X, P = ku.row_tables.py_func(Fp, a[1], a[2].shape[0])[:2]
            Xs, Ps = former_cv(X, P, a[3], a[35][0], a[35][1])
            fcase = {0: Fp, 36: False}
            seen["predicted"] += 1
            seen["in_kernel"] += 1
        elif stacked:
            Xs, Ps = stacked[0]
            seen["predicted"] += 1
        else:
            X, P = ku.row_tables.py_func(a[0], a[1], a[2].shape[0])[:2]
            Xs, Ps = X.take(a[3], axis=0), P.take(a[3], axis=0)
        for case in (a, tight):
            former = list(case)
            for i, v in fcase.items():  # (the former calls on the rows the prediction wrote)
                former[i] = v
            got, want = _outcome(ka.associate_update, case), _outcome(_former_pair_calls(Xs, Ps), former)
            assert got == want
            seen["bounded"] += want[0][2]  # (update_pairs' bounded rows)
        seen["pairs"] += len(got[0][4]) // 48  # (the applied pairs' rows: six int64)
        seen["unused"] += len(got[0][5]) // 8
        seen["use_map"] += bool(a[29])
        seen["calls"] += 1
        return ka.associate_update(*a)

    saved = tracker_mod.associate_update
    tracker_mod.associate_update, tracker_mod.cv_predict, tracker_mod.Tracker._predict = checked, cv, predict
    try:
        _run_two_scenes()
    finally:
        tracker_mod.associate_update, tracker_mod.cv_predict, tracker_mod.Tracker._predict = \
            saved, former_cv, former_predict
    assert seen["calls"] > 100 and seen["pairs"] > 500 and seen["bounded"] > 20 and seen["unused"] > 20, seen
    assert 20 < seen["use_map"] < seen["calls"] and seen["predicted"] > 100 and seen["in_kernel"] > 100, seen


def _run_two_scenes() -> None:
    """Two simulated pipeline runs of 6 s (seed 11): sim:drive with the map evidence, sim:crowd without."""
    for name, use_map in (("sim:drive", True), ("sim:crowd", False)):
        pipe = Pipeline(_with_map_evidence(use_map))
        for scan in open_source(name, seed=11, duration=6.0):
            pipe.process(scan)


def test_managed_rows_are_managed_at_manage_time() -> None:
    """The management's arrays that ``associate_update`` makes (pass trk117) are the ones ``TrackManage._manage``
    would make itself: every array ``manage_scan`` reads or writes (P, X, CI, CL, WN, MEV, the rows, the parameters)
    has the same bytes when ``_manage`` reads the outputs as right after the fused call (nothing between writes them;
    the test above shows the fused call's outputs are ``manage_scan``'s on them), on every scan of two simulated
    pipeline runs (sim:drive with the map evidence, sim:crowd without); scans without an association (no track or no
    detection) call ``manage_scan`` themselves."""
    from dynslam2d.detect import trackmanage

    seen = {"fused": 0, "own": 0}
    former_manage, former_call = trackmanage.TrackManage._manage, tracker_mod.associate_update
    after: list = []

    def snap(self) -> list:
        return [v.tobytes() for v in (self._P, self._X, self._CI, self._CL, self._WN, self._MEV, self._rows(),
                                      self._upd_p)]

    def call(*a):
        out = former_call(*a)
        X, P, _, CL, MEV, CI, WN = ku.row_tables.py_func(a[0], a[1], a[2].shape[0])
        after[:] = [(P.tobytes(), X.tobytes(), CI.tobytes(), CL.tobytes(), WN.tobytes(), MEV.tobytes(),
                     a[3].tobytes(), a[16].tobytes())]
        return out

    def checked(self, t: float, updated: set[int]) -> None:
        if self._managed is not None:
            assert after and snap(self) == list(after[0])
            seen["fused"] += 1
        elif self._tracks:
            seen["own"] += 1
        after.clear()
        former_manage(self, t, updated)
        assert self._managed is None

    trackmanage.TrackManage._manage, tracker_mod.associate_update = checked, call
    try:
        _run_two_scenes()
    finally:
        trackmanage.TrackManage._manage, tracker_mod.associate_update = former_manage, former_call
    assert seen["fused"] > 100, seen  # ("own": none in these two runs; the digest's real bags have them)
