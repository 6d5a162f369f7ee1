"""The tracker's faster per-track loops (issue 9 speed) against the plain computations they replace: the
vacated-space search (the stored scan whose age is nearest each free-space reference age) on random stamp
lists and on a simulated box driving away from the laser."""

from __future__ import annotations

import bisect
import math
import random

import numpy as np
from conftest import room_box_scan

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.kernels import segment_means
from dynslam2d.detect.tracker import _nearest_age
from dynslam2d.types import Pose2D, Scan

N = 360


def _window_argmin(stamps: list[float], t: float, a: float) -> int:
    """The search as first written: np.argmin of |age − a| over the six entries around the insertion point."""
    ins = bisect.bisect_left(stamps, t - a)
    lo, hi = max(ins - 3, 0), min(ins + 3, len(stamps))
    dev = np.abs((t - np.asarray(stamps[lo:hi])) - a)
    return -1 if np.isnan(dev).all() else lo + int(np.nanargmin(dev))


def test_nearest_age_is_the_window_argmin_on_random_stamp_lists() -> None:
    """Scan periods of 0.03-0.5 s, repeated stamps (dt = 0), stamps 1e-7 s apart, epoch-sized stamps and ages
    before / inside / after the stored span: always the same entry as the six-wide argmin, first one on ties."""
    rng = random.Random(7)
    ties = 0
    for _ in range(20000):
        base = rng.choice([0.0, 1000.0, 1.3e9])
        stamps, x = [], base
        for _ in range(rng.randint(1, 25)):
            x += rng.choice([0.0, 0.0, 1e-7, 0.033, 0.0667, 0.1, 0.3, 0.5])
            stamps.append(x)
        t = x + rng.choice([0.0, 0.03, 0.0667, 0.3, 0.8, 3.0])
        for a in (0.3, 0.8, rng.random()):
            j = _nearest_age(stamps, len(stamps), t, a)
            assert j == _window_argmin(stamps, t, a), (stamps, t, a)
            ties += j + 1 < len(stamps) and stamps[j + 1] == stamps[j]
    assert ties > 100  # repeated stamps were exercised: the first of equal entries is taken
    assert _nearest_age([1.0, 2.0], 2, math.nan, 0.3) == -1  # nothing comparable


def _scan(pose: Pose2D, box_x: float, stamp: float, seed: int) -> Scan:
    return room_box_scan(pose, (box_x, 0.0, 0.6, 0.6), stamp, seed, N)


def _vacated_reference(tr: Tracker, t: float) -> dict[int, float]:
    """Tracker._vacated with the plain window argmin (the code before the faster search)."""
    chunks, owners, counts = [], [], [0]
    for k in tr._tracks:
        for a in tr._free.ref_ages:
            if not k.past:
                continue
            j = _window_argmin(k.past_t, t, a)
            if t - k.past_t[j] > 0.0:
                chunks.append(k.past[j][1])
                owners.append(k.id)
                counts.append(k.past[j][1].shape[0])
    out: dict[int, float] = {}
    if chunks:
        free = tr._free.seen_through_by(tr._cur_ref, np.concatenate(chunks))
        for tid, f in zip(owners, segment_means(free.astype(np.float64), np.cumsum(counts)).tolist()):
            out[tid] = max(out.get(tid, 0.0), f)
    return out


def test_vacated_space_of_a_receding_box_matches_the_plain_search() -> None:
    """A box driving straight away from the laser at 1.2 m/s: the laser sees through where its face was (the
    vacated fraction is high), and the faster search picks the same stored scans as the plain one every step."""
    tr = Tracker(DetectConfig())
    pose = Pose2D(-5.0, 0.0, 0.0)
    checked, high = 0, 0
    for i in range(45):
        t = i / 15.0
        tr.update(_scan(pose, -3.5 + 1.2 * t, t, i), pose)
        if i >= 10:
            got = tr._vacated(tr._tracks, t)
            assert got == _vacated_reference(tr, t)
            checked += len(got)
            high += any(v > 0.5 for v in got.values())
    assert checked >= 30 and high >= 20  # the box's track had vacated space at almost every step
