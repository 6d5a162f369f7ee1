"""Retroactive erasure: take out of the online map what a track wrote while it stood still.

A parked car, a box standing in a corridor, a person waiting: while an object is not in
the dynamic set M its points are mapped like structure. When it starts to move and
enters M, :class:`EvidenceLedger` removes the evidence those points added (docs/maps.md,
"Retroactive erasure").

Bookkeeping, per track and map level, at every map update (the pipeline calls
:meth:`EvidenceLedger.before_update` and :meth:`EvidenceLedger.after_update` around
:meth:`HectorSlam.update_map`):

* the hit cells of the track's kept beams in that scan, **only** where no other kept
  beam of the same scan hit the same cell (a cell shared with a wall is the wall's);
* the log-odds the scan added there (after − before; a hit cell gets exactly one
  occupied update per scan, hector_mapping's ``OccGridMapBase::updateByScan``, so the
  change of that cell in that scan is the hit's evidence, including the cap);
* whether the cell was unknown before the track's first hit and nothing but the track's
  hits touched it since (then erasure returns it to *unknown*).

Erasure (:meth:`EvidenceLedger.erase_entering`) subtracts the recorded log-odds from each
recorded cell where they make up at least ``erase_min_share`` of the cell's log-odds (a wall
cell that many scans hit keeps the few hits a false track added) — a cell that was free before the object stood there
is free again, one that only the object made known is unknown again — and refreshes the probability cache
of those cells. No other cell of any level changes. A track's evidence is erased when it
is in the pipeline's removal set, *stood* before it entered it (slower than ``stand_speed``
at one place for ``link_min_stand``: what a walker wrote in the second before it joined M
is left to the clean-up pass) and has moved ``erase_min_travel`` from where it entered it
(a false track that is in M for a moment without going anywhere erases nothing); evidence
of a track that ended while the object stood (the robot drove away) is kept for
``ledger_keep_s`` (only if the track was confirmed: tentative clutter is dropped) and erased
with a track that stood where the ended track last was and then enters M.

Frames and units: cells are absolute level indices (cell (i, j) centred at
(i·r_k, j·r_k) in the map frame, :mod:`dynslam2d.slam.grid`), stable when a level grows;
distances in m, stamps in s, log-odds dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.detect.memoryconfig import MemoryConfig
from dynslam2d.slam.grid import MultiResMap
from dynslam2d.types import Pose2D, Scan, Track


@dataclass(eq=False)
class _LevelRecord:
    """Evidence of one track on one map level: absolute cell → [added log-odds, pure, last update index]."""

    cells: dict[tuple[int, int], list] = field(default_factory=dict)


@dataclass(eq=False)
class _Ledger:
    """What one track's points wrote into the map while it was not removed."""

    id: int
    first_box: tuple[float, float, float]  # centre x, y and half of the longer side where first seen, m
    first_t: float  # stamp when the track was first reported, s
    last_box: tuple[float, float, float]  # the same where last seen, m
    last_seen: float  # stamp, s
    levels: list[_LevelRecord]
    m_start: tuple[float, float] | None = None  # centre when first in the removal set, m
    linked: bool = False  # ended-track evidence already joined to a live track
    confirmed: bool = False  # the track was reported confirmed at least once (not only tentative clutter)
    skip: bool = False  # this stay in the removal set erases nothing (the track did not stand before it)

    @property
    def n_cells(self) -> int:
        return sum(len(lv.cells) for lv in self.levels)


@dataclass(eq=False)
class PendingUpdate:
    """Cells and log-odds read before one map update (:meth:`EvidenceLedger.before_update`)."""

    per_track: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]  # id → per level (cells, before, uidx)


def _box_key(t: Track) -> tuple[float, float, float]:
    b = t.box
    return (float(b.px), float(b.py), 0.5 * float(max(b.length, b.width)))


class EvidenceLedger:
    """Per-track record of map evidence and its erasure (module docstring)."""

    def __init__(self, config: MemoryConfig, laser_min_dist: float, laser_max_dist: float) -> None:
        self.config = config
        self.laser_min_dist = float(laser_min_dist)
        self.laser_max_dist = float(laser_max_dist)
        self._ledgers: dict[int, _Ledger] = {}
        self._ended: dict[int, _Ledger] = {}
        #: live track id → [box where it stands, stamp it began standing there, last stamp it stood there]
        self._first: dict[int, list] = {}
        #: absolute finest-level cells whose evidence was erased (for map.png), with the count of events
        self.erased_cells: set[tuple[int, int]] = set()
        self.stats = {"erasures": 0, "tracks_erased": 0, "cells_changed": 0, "cells_to_unknown": 0,
                      "ended_ledgers_linked": 0, "cells_recorded": 0}

    # ------------------------------------------------------------------ recording
    def before_update(self, scan: Scan, pose: Pose2D, tracks: list[Track], removed: np.ndarray,
                      hmap: MultiResMap) -> PendingUpdate | None:
        """Read, before the map update with ``scan`` (beams ``removed`` taken out) at ``pose``, the
        log-odds of the cells each track's kept beams will hit (removed beams, those of the tracks in the
        removal set, are not recorded). Returns None when nothing is to be recorded."""
        mine = [t for t in tracks if t.beams.shape[0]]
        if not mine:
            return None
        r = scan.ranges
        with np.errstate(invalid="ignore"):
            valid = scan.valid_mask() & (r > self.laser_min_dist) & (r < self.laser_max_dist) & ~removed
        owner = np.full(r.shape[0], -1, dtype=np.int64)
        for t in mine:
            owner[t.beams] = t.id
        idx = np.flatnonzero(valid)
        if idx.shape[0] == 0:
            return None
        a = scan.angles[idx]
        pts = pose.transform_points(np.column_stack((r[idx] * np.cos(a), r[idx] * np.sin(a))))
        own = owner[idx]
        if not (own >= 0).any():
            return None
        per_track: dict[int, list] = {}
        for lv in hmap.levels:
            cells = np.floor(pts / lv.resolution + 0.5).astype(np.int64)
            key = cells[:, 0] * 4294967296 + cells[:, 1]  # (i, j) as one integer (|i|, |j| < 2^31)
            other = np.unique(key[own < 0])
            for t in mine:
                sel = own == t.id
                if not sel.any():
                    continue
                ck, first = np.unique(key[sel], return_index=True)
                excl = ~np.isin(ck, other, assume_unique=True)
                c = cells[sel][first[excl]]
                before, uidx = self._read(lv, c)
                per_track.setdefault(t.id, []).append((c, before, uidx))
        for t in mine:
            if t.id in per_track:
                if t.id not in self._ledgers:
                    self._ledgers[t.id] = self._new_ledger(t, t.stamp, len(hmap.levels))
        return PendingUpdate(per_track) if per_track else None

    def _new_ledger(self, t: Track, stamp: float, n_levels: int) -> _Ledger:
        """An empty ledger of ``t``; its first box is where the track was first reported."""
        box, t0, _ = self._first.get(t.id, (_box_key(t), stamp, stamp))
        return _Ledger(t.id, box, t0, _box_key(t), stamp, [_LevelRecord() for _ in range(n_levels)])

    @staticmethod
    def _read(lv, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log-odds (float64) and update index of absolute cells (0 and −1 outside the level's array)."""
        n = cells.shape[0]
        lo = np.zeros(n)
        ui = np.full(n, -1, dtype=np.int64)
        if lv.empty or n == 0:
            return lo, ui
        h, w = lv.shape
        col = cells[:, 0] - lv.i0
        row = cells[:, 1] - lv.j0
        ok = (col >= 0) & (row >= 0) & (col < w) & (row < h)
        lo[ok] = lv.logodds[row[ok], col[ok]]
        ui[ok] = lv.uidx[row[ok], col[ok]]
        return lo, ui

    def after_update(self, pending: PendingUpdate, hmap: MultiResMap) -> None:
        """Record the evidence the map update added in the cells read by :meth:`before_update`."""
        cap = self.config.max_ledger_cells
        for tid, per_level in pending.per_track.items():
            led = self._ledgers.get(tid)
            if led is None:
                continue
            for k, (cells, before, ui_before) in enumerate(per_level):
                lv = hmap.levels[k]
                after, ui_after = self._read(lv, cells)
                rec = led.levels[k].cells
                for (i, j), b, a, ub, ua in zip(cells.tolist(), before.tolist(), after.tolist(), ui_before.tolist(),
                                                ui_after.tolist()):
                    if ua == ub:
                        continue  # not updated (outside the array, or the ray was skipped)
                    key = (i, j)
                    e = rec.get(key)
                    if e is None:
                        if len(rec) >= cap:
                            continue
                        rec[key] = [a - b, ub < 0, ua]
                        self.stats["cells_recorded"] += 1
                    else:
                        e[0] += a - b
                        e[1] = e[1] and ub == e[2]  # nothing but this track touched it since its last hit
                        e[2] = ua

    def observe(self, tracks: list[Track], removing: set[int], stamp: float) -> None:
        """Keep each live track's last box; move ledgers of ended tracks aside; drop old ones."""
        live = {t.id: t for t in tracks}
        reach = self.config.link_margin + 0.5
        for t in tracks:
            a = self._first.get(t.id)
            if a is None:
                self._first[t.id] = [_box_key(t), stamp, stamp]
            elif t.id not in removing and float(np.hypot(t.velocity[0], t.velocity[1])) < self.config.stand_speed:
                if math.hypot(t.box.px - a[0][0], t.box.py - a[0][1]) <= reach:
                    a[2] = stamp  # still standing where it stood
                else:
                    self._first[t.id] = [_box_key(t), stamp, stamp]  # standing at a new place
        if len(self._first) > len(live):
            self._first = {tid: b for tid, b in self._first.items() if tid in live}
        for tid in list(self._ledgers):
            t = live.get(tid)
            if t is None:
                led = self._ledgers.pop(tid)
                if led.confirmed:  # tentative clutter (wall fragments, noise) is never linked
                    self._ended[tid] = led
            elif tid not in removing:
                led = self._ledgers[tid]
                led.m_start, led.skip, led.linked = None, False, False  # out of the removal set (again)
                led.last_box = _box_key(t)
                led.last_seen = stamp
                led.confirmed = led.confirmed or t.state != "tentative"
        keep = self.config.ledger_keep_s
        for tid in [i for i, led in self._ended.items() if stamp - led.last_seen > keep]:
            del self._ended[tid]

    # ------------------------------------------------------------------ erasure
    def erase_entering(self, tracks: list[Track], removing: set[int], stamp: float, hmap: MultiResMap) -> int:
        """Erase the evidence of every live track in the removal set ``removing`` (ids) that has moved
        ``erase_min_travel`` from where it was first removed, with the evidence of ended tracks that stood
        where it was first seen. Returns the number of cells changed on the finest level."""
        if not self.config.erase:
            return 0
        changed = 0
        for t in tracks:
            if t.id not in removing:
                continue
            led = self._ledgers.get(t.id)
            if led is None:
                led = self._new_ledger(t, stamp, len(hmap.levels))
                self._ledgers[t.id] = led
            x, y = float(t.box.px), float(t.box.py)
            if led.m_start is None:
                led.m_start = (x, y)
                (fx, fy, fh), f_t, last_t = self._first.get(t.id, (led.first_box, led.first_t, led.first_t))
                led.first_box, led.first_t = (fx, fy, fh), f_t
                # only what stood before it moved wrote evidence worth erasing (a person born walking enters
                # M within a second: its few early hits are left to the clean-up pass), and only it may be
                # what ended tracks saw parked where it stood
                stood = (last_t - f_t >= self.config.link_min_stand
                         and math.hypot(x - fx, y - fy) <= self.config.link_margin + 1.0)
                led.skip = not stood
                led.linked = not stood
            if led.skip or math.hypot(x - led.m_start[0], y - led.m_start[1]) < self.config.erase_min_travel:
                continue
            if not led.linked:
                led.linked = True
                for other in self._linked_ended(led):
                    changed += self._erase(other, hmap)
                    self.stats["ended_ledgers_linked"] += 1
                    del self._ended[other.id]
            if led.n_cells:
                changed += self._erase(led, hmap)
        return changed

    def _linked_ended(self, led: _Ledger) -> list[_Ledger]:
        """Ended ledgers whose last box lies where ``led``'s track was first seen."""
        fx, fy, fh = led.first_box
        out = []
        for other in self._ended.values():
            ox, oy, oh = other.last_box
            if math.hypot(ox - fx, oy - fy) <= max(fh, oh) + self.config.link_margin:
                out.append(other)
        return out

    def _erase(self, led: _Ledger, hmap: MultiResMap) -> int:
        """Subtract ``led``'s evidence from every level (only its cells change); clear the ledger."""
        n0 = 0
        for k, rec in enumerate(led.levels):
            if not rec.cells:
                continue
            lv = hmap.levels[k]
            keys = np.array(list(rec.cells.keys()), dtype=np.int64).reshape(-1, 2)
            vals = list(rec.cells.values())
            delta = np.array([v[0] for v in vals])
            pure = np.array([v[1] for v in vals], dtype=bool)
            last = np.array([v[2] for v in vals], dtype=np.int64)
            col = keys[:, 0] - lv.i0
            row = keys[:, 1] - lv.j0
            h, w = lv.shape
            ok = (col >= 0) & (row >= 0) & (col < w) & (row < h)
            col, row, delta, pure, last = col[ok], row[ok], delta[ok], pure[ok], last[ok]
            cur = lv.logodds[row, col].astype(np.float64)
            # a cell whose log-odds the track's hits make up only a small part of is the structure's
            mine = delta >= self.config.erase_min_share * cur
            col, row, delta, pure, last, cur = col[mine], row[mine], delta[mine], pure[mine], last[mine], cur[mine]
            keys = keys[ok][mine]
            # unknown again: the track's hits made the cell known and nothing else touched it since
            unknown = pure & (lv.uidx[row, col] == last)
            new = np.where(unknown, 0.0, cur - delta).astype(np.float32)
            lv.logodds[row, col] = new
            lv.prob[row, col] = np.where(unknown, 0.5, 1.0 / (1.0 + np.exp(-new.astype(np.float64))))
            lv.uidx[row, col] = np.where(unknown, -1, lv.uidx[row, col])
            if k == 0:
                n0 = int(col.shape[0])
                self.stats["cells_to_unknown"] += int(unknown.sum())
                self.erased_cells.update(map(tuple, keys.tolist()))
            rec.cells.clear()
        self.stats["cells_changed"] += n0
        self.stats["erasures"] += 1
        self.stats["tracks_erased"] += 1
        hmap.version += 1
        return n0

    # ------------------------------------------------------------------ output
    def erased_mask(self, origin: tuple[float, float], shape: tuple[int, int], resolution: float) -> np.ndarray:
        """(H, W) bool over a finest-level map whose lower-left cell corner is ``origin`` (m): True where
        evidence was erased."""
        out = np.zeros(shape, dtype=bool)
        if not self.erased_cells:
            return out
        c = np.array(list(self.erased_cells), dtype=np.int64)
        # cell i is centred at i·r: its lower-left corner at (i − 0.5)·r
        col = np.round((c[:, 0] - 0.5) - origin[0] / resolution).astype(np.int64)
        row = np.round((c[:, 1] - 0.5) - origin[1] / resolution).astype(np.int64)
        ok = (col >= 0) & (row >= 0) & (col < shape[1]) & (row < shape[0])
        out[row[ok], col[ok]] = True
        return out

    def summary(self) -> dict[str, int]:
        """Counters for summary.json's ``memory`` block."""
        return {**self.stats, "erased_cells_finest": len(self.erased_cells),
                "ledgers_live": len(self._ledgers), "ledgers_ended": len(self._ended)}


__all__ = ["EvidenceLedger", "PendingUpdate"]
