"""The batch engine's speed-up: the paper's experiment (3 trials × 4 filter modes) serial vs pooled.

Runs ``dynslam2d.experiments.run_experiment`` — whose 12 cells go through the batch engine
(``dynslam2d.batch.engine.map_jobs``) — once with ``workers=1`` (one cell after the other in
this process) and once with ``--workers`` processes (default 2), in one invocation, and prints
both wall times and their ratio. It also checks that both give the same table (every column
but scans/s), which is the engine's promise. Not run by pytest (speed is never asserted).

    python benchmarks/bench_batch.py [--workers 2] [--duration 60] [--ray]

``--ray`` adds a third timing on a local Ray started in-process (``ray.init(num_cpus=workers)``).
The kernels are warmed up first (a 2-s run) so that neither timing includes numba's compile.
Besides wall times it prints CPU times (this process for the serial run, the finished workers
for the pool), which other programs on a shared machine do not inflate: the pool's CPU time
over the worker count, against the serial CPU time, is the wall ratio on idle CPUs.
"""

from __future__ import annotations

import argparse
import os
import time

from dynslam2d.experiments import run_experiment


def _table(rows: list[dict[str, object]]) -> list[dict[str, object]]:
    return [{k: v for k, v in r.items() if k != "scans_per_s"} for r in rows]


def _same(a: list[dict[str, object]], b: list[dict[str, object]]) -> bool:
    def norm(v: object) -> object:
        return "nan" if isinstance(v, float) and v != v else v

    def rows(path):
        return [{k: norm(v) for k, v in r.items()} for r in _table(path)]

    return rows(a) == rows(b)


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's finished child processes (the pool's workers)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--duration", type=float, default=None, help="seconds per trial (default: the trials' own 60 s)")
    ap.add_argument("--ray", action="store_true", help="also time the same cells on a local Ray")
    args = ap.parse_args()

    run_experiment(("paper-1",), ("box",), duration=2.0)  # warm the numba cache
    print(f"paper experiment, 3 trials x 4 filter modes, duration {args.duration or 'default (60 s)'}; "
          f"CPUs available: {len(os.sched_getaffinity(0))}, load average {os.getloadavg()[0]:.1f}")
    t0, c0 = time.perf_counter(), time.process_time()
    serial = run_experiment(duration=args.duration, workers=1)
    t_serial, c_serial = time.perf_counter() - t0, time.process_time() - c0
    t0, k0 = time.perf_counter(), _children_cpu()
    pooled = run_experiment(duration=args.duration, workers=args.workers)
    t_pool, c_pool = time.perf_counter() - t0, _children_cpu() - k0
    print(f"serial (1 process)          {t_serial:7.1f} s wall, {c_serial:7.1f} s CPU   (load average now "
          f"{os.getloadavg()[0]:.1f}; above the CPU count, other programs share the CPUs and the wall ratio is theirs "
          f"too)")
    print(f"pool ({args.workers} worker processes)   {t_pool:7.1f} s wall, {c_pool:7.1f} s CPU in the workers   "
          f"ratio pool/serial {t_pool / t_serial:.2f} wall, {c_pool / c_serial:.2f} CPU"
          f"   same table: {_same(serial.rows, pooled.rows)}")
    print(f"on {args.workers} otherwise idle CPUs the pool's wall time would be about "
          f"{c_pool / args.workers / c_serial:.2f} × the serial one (its CPU time spread over the workers)")
    if args.ray:
        import ray

        ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
        try:
            t0 = time.perf_counter()
            on_ray = run_experiment(duration=args.duration, ray="auto")
            t_ray = time.perf_counter() - t0
        finally:
            ray.shutdown()
        print(f"Ray ({args.workers} CPUs, in-process)   {t_ray:7.1f} s   ratio ray/serial {t_ray / t_serial:.2f}"
              f"   same table: {_same(serial.rows, on_ray.rows)}")


if __name__ == "__main__":
    main()
