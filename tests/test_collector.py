"""The collector's scope around the per-scan loop (dynslam2d.collector.scan_loop_gc, pipeline.run)."""

from __future__ import annotations

import gc

import pytest

from dynslam2d.collector import SCAN_LOOP_GC_THRESHOLD0, scan_loop_gc
from dynslam2d.pipeline import Pipeline, StepResult, run
from dynslam2d.sim import SimSource
from dynslam2d.types import Scan

BEFORE = (700, 10, 10)


@pytest.fixture
def thresholds():
    """CPython's default thresholds during the test; the process's own back afterwards."""
    saved = gc.get_threshold()
    enabled = gc.isenabled()
    gc.set_threshold(*BEFORE)
    gc.enable()
    try:
        yield
    finally:
        gc.set_threshold(*saved)
        if enabled:  # (a test that switched it off must not leave the rest of the suite without a collector)
            gc.enable()
        else:
            gc.disable()


def test_scope_raises_and_restores(thresholds) -> None:
    with scan_loop_gc(12345) as changed:
        assert changed
        assert gc.get_threshold() == (12345, 10, 10)
    assert gc.get_threshold() == BEFORE


def test_scope_restores_on_exception(thresholds) -> None:
    with pytest.raises(RuntimeError, match="inside"):
        with scan_loop_gc(5000):
            assert gc.get_threshold() == (5000, 10, 10)
            raise RuntimeError("inside")
    assert gc.get_threshold() == BEFORE


def test_scope_keeps_other_generations_and_higher_settings(thresholds) -> None:
    gc.set_threshold(700, 20, 30)
    with scan_loop_gc(9000):
        assert gc.get_threshold() == (9000, 20, 30)
    assert gc.get_threshold() == (700, 20, 30)
    gc.set_threshold(20000, 100, 10)  # a cold command-line run's compile setting: higher already
    with scan_loop_gc(9000) as changed:
        assert not changed
        assert gc.get_threshold() == (20000, 100, 10)
    assert gc.get_threshold() == (20000, 100, 10)


@pytest.mark.parametrize("threshold0", [None, 0, -1])
def test_scope_off(thresholds, threshold0) -> None:
    with scan_loop_gc(threshold0) as changed:
        assert not changed
        assert gc.get_threshold() == BEFORE
    assert gc.get_threshold() == BEFORE


def test_scope_leaves_a_disabled_collector(thresholds) -> None:
    gc.disable()
    with scan_loop_gc(9000) as changed:
        assert not changed
        assert gc.get_threshold() == BEFORE
    assert not gc.isenabled()
    gc.set_threshold(0)  # disabled by a zero threshold
    with scan_loop_gc(9000) as changed:
        assert not changed
    assert gc.get_threshold()[0] == 0


def test_scope_leaves_a_setting_made_inside(thresholds) -> None:
    with scan_loop_gc(9000):
        gc.set_threshold(3000, 10, 10)
    assert gc.get_threshold() == (3000, 10, 10)


class _Watch:
    """An observer noting the collector's thresholds at every scan; raises at scan ``fail_at`` (1-based)."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.seen: list[tuple[int, int, int]] = []
        self.fail_at = fail_at

    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None:
        self.seen.append(gc.get_threshold())
        if self.fail_at is not None and len(self.seen) == self.fail_at:
            raise RuntimeError("observer failed")

    def on_finish(self, result: object, pipeline: Pipeline) -> None:
        self.seen.append(gc.get_threshold())


def test_run_raises_the_threshold_during_its_loop_only(thresholds) -> None:
    watch = _Watch()
    res = run(SimSource("static", duration=2.0), observers=[watch])
    assert res.n_scans > 5
    loop, finish = watch.seen[:-1], watch.seen[-1]
    assert len(loop) == res.n_scans
    assert set(loop) == {(SCAN_LOOP_GC_THRESHOLD0, 10, 10)}
    assert finish == BEFORE  # the end-of-run work (and the observers' on_finish) run with the caller's setting
    assert gc.get_threshold() == BEFORE


def test_run_restores_the_threshold_when_the_loop_raises(thresholds) -> None:
    watch = _Watch(fail_at=3)
    with pytest.raises(RuntimeError, match="observer failed"):
        run(SimSource("static", duration=2.0), observers=[watch])
    assert watch.seen == [(SCAN_LOOP_GC_THRESHOLD0, 10, 10)] * 3
    assert gc.get_threshold() == BEFORE


def test_run_can_leave_the_collector_alone(thresholds) -> None:
    watch = _Watch()
    run(SimSource("static", duration=1.0), observers=[watch], gc_threshold0=None)
    assert set(watch.seen) == {BEFORE}
