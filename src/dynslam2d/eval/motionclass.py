"""Removal metrics split by what each labelled object is doing: walking, standing, stopped.

The simulator labels every beam that hits a mover with the mover's id, whether it
moves at that moment or not. A mover that has not moved yet is a *standing* object
— it belongs in the scan and the map (issue 9: standing people are not movers) —
while a walking one must be removed. A mover that stands after having moved is
*stopped*: whether it should be removed depends on the memory of past motion, so it
is reported apart and counts in neither of the other classes.

Classes per beam (:data:`CLASS_NAMES`): −1 no return, 0 static structure, 1 walking
(mover speed > ``speed_threshold`` at that scan), 2 standing (never faster than the
threshold up to that scan), 3 stopped. Speeds come from the ground truth's exact
mover velocities (``movers.csv``: vx, vy in m/s).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError

NO_RETURN, STATIC, WALKING, STANDING, STOPPED = -1, 0, 1, 2, 3
CLASS_NAMES = {NO_RETURN: "no return", STATIC: "static", WALKING: "walking", STANDING: "standing",
               STOPPED: "stopped"}
#: Default speed above which a mover counts as moving at a scan, m/s.
SPEED_THRESHOLD = 0.05


def mover_classes(mover_rows: np.ndarray, stamps: np.ndarray,
                  speed_threshold: float = SPEED_THRESHOLD) -> tuple[np.ndarray, np.ndarray]:
    """Per-scan class of every mover.

    Args:
        mover_rows: structured rows with fields stamp (s), id, vx, vy (m/s), one per
            (scan, mover), as :meth:`GroundTruth.mover_rows` / ``movers.csv`` give them.
        stamps: (n,) scan stamps of the labels, s; rows are matched to them within 1 µs.
        speed_threshold: speed above which a mover is walking, m/s.
    Returns:
        ``(ids, classes)``: (k,) mover ids and (n, k) int8 classes (WALKING, STANDING or
        STOPPED; STANDING where a scan has no row for that mover).
    """
    st = np.asarray(stamps, dtype=np.float64).reshape(-1)
    ids = np.unique(mover_rows["id"]).astype(np.int64)
    moving = np.zeros((st.shape[0], ids.shape[0]), dtype=bool)
    if mover_rows.shape[0] and st.shape[0]:
        col = np.searchsorted(ids, mover_rows["id"])
        row = np.searchsorted(st, mover_rows["stamp"])
        row = np.clip(row, 0, max(st.shape[0] - 1, 0))
        left = np.clip(row - 1, 0, None)
        use_left = np.abs(st[left] - mover_rows["stamp"]) < np.abs(st[row] - mover_rows["stamp"])
        row = np.where(use_left, left, row)
        ok = np.abs(st[row] - mover_rows["stamp"]) <= 1e-6
        speed = np.hypot(mover_rows["vx"], mover_rows["vy"])
        moving[row[ok], col[ok]] = speed[ok] > speed_threshold
    moved_before = np.logical_or.accumulate(moving, axis=0)
    classes = np.full(moving.shape, STANDING, dtype=np.int8)
    classes[moved_before] = STOPPED
    classes[moving] = WALKING
    return ids, classes


def beam_classes(labels: np.ndarray, ids: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """(n, beams) int8 beam classes from per-beam labels (−1 none, 0 static, k mover k)
    and the per-scan mover classes of :func:`mover_classes` (same scans, same order).

    Raises:
        DynSlamError: a label names a mover that has no class, or shapes disagree.
    """
    lab = np.asarray(labels)
    if classes.shape[0] != lab.shape[0]:
        raise DynSlamError(f"motion classes: {classes.shape[0]} scans of mover classes, {lab.shape[0]} of labels")
    out = np.where(lab < 0, NO_RETURN, STATIC).astype(np.int8)
    dyn = lab >= 1
    if dyn.any():
        col = np.searchsorted(ids, lab[dyn])
        col_c = np.clip(col, 0, max(ids.shape[0] - 1, 0))
        if ids.shape[0] == 0 or np.any(ids[col_c] != lab[dyn]):
            raise DynSlamError("motion classes: labels name a mover that has no rows in the movers table")
        rows = np.nonzero(dyn)[0]
        out[dyn] = classes[rows, col_c]
    return out


@dataclass(frozen=True)
class MotionRemoval:
    """Removed share per beam class (beams summed over all scans; NaN when a class is empty).

    Attributes:
        walking_recall: removed walking-mover beams / walking-mover beams.
        standing_removed_share: removed standing-mover beams / standing-mover beams
            (these should stay: a removal here is a false one).
        stopped_removed_share: removed / beams of movers standing after having moved.
        static_removed_share: removed static-structure beams / static beams.
        n_walking, n_standing, n_stopped, n_static: beams per class.
        n_removed_walking, n_removed_standing, n_removed_stopped, n_removed_static.
        speed_threshold: m/s.
        mover_recall: removed / beams of walking and stopped movers together (stopped movers counted as
            movers: what track memory must remove, docs/maps.md).
        seen_mover_recall: the same, counting a stopped mover only once the sensor has seen it walk
            (at least ``min_hits`` beams on it in a scan where it walked; NaN without per-scan hits):
            a mover that walked out of view and stands where it is first seen cannot be known to move.
        n_seen_stopped, n_removed_seen_stopped: beams of stopped movers seen walking before, and removed.
    """

    walking_recall: float
    standing_removed_share: float
    stopped_removed_share: float
    static_removed_share: float
    n_walking: int
    n_standing: int
    n_stopped: int
    n_static: int
    n_removed_walking: int
    n_removed_standing: int
    n_removed_stopped: int
    n_removed_static: int
    speed_threshold: float
    mover_recall: float = float("nan")
    seen_mover_recall: float = float("nan")
    n_seen_stopped: int = 0
    n_removed_seen_stopped: int = 0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _seen_walking_before(mover_rows: np.ndarray, stamps: np.ndarray, ids: np.ndarray, speed_threshold: float,
                         min_hits: int) -> np.ndarray | None:
    """(n, k) bool: mover k was seen walking (≥ ``min_hits`` beams on it while faster than the threshold) at
    or before scan i; None when the rows have no ``hits``."""
    if "hits" not in (mover_rows.dtype.names or ()):
        return None
    st = np.asarray(stamps, dtype=np.float64).reshape(-1)
    seen = np.zeros((st.shape[0], ids.shape[0]), dtype=bool)
    if mover_rows.shape[0] and st.shape[0]:
        col = np.searchsorted(ids, mover_rows["id"])
        row = np.clip(np.searchsorted(st, mover_rows["stamp"] - 1e-6), 0, st.shape[0] - 1)
        ok = np.abs(st[row] - mover_rows["stamp"]) <= 1e-6
        walk = (np.hypot(mover_rows["vx"], mover_rows["vy"]) > speed_threshold) & (mover_rows["hits"] >= min_hits)
        seen[row[ok & walk], col[ok & walk]] = True
    return np.logical_or.accumulate(seen, axis=0)


def removal_by_motion(removed: np.ndarray, labels: np.ndarray, label_stamps: np.ndarray, mover_rows: np.ndarray,
                      speed_threshold: float = SPEED_THRESHOLD, min_hits: int = 3) -> MotionRemoval:
    """Score removed beams per class (walking / standing / stopped movers, static structure).

    Args:
        removed: (n, beams) bool, True where the filter removed the beam.
        labels: (n, beams) per-beam labels of the same scans; ``label_stamps`` (n,) their stamps, s.
        mover_rows: the ground truth's mover rows (stamp, id, vx, vy, …).
        speed_threshold: m/s, see :func:`mover_classes`.
    """
    rem = np.asarray(removed, dtype=bool)
    if rem.shape != np.shape(labels):
        raise DynSlamError(f"motion classes: removed mask has shape {rem.shape} but labels have {np.shape(labels)}")
    ids, classes = mover_classes(mover_rows, label_stamps, speed_threshold)
    cls = beam_classes(labels, ids, classes)
    n = {c: int((cls == c).sum()) for c in (WALKING, STANDING, STOPPED, STATIC)}
    r = {c: int((rem & (cls == c)).sum()) for c in n}

    def share(c: int) -> float:
        return r[c] / n[c] if n[c] else float("nan")

    n_mov, r_mov = n[WALKING] + n[STOPPED], r[WALKING] + r[STOPPED]
    seen = _seen_walking_before(mover_rows, label_stamps, ids, speed_threshold, min_hits)
    n_ss = r_ss = 0
    seen_recall = float("nan")
    if seen is not None:
        lab = np.asarray(labels)
        dyn = lab >= 1
        seen_beam = np.zeros(lab.shape, dtype=bool)
        if dyn.any() and ids.shape[0]:
            rows_i = np.nonzero(dyn)[0]
            seen_beam[dyn] = seen[rows_i, np.clip(np.searchsorted(ids, lab[dyn]), 0, ids.shape[0] - 1)]
        ss = (cls == STOPPED) & seen_beam
        n_ss, r_ss = int(ss.sum()), int((rem & ss).sum())
        den = n[WALKING] + n_ss
        seen_recall = (r[WALKING] + r_ss) / den if den else float("nan")

    return MotionRemoval(
        walking_recall=share(WALKING),
        standing_removed_share=share(STANDING),
        stopped_removed_share=share(STOPPED),
        static_removed_share=share(STATIC),
        n_walking=n[WALKING], n_standing=n[STANDING], n_stopped=n[STOPPED], n_static=n[STATIC],
        n_removed_walking=r[WALKING], n_removed_standing=r[STANDING], n_removed_stopped=r[STOPPED],
        n_removed_static=r[STATIC],
        speed_threshold=float(speed_threshold),
        mover_recall=r_mov / n_mov if n_mov else float("nan"),
        seen_mover_recall=seen_recall,
        n_seen_stopped=n_ss,
        n_removed_seen_stopped=r_ss,
    )


@dataclass(frozen=True)
class MoverTimeToM:
    """One mover: when it was first seen walking and when a track in M first caught it (s; None = never)."""

    id: int
    onset: float | None
    reached: float | None
    delay: float | None


@dataclass(frozen=True)
class TimeToM:
    """How fast walking movers enter the dynamic set M (issue 9: within 0.5 s of starting to move).

    Attributes:
        movers: per mover seen walking, onset / reached / delay.
        seen_walking: movers seen walking at least once.
        reached: of those, movers a track in M caught after their onset.
        median_delay: median delay of the movers reached, s (NaN if none).
        within_half_second: share of the movers seen walking that were caught within 0.5 s.
        m_radius: a track in M with its centre this close to the mover's centre catches it, m.
    """

    movers: list[MoverTimeToM]
    seen_walking: int
    reached: int
    median_delay: float
    within_half_second: float
    m_radius: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def time_to_m(mover_rows: np.ndarray, tracks: np.ndarray, transform: Any | None = None, m_radius: float = 0.5,
              speed_threshold: float = SPEED_THRESHOLD, min_hits: int = 3) -> TimeToM:
    """Per walking mover, the time from its *onset* — the first scan where it walks (speed >
    ``speed_threshold``) and at least ``min_hits`` beams hit it — to the first scan from then on
    where a track in M has its centre within ``m_radius`` m of the mover's centre.

    Args:
        mover_rows: ground-truth rows (stamp, id, x, y, vx, vy, hits; ground-truth frame).
        tracks: tracks.csv rows (:data:`dynslam2d.io.runfolder.TRACK_DTYPE`; the run's map frame).
        transform: maps the run's map frame into the ground-truth frame (the ATE alignment,
            a :class:`~dynslam2d.types.Pose2D`); None = the frames coincide.
    """
    in_m = tracks[tracks["in_M"]] if tracks.shape[0] else tracks
    xy = np.column_stack((in_m["x"], in_m["y"])) if in_m.shape[0] else np.zeros((0, 2))
    if transform is not None and xy.shape[0]:
        xy = transform.transform_points(xy)
    order = np.argsort(in_m["stamp"], kind="stable") if in_m.shape[0] else np.zeros(0, dtype=np.int64)
    m_stamps = in_m["stamp"][order] if in_m.shape[0] else np.zeros(0)
    xy = xy[order]
    out: list[MoverTimeToM] = []
    for mid in np.unique(mover_rows["id"]):
        rows = mover_rows[mover_rows["id"] == mid]
        rows = rows[np.argsort(rows["stamp"], kind="stable")]
        walking = np.hypot(rows["vx"], rows["vy"]) > speed_threshold
        seen = rows["hits"] >= min_hits
        start = np.flatnonzero(walking & seen)
        if start.shape[0] == 0:
            continue
        onset = float(rows["stamp"][start[0]])
        reached = None
        for r in rows[start[0]:]:
            lo = np.searchsorted(m_stamps, r["stamp"] - 1e-6)
            hi = np.searchsorted(m_stamps, r["stamp"] + 1e-6)
            if hi > lo and np.hypot(xy[lo:hi, 0] - r["x"], xy[lo:hi, 1] - r["y"]).min() <= m_radius:
                reached = float(r["stamp"])
                break
        out.append(MoverTimeToM(int(mid), onset, reached, None if reached is None else reached - onset))
    delays = [m.delay for m in out if m.delay is not None]
    return TimeToM(
        movers=out,
        seen_walking=len(out),
        reached=len(delays),
        median_delay=float(np.median(delays)) if delays else float("nan"),
        within_half_second=(sum(d <= 0.5 + 1e-9 for d in delays) / len(out)) if out else float("nan"),
        m_radius=float(m_radius),
    )


__all__ = ["CLASS_NAMES", "MotionRemoval", "MoverTimeToM", "TimeToM", "beam_classes", "mover_classes",
           "removal_by_motion", "time_to_m"]
