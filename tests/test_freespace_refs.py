"""Pass rest18: the free-space memory's choice of reference scans (``FreeSpaceMemory._refs``) by bisection on a
time-ordered buffer is the earlier scan of every buffered age, scan for scan, also with repeated stamps, ties, stamps
that go back and memories that drop scans."""

from __future__ import annotations

import numpy as np

from dynslam2d.detect.freespace import FreeSpaceMemory
from dynslam2d.types import Pose2D, Scan


def _old_refs(mem: FreeSpaceMemory, now: float) -> list:
    """The earlier implementation (pass front17's), every buffered age compared."""
    out: list = []
    if not mem._buf:
        return out
    ages = [now - b.stamp for b in mem._buf]
    for a in mem.ref_ages:
        dev = [abs(x - a) for x in ages]
        j = dev.index(min(dev))
        if ages[j] > 0.0 and mem._buf[j] not in out:
            out.append(mem._buf[j])
    return out


def _scan(stamp: float) -> Scan:
    return Scan(stamp=stamp, angle_min=-1.0, angle_increment=0.1, ranges=np.full(21, 3.0), range_min=0.1,
                range_max=10.0)


def test_refs_by_bisection_equal_the_scan_of_every_age() -> None:
    rng = np.random.default_rng(7)
    pose = Pose2D(0.0, 0.0, 0.0)
    n_fast = 0
    for case in range(60):
        ages = [(0.3, 0.8), (0.8, 0.3), (0.3, 0.8, 0.3), (0.0,), (0.1, 0.1), (0.25, 0.5, 1.0)][case % 6]
        dyadic = case % 4 == 1  # (stamps and ages on a 1/16 s grid: exact differences, equal deviations both sides)
        if dyadic:
            ages = (0.25, 0.5, 0.25 + 0.0625)
        mem = FreeSpaceMemory(ref_ages=ages, max_age=float(rng.choice([0.6, 1.5, 3.0])))
        t = 100.0
        back = case % 3  # (1: stamps go back in the first 20 scans only, 2: all along)
        for i in range(150):
            # steps on a 0.05 s grid so that ages land exactly on the reference ages and on ties; repeats
            if dyadic:
                step = float(rng.choice([0.0, 0.0625, 0.125, 0.1875,
                                           -0.125 if back == 2 or (back and i < 20) else 0.0]))
            elif back == 2 or (back and i < 20):
                step = float(rng.choice([-0.3, -0.05, 0.0, 0.05, 0.1]))
            else:
                step = float(rng.choice([0.0, 0.05, 0.05, 0.1, 0.15, 0.25]))
            t = round(t + step, 2) if case % 2 and not dyadic else t + step
            s = _scan(t)
            mem.add(s, pose, s.valid_view())
            stamps = [b.stamp for b in mem._buf]
            assert (mem._descents == 0) == all(x <= y for x, y in zip(stamps, stamps[1:]))
            for now in (t, t + 0.0625, t + 0.3, t + 0.5625, t + float(rng.uniform(0.0, 1.0))):
                got = mem._refs(now)
                want = _old_refs(mem, now)
                assert [id(b) for b in got] == [id(b) for b in want]
                n_fast += mem._descents == 0
        mem.clear()
        assert mem._descents == 0 and mem._refs(t) == []
    assert n_fast > 10000  # (the bisection ran on most queries)


def test_refs_where_the_stamps_bisection_is_off_by_rounding() -> None:
    """Pass trk71: ``_refs`` bisects the stamps list at now − a and corrects with the exact test (now − stamp < a);
    with reads landing on the reference ages of the stamps (± an ulp) and stamps an ulp apart, on unix-time stamps
    (≈ 1.7e9 s, the bisection one index late) and on stamps from 0 s (now − stamp inexact: one late or early), the
    correction runs both ways and the choice is still the scan of every age, scan for scan (without the step back
    it is not)."""
    import math
    from bisect import bisect_right

    rng = np.random.default_rng(71)
    pose = Pose2D(0.0, 0.0, 0.0)
    off = {-1: 0, 1: 0}
    for case in range(40):
        mem = FreeSpaceMemory(ref_ages=(0.3, 0.8, 0.1 * (1 + case % 5)), max_age=1.5)
        t = 1.7e9 + float(rng.uniform(0.0, 1e4)) if case % 2 else float(rng.uniform(0.0, 0.05))
        for _ in range(40):
            r = int(rng.integers(3))  # (a step, an ulp — two stamps at nearly the same age — or a fixed period)
            t = t + float(rng.uniform(0.01, 0.12)) if r == 0 else math.nextafter(t, math.inf) if r == 1 else t + 0.05
            s = _scan(t)
            mem.add(s, pose, s.valid_view())
            assert mem._stamps == [b.stamp for b in mem._buf]
            stamps = mem._stamps
            nows = [x + a for x in stamps[-8:] for a in mem.ref_ages]
            nows += [math.nextafter(x, math.inf) for x in nows] + [math.nextafter(x, -math.inf) for x in nows]
            for now in nows:
                for a in mem.ref_ages:
                    exact = next((i for i, x in enumerate(stamps) if now - x < a), len(stamps))
                    k = bisect_right(stamps, now - a)
                    if k != exact:
                        off[1 if k > exact else -1] += 1
                want = _old_refs(mem, now)
                assert [id(b) for b in mem._refs(now)] == [id(b) for b in want]
    assert off[1] > 10 and off[-1] > 10  # (both corrections ran)
