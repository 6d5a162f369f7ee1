"""What the clean-up pass erased, cell by cell (docs/maps.md, "What the erased cells are"; not run by pytest).

For each input: one run with the default configuration (or ``--set``) and the clean-up pass watching, keeping
the counted scans; then every erased cell is put in one class by its distance to the cleaned map's kept
occupied cells:

  * ``fringe``: hit by at most two counted scans (a stray return; harmless either way);
  * ``thinned``: a kept occupied cell among its 8 neighbours (the structure stays, one cell thinner);
  * ``copy``: the nearest kept cell 0.075–0.40 m away (a second outline of something the map keeps);
  * ``gone``: no kept cell within 0.40 m (the whole object left the map).

how many were hit mostly at grazing incidence, mostly beside a depth jump (mixed pixels) or from closer than
0.5 m (the robot's body), and, for each class, **how well the scans that saw through a cell agree with the
scans that hit it** around the cell: the endpoints of (up to 8) passing scans within 2 m of the cell are
registered (2D point-to-point ICP, trimmed at 0.3 m) onto those of (up to 8) hitting scans, leaving out 0.25 m
around the cell itself; the "misalignment" is how far that moves the cell's centre. A mover that left is seen
through from poses that agree with the poses that hit it (misalignment ≈ the SLAM's error, a few mm in
simulation); a wall whose copies come from pose error is seen through by scans that are off by the size of the
copy's offset. ``--visits`` registers whole counted scans of later visits onto a first one.

With ground truth (``sim:<scenario>``) the erased cells within 0.10 m of the true static structure are
counted too (walls the pass erased). Run-wide: erased / lost (online occupied cells > 0.10 m from every
kept cell) / restored cells.

    python benchmarks/bench_erased.py ../shared/data/dynamic/leg_tracker/negative_2.bag --topic /right_scan
    python benchmarks/bench_erased.py ../shared/data/dynamic/leg_tracker/negative_2.bag --topic /right_scan \\
        --visits 0:25,137:150,173:205,205:221      # counted scans of three later visits onto the first's
    python benchmarks/bench_erased.py sim:parking
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.spatial import cKDTree

from dynslam2d.config import Config, with_assignments
from dynslam2d.eval.maps import distance_to
from dynslam2d.inputs import open_source
from dynslam2d.pipeline import run
from dynslam2d.results import compute_metrics, ground_truth_for
from dynslam2d.slam.cleanup import CleanupRecorder, VisibilityCounter
from dynslam2d.types import Pose2D, Scan

#: Class bounds on the distance to the nearest kept occupied cell, m (beside = 8-neighbour at 0.05 m).
BESIDE_M, COPY_M = 0.075, 0.40
#: Registration neighbourhood around an erased cell and the disc around it left out, m.
NEAR_M, HOLE_M = 2.0, 0.25
#: Misalignment from which an erasure is counted as caused by pose disagreement, m (two cells).
MISALIGNED_M = 0.10


class KeepingCounter(VisibilityCounter):
    """A :class:`VisibilityCounter` that also keeps every (scan, pose, removed) it counted."""

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self.kept: list[tuple[Scan, Pose2D, np.ndarray | None]] = []

    def add(self, scan: Scan, pose: Pose2D, removed: np.ndarray | None = None) -> None:
        super().add(scan, pose, removed)
        self.kept.append((scan, pose, None if removed is None else np.array(removed)))


class KeepingRecorder(CleanupRecorder):
    counter_class = KeepingCounter


def _events(counter: KeepingCounter, cells: np.ndarray) -> tuple[list[list[int]], list[list[int]]]:
    """Per erased cell (absolute (i, j) rows of ``cells``), the indices of the counted scans that hit it and
    that passed through it — the counter's own kernel, one scan at a time on a scratch counter."""
    scratch = VisibilityCounter(counter.resolution, counter.config, counter.slam)
    scratch.reserve([(s, p) for s, p, _ in counter.kept])
    hits: list[list[int]] = [[] for _ in range(len(cells))]
    passes: list[list[int]] = [[] for _ in range(len(cells))]
    for k, (scan, pose, removed) in enumerate(counter.kept):
        scratch.clear()
        scratch.add(scan, pose, removed)
        got = scratch.at(cells[:, 0], cells[:, 1])
        for m in np.nonzero(got[:, 0])[0]:
            hits[m].append(k)
        for m in np.nonzero((got[:, 0] == 0) & (got[:, 1] != 0))[0]:
            passes[m].append(k)
    return hits, passes


def _hit_kinds(counter: KeepingCounter, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per erased cell (absolute (i, j) rows of ``cells``): whether most of the kept beams that ended in it met
    their surface at grazing incidence (below 15°, from the neighbouring endpoints as the counter estimates it),
    whether most ended beside a depth jump of more than 0.2 m to a neighbouring beam (mixed pixels), and whether
    any ended closer than 0.5 m to the laser (the robot's own body)."""
    key = cells[:, 0] * (1 << 32) + cells[:, 1]
    order = np.argsort(key)
    n = len(cells)
    total, grazing, jump, close = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool)
    res, slam = counter.resolution, counter.slam
    for scan, pose, removed in counter.kept:
        r = scan.ranges
        with np.errstate(invalid="ignore"):
            ok = scan.valid_mask() & (r > slam.laser_min_dist) & (r < slam.laser_max_dist)
        kept = ok & ~removed if removed is not None and removed.shape == ok.shape else ok
        ca, sa = scan.trig()
        lx, ly = np.where(ok, r * ca, 0.0), np.where(ok, r * sa, 0.0)
        prev_ok, next_ok = np.r_[False, ok[:-1]], np.r_[ok[1:], False]
        ax, ay = np.where(prev_ok, np.r_[0.0, lx[:-1]], lx), np.where(prev_ok, np.r_[0.0, ly[:-1]], ly)
        bx, by = np.where(next_ok, np.r_[lx[1:], 0.0], lx), np.where(next_ok, np.r_[ly[1:], 0.0], ly)
        tx, ty = bx - ax, by - ay
        tn = np.hypot(tx, ty)
        with np.errstate(invalid="ignore", divide="ignore"):
            sn = np.where(tn > 0, np.abs(lx * ty - ly * tx) / (tn * np.where(ok, r, 1.0)), 1.0)
            rr = np.where(ok, r, np.nan)
            jumps = np.fmax(np.where(prev_ok, np.abs(rr - np.r_[np.nan, rr[:-1]]), 0.0),
                            np.where(next_ok, np.abs(rr - np.r_[rr[1:], np.nan]), 0.0))
        c, si = math.cos(pose.theta), math.sin(pose.theta)
        wx, wy = pose.x + c * lx - si * ly, pose.y + si * lx + c * ly
        ci = np.floor(wx / res + 0.5).astype(np.int64)
        cj = np.floor(wy / res + 0.5).astype(np.int64)
        beam = np.nonzero(kept)[0]
        k = ci[beam] * (1 << 32) + cj[beam]
        pos = np.searchsorted(key[order], k)
        hit = (pos < n) & (key[order][np.minimum(pos, n - 1)] == k)
        for b, m in zip(beam[hit], order[pos[hit]]):
            total[m] += 1
            grazing[m] += sn[b] < math.sin(math.radians(15.0))
            jump[m] += jumps[b] > 0.2
            close[m] |= r[b] < 0.5
    with np.errstate(invalid="ignore"):
        return grazing / total > 0.5, jump / total > 0.5, close


def _endpoints(scan: Scan, pose: Pose2D, removed: np.ndarray | None, slam) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n, 2) map-frame endpoints of the scan's returns that the counter took as hits, m."""
    r = scan.ranges
    with np.errstate(invalid="ignore"):
        ok = scan.valid_mask() & (r > slam.laser_min_dist) & (r < slam.laser_max_dist)
    if removed is not None and removed.shape == ok.shape:
        ok &= ~removed
    ca, sa = scan.trig()
    lx, ly = r[ok] * ca[ok], r[ok] * sa[ok]
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    return np.column_stack((pose.x + c * lx - s * ly, pose.y + s * lx + c * ly))


def _icp(src: np.ndarray, dst: np.ndarray, iters: int = 30) -> tuple[np.ndarray, np.ndarray] | None:
    """The rigid transform (R, t) registering ``src`` onto ``dst`` ((n, 2) points, m): 2D point-to-point ICP with
    the SVD step of Arun, Huang & Blostein (IEEE TPAMI 1987), pairs farther than 0.3 m left out. None with fewer
    than 20 pairs."""
    if len(src) < 20 or len(dst) < 20:
        return None
    tree = cKDTree(dst)
    R, t = np.eye(2), np.zeros(2)
    for _ in range(iters):
        p = src @ R.T + t
        d, i = tree.query(p)
        m = d < 0.3
        if m.sum() < 20:
            return None
        a, b = p[m], dst[i[m]]
        ac, bc = a.mean(0), b.mean(0)
        u, _s, vt = np.linalg.svd((a - ac).T @ (b - bc))
        dd = np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        Ri = vt.T @ dd @ u.T
        R, t = Ri @ R, Ri @ t + bc - Ri @ ac
    return R, t


def _icp_shift(src: np.ndarray, dst: np.ndarray, at: np.ndarray) -> float:
    """How far the transform registering ``src`` onto ``dst`` (:func:`_icp`) moves the point ``at``, m (NaN
    when it fails)."""
    rt = _icp(src, dst)
    return math.nan if rt is None else float(np.hypot(*(rt[0] @ at + rt[1] - at)))


def _visits(pts: list[np.ndarray], where: list[np.ndarray], spec: str) -> None:
    """Print, for the counted scans of each range after the first (``A:B,C:D,...``, counted-scan indices), the
    transform registering each of (up to 5 of) them onto all the first range's scans — how far it moves the
    scan's own position ``where[k]`` (m) and its rotation: how far the run's poses of two visits disagree about the
    same structure."""
    groups = [tuple(int(v) for v in g.split(":")) for g in spec.split(",")]
    ref = np.vstack(pts[groups[0][0]:groups[0][1]])
    for a, b in groups[1:]:
        for k in np.unique(np.linspace(a, b - 1, min(b - a, 5)).round().astype(int)):
            rt = _icp(pts[k], ref)
            if rt is None:
                print(f"  scan {k}: no registration onto scans {groups[0][0]}:{groups[0][1]}")
                continue
            R, t = rt
            shift = float(np.hypot(*(R @ where[k] + t - where[k])))
            print(f"  scan {k} onto scans {groups[0][0]}:{groups[0][1]}: shift {shift:.3f} m, "
                  f"rotation {math.degrees(math.atan2(R[1, 0], R[0, 0])):+.2f} deg")


def _misalignment(counter: KeepingCounter, pts: list[np.ndarray], xy: np.ndarray, hits: list[int],
                  passes: list[int]) -> float:
    def near(ids: list[int]) -> np.ndarray:
        ids = [ids[k] for k in np.unique(np.linspace(0, len(ids) - 1, min(len(ids), 8)).round().astype(int))]
        p = np.vstack([pts[k] for k in ids]) if ids else np.zeros((0, 2))
        d = np.hypot(p[:, 0] - xy[0], p[:, 1] - xy[1])
        return p[(d < NEAR_M) & (d > HOLE_M)]

    if not hits or not passes:
        return math.nan
    return _icp_shift(near(passes), near(hits), xy)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--topic", default=None, help="scan topic of a bag with several")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="configuration override, e.g. clean.rehit_min_hits=0 (repeatable)")
    ap.add_argument("--visits", default=None, metavar="A:B,C:D,...",
                    help="register counted scans of the later ranges onto the first range's (pose disagreement)")
    args = ap.parse_args()
    for inp in args.inputs:
        cfg = with_assignments(Config(), args.set)
        src = open_source(inp, topic=args.topic if not inp.startswith("sim:") else None)
        rec = KeepingRecorder(cfg.clean)
        result = run(src, cfg, observers=[rec])
        cl, counter = rec.result, rec.counter
        assert cl is not None and isinstance(counter, KeepingCounter)
        grid, res = result.grid, result.grid.resolution
        occ = grid.occupied()
        dk = distance_to(occ & ~cl.erased, res)
        lost = occ & (dk > 0.1 + 1e-9)
        rows, cols = np.nonzero(cl.erased)
        xy = np.column_stack((grid.origin[0] + (cols + 0.5) * res, grid.origin[1] + (rows + 0.5) * res))
        cells = np.column_stack((np.floor(xy[:, 0] / res + 0.5), np.floor(xy[:, 1] / res + 0.5))).astype(np.int64)
        hits, passes = _events(counter, cells)
        pts = [_endpoints(s, p, r, counter.slam) for s, p, r in counter.kept]
        if args.visits:
            _visits(pts, [np.array([p.x, p.y]) for _, p, _ in counter.kept], args.visits)
        mis = np.array([_misalignment(counter, pts, xy[m], hits[m], passes[m]) for m in range(len(xy))])
        grazing, mixed, close = _hit_kinds(counter, cells)
        H = cl.hits[rows, cols].astype(int)
        d = dk[rows, cols]
        cls = np.where(H <= 2, "fringe", np.where(d <= BESIDE_M, "thinned", np.where(d <= COPY_M, "copy", "gone")))
        name = inp.rsplit("/", 1)[-1] + (f" {args.topic}" if args.topic else "")
        print(f"{name}: {result.n_scans} scans, {cl.stats['scans_counted']} counted; erased {len(xy)} of "
              f"{int(occ.sum())} occupied cells ({len(xy) * res * res:.2f} m2), lost {int(lost.sum())}, restored "
              f"{int(cl.restored.sum()) if cl.restored is not None else 0}")
        print(f"  most hits at incidence below 15 deg: {int(grazing.sum())} cells; most hits beside a depth jump over "
              f"0.2 m (mixed pixels): {int(mixed.sum())}; hit from closer than 0.5 m (the robot's body): "
              f"{int(close.sum())}")
        gt = ground_truth_for(src, None, cfg.slam.map_resolution)
        on_wall = np.zeros(len(xy), dtype=bool)
        if gt is not None:
            a = compute_metrics(result, gt)["alignment"]
            c, s = math.cos(a["theta"]), math.sin(a["theta"])
            gxy = np.column_stack((a["x"] + c * xy[:, 0] - s * xy[:, 1], a["y"] + s * xy[:, 0] + c * xy[:, 1]))
            g = gt.static_map
            gd = distance_to(g.occupied(0.5), g.resolution)
            gc = g.world_to_cell(gxy)
            inside = (gc[:, 0] >= 0) & (gc[:, 0] < g.shape[1]) & (gc[:, 1] >= 0) & (gc[:, 1] < g.shape[0])
            on_wall[inside] = gd[gc[inside, 1], gc[inside, 0]] <= 0.10 + 1e-9
            print(f"  erased cells within 0.10 m of the true static structure: {int(on_wall.sum())}")
        print(f"  {'class':8s} {'cells':>6s} {'misaligned':>11s} {'median mis.':>11s} {'median H/T':>10s}"
              + ("  on walls" if gt is not None else ""))
        for k in ("fringe", "thinned", "copy", "gone"):
            m = cls == k
            if not m.any():
                continue
            mm = mis[m]
            fin = np.isfinite(mm)
            share = f"{int((mm[fin] >= MISALIGNED_M).sum())}/{int(fin.sum())}"
            med = f"{np.median(mm[fin]):.3f} m" if fin.any() else "—"
            ht = f"{int(np.median(H[m]))}/{int(np.median(cl.through[rows, cols][m]))}"
            print(f"  {k:8s} {int(m.sum()):6d} {share:>11s} {med:>11s} {ht:>10s}"
                  + (f"  {int(on_wall[m].sum())}" if gt is not None else ""))


if __name__ == "__main__":
    main()
