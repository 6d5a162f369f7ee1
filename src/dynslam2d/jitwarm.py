"""Compile a cold run's late kernels in a second process while the run compiles its early ones.

numba compiles a kernel on its first call, one after another, on one core: a first run of the README's
first command waits for about 25 s of compiling. On a machine with a second core the command line starts
one background process (:func:`start_background_compile`) when the kernel cache is cold. It imports the
kernel modules and compiles the kernels of :data:`dynslam2d.jitmanifest.KERNELS` for their recorded
signatures, last-used first, into the same numba cache folder, while the run compiles in its natural
order. When the run reaches a kernel the background process has finished, numba's dispatcher finds it in
the cache (``Dispatcher.compile`` looks in the cache before it compiles a new signature; numba writes an
entry's data and index each to a temporary file renamed into place, so the run reads a whole entry or
none and then compiles the kernel itself). A loaded kernel is the compiled code of the same source, so
results do not change.

The background process is not started when the cache is warm, on one usable CPU
(``os.sched_getaffinity``), or when ``DYNSLAM2D_COMPILE_WORKER=0`` (also ``off``/``false``/``no``). It
runs in its own process group and ignores SIGINT, so a Ctrl-C in the terminal reaches the run only (which
stops the process on its way out, as at any exit); it leaves when the run's process is gone (Linux:
``PR_SET_PDEATHSIG``; elsewhere it checks between kernels), prints nothing and never fails the run: a
kernel it cannot compile is skipped.
"""

from __future__ import annotations

import atexit
import importlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

#: Environment variable that turns the background compile off (``0``, ``off``, ``false``, ``no``).
WORKER_ENV = "DYNSLAM2D_COMPILE_WORKER"
_OFF = ("0", "off", "false", "no")


def _type_text(t: Any) -> str:
    from numba.core import types

    if isinstance(t, types.Array) and t.aligned:  # numba's repr without its defaults
        return f"Array({t.dtype}, {t.ndim}, {t.layout!r}{'' if t.mutable else ', True'})"
    return repr(t)


def signature_text(args: Iterable[Any]) -> str:
    """A kernel's argument types as text (numba type names, an array's defaults left out), as stored in
    :mod:`dynslam2d.jitmanifest`; :func:`parse_signature` reads it back."""
    return "(" + "".join(_type_text(t) + ", " for t in args).rstrip(" ") + ")"


def parse_signature(text: str) -> tuple[Any, ...]:
    """The numba argument types of :func:`signature_text`'s text (evaluated among numba's type names only)."""
    from numba.core import types

    names: dict[str, Any] = dict(vars(types))
    names.update(bool=types.boolean, omitted=lambda default: types.Omitted(default))
    sig = eval(text, {"__builtins__": {}}, names)  # noqa: S307 - the project's own manifest, numba names only
    return tuple(sig)


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def worker_wanted() -> bool:
    """Whether a cold run should compile in the background: a second usable CPU and not turned off by
    ``DYNSLAM2D_COMPILE_WORKER``."""
    return os.environ.get(WORKER_ENV, "").strip().lower() not in _OFF and usable_cpus() >= 2


class BackgroundCompile:
    """The background compile process of a cold run; :meth:`stop` ends it (also at interpreter exit)."""

    def __init__(self, proc: subprocess.Popen[bytes]) -> None:
        self.proc = proc
        atexit.register(self.stop)

    def stop(self, timeout: float = 2.0) -> None:
        """End the process if it still runs (SIGTERM, then SIGKILL after ``timeout`` s) and reap it."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        atexit.unregister(self.stop)


def _leave_with_parent(parent: int) -> bool:
    """In the background process: have Linux send SIGTERM when the run's process dies (prctl
    PR_SET_PDEATHSIG), then check that it has not died already. False when it has."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except Exception:  # noqa: BLE001 - compile_kernels also checks its parent between kernels
            pass
    return os.getppid() == parent


def start_background_compile() -> BackgroundCompile | None:
    """Start the background compile (``python -m dynslam2d.jitwarm``) unless :func:`worker_wanted` says no.

    The child is the same interpreter with the same environment, so it caches into the same
    ``NUMBA_CACHE_DIR``. It must import this very copy of dynslam2d (numba keys the cache by the source
    files): an installed copy it finds in site-packages as this process did; a checkout's folder (not an
    installed one, which must not go before the standard library) is put first on its ``PYTHONPATH``, and
    ``-P`` keeps the current folder off its path. Returns None when not started or when it cannot start."""
    if not worker_wanted():
        return None
    import site

    root = str(Path(__file__).resolve().parents[1])
    installed = {str(Path(p).resolve()) for p in [*site.getsitepackages(), site.getusersitepackages()]}
    paths = [] if root in installed else [root]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (*paths, os.environ.get("PYTHONPATH")) if p))
    try:
        proc = subprocess.Popen(
            [sys.executable, "-P", "-m", "dynslam2d.jitwarm", str(os.getpid())], env=env, stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=True,
            start_new_session=True)  # its own process group: a Ctrl-C in the terminal reaches the run only
    except OSError:
        return None
    return BackgroundCompile(proc)


def _dispatcher(name: str) -> Any:
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def compile_kernels(kernels: Iterable[tuple[str, str]], parent: int | None = None) -> list[str]:
    """Compile each (kernel, signature) of ``kernels`` in the order given, skipping kernels whose cache
    already holds an entry (the run got there first); stop when process ``parent`` is gone. Returns the
    kernels compiled or loaded here."""
    from dynslam2d.jitcache import _has_valid_index

    done = []
    for name, sig in kernels:
        if parent is not None and os.getppid() != parent:
            break
        try:
            disp = _dispatcher(name)
            if _has_valid_index(disp):
                continue
            disp.compile(parse_signature(sig))
        except Exception:  # noqa: BLE001 - the run compiles what is missing, as without this process
            continue
        done.append(name)
    return done


def main(argv: list[str] | None = None) -> None:
    """``python -m dynslam2d.jitwarm PARENT_PID``: compile the manifest's kernels, last-used first."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the run's to handle; it stops this process
    args = sys.argv[1:] if argv is None else argv
    parent = int(args[0]) if args else None
    if parent is not None and not _leave_with_parent(parent):
        return
    from dynslam2d.jitcache import load_blas_alone, plain_numba_errors

    plain_numba_errors()
    load_blas_alone()
    from dynslam2d.jitmanifest import KERNELS

    compile_kernels(reversed(KERNELS), parent)


if __name__ == "__main__":
    main()
