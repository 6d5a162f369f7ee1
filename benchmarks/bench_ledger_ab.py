"""The evidence ledger's methods, this ``slam/erasure.py`` against another one, in lockstep in one process (not run
by pytest).

``bench_pipeline_ab.py`` compares whole checkouts scan by scan; the ledger's share of a scan (≈ 0.1–0.25 ms of
1–2 ms) moves by less than that harness resolves. Here two pipelines of this checkout run the input side by side,
scan by scan (which one goes first alternates), the first with the other file's ``EvidenceLedger`` (loaded as a
module of its own, everything else this checkout's), and the thread CPU of each ledger method
(``observe``, ``before_update``, ``after_update``, ``erase_entering``) is timed in place. Both ledgers' summaries
must be equal at the end (the same counters: the two files record the same evidence). The kernels
(``slam/ledgerkernels.py``) are this checkout's on both sides unless ``--kernels`` gives the other side the
``ledgerkernels.py`` beside its file. Printed: per method the median and mean µs of each side and their ratios, and
the mean per scan of all four.

Two pipelines share one process: their caches evict each other's data, so the per-call figures run higher than
in ``bench_pipeline_ab.py --parts``; and the garbage collector is the process's: its passes land in either side.
``--gc`` prints the process's collections and their CPU (one pipeline per side is still two: use it on one
checkout at a time, or compare ``--gc`` runs of ``--only``). The scan loop runs with the collector setting of
``pipeline.run``'s loop (``bench_pipeline.scan_loop_gc``; none in a checkout before it).

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_ledger_ab.py negative_2/right \\
        --other <base>/src/dynslam2d/slam/erasure.py [--reps 2] [--kernels]
    PYTHONPATH=src taskset -c 1 python benchmarks/bench_ledger_ab.py negative_2/right --only --gc
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import importlib.util
import inspect
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import scan_loop_gc  # noqa: E402 - pipeline.run's collector setting (before it: none)
from kernelwarm import preload  # noqa: E402

WARMUP = 60
METHODS = ("observe", "before_update", "after_update", "erase_entering")


def _load(path: Path, name: str = "erasure_other"):
    """The module at ``path`` (an ``erasure.py``), imported under a name of its own."""
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # (dataclasses look their module up while the class is made)
    spec.loader.exec_module(mod)
    return mod


def _load_other(path: Path, kernels: bool):
    """The other ``erasure.py``; with ``kernels``, its ledger reads the ``ledgerkernels.py`` beside it (imported
    under a name of its own, numba's cache its own) instead of this checkout's.

    The kernels are loaded from a copy in a folder of the temporary directory named by the file's content, not
    from the other checkout's path: numba keys its cache by the source's path and records the module's name in it,
    so loading them from their own path under another name left cache entries that the other checkout's own
    imports then loaded and failed on (``No module named 'ledgerkernels_other'``; pass led36)."""
    mod = _load(path)
    if kernels:
        text = path.with_name("ledgerkernels.py").read_bytes()
        folder = Path(tempfile.gettempdir()) / "bench_ledger_ab" / hashlib.sha1(text).hexdigest()[:16]
        folder.mkdir(parents=True, exist_ok=True)
        copy = folder / "ledgerkernels.py"
        if not copy.exists() or copy.read_bytes() != text:
            copy.write_bytes(text)
        mod._lk = _load(copy, "ledgerkernels_other")
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", choices=sorted(INPUTS))
    ap.add_argument("--other", type=Path, help="the other erasure.py")
    ap.add_argument("--only", action="store_true", help="this checkout's ledger alone (one pipeline)")
    ap.add_argument("--kernels", action="store_true",
                    help="the other side also with the ledgerkernels.py beside its erasure.py (else this checkout's)")
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--gc", action="store_true", help="also the garbage collector's passes and CPU")
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = ap.parse_args()
    if not args.only and args.other is None:
        ap.error("--other or --only")

    import dynslam2d.pipeline as pl
    import dynslam2d.slam.erasure as this
    from dynslam2d.inputs import open_source

    rel, topic = INPUTS[args.input]
    scans = list(open_source(rel if rel.startswith("sim:") else str(args.data / rel), topic))
    sides = {"this": this} if args.only else {"other": _load_other(args.other, args.kernels), "this": this}
    tn = time.thread_time_ns
    times: dict[tuple[str, str], list[int]] = {}
    gc_ns = [0, 0]

    def on_gc(phase: str, info: dict) -> None:
        if phase == "start":
            gc_ns[1] = tn()
        else:
            gc_ns[0] += tn() - gc_ns[1]

    def timed(obj, tag: str) -> None:
        for k in METHODS:
            f = getattr(obj, k)

            def w(*a, _f=f, _k=k, **kw):
                t0 = tn()
                r = _f(*a, **kw)
                times.setdefault((tag, _k), []).append(tn() - t0)
                return r
            setattr(obj, k, w)

    def pipeline(mod):
        p = pl.Pipeline()
        old = p.ledger
        p.ledger = mod.EvidenceLedger(old.config, old.laser_min_dist, old.laser_max_dist, keep_beams=old.keep_beams)
        obs = p.ledger.observe
        if "states" not in inspect.signature(obs).parameters:  # (a ledger before pass led32: no tracker states)
            p.ledger.observe = lambda tracks, removing, stamp, states=None: obs(tracks, removing, stamp)
        return p

    for mod in sides.values():  # warm-up: kernels compiled or loaded, first calls made
        w = pipeline(mod)
        for s in scans[:WARMUP]:
            w.process(s)
    del w
    preload(extra=sides.values())  # (kernels first called after the warm-up, either side's ledger's)
    if args.gc:
        gc.callbacks.append(on_gc)
        before = [g["collections"] for g in gc.get_stats()]
    summaries: dict[str, list] = {tag: [] for tag in sides}
    for _ in range(args.reps):
        pipes = {tag: pipeline(mod) for tag, mod in sides.items()}
        for tag, p in pipes.items():
            timed(p.ledger, tag)
        order = list(pipes.values())
        with scan_loop_gc():
            for i, s in enumerate(scans):
                for p in (order if i % 2 else order[::-1]):
                    p.process(s)
        for tag, p in pipes.items():
            summaries[tag].append(p.ledger.summary())
    if not args.only and summaries["other"] != summaries["this"]:
        raise SystemExit(f"the ledgers' summaries differ: {summaries}")
    n = len(times[("this", "observe")])
    print(f"{args.input}: {n} scans ({args.reps} rep(s)); thread CPU µs per call")
    total = {}
    for tag in sides:
        total[tag] = sum(sum(times.get((tag, k), [])) for k in METHODS) / n / 1e3
    for k in METHODS:
        b = times.get(("this", k), [])
        if not b:
            continue
        med, mean = statistics.median(b) / 1e3, statistics.mean(b) / 1e3
        line = f"  {k:14s} n={len(b):5d}  this median {med:7.2f} mean {mean:7.2f}"
        if not args.only:
            a = times[("other", k)]
            line += (f"  | other median {statistics.median(a) / 1e3:7.2f} mean {statistics.mean(a) / 1e3:7.2f}"
                     f"  | ratio median {statistics.median(b) / statistics.median(a):.3f}"
                     f" mean {statistics.mean(b) / statistics.mean(a):.3f}")
        print(line)
    line = f"  all four, mean per scan: this {total['this']:.2f}"
    if not args.only:
        line += f", other {total['other']:.2f}, ratio {total['this'] / total['other']:.3f}"
    print(line)
    if args.gc:
        after = [g["collections"] for g in gc.get_stats()]
        print(f"  garbage collections (generations 0, 1, 2): {[a - b for a, b in zip(after, before)]}, "
              f"CPU {gc_ns[0] / 1e6:.1f} ms")


if __name__ == "__main__":
    main()
