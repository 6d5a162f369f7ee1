"""Where the track stage's kernels lose their time inside the pipeline: the in-situ cost against replays that add one
factor at a time (not run by pytest).

The ``track`` stage's kernel calls (``bench_track_kernels.TARGETS``) are wrapped where the tracker's modules call
them. After a 60-scan warm-up, three pipelines run over the input, each with ``pipeline.run``'s collector setting:

* ``clean``: each call timed (thread CPU) and nothing else; ``Tracker.update`` timed as a whole (the Python between
  the kernels is the update's time less its kernels');
* ``copy``: each call's arguments copied just before it and dropped (as ``record`` without keeping them);
* ``record``: each call's arguments copied just before it (arrays below 200 000 elements; the map view by
  reference) for the replays, then timed: the copy reads every argument, so this is the in-situ cost with the
  arguments' data warm ("prefetched");
* ``dispatch``: before each call a no-op kernel with the same arguments (same types: the dispatcher's type check and
  the arguments' unboxing, nothing else) is called and timed, then the kernel: the dispatch part in situ.

Then every scan's recorded calls are replayed, in the scan's order, in these contexts (fresh copies of the scan's
array arguments made before the context, outside the timing), the ``seq`` contexts alternated in blocks of 50 scans
so that the machine's load drifts under all of them alike; at the end a fourth ``clean`` pipeline repeats the
in-situ figure:

* ``iso``: each kernel's calls back to back (``bench_track_kernels.py``'s warm figure);
* ``seq``: scan after scan, the scan's calls in their order, nothing between scans (other kernels interleaved: the
  code-cache and branch-predictor part that interleaving alone costs);
* ``seq+N MB``: N MB (1, 4, 16) of a buffer written between scans (data caches and TLB);
* ``seq+stages``: between scans, a second pipeline (its tracker's ``update`` stubbed to return no tracks) processes
  the same scan: the matcher, the filter, the map update, the ledger and the loop closer run for real, their code and
  data evicting the tracker's;
* ``noop seq`` / ``noop seq+stages``: the scans' calls replaced by the same-argument no-ops (dispatch alone, warm
  and after the stages).

NRT allocations (``numba``'s own counters) are counted in the ``seq`` replay; their warm price is measured by a
kernel that makes and frees as many arrays of the median size. Printed per input: the kernels' sum a scan (median
over scans, µs) in every context, each context's share of the in-situ − iso gap, and per kernel the in-situ, iso,
``seq+stages`` medians.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_kernel_context.py sim:paper sim:crowd negative_2/right
        [--rounds 2] [--data <data>]

Inputs: the names of ``bench_digest.py`` or a built-in scene (``sim:NAME``). ``--rounds`` repeats the whole
measurement (in-situ runs and replays, in the same order) so the load's drift shows.
"""

from __future__ import annotations

import argparse
import importlib
import resource
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import scan_loop_gc  # noqa: E402
from bench_track_kernels import TARGETS, _copy, warmed_scans  # noqa: E402

clock = time.thread_time_ns
MBS = (1, 4, 16)
BLOCK = 50  # scans a replay context runs before the next context's turn


def _noop_for(n_args: int):
    """A no-op njit kernel of ``n_args`` arguments (its dispatcher checks and unboxes them, its body returns 0)."""
    from dynslam2d.jitbox import njit

    names = ", ".join(f"a{i}" for i in range(n_args))
    ns: dict = {}
    exec(f"def noop({names}):\n    return 0\n", ns)  # noqa: S102 (a probe of the benchmark's own)
    return njit(cache=False)(ns["noop"])


class Wrapped:
    """The tracker's kernels wrapped where its modules look them up; ``mode`` picks what a call records."""

    def __init__(self) -> None:
        self.kernels: dict = {}
        self.undo: list = []
        self.mode = "off"
        self.noops: dict = {}
        self.scan: list = []  # this scan's calls: (name, args copy or None, µs in situ, no-op µs or 0)
        for modname, n in TARGETS:
            mod = importlib.import_module(modname)
            f = getattr(mod, n)
            self.kernels[n] = f
            self.undo.append((mod, n, f))
            setattr(mod, n, self._wrap(n, f))

    def _wrap(self, n: str, f):
        def timed(*a):
            mode = self.mode
            if mode == "off":
                return f(*a)
            rec = None
            t_noop = 0
            if mode == "record":
                rec = _copy(a)
            elif mode == "copy":
                _copy(a)
            elif mode == "dispatch":
                g = self.noops.get(n)
                if g is None:
                    g = self.noops[n] = _noop_for(len(a))
                    g(*a)  # (compiled outside the timing)
                t0 = clock()
                g(*a)
                t_noop = clock() - t0
            t0 = clock()
            r = f(*a)
            self.scan.append((n, rec, clock() - t0, t_noop))
            return r
        return timed

    def restore(self) -> None:
        for mod, n, f in self.undo:
            setattr(mod, n, f)


def _situ(scans: list, w: Wrapped, mode: str) -> tuple[list, list, list]:
    """One pipeline over ``scans`` with the wrappers in ``mode``: per scan its calls, ``Tracker.update``'s ns and
    the minor page faults during it."""
    from dynslam2d.detect import tracker as tracker_mod
    from dynslam2d.pipeline import Pipeline

    update = tracker_mod.Tracker.update
    per_scan: list = []
    upd: list = []
    faults: list = []

    def timed_update(self, *a, **k):
        f0 = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
        t0 = clock()
        r = update(self, *a, **k)
        upd.append(clock() - t0)
        faults.append(resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - f0)
        return r

    tracker_mod.Tracker.update = timed_update
    try:
        pipe = Pipeline()
        w.mode = mode
        with scan_loop_gc():
            for s in scans:
                w.scan = []
                pipe.process(s)
                per_scan.append(w.scan)
    finally:
        w.mode = "off"
        tracker_mod.Tracker.update = update
    return per_scan, upd, faults


def _stages_pipeline(scans: list):
    """A pipeline whose tracker returns no tracks (the other stages run for real), warmed on the first scans."""
    from dynslam2d.pipeline import Pipeline

    p = Pipeline()
    p.tracker.update = lambda *a, **k: []
    return p


def _replay(recorded: list, idx: range, kernels: dict, between, noops: dict | None = None,
            count: bool = False) -> tuple:
    """Replay the calls of scans ``idx`` in order, ``between(i)`` called before scan ``i``'s (after its copies are
    made). Returns per scan the kernels' ns sum, per call (name, ns), NRT allocations per scan."""
    from numba.core.runtime import _nrt_python as nrt

    sums, per_call, allocs = [], [], []
    for i in idx:
        copies = [(n, _copy(a)) for n, a, _, _ in recorded[i]]
        between(i)
        tot = 0
        a0 = nrt.memsys_get_stats_alloc() if count else 0
        for n, a in copies:
            f = noops[n] if noops is not None else kernels[n]
            t0 = clock()
            f(*a)
            dt = clock() - t0
            tot += dt
            per_call.append((n, dt))
        if count:
            allocs.append(nrt.memsys_get_stats_alloc() - a0)
        sums.append(tot)
    return sums, per_call, allocs


def _iso(recorded: list, kernels: dict) -> tuple[list, list]:
    """Each kernel's calls back to back (best of two passes per call): per scan the sum, per call (name, ns)."""
    index = [(i, j) for i, calls in enumerate(recorded) for j in range(len(calls))]
    best: dict = {}
    for _ in range(2):
        for n in kernels:
            for i, j in index:
                name, a, _, _ = recorded[i][j]
                if name != n:
                    continue
                a2 = _copy(a)
                t0 = clock()
                kernels[n](*a2)
                dt = clock() - t0
                best[(i, j)] = min(best.get((i, j), dt), dt)
    sums = [sum(best[(i, j)] for j in range(len(c))) for i, c in enumerate(recorded)]
    return sums, [(recorded[i][j][0], best[(i, j)]) for i, j in index]


def _alloc_price(n_elems: int, k: int) -> float:
    """Warm ns of ``k`` NRT allocations (and frees) of ``n_elems`` float64, a kernel's only work."""
    from dynslam2d.jitbox import njit

    @njit(cache=False)
    def allocs(n: int, k: int) -> float:
        s = 0.0
        for _ in range(k):
            a = np.empty(n)
            a[0] = 1.0
            s += a[0]
        return s

    @njit(cache=False)
    def none(n: int, k: int) -> float:
        s = 0.0
        for _ in range(k):
            s += 1.0
        return s

    allocs(n_elems, k)
    none(n_elems, k)
    ta, tn = [], []
    for _ in range(2000):
        t0 = clock()
        allocs(n_elems, k)
        ta.append(clock() - t0)
        t0 = clock()
        none(n_elems, k)
        tn.append(clock() - t0)
    return (float(np.median(ta)) - float(np.median(tn))) / k


def _med_us(x) -> float:
    return float(np.median(x)) / 1e3 if len(x) else float("nan")


def _per_kernel(calls_by_scan: list) -> dict:
    out: dict = {}
    for calls in calls_by_scan:
        for c in calls:
            out.setdefault(c[0], []).append(c[2])
    return out


def run(name: str, data: Path, rounds: int) -> None:
    from numba.core.runtime import _nrt_python as nrt


    scans = warmed_scans(name, data)
    w = Wrapped()
    try:
        print(f"{name}: {len(scans)} scans; the track stage's kernels, µs a scan (median over scans; thread CPU)")
        for rnd in range(rounds):
            clean, upd, f_clean = _situ(scans, w, "clean")
            copied, _, f_copy = _situ(scans, w, "copy")
            rec, _, f_rec = _situ(scans, w, "record")
            disp, _, _ = _situ(scans, w, "dispatch")
            keep = [i for i, c in enumerate(rec) if c]  # (scans with kernel calls)
            recorded = [rec[i] for i in keep]
            situ = [sum(c[2] for c in clean[i]) for i in keep]
            rows = {"in situ (clean)": situ,
                    "in situ, arguments copied first (dropped)": [sum(c[2] for c in copied[i]) for i in keep],
                    "in situ, arguments copied first (kept)": [sum(c[2] for c in r) for r in recorded],
                    "in situ, same-argument no-op first": [sum(c[2] for c in disp[i]) for i in keep],
                    "same-argument no-ops in situ (dispatch alone)": [sum(c[3] for c in disp[i]) for i in keep]}
            py = [u - s for u, s in zip([upd[i] for i in keep], situ, strict=True)]
            iso, iso_calls = _iso(recorded, w.kernels)
            rows["iso (warm, each kernel back to back)"] = iso
            for r in recorded:
                for n, a, _, _ in r:
                    if n not in w.noops:
                        w.noops[n] = _noop_for(len(a))
            src = [scans[i] for i in keep]
            bufs = {mb: np.zeros(mb * (1 << 20) // 8) for mb in MBS}

            def dirty(i: int, mb: int, bufs: dict = bufs) -> None:
                bufs[mb] += 1.0  # (reads and writes every line and page of the buffer)

            p2, p3 = _stages_pipeline(scans), _stages_pipeline(scans)
            contexts = [("seq (scan order)", lambda i: None, None)]
            contexts += [(f"seq + {mb} MB written between scans", lambda i, mb=mb: dirty(i, mb), None) for mb in MBS]
            contexts += [("seq + the other stages between scans", lambda i, p=p2, s=src: p.process(s[i]), None),
                         ("noop seq (dispatch alone, warm)", lambda i: None, w.noops),
                         ("noop seq + the other stages", lambda i, p=p3, s=src: p.process(s[i]),
                          w.noops)]
            stage_calls: list = []
            for k, _, _ in contexts:
                rows[k] = []
            with scan_loop_gc():  # (the contexts alternated in blocks of scans: the load's drift shared)
                for start in range(0, len(recorded), BLOCK):
                    blk = range(start, min(start + BLOCK, len(recorded)))
                    for k, between, noops in contexts:
                        sums, per_call, _ = _replay(recorded, blk, w.kernels, between, noops)
                        rows[k] += sums
                        if k == "seq + the other stages between scans":
                            stage_calls += per_call
            nrt.memsys_enable_stats()
            allocs = _replay(recorded, range(len(recorded)), w.kernels, lambda i: None, count=True)[2]
            nrt.memsys_disable_stats()
            again, _, _ = _situ(scans, w, "clean")
            rows["in situ (clean), again after the replays"] = [sum(c[2] for c in again[i]) for i in keep]
            s_us, i_us = _med_us(situ), _med_us(iso)
            gap = s_us - i_us
            print(f" round {rnd + 1}: {len(keep)} scans with calls, {np.mean([len(r) for r in recorded]):.1f} calls a "
                  f"scan; Tracker.update less its kernels (Python): {_med_us(py):.1f} µs; "
                  f"gap in situ − iso {gap:.1f} µs")
            for k, v in rows.items():
                m = _med_us(v)
                share = (m - i_us) / gap if gap > 0 else float("nan")
                print(f"   {k:42s} {m:7.1f}  (above iso: {m - i_us:6.1f} = {100 * share:5.1f} % of the gap)")
            print(f"   minor page faults in Tracker.update, mean a scan: clean {np.mean(f_clean):.2f}, copies "
                  f"dropped {np.mean(f_copy):.2f}, copies kept {np.mean(f_rec):.2f}")
            na = float(np.median(allocs))
            price = _alloc_price(700, max(int(round(na)), 1))
            print(f"   NRT allocations a scan (seq): median {na:.0f}, mean {np.mean(allocs):.1f}; warm price "
                  f"{price:.0f} ns each (700 float64) -> {na * price / 1e3:.1f} µs a scan")
            kc = _per_kernel([clean[i] for i in keep])
            ki: dict = {}
            for n, dt in iso_calls:
                ki.setdefault(n, []).append(dt)
            ks: dict = {}
            for n, dt in stage_calls:
                ks.setdefault(n, []).append(dt)
            kd = _per_kernel([[(c[0], None, c[3]) for c in disp[i]] for i in keep])
            print("   per kernel, µs a call (median): in situ / iso / seq+stages / same-argument no-op in situ; "
                  "calls a scan")
            for n in w.kernels:
                if n in kc:
                    print(f"     {n:22s} {_med_us(kc[n]):6.1f} / {_med_us(ki[n]):6.1f} / {_med_us(ks[n]):6.1f} / "
                          f"{_med_us(kd[n]):5.2f}  {len(kc[n]) / len(keep):.2f}")
    finally:
        w.restore()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = ap.parse_args()
    for name in args.inputs:
        run(name, args.data, args.rounds)


if __name__ == "__main__":
    main()
