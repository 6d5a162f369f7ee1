"""The kernels compiled ahead of time for this machine: one extension module that replaces numba at run time.

``dynslam2d kernels build`` compiles every kernel signature a run uses (:mod:`dynslam2d.kernelbuild`, in a child:
numba's ``numba.pycc`` with a C compiler) into one extension module for this machine's CPU, in the kernel cache
folder (:func:`aot_dir`, beside numba's cache, so it survives reinstalls), with a sidecar JSON that holds its key
(:func:`current_key`: the kernel sources' fingerprint, the numba version it was built with, the Python version and
the CPU's identity), its exports (kernel, export name, numba argument types as text) and the module file's name,
size and SHA-256. :func:`install` writes the module under its content-hash name and then the sidecar in one rename,
under the folder's lock (:func:`build_lock`): a run loads the module its sidecar names, checked, or none.

When that module is present and its key is this process's (:func:`table`), :mod:`dynslam2d.jitbox`'s kernel decorator
returns, at import, a plain Python function per kernel that checks its arguments (:func:`make_kernel`) and calls
the module's export of those types, and the kernel modules import no numba and no llvmlite at all: their
module-level numba names (``types``, the lowering hooks, llvmlite's ``ir`` ...) are inert stand-ins (:data:`INERT`). The
exports compute the bits the JIT kernels compute (no fast-math, same LLVM, same CPU). With no valid module, or with
``DYNSLAM2D_KERNELS=jit``, nothing here is used and the kernels are numba's dispatchers as before.

pycc's functions do not check their arguments (a float32 array for a float64 one reads garbage or crashes), so the
wrapper checks each argument against the exported types: an array's type, dtype, ndim, C-contiguity and
writability, a scalar's Python or NumPy type, a tuple's length and items. Arguments that fit no export raise
:class:`KernelArgumentError` naming the kernel, the argument and the expected type (this release has no switch back
to numba inside a process that started without it: set ``DYNSLAM2D_KERNELS=jit`` or rebuild with the input that
needs it, ``dynslam2d kernels build --input``). docs/kernels.md.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dynslam2d.errors import DynSlamError

#: Environment variable choosing the kernels: ``auto`` (the AOT module when valid, else numba; the default) or
#: ``jit`` (numba's JIT kernels even when a valid AOT module is present).
MODE_ENV = "DYNSLAM2D_KERNELS"
#: Environment variable naming the folder of the AOT module (default :func:`aot_dir`'s).
DIR_ENV = "DYNSLAM2D_KERNELS_DIR"
#: The extension module's name (and file stem).
MODULE_NAME = "dynslam2d_aot_kernels"
#: The sidecar JSON beside it: key, exports, build figures, and the module file it goes with (its name holds the
#: file's content hash; the sidecar is written last, so replacing it switches module and sidecar at once).
SIDECAR = f"{MODULE_NAME}.json"
#: The lock file a build (and ``kernels clear``) holds: one build per folder at a time.
LOCK = f"{MODULE_NAME}.lock"
#: Format of the sidecar; a different one is not loaded (1: aot41's, a module file without content hash).
FORMAT = 2
#: The module files a build writes (``dynslam2d_aot_kernels-<16 hex of its SHA-256>.<abi>.so``; aot41's had no hash)
MODULE_FILE = re.compile(rf"^{MODULE_NAME}(-[0-9a-f]{{16}})?(\.[A-Za-z0-9_-]+)*\.(so|pyd)$")
#: A build's temporary files while it writes (never named by a sidecar, so never loaded; the next build removes them)
TEMP_FILE = re.compile(rf"^\.{MODULE_NAME}.*\.tmp-[0-9]+-[0-9a-f]+$")


class KernelArgumentError(DynSlamError, TypeError):
    """A kernel of the AOT module called with arguments of types no export has."""


def aot_dir() -> Path:
    """The folder of the AOT module: ``$DYNSLAM2D_KERNELS_DIR`` or ``<cache root>/../aot``
    (``~/.cache/dynslam2d/aot`` by default, beside numba's cache folder)."""
    given = os.environ.get(DIR_ENV)
    if given:
        return Path(given)
    from dynslam2d.jitcache import cache_root

    return cache_root().parent / "aot"


def mode() -> str:
    """``DYNSLAM2D_KERNELS``: ``jit`` (numba's kernels), ``aot`` (the AOT module and no fallback to numba: arguments
    of types it lacks raise) or ``auto`` (the default: the AOT module when valid, numba for what it lacks)."""
    value = os.environ.get(MODE_ENV, "").strip().lower()
    return value if value in ("jit", "aot") else "auto"


def cpu_identity() -> str:
    """16 hex digits identifying this CPU model and its features: the first processor's vendor, model name and
    flags in /proc/cpuinfo (``Features`` / ``CPU part`` on ARM), with the machine type; read without llvmlite."""
    parts = [platform.machine()]
    try:
        with open("/proc/cpuinfo", encoding="latin-1") as fh:
            text = fh.read().split("\n\n")[0]
        for line in text.splitlines():
            key, _, value = line.partition(":")
            if key.strip() in ("vendor_id", "model name", "flags", "Features", "CPU implementer", "CPU part",
                               "cpu family", "model"):
                parts.append(f"{key.strip()}={value.strip()}")
    except OSError:
        parts.append(platform.processor())
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def numba_version() -> str:
    """The installed numba's version, from its distribution metadata (numba is not imported)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("numba")
    except PackageNotFoundError:
        return "none"


def current_key() -> dict[str, str]:
    """What a valid AOT module must have been built for: this process's kernel sources, numba, Python and CPU."""
    from dynslam2d.jitcache import kernel_sources_fingerprint

    return {"sources": kernel_sources_fingerprint(), "numba": numba_version(),
            "python": f"{sys.implementation.cache_tag}-{platform.python_version()}", "cpu": cpu_identity()}


@dataclass
class KernelsStatus:
    """What :func:`status` found: the folder, whether a module is there and usable, and why not."""

    folder: Path
    present: bool
    valid: bool
    reason: str
    mode: str
    info: dict[str, Any] = field(default_factory=dict)
    #: The parts of the module's key that differ from this process's (``sources``, ``numba``, ``python``, ``cpu``;
    #: empty unless the module is stale).
    stale: tuple[str, ...] = ()


def _module_path(folder: Path, info: dict[str, Any]) -> Path:
    return folder / str(info.get("file", ""))


def file_digest(path: Path) -> str:
    """The SHA-256 of a file's content, hex (about 1 ms for the 1.4 MiB module)."""
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def status(folder: Path | None = None) -> KernelsStatus:
    """Whether ``folder`` (default :func:`aot_dir`) holds an AOT module this process would load, and if not why.

    Valid: the sidecar's format is this version's, it names a module file (a plain name matching
    :data:`MODULE_FILE`) whose size and SHA-256 are the sidecar's, and its key is :func:`current_key`. A folder that
    cannot be read (permissions, a file in the way) is "no module": runs use numba's kernels."""
    folder = folder if folder is not None else aot_dir()
    md = mode()
    try:
        return _status(folder, md)
    except OSError as exc:
        return KernelsStatus(folder, False, False, f"cannot read {folder} ({exc.strerror or exc})", md)


def _status(folder: Path, md: str) -> KernelsStatus:
    side = folder / SIDECAR
    if not side.is_file():
        return KernelsStatus(folder, False, False, "no AOT module built (dynslam2d kernels build)", md)
    try:
        info = json.loads(side.read_text())
    except (OSError, ValueError) as exc:
        return KernelsStatus(folder, True, False, f"unreadable {SIDECAR} ({exc})", md)
    if not isinstance(info, dict) or info.get("format") != FORMAT or not isinstance(info.get("exports"), dict):
        return KernelsStatus(folder, True, False, "built by another version of dynslam2d (build again)", md,
                             info if isinstance(info, dict) else {})
    name = str(info.get("file", ""))
    path = folder / name
    if not MODULE_FILE.match(name) or not path.is_file():
        return KernelsStatus(folder, True, False, "the extension module file is missing", md, info)
    if path.stat().st_size != info.get("bytes") or file_digest(path) != info.get("sha256"):
        return KernelsStatus(folder, True, False, f"the module file {name} does not match its sidecar "
                                                  "(build again)", md, info)
    key, now = info.get("key", {}), current_key()
    key = key if isinstance(key, dict) else {}
    stale = tuple(k for k in now if key.get(k) != now[k])
    if stale:
        return KernelsStatus(folder, True, False, "stale: " + ", ".join(_stale_part(k, key, info, now) for k in stale),
                             md, info, stale)
    return KernelsStatus(folder, True, True, "valid", md, info)


def _stale_part(part: str, key: dict[str, Any], info: dict[str, Any], now: dict[str, str]) -> str:
    """What changed in one part of a stale module's key, as ``kernels status`` and a run's note say it."""
    if part == "sources":
        return "the kernel sources changed (dynslam2d updated or edited since the build)"
    if part == "numba":
        return f"another numba version (built with {key.get('numba', '?')}, now {now['numba']})"
    if part == "python":
        return f"another Python (built for {key.get('python', '?')}, now {now['python']})"
    built_on, here = str(info.get("cpu_name") or "?"), cpu_name()
    if built_on == here:
        return f"another CPU (the same model, {here}, with other feature flags)"
    return f"another CPU (built on {built_on}, this is {here})"


# --- argument types: numba's type text (jitwarm.signature_text) read without numba ---------------------------

@dataclass(frozen=True)
class ArraySpec:
    dtype: str
    ndim: int
    layout: str
    readonly: bool = False

    def text(self) -> str:
        return f"Array({self.dtype}, {self.ndim}, {self.layout!r}{', True' if self.readonly else ''})"


@dataclass(frozen=True)
class TupleSpec:
    items: tuple[Any, ...]

    def text(self) -> str:
        return "Tuple(" + ", ".join(_text(t) for t in self.items) + ")"


#: Scalar numba type names an export may take, with the NumPy scalar type numba gives that name.
SCALARS = ("float64", "float32", "int64", "int32", "int16", "int8", "uint64", "uint32", "uint16", "uint8", "bool",
           "complex128", "complex64")


def _text(t: Any) -> str:
    return t if isinstance(t, str) else t.text()


def _array(dtype: str, ndim: int, layout: str, readonly: bool = False, aligned: bool = True) -> ArraySpec:
    if not aligned:
        raise ValueError("unaligned array")
    return ArraySpec(dtype, ndim, layout, bool(readonly))


class _Unsupported(ValueError):
    pass


def parse_types(text: str) -> list[Any]:
    """The argument types of a signature text: an :class:`ArraySpec`, a :class:`TupleSpec` or a scalar's numba
    name per argument; raises ValueError for a type an export cannot take (literals, omitted, numba's own)."""
    names: dict[str, Any] = {s: s for s in SCALARS}
    names.update(Array=_array, UniTuple=lambda t, n: TupleSpec((t,) * n), Tuple=lambda *ts: TupleSpec(tuple(ts)),
                 False_=False, True_=True)

    class _Names(dict):
        def __missing__(self, key: str) -> Any:
            raise _Unsupported(key)

    try:
        value = eval(text.replace("aligned=True", "True"), {"__builtins__": {}, "False": False, "True": True},
                     _Names(names))  # noqa: S307 - numba type names only (the project's own build sidecar)
    except (_Unsupported, SyntaxError, TypeError) as exc:
        raise ValueError(f"unsupported type in {text}: {exc}") from None
    if not isinstance(value, tuple):
        value = (value,)
    for t in value:
        if isinstance(t, str) and t not in SCALARS:
            raise ValueError(f"unsupported type {t} in {text}")
    return list(value)


def _check_expr(t: Any, x: str, env: dict[str, Any]) -> str:
    """A Python expression that holds when the value ``x`` is exactly of type ``t`` for numba (its ``typeof``)."""
    import numpy as np

    if isinstance(t, ArraySpec):
        dname = f"_d_{t.dtype}"
        env[dname] = np.dtype("bool" if t.dtype == "bool" else t.dtype)
        # one flags look-up: numpy's carray / farray are C- / F-contiguous, aligned and writable
        flag = {("C", False): "carray", ("C", True): "c_contiguous", ("F", False): "farray",
                ("F", True): "f_contiguous", ("A", False): "writeable"}.get((t.layout, t.readonly))
        return (f"((type({x}) is _nd or isinstance({x}, _nd)) and ({x}.dtype is {dname} or {x}.dtype == {dname}) "
                f"and {x}.ndim == {t.ndim}" + (f" and {x}.flags.{flag})" if flag else ")"))
    if isinstance(t, TupleSpec):
        inner = " and ".join(_check_expr(item, f"{x}[{k}]", env) for k, item in enumerate(t.items))
        return f"(type({x}) is tuple and len({x}) == {len(t.items)}" + (f" and {inner})" if inner else ")")
    sname = f"_s_{t}"
    env[sname] = np.bool_ if t == "bool" else getattr(np, t)
    py = {"float64": "float", "int64": "int", "bool": "bool", "complex128": "complex"}.get(t)
    return f"(type({x}) is {py} or type({x}) is {sname})" if py else f"(type({x}) is {sname})"


def describe(x: Any) -> str:
    """An argument's type as an error message shows it."""
    import numpy as np

    if isinstance(x, np.ndarray):
        layout = "C" if x.flags.c_contiguous else "F" if x.flags.f_contiguous else "A"
        return f"Array({x.dtype}, {x.ndim}, {layout!r}{'' if x.flags.writeable else ', read-only'})"
    if isinstance(x, tuple):
        return "tuple(" + ", ".join(describe(v) for v in x) + ")"
    return type(x).__name__


def _mismatch(qual: str, params: list[str], exports: list[tuple[str, list[Any]]], args: tuple[Any, ...]) -> str:
    """The message of :class:`KernelArgumentError`: the first argument that fits no export of the kernel."""
    if not exports:
        return (f"kernel {qual} is not in the AOT kernel module (no run of its build called it from Python); run "
                f"with {MODE_ENV}=jit or rebuild it with the input that needs it (dynslam2d kernels build --input)")
    env: dict[str, Any] = {"_nd": __import__("numpy").ndarray}
    for k, name in enumerate(params):
        expected = [types[k] for _n, types in exports if k < len(types)]
        if k >= len(args) or not expected:
            continue
        fits = [eval(_check_expr(t, "x", env), env, {"x": args[k]}) for t in expected]  # noqa: S307 - our expressions
        if not any(fits):
            want = " or ".join(sorted({_text(t) for t in expected}))
            return (f"kernel {qual}: argument {name!r} (position {k}) is {describe(args[k])}, the AOT kernel module "
                    f"takes {want}; run with {MODE_ENV}=jit or rebuild it (dynslam2d kernels build)")
    return (f"kernel {qual}: these {len(args)} arguments fit none of the AOT kernel module's "
            f"{len(exports)} signature(s); run with {MODE_ENV}=jit or rebuild it (dynslam2d kernels build)")


def make_kernel(py_func: Callable[..., Any], qual: str, exports: list[tuple[Callable[..., Any], list[Any]]]
                ) -> Callable[..., Any]:
    """A plain function with ``py_func``'s parameters (and defaults) that calls the first export whose argument
    types the arguments have, and raises :class:`KernelArgumentError` when none fits. ``exports``: (compiled
    function, argument types of :func:`parse_types`) in order of preference."""
    import inspect

    import numpy as np

    params = [p.name for p in inspect.signature(py_func).parameters.values()]
    env: dict[str, Any] = {"_nd": np.ndarray}
    lines = [f"def _kernel({', '.join(params)}):"]
    for k, (fn, types) in enumerate(exports):
        if len(types) != len(params):
            continue
        env[f"_e{k}"] = fn
        cond = " and ".join(_check_expr(t, p, env) for t, p in zip(types, params)) or "True"
        lines.append(f"    if {cond}:\n        return _e{k}({', '.join(params)})")
    lines.append(f"    return _miss(({', '.join(params)}{',' if params else ''}))")
    named = [(getattr(fn, "__name__", "?"), types) for fn, types in exports]

    def _miss(args: tuple[Any, ...]) -> Any:
        dispatcher = to_jit(qual)
        if dispatcher is None:
            raise KernelArgumentError(_mismatch(qual, params, named, args))
        return dispatcher(*args)

    env["_miss"] = _miss
    exec(compile("\n".join(lines), f"<aot kernel {qual}>", "exec"), env)  # noqa: S102 - generated from types only
    fn = env["_kernel"]
    fn.__name__ = py_func.__name__
    fn.__defaults__ = py_func.__defaults__
    fn.__module__ = py_func.__module__
    fn.__qualname__ = py_func.__qualname__
    fn.__doc__ = py_func.__doc__
    fn.py_func = py_func  # as numba's dispatchers have it
    fn.aot_exports = [(getattr(e, "__name__", "?"), [_text(t) for t in types]) for e, types in exports]
    return fn


# --- the loaded module ------------------------------------------------------------------------------------------

class KernelTable:
    """The loaded AOT module's exports by kernel (``module.qualname``)."""

    def __init__(self, module: Any, info: dict[str, Any], folder: Path) -> None:
        self.module = module
        self.info = info
        self.folder = folder
        self.exports: dict[str, list[tuple[Callable[..., Any], list[Any]]]] = {}
        for qual, rows in info["exports"].items():
            self.exports[qual] = [(getattr(module, name), parse_types(text)) for name, text in rows]

    def decorator(self, *args: Any, **kwargs: Any) -> Any:
        """numba's kernel decorator for the kernel modules when the AOT module is used: a decorated kernel becomes
        :func:`make_kernel`'s function over its exports, or a function that raises when called if the module
        has none (a kernel only other kernels call, compiled into them)."""
        import types as pytypes

        if len(args) == 1 and isinstance(args[0], pytypes.FunctionType) and not kwargs:
            return self.kernel(args[0])
        return self.kernel

    def kernel(self, py_func: Callable[..., Any]) -> Callable[..., Any]:
        note_module(py_func.__module__)
        qual = f"{py_func.__module__}.{py_func.__qualname__}"
        return make_kernel(py_func, qual, self.exports.get(qual, []))


_TABLE: list[KernelTable | None] = []
#: Why :func:`table` decided on numba's kernels although a module is built (:func:`unused_reason`), once decided.
_WHY: list[str] = []


def table() -> KernelTable | None:
    """The AOT module of :func:`aot_dir` loaded into this process when it is valid for it (:func:`status`) and
    ``DYNSLAM2D_KERNELS`` is not ``jit``; None otherwise. Decided once per process (the first call)."""
    if _TABLE:
        return _TABLE[0]
    loaded = None
    if mode() != "jit" and "numba" in sys.modules:
        st = status()
        if st.valid:
            _WHY.append("the kernels built ahead of time were not used, numba was imported before dynslam2d; "
                        "numba's kernels ran instead")
    elif mode() != "jit":
        # twice: a build that switched to a new module between this process reading the sidecar and loading the
        # file it named has removed that file; the sidecar then names the new one
        for _attempt in range(2):
            st = status()
            if not st.valid:
                if st.present:
                    why = st.reason.removesuffix(" (build again)")  # the remedy follows once
                    _WHY.append(f"the kernels built ahead of time were not used, {why}; numba's kernels ran "
                                "instead: run `dynslam2d kernels build` again")
                break
            import importlib.util

            path = _module_path(st.folder, st.info)
            try:
                spec = importlib.util.spec_from_file_location(MODULE_NAME, path)
                if spec is not None and spec.loader is not None:
                    module = importlib.util.module_from_spec(spec)
                    spec.loader.exec_module(module)
                    loaded = KernelTable(module, st.info, st.folder)
                break
            except (ImportError, OSError, AttributeError, ValueError) as exc:
                loaded = None  # numba's kernels, as without a module
                if path.is_file():
                    _WHY.append(f"the kernels built ahead of time were not used, {path.name} failed to load "
                                f"({type(exc).__name__}: {' '.join(str(exc).split())}); numba's kernels ran "
                                "instead: run `dynslam2d kernels build` again")
                    break
    _TABLE.append(loaded)
    return loaded


def in_use() -> str:
    """Which kernels this process runs: ``aot`` (the AOT module's), ``jit`` (numba's: no valid module,
    ``DYNSLAM2D_KERNELS=jit``, or numba imported first) or ``aot+jit`` (it started on the AOT module and a call of
    argument types the module lacks switched it to numba's, :func:`to_jit`)."""
    if _FALLBACK:
        return "aot+jit"
    return "aot" if table() is not None else "jit"


def unused_reason(recording: str = "RECORDING") -> str | None:
    """One line on why this process did not run (all of) the kernels built ahead of time although a module is in
    :func:`aot_dir`: stale (which part of its key differs, :func:`status`), not matching its sidecar, failed to
    load, numba imported first, or a call of types the module lacks (which kernel, and the remedy). None when
    the module ran throughout, when none is built and when ``DYNSLAM2D_KERNELS=jit`` chose numba. For the command
    line to show after a run (this module prints nothing); ``recording``: the input the remedy names."""
    table()
    if _FALLBACK:
        return (f"the kernels built ahead of time lack the argument types of a call of {_FALLBACK[0]}: numba's "
                f"kernels ran from then on; `dynslam2d kernels build --input {recording}` adds them")
    return _WHY[0] if _WHY else None


#: The kernel modules in the order they first used the AOT module's stand-ins (their imports complete before).
_MODULES: list[str] = []
#: After :func:`to_jit` switched this process to numba: each kernel's dispatcher by ``module.qualname``.
_DISPATCHERS: dict[str, Any] = {}
#: The kernel whose call switched this process to numba (:func:`to_jit`), for :func:`unused_reason`.
_FALLBACK: list[str] = []


def note_module(name: str) -> None:
    """Record kernel module ``name`` (:data:`_MODULES`) for :func:`to_jit`."""
    if name not in _MODULES:
        _MODULES.append(name)


def _is_stand_in(value: Any) -> bool:
    return (getattr(value, "aot_exports", None) is not None or getattr(value, "aot_stand_in", False)
            or isinstance(value, _Inert) or (isinstance(value, type) and issubclass(value, _Inert))
            or isinstance(getattr(value, "__self__", None), KernelTable))


def to_jit(qual: str) -> Any:
    """numba's dispatcher of kernel ``qual`` for a call whose argument types the AOT module lacks; None when
    ``DYNSLAM2D_KERNELS=aot`` or numba is not installed (the caller raises :class:`KernelArgumentError`).

    The first such call turns the whole process to numba: :mod:`dynslam2d.jitbox` and every kernel module (in the
    order they were imported) are executed again from their sources into fresh namespaces with numba's names, and
    each global of the real module that held a stand-in (a kernel's wrapper, a lowering hook, a numba type or a value
    made of them) gets the new object: numba resolves a kernel's callees from its module's globals when it compiles,
    so every kernel then compiles (or loads from numba's cache) as without the AOT module. Calls whose types the
    module has keep going to it (the same bits); the others go to the dispatchers, also through wrappers other
    modules imported."""
    if not _DISPATCHERS:
        import builtins
        import importlib.util

        if not _TABLE or _TABLE[0] is None or mode() == "aot" or importlib.util.find_spec("numba") is None:
            return None  # (no AOT module in use here: nothing to switch)
        _TABLE[0] = None  # jitbox's new namespace imports numba
        _FALLBACK.append(qual)
        for name in ["dynslam2d.jitbox", *[m for m in _MODULES if m != "dynslam2d.jitbox"]]:
            module = sys.modules[name]
            fresh: dict[str, Any] = {"__name__": name, "__file__": module.__file__, "__spec__": module.__spec__,
                                     "__package__": module.__package__, "__builtins__": builtins}
            path = str(module.__file__)
            with open(path, "rb") as fh:
                exec(compile(fh.read(), path, "exec"), fresh)  # noqa: S102 - the package's own module
            real = vars(module)
            for key, value in list(real.items()):
                if (name == "dynslam2d.jitbox" or _is_stand_in(value)) and key in fresh and not key.startswith("__"):
                    real[key] = fresh[key]
            for value in fresh.values():
                func = getattr(value, "py_func", None)
                if func is not None and hasattr(value, "overloads") and func.__module__ == name:
                    _DISPATCHERS[f"{name}.{func.__qualname__}"] = value
    return _DISPATCHERS.get(qual)


class _Inert:
    """A stand-in for every numba or llvmlite name a kernel module uses at import when the AOT module replaces
    numba: callable, subscriptable, with any attribute, usable as a base class; it does nothing."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        pass

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return INERT

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):
            raise AttributeError(attr)
        return INERT

    def __getitem__(self, key: Any) -> Any:
        return INERT

    def __mro_entries__(self, bases: tuple[Any, ...]) -> tuple[type, ...]:
        return (_Inert,)


#: The one inert stand-in (:class:`_Inert`).
INERT = _Inert()


class BuildError(DynSlamError):
    """The AOT module cannot be built here (no C compiler, no setuptools, a kernel pycc rejects)."""


def build_requirements() -> str | None:
    """Why the AOT module cannot be built in this environment (one line), or None when it can."""
    import importlib.util
    import shutil
    import sysconfig

    cc = os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    if shutil.which(cc.split()[0]) is None and shutil.which("gcc") is None and shutil.which("cc") is None:
        return f"no C compiler found ({cc.split()[0]}, gcc, cc): install one (e.g. apt install gcc) to build kernels"
    if importlib.util.find_spec("setuptools") is None:
        return ('setuptools is not installed: pip install "dynslam2d[aot]" (or pip install setuptools) to build '
                "kernels")
    if importlib.util.find_spec("numba") is None:
        return "numba is not installed"
    return None


def export_name(qual: str, k: int) -> str:
    """The AOT module's name of a kernel's ``k``-th signature."""
    mod, _, name = qual.rpartition(".")
    return f"{mod.replace('.', '_')}__{name.replace('.', '_')}__{k}"


def cpu_name() -> str:
    """This CPU's model name from /proc/cpuinfo (``platform.processor()`` elsewhere), for ``kernels status``."""
    try:
        with open("/proc/cpuinfo", encoding="latin-1") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() in ("model name", "Model", "Processor"):
                    return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def unwritable(folder: Path, exc: OSError) -> str:
    """The one-line error of a kernel folder that cannot be written."""
    why = exc.strerror or type(exc).__name__
    return (f"cannot write the kernel folder {folder} ({why}); set {DIR_ENV} to a writable folder "
            f"(runs are not affected: they use numba's JIT kernels)")


@contextmanager
def build_lock(folder: Path) -> Iterator[None]:
    """Hold ``folder``'s lock file (:data:`LOCK`, created with the folder) while a build or a clear changes it.

    Raises :class:`BuildError` at once, with one line, when the folder cannot be written (naming it and
    ``DYNSLAM2D_KERNELS_DIR``) or when another process holds the lock (a build running). An ``flock`` lock: the
    system releases it when its process ends, however it ends (Ctrl-C, a crash), so no stale lock remains."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise BuildError(unwritable(folder, exc)) from None
    try:
        try:
            import fcntl
        except ImportError:  # (not a POSIX system: no lock; the sidecar's atomic switch still holds)
            fcntl = None  # type: ignore[assignment]
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
                raise BuildError(f"another `dynslam2d kernels build` (pid {holder}) is writing {folder}: wait for "
                                 f"it to finish (the module it replaces stays in use until then)") from None
            except OSError:
                pass  # a file system without flock: the sidecar's atomic switch still holds
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, str(os.getpid()).encode())  # (for the message of a second build)
        yield
    finally:
        os.close(fd)


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file of this process in the same folder (:data:`TEMP_FILE`),
    synced, then renamed over ``path``: a reader sees the old file or the new one, never a part."""
    import secrets

    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def install(folder: Path, module_file: Path, info: dict[str, Any]) -> dict[str, Any]:
    """Put the built extension ``module_file`` and its sidecar ``info`` into ``folder`` (call under
    :func:`build_lock`); returns the sidecar written.

    The module goes to a new file named by its content hash (``dynslam2d_aot_kernels-<16 hex>.<abi>.so``), then
    the sidecar, which names that file with its size and SHA-256, replaces the old sidecar in one rename: a run
    reads the old sidecar (and loads the old module, still there) or the new one (the new module, complete before).
    Interrupted anywhere, the folder holds the previous valid pair, at most with an unnamed module file or a
    temporary file that no sidecar names. After the switch the other module files and temporary files are removed
    (a process that loaded one keeps its mapping; one about to load it reads the new sidecar again)."""
    data = module_file.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    suffix = module_file.name[len(MODULE_NAME):] if module_file.name.startswith(MODULE_NAME) else ".so"
    name = f"{MODULE_NAME}-{digest[:16]}{suffix}"
    info = dict(info, format=FORMAT, file=name, bytes=len(data), sha256=digest)
    _write_atomic(folder / name, data)
    _write_atomic(folder / SIDECAR, json.dumps(info, indent=1).encode())  # the switch
    try:
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)  # the renames on disk before the old module goes
        finally:
            os.close(dfd)
    except OSError:
        pass
    for path in folder.iterdir():
        if path.name != name and (MODULE_FILE.match(path.name) or TEMP_FILE.match(path.name)):
            try:
                path.unlink()
            except OSError:
                pass
    return info


def clear(folder: Path | None = None) -> list[Path]:
    """Delete every file a build made in ``folder`` (default :func:`aot_dir`): the module files, the sidecar,
    temporary files of an interrupted build and the lock file, nothing else; returns them. Raises
    :class:`BuildError` while a build is running there or when the folder cannot be written."""
    folder = folder if folder is not None else aot_dir()
    try:
        if not folder.is_dir():
            return []
    except OSError:
        return []
    gone = []
    with build_lock(folder):
        for path in sorted(folder.iterdir()):
            if path.name == SIDECAR or MODULE_FILE.match(path.name) or TEMP_FILE.match(path.name):
                if path.is_file():
                    path.unlink()
                    gone.append(path)
        (folder / LOCK).unlink()  # last, while held: a build starting now makes a new lock file
    return gone
