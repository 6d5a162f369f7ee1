"""run()'s late observers (pass wall38): an observer with ``scan_batch`` > 1 gets every scan's ``on_scan`` call,
in order, in batches of that many scans, all before ``on_finish``; the others are called after every scan."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.pipeline import Pipeline, StepResult, _split_observers, run
from dynslam2d.sim import SimSource
from dynslam2d.types import Scan


class _Record:
    """Notes every call: (scan stamp, step index, step object, scans the pipeline had processed by then)."""

    def __init__(self, scan_batch: int | None = None) -> None:
        if scan_batch is not None:
            self.scan_batch = scan_batch
        self.calls: list[tuple[float, int, StepResult, int]] = []
        self.finished_after = -1

    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None:
        self.calls.append((scan.stamp, step.index, step, pipeline.slam.n_scans))

    def on_finish(self, result: object, pipeline: Pipeline) -> None:
        self.finished_after = len(self.calls)


def test_split_observers() -> None:
    a, b, c, d = _Record(), _Record(1), _Record(5), _Record(3)
    assert _split_observers([a, c, b, d]) == ([a, b], [c, d], 3)
    assert _split_observers([a, b]) == ([a, b], [], 1)


@pytest.mark.parametrize("batch", [3, 7])
def test_late_observers_see_every_scan_in_order_in_batches(batch: int) -> None:
    now, late, other = _Record(), _Record(batch), _Record(batch + 7)  # (the smallest batch is the late ones')
    res = run(SimSource("static", duration=2.0), observers=[late, now, other])
    n = res.n_scans
    assert n > 2 * batch + 1 and n % batch != 0  # (a last, partial batch)
    # the same calls, in scan order, the same step objects
    assert [c[:3] for c in late.calls] == [c[:3] for c in now.calls] == [c[:3] for c in other.calls]
    assert [c[1] for c in now.calls] == list(range(n))
    assert now.finished_after == late.finished_after == n  # every late call made before on_finish
    # the others right after their scan; the late ones once `batch` scans (or the loop) are done
    assert [c[3] for c in now.calls] == list(range(1, n + 1))
    seen = np.array([c[3] for c in late.calls])
    expect = np.minimum((np.arange(n) // batch + 1) * batch, n)
    assert seen.tolist() == expect.tolist()
    assert [c[3] for c in other.calls] == seen.tolist()


def test_late_observers_change_no_result() -> None:
    a = run(SimSource("static", duration=2.0), observers=[_Record()])
    b = run(SimSource("static", duration=2.0), observers=[_Record(4)])
    assert a.trajectory.poses.tobytes() == b.trajectory.poses.tobytes()
    assert a.grid.prob.tobytes() == b.grid.prob.tobytes()
