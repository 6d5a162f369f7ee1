"""Compile a cold run's late kernels in a second process while the run compiles its early ones.

numba compiles a kernel on its first call, one after another, on one core: a first run of the README's
first command waits for about 25 s of compiling. On a machine with a second core the command line starts
one background process (:func:`start_background_compile`) when the kernel cache is cold. It imports the
kernel modules and compiles the kernels of :data:`dynslam2d.jitmanifest.KERNELS` for their recorded
signatures into the same numba cache folder, while the run compiles in its natural order: the largest
kernel the run will not reach before it is compiled first (:func:`next_kernel`, from the recorded compile
times), so that the two processes meet on a small kernel. When the run reaches a kernel the background
process has finished, numba's dispatcher finds it in the cache (``Dispatcher.compile`` looks in the cache
before it compiles a new signature; numba writes an entry's data and index each to a temporary file renamed
into place, so the run reads a whole entry or none and then compiles the kernel itself). A loaded kernel is
the compiled code of the same source, so results do not change.

The two processes also tell each other which kernel each is compiling (:class:`CompileBoard`): where they
meet, the run waits for a kernel the background process has already started instead of compiling it a
second time from the beginning, and the background process skips a kernel the run is compiling. Each marks a
kernel before it looks for the other's mark, so two processes that arrive at once cannot both compile it.

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
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
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


class CompileBoard:
    """Which dynslam2d kernels the run (``run``) and its background process (``bg``) are compiling right now.

    One empty file per kernel and process in a folder both know (``<who>.<module>.<qualname>``). A process
    claims a kernel before an outermost compile of it (numba's cache lookup missed; a callee compiled inside
    another kernel's compile is never written to the cache, so it is each process's own work): it first marks
    the kernel, then looks for the other process's mark (:meth:`take`, :meth:`claim`). Marking before looking
    (the order of Dekker's mutual exclusion, E. W. Dijkstra, "Cooperating sequential processes", 1965) means
    two processes that arrive at once both see the other's mark, so they cannot both compile it: the
    background process yields (removes its mark; skips the kernel, or waits and loads it) and the run waits
    until the background process has saved the kernel or yielded, then looks in the cache again. A mark is
    removed once numba has written the kernel to the cache (``Cache.save_overload``), when it is loaded
    instead, or when its compile fails. The background process's own compiles at a module's import (a kernel
    with declared signatures compiles when its module is imported: ``slam.ledgerkernels``) go through the
    same claim, so that importing a module never compiles a kernel the run is compiling (pass cmp95).
    :meth:`install` hooks this into the process's numba. Only kernels whose dispatcher caches to disk
    (``cache=True``) are claimed, so every mark is removed by the save that follows."""

    def __init__(self, folder: str | Path, me: str) -> None:
        self.folder = Path(folder)
        self.me = me
        self.other = "bg" if me == "run" else "run"
        self._undo: list[Callable[[], None]] = []

    def _path(self, who: str, name: str) -> Path:
        return self.folder / f"{who}.{name}"

    def busy(self, who: str, name: str) -> bool:
        """Whether process ``who`` ("run" or "bg") is compiling kernel ``name`` (module.qualname)."""
        return self._path(who, name).exists()

    def busy_for(self, who: str, name: str) -> float | None:
        """Seconds since process ``who`` started compiling kernel ``name`` (its mark's age), None when it is not
        compiling it."""
        try:
            return max(time.time() - self._path(who, name).stat().st_mtime, 0.0)
        except OSError:
            return None

    def mark(self, name: str) -> None:
        try:
            self._path(self.me, name).touch()
        except OSError:  # (the folder is gone: the run has finished)
            pass

    def clear(self, name: str | None = None) -> None:
        """Remove this process's mark of ``name``, or all its marks."""
        paths = [self._path(self.me, name)] if name else self.folder.glob(f"{self.me}.*")
        for path in paths:
            try:
                path.unlink()
            except OSError:
                pass

    def claim(self, name: str) -> bool:
        """Claim kernel ``name`` for this process without waiting: True when it holds the mark already (it claimed
        it before, or the run marked it as this process's) or when, after marking it, the other process's mark is
        not there; else its own mark is removed again and False (the other process compiles it)."""
        if self.busy(self.me, name):
            return True
        self.mark(name)
        if not self.busy(self.other, name):
            return True
        self.clear(name)
        return False

    def take(self, name: str, load: Callable[[], Any], other_alive: Callable[[], bool],
             max_wait_s: float = 120.0) -> tuple[Any, float]:
        """At a cache miss of kernel ``name`` before an outermost compile: claim it, or wait for the other process's
        compile of it and load it (``load()``: numba's cache lookup, None on a miss). Returns (what ``load()``
        returned, None: this process compiles it and holds its mark until the save; s waited).

        The run marks and then waits while the background process's mark is there (the background process
        yields where both marked), at most ``max_wait_s`` and while ``other_alive()``; the background process
        (``bg``) marks, and where the run's mark is there too removes its own and waits for the run's compile the
        same way. Either then looks in the cache again; on a miss (the other process yielded, failed or is gone)
        it compiles the kernel itself, marked."""
        t0 = time.perf_counter()
        while True:
            if self.me == "run":
                self.mark(name)  # (before it looks: where both marked, the background process yields)
                if not self.busy(self.other, name):
                    return None, time.perf_counter() - t0
            elif self.claim(name):
                return None, time.perf_counter() - t0
            while self.busy(self.other, name) and other_alive() and time.perf_counter() - t0 < max_wait_s:
                time.sleep(0.005)
            data = load()
            if data is not None:
                self.clear(name)
                return data, time.perf_counter() - t0
            if self.me == "run" or not other_alive() or time.perf_counter() - t0 >= max_wait_s:
                self.mark(name)
                return None, time.perf_counter() - t0
            # (the background process: the run's mark went without a save; it failed or loaded it: claim again)

    def install(self, other_alive: Callable[[], bool] | None = None, max_wait_s: float = 120.0) -> None:
        """Claim this process's outermost kernel compiles at numba's cache misses (:meth:`take`, while
        ``other_alive()`` holds: by default always), remove the mark when the kernel is saved or its compile
        fails."""
        from numba.core import caching, event

        from dynslam2d.jitcache import add_compile_wait

        board = self
        alive = other_alive or (lambda: True)
        depth = [0]  # (compiles in progress in this process: a cache lookup at 0 is an outermost compile's)

        class _Depth(event.Listener):
            def on_start(self, ev: Any) -> None:
                depth[0] += 1

            def on_end(self, ev: Any) -> None:
                depth[0] -= 1
                if depth[0] == 0 and (getattr(ev, "exc_details", None) or (None,))[0] is not None:
                    name = _kernel_name(getattr((ev.data or {}).get("dispatcher"), "py_func", None))
                    if name is not None:  # (a compile that failed is not saved: its mark goes here)
                        board.clear(name)

        load, save = caching.Cache.load_overload, caching.Cache.save_overload

        def save_overload(cache: Any, sig: Any, data: Any) -> None:
            try:
                save(cache, sig, data)
            finally:
                name = _kernel_name(getattr(cache, "_py_func", None))
                if name is not None:
                    board.clear(name)

        def load_overload(cache: Any, sig: Any, target_context: Any) -> Any:
            data = load(cache, sig, target_context)
            name = _kernel_name(getattr(cache, "_py_func", None))
            if data is not None or name is None or depth[0]:
                return data
            data, waited = board.take(name, lambda: load(cache, sig, target_context), alive, max_wait_s)
            add_compile_wait(waited)
            return data

        listener = _Depth()
        event.register("numba:compile", listener)
        caching.Cache.save_overload = save_overload
        caching.Cache.load_overload = load_overload

        def undo() -> None:
            event.unregister("numba:compile", listener)
            caching.Cache.load_overload, caching.Cache.save_overload = load, save

        self._undo.append(undo)

    def uninstall(self) -> None:
        """Undo :meth:`install` and remove this process's marks."""
        while self._undo:
            self._undo.pop()()
        self.clear()


def _kernel_name(func: Any) -> str | None:
    """``module.qualname`` of a dynslam2d kernel's Python function, else None."""
    module = getattr(func, "__module__", None) or ""
    return f"{module}.{func.__qualname__}" if module.split(".")[0] == "dynslam2d" else None


class BackgroundCompile:
    """The background compile process of a cold run; :meth:`stop` ends it (also at interpreter exit)."""

    def __init__(self, proc: subprocess.Popen[bytes], board: CompileBoard | None = None) -> None:
        self.proc = proc
        self.board = board
        atexit.register(self.stop)

    def stop(self, timeout: float = 2.0) -> None:
        """End the process if it still runs (SIGTERM, then SIGKILL after ``timeout`` s) and reap it."""
        if self.board is not None:
            self.board.uninstall()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.board is not None:
            shutil.rmtree(self.board.folder, ignore_errors=True)
            self.board = None
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
        folder = tempfile.mkdtemp(prefix="dynslam2d-compile-")
        proc = subprocess.Popen(
            [sys.executable, "-P", "-m", "dynslam2d.jitwarm", str(os.getpid()), folder], env=env,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=True,
            start_new_session=True)  # its own process group: a Ctrl-C in the terminal reaches the run only
    except OSError:
        return None
    board = CompileBoard(folder, "run")
    try:
        board.install(other_alive=lambda: proc.poll() is None)
    except Exception:  # noqa: BLE001 - numba internals changed: the two processes just do not coordinate
        board.uninstall()
    return BackgroundCompile(proc, board)


def _dispatcher(name: str) -> Any:
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def compile_kernels(kernels: Iterable[tuple[str, str]], parent: int | None = None,
                    board: CompileBoard | None = None) -> list[str]:
    """Compile each (kernel, signature) of ``kernels`` in the order given, skipping kernels whose cache
    already holds an entry or that the run is compiling (``board``: the run got there first); stop when
    process ``parent`` is gone. Returns the kernels compiled or loaded here."""
    done = []
    for name, sig in kernels:
        if parent is not None and os.getppid() != parent:
            break
        if _compile_one(name, sig, board):
            done.append(name)
    return done


def _cached(name: str) -> bool:
    """Whether numba's cache holds kernel ``name``: from its index file alone while its module is not imported here
    (:func:`dynslam2d.jitcache.index_holds`: the background process imports only the modules of the kernels it
    compiles, ≈ 0.3 s less before its first compile), else, or when that cannot tell, from its dispatcher."""
    from dynslam2d.jitcache import _has_valid_index, index_holds

    if name.rpartition(".")[0] not in sys.modules:
        held = index_holds(name)
        if held is not None:
            return held
    return bool(_has_valid_index(_dispatcher(name)))


def _compile_one(name: str, sig: str, board: CompileBoard | None) -> bool:
    """Compile kernel ``name`` for signature ``sig`` here unless the run is compiling it (``board``) or the cache
    already holds it; clears this process's mark on ``board`` afterwards. True when compiled here."""
    from dynslam2d.jitcache import _has_valid_index

    try:
        if board is not None and not board.busy(board.me, name) and board.busy(board.other, name):
            return False  # (before the import: it may compile the module's kernels with declared signatures)
        disp = _dispatcher(name)
        if _has_valid_index(disp):
            return False
        if board is not None and not board.claim(name):  # (the run may have started it during the import)
            return False
        disp.compile(parse_signature(sig))
    except Exception:  # noqa: BLE001 - the run compiles what is missing, as without this process
        return False
    finally:
        if board is not None:
            board.clear()  # (a kernel that failed to compile leaves no mark the run would wait on)
    return True


def next_kernel(pending: list[tuple[int, float]], run_at: int, run_left: float) -> int:
    """Which of the ``pending`` kernels the background process compiles next (a position in ``pending``).

    ``pending``: (position in the run's order of first use, compile time s) of the kernels that neither process
    has compiled nor is compiling, in that order; ``run_at``: the position of the kernel the run compiles now or
    next; ``run_left``: s until it is done with that one (0 when it has not started it). The run reaches a
    pending kernel once it has compiled the pending kernels before it (those at ``run_at`` or later; one the
    background process has saved it only loads). The largest kernel the background process can compile before
    the run reaches it, at the same speed: the large kernels go first, so that where the two processes meet,
    the one arriving second waits for a small kernel only (``reversed(KERNELS)`` met on whichever kernel the
    load put there: ``match_pyramid`` 4.7 s, ``record_cells`` 6.5 s). When no kernel fits, the one with the most
    time to spare (the shortest wait for the run), and one the run has passed only when nothing is ahead of it.
    """
    fits, spare = -1, -1
    fit_cost = spare_s = -float("inf")
    ahead = run_left
    for k, (at, cost) in enumerate(pending):
        if at < run_at:
            continue
        if ahead - cost >= 0 and cost > fit_cost:
            fits, fit_cost = k, cost
        if ahead - cost > spare_s:
            spare, spare_s = k, ahead - cost
        ahead += cost
    return fits if fits >= 0 else spare if spare >= 0 else len(pending) - 1


def compile_balanced(kernels: Iterable[tuple[str, str]], costs: dict[str, float], parent: int | None = None,
                     board: CompileBoard | None = None) -> list[str]:
    """Compile the ``kernels`` (the run's order of first use) the run has not compiled, one at a time in the
    order :func:`next_kernel` chooses from what the cache holds and the kernel the run is compiling
    (``board``); ``costs``: each kernel's recorded compile time, s (:data:`dynslam2d.jitmanifest.COMPILE_S`; 1 s
    where missing). Stops when process ``parent`` is gone or nothing is left for this process. Returns the
    kernels compiled here."""
    waiting = dict(enumerate(kernels))
    cost = {at: max(costs.get(name, 1.0), 0.01) for at, (name, _) in waiting.items()}
    done: list[str] = []
    wall = recorded = 0.0  # (this process's compile wall time against the recorded times: the speed now)
    while waiting:
        if parent is not None and os.getppid() != parent:
            break
        running: dict[int, float] = {}
        for at, (name, _) in list(waiting.items()):
            try:
                age = board.busy_for("run", name) if board is not None else None
                if age is not None:
                    running[at] = age
                elif _cached(name):
                    del waiting[at]  # (the run compiled it)
            except Exception:  # noqa: BLE001 - the run compiles what is missing, as without this process
                del waiting[at]
        pending = [(at, cost[at]) for at in sorted(waiting) if at not in running]
        if not pending:
            break
        if running:
            run_at = min(running)
            run_left = max(cost[run_at] - running[run_at] * (recorded / wall if wall > 0 else 1.0), 0.0)
        else:
            run_at, run_left = pending[0][0], 0.0
        at = pending[next_kernel(pending, run_at, run_left)][0]
        name, sig = waiting.pop(at)
        t0 = time.perf_counter()
        if not _compile_one(name, sig, board):
            continue
        wall += time.perf_counter() - t0
        recorded += cost[at]
        done.append(name)
    return done


def main(argv: list[str] | None = None) -> None:
    """``python -m dynslam2d.jitwarm PARENT_PID [BOARD_FOLDER]``: compile the manifest's kernels the run has not
    reached, large ones first (:func:`compile_balanced`), telling the run through :class:`CompileBoard` which one
    it is compiling."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the run's to handle; it stops this process
    args = sys.argv[1:] if argv is None else argv
    parent = int(args[0]) if args else None
    if parent is not None and not _leave_with_parent(parent):
        return
    from dynslam2d.jitcache import lean_compile_gc, lean_numba_compile, load_blas_alone, plain_numba_errors

    plain_numba_errors()
    load_blas_alone()
    lean_numba_compile()
    lean_compile_gc()
    import gc

    # No cyclic collections at all in this short-lived process: numba's typing and lowering keep many objects alive,
    # which each young collection walks again (≈ 1.6 s of CPU when one process compiles every kernel, for ≈ +50 MiB
    # of peak memory while it compiles; docs/speed.md, passes cmp79 and cmp142). It exits when its kernels are done.
    gc.disable()
    from dynslam2d.jitmanifest import COMPILE_S, KERNELS

    board = CompileBoard(args[1], "bg") if len(args) > 1 else None
    if board is not None:
        try:
            board.install(other_alive=lambda: parent is None or os.getppid() == parent)
        except Exception:  # noqa: BLE001 - numba internals changed: compile without telling the run
            board = None
    compile_balanced(KERNELS, COMPILE_S, parent, board)


if __name__ == "__main__":
    main()
