"""Removal of annotated people: ``dynslam2d eval people BAG RUN_DIR``.

Scores a run (``kept_mask.npz``, ``tracks.csv``, ``trajectory.tum``) of an annotated
leg_tracker bag (:mod:`dynslam2d.io.annotations`) against the hand-annotated people.

Definitions (docs/real.md):

* **person beams** of an annotated scan: beams with a return whose endpoint lies
  within ``radius`` (default 0.35 m) of one of that scan's annotations;
  **non-person beams**: every other beam with a return of an annotated scan.
  Scans without annotation are left out of both (a person may be in view but not
  annotated); ``removed_share_all`` is the removed share over every scan.
* **walking / standing**: an annotation is *walking* when the same person id moved
  at ≥ ``walk_speed`` (default 0.3 m/s) over a window of ``window`` s (default 1 s)
  centred on it (straight-line displacement between the first and last annotation
  of that id in the window / their time difference; the window must span at least
  ``window``/3, else the annotation is *unknown*). Positions are compared in the
  map frame — the run's own trajectory places each scan — or, with
  ``motion_frame="scan"``, in the laser frame (only right for a motionless sensor).
* **recall**: removed person beams / person beams (and per class);
  **non_person_removed_share**: removed non-person beams / non-person beams.
* **time to M**: per person, from the first walking annotation to the first later
  annotated scan where a track in M (tracks.csv ``in_M``) has its centre within
  ``m_radius`` (default 0.5 m) of the person (map frame).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.annotations import PEOPLE_TOPIC, AnnotatedScans
from dynslam2d.types import Pose2D

WALKING, STANDING, UNKNOWN = "walking", "standing", "unknown"
#: Stamp tolerance when matching a run's scans to the bag's, s.
STAMP_TOL = 1e-6


@dataclass(frozen=True)
class PeopleParams:
    """Parameters of :func:`people_metrics` (m, m/s, s)."""

    radius: float = 0.35
    walk_speed: float = 0.3
    window: float = 1.0
    m_radius: float = 0.5
    motion_frame: str = "map"

    def __post_init__(self) -> None:
        if self.motion_frame not in ("map", "scan"):
            raise DynSlamError(f"eval people: motion frame must be 'map' or 'scan', got {self.motion_frame!r}")
        for name in ("radius", "walk_speed", "window", "m_radius"):
            if not getattr(self, name) > 0:
                raise DynSlamError(f"eval people: {name} must be > 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class PersonResult:
    """One person id: beams, removal, motion and time to M (s; None when it never happened)."""

    id: int
    annotations: int
    beams: int
    removed: int
    recall: float
    walking_annotations: int
    first_seen: float
    first_motion: float | None
    reached_m: float | None
    time_to_m: float | None


@dataclass(frozen=True)
class PeopleMetrics:
    """Result of :func:`people_metrics` (beam counts summed over the scored scans)."""

    scans: int
    scans_annotated: int
    annotations: int
    people: int
    walking_people: int
    person_beams: int
    person_removed: int
    recall: float
    walking_beams: int
    walking_removed: int
    walking_recall: float
    standing_beams: int
    standing_removed: int
    standing_recall: float
    unknown_beams: int
    non_person_beams: int
    non_person_removed: int
    non_person_removed_share: float
    removed_share_all: float
    people_reached_m: int
    median_time_to_m: float
    per_person: list[PersonResult] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Plain mapping for JSON (NaN stays NaN; json writes it as NaN)."""
        return asdict(self)


def _ratio(a: int, b: int) -> float:
    return a / b if b else float("nan")


def _match_rows(run_stamps: np.ndarray, bag_stamps: np.ndarray, what: str) -> np.ndarray:
    """For each bag scan, the row of the run with the same stamp (−1 when the run skipped it)."""
    order = np.argsort(run_stamps, kind="stable")
    srt = run_stamps[order]
    pos = np.clip(np.searchsorted(srt, bag_stamps), 0, max(srt.shape[0] - 1, 0))
    best = pos.copy()
    left = np.clip(pos - 1, 0, None)
    closer = np.abs(srt[left] - bag_stamps) < np.abs(srt[pos] - bag_stamps)
    best[closer] = left[closer]
    ok = np.abs(srt[best] - bag_stamps) <= STAMP_TOL
    rows = np.where(ok, order[best], -1)
    if not ok.any():
        raise DynSlamError(f"eval people: no scan of {what} has a stamp in the run (was the run made from this bag "
                           f"and topic?)")
    return rows


def _motion_classes(ids: np.ndarray, times: np.ndarray, xy: np.ndarray, p: PeopleParams) -> np.ndarray:
    """Per annotation: WALKING, STANDING or UNKNOWN from the centred-window speed."""
    out = np.full(ids.shape[0], UNKNOWN, dtype=object)
    half = p.window / 2.0
    for pid in np.unique(ids):
        idx = np.flatnonzero(ids == pid)
        idx = idx[np.argsort(times[idx], kind="stable")]
        t = times[idx]
        lo = np.searchsorted(t, t - half, side="left")
        hi = np.searchsorted(t, t + half, side="right") - 1
        span = t[hi] - t[lo]
        ok = span >= p.window / 3.0
        disp = np.hypot(*(xy[idx[hi]] - xy[idx[lo]]).T)
        speed = np.where(ok, disp / np.where(ok, span, 1.0), np.nan)
        out[idx[ok & (speed >= p.walk_speed)]] = WALKING
        out[idx[ok & (speed < p.walk_speed)]] = STANDING
    return out


def people_metrics(
    ann: AnnotatedScans,
    removed: np.ndarray,
    removed_stamps: np.ndarray,
    trajectory_stamps: np.ndarray | None,
    trajectory_poses: np.ndarray | None,
    tracks: np.ndarray,
    params: PeopleParams | None = None,
) -> PeopleMetrics:
    """Score a run against annotated people (definitions in the module docstring).

    Args:
        ann: the bag's scans and annotations.
        removed: (n_run, beams) bool removal mask of the run; ``removed_stamps`` (n_run,) s.
        trajectory_stamps, trajectory_poses: the run's laser poses in the map frame
            ((k,) s and (k, 3) x, y, yaw); needed for ``motion_frame="map"`` and for time to M.
        tracks: tracks.csv rows (:data:`dynslam2d.io.runfolder.TRACK_DTYPE`).
        params: thresholds.
    Raises:
        DynSlamError: the run does not come from this bag (no common stamps, beam counts differ).
    """
    p = params or PeopleParams()
    n = len(ann.scans)
    stamps = ann.stamps
    rows = _match_rows(np.asarray(removed_stamps, dtype=np.float64), stamps, ann.origin)
    if removed.shape[1] != ann.scans[0].n_beams:
        raise DynSlamError(f"eval people: the run's mask has {removed.shape[1]} beams per scan, the bag's scans "
                           f"{ann.scans[0].n_beams} (was the run made from this bag and topic?)")
    poses: np.ndarray | None = None  # (n, 3) map-frame laser pose per bag scan, NaN where unknown
    if trajectory_stamps is not None and trajectory_poses is not None and len(trajectory_stamps):
        trow = _match_rows(np.asarray(trajectory_stamps, dtype=np.float64), stamps, ann.origin)
        poses = np.full((n, 3), np.nan)
        poses[trow >= 0] = np.asarray(trajectory_poses)[trow[trow >= 0]]
    if p.motion_frame == "map" and poses is None:
        raise DynSlamError("eval people: motion frame 'map' needs the run's trajectory.tum")

    # annotations in the map frame (or the scan frame) for motion, time to M
    a_stamp = stamps[ann.scan_index]
    a_map = np.full(ann.xy.shape, np.nan)
    if poses is not None:
        for k, (i, xy) in enumerate(zip(ann.scan_index, ann.xy)):
            if np.isfinite(poses[i]).all():
                a_map[k] = Pose2D.from_array(poses[i]).transform_points(xy[None, :])[0]
    motion_xy = ann.xy if p.motion_frame == "scan" else a_map
    scored = rows[ann.scan_index] >= 0
    usable = scored & np.isfinite(motion_xy).all(axis=1)
    classes = np.full(ann.ids.shape[0], UNKNOWN, dtype=object)
    classes[usable] = _motion_classes(ann.ids[usable], a_stamp[usable], motion_xy[usable], p)

    # person beams per annotated scan
    count = {WALKING: 0, STANDING: 0, UNKNOWN: 0}
    rem_count = dict(count)
    per_beams: dict[int, list[int]] = {}
    non_person = non_person_removed = 0
    annotated = np.unique(ann.scan_index[scored])
    by_scan: dict[int, list[int]] = {}
    for k in np.flatnonzero(scored):
        by_scan.setdefault(int(ann.scan_index[k]), []).append(int(k))
    for i in annotated:
        scan = ann.scans[i]
        valid = scan.valid_mask()
        pts = scan.points(valid)
        beam_idx = np.flatnonzero(valid)
        rem = removed[rows[i]][beam_idx]
        person_any = np.zeros(beam_idx.shape[0], dtype=bool)
        ks = by_scan[int(i)]
        d = np.hypot(pts[:, None, 0] - ann.xy[ks, 0][None, :], pts[:, None, 1] - ann.xy[ks, 1][None, :])
        near = d <= p.radius
        nearest = np.argmin(np.where(near, d, np.inf), axis=1) if len(ks) else np.zeros(0, int)
        person_any = near.any(axis=1)
        for j, k in enumerate(ks):
            mine = person_any & (nearest == j)  # a beam near two people counts for the nearer
            nb, nr = int(mine.sum()), int((mine & rem).sum())
            count[classes[k]] += nb
            rem_count[classes[k]] += nr
            acc = per_beams.setdefault(int(ann.ids[k]), [0, 0])
            acc[0] += nb
            acc[1] += nr
        non_person += int((~person_any).sum())
        non_person_removed += int((~person_any & rem).sum())

    # removed share over every scan of the bag the run holds (beams with a return)
    total = total_removed = 0
    for i in np.flatnonzero(rows >= 0):
        valid = ann.scans[i].valid_mask()
        total += int(valid.sum())
        total_removed += int((removed[rows[i]] & valid).sum())

    per_person = _time_to_m(ann, classes, a_stamp, a_map, scored, tracks, per_beams, p)
    person_beams = sum(count.values())
    person_removed = sum(rem_count.values())
    delays = [r.time_to_m for r in per_person if r.time_to_m is not None]
    return PeopleMetrics(
        scans=int((rows >= 0).sum()),
        scans_annotated=int(annotated.shape[0]),
        annotations=int(scored.sum()),
        people=len(per_person),
        walking_people=sum(1 for r in per_person if r.first_motion is not None),
        person_beams=person_beams,
        person_removed=person_removed,
        recall=_ratio(person_removed, person_beams),
        walking_beams=count[WALKING],
        walking_removed=rem_count[WALKING],
        walking_recall=_ratio(rem_count[WALKING], count[WALKING]),
        standing_beams=count[STANDING],
        standing_removed=rem_count[STANDING],
        standing_recall=_ratio(rem_count[STANDING], count[STANDING]),
        unknown_beams=count[UNKNOWN],
        non_person_beams=non_person,
        non_person_removed=non_person_removed,
        non_person_removed_share=_ratio(non_person_removed, non_person),
        removed_share_all=_ratio(total_removed, total),
        people_reached_m=len(delays),
        median_time_to_m=float(np.median(delays)) if delays else float("nan"),
        per_person=per_person,
        params=asdict(p),
    )


def _time_to_m(ann: AnnotatedScans, classes: np.ndarray, a_stamp: np.ndarray, a_map: np.ndarray,
               scored: np.ndarray, tracks: np.ndarray, per_beams: dict[int, list[int]],
               p: PeopleParams) -> list[PersonResult]:
    """Per person: first walking annotation and the first later scan with a track in M near it."""
    in_m = tracks[tracks["in_M"]] if tracks.shape[0] else tracks
    m_stamps = in_m["stamp"] if in_m.shape[0] else np.zeros(0)
    out = []
    for pid in np.unique(ann.ids[scored]):
        idx = np.flatnonzero(scored & (ann.ids == pid))
        idx = idx[np.argsort(a_stamp[idx], kind="stable")]
        walking = idx[classes[idx] == WALKING]
        first_motion = float(a_stamp[walking[0]]) if walking.shape[0] else None
        reached = None
        if first_motion is not None and m_stamps.shape[0]:
            for k in idx[a_stamp[idx] >= first_motion]:
                if not np.isfinite(a_map[k]).all():
                    continue
                here = in_m[np.abs(m_stamps - a_stamp[k]) <= STAMP_TOL]
                if here.shape[0] and np.hypot(here["x"] - a_map[k, 0], here["y"] - a_map[k, 1]).min() <= p.m_radius:
                    reached = float(a_stamp[k])
                    break
        beams, removed = per_beams.get(int(pid), [0, 0])
        out.append(PersonResult(
            id=int(pid),
            annotations=int(idx.shape[0]),
            beams=beams,
            removed=removed,
            recall=_ratio(removed, beams),
            walking_annotations=int(walking.shape[0]),
            first_seen=float(a_stamp[idx[0]]),
            first_motion=first_motion,
            reached_m=reached,
            time_to_m=None if reached is None or first_motion is None else reached - first_motion,
        ))
    return out


def evaluate_people(
    bag: str | os.PathLike[str],
    run_dir: str | os.PathLike[str],
    *,
    scan_topic: str | None = None,
    people_topic: str = PEOPLE_TOPIC,
    params: PeopleParams | None = None,
) -> PeopleMetrics:
    """:func:`people_metrics` on a bag (or a zip holding one) and a results folder.

    ``scan_topic``: the LaserScan topic the run used (may be omitted when the bag has one).
    """
    from dynslam2d.io.annotations import read_people_annotations
    from dynslam2d.io.runfolder import read_removed_mask, read_run_trajectory, read_tracks

    p = params or PeopleParams()
    mask = read_removed_mask(run_dir)
    tracks = read_tracks(run_dir)
    traj = read_run_trajectory(run_dir)
    ann = read_people_annotations(bag, scan_topic=scan_topic, people_topic=people_topic)
    return people_metrics(ann, mask.removed, mask.stamps, traj.stamps, traj.poses, tracks, p)


__all__ = ["PeopleMetrics", "PeopleParams", "PersonResult", "evaluate_people", "people_metrics"]
