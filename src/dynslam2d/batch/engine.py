"""Run a list of jobs in parallel: serially in-process, on a local process pool, or on Ray.

:func:`map_jobs` calls a worker function on every job and returns one :class:`Outcome`
per job, **in the jobs' order** whatever order they finish in. A job that raises is
recorded as failed with a one-line error and never stops the others. ``on_outcome`` is
called in the calling process as each job finishes (the CLI draws its progress bar from
it); nothing here prints.

What travels (docs/batch.md): the job (a small picklable object) goes to the worker and
the worker function's return value comes back as an object; anything else the worker
reads or writes (recordings, results folders) goes through paths that must be valid
on the worker — a shared path on a cluster.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

from dynslam2d.errors import DynSlamError

#: The hint printed when ``--ray`` is used without Ray installed.
RAY_HINT = 'Ray is not installed; install the cluster extra: pip install "dynslam2d[cluster]"'


@dataclass
class Outcome:
    """What became of one job: ``status`` is "done", "skipped" (finished earlier) or "failed".

    ``value`` is the worker function's return value (None when failed); ``error`` the
    one-line reason of a failure; ``seconds`` the job's wall time in its worker.
    """

    name: str
    status: str
    value: Any = None
    error: str | None = None
    seconds: float = 0.0


def one_line(exc: BaseException) -> str:
    """A one-line description of ``exc``: DynSlamError's own message, else ``Type: message``."""
    text = " ".join(str(exc).split())
    if isinstance(exc, DynSlamError):
        return text or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def call_job(fn: Callable[[Any], Any], job: Any) -> Outcome:
    """Run ``fn(job)`` and wrap the result or the error in an Outcome (runs inside the worker)."""
    name = str(getattr(job, "name", job))
    t0 = time.perf_counter()
    try:
        value = fn(job)
    except Exception as exc:  # a failed job is recorded; the batch goes on
        return Outcome(name, "failed", error=one_line(exc), seconds=time.perf_counter() - t0)
    return Outcome(name, "done", value=value, seconds=time.perf_counter() - t0)


def _serial(fn: Callable[[Any], Any], jobs: Sequence[Any], done: Callable[[int, Outcome], None]) -> None:
    for i, job in enumerate(jobs):
        done(i, call_job(fn, job))


def _pool(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int, done: Callable[[int, Outcome], None]) -> None:
    import multiprocessing as mp

    # "spawn": every worker starts a fresh interpreter (no inherited threads or numba state),
    # as a Ray worker does; the kernels come from the AOT module (docs/kernels.md) or numba's on-disk cache.
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        pending = {pool.submit(call_job, fn, job): i for i, job in enumerate(jobs)}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=lambda f: pending[f]):
                i = pending.pop(fut)
                try:
                    out = fut.result()
                except Exception as exc:  # the worker process itself died
                    out = Outcome(str(getattr(jobs[i], "name", i)), "failed", error=one_line(exc))
                done(i, out)


def ray_module() -> Any:
    """Import Ray or raise DynSlamError with the install hint."""
    try:
        import ray
    except ImportError:
        raise DynSlamError(RAY_HINT) from None
    return ray


def _ray(fn: Callable[[Any], Any], jobs: Sequence[Any], address: str, done: Callable[[int, Outcome], None]) -> None:
    ray = ray_module()
    if not ray.is_initialized():
        try:
            ray.init(address=None if address == "local" else address, ignore_reinit_error=True,
                     log_to_driver=False, include_dashboard=False)
        except Exception as exc:
            raise DynSlamError(f"--ray {address}: cannot connect to the Ray cluster ({one_line(exc)}); "
                               f"start one with 'ray start --head' or give its address") from None
    remote = ray.remote(num_cpus=1, max_retries=0, **_ray_kernel_env())(call_job)
    refs = {remote.remote(fn, job): i for i, job in enumerate(jobs)}
    while refs:
        ready, _ = ray.wait(list(refs), num_returns=1)
        for ref in ready:
            i = refs.pop(ref)
            try:
                out = ray.get(ref)
            except Exception as exc:  # the task's worker died
                out = Outcome(str(getattr(jobs[i], "name", i)), "failed", error=one_line(exc))
            done(i, out)


def _ray_kernel_env() -> dict[str, Any]:
    """Ray task options that give the workers this process's choice of kernels (docs/kernels.md): the variables
    ``DYNSLAM2D_KERNELS`` and ``DYNSLAM2D_KERNELS_DIR`` when set here, through the tasks' ``runtime_env`` (a Ray
    worker's environment is otherwise its node's ``ray start`` shell's, or this process's at the first ``ray.init``).
    Unset here, a worker uses its own machine's default kernel folder (each node builds its module for its CPU)."""
    from dynslam2d.jitaot import DIR_ENV, MODE_ENV

    env = {k: os.environ[k] for k in (MODE_ENV, DIR_ENV) if os.environ.get(k)}
    return {"runtime_env": {"env_vars": env}} if env else {}


def map_jobs(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    workers: int = 1,
    ray: str | None = None,
    on_outcome: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Run ``fn(job)`` for every job; return the outcomes in the jobs' order.

    Args:
        fn: a module-level function (it is pickled by reference to the workers).
        workers: 1 = in this process, one job after the other; N > 1 = a pool of N
            processes on this machine. Ignored with ``ray``.
        ray: None = local; a Ray address (``auto`` = the cluster this machine belongs to,
            ``ray://host:10001``, ``host:6379``, ``local`` = start Ray on this machine).
            An already initialised Ray (``ray.init()`` in the calling program) is used as is.
        on_outcome: called in this process after each job, in completion order.
    """
    if workers < 1:
        raise DynSlamError(f"--workers must be at least 1, got {workers}")
    results: list[Outcome | None] = [None] * len(jobs)

    def done(i: int, out: Outcome) -> None:
        results[i] = out
        if on_outcome is not None:
            on_outcome(out)

    if not jobs:
        return []
    if ray is not None:
        _ray(fn, jobs, ray, done)
    elif workers == 1 or len(jobs) == 1:
        _serial(fn, jobs, done)
    else:
        _pool(fn, jobs, min(workers, len(jobs)), done)
    return [r for r in results if r is not None]


__all__ = ["Outcome", "RAY_HINT", "call_job", "map_jobs", "one_line", "ray_module"]
