"""Scratch folders for the benchmark scripts, removed when the script ends (shared by the benchmarks; not run by
pytest).

``tempfile.mkdtemp`` leaves its folder behind: one session of ``bench_compile.py`` left 266 MB of numba caches and
run folders in the temporary folder. :func:`scratch_dir` makes the same folder and removes it when the process that
made it exits: normally, on an uncaught exception, on ``SystemExit``, on Ctrl-C (``KeyboardInterrupt``) and on
SIGTERM (turned into ``SystemExit`` when nothing else handles it). A folder asked to be kept (a script's
``--keep``-style option, or ``BENCH_KEEP_SCRATCH=1`` in the environment for the scripts without one) is left alone;
the script reports where it is.

Child processes forked from the maker (``multiprocessing``) never remove its folders: only the maker's exit does.
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import tempfile
import threading
from pathlib import Path

#: Set to 1 to keep every scratch folder of the scripts that have no ``--keep``-style option of their own.
KEEP_ENV = "BENCH_KEEP_SCRATCH"

#: (maker's process id, folder) of every folder to remove at exit, in the order made.
_OWNED: list[tuple[int, str]] = []
_HOOKED: list[bool] = []


def keep_requested() -> bool:
    """True when ``BENCH_KEEP_SCRATCH`` asks to keep the scratch folders (any value but "", "0")."""
    return os.environ.get(KEEP_ENV, "") not in ("", "0")


def remove_owned() -> None:
    """Remove the folders this process made and did not keep (newest first); the exit hook (safe to call twice)."""
    pid = os.getpid()
    while _OWNED:
        owner, path = _OWNED.pop()
        if owner == pid:
            shutil.rmtree(path, ignore_errors=True)


def _sigterm_exit(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


def _hook() -> None:
    """Register :func:`remove_owned` at exit once; turn SIGTERM into ``SystemExit`` if it still kills outright.
    (Ctrl-C already raises ``KeyboardInterrupt`` under Python's own SIGINT handler, so the exit hook runs.)"""
    if _HOOKED:
        return
    _HOOKED.append(True)
    atexit.register(remove_owned)
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _sigterm_exit)


def scratch_dir(prefix: str, *, keep: bool = False, dir: str | Path | None = None) -> str:
    """A new empty folder (``tempfile.mkdtemp(prefix=prefix, dir=dir)``; its absolute path), removed with all it
    holds when this process exits, unless ``keep`` or ``BENCH_KEEP_SCRATCH`` asks to keep it."""
    path = tempfile.mkdtemp(prefix=prefix, dir=None if dir is None else str(dir))
    if not (keep or keep_requested()):
        _hook()
        _OWNED.append((os.getpid(), path))
    return path
