"""Pass trk71: ``Tracker._update_tracks``' per-pair bookkeeping, written for the common case (the re-acquired flag
from ``update_pairs``' ``info``, ``person`` kept as ``person_streak > 0``), leaves every updated track as the former
loop did: its free-space entries (values, snapshots of the stored points, which list they hold), stored points and
their first live entry, beams, flags and counters, and the updated set in the same insertion order (the used set is
gone since pass trk138: the kernel lists the unused detections, tests/test_detect_associate_fused.py)."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.detect import DetectConfig, Tracker
from dynslam2d.detect.tracktable import _PAST_COMPACT
from dynslam2d.sim import simulate
from dynslam2d.types import Pose2D


def _former_update_tracks(self, applied, dets, t) -> None:
    """``_update_tracks`` as it was before pass trk71 (main at 8535922), its ``missed`` list read from the applied
    flag 2 of ``info`` (the kernel's former 1 and its ``missed`` per track); the pairs and ``info`` rows taken from
    the kernel's applied rows (pass trk138), the detections taken into a set nothing reads any more."""
    pairs = [(r[0], r[1]) for r in applied]
    info = [r[2:] for r in applied]
    missed = {ti: ok == 2 for (ti, _), (ok, *_r) in zip(pairs, info)}
    tc = self.config.tracker
    nsus = tc.sustain_updates
    max_age = self._free.max_age if self._free is not None else None
    ref = self._cur_ref if self._free is not None else None
    tracks = self._tracks
    upd, used = self._updated, set()
    for (ti, di), (ok, start, npt, circle_person) in zip(pairs, info):
        if not ok:
            continue
        k, det = tracks[ti], dets[di]
        upd.add(k.id)
        used.add(di)
        arrays = det._s
        a0 = start - arrays.off
        past = k.past
        pa = k.past_a
        np0 = len(past)
        snap = ref is not None and np0 > pa
        if missed[ti]:
            k.past = []
            k.past_a = 0
            k.free.clear()
            k.fast = 0
            k.probation = k.in_m and not k.remembered
        k.merged = False
        person = det.person or circle_person == 1
        # (k.person = person: a field then, the streak's sign now — the test compares k.person with it)
        k.person_streak = k.person_streak + 1 if person else 0
        k.beams = arrays.beams[a0:a0 + npt]
        free = k.free
        free.append((det, ref, t, past, pa, np0) if snap else max(det.free_fraction, 0.0))
        if len(free) > nsus:
            del free[0]
        if max_age is not None:
            past = k.past
            past.append((t, arrays.pts, a0, npt))
            pa = k.past_a
            n = len(past)
            while pa < n and t - past[pa][0] > max_age:
                pa += 1
            if pa >= _PAST_COMPACT:
                k.past = past[pa:]
                pa = 0
            k.past_a = pa


class _LegsTracker(Tracker):
    """A tracker whose every third detection is taken as a merged pair of legs (``det.person``, set by the leg merge:
    few in the simulated scenes), in both trackers alike."""

    def _detect(self, scan, pose):
        dets = super()._detect(scan, pose)
        for j in range(0, len(dets), 3):
            dets[j].person = True
        return dets


class _FormerTracker(_LegsTracker):
    _update_tracks = _former_update_tracks


def _past_key(past: list, a: int, b: int) -> list:
    return [(e[0], e[2], e[3], e[1].shape) for e in past[a:b]]


def _state(tr: Tracker) -> tuple:
    """Everything the bookkeeping writes, comparable across two trackers (identities as relations within one)."""
    out = [list(tr._updated)]
    for k in tr._tracks:
        free = []
        for e in k.free:
            if type(e) is tuple:
                det, ref, t, past, a, b = e
                free.append(("snap", det._j, ref.stamp, t, a, b, _past_key(past, a, b), past is k.past))
            elif type(e) is float:
                free.append(("value", e))
            else:
                free.append(("det", e._j))
        out.append((k.id, free, _past_key(k.past, 0, len(k.past)), k.past_a, k.beams.tobytes(), k.person,
                    k.person_streak, k.merged, k.fast, k.probation, k.in_m))
    return tuple(out)


@pytest.mark.parametrize("free_space", [True, False])
def test_update_bookkeeping_is_the_former_loop(free_space: bool) -> None:
    cfg = DetectConfig()
    cfg.tracker.free_space_check = free_space
    sim = simulate("crowd", duration=12.0, seed=3)
    poses = [Pose2D.from_array(p) for p in sim.ground_truth.poses_in("first")]
    new, old = _LegsTracker(cfg), _FormerTracker(cfg)
    seen = {"reacquired": 0, "person": 0, "snap_old_list": 0, "updated": 0, "merged": 0}
    former = Tracker._update_tracks

    def counting(self, applied, dets, t):
        seen["reacquired"] += sum(1 for r in applied if r[2] == 2)
        seen["updated"] += sum(1 for r in applied if r[2])
        return former(self, applied, dets, t)

    Tracker._update_tracks = counting
    try:
        for i, (scan, pose) in enumerate(zip(sim.scans, poses)):
            if i % 5 == 0:  # (flags the management step sets: an update must clear them, in both trackers alike)
                for tr in (new, old):
                    for k in tr._tracks:
                        k.merged = k.merged or k.id % 2 == 0
            got = new.update(scan, pose)
            want = old.update(scan, pose)
            assert [(r.id, r.state, r.in_m) for r in got] == [(r.id, r.state, r.in_m) for r in want]
            a, b = _state(new), _state(old)
            assert a == b
            for k in new._tracks:
                seen["person"] += k.person_streak > 0
                seen["merged"] += k.merged
                seen["snap_old_list"] += any(type(e) is tuple and e[3] is not k.past for e in k.free)
    finally:
        Tracker._update_tracks = former
    assert seen["updated"] > 1000 and seen["reacquired"] > 5 and seen["person"] > 20 and seen["merged"] > 20
    if free_space:
        assert seen["snap_old_list"] > 20  # (snapshots holding a list the track no longer appends to)


def test_person_is_the_streak() -> None:
    """``_Track.person`` is ``person_streak > 0``; setting it False ends the streak, True starts one if none."""
    from dynslam2d.detect.tracktable import _new_track

    k = _new_track(1, 0.0, np.zeros(2), (0.0,) * 6, (0,) * 4, np.zeros(0, dtype=np.int64), [], [])
    assert k.person is False and k.person_streak == 0
    k.person_streak = 3
    assert k.person is True
    k.person = True
    assert k.person_streak == 3
    k.person = False
    assert k.person_streak == 0 and k.person is False
    k.person = True
    assert k.person_streak == 1
