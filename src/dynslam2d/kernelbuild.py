"""Building the AOT kernel module (:mod:`dynslam2d.jitaot`): ``dynslam2d kernels build`` runs :func:`build` in a
child process that uses numba's JIT kernels.

The build runs representative inputs through ``dynslam2d run`` (:func:`representative_runs`), records the argument
types of every kernel call from Python, adds :mod:`dynslam2d.jitmanifest`'s signatures and compiles each (kernel,
types) with its return type through ``numba.pycc`` (pending deprecation in numba, kept until a replacement exists;
docs/kernels.md) for this machine's CPU, then installs the module and its sidecar JSON (key and exports) into
:func:`dynslam2d.jitaot.aot_dir` with one atomic switch (:func:`dynslam2d.jitaot.install`), holding the folder's
lock (:func:`dynslam2d.jitaot.build_lock`) from the start: one build per folder at a time. Progress goes to a
callback (the command line's child process, ``dynslam2d.cli._kernel_build_child``, writes it as JSON lines).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from dynslam2d.jitaot import (
    FORMAT,
    MODULE_NAME,
    BuildError,
    aot_dir,
    build_lock,
    build_requirements,
    cpu_name,
    current_key,
    export_name,
    install,
    parse_types,
    table,
)


def _called_kernels(prefix: str = "dynslam2d.") -> tuple[dict[str, list[str]], Callable[[], None]]:
    """Record the argument types of every call from Python of a dynslam2d kernel (defaults filled in), as
    :func:`dynslam2d.jitwarm.signature_text` writes them; returns the record and a function that stops it."""
    import inspect

    from numba.core.registry import CPUDispatcher

    from dynslam2d.jitwarm import signature_text

    seen: dict[str, list[str]] = {}
    had = "__call__" in vars(CPUDispatcher)
    plain = CPUDispatcher.__mro__[1].__call__

    def call(self: Any, *args: Any, **kwargs: Any) -> Any:
        fn = self.py_func
        if (fn.__module__ or "").startswith(prefix):
            try:
                bound = inspect.signature(fn).bind(*args, **kwargs)
                bound.apply_defaults()
                text = signature_text(self.typeof_pyval(v) for v in bound.args)
            except (TypeError, ValueError):
                text = None
            if text is not None:
                texts = seen.setdefault(f"{fn.__module__}.{fn.__qualname__}", [])
                if text not in texts:
                    texts.append(text)
        return plain(self, *args, **kwargs)

    CPUDispatcher.__call__ = call

    def stop() -> None:
        if had:
            return
        del CPUDispatcher.__call__

    return seen, stop


def representative_runs(scratch: Path, inputs: Iterable[str] = (), duration: float = 12.0) -> list[list[str]]:
    """``dynslam2d run`` argument lists whose runs call every kernel a run of a simulated scene, a bag, a CARMEN
    log and each of ``inputs`` calls: the paper scene (default filter), a crowd around a robot driving a circuit
    (box filter, loop closure with place descriptors), a driving robot written as a ROS 1 bag, a long corridor
    written as a CARMEN FLASER log (180 beams at 5 Hz, as MIT CSAIL's), and the user's recordings. ``duration``:
    simulated seconds of the paper scene and the bag (the crowd 7.5 times, the corridor 3 times as long)."""
    import numpy as np

    from dynslam2d.sim.export import write_simulation
    from dynslam2d.sim.simulation import simulate

    # the crowd's robot drives a circuit: at 7.5 × 12 s with one far search per keyframe its loop closer ranks
    # submaps by place descriptors and sums graph distances (what MIT CSAIL's run calls)
    runs = [["sim:paper", "--duration", f"{duration:g}"],
            ["sim:crowd", "--duration", f"{7.5 * duration:g}", "--filter", "box", "--set", "loop.far_searches=1"]]
    sim = simulate("drive", 0, duration)
    files = write_simulation(sim, scratch / "bag", storage="ros1")
    runs.append([str(files.get("bag", scratch / "bag" / "scans.bag"))])
    carmen = simulate("long-corridor", 0, 3.0 * duration, beams=180, fov=np.pi * 179 / 180, rate_hz=5.0)
    lines = []
    for scan in carmen.scans:
        pose = scan.odom if scan.odom is not None else None
        x, y, th = (pose.x, pose.y, pose.theta) if pose is not None else (0.0, 0.0, 0.0)
        r = np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)
        lines.append(f"FLASER {r.shape[0]} " + " ".join(f"{v:.3f}" for v in r)
                     + f" {x:.6f} {y:.6f} {th:.6f} {x:.6f} {y:.6f} {th:.6f} {scan.stamp:.6f} sim {scan.stamp:.6f}")
    (scratch / "sim.clf").write_text("\n".join(lines) + "\n")
    runs.append([str(scratch / "sim.clf")])
    runs.extend([str(p)] for p in inputs)
    return runs


def build(folder: Path | None = None, *, inputs: Iterable[str] = (), cpu: str = "host",
          progress: Callable[[str, dict[str, Any]], None] | None = None, duration: float = 12.0) -> dict[str, Any]:
    """Build the AOT module into ``folder`` (default :func:`aot_dir`) in this process, which must use numba's
    kernels (``DYNSLAM2D_KERNELS=jit``, set by ``dynslam2d kernels build``'s child process): runs
    :func:`representative_runs`, records the argument types of every kernel call from Python, adds the manifest's
    (:mod:`dynslam2d.jitmanifest`), and compiles each (kernel, types) with its return type through
    ``numba.pycc`` for ``cpu`` (LLVM's name; ``host`` this machine's). ``progress(stage, data)`` is told of each
    step. Returns the sidecar's content. Raises :class:`BuildError` when the environment cannot build, the folder
    cannot be written or another build holds its lock; an interrupted build leaves the folder's previous module in
    use (:func:`dynslam2d.jitaot.install`)."""
    why = build_requirements()
    if why:
        raise BuildError(why)
    folder = folder if folder is not None else aot_dir()
    with build_lock(folder):  # before a minute of work: a clear error when another build runs
        return _build(folder, inputs, cpu, progress or (lambda stage, data: None), duration)


def _build(folder: Path, inputs: Iterable[str], cpu: str, note: Callable[[str, dict[str, Any]], None],
           duration: float) -> dict[str, Any]:
    import tempfile
    import time
    import warnings

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import numba
        from numba.pycc import CC
    from numba.core import typing
    from numba.core.registry import CPUDispatcher

    from dynslam2d.jitwarm import _dispatcher, parse_signature

    if table() is not None:
        raise BuildError("this process uses the AOT module; build in one that uses numba's kernels")
    key = current_key()  # the sources the kernels are compiled from (read before any run)
    seen, stop = _called_kernels()
    from dynslam2d.cli import app

    with tempfile.TemporaryDirectory(prefix="dynslam2d-kernels-") as tmp:
        scratch = Path(tmp)
        try:
            runs = representative_runs(scratch, inputs, duration)
            for k, run in enumerate(runs):
                note("run", {"k": k, "n": len(runs), "input": run[0]})
                try:
                    app(["run", *run, "--out", str(scratch / f"run{k}"), "--quiet", "--force"],
                        standalone_mode=False)
                except SystemExit:
                    pass
        finally:
            stop()
        from dynslam2d.jitmanifest import KERNELS

        for qual, text in KERNELS:
            texts = seen.setdefault(qual, [])
            if text not in texts:
                texts.append(text)
        entries: list[tuple[str, str, Any, Any]] = []
        skipped: dict[str, str] = {}
        from dynslam2d.jitwarm import signature_text

        for qual, texts in sorted(seen.items()):
            disp = _dispatcher(qual)
            if not isinstance(disp, CPUDispatcher):
                continue
            if not disp._can_compile:  # declared with its signature(s): numba converts the arguments to them
                texts = [signature_text(sig.args) for sig in disp.nopython_signatures]
            for text in texts:
                try:
                    parse_types(text)
                except ValueError as exc:
                    skipped[f"{qual} {text}"] = str(exc)
                    continue
                argt = parse_signature(text)
                if disp._can_compile:
                    disp.compile(argt)
                over = disp.overloads.get(argt)
                if over is None:  # declared with its signature(s): numba converts the arguments to them
                    skipped[f"{qual} {text}"] = "no compiled overload of these types"
                    continue
                entries.append((qual, text, typing.signature(over.signature.return_type, *argt), disp.py_func))
        note("compile", {"kernels": len({e[0] for e in entries}), "signatures": len(entries)})
        import numba.pycc.compiler as pycc_compiler

        plain_compile_extra = pycc_compiler.compile_extra

        def compile_extra(typingctx: Any, targetctx: Any, func: Any, *rest: Any, **kw: Any) -> Any:
            # pycc hands one Flags object to every export and numba's pipeline clears its enable_ssa on the first
            # compile: later kernels would be typed without SSA (docs/speed.md, pass aot40). A copy per kernel.
            note("kernel", {"name": f"{func.__module__}.{func.__qualname__}"})
            return plain_compile_extra(typingctx, targetctx, func, rest[0], rest[1], rest[2].copy(), *rest[3:], **kw)

        pycc_compiler.compile_extra = compile_extra
        out = scratch / "out"
        out.mkdir()
        exports: dict[str, list[list[str]]] = {}
        try:
            cc = CC(MODULE_NAME)
            cc.output_dir = str(out)
            cc.verbose = False
            cc.target_cpu = cpu
            numbered: dict[str, int] = {}
            for qual, text, sig, fn in entries:
                k = numbered[qual] = numbered.get(qual, -1) + 1
                name = export_name(qual, k)
                cc.export(name, sig)(fn)
                exports.setdefault(qual, []).append([name, text])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    cc.compile()
                except Exception as exc:  # noqa: BLE001 - pycc's and the compiler's errors, as one line
                    lines = [ln for ln in str(exc).splitlines() if ln.strip()]
                    raise BuildError(f"numba.pycc failed: {type(exc).__name__}: {' | '.join(lines[-3:])}") from exc
        finally:
            pycc_compiler.compile_extra = plain_compile_extra
        so = next(out.glob(f"{MODULE_NAME}*"))
        info = {"format": FORMAT, "key": key, "cpu_target": cpu, "cpu_name": cpu_name(),
                "numba_imported": numba.__version__, "exports": exports, "skipped": skipped,
                "build_s": round(time.perf_counter() - t0, 1),
                "built": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        info = install(folder, so, info)
    return info
