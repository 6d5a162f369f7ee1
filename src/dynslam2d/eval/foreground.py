"""Foreground and background removals for a motionless sensor: ``dynslam2d eval foreground``.

With a laser that never moves, what is always there is the per-beam median range:
the median of each beam's returns over the whole recording (no-return readings left
out; :func:`dynslam2d.eval.stationary.median_background_scan` with no minimum share).
A beam of a scan is **foreground** when its return lies at least ``margin`` (default
0.3 m) in front of that background range — something (usually a person) stood
between the sensor and the background (a beam that never returns has no background
and is never foreground). Of the other returns, those of beams that return in at
least half of the scans are **background**; those of beams that usually return
nothing (open space beyond the sensor's reach) are **rare-beam returns**: their
median is set by whatever passed through them, mostly people, so they are neither
a trustworthy background nor counted as foreground, and are reported apart.
docs/real.md uses this for the stationary leg_tracker bags:

* foreground_removed_share = removed foreground beams / foreground beams (should be high),
* background_removed_share = removed background beams / background beams (should be ≈ 0),
* rare_removed_share = removed rare-beam returns / rare-beam returns,
* scans_with_foreground = scans with at least ``min_beams`` (5) foreground beams.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.eval.stationary import median_background_scan
from dynslam2d.types import Scan

#: Default margin in front of the background for a foreground beam, m.
FOREGROUND_MARGIN = 0.3
#: Foreground beams a scan needs to count as "with foreground".
MIN_FOREGROUND_BEAMS = 5
#: Share of scans in which a beam must return for its median to be a background.
STABLE_SHARE = 0.5


def foreground_mask(scans: Sequence[Scan],
                    margin: float = FOREGROUND_MARGIN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(foreground, valid, stable)``: (n, beams) bool masks of foreground beams and of beams
    with a return, and the (beams,) mask of beams that return in ≥ :data:`STABLE_SHARE` of the scans.

    Raises:
        DynSlamError: no scans, or scans whose beam counts differ.
    """
    if not scans:
        raise DynSlamError("foreground: no scans")
    nb = scans[0].n_beams
    if any(s.n_beams != nb for s in scans):
        raise DynSlamError(f"foreground: scans have different beam counts (first has {nb}); "
                           "the background needs one beam geometry")
    background = median_background_scan(scans, min_valid_share=0.0).ranges  # NaN: never returned
    valid = np.vstack([s.valid_mask() for s in scans])
    ranges = np.vstack([s.ranges for s in scans])
    with np.errstate(invalid="ignore"):
        fg = valid & (ranges <= background[None, :] - margin)
    return fg, valid, valid.mean(axis=0) >= STABLE_SHARE


@dataclass(frozen=True)
class ForegroundRemoval:
    """Removed foreground / background beams of a run (counts summed over the scans scored)."""

    scans: int
    scans_with_foreground: int
    foreground_beams: int
    foreground_removed: int
    foreground_removed_share: float
    background_beams: int
    background_removed: int
    background_removed_share: float
    rare_beams: int
    rare_removed: int
    rare_removed_share: float
    margin_m: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def foreground_removal(
    scans: Sequence[Scan],
    removed: np.ndarray,
    removed_stamps: np.ndarray,
    margin: float = FOREGROUND_MARGIN,
    min_beams: int = MIN_FOREGROUND_BEAMS,
) -> ForegroundRemoval:
    """Score a run's removal mask against the foreground of ``scans`` (the recording).

    Rows of ``removed`` are matched to the scans by stamp (within 1 µs); scans the run
    skipped are left out. The background is built from every scan given.

    Raises:
        DynSlamError: no common stamp, or a beam count that differs from the recording's.
    """
    fg, valid, stable = foreground_mask(scans, margin)
    stamps = np.array([s.stamp for s in scans])
    rs = np.asarray(removed_stamps, dtype=np.float64)
    rem = np.asarray(removed, dtype=bool)
    if rem.ndim != 2 or rem.shape[1] != fg.shape[1]:
        raise DynSlamError(f"foreground: the run's mask has shape {rem.shape}, the recording {fg.shape[1]} beams "
                           f"per scan (was the run made from this recording and topic?)")
    order = np.argsort(rs, kind="stable")
    srt = rs[order]
    rows = np.full(stamps.shape[0], -1)
    if srt.shape[0]:
        pos = np.clip(np.searchsorted(srt, stamps), 0, srt.shape[0] - 1)
        for c in (pos, np.clip(pos - 1, 0, None)):  # the stamps either side
            hit = (rows < 0) & (np.abs(srt[c] - stamps) <= 1e-6)
            rows[hit] = order[c][hit]
    keep = rows >= 0
    if not keep.any():
        raise DynSlamError("foreground: no scan of the recording has a stamp in the run "
                           "(was the run made from this recording and topic?)")
    fg, valid, r = fg[keep], valid[keep], rem[rows[keep]]
    bg = valid & ~fg & stable[None, :]
    rare = valid & ~fg & ~stable[None, :]
    nf, nb, nr = int(fg.sum()), int(bg.sum()), int(rare.sum())
    rf, rb, rr = int((r & fg).sum()), int((r & bg).sum()), int((r & rare).sum())
    return ForegroundRemoval(
        scans=int(keep.sum()),
        scans_with_foreground=int((fg.sum(axis=1) >= min_beams).sum()),
        foreground_beams=nf,
        foreground_removed=rf,
        foreground_removed_share=rf / nf if nf else float("nan"),
        background_beams=nb,
        background_removed=rb,
        background_removed_share=rb / nb if nb else float("nan"),
        rare_beams=nr,
        rare_removed=rr,
        rare_removed_share=rr / nr if nr else float("nan"),
        margin_m=float(margin),
    )


def evaluate_foreground(
    input: str | os.PathLike[str],
    run_dir: str | os.PathLike[str],
    *,
    topic: str | None = None,
    margin: float = FOREGROUND_MARGIN,
) -> ForegroundRemoval:
    """:func:`foreground_removal` on a recording (any input ``open_source`` reads) and a results folder."""
    from dynslam2d.inputs import open_source
    from dynslam2d.io.runfolder import read_removed_mask

    if not margin > 0:
        raise DynSlamError(f"foreground: margin must be > 0 m, got {margin}")
    mask = read_removed_mask(run_dir)
    scans = list(open_source(input, topic))
    return foreground_removal(scans, mask.removed, mask.stamps, margin)


__all__ = ["ForegroundRemoval", "evaluate_foreground", "foreground_mask", "foreground_removal"]
