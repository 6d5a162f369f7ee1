"""Front-end jumps and the loop closer's view of a drifted stretch (docs/slam.md, "negative_2: the stretch that maps
walls twice"; not run by pytest).

``steps RUN_DIR...``: for each run folder (``dynslam2d run ... --out RUN_DIR``), the scans whose front-end step
exceeds the motion before it the most (:func:`dynslam2d.slam.jumps.step_excess`: excess m over both predictions,
in predicted steps, rotation excess °), the scans flagged as jumps with the folder's configuration, the steps around
the largest, and how far the optimised trajectory (``trajectory.tum``) is from the front end's
(``trajectory_frontend.tum``)::

    python benchmarks/bench_jumps.py steps results/n2r results/csail

``reference RUN_DIR LOG [--window A:B]``: for a run of a CARMEN log whose pose fields are corrected poses (the
flirtlib logs' TORO poses, GMapping's ``*-corrected.log.gz``), each flagged step of the front end
(``trajectory_frontend.tum``) against the same two scans' step in the log's ``laser_pose``: fine (< 0.1 m off) or
wrong (>= 0.25 m); the same for the constant-velocity prediction alone (the rule before the constant-step one
joined it); the rule on the corrected poses themselves; how the time steps relate to the steps; what other
``jump_shift`` / ``jump_ratio`` (and a regular-time-step guard) would flag; with ``--window`` each pose of scans
A..B-1 relative to scan A-1 in both::

    python benchmarks/bench_jumps.py reference results/intel ../shared/data/intel/intel-lab.flirtlib.log

``loops INPUT [KEY=VALUE...] [--topic T] [--nodes A:B]``: one run with the loop closer's local searches traced:
for every keyframe in A:B and submap searched, the correlative score and runner-up, how far the match moved the
keyframe from the front end's pose, and the refined match's support (count, share of the query points) against
the acceptance bounds (``loop.min_support``, ``min_support_share``, ``min_spread``)::

    python benchmarks/bench_jumps.py loops ../shared/data/dynamic/leg_tracker/negative_2.bag --topic /right_scan \\
        --nodes 190:211
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from dynslam2d.config import Config, with_assignments
from dynslam2d.slam.jumps import jump_flags, model_excess, step_excess


def _tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps s, poses (n, 3) x, y, θ) of a TUM trajectory file (planar: θ from the quaternion's z, w)."""
    a = np.loadtxt(path)
    return a[:, 0], np.column_stack((a[:, 1], a[:, 2], 2 * np.arctan2(a[:, 6], a[:, 7])))


def steps(dirs: list[str]) -> None:
    for d in map(Path, dirs):
        t, p = _tum(d / ("trajectory_frontend.tum" if (d / "trajectory_frontend.tum").exists() else "trajectory.tum"))
        sc = Config.model_validate(__import__("yaml").safe_load((d / "config.yaml").read_text())).slam \
            if (d / "config.yaml").exists() else Config().slam
        shift, turn, ratio = step_excess(t, p)
        flag = jump_flags(t, p, sc.jump_shift, sc.jump_ratio, sc.jump_turn)[0]
        top = np.argsort(-shift)[:4]
        print(f"{d}: {len(t)} scans, jumps {np.flatnonzero(flag).tolist()} (jump_shift {sc.jump_shift} m, "
              f"jump_ratio {sc.jump_ratio}, jump_turn {sc.jump_turn} rad)")
        print("  largest excess: " + ", ".join(
            f"scan {i} {shift[i]:.3f} m ({ratio[i]:.1f} steps)" for i in top)
            + f"; rotation excess max {math.degrees(turn.max()):.1f} deg at scan {int(np.argmax(turn))}")
        k = int(top[0])
        for i in range(max(1, k - 3), min(len(t), k + 3)):
            step = math.hypot(*(p[i, :2] - p[i - 1, :2]))
            dth = math.degrees(math.remainder(p[i, 2] - p[i - 1, 2], 2 * math.pi))
            print(f"    scan {i}: dt {t[i] - t[i - 1]:.3f} s, step {step:.3f} m, {dth:+.1f} deg, excess "
                  f"{shift[i]:.3f} m")
        if (d / "trajectory_frontend.tum").exists() and (d / "trajectory.tum").exists():
            _, q = _tum(d / "trajectory.tum")
            diff = np.hypot(*(q[:, :2] - p[:, :2]).T)
            print(f"  optimised vs front end: max {diff.max():.3f} m (scan {int(np.argmax(diff))}), median "
                  f"{np.median(diff):.3f} m")


def _rel(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pose ``q`` in the frame of pose ``p`` (x, y m; θ rad wrapped)."""
    c, s = math.cos(p[2]), math.sin(p[2])
    dx, dy = q[0] - p[0], q[1] - p[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, math.remainder(q[2] - p[2], 2 * math.pi)])


def _span(v: np.ndarray, fmt: str = ".3f") -> str:
    return f"{v.min():{fmt}}–{v.max():{fmt}}" if v.size else "—"


def _classes(flag: np.ndarray, err: np.ndarray, shift: np.ndarray, ratio: np.ndarray, indent: str = "  ") -> None:
    """The flagged steps by their error against the corrected step (``err`` m): fine, between, wrong."""
    for name, m in (("fine (< 0.1 m)", flag & (err < 0.1)), ("between", flag & (err >= 0.1) & (err < 0.25)),
                    ("wrong (>= 0.25 m)", flag & (err >= 0.25))):
        print(f"{indent}{name}: {int(m.sum())}, step error {_span(err[m])} m, excess {_span(shift[m])} m, "
              f"{_span(ratio[m], '.1f')} predicted steps; scans {np.flatnonzero(m).tolist()}")


def reference(run_dir: str, log: str, window: str | None) -> None:
    from dynslam2d.io.carmen import CarmenSource

    d = Path(run_dir)
    sc = Config.model_validate(__import__("yaml").safe_load((d / "config.yaml").read_text())).slam
    t, p = _tum(d / "trajectory_frontend.tum")
    recs = list(CarmenSource(log).records())
    rp = np.array([[r.laser_pose.x, r.laser_pose.y, r.laser_pose.theta] for r in recs])
    if len(recs) != len(t) or not np.allclose([r.scan.stamp for r in recs], t, atol=1e-6):
        raise SystemExit(f"{log}: {len(recs)} scans, the run {len(t)}: not the run's input")
    err = np.zeros(len(t))  # each step's translation against the corrected step, m
    err[1:] = [math.hypot(*(_rel(p[i - 1], p[i])[:2] - _rel(rp[i - 1], rp[i])[:2])) for i in range(1, len(t))]
    flag, shift, _ = jump_flags(t, p, sc.jump_shift, sc.jump_ratio, sc.jump_turn)
    ratio = step_excess(t, p)[2]
    ref_flag = jump_flags(t, rp, sc.jump_shift, sc.jump_ratio, sc.jump_turn)[0]
    print(f"{d}: {len(t)} scans, {int(flag.sum())} flagged; the same rule on the corrected poses flags "
          f"{int(ref_flag.sum())} ({int((flag & ref_flag).sum())} of ours among them)")
    _classes(flag, err, shift, ratio)
    vs, _, ve = model_excess(t, p)["velocity"]  # the constant-velocity prediction alone: the rule before
    vflag = (vs >= sc.jump_shift) & (vs >= sc.jump_ratio * ve)
    print(f"  constant velocity alone (the rule before): {int(vflag.sum())} flagged")
    _classes(vflag, err, vs, vs / np.maximum(ve, 1e-9), "    ")
    dt = np.diff(t)
    ref_step = np.hypot(*np.diff(rp[:, :2], axis=0).T)
    print(f"  time steps: {100 * np.mean(dt <= 0.004):.0f} % <= 4 ms, {int((dt > 2).sum())} > 2 s, median "
          f"{np.median(dt):.3f} s; correlation of the corrected step length with the time step "
          f"{np.corrcoef(ref_step, dt)[0, 1]:.2f}")
    med = np.array([np.median(dt[max(0, k - 3):k]) if k >= 3 else np.nan for k in range(len(dt))])
    regular = np.zeros(len(t), dtype=bool)
    regular[1:] = np.maximum(dt, med) / np.minimum(dt, med) <= 1.5  # NaN (no three steps before) -> False
    for shift_m, r in ((0.25, 3.0), (0.35, 3.0), (0.5, 3.0), (0.25, 10.0), (0.5, 10.0)):
        f = jump_flags(t, p, shift_m, r)[0]
        print(f"  jump_shift {shift_m}, jump_ratio {r:g}: " + "; ".join(
            f"{label}{int(g.sum())} flags, {int((g & (err >= 0.25)).sum())} wrong, {int((g & (err < 0.1)).sum())} fine"
            for label, g in (("", f), ("time step within 1.5x of the 3 before: ", f & regular))))
    a, b = p[:, :2] - p[:, :2].mean(0), rp[:, :2] - rp[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)  # rigid 2D alignment (Umeyama 1991, without scale)
    rot = vt.T @ np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    res = np.linalg.norm(a @ rot.T - b, axis=1)
    length = [float(np.hypot(*np.diff(q[:, :2], axis=0).T).sum()) for q in (p, rp)]
    print(f"  whole run: path {length[0]:.1f} m against {length[1]:.1f} m, {np.sqrt(np.mean(res ** 2)):.3f} m RMSE "
          f"against the corrected poses after a rigid alignment")
    if window:
        lo, hi = (int(v) for v in window.split(":"))
        for i in range(lo, hi):
            x, y = _rel(p[lo - 1], p[i]), _rel(rp[lo - 1], rp[i])
            off = math.degrees(math.remainder(x[2] - y[2], 2 * math.pi))
            print(f"    scan {i}: {t[i] - t[0]:.2f} s, front end {x[0]:+.3f} {x[1]:+.3f} m {math.degrees(x[2]):+.1f} "
                  f"deg, corrected {y[0]:+.3f} {y[1]:+.3f} m {math.degrees(y[2]):+.1f} deg: off "
                  f"{math.hypot(*(x[:2] - y[:2])):.3f} m {off:+.1f} deg")


def loops(inp: str, topic: str | None, nodes: str, sets: list[str]) -> None:
    import dynslam2d.slam.loops as lp
    from dynslam2d.inputs import open_source
    from dynslam2d.pipeline import run
    from dynslam2d.slam.matcher import match_multires, support

    a, b = (int(v) for v in nodes.split(":"))
    rows: list[str] = []
    orig_cs, orig_match_at = lp.correlative_search, lp.LoopCloser._match_at
    cur: dict[str, object] = {}

    def cs(lvl, pts, pred, *args, **kw):  # type: ignore[no-untyped-def]
        r = orig_cs(lvl, pts, pred, *args, **kw)
        if r is not None:
            cur["score"], cur["runner_up"], cur["pose"] = r.score, r.runner_up, r.pose
            cur["moved"] = (math.hypot(r.pose[0] - pred[0], r.pose[1] - pred[1]), math.degrees(r.pose[2] - pred[2]))
        return r

    def match_at(self, node, s, pts, pred, lin, ang, min_margin, level=None,  # type: ignore[no-untyped-def]
                 accept_turn=None):
        cur.clear()
        # without the far search's accept_turn: every search runs over all its rotations, so that its score and
        # runner-up are printed (the same candidates: correlative_search's accept_turn refuses only what the far
        # search refuses)
        cand = orig_match_at(self, node, s, pts, pred, lin, ang, min_margin, level)
        if a <= node < b and "score" in cur:
            c, sc = self.config, self.slam
            txt = f"keyframe {node} submap {s}: score {cur['score']:.3f} runner-up {cur['runner_up'] or 0:.3f}"
            if "moved" in cur:
                txt += f", match {cur['moved'][0]:.2f} m / {cur['moved'][1]:+.1f} deg from the front end"
            grid = self._submap(s)
            levels = grid.levels[:max(c.search_level + 1, 2)]
            seed = np.asarray(cur["pose"] if cand is None else cand.z, dtype=np.float64)
            if cur.get("runner_up") is not None:
                p = match_multires(levels, pts, seed, sc.iterations_coarse, sc.iterations_finest, False,
                                   sc.step_mode == "lm", sc.lm_lambda_init, sc.lm_lambda_max, sc.max_rotation_step,
                                   sc.max_translation_step)
                n_sup, spread = support(levels[0], pts, p, sc.support_probability)
                txt += (f", support {n_sup}/{pts.shape[0]} = {n_sup / pts.shape[0]:.2f} (min {c.min_support_share}), "
                        f"spread {spread:.2f} rad")
            rows.append(txt + (" -> candidate" if cand is not None else ""))
        return cand

    lp.correlative_search, lp.LoopCloser._match_at = cs, match_at
    try:
        result = run(open_source(inp, topic=topic), with_assignments(Config(), sets))
    finally:
        lp.correlative_search, lp.LoopCloser._match_at = orig_cs, orig_match_at
    print("\n".join(rows))
    if result.loop is not None:
        print(f"loops active {result.loop.loops}; stats accepted {result.loop.stats.get('loops_accepted')}, "
              f"rejected {result.loop.stats.get('loops_rejected')}")


def main() -> None:
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    s1 = sub.add_parser("steps")
    s1.add_argument("dirs", nargs="+")
    s3 = sub.add_parser("reference")
    s3.add_argument("run_dir")
    s3.add_argument("log")
    s3.add_argument("--window", default=None, metavar="A:B")
    s2 = sub.add_parser("loops")
    s2.add_argument("input")
    s2.add_argument("--topic", default=None)
    s2.add_argument("--nodes", default="0:1000000")
    s2.add_argument("sets", nargs="*", metavar="KEY=VALUE")
    args = ap.parse_args()
    if args.cmd == "steps":
        steps(args.dirs)
    elif args.cmd == "reference":
        reference(args.run_dir, args.log, args.window)
    else:
        loops(args.input, args.topic, args.nodes, args.sets)


if __name__ == "__main__":
    main()
