"""Study (issue 13 item 1, pass stu70; not run by pytest): ``TrackManage._manage``'s per-track loop as one numba
kernel over row arrays (struct of arrays), fed each scan from the real tracker's state, against the Python loop.

Each scan of a real pipeline, ``Tracker._manage`` is wrapped: the ``_Track`` fields the loop reads are copied into
per-track columns (outside the timing: in a struct-of-arrays tracker they would be its row arrays), then, alternating
which goes first, (a) the library's ``_manage`` runs (thread CPU timed) and (b) the prototype runs on copies of the
counter table: ``manage_counters`` + :func:`manage_rows_proto` + the glue a row-array tracker would keep (the
non-zero actions' indices as a list). The prototype decides every track on the common paths (kept, deleted by the
counters or by coasting, clutter retirement, the fast / slow-since / memory bookkeeping, the in-M "moving on" and
the four common not-in-M reasons, as codes + floats: the text formatted when read) and returns a *defer* action for
the rare paths that read objects (``_dynamic``, the probation test, the riding test, merged / hidden / remembered
tracks without detection): there Python would continue per track. After each scan every non-deferred track's
outcome is compared with the Python loop's: kept / deleted (and why), ``in_m``, ``fast``, ``slow_since``,
``remembered``, ``rode``, the memory's ``m_*`` and the reason's text.

    PYTHONPATH=src taskset -c 1 python benchmarks/study_manage_rows.py sim:paper sim:crowd negative_2/right
    PYTHONPATH=src python benchmarks/study_manage_rows.py --compile   # the prototype's cold compile, fresh processes
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402

clock = time.thread_time_ns
NAN = float("nan")

# actions (out_action)
A_KEEP, A_DEL_TENT, A_DEL_COV, A_DEL_SPEED, A_DEL_COAST, A_RETIRE, A_RETIRE_TENT, A_DEFER_UPD, A_DEFER_MISS = range(9)
# reason codes (out_reason): 0 unchanged (deferred / not updated)
R_NONE, R_TENT, R_SLOW, R_FAST, R_MOVING = range(5)
# configuration columns
Q_VMIN, Q_MAXSIG, Q_VEXIT, Q_NSUS, Q_NPU, Q_RETN, Q_RETS, Q_SEXIT, Q_ONMAP, Q_PROBE, Q_MEM = range(11)


def _kernel(codes, speeds, sigs, nears, rows, WN, MEV, X, fast, in_m, was_in_m, remembered, probation, pstreak,  # noqa: ANN001, PLR0913
            merged_f, rode, slow, msx, msy, mlast, mtime, mtravel, bx, by, nfree, q, t, action, reason, rdisp):
    """The per-track loop of ``TrackManage._manage`` over the tracks' columns (index i = i-th live track, its state
    row ``rows[i]``); columns updated in place, NaN for None. The same tests in the same order."""
    v_min, max_ssig, v_exit = q[Q_VMIN], q[Q_MAXSIG], q[Q_VEXIT]
    nsus, npu, retire_n = int(q[Q_NSUS]), int(q[Q_NPU]), int(q[Q_RETN])
    retire_s, s_exit = q[Q_RETS], q[Q_SEXIT]
    on_map, probe, mem = q[Q_ONMAP] != 0.0, q[Q_PROBE] != 0.0, q[Q_MEM] != 0.0
    for i in range(codes.shape[0]):
        code = codes[i]
        sp = speeds[i]
        r = rows[i]
        reason[i] = R_NONE
        if code <= 1:
            nm = WN[r, 0]
            if retire_n and not was_in_m[i] and not remembered[i] and nm >= retire_n and sp < v_min:
                lo = MEV[r, nm - retire_n, 0]
                for j in range(nm - retire_n + 1, nm):
                    lo = min(lo, MEV[r, j, 0])
                if lo >= retire_s:
                    action[i] = A_RETIRE_TENT if code == 0 else A_RETIRE
                    continue
            if sp > v_min and sigs[i] < max_ssig:
                fast[i] += 1
            else:
                fast[i] = 0
            kfast = fast[i]
            if sp < v_exit:
                if math.isnan(slow[i]):
                    slow[i] = t
            elif remembered[i] and kfast < nsus:
                pass
            else:
                slow[i] = NAN
            im = in_m[i]
            if im and probation[i] and probe and nfree[i] >= nsus:
                action[i] = A_DEFER_UPD  # (_probation_fails reads the free-space entries)
                continue
            if nears[i] == 1:
                rode[i] = False
            if nears[i] > 1:
                action[i] = A_DEFER_UPD  # (the riding test: ride_window + the track's beams)
                continue
            if im and math.isnan(slow[i]) and (was_in_m[i] or pstreak[i] < npu or not on_map):
                leaves = False
                if on_map and nm and nm >= nsus:
                    s = 0.0
                    for j in range(nm):
                        s += MEV[r, j, 0]
                    leaves = s / nm >= s_exit
                if not leaves:
                    remembered[i] = False
                    x0, x1 = X[r, 0], X[r, 1]
                    reason[i] = R_MOVING
                    rdisp[i] = np.hypot(x0 - bx[i], x1 - by[i])
                    if mem:
                        if math.isnan(msx[i]):
                            msx[i], msy[i] = x0, x1
                        elif not math.isnan(mlast[i]):
                            mtime[i] += t - mlast[i]
                        mlast[i] = t
                        mtravel[i] = max(mtravel[i], py_hypot(x0 - msx[i], x1 - msy[i]))
                    action[i] = A_KEEP
                    continue
                action[i] = A_DEFER_UPD  # (_dynamic: the structure exit's reason)
                continue
            if im:
                action[i] = A_DEFER_UPD  # (_dynamic)
                continue
            if code == 0:
                reason[i] = R_TENT
            elif sp <= v_min:
                reason[i] = R_SLOW
            elif kfast < nsus and sigs[i] < max_ssig and pstreak[i] < npu:
                reason[i] = R_FAST
            else:
                action[i] = A_DEFER_UPD  # (_dynamic)
                continue
            if mem and (not math.isnan(msx[i]) or remembered[i]):
                msx[i] = msy[i] = mlast[i] = NAN
                remembered[i] = False
                mtime[i] = mtravel[i] = 0.0
            action[i] = A_KEEP
            continue
        if code < 16:
            if merged_f[i] or (in_m[i] and not remembered[i] and not math.isnan(slow[i]) and mem):
                action[i] = A_DEFER_MISS  # (merged into structure; the hidden test reads the scan)
                continue
            if code >= 8:
                if remembered[i]:
                    action[i] = A_DEFER_MISS  # (_remembered_coasts: the seen-through test)
                    continue
                action[i] = A_DEL_COAST
                continue
            if code == 2:
                action[i] = A_KEEP
                continue
        code &= ~16
        action[i] = A_DEL_TENT if code == 3 else (A_DEL_COV if code == 4 else A_DEL_SPEED)


def build(cache: bool = True):
    """The prototype compiled (``cache=False`` for the cold-compile measurement)."""
    global py_hypot
    from dynslam2d.detect.kernels_update import py_hypot as ph
    py_hypot = ph
    return numba.njit(cache=cache)(_kernel)


py_hypot = None


def build_fused(kern, cache: bool = True):
    """``manage_counters`` and the row loop in one call (one dispatch), returning the speeds and the indices of the
    tracks not simply kept (what Python would still visit)."""
    from dynslam2d.detect.kernels_update import manage_counters

    def _fused(P, X, CI, CL, WN, rows, upd_p, t, MEV, fast, in_m, was_in_m, remembered, probation, pstreak,  # noqa: ANN001, ANN202, PLR0913
               merged_f, rode, slow, msx, msy, mlast, mtime, mtravel, bx, by, nfree, q, action, reason, rdisp):
        codes, sigs, speeds, nears = manage_counters(P, X, CI, CL, WN, rows, upd_p, t)
        kern(codes, speeds, sigs, nears, rows, WN, MEV, X, fast, in_m, was_in_m, remembered, probation, pstreak,
             merged_f, rode, slow, msx, msy, mlast, mtime, mtravel, bx, by, nfree, q, t, action, reason, rdisp)
        m = 0
        for i in range(action.shape[0]):
            if action[i] != 0:
                m += 1
        nz = np.empty(m, dtype=np.int64)
        m = 0
        for i in range(action.shape[0]):
            if action[i] != 0:
                nz[m] = i
                m += 1
        return speeds, nz

    return numba.njit(cache=cache)(_fused)


RARE = ("_dynamic", "_probation_fails", "_rides_with_laser", "_hidden", "_remembered_coasts", "_retire", "_remember")


class Study:
    def __init__(self, kern, fused) -> None:
        self.kern = kern
        self.fused = fused
        self.t_f: list[int] = []
        self.fused_diff = 0
        self.t_py: list[int] = []
        self.t_k: list[int] = []
        self.t_parts: list[tuple[int, int, int]] = []
        self.t_rare: list[int] = [0]
        self.depth = 0
        self.n_tracks = self.n_defer = self.n_nonzero = 0
        self.mismatch: list[str] = []
        self.scans = 0

    def wrap(self, orig):
        from dynslam2d.detect.kernels_update import manage_counters
        from dynslam2d.detect.trackmanage import _slow_reason, _slow_reason_texts

        study = self

        def _manage(tr, t, updated):
            tracks = list(tr._tracks)
            if not tracks:
                return orig(tr, t, updated)
            tc = tr.config.tracker
            n = len(tracks)
            rows = tr._rows().copy()
            CI, CL = tr._CI.copy(), tr._CL.copy()
            merged = tr._merged
            nan = NAN
            fast = np.array([k.fast for k in tracks], dtype=np.int64)
            in_m = np.array([k.in_m for k in tracks], dtype=np.bool_)
            was = np.array([k.was_in_m for k in tracks], dtype=np.bool_)
            rem = np.array([k.remembered for k in tracks], dtype=np.bool_)
            prob = np.array([k.probation for k in tracks], dtype=np.bool_)
            ps = np.array([k.person_streak for k in tracks], dtype=np.int64)
            mf = np.array([bool(merged) and k.in_m and k.id in merged for k in tracks], dtype=np.bool_)
            rode = np.array([k.rode for k in tracks], dtype=np.bool_)
            slow = np.array([nan if k.slow_since is None else k.slow_since for k in tracks])
            msx = np.array([nan if k.m_start_xy is None else k.m_start_xy[0] for k in tracks])
            msy = np.array([nan if k.m_start_xy is None else k.m_start_xy[1] for k in tracks])
            mlast = np.array([nan if k.m_last_t is None else k.m_last_t for k in tracks])
            mtime = np.array([k.m_time for k in tracks])
            mtravel = np.array([k.m_travel for k in tracks])
            bx = np.array([k.birth_xy[0] for k in tracks], dtype=np.float64)
            by = np.array([k.birth_xy[1] for k in tracks], dtype=np.float64)
            nfree = np.array([len(k.free) for k in tracks], dtype=np.int64)
            q = np.array([tc.v_min, tc.max_speed_sigma, tc.v_exit_ratio * tc.v_min, tc.sustain_updates,
                          tc.person_sustain_updates, tc.structure_retire_updates if tr._map is not None else 0,
                          tc.structure_retire_fraction, tc.map_structure_exit, tr._map is not None,
                          tr._free is not None, tr.config.memory.enabled], dtype=np.float64)
            action = np.empty(n, dtype=np.int8)
            reason = np.empty(n, dtype=np.int8)
            rdisp = np.zeros(n)
            P, X, WN, MEV, upd_p, kern = tr._P, tr._X, tr._WN, tr._MEV, tr._upd_p, study.kern

            def proto():
                t0 = clock()
                codes, sigs, speeds, nears = manage_counters(P, X, CI, CL, WN, rows, upd_p, t)
                t1 = clock()
                kern(codes, speeds, sigs, nears, rows, WN, MEV, X, fast, in_m, was, rem, prob, ps, mf, rode, slow,
                     msx, msy, mlast, mtime, mtravel, bx, by, nfree, q, t, action, reason, rdisp)
                t2 = clock()
                nz = np.flatnonzero(action).tolist()  # (the glue: Python visits only the non-kept tracks)
                dt = clock() - t0
                study.t_parts.append((t1 - t0, t2 - t1, dt - (t2 - t0)))
                return dt, speeds, nz

            cols = (fast, in_m, was, rem, prob, ps, mf, rode, slow, msx, msy, mlast, mtime, mtravel, bx, by, nfree)
            fcols = tuple(c.copy() for c in cols)
            CIf, CLf = tr._CI.copy(), tr._CL.copy()
            faction, freason, frdisp = np.empty(n, dtype=np.int8), np.empty(n, dtype=np.int8), np.zeros(n)
            fused = study.fused

            def proto_fused():
                t0 = clock()
                _, nzf = fused(P, X, CIf, CLf, WN, rows, upd_p, t, MEV, *fcols, q, faction, freason, frdisp)
                nzf = nzf.tolist()
                return clock() - t0

            st = tr.stats
            before = (st.deleted_tentative, st.deleted_covariance, st.deleted_speed, st.deleted_coasting,
                      st.deleted_structure)
            study.t_rare.append(0)
            turn = study.scans % 3  # (the three in rotating order)
            for j in range(3):
                w = (turn + j) % 3
                if w == 0:
                    t0 = clock()
                    orig(tr, t, updated)
                    dp = clock() - t0
                elif w == 1:
                    dk, speeds, nz = proto()
                else:
                    df = proto_fused()
            study.t_f.append(df)
            if not (np.array_equal(faction, action) and np.array_equal(freason, reason)
                    and all(np.array_equal(a, b, equal_nan=True) for a, b in zip(cols, fcols))):
                study.fused_diff += 1
            study.scans += 1
            study.t_py.append(dp)
            study.t_k.append(dk)
            study.n_tracks += n
            study.n_nonzero += len(nz)
            # compare every non-deferred track's outcome
            kept = {id(k) for k in tr._tracks}
            nsus = tc.sustain_updates
            slow_texts = _slow_reason_texts(tc.v_min)
            tail = f" m/s ≤ v_min {tc.v_min:.2f}"
            cnt = [0, 0, 0, 0, 0]
            for i, k in enumerate(tracks):
                a = int(action[i])
                if a in (A_DEFER_UPD, A_DEFER_MISS):
                    study.n_defer += 1
                    continue
                if a in (A_DEL_TENT, A_DEL_COV, A_DEL_SPEED, A_DEL_COAST):
                    cnt[a - 1] += 1
                if a in (A_RETIRE, A_RETIRE_TENT):
                    cnt[4] += 1
                    continue  # (_retire: the track leaves the live list either way)
                if (a == A_KEEP) != (id(k) in kept):
                    study.mismatch.append(f"scan {study.scans} track {k.id}: kept {id(k) in kept} vs action {a}")
                    continue
                if a != A_KEEP:
                    continue
                sp = speeds[i]
                rc = int(reason[i])
                text = None
                if rc == R_TENT:
                    text = "not in M: tentative track"
                elif rc == R_SLOW:
                    text = _slow_reason(sp, slow_texts, tail)
                elif rc == R_FAST:
                    text = f"not in M: speed > v_min for {int(fast[i])}/{nsus} updates"
                elif rc == R_MOVING:
                    text = f"in M: speed {sp:.2f} m/s, moved {rdisp[i]:.2f} m since birth"

                def f(v):
                    return None if v != v else v
                mine = (bool(in_m[i]), int(fast[i]), f(slow[i]), bool(rem[i]), bool(rode[i]),
                        None if msx[i] != msx[i] else (msx[i], msy[i]), f(mlast[i]), mtime[i], mtravel[i])
                theirs = (k.in_m, k.fast, k.slow_since, k.remembered, k.rode, k.m_start_xy, k.m_last_t, k.m_time,
                          k.m_travel)
                if mine != theirs or (text is not None and text != k.reason):
                    study.mismatch.append(f"scan {study.scans} track {k.id}: {mine} {text!r} vs {theirs} "
                                          f"{k.reason!r}")
            after = (st.deleted_tentative, st.deleted_covariance, st.deleted_speed, st.deleted_coasting,
                     st.deleted_structure)
            py_cnt = [b - a for a, b in zip(before, after)]
            if cnt != py_cnt and not any(action[i] == A_DEFER_MISS for i in range(n)):
                study.mismatch.append(f"scan {study.scans}: deletions {cnt} vs {py_cnt}")

        return _manage


def run(name: str, data: Path, kern, fused) -> None:
    from dynslam2d.detect import tracker as tracker_mod
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    rel, topic = INPUTS.get(name, (name, None))
    scans = list(open_source(rel if rel.startswith("sim:") else str(data / rel), topic))
    study = Study(kern, fused)
    orig = tracker_mod.Tracker._manage
    tracker_mod.Tracker._manage = study.wrap(orig)
    # the rare paths' methods timed inside the Python loop (what a row kernel would still leave to Python per track)
    rare = {}
    for m in RARE:
        f = getattr(tracker_mod.Tracker, m)
        rare[m] = f

        def timed(self, *a, _f=f, **k):
            if study.depth:  # (nested: _dynamic → _remember; counted once)
                return _f(self, *a, **k)
            study.depth += 1
            t0 = clock()
            try:
                return _f(self, *a, **k)
            finally:
                study.t_rare[-1] += clock() - t0
                study.depth -= 1
        setattr(tracker_mod.Tracker, m, timed)
    try:
        pipe = Pipeline()
        for s in scans:
            pipe.process(s)
    finally:
        tracker_mod.Tracker._manage = orig
        for m, f in rare.items():
            setattr(tracker_mod.Tracker, m, f)
    w = 60  # (warm-up scans left out of the timing)
    tp, tk = np.array(study.t_py[w:]) / 1e3, np.array(study.t_k[w:]) / 1e3
    ns = study.scans
    print(f"{name}: {ns} scans, {study.n_tracks / ns:.1f} tracks a scan, deferred to Python "
          f"{study.n_defer / ns:.2f} a scan ({100 * study.n_defer / max(study.n_tracks, 1):.1f} %), non-kept "
          f"{study.n_nonzero / ns:.2f} a scan; mismatches {len(study.mismatch)}")
    for m in study.mismatch[:5]:
        print("   ", m)
    print(f"    _manage (Python, with manage_counters) median {np.median(tp):.1f} µs (mean {tp.mean():.1f}); "
          f"prototype (manage_counters + kernel + glue) median {np.median(tk):.1f} µs (mean {tk.mean():.1f}); "
          f"ratio of medians {np.median(tk) / np.median(tp):.3f}, median of per-scan differences "
          f"{np.median(tp - tk):.1f} µs")
    rare_t = np.array(study.t_rare[1:][w:]) / 1e3
    print(f"    rare-path methods inside the Python loop ({', '.join(RARE)}): mean {rare_t.mean():.1f} µs a scan, "
          f"median {np.median(rare_t):.1f}; scans with any {100 * np.mean(rare_t > 0):.0f} %")
    tf = np.array(study.t_f[w:]) / 1e3
    print(f"    fused (one call: manage_counters + the loop + the indices) median {np.median(tf):.1f} µs (mean "
          f"{tf.mean():.1f}); ratio to Python {np.median(tf) / np.median(tp):.3f}; scans where it differs from the "
          f"two-call prototype {study.fused_diff}")
    net = tp - rare_t - tk
    netf = tp - rare_t - tf
    print(f"    fused: saving with the rare paths in Python median {np.median(netf):.1f} µs, mean {netf.mean():.1f}")
    print(f"    saving with the rare paths still in Python (Python − rare − prototype, per scan): median "
          f"{np.median(net):.1f} µs, mean {net.mean():.1f}")
    parts = np.array(study.t_parts[w:]) / 1e3
    print("    prototype's parts, median µs: manage_counters {:.1f}, the new kernel {:.1f}, glue {:.1f}".format(
        *np.median(parts, axis=0)))


def compile_probe() -> None:
    """One cold compile of the prototype (cache=False), thread CPU and wall, in this (fresh) process."""
    import dynslam2d.detect.kernels_update  # noqa: F401 (its import and py_hypot's own compile are not counted)
    from dynslam2d.detect.kernels_update import py_hypot as ph
    ph(3.0, 4.0)
    kern = build(cache=False)
    n = 3
    i8, f8, b1 = np.zeros(n, np.int8), np.zeros(n), np.zeros(n, np.bool_)
    i64 = np.zeros(n, np.int64)
    args = (i8, f8, f8.copy(), i64, i64.copy(), np.zeros((4, 3), np.int64), np.zeros((4, 5, 3)), np.zeros((4, 4)),
            i64.copy(), b1, b1.copy(), b1.copy(), b1.copy(), i64.copy(), b1.copy(), b1.copy(), f8.copy(), f8.copy(),
            f8.copy(), f8.copy(), f8.copy(), f8.copy(), f8.copy(), f8.copy(), i64.copy(), np.zeros(11), 0.0,
            np.zeros(n, np.int8), np.zeros(n, np.int8), f8.copy())
    w0, c0 = time.perf_counter(), time.process_time()
    kern(*args)
    w1, c1 = time.perf_counter(), time.process_time()
    print(f"cold compile, the row loop: wall {w1 - w0:.3f} s, CPU {c1 - c0:.3f} s")
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline
    pipe = Pipeline()  # (the library's kernels loaded from its cache with the types the tracker passes)
    for s in list(open_source("sim:paper", None))[:40]:
        pipe.process(s)
    tr = pipe.tracker
    rows = np.zeros(n, np.int64)
    fused = build_fused(kern, cache=False)
    w0, c0 = time.perf_counter(), time.process_time()
    fused(tr._P, tr._X, tr._CI.copy(), tr._CL.copy(), tr._WN, rows, tr._upd_p, 0.0, tr._MEV, *args[8:26], args[27],
          args[28], args[29])
    print(f"cold compile, fused (manage_counters from the library's cache as a callee + the loop): wall "
          f"{time.perf_counter() - w0:.3f} s, CPU {time.process_time() - c0:.3f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="*")
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    ap.add_argument("--compile", action="store_true", help="measure the cold compile in 3 fresh processes")
    ap.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.probe:
        compile_probe()
        return
    if a.compile:
        for _ in range(3):
            subprocess.run([sys.executable, __file__, "--probe"], check=True)
        return
    kern = build(cache=True)
    fused = build_fused(kern, cache=True)
    for name in a.inputs:
        run(name, a.data, kern, fused)


if __name__ == "__main__":
    main()
