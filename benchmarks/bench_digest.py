"""Output digests of the whole pipeline on 12 inputs, to check a speed change leaves every output bit-identical
(not run by pytest).

For each input the pipeline (default configuration) runs over every scan, with the collector setting of
``pipeline.run``'s loop (``bench_pipeline.scan_loop_gc``); a SHA-256 digest is taken of everything a scan
produced (pose, score, flags, removed beams and by which track, body beams, every track's id, state, box,
velocity, covariance, hits, misses, kind, in_m, m_reason, beams) and, at the end, of every map level's log-odds,
probability cache and update indices. Two checkouts agree when every line matches.

    python benchmarks/bench_digest.py [--only negative_2 sim:crowd ...] [--json out.json]
    python benchmarks/bench_digest.py --compare ../main/src     # runs both checkouts, prints the differences

With ``--compare`` this checkout's digests are computed in this process and the other checkout's in a
subprocess (``PYTHONPATH=<other>``); ``--cache FILE`` keeps the other checkout's digests between calls
(recomputed when the file is missing).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: name → (input relative to the data folder or sim:…, topic)
INPUTS: dict[str, tuple[str, str | None]] = {
    "negative_2/left": ("dynamic/leg_tracker/negative_2.bag", "/left_scan"),
    "negative_2/rear": ("dynamic/leg_tracker/negative_2.bag", "/rear_scan"),
    "negative_2/right": ("dynamic/leg_tracker/negative_2.bag", "/right_scan"),
    "positive_7": ("dynamic/leg_tracker/positive_7.bag", None),
    "positive_1": ("dynamic/leg_tracker/positive_1.bag", None),
    "demo": ("dynamic/leg_tracker/demo_stationary_simple_environment.bag", None),
    "overtakes": ("dynamic/datmo/overtakes.bag", None),
    "mit-csail": ("mit-csail/mit-csail.clf", None),
    "sim:drive": ("sim:drive", None),
    "sim:crowd": ("sim:crowd", None),
    "sim:stop-and-go": ("sim:stop-and-go", None),
    "sim:corridor": ("sim:corridor", None),
}


def _h(h, *arrays) -> None:
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())


def digest(data: Path, name: str) -> dict[str, str] | None:
    """{"steps": digest of every StepResult, "map": digest of the map levels, "scans": count}; None if absent."""
    from bench_pipeline import scan_loop_gc  # (this script's folder)

    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import Pipeline

    rel, topic = INPUTS[name]
    path = rel if rel.startswith("sim:") else str(data / rel)
    if not rel.startswith("sim:") and not Path(path).exists():
        return None
    pipe = Pipeline()
    hs = hashlib.sha256()
    n = 0
    with scan_loop_gc():  # pipeline.run's collector setting (a checkout without it: none)
        for scan in open_source(path, topic):
            s = pipe.process(scan)
            n += 1
            _h(hs, np.array([s.pose.x, s.pose.y, s.pose.theta, s.score, s.degeneracy, s.support_spread]),
               np.array([s.map_updated, s.rejected, s.skipped, s.degenerate, s.low_support]),
               np.array([s.support_points]), s.removed, s.removed_by, s.body)
            hs.update(f"{s.reason}|{s.pose_source}|{s.slam_state}".encode())
            for t in s.tracks:
                b = t.box
                hs.update(f"{t.id}|{t.state}|{t.kind}|{t.in_m}|{t.m_reason}|{t.hits}|{t.misses}|"
                          f"{t.remembered}".encode())
                _h(hs, np.array([t.stamp, b.px, b.py, b.theta, b.length, b.width, t.age]), t.velocity,
                   t.covariance, t.beams if t.beams is not None else np.zeros(0))
    hm = hashlib.sha256()
    for lv in pipe.slam.map.levels:
        # (a never-updated cell's update index is −1 before pass mem43, 0 since: hashed as 0 for both; a scan's
        # indices are >= 1)
        # (the probability cache's uint32 words since pass mem52 — a float32's bits XOR 0.5's — hashed decoded, as the
        # float32 probabilities of before)
        prob = lv.prob if lv.prob.dtype != np.uint32 else (lv.prob ^ np.uint32(0x3F000000)).view(np.float32)
        _h(hm, np.array([lv.i0, lv.j0, lv.update_counter]), lv.logodds, prob, np.maximum(lv.uidx, 0))
    if pipe.ledger is not None:
        hm.update(json.dumps(pipe.ledger.summary(), sort_keys=True).encode())
    return {"scans": str(n), "steps": hs.hexdigest()[:16], "map": hm.hexdigest()[:16]}


def run_all(data: Path, names: list[str]) -> dict[str, dict[str, str] | None]:
    out = {}
    for name in names:
        out[name] = digest(data, name)
        print(f"{name:<18} {json.dumps(out[name])}", file=sys.stderr, flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="+", default=None, help="inputs whose name contains one of these")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--json", type=Path, default=None, help="write this checkout's digests here")
    ap.add_argument("--compare", type=Path, default=None, help="the other checkout's src/")
    ap.add_argument("--cache", type=Path, default=None, help="the other checkout's digests (read / written)")
    args = ap.parse_args()
    names = [n for n in INPUTS if args.only is None or any(o in n for o in args.only)]
    if args.compare is None:
        res = run_all(args.data, names)
        if args.json is not None:
            args.json.write_text(json.dumps(res, indent=1))
        else:
            print(json.dumps(res, indent=1))
        return
    other: dict = {}
    if args.cache is not None and args.cache.exists():
        other = json.loads(args.cache.read_text())
    missing = [n for n in names if n not in other]
    if missing:
        env = dict(os.environ, PYTHONPATH=str(args.compare.resolve()))
        cmd = [sys.executable, str(Path(__file__).resolve()), "--data", str(args.data), "--only", *missing]
        got = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout)
        other.update(got)
        if args.cache is not None:
            args.cache.write_text(json.dumps(other, indent=1))
    this = run_all(args.data, names)
    same = absent = 0
    for n in names:
        if this[n] is None or other.get(n) is None:  # a recording not under --data: nothing was compared
            absent += 1
            print(f"{n:<18} ABSENT     (no {INPUTS[n][0]} under {args.data}: pass --data)")
            continue
        ok = this[n] == other.get(n)
        same += ok
        print(f"{n:<18} {'identical' if ok else 'DIFFERENT'}  this {this[n]}  other {other.get(n)}")
    print(f"{same} / {len(names)} inputs identical" + (f", {absent} absent (not compared)" if absent else ""))
    if same != len(names):
        sys.exit(1)


if __name__ == "__main__":
    main()
