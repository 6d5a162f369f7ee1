"""The background compile started before ``run`` imports its modules on an empty cache, and without the cyclic
collector (pass cmp142, issue 13 item 2, docs/speed.md).

An empty cache folder (no numba index file) is a first run: ``dynslam2d run`` starts the second process at once
instead of after importing the configuration, numba and the kernel modules; a folder holding any index is left to
the kernel check as before. The background process compiles with the collector off.
"""

from __future__ import annotations

import gc
import signal

from dynslam2d import cli, jitcache, jitwarm


def test_cache_holds_no_index_only_for_an_empty_or_missing_folder(tmp_path, monkeypatch):
    monkeypatch.setenv(jitcache.CACHE_ENV, str(tmp_path / "missing"))
    assert jitcache.cache_holds_no_index()
    folder = tmp_path / "cache"
    (folder / "a_123").mkdir(parents=True)
    (folder / "a_123" / "m.f-10.py311.1.nbc").write_bytes(b"")  # (data without an index: numba cannot load it)
    assert jitcache.cache_holds_no_index(folder)
    (folder / "b_456").mkdir()
    (folder / "b_456" / "m.f-10.py311.nbi").write_bytes(b"")
    assert not jitcache.cache_holds_no_index(folder)
    monkeypatch.setenv(jitcache.CACHE_ENV, str(folder))
    assert not jitcache.cache_holds_no_index()
    monkeypatch.delenv(jitcache.CACHE_ENV)
    assert not jitcache.cache_holds_no_index()  # (numba's own folders: the kernel check decides)


def test_run_starts_the_background_compile_early_on_an_empty_cache_only(monkeypatch):
    started: list[int] = []
    monkeypatch.setattr(jitwarm, "start_background_compile", lambda: started.append(1) or "early")
    for empty, want in ((True, "early"), (False, None)):
        monkeypatch.setattr(jitcache, "cache_holds_no_index", lambda e=empty: e)
        assert cli._early_background_compile() == want
    assert started == [1]
    # the early process makes the start-up check cold without asking the cache again, and is not started twice
    monkeypatch.setattr(jitcache, "lean_numba_compile", lambda: False)  # (numba of this test process left as it is)
    monkeypatch.setattr(jitcache, "lean_compile_gc", lambda: started.append(2) or False)
    monkeypatch.setattr(jitcache, "kernel_cache_state", lambda: jitcache.KernelCacheState(40, 40))  # (a warm cache)
    assert cli._cold_start("early") == (True, "early")
    assert started == [1, 2]


def test_background_process_compiles_with_the_collector_off(monkeypatch):
    seen: list[bool] = []
    monkeypatch.setattr(jitwarm, "compile_balanced", lambda *a, **k: seen.append(gc.isenabled()) or [])
    monkeypatch.setattr(jitcache, "lean_numba_compile", lambda: False)
    monkeypatch.setattr(jitcache, "lean_compile_gc", lambda: False)
    monkeypatch.setattr(jitcache, "load_blas_alone", lambda: False)
    monkeypatch.setattr(jitcache, "plain_numba_errors", lambda: False)
    handler = signal.getsignal(signal.SIGINT)
    try:
        jitwarm.main([])
    finally:
        gc.enable()
        signal.signal(signal.SIGINT, handler)  # (main ignores Ctrl-C)
    assert seen == [False]
