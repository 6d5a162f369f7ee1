"""Thread CPU per top-level statement of one function of the per-scan path, in situ (not run by pytest).

``bench_pipeline_ab.py --parts`` wraps ≈ 30 callables in timers (≈ 1 µs each, ≈ 0.6 µs of it charged to the
caller), which inflates the parents' "unattributed" time. This probe instead recompiles ONE function with a
thread-CPU mark after each of its top-level statements (a statement that holds a block — ``if``, ``for`` — is
timed whole; a ``return`` statement is not) and runs the pipeline over the input: no wrapper around any callee, one
mark ≈ 0.3–0.4 µs. Printed per statement: median µs over the scans that update the map and over the others, and the
mean over all scans.

    PYTHONPATH=src taskset -c 0 python benchmarks/bench_pipeline_lines.py sim:paper \\
        [--func dynslam2d.pipeline.Pipeline.process] [--data <data>] [--min-us 0.9]

``--func`` takes ``module.Class.method`` or ``module.function`` (a module function is replaced in its own module
only: callers that imported it by name keep the original). Inputs: the names of ``bench_digest.py`` or a built-in
scene (``sim:NAME``), or ``ten-movers`` (:func:`scenes.input_scans`). The pipeline is warmed on the first 60 scans
first (a throw-away one), and the scan loop runs with ``pipeline.run``'s collector setting, as
``bench_pipeline_ab.py``'s workers do.
"""

from __future__ import annotations

import argparse
import ast
import collections
import importlib
import inspect
import sys
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_digest import INPUTS  # noqa: E402
from bench_pipeline import scan_loop_gc  # noqa: E402
from scenes import input_scans  # noqa: E402 - an input's scans (bench_digest's, a built-in scene or ten-movers)

WARMUP = 60


def _target(path: str) -> tuple[object, str, dict]:
    """(the object holding the function, its name, the module's namespace) of ``module[.Class].name``."""
    parts = path.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        try:
            mod = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        owner = mod
        for p in parts[cut:-1]:
            owner = getattr(owner, p)
        return owner, parts[-1], mod.__dict__
    raise SystemExit(f"cannot import {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input", help=f"{', '.join(sorted(INPUTS))} or a built-in scene (sim:NAME)")
    ap.add_argument("--func", default="dynslam2d.pipeline.Pipeline.process")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--min-us", type=float, default=0.0, help="print only statements above this (median or mean)")
    args = ap.parse_args()

    import numpy as np

    from dynslam2d.pipeline import Pipeline

    owner, name, namespace = _target(args.func)
    src = textwrap.dedent(inspect.getsource(getattr(owner, name)))
    tree = ast.parse(src)
    fn = tree.body[0]
    body = [ast.parse("_MARK(0)").body[0]]
    for st in fn.body:
        body += [st, ast.parse(f"_MARK({st.lineno})").body[0]]
    fn.body = body
    fn.decorator_list = []
    ast.fix_missing_locations(tree)
    acc: collections.Counter = collections.Counter()
    last = [0]
    clock = time.thread_time_ns

    def _mark(line: int) -> None:
        t = clock()
        acc[line] += t - last[0]
        last[0] = clock()

    ns = dict(namespace)
    ns["_MARK"] = _mark
    exec(compile(tree, f"<{args.func}>", "exec"), ns)  # noqa: S102 - the function's own source, with marks
    setattr(owner, name, ns[name])

    scans = input_scans(args.data, args.input)
    warm = Pipeline()
    for s in scans[:WARMUP]:
        warm.process(s)
    del warm
    pipe = Pipeline()
    rows, upd = [], []
    with scan_loop_gc():
        for s in scans:
            acc.clear()
            last[0] = clock()
            step = pipe.process(s)
            rows.append(dict(acc))
            upd.append(bool(step.map_updated))
    u = np.array(upd)
    lines = src.splitlines()
    print(f"{args.input}: {len(scans)} scans, {int(u.sum())} update the map; {args.func}, thread CPU µs per statement "
          "(line 0: from the scan's start to the function's first statement)")
    print(f"  {'line':>4} {'updating':>9} {'other':>9} {'mean':>9}  statement")
    for ln in sorted({k for r in rows for k in r}):
        v = np.array([r.get(ln, 0) / 1e3 for r in rows])
        med_u = float(np.median(v[u])) if u.any() else 0.0
        med_o = float(np.median(v[~u])) if (~u).any() else 0.0
        if max(med_u, med_o, v.mean()) < args.min_us:
            continue
        text = lines[ln - 1].strip()[:80] if ln else "(before the first statement)"
        print(f"  {ln:4d} {med_u:9.1f} {med_o:9.1f} {v.mean():9.1f}  {text}")


if __name__ == "__main__":
    main()
