"""Track paths from a run's track rows (:data:`dynslam2d.pipeline.TRACK_COLUMNS`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dynslam2d.types import Box


@dataclass(frozen=True, eq=False)
class TrackPath:
    """One track over the whole run, map frame.

    Attributes:
        id: track id.
        stamps: (n,) stamps of the scans that reported it, s.
        xy: (n, 2) box centres, m.
        velocity: (n, 2) velocity, m/s.
        in_m: (n,) bool, in the dynamic set M at that scan.
        states: (n,) state strings ("tentative", "confirmed", "coasting").
        last_box: the box of the last report.
    """

    id: int
    stamps: np.ndarray
    xy: np.ndarray
    velocity: np.ndarray
    in_m: np.ndarray
    states: np.ndarray
    last_box: Box

    @property
    def speed(self) -> np.ndarray:
        """(n,) |v|, m/s."""
        return np.hypot(self.velocity[:, 0], self.velocity[:, 1])

    @property
    def ever_confirmed(self) -> bool:
        return bool((self.states == "confirmed").any())

    @property
    def ever_in_m(self) -> bool:
        return bool(self.in_m.any())

    @property
    def length_m(self) -> float:
        """Length of the centre path, m."""
        if len(self.xy) < 2:
            return 0.0
        return float(np.hypot(*np.diff(self.xy, axis=0).T).sum())


def track_paths(track_rows: Sequence[tuple]) -> dict[int, TrackPath]:
    """Group ``track_rows`` (RunResult.track_rows / tracks.csv rows) by track id, in time order."""
    from dynslam2d.records import TrackRows

    if isinstance(track_rows, TrackRows):
        return _track_paths_compact(track_rows)
    by_id: dict[int, list[tuple]] = {}
    for row in track_rows:
        by_id.setdefault(int(row[1]), []).append(row)
    out: dict[int, TrackPath] = {}
    for tid, rows in by_id.items():
        rows.sort(key=lambda r: r[0])
        a = np.array([[r[0], r[3], r[4], r[8], r[9]] for r in rows], dtype=np.float64)
        last = rows[-1]
        out[tid] = TrackPath(
            id=tid,
            stamps=a[:, 0],
            xy=a[:, 1:3],
            velocity=a[:, 3:5],
            in_m=np.array([bool(r[10]) for r in rows]),
            states=np.array([str(r[2]) for r in rows]),
            last_box=Box(float(last[3]), float(last[4]), float(last[5]), float(last[6]), float(last[7])),
        )
    return out


def _track_paths_compact(rows: object) -> dict[int, TrackPath]:
    """:func:`track_paths` on a :class:`~dynslam2d.records.TrackRows` (vectorised grouping)."""
    a = rows.array()  # type: ignore[attr-defined]
    names = np.array(rows.state_names())  # type: ignore[attr-defined]
    out: dict[int, TrackPath] = {}
    if len(a) == 0:
        return out
    a = a[np.lexsort((a["stamp"], a["id"]))]
    ids, first = np.unique(a["id"], return_index=True)
    last = np.r_[first[1:], len(a)]
    xy = np.column_stack((a["x"], a["y"])).astype(np.float64)
    vel = np.column_stack((a["vx"], a["vy"])).astype(np.float64)
    states = names[a["state"]]
    for tid, i, j in zip(ids.tolist(), first.tolist(), last.tolist()):
        r = a[j - 1]
        out[int(tid)] = TrackPath(
            id=int(tid), stamps=a["stamp"][i:j].copy(), xy=xy[i:j], velocity=vel[i:j],
            in_m=a["in_M"][i:j].copy(), states=states[i:j],
            last_box=Box(float(r["x"]), float(r["y"]), float(r["heading"]), float(r["length"]), float(r["width"])),
        )
    return out


def final_confirmed(paths: dict[int, TrackPath], last_stamp: float | None) -> list[TrackPath]:
    """Tracks reported as confirmed at the last scan of the run (``last_stamp``, s)."""
    if last_stamp is None:
        return []
    return [p for p in paths.values() if p.stamps[-1] == last_stamp and p.states[-1] == "confirmed"]


def tracks_to_draw(paths: dict[int, TrackPath], last_stamp: float | None) -> list[TrackPath]:
    """The tracks worth a path on a figure: ever in M, or confirmed at the end (sorted by id)."""
    final = {p.id for p in final_confirmed(paths, last_stamp)}
    return sorted((p for p in paths.values() if p.ever_in_m or p.id in final), key=lambda p: p.id)


def boxes_to_draw(paths: dict[int, TrackPath], last_stamp: float | None) -> list[tuple[int, Box]]:
    """(id, last box) of the tracks confirmed at the last scan that were ever in M, by id: the moving
    objects the filter removed; a confirmed track never in M (often a piece of static wall) gets none."""
    return [(p.id, p.last_box) for p in sorted(final_confirmed(paths, last_stamp), key=lambda p: p.id)
            if p.ever_in_m]


#: Id labels closer than this to an already placed one are left out, in units of the map's longer side.
LABEL_GAP = 0.04
#: At most this many id labels per figure (in-M tracks and long paths first).
MAX_LABELS = 40


def label_tracks(tracks: Sequence[TrackPath], span: float, gap: float = LABEL_GAP,
                 max_labels: int = MAX_LABELS) -> list[TrackPath]:
    """The tracks whose id a figure labels at its last position: tracks in M first, then the
    longest paths; a label closer than ``gap`` × ``span`` (m; ``span`` the map's longer side) to
    one already placed is left out; at most ``max_labels`` (a pile of ids is unreadable)."""
    placed = np.zeros((0, 2))
    out: list[TrackPath] = []
    for t in sorted(tracks, key=lambda t: (not t.ever_in_m, -t.length_m)):
        if len(out) >= max_labels:
            break
        end = t.xy[-1]
        if len(placed) and float(np.min(np.hypot(*(placed - end).T))) < gap * span:
            continue
        placed = np.vstack((placed, end))
        out.append(t)
    return out


__all__ = ["LABEL_GAP", "MAX_LABELS", "TrackPath", "boxes_to_draw", "final_confirmed", "label_tracks",
           "track_paths", "tracks_to_draw"]
