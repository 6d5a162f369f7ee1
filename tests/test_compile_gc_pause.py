"""The cyclic garbage collector off in a cold command-line run while its kernels compile, back on (frozen heap, the
same thresholds) once its scans compile nothing any more (jitcache.CompileCollectorPause; docs/speed.md, pass cmp143).
"""

from __future__ import annotations

import gc

import pytest

from dynslam2d import cli, jitcache


@pytest.fixture
def collector_restored():
    """The collector on at the start of each test (what a command-line run starts with, whatever an earlier test in
    this process left), and as it was (on or off, its thresholds, nothing frozen) after it."""
    threshold, frozen, enabled = gc.get_threshold(), gc.get_freeze_count(), gc.isenabled()
    gc.enable()
    yield
    if enabled:
        gc.enable()
    else:
        gc.disable()
    gc.set_threshold(*threshold)
    if frozen == 0:
        gc.unfreeze()


def test_pause_resumes_after_quiet_scans_with_the_thresholds_it_had(monkeypatch, collector_restored):
    clock = [10.0]
    monkeypatch.setattr(jitcache, "compile_seconds", lambda: clock[0])
    gc.set_threshold(20000, 100, 10)  # (a cold run's compile thresholds, jitcache.lean_compile_gc)
    pause = jitcache.CompileCollectorPause(quiet_scans=3)
    assert pause.pause() and not gc.isenabled()
    for compiled in (1.0, 0.5, 0.0, 0.0, 2.0, 0.0, 0.0):  # compiles in scans 1, 2 and 5: never 3 quiet in a row
        clock[0] += compiled
        pause.on_scan(None, None, None)
        assert not gc.isenabled() and pause.paused
    pause.on_scan(None, None, None)  # the third quiet scan in a row
    assert gc.isenabled() and not pause.paused and pause.resumed_after == 8
    assert gc.get_threshold() == (20000, 100, 10)
    assert gc.get_freeze_count() > 0  # what the compile left alive is not walked again
    pause.resume()
    pause.on_finish(None, None)
    assert gc.isenabled() and pause.resumed_after == 8


def test_pause_ends_at_the_run_end_and_leaves_a_disabled_collector_alone(monkeypatch, collector_restored):
    monkeypatch.setattr(jitcache, "compile_seconds", lambda: 0.0)
    pause = jitcache.CompileCollectorPause(quiet_scans=3)
    assert pause.pause()
    pause.on_scan(None, None, None)
    pause.on_finish(None, None)  # a run of fewer scans than quiet_scans
    assert gc.isenabled() and pause.resumed_after == 1
    gc.disable()  # a program that switched it off itself: left off
    other = jitcache.CompileCollectorPause()
    assert not other.pause()
    other.resume()
    assert not gc.isenabled()


def _run_seeing_the_collector(monkeypatch, tmp_path, cold: bool) -> list[bool]:
    """``dynslam2d run`` of a short simulation with the cache taken as cold or warm (no background compile);
    whether the collector was on after each scan, as an observer after the run's own saw it."""
    from dynslam2d.cli import app

    seen: list[bool] = []

    class Spy:
        def on_scan(self, scan, step, pipeline):
            seen.append(gc.isenabled())

        def on_finish(self, result, pipeline):
            pass

    run_observers = cli._run_observers
    monkeypatch.setattr(cli, "_run_observers", lambda *a, **k: [*run_observers(*a, **k), Spy()])
    monkeypatch.setattr(cli, "_cold_start", lambda background=None: (cold, None))
    try:
        app(["run", "sim:static", "--duration", "1", "--out", str(tmp_path / "run"), "-q"], standalone_mode=False)
    except SystemExit as exc:
        assert not exc.code
    return seen


def test_cold_run_pauses_the_collector_for_its_first_scans_only(monkeypatch, tmp_path, collector_restored):
    threshold, frozen = gc.get_threshold(), gc.get_freeze_count()
    seen = _run_seeing_the_collector(monkeypatch, tmp_path, cold=True)
    # off from the first scan; back on after the first COMPILE_QUIET_SCANS scans that compiled nothing (a scan
    # compiles only where this checkout's kernels are not cached yet), and on to the end
    assert True in seen, "the collector stayed off through the scans"
    back = seen.index(True)
    assert back >= jitcache.COMPILE_QUIET_SCANS - 1 and all(seen[back:]) and len(seen) > back + 5
    assert gc.isenabled() and gc.get_threshold() == threshold and gc.get_freeze_count() > frozen


def test_warm_run_leaves_the_collector_alone(monkeypatch, tmp_path, collector_restored):
    frozen = gc.get_freeze_count()
    seen = _run_seeing_the_collector(monkeypatch, tmp_path, cold=False)
    assert seen and all(seen)
    assert gc.isenabled() and gc.get_freeze_count() == frozen
