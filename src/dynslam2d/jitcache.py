"""Whether numba's on-disk cache holds the project's compiled kernels.

Every kernel is ``@njit(cache=True)``: the first run after an install or an edit of a
kernel module compiles them (tens of seconds), later runs load them from numba's cache.
The command line uses :func:`kernel_cache_state` to say "compiling kernels" instead of
reporting a misleading speed for such a run, and :func:`compile_seconds` measures the time
spent compiling (``kernel_compile_s`` in summary.json).

Where the cache lives: :func:`default_cache_dir` (``$XDG_CACHE_HOME/dynslam2d/numba``, by default
``~/.cache/dynslam2d/numba``), which ``import dynslam2d`` gives numba as ``NUMBA_CACHE_DIR`` unless
that is already set (:func:`use_default_cache_dir`). numba's default, ``__pycache__`` beside the
installed sources, is replaced with the files by every ``pip install``; a cache outside
site-packages survives a reinstall, and numba keys each entry by the SHA-256 of the source file
(numba ≥ 0.59), so an unchanged kernel module is loaded, not compiled again (docs/speed.md).

numba checks only the kernel's own file: a kernel that calls (and so compiles in) a kernel of another
module would be loaded stale after that other module changed. The default folder therefore has one
subfolder per version of the kernel modules' sources (:func:`kernel_sources_fingerprint`), and folders of
versions unused for :data:`STALE_AFTER_DAYS` are removed when a new one is made.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: Environment variable naming numba's cache folder (numba's own).
CACHE_ENV = "NUMBA_CACHE_DIR"


#: Prefix of the per-version subfolders of the default cache folder.
VERSION_PREFIX = "k-"

#: A version subfolder not used for this many days is removed when a new version's folder is made.
STALE_AFTER_DAYS = 14.0


def kernel_sources_fingerprint(package_dir: Path | None = None) -> str:
    """16 hex digits of the SHA-256 over the package's kernel modules: paths and bytes.

    A kernel module mentions ``njit`` or ``intrinsic`` (numba intrinsics, such as :mod:`dynslam2d.jitvec`'s lane
    operations, generate code inside the kernels that call them and are not in the kernels' own files).
    Any edit of a kernel module, including one whose kernels others call, gives a new fingerprint;
    reinstalling the same sources gives the same one. Reads the package's sources (about 1.6 MB, a few ms).
    """
    root = package_dir if package_dir is not None else Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        data = path.read_bytes()
        if b"njit" in data or b"intrinsic" in data:
            digest.update(path.relative_to(root).as_posix().encode() + b"\0")
            digest.update(data)
    return digest.hexdigest()[:16]


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/dynslam2d/numba`` (``~/.cache/dynslam2d/numba`` when XDG_CACHE_HOME is unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "dynslam2d" / "numba"


def default_cache_dir() -> Path:
    """The cache folder of this version of the kernel sources: ``<cache_root()>/k-<fingerprint>``."""
    return cache_root() / f"{VERSION_PREFIX}{kernel_sources_fingerprint()}"


def remove_stale_versions(root: Path, keep: Path, days: float = STALE_AFTER_DAYS) -> list[Path]:
    """Delete the version subfolders of ``root`` other than ``keep`` not used for ``days`` days; returns them.

    "Used" is the folder's modification time, which :func:`use_default_cache_dir` refreshes on every
    import. Only folders named ``k-<16 hex digits>`` are touched; errors (another process deleting the
    same folder, permissions) are ignored.
    """
    limit = time.time() - days * 86400.0
    removed = []
    for path in root.glob(f"{VERSION_PREFIX}*"):
        name = path.name[len(VERSION_PREFIX):]
        if path == keep or len(name) != 16 or any(c not in "0123456789abcdef" for c in name):
            continue
        try:
            if path.is_dir() and path.stat().st_mtime < limit:
                shutil.rmtree(path)
                removed.append(path)
        except OSError:
            continue
    return removed


def use_default_cache_dir() -> str | None:
    """Point numba's cache at :func:`default_cache_dir` unless the user chose one.

    Called by ``import dynslam2d`` before any kernel module is imported. Does nothing when
    ``NUMBA_CACHE_DIR`` is set (the user's choice wins) or numba is already imported (its
    configuration is read once, at import; the kernels then cache in ``__pycache__``). When the
    folder cannot be created, numba's default is kept. Returns the folder in use, or None.
    """
    if os.environ.get(CACHE_ENV):
        return os.environ[CACHE_ENV]
    if "numba" in sys.modules:
        return None
    path = default_cache_dir()
    try:
        is_new = not path.is_dir()
        path.mkdir(parents=True, exist_ok=True)
        os.utime(path)  # marks this version as used (remove_stale_versions)
    except OSError:
        return None
    if not os.access(path, os.W_OK):
        return None
    if is_new:
        remove_stale_versions(path.parent, path)
    os.environ[CACHE_ENV] = str(path)
    return str(path)


def cache_holds_no_index(folder: str | os.PathLike[str] | None = None) -> bool:
    """Whether numba's cache folder (``folder``, by default ``NUMBA_CACHE_DIR``) holds no index file (``*.nbi``) at
    all, or does not exist: every kernel a run needs must then be compiled. Told from the folder alone, without
    importing numba or a kernel module (it stops at the first index file found: a few ms on a warm cache). False
    when no folder is set (numba's in-tree ``__pycache__`` folders: the caller asks numba instead)."""
    path = folder if folder is not None else os.environ.get(CACHE_ENV)
    if not path:
        return False
    try:
        for _, _, files in os.walk(path):
            if any(name.endswith(".nbi") for name in files):
                return False
    except OSError:
        return False
    return True


#: numba's switch for plain (uncoloured) error messages (numba.core.errors), read when numba is imported.
PLAIN_ERRORS_ENV = "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"


def plain_numba_errors() -> bool:
    """Have numba format its error messages without terminal highlighting, unless the user chose otherwise.

    While it types a kernel, numba tries many templates per call and formats an error message for every
    attempt that does not fit (tens of thousands on a cold run); with colorama installed each message is
    wrapped in colorama's ``init()`` / ``deinit()``, which re-wraps ``sys.stdout`` and ``sys.stderr`` every
    time — 2–4 % of the cold compile of the README's first command (docs/speed.md). numba's default theme
    only makes the messages bold; numba's own test suite runs without it. The command line calls this
    first (it owns the process); does nothing once numba is imported (it reads the setting at import) or
    when the variable is set. Returns whether it set it."""
    if PLAIN_ERRORS_ENV in os.environ or "numba" in sys.modules:
        return False
    os.environ[PLAIN_ERRORS_ENV] = "1"
    return True


def lean_numba_compile() -> bool:
    """Have numba do less work per compiled function in this process, without changing any kernel's code.

    - **No C-callable wrapper.** numba emits, beside each function and its Python wrapper, a ``cfunc``
      wrapper so that the function can be passed around as a first-class function value; no kernel of
      this project is used that way (``@cfunc`` sets its own flag and is not affected). Setting
      ``no_cfunc_wrapper`` where a function's options leave it unset saves building, optimising and
      compiling 110–120 such wrappers on a cold run of the README's first command (kernels and numba's
      own ``np.empty``-style helpers alike).
    - **Cheaper option comparisons.** numba looks up every overloaded call it types (``np.empty``,
      ``min``, operators: about 70 000 lookups on that cold run) in a cache keyed by the compile flags;
      ``TargetConfig.__hash__`` hashes the sorted option names (a constant per class) and ``__eq__``
      compares all 22 options' values, rebuilding both dicts each time (3.6 and 6.1 µs). The hash is kept
      per class and equal stored values answer ``__eq__`` at once; the results are the same.
    - **Cheaper unequal option comparisons.** Those lookups compare the flags of different compiles too (a
      kernel's against a helper's: every key in numba's cache has the class's one hash): about 40 000
      comparisons on that cold run whose stored values differ, each rebuilding both dicts through the options'
      Python properties. They now compare the stored values over the class's defaults (numba's property
      returns the stored value, else the option's default: the same dicts, built without 44 property calls).
    - **Call typing remembered** (:func:`remembered_call_typing`, installed at the first compile): a call of one of
      numba's functions with argument types typed before tries the template that accepted them first instead of
      every template again (about a tenth of the compile CPU more; the same code).
    - **Compiles on a roomy frame stack** (:func:`roomy_compile_stack`): no 16 KiB chunk of CPython's frame
      stack mapped and unmapped per call where the compiler's stack depth sits at a chunk's end (≈ 200 000
      times on that cold run; 5–8 % of its compile CPU).
    - **Inlining without copying the callee's IR twice** (:func:`lean_inlining`, installed at the first compile):
      three quarters of numba's inlining pass.
    - **No machine code for a kernel compiled only as a callee** (:func:`lazy_callee_code`, installed at the first
      compile): its caller links its optimised IR anyway; the code is made when Python calls it.
    - **No context refresh that would install nothing** (:func:`lean_refresh`, installed at the first compile): ≈ 4 700
      refreshes per cold run after a lookup that misses on purpose.
    - **No debug-logging calls in numba's SSA pass** (:func:`quiet_ssa_debug`, installed at the first compile): about
      a million ``Logger.debug`` calls per cold run that log nothing.
    - **llvmlite's builder placed before a block's last instruction without a search** (:func:`lean_positions`,
      installed at the first compile): numba's ``alloca`` placements in the entry block.
    - **llvmlite's IR printer with less Python work, ABI sizes remembered** (``jitprint.install``, at the first
      compile): the text numba hands to LLVM, the same text; and numba's reference counts without the dead
      extracts of every member of a value (≈ a quarter of the IR instructions; the same machine code).
    - **llvmlite's IR modules freed when their compile ends** (:func:`free_spent_ir`, installed at the first
      compile): by reference counting instead of Python's cyclic collector (≈ 1.7 million objects a cold run).

    Together about a tenth of the compile CPU (docs/speed.md), and the remembered call typing about a tenth
    more. The command line and its background compile call this first (they own the process); a library
    user's process is left as it is. Returns whether it changed numba; does nothing when called again or when
    numba's internals differ."""
    try:
        from numba.core import cpu, targetconfig
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    options, config = cpu.CPUTargetOptions, targetconfig.TargetConfig
    if getattr(options.finalize, "_dynslam2d_lean", False) or not hasattr(config, "_values"):
        return False
    finalize, equal = options.finalize, config.__eq__
    hashes: dict[type, int] = {}
    defaults: dict[type, dict[str, Any]] = {}

    def lean_finalize(self: Any, flags: Any, opts: Any) -> None:
        finalize(self, flags, opts)
        if not flags.is_set("no_cfunc_wrapper"):
            flags.no_cfunc_wrapper = True

    def class_hash(self: Any) -> int:  # numba's own: hash(tuple(sorted(self.values()))), the sorted option names
        cls = type(self)
        if cls not in hashes:
            hashes[cls] = hash(tuple(sorted(cls.options)))
        return hashes[cls]

    def full_values(cls: type, values: dict[str, Any]) -> dict[str, Any]:  # numba's values(): default if unset
        if cls not in defaults:
            defaults[cls] = {name: option.default for name, option in cls.options.items()}
        return {**defaults[cls], **values}

    def fast_equal(self: Any, other: Any) -> Any:
        if type(self) is not type(other):
            return equal(self, other)
        mine, theirs = self._values, other._values
        return mine == theirs or full_values(type(self), mine) == full_values(type(self), theirs)

    lean_finalize._dynslam2d_lean = True  # type: ignore[attr-defined]
    options.finalize = lean_finalize
    config.__hash__ = class_hash  # type: ignore[method-assign,assignment]
    config.__eq__ = fast_equal  # type: ignore[method-assign,assignment]
    roomy_compile_stack()
    # numba's SSA pass, variable lists, use / def sets, live map (cold36, ssa36, uni36); llvmlite's IR printer and
    # remembered ABI sizes (cmp39)
    from dynslam2d import jitprint, jitssa

    at_first_compile(remembered_call_typing, lean_inlining, lazy_callee_code,  # (reading numba's sources: not warm)
                     quiet_ssa_debug, jitssa.install, jitprint.install, lean_refresh, lean_positions, free_spent_ir)
    return True


#: SHA-256 (16 hex digits) of llvmlite 0.50's ``IRBuilder.position_before`` as :func:`lean_positions` checks it.
POSITION_BEFORE_SOURCE = "a7fcbfdba4fcafe7"


def lean_positions() -> bool:
    """Have llvmlite's ``IRBuilder.position_before`` find an instruction that ends its block without searching the
    block (pass cmp70).

    numba puts every ``alloca`` of a function in its entry block (``cgutils.alloca_once``: ``goto_entry_block``,
    which positions the builder before the block's terminator); llvmlite finds the terminator's place with
    ``list.index`` over the block's instructions, thousands in a large kernel: ≈ 8 000 calls and 0.15 s of one core
    on a cold run of the README's first command. An instruction is in its block's list once (llvmlite inserts each
    new instruction object once; they compare by identity), so when it is the list's last element its index is the
    list's length less one: the same position. Any other instruction is searched for as llvmlite does. Done only
    when llvmlite's function has the source checked (:data:`POSITION_BEFORE_SOURCE`). Returns whether it changed
    llvmlite (not when called again)."""
    from llvmlite.ir import builder

    from dynslam2d.jitbox import source_hash

    own = builder.IRBuilder.position_before
    if getattr(own, "_dynslam2d_lean", False) or source_hash(own) != POSITION_BEFORE_SOURCE:
        return False

    def position_before(self: Any, instr: Any) -> None:
        self._block = instr.parent
        instructions = self._block.instructions
        self._anchor = (len(instructions) - 1 if instructions and instructions[-1] is instr
                        else instructions.index(instr))

    position_before._dynslam2d_lean = True  # type: ignore[attr-defined]
    position_before.__wrapped__ = own  # type: ignore[attr-defined]
    position_before.__doc__ = own.__doc__
    builder.IRBuilder.position_before = position_before
    return True


#: SHA-256 (16 hex digits) of numba 0.68's ``CPUCodeLibrary.add_ir_module`` as :func:`free_spent_ir` checks it.
ADD_IR_MODULE_SOURCE = "fb6dd665f0f609c4"


def _owned_ir(module: Any) -> list[Any]:
    """The objects of llvmlite IR ``module`` that belong to it alone: the module, its global values (functions,
    global variables), each function's arguments, return value, blocks and their instructions, and the module's
    metadata nodes. Not the operands they refer to (constants such as numba's ``cgutils.true_bit`` and the types
    are shared by every module)."""
    from llvmlite import ir

    objs: list[Any] = [module]
    for value in list(module.globals.values()):
        objs.append(value)
        if isinstance(value, ir.Function):
            objs.extend(value.args)
            objs.append(value.return_value)
            for block in value.blocks:
                objs.append(block)
                objs.extend(block.instructions)
    objs.extend(module.metadata)
    objs.extend(module.namedmetadata.values())
    return objs


def free_spent_ir() -> bool:
    """Have the llvmlite IR modules numba has handed to LLVM freed by reference counting, not by Python's cyclic
    garbage collector (pass cmp71).

    numba builds each function's code as an llvmlite IR module (a Python object per instruction, block, argument
    and function), prints it and has LLVM parse the text (``CPUCodeLibrary.add_ir_module``); from then on only the
    parsed module is used. The Python objects are in reference cycles (an instruction's ``parent`` is its block,
    which lists it; a block's is its function, whose ``blocks`` list it; a function's is its module, whose
    ``globals`` hold it), so only the collector frees them: on a cold run of the README's first command ≈ 1.7 of
    the ≈ 2.4 million objects the collector finds dead (165 modules, ≈ 356 000 objects of their own, and the
    operand lists, constants and attribute dicts only they hold). The collections that walk them while the
    compile goes on, and the full collection that frees them later, cost ≈ 1–2 s of CPU (docs/speed.md).

    Here each module handed to ``add_ir_module`` is kept until the compile it was made in (numba's
    ``numba:compile`` event: a kernel's, or a callee's inside it) ends; then the attribute dicts of the objects that
    belong to it alone (:func:`_owned_ir`) are emptied, which breaks every cycle among them, so the module and all
    it holds go as soon as numba drops its last reference. numba reads a module only while it lowers the function
    and in ``add_ir_module`` itself (checked: :data:`ADD_IR_MODULE_SOURCE`), so no code changes; done only with
    llvmlite's ``ir`` sources as ``jitprint`` checks them. Installed by :func:`lean_numba_compile` at the first
    compile (the command line's processes only). Returns whether it changed numba (not when called again)."""
    from numba.core import codegen, event

    from dynslam2d import jitprint
    from dynslam2d.jitbox import source_hash

    library = codegen.CPUCodeLibrary
    own = library.add_ir_module
    if getattr(own, "_dynslam2d_spent", False) or source_hash(own) != ADD_IR_MODULE_SOURCE:
        return False
    if not jitprint._sources_checked():
        return False
    spent: list[Any] = []  # modules handed to LLVM, oldest first
    marks: list[int] = []  # len(spent) when each open compile started (innermost last)

    def add_ir_module(self: Any, ir_module: Any) -> None:
        own(self, ir_module)
        spent.append(ir_module)

    class _Compiles(event.Listener):
        def on_start(self, ev: Any) -> None:
            marks.append(len(spent))

        def on_end(self, ev: Any) -> None:
            mark = min(marks.pop(), len(spent)) if marks else 0  # (installed inside a compile: its start unseen)
            done = spent[mark:]
            del spent[mark:]
            for module in done:
                if getattr(module, "globals", None) is None:  # (already emptied: handed to LLVM twice)
                    continue
                for obj in _owned_ir(module):
                    getattr(obj, "__dict__", {}).clear()

    add_ir_module._dynslam2d_spent = True  # type: ignore[attr-defined]
    add_ir_module.__wrapped__ = own  # type: ignore[attr-defined]
    add_ir_module.__doc__ = own.__doc__
    library.add_ir_module = add_ir_module  # type: ignore[method-assign]
    event.register("numba:compile", _Compiles())
    return True


def at_first_compile(*installs: Callable[[], Any]) -> None:
    """Call each of ``installs`` when numba first compiles a function in this process (its ``numba:compile`` event,
    which a load from the cache does not raise), before that compile's passes run.

    :func:`remembered_call_typing` and :func:`lean_inlining` read numba's sources to check what they re-implement
    (≈ 15 ms each): a warm run, which loads every kernel from the cache, need not pay for them."""
    from numba.core import event

    pending = list(installs)

    class _First(event.Listener):
        def on_start(self, ev: Any) -> None:
            while pending:
                pending.pop(0)()

        def on_end(self, ev: Any) -> None:
            pass

    event.register("numba:compile", _First())


#: Value-stack slots reserved by :func:`roomy_call`'s frame (8 bytes each; never used): the frame, ≈ 1 MiB, does not fit
#: CPython's 1 MiB data-stack chunk with the chunk's overhead, so the chunk made for it is 2 MiB, and the ≈ 1 MiB after
#: the frame holds the frames of the call.
ROOMY_STACK_SLOTS = 1 << 17


def _call(fn: Any, *args: Any, **kwargs: Any) -> Any:
    return fn(*args, **kwargs)


def _roomy(func: Any) -> Any:
    """``func`` with :data:`ROOMY_STACK_SLOTS` more value-stack slots in its frame (where frames live on CPython's
    data stack, 3.11 and later; else ``func`` itself)."""
    if sys.implementation.name != "cpython" or sys.version_info < (3, 11):
        return func
    code = func.__code__
    return type(func)(code.replace(co_stacksize=code.co_stacksize + ROOMY_STACK_SLOTS), func.__globals__,
                      "roomy_call")


#: ``roomy_call(fn, *args, **kwargs)`` is ``fn(*args, **kwargs)`` run in a fresh 2 MiB chunk of CPython's frame stack
#: (:func:`roomy_compile_stack`).
roomy_call = _roomy(_call)


def roomy_compile_stack() -> bool:
    """Run each outermost numba compile of this process in a fresh 2 MiB chunk of CPython's frame stack, so that
    no call in the compiler's inner loops pushes a frame across a chunk boundary.

    CPython (3.11 and later) keeps Python frames on a per-thread stack of memory chunks, 16 KiB each by default
    (``_PyThreadState_PushFrame``): a frame that does not fit in the current chunk gets a new chunk (``mmap``),
    and popping the first frame of a chunk frees it (``munmap``). Where the compiler's stack depth sits at a
    chunk's end, every call its loops make there maps and unmaps 16 KiB and faults its pages in: a cold run of
    the README's first command (one process) made ≈ 200 000 such pairs, 38 000 of them in the SSA pass of one
    kernel (``detect.mapevidence.seen_through_structure_kernel``: 0.3–0.5 s instead of 0.04 s). Which kernels
    are hit depends on the depth of the Python stack when they compile, so one more frame above the compile
    moves or removes it (docs/speed.md, pass cold28). Here numba's ``Dispatcher.compile``, when no compile is
    running in the process, is called through :func:`roomy_call`, whose frame reserves
    :data:`ROOMY_STACK_SLOTS` value-stack slots it never uses: CPython makes a 2 MiB chunk for it, and the
    compile's frames (its callees' and numba's helpers' compiles included) fit in the ≈ 1 MiB after it; the
    chunk's untouched pages are never faulted in, and it is freed when the compile returns (a load from the
    cache goes the same way: one map and unmap). The compiled code is the same. Called by
    :func:`lean_numba_compile`; returns whether it installed this (not when called again, nor before CPython
    3.11, whose frames are objects of their own)."""
    if roomy_call is _call:
        return False
    from numba.core import dispatcher

    compile_ = dispatcher.Dispatcher.compile
    if getattr(compile_, "_dynslam2d_roomy", False):
        return False
    depth = [0]

    def compile_roomy(self: Any, sig: Any) -> Any:
        if depth[0]:
            return compile_(self, sig)
        depth[0] += 1
        try:
            return roomy_call(compile_, self, sig)
        finally:
            depth[0] -= 1

    compile_roomy._dynslam2d_roomy = True  # type: ignore[attr-defined]
    compile_roomy.__wrapped__ = compile_  # type: ignore[attr-defined]
    dispatcher.Dispatcher.compile = compile_roomy  # type: ignore[method-assign]
    return True


#: SHA-256 (first 16 hex digits) of the source of numba's ``BaseFunction.get_call_type`` that
#: :func:`remembered_call_typing` re-implements (numba 0.68); any other source is left as it is.
GET_CALL_TYPE_SOURCE = "6559c167bfc0ad36"


def remembered_call_typing() -> bool:
    """Have numba try, for a call it has typed before, the template that typed it first.

    numba types every call of a function it implements (``operator.add``, ``min``, ``np.empty``, ``math.floor``,
    …) by trying that function's templates in order until one accepts the argument types
    (``BaseFunction.get_call_type``), and does so again at every call site: about 10 templates per call, ≈ 26 000
    calls on a cold run of the README's first command, 95 % of them with argument types already typed for the
    same function. Here the first success is remembered per (function type, typing context, target, argument
    types, keyword types) as the template and the literal choice that accepted them; a later call with the same
    key applies that template again (with its side effects: the overload it compiled and the implementation key
    that lowering reads are set again, as numba's own loop sets them), skipping the templates that failed for
    those types before. A template's answer depends only on the argument types (numba's types are interned; a
    function given more templates is a new function type), so the same signature and code come out: every
    compiled kernel of a cold run has the same optimised LLVM IR as without this (docs/speed.md, pass cold23).
    A call that fails is never remembered, so errors are raised as before; should the remembered template not
    accept the types again, numba's full search runs. Called by :func:`lean_numba_compile`; returns whether it
    changed numba (not when called again, or when numba's ``get_call_type`` is not the one re-implemented)."""
    import inspect

    try:
        from numba.core import errors, utils
        from numba.core.target_extension import get_local_target
        from numba.core.types import functions
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    base = functions.BaseFunction
    original = base.get_call_type
    if getattr(original, "_dynslam2d_remembered", False):
        return False
    try:
        source = inspect.getsource(original)
    except (OSError, TypeError):
        return False
    if hashlib.sha256(source.encode()).hexdigest()[:16] != GET_CALL_TYPE_SOURCE:
        return False
    unlit = functions._unlit_non_poison
    remembered: dict[tuple[Any, ...], tuple[Any, bool]] = {}

    def apply(temp: Any, uselit: bool, args: Any, kws: Any) -> Any:
        if uselit:
            return temp.apply(args, kws)
        return temp.apply(tuple([unlit(a) for a in args]), {k: unlit(v) for k, v in kws.items()})

    def get_call_type(self: Any, context: Any, args: Any, kws: Any) -> Any:
        target_hw = get_local_target(context)
        try:
            key: tuple[Any, ...] | None = (self, context, target_hw, tuple(args), tuple(sorted(kws.items())))
            hit = remembered.get(key)  # type: ignore[arg-type]
        except TypeError:  # (an unhashable argument type: numba's search, not remembered)
            key = hit = None
        if hit is not None:
            temp = hit[0](context)
            try:
                sig = apply(temp, hit[1], args, kws)
            except errors.NumbaError:
                sig = None
            if sig is not None:
                self._impl_keys[sig.args] = temp.get_impl_key(sig)
                return sig
        # numba's BaseFunction.get_call_type (0.68), remembering the template that succeeds
        prefer_lit = [True, False]  # old behavior preferring literal
        prefer_not = [False, True]  # new behavior preferring non-literal
        failures = functions._ResolutionFailures(context, self, args, kws, depth=self._depth)
        order = utils.order_by_target_specificity(target_hw, self.templates, fnkey=self.key[0])
        self._depth += 1
        for temp_cls in order:
            temp = temp_cls(context)
            choice = prefer_lit if temp.prefer_literal else prefer_not
            for uselit in choice:
                try:
                    sig = apply(temp, uselit, args, kws)
                except Exception as e:
                    if not isinstance(e, errors.NumbaError):
                        raise e
                    sig = None
                    failures.add_error(temp, False, e, uselit)
                else:
                    if sig is not None:
                        self._impl_keys[sig.args] = temp.get_impl_key(sig)
                        self._depth -= 1
                        if key is not None:
                            remembered[key] = (temp_cls, uselit)
                        return sig
                    registered_sigs = getattr(temp, "cases", None)
                    if registered_sigs is not None:
                        msg = "No match for registered cases:\n%s"
                        msg = msg % "\n".join(f" * {x}" for x in registered_sigs)
                    else:
                        msg = "No match."
                    failures.add_error(temp, True, msg, uselit)
        failures.raise_error()

    get_call_type._dynslam2d_remembered = True  # type: ignore[attr-defined]
    get_call_type.__wrapped__ = original  # type: ignore[attr-defined]
    base.get_call_type = get_call_type  # type: ignore[method-assign]
    return True


#: SHA-256 (first 16 hex digits) of the sources of numba's ``InlineWorker.inline_ir`` and ``inline_function`` that
#: :func:`lean_inlining` rewrites (numba 0.68); any other source is left as it is.
INLINE_IR_SOURCE = "26fd2b7600c9d929"
INLINE_FUNCTION_SOURCE = "1b53f183258e659d"

#: The two statements of ``inline_ir`` that copy the callee's IR block by block (``copy.deepcopy`` of each block with a
#: memo of its own, the function's scope and every variable in it included).
_COPY_CALLEE = "callee_ir = copy_ir(callee_ir)"
_COPY_ORIGINAL = "callee_ir_original = copy_ir(callee_ir)"


def lean_inlining() -> bool:
    """Have numba inline an ``inline="always"`` function into its caller without copying the callee's IR twice.

    numba's ``InlineWorker.inline_ir`` (numba.core.inline_closurecall) first deep-copies the callee's IR, block by block
    ("it gets mutated"), then deep-copies that copy once more as "an unmutated copy to return"; each block's copy
    copies the function's scope with all its variables again, so the two copies cost more than the callee's whole
    untyped front end (``translate_bytecode`` to ``inline_closure_likes``) that ``inline_function`` runs to get the IR:
    three quarters of numba's ``inline_inlinables`` pass on a cold run of the README's first command (docs/speed.md,
    pass cold30). Here:

    - the second copy is not made (``inline_ir`` returns None in its place): both of numba's callers of ``inline_ir``
      (``InlineInlinables`` through ``inline_function``, and ``InlineOverloads``) discard it;
    - ``inline_function``, whose callee IR is the one ``run_untyped_passes`` has just built for this call and nothing
      else holds, inlines it without the first copy either (``InlineOverloads`` passes IR kept in its cache: it keeps
      that copy).

    The inlined statements are the same objects' copies or the objects themselves, with the same names and labels;
    the blocks' scopes are set to the caller's as before. Every kernel of a cold run gets the same LLVM IR as without
    this (docs/speed.md). The functions are numba's own source with those statements edited, compiled in numba's
    module; done only when that source is the one checked here (:data:`INLINE_IR_SOURCE`,
    :data:`INLINE_FUNCTION_SOURCE`). Called by :func:`lean_numba_compile`; returns whether it changed numba (not when
    called again)."""
    import inspect
    import textwrap

    try:
        from numba.core import inline_closurecall
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    worker = inline_closurecall.InlineWorker
    inline_ir, inline_function = worker.inline_ir, worker.inline_function
    if getattr(inline_function, "_dynslam2d_lean", False):
        return False
    try:
        source = textwrap.dedent(inspect.getsource(inline_ir))
        function_source = inspect.getsource(inline_function)
    except (OSError, TypeError):
        return False
    if (hashlib.sha256(inspect.getsource(inline_ir).encode()).hexdigest()[:16] != INLINE_IR_SOURCE
            or hashlib.sha256(function_source.encode()).hexdigest()[:16] != INLINE_FUNCTION_SOURCE
            or source.count(_COPY_CALLEE) != 1 or source.count(_COPY_ORIGINAL) != 1):
        return False

    def build(text: str, name: str) -> Any:
        space = dict(vars(inline_closurecall))  # numba's module globals (the helpers inline_ir calls)
        exec(compile(text.replace("def inline_ir(", f"def {name}(", 1), inline_closurecall.__file__, "exec"), space)
        func = space[name]
        return type(func)(func.__code__, vars(inline_closurecall), name, func.__defaults__)

    kept = source.replace(_COPY_ORIGINAL, "callee_ir_original = None", 1)
    no_copy = build(kept.replace(_COPY_CALLEE, "pass", 1), "inline_ir_fresh")
    no_original = build(kept, "inline_ir")

    def lean_function(self: Any, caller_ir: Any, block: Any, i: Any, function: Any, arg_typs: Any = None) -> Any:
        callee_ir = self.run_untyped_passes(function)  # numba's inline_function, without the copy of a fresh IR
        freevars = function.__code__.co_freevars
        return no_copy(self, caller_ir, block, i, callee_ir, freevars, arg_typs=arg_typs)

    no_original.__wrapped__ = inline_ir  # type: ignore[attr-defined]
    lean_function._dynslam2d_lean = True  # type: ignore[attr-defined]
    lean_function.__wrapped__ = inline_function  # type: ignore[attr-defined]
    worker.inline_ir = no_original
    worker.inline_function = lean_function
    return True


#: SHA-256 (first 16 hex digits) of the sources of the numba 0.68 functions :func:`lean_refresh` relies on: what a
#: context refresh does (both contexts' ``refresh``, ``load_additional_registries``, ``_load_builtins``), how a registry
#: is installed (``install_registry``: only the registrations appended since its loader last read) and the loaders'
#: streams; any other source is left as it is.
REFRESH_SOURCES = {"BaseContext.refresh": "83e8f5cc63a7fee8", "BaseContext.install_registry": "bdaf4e9db8fe66e2",
                   "CPUContext.load_additional_registries": "0383d5716d370fa9",
                   "typing.BaseContext.refresh": "1440782349211fb6",
                   "typing.BaseContext._load_builtins": "0dd81dada6654089",
                   "typing.BaseContext.install_registry": "8b38bc0cff80e2fe",
                   "typing.Context.load_additional_registries": "a99a8a1a62aa8bb5",
                   "BaseRegistryLoader": "62eb98cb0c91ce1d", "stream_list": "34549f7d2c7ea9c9",
                   "init_all": "8cad7f8ebbb5530e"}


def _registry_lists(ctx: Any) -> tuple[tuple[Any, ...], tuple[int, ...]]:
    """The registries numba's target context ``ctx`` and its typing context have loaders for, and every list each
    loader streams (``registry_items``), in the contexts' order."""
    regs: list[Any] = []
    lists: list[Any] = []
    for c in (ctx, ctx.typing_context):
        for reg, loader in c._registries.items():
            regs.append(reg)
            lists.extend(getattr(reg, name) for name in loader.registry_items)
    return tuple(regs), tuple(lists)


def _registrations_seen(ctx: Any) -> tuple[Any, ...]:
    """What a refresh of numba's target context ``ctx`` could still install: whether numba's run-time system and
    extension entry points are initialised, how many registries each context has loaders for, and the length of
    every list those loaders stream (the lists of :func:`_registry_lists`, kept on the context while the registries
    are the same ones)."""
    from numba.core import entrypoints
    from numba.core.runtime import rtsys

    sizes = (len(ctx._registries), len(ctx.typing_context._registries))
    kept = ctx.__dict__.get("_dynslam2d_lists")
    if kept is None or kept[0] != sizes:
        regs, lists = _registry_lists(ctx)
        kept = ctx._dynslam2d_lists = (sizes, regs, lists)  # (holds the registries: their lists stay these objects)
    return (rtsys._init, entrypoints._already_initialized, sizes, *map(len, kept[2]))


def lean_refresh() -> bool:
    """Have numba skip a target context's refresh when it would install nothing.

    ``BaseContext.get_function`` refreshes the context (``refresh``: the CPU context's additional registries, the
    builtin registry, the typing context's registries, ≈ 30 ``from … import`` statements and 17 registries asked for
    new registrations) whenever a lookup misses, before it looks again; numba's array structures miss on purpose
    (``make_array``'s ``_make_refs`` asks for an ``__array__`` implementation that plain arrays do not have, at every
    array value the lowering touches), and so do ``static_getitem`` / ``static_setitem`` before their fallbacks, and
    every overload template refreshes the target context: ≈ 4 700 refreshes on a cold run of the README's first
    command, all but a handful installing nothing. A registry is installed incrementally (its loader streams only
    the registrations appended since it last read, ``utils.stream_list``), so a refresh installs nothing when no
    list of a registry either context has a loader for grew since a refresh during which none grew (the fixed
    modules imported, the fixed registries loaded then, numba's run-time system and entry points initialised):
    :func:`_registrations_seen` before and after each full refresh; when it is unchanged since a refresh that left
    it unchanged, the call returns at once. The contexts' tables are then the same as numba's refresh leaves them,
    so every lookup, and every kernel's IR and code, is the same. A context whose class overrides the additional
    registries is refreshed as numba does. Called by :func:`lean_numba_compile` at the first compile; returns whether
    it changed numba (not when called again, nor when numba's sources differ, :data:`REFRESH_SOURCES`)."""
    import inspect

    try:
        from numba.core import base, cpu, entrypoints, utils
        from numba.core.typing import context as typing_context
        from numba.core.typing import templates
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    refresh = base.BaseContext.refresh
    if getattr(refresh, "_dynslam2d_refresh", False):
        return False
    found = {"BaseContext.refresh": refresh, "BaseContext.install_registry": base.BaseContext.install_registry,
             "CPUContext.load_additional_registries": cpu.CPUContext.load_additional_registries,
             "typing.BaseContext.refresh": typing_context.BaseContext.refresh,
             "typing.BaseContext._load_builtins": typing_context.BaseContext._load_builtins,
             "typing.BaseContext.install_registry": typing_context.BaseContext.install_registry,
             "typing.Context.load_additional_registries": typing_context.Context.load_additional_registries,
             "BaseRegistryLoader": templates.BaseRegistryLoader, "stream_list": utils.stream_list,
             "init_all": entrypoints.init_all}
    for name, func in found.items():
        try:
            source = inspect.getsource(func)
        except (OSError, TypeError):
            return False
        if hashlib.sha256(source.encode()).hexdigest()[:16] != REFRESH_SOURCES.get(name):
            return False
    checked = {cpu.CPUContext: (cpu.CPUContext.load_additional_registries, typing_context.Context)}

    def lean(self: Any) -> None:
        kinds = checked.get(type(self))
        typing = getattr(self, "typing_context", None)
        if (kinds is None or type(self).load_additional_registries is not kinds[0] or type(typing) is not kinds[1]
                or type(self).install_registry is not base.BaseContext.install_registry):
            refresh(self)
            return
        clean = self.__dict__.get("_dynslam2d_refreshed")
        if clean is not None and clean == _registrations_seen(self):
            return
        before = _registrations_seen(self)
        self.__dict__.pop("_dynslam2d_refreshed", None)
        refresh(self)
        after = _registrations_seen(self)
        if after == before:  # (nothing grew during it: every loader has read its whole list)
            self._dynslam2d_refreshed = after

    lean._dynslam2d_refresh = True  # type: ignore[attr-defined]
    lean.__wrapped__ = refresh  # type: ignore[attr-defined]
    base.BaseContext.refresh = lean  # type: ignore[method-assign]
    return True


#: SHA-256 (first 16 hex digits) of the sources of numba's functions whose behaviour :func:`lazy_callee_code` relies on
#: or re-does in part (numba 0.68); any other source is left as it is.
LAZY_SOURCES = {
    "Dispatcher.compile": "0ab4aee15e79bb1d",
    "Dispatcher.add_overload": "3cd1a51507868539",
    "Dispatcher.get_overload": "7dd56f622edd2016",
    "Dispatcher.get_impl_key": "a43b40607b476035",
    "CPUCodeLibrary._finalize_final_module": "95bbf4fcbb90ed99",
    "CPUContext.get_executable": "3892c8a654a2ca69",
    "Cache._save_overload": "cfe1bb44a31657d2",
    "CPUCodeLibrary._get_module_for_linking": "56dde0e0555b5ec8",
}


#: Whether :func:`lazy_callee_code` also leaves a lazy callee's LLVM optimisation to the kernels that link its code.
CALLEE_OPTIMISED_IN_CALLER = True

#: Lazy callees (``module.function``) whose own function, once optimised in the first kernel that links it, is
#: linked optimised into the later kernels that link it instead of being optimised again in each (pass cmp49; with
#: :data:`CALLEE_OPTIMISED_IN_CALLER`). Only kernels whose callers' machine code was checked to be the same as when
#: each optimises the callee itself (``benchmarks/check_jitprint.py --dump D --asm``, passes cmp49 and cmp51).
#: ``measure_batch``: ≈ 15 000 IR instructions, linked by ``detect_rows``, ``association_gates`` and
#: ``update_pairs``; ``_bearing_bin`` by ``gated_points`` and ``match_pyramid``; ``_scan_geometry`` by
#: ``vacated_scan_kernel`` and ``_geometry_bounds``.
CALLEE_OPTIMISED_ONCE = frozenset({
    "dynslam2d.detect.kernels.measure_batch",
    "dynslam2d.slam.matcher._bearing_bin",
    "dynslam2d.slam.cleanup._scan_geometry",
})

#: Suffix of the name given, in the module a later caller links, to the callee's unoptimised copy that
#: :data:`CALLEE_OPTIMISED_ONCE` leaves unused.
UNUSED_SUFFIX = "$dynslam2d_unused"


class LazyEntry:
    """Stand-in for the entry point (numba's Python-callable wrapper of the machine code) of a kernel compiled only
    because another kernel calls it (:func:`lazy_callee_code`): what numba's ``get_executable`` needs to make the real
    one. Not callable; numba's dispatcher never holds it in its table of callable signatures."""

    __slots__ = ("context", "library", "fndesc", "env")

    def __init__(self, context: Any, library: Any, fndesc: Any, env: Any) -> None:
        self.context, self.library, self.fndesc, self.env = context, library, fndesc, env


def _lazy_sources_checked() -> dict[str, Any] | None:
    """numba's functions named in :data:`LAZY_SOURCES`, when their sources are the ones checked; else None."""
    import inspect

    try:
        from numba.core import caching, codegen, cpu, dispatcher, types
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    found = {
        "Dispatcher.compile": dispatcher.Dispatcher.compile,
        "Dispatcher.add_overload": dispatcher.Dispatcher.add_overload,
        "Dispatcher.get_overload": dispatcher.Dispatcher.get_overload,
        "Dispatcher.get_impl_key": types.Dispatcher.get_impl_key,
        "CPUCodeLibrary._finalize_final_module": codegen.CPUCodeLibrary._finalize_final_module,
        "CPUContext.get_executable": cpu.CPUContext.get_executable,
        "Cache._save_overload": caching.Cache._save_overload,
        "CPUCodeLibrary._get_module_for_linking": codegen.CPUCodeLibrary._get_module_for_linking,
    }
    for name, func in found.items():
        try:
            source = inspect.getsource(func)  # (of numba's own function where a wrapper names it __wrapped__)
        except (OSError, TypeError):
            return None
        if hashlib.sha256(source.encode()).hexdigest()[:16] != LAZY_SOURCES[name]:
            return None
    return found


def optimised_callee(first: Any, kernel: str) -> Any | None:
    """For :data:`CALLEE_OPTIMISED_ONCE`: the lazy callee's function ``kernel`` as the library ``first`` (its first
    caller) has it right after LLVM's optimisation, with the functions and globals it uses (a clone of that final
    module, everything else dropped by LLVM's global dead-code elimination, linkages restored); None when ``first``
    has no definition of ``kernel`` (inlined everywhere). Taken before ``first``'s machine code: MCJIT's code
    generator rewrites the module it compiles in place (CodeGenPrepare's slow-division bypass, select sinking,
    ``freeze``, hoisted constants; pass cmp51), and a copy taken after that compiles to other instructions when a
    later caller's code generator runs those rewrites on it again."""
    import llvmlite.binding as ll

    try:
        if first._final_module.get_function(kernel).is_declaration:
            return None
    except NameError:
        return None
    optimised = first._final_module.clone()
    linkages: dict[str, Any] = {}
    for value in [*optimised.functions, *optimised.global_variables]:
        if not value.is_declaration and not value.name.startswith("llvm."):
            linkages[value.name] = value.linkage
            value.linkage = "external" if value.name == kernel else "internal"
    manager = ll.ModulePassManager()
    manager.add_global_dead_code_eliminate_pass()
    manager.run(optimised, ll.create_pass_builder(first._codegen._tm, ll.create_pipeline_tuning_options()))
    for value in [*optimised.functions, *optimised.global_variables]:
        if value.name in linkages:
            value.linkage = linkages[value.name]
    return optimised


def optimised_once(optimised: Any, kernel: str, linked: Any) -> tuple[Any, Any] | None:
    """For :data:`CALLEE_OPTIMISED_ONCE`: the two modules a later caller of a lazy callee links instead of the
    callee's unoptimised module ``linked`` — that module with the callee's own function ``kernel`` renamed out of
    the way (:data:`UNUSED_SUFFIX`: the caller's calls are left to a declaration, so its pipeline does not optimise
    the callee again, and the unused copy is dropped), and, linked after the caller's optimisation, ``optimised``
    (:func:`optimised_callee` of the first caller); None when there is no such module."""
    if optimised is None:
        return None
    try:
        unused = linked.clone()
        unused.get_function(kernel).name = kernel + UNUSED_SUFFIX
    except NameError:
        return None
    return unused, optimised


def lazy_callee_code() -> bool:
    """Have numba make the machine code of a dynslam2d kernel that it compiles only because another kernel calls it
    when Python first asks for that kernel, not when it compiles it.

    A kernel ``f`` that calls a kernel ``g`` compiles ``g`` while typing the call (``Dispatcher.get_call_template``):
    numba optimises ``g``'s library, compiles it to machine code (MCJIT ``finalize_object``), takes the address of
    its Python wrapper (``CPUContext.get_executable``) and writes ``g`` to the cache (its machine code and bitcode).
    ``f`` then links ``g``'s optimised IR into its own library and optimises and compiles it again: ``g``'s own
    machine code, wrapper and cache entry serve only a later call of ``g`` from Python, which the README's first
    command never makes (``g`` is not in :mod:`dynslam2d.jitmanifest`), and a warm run loads ``f`` whole from the
    cache without ``g`` (docs/speed.md, passes cold25, cold30 and cold34). numba's own helpers compiled for a kernel
    (``@overload`` implementations such as ``np.empty``'s, compiled without a Python wrapper: never callable from
    Python) are treated the same (pass cold35). Here, for a dynslam2d kernel or a function without a Python wrapper
    compiled while another compile is in progress (numba's ``numba:compile`` events):

    - ``get_executable`` returns a :class:`LazyEntry` instead of the wrapper, and ``g``'s library, once optimised
      (as numba does it, when ``f`` links it), is not handed to the execution engine (no machine code);
    - the dispatcher keeps the compile result for typing and linking (``overloads``) but not in its table of
      callable signatures, and no cache entry is written for it;
    - the caller's lowering finds ``g``'s code under that stand-in (numba keys a kernel's implementation by its entry
      point: ``types.Dispatcher.get_impl_key``, ``Dispatcher.get_overload``, ``insert_user_function``);
    - when Python calls ``g`` (``Dispatcher.compile`` outside any compile, ``_compile_for_args``),
      the library is handed to the engine and compiled, the wrapper made, the signature entered in the table and
      written to the cache: what numba would have done at the compile, from the same optimised IR.

    With :data:`CALLEE_OPTIMISED_IN_CALLER` (pass cmp41), ``g``'s library is not optimised either: ``f`` links ``g``'s
    IR as numba lowered it and optimises it once, in its own module pipeline, which simplifies every function
    bottom-up before its inliner looks at it. LLVM's module pipeline of ``g`` alone was ≈ 1.2 s of a cold run's
    ≈ 7 s of optimisation (docs/speed.md, pass cmp41), done again in ``f``. ``g``'s optimisation is run when Python
    first calls ``g`` (as a compile of ``g``, before its machine code), on ``g``'s own module only: callers linked
    ``g``'s unoptimised IR, and later callers link it too. The callers' code is not the same as with ``g``
    optimised first (no pipeline reassociates or contracts floating point, no ``fastmath``: the same numbers).

    A library whose IR refers to numba's run-time linker (recursion: ``.numba.unresolved$`` names) is compiled as
    numba does. Done only when numba's sources are the ones checked (:data:`LAZY_SOURCES`); called by
    :func:`lean_numba_compile` at the first compile, so it touches only the command line's processes. Returns
    whether it changed numba."""
    import weakref

    found = _lazy_sources_checked()
    if found is None or getattr(found["Dispatcher.add_overload"], "_dynslam2d_lazy", False):
        return False
    from numba.core import caching, codegen, cpu, dispatcher, event, sigutils

    from dynslam2d import jitbox  # noqa: F401 - its LLVM optimisation in place first (the one wrapped below)

    compile_, add_overload = dispatcher.Dispatcher.compile, found["Dispatcher.add_overload"]
    optimise_final = codegen.CPUCodeLibrary._optimize_final_module  # (jitbox's one_llvm_optimisation, or numba's)
    compile_for_args = dispatcher.Dispatcher._compile_for_args
    finalize_final, get_executable = found["CPUCodeLibrary._finalize_final_module"], found["CPUContext.get_executable"]
    save = found["Cache._save_overload"]
    for_linking = found["CPUCodeLibrary._get_module_for_linking"]
    unresolved = codegen.RuntimeLinker.PREFIX
    lazy = [False]  # per compile in progress (numba's "numba:compile" events): whether it is a kernel's callee

    class _Callees(event.Listener):
        def on_start(self, ev: Any) -> None:
            disp = (ev.data or {}).get("dispatcher")
            module = getattr(getattr(disp, "py_func", None), "__module__", "") or ""
            no_wrapper = bool((getattr(disp, "targetoptions", None) or {}).get("no_cpython_wrapper", False))
            lazy.append(len(lazy) > 1 and (module.startswith("dynslam2d.") or no_wrapper))

        def on_end(self, ev: Any) -> None:
            if len(lazy) > 1:
                lazy.pop()

    def lazy_executable(self: Any, library: Any, fndesc: Any, env: Any) -> Any:
        if lazy[-1] and not library._finalized:  # (a library loaded from the cache is finalized: numba's way)
            library._dynslam2d_lazy = True
            if f"{fndesc.modname}.{fndesc.qualname}" in CALLEE_OPTIMISED_ONCE:
                library._dynslam2d_kernel = fndesc.mangled_name
            return LazyEntry(self, library, fndesc, env)
        return get_executable(self, library, fndesc, env)

    def recursive(module: Any) -> bool:
        return any(g.name.startswith(unresolved) for g in module.global_variables)

    def lazy_optimise_final(self: Any) -> None:
        if getattr(self, "_dynslam2d_lazy", False) and not recursive(self._final_module):
            self._dynslam2d_unoptimised = True  # (its callers optimise its code; Python's first call: optimise_own)
            self._dynslam2d_links_raw = True  # (what callers link stays unoptimised: optimise_own keeps a clone)
            return None
        later = self.__dict__.pop("_dynslam2d_link_after", ())
        optimise_final(self)
        for optimised in later:  # (CALLEE_OPTIMISED_ONCE: callees' functions optimised in their first caller)
            self._final_module.link_in(optimised, preserve=True)
        for callee in self.__dict__.pop("_dynslam2d_first_of", ()):  # (before this library's machine code)
            callee._dynslam2d_optimised = optimised_callee(self, callee._dynslam2d_kernel)
        return None

    finalizing: list[Any] = []  # libraries being finalized, innermost last (a caller links its callees' modules)
    finalize_library = codegen.CPUCodeLibrary.finalize

    def tracked_finalize(self: Any) -> None:
        finalizing.append(self)
        try:
            finalize_library(self)
        finally:
            finalizing.pop()

    def once_for_linking(self: Any) -> Any:
        module = for_linking(self)
        kernel = getattr(self, "_dynslam2d_kernel", None)
        if not (kernel and finalizing and getattr(self, "_dynslam2d_links_raw", False)):
            return module
        caller = finalizing[-1]
        if caller is self or getattr(caller, "_dynslam2d_lazy", False):  # (a lazy caller stays unoptimised)
            return module
        once = self.__dict__.get("_dynslam2d_once", False)  # (False: not tried yet)
        if once is False:
            if not self.__dict__.get("_dynslam2d_first_caller", False):  # the first caller optimises the callee's
                self._dynslam2d_first_caller = True  # code, as in numba's way, and keeps it (lazy_optimise_final)
                caller.__dict__.setdefault("_dynslam2d_first_of", []).append(self)
                return module
            once = self._dynslam2d_once = optimised_once(self.__dict__.get("_dynslam2d_optimised"), kernel, module)
        if not once:
            return module
        caller.__dict__.setdefault("_dynslam2d_link_after", []).append(once[1])
        return once[0]

    def optimise_own(disp: Any, args: tuple[Any, ...], cres: Any, library: Any) -> None:
        """The optimisation :func:`lazy_optimise_final` left out, before ``library``'s machine code, as a compile of
        ``disp`` (numba's "numba:compile" event: the pipeline ``optimise_final`` runs inside a kernel's compile),
        with the IR its callers link kept as it was."""
        library._dynslam2d_unoptimised = False
        if library._get_module_for_linking() is library._final_module:
            library._shared_module = library._final_module.clone()
        data = {"dispatcher": disp, "args": args, "return_type": cres.signature.return_type}
        with event.trigger_event("numba:compile", data=data):
            optimise_final(library)
        library._final_module.verify()

    def lazy_finalize_final(self: Any) -> None:
        module = self._final_module
        if not getattr(self, "_dynslam2d_lazy", False) or recursive(module):
            self._dynslam2d_lazy = False
            return finalize_final(self)
        # numba's _finalize_final_module up to the engine: its checks and the module's library for the object cache
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        module._CPUCodeLibrary__library = weakref.proxy(self)  # (numba's name-mangled attribute)
        self._finalized = True
        return None

    def to_engine(disp: Any, args: tuple[Any, ...], cres: Any, library: Any) -> None:
        """The rest of numba's _finalize_final_module for a library :func:`lazy_finalize_final` kept back."""
        library._ensure_finalized()
        if getattr(library, "_dynslam2d_lazy", False):
            library._dynslam2d_lazy = False
            if getattr(library, "_dynslam2d_unoptimised", False):
                optimise_own(disp, args, cres, library)
            cleanup = library._codegen._add_module(library._final_module)
            if cleanup:
                weakref.finalize(library, cleanup)
            library._finalize_specific()

    def materialise(disp: Any, args: tuple[Any, ...]) -> Any:
        cres = disp.overloads[args]
        entry = cres.entry_point
        to_engine(disp, args, cres, entry.library)
        cfunc = get_executable(entry.context, entry.library, entry.fndesc, entry.env)
        try:
            entry.context.remove_user_function(entry)
        except KeyError:
            pass
        entry.context.insert_user_function(cfunc, entry.fndesc, [entry.library])
        cres = cres._replace(entry_point=cfunc)
        add_overload(disp, cres)
        disp._cache.save_overload(args, cres)
        return cfunc

    def lazy_add_overload(self: Any, cres: Any) -> None:
        if isinstance(cres.entry_point, LazyEntry):
            self.overloads[tuple(cres.signature.args)] = cres  # (typing and linking only: not callable)
            return
        add_overload(self, cres)

    def lazy_compile(self: Any, sig: Any) -> Any:
        if len(lazy) == 1:  # not inside a compile: a call from Python, which needs the machine code
            args = tuple(sigutils.normalize_signature(sig)[0])
            existing = self.overloads.get(args)
            if existing is not None and isinstance(existing.entry_point, LazyEntry):
                with dispatcher.global_compiler_lock:
                    return materialise(self, args)
        return compile_(self, sig)

    def lazy_compile_for_args(self: Any, *args: Any, **kws: Any) -> Any:
        entry = compile_for_args(self, *args, **kws)
        if isinstance(entry, LazyEntry):  # (a call from Python made while compiling)
            args_ = next(a for a, c in self.overloads.items() if c.entry_point is entry)
            with dispatcher.global_compiler_lock:
                return materialise(self, args_)
        return entry

    def lazy_save(self: Any, sig: Any, data: Any) -> None:
        if isinstance(getattr(data, "entry_point", None), LazyEntry):
            return
        save(self, sig, data)

    for new, old in ((lazy_add_overload, add_overload), (lazy_compile, compile_),
                     (lazy_compile_for_args, compile_for_args), (lazy_finalize_final, finalize_final),
                     (lazy_executable, get_executable), (lazy_save, save)):
        new.__wrapped__ = old  # type: ignore[attr-defined]
    lazy_add_overload._dynslam2d_lazy = True  # type: ignore[attr-defined]
    event.register("numba:compile", _Callees())
    dispatcher.Dispatcher.add_overload = lazy_add_overload  # type: ignore[method-assign]
    dispatcher.Dispatcher.compile = lazy_compile  # type: ignore[method-assign]
    dispatcher.Dispatcher._compile_for_args = lazy_compile_for_args  # type: ignore[method-assign]
    codegen.CPUCodeLibrary._finalize_final_module = lazy_finalize_final  # type: ignore[method-assign]
    if CALLEE_OPTIMISED_IN_CALLER:
        lazy_optimise_final.__wrapped__ = optimise_final  # type: ignore[attr-defined]
        codegen.CPUCodeLibrary._optimize_final_module = lazy_optimise_final  # type: ignore[method-assign]
        if CALLEE_OPTIMISED_ONCE:
            tracked_finalize.__wrapped__ = finalize_library  # type: ignore[attr-defined]
            once_for_linking.__wrapped__ = for_linking  # type: ignore[attr-defined]
            codegen.CPUCodeLibrary.finalize = tracked_finalize  # type: ignore[method-assign]
            codegen.CPUCodeLibrary._get_module_for_linking = once_for_linking  # type: ignore[method-assign]
    cpu.CPUContext.get_executable = lazy_executable  # type: ignore[method-assign]
    caching.Cache._save_overload = lazy_save  # type: ignore[method-assign]
    return True


#: SHA-256 (first 16 hex digits) of the source of numba's ``numba.core.ssa`` module that :func:`quiet_ssa_debug`
#: rewrites (numba 0.68); any other source is left as it is.
SSA_SOURCE = "d20accd92757fef6"


class _NoDebugCalls:
    """AST transformer: every ``_logger.debug(...)`` statement becomes ``pass`` (the other lines keep their numbers)."""

    @staticmethod
    def rewrite(tree: Any) -> int:
        import ast

        count = 0
        for node in ast.walk(tree):
            for field in ("body", "orelse", "finalbody"):
                stmts = getattr(node, field, None)
                if not isinstance(stmts, list):
                    continue
                for i, stmt in enumerate(stmts):
                    call = getattr(stmt, "value", None) if isinstance(stmt, ast.Expr) else None
                    func = getattr(call, "func", None)
                    if (isinstance(call, ast.Call) and isinstance(func, ast.Attribute) and func.attr == "debug"
                            and isinstance(func.value, ast.Name) and func.value.id == "_logger"):
                        stmts[i] = ast.copy_location(ast.Pass(), stmt)
                        count += 1
        return count


def quiet_ssa_debug() -> bool:
    """Have numba's SSA reconstruction (``numba.core.ssa``) run without its ``_logger.debug`` calls.

    ``reconstruct_ssa`` runs, for every variable assigned more than once in a function's IR, a pass over every
    statement of every block, and logs each statement, each replacement and each definition looked up through
    ``_logger.debug``: about 1.1 million calls of ``Logger.debug`` (each checking whether DEBUG is enabled, which it
    is not) on a cold run of the README's first command, a few tenths of a second of CPU (docs/speed.md, passes cold34
    and cold35). Here the functions of numba's ``ssa`` module get their own code compiled from numba's source with
    each ``_logger.debug(...)`` statement replaced by ``pass`` (the arguments have no side effects: names, subscripts of
    the pass's dicts and ``_lazy_pformat`` wrappers); every function object stays the same, so every reference to it
    (imports by other modules, class attributes) runs the new code. The IR is the same statements; only the log lines
    are not written. Done only when the module's source is the one checked here (:data:`SSA_SOURCE`) and its logger
    does not log DEBUG at install; called by :func:`lean_numba_compile` at the first compile, so it touches only the
    command line's processes. Returns whether it changed numba (not when called again)."""
    import ast
    import inspect
    import logging

    try:
        from numba.core import ssa
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    if getattr(ssa, "_dynslam2d_quiet", False) or ssa._logger.isEnabledFor(logging.DEBUG):
        return False
    try:
        source = inspect.getsource(ssa)
    except (OSError, TypeError):
        return False
    if hashlib.sha256(source.encode()).hexdigest()[:16] != SSA_SOURCE:
        return False
    tree = ast.parse(source, ssa.__file__)
    if not _NoDebugCalls.rewrite(tree):
        return False
    codes: dict[str, Any] = {}
    pending = [compile(tree, ssa.__file__, "exec")]
    while pending:
        code = pending.pop()
        for const in code.co_consts:
            if inspect.iscode(const):
                codes[const.co_qualname] = const
                pending.append(const)
    funcs: list[Any] = []
    for value in vars(ssa).values():
        if inspect.isfunction(value) and value.__module__ == ssa.__name__:
            funcs.append(value)
        elif inspect.isclass(value) and value.__module__ == ssa.__name__:
            funcs.extend(v for v in vars(value).values() if inspect.isfunction(v))
    swaps = []
    for func in funcs:
        new = codes.get(func.__code__.co_qualname)
        if new is None or new.co_freevars != func.__code__.co_freevars:
            return False
        if new.co_code != func.__code__.co_code or new.co_names != func.__code__.co_names:
            swaps.append((func, new))
    for func, new in swaps:
        func.__code__ = new
    ssa._dynslam2d_quiet = True
    return True


#: CPython's default thresholds of its cyclic garbage collector (``gc.get_threshold()``).
DEFAULT_GC_THRESHOLD = (700, 10, 10)

#: The collector's thresholds in a process that compiles the kernels (:func:`lean_compile_gc`).
COMPILE_GC_THRESHOLD = (20000, 100, 10)


def lean_compile_gc() -> bool:
    """Have Python's cyclic garbage collector run less often in a process that compiles the kernels.

    numba's typing and lowering allocate millions of objects, most of them short-lived, and keep many alive
    (types, IR, compiled libraries). With CPython's default thresholds a cold run of the README's first command
    (one core, background compile off) makes about 3 900 collections, 25 of them full ones that walk every
    object alive (0.2–0.3 s each): 6–7 s of CPU, about a sixth of its compile. Collecting generation 0 every
    20 000 allocations instead of every 700 lets most of numba's temporaries die before a collection would
    promote them, so the old generation grows slowly: about 120–200 collections, one of them full, ≈ 2.5 s, for
    about 20 MB more peak memory while compiling (494–500 MB against 475 MB; docs/speed.md, "Cold compile pass 4").
    Most of what then remained were the generation-1 collections (one per 10 young ones, ≈ 20 of 80–90 ms each,
    walking every object that survived a young collection): one per 100 young ones instead (and so no full one)
    takes 1.6 s of collector CPU instead of 2.7–3.2 s, for ≈ 100 MB more peak memory in a one-process compile
    (563 MB against 457 MB; docs/speed.md, "pass cold24"). Nothing a kernel computes changes.

    The command line calls this when the kernel cache is cold (a warm run keeps CPython's defaults), and so does
    its background compile; a library user's process is left as it is. Leaves thresholds the program has
    changed (anything but CPython's defaults). Returns whether it set them."""
    import gc

    if gc.get_threshold() != DEFAULT_GC_THRESHOLD:
        return False
    gc.set_threshold(*COMPILE_GC_THRESHOLD)
    return True


#: Scans in a row that compiled nothing (and waited for no compile) after which a cold run's collector comes back
#: (:class:`CompileCollectorPause`).
COMPILE_QUIET_SCANS = 3


class CompileCollectorPause:
    """Python's cyclic garbage collector off in a cold command-line run while its kernels compile, back on once the
    run's scans compile nothing any more (issue 13 item 2; docs/speed.md, pass cmp143).

    numba's typing and lowering keep many objects alive (types, IR, compiled libraries): even at the compile's
    thresholds (:func:`lean_compile_gc`) every young collection walks the new ones again and every older one all
    that survived, ≈ 1.3 s of CPU in the run process's cold compile, on its critical path (pass cmp142). With the
    collector off nothing is walked; the garbage in reference cycles waits. :meth:`resume` then makes one full
    collection (that garbage freed), moves every object still alive into the permanent generation
    (``gc.freeze()``: numba's compiled kernels and types live as long as the process and are never walked again,
    neither by the scan loop's collections nor by the full ones a run's figures make, ``viz.figure.save_png``) and
    switches the collector on with the thresholds it had: the scan loop's collections then are those of a run
    that never paused (:func:`dynslam2d.collector.scan_loop_gc`), over fewer objects.

    Used as a run observer (:class:`dynslam2d.pipeline.RunObserver`): :meth:`on_scan` resumes after
    ``quiet_scans`` scans in a row in which this process neither compiled nor waited for the background compile
    (:func:`compile_seconds` unchanged); :meth:`on_finish` at the latest, and the command line calls
    :meth:`resume` again when the run ends or fails (it does nothing the second time). A kernel first needed
    later (a loop closure's) compiles with the collector on, as before. Nothing a kernel computes changes."""

    def __init__(self, quiet_scans: int = COMPILE_QUIET_SCANS) -> None:
        self.quiet_scans = quiet_scans
        self.paused = False
        self.resumed_after: int | None = None  #: scans done when the collector came back (None: not yet)
        self._compile_s = 0.0
        self._quiet = 0
        self._scans = 0

    def pause(self) -> bool:
        """Switch the collector off (when it is on). Returns whether it did."""
        import gc

        if self.paused or not gc.isenabled():
            return False
        self._compile_s = compile_seconds()
        gc.disable()
        self.paused = True
        return True

    def resume(self) -> None:
        """One full collection, everything alive into the permanent generation, the collector on again (only after
        :meth:`pause`; once)."""
        import gc

        if not self.paused:
            return
        self.paused = False
        self.resumed_after = self._scans
        gc.collect()
        gc.freeze()
        gc.enable()

    def on_scan(self, scan: object, step: object, pipeline: object) -> None:
        if not self.paused:
            return
        self._scans += 1
        now = compile_seconds()
        self._quiet = 0 if now != self._compile_s else self._quiet + 1
        self._compile_s = now
        if self._quiet >= self.quiet_scans:
            self.resume()

    def on_finish(self, result: object, pipeline: object) -> None:
        self.resume()


#: SciPy's BLAS extension module, which numba imports to check for BLAS (numba.np.arraymath).
BLAS_MODULE = "scipy.linalg.cython_blas"


def load_blas_alone() -> bool:
    """Load SciPy's BLAS extension ``scipy.linalg.cython_blas`` on its own, before numba needs it.

    numba checks for BLAS when it loads or compiles its first kernel (``numba.np.arraymath`` imports
    ``scipy.linalg.cython_blas``), and importing a submodule first imports its package: the whole of
    ``scipy.linalg``, about 17 MiB and 0.2 s of CPU that a run never uses (no kernel calls BLAS; the
    pose graph's sparse solver imports what it needs when loop closure solves a graph). Loaded from its
    file and registered under its name, the extension is what numba's import finds, and ``scipy.linalg``
    stays unimported (docs/speed.md, "Memory and compile, fourth pass"). The command line calls this
    first: it owns the process; a library user's process is left as it is. One difference for other code
    in the same process: when it later imports ``scipy.linalg``, the package has no ``cython_blas``
    attribute until that code imports the submodule by name (``from scipy.linalg import cython_blas``
    works either way). Returns whether it loaded the module; does nothing once numba's check or
    ``scipy.linalg`` ran, and on any failure (numba then imports it as usual)."""
    if BLAS_MODULE in sys.modules or "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
        return False
    try:
        import importlib.machinery
        import importlib.util

        spec = importlib.util.find_spec("scipy")  # (a top-level find_spec imports nothing)
        for folder in (spec.submodule_search_locations or []) if spec is not None else []:
            for suffix in importlib.machinery.EXTENSION_SUFFIXES:
                path = Path(folder) / "linalg" / f"cython_blas{suffix}"
                if path.is_file():
                    ext = importlib.util.spec_from_file_location(BLAS_MODULE, path)
                    if ext is None or ext.loader is None:
                        return False
                    mod = importlib.util.module_from_spec(ext)
                    ext.loader.exec_module(mod)
                    sys.modules[BLAS_MODULE] = mod
                    return True
    except Exception:  # noqa: BLE001 - an optimisation only: numba imports the package as usual
        sys.modules.pop(BLAS_MODULE, None)
        return False
    return False


class _CompileClock:
    """Total wall time numba has spent compiling in this process, s: one listener on numba's
    "numba:compile" event (cache misses only; a load from the cache is no compile), installed on first
    use; nested compiles (a kernel compiling the kernels it calls) count once."""

    def __init__(self) -> None:
        self.total = 0.0
        self._depth = 0
        self._t0 = 0.0
        self._installed = False

    def install(self) -> None:
        if self._installed:
            return
        try:
            from numba.core import event
        except ImportError:  # pragma: no cover - numba is a dependency
            return
        clock = self

        class _Listener(event.Listener):
            def on_start(self, ev: object) -> None:
                if clock._depth == 0:
                    clock._t0 = time.perf_counter()
                clock._depth += 1

            def on_end(self, ev: object) -> None:
                clock._depth -= 1
                if clock._depth == 0:
                    clock.total += time.perf_counter() - clock._t0

        event.register("numba:compile", _Listener())
        self._installed = True


_CLOCK = _CompileClock()


def compile_seconds() -> float:
    """Seconds numba has spent compiling kernels in this process so far, plus the time spent waiting for a
    kernel the background compile was compiling (:class:`dynslam2d.jitwarm.CompileBoard`; start measuring
    with a first call; the difference of two calls is the compile time in between)."""
    _CLOCK.install()
    return _CLOCK.total


def add_compile_wait(seconds: float) -> None:
    """Count ``seconds`` spent waiting for another process's compile of a kernel as compile time (outside
    a compile of this process's own; inside one it is already counted)."""
    if _CLOCK._depth == 0:
        _CLOCK.total += seconds


@dataclass(frozen=True)
class KernelCacheState:
    """Cached kernels among the loaded ones (module-level numba dispatchers of dynslam2d)."""

    total: int
    cached: int

    @property
    def missing(self) -> int:
        return self.total - self.cached

    @property
    def cold(self) -> bool:
        """True when at least a quarter of the kernels must be compiled: a first run, or one
        after an update. A few kernels that no run has needed yet do not count as cold."""
        return self.total > 0 and 4 * self.missing >= self.total


def _has_valid_index(dispatcher: object) -> bool | None:
    """Whether numba's cache index of ``dispatcher`` exists and matches its source file
    (numba drops an index whose source stamp differs); None if this cannot be told."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    load = getattr(cache_file, "_load_index", None)  # numba internals: fail soft if they change
    if load is None:
        return None
    try:
        return bool(load())
    except Exception:
        return None


def index_holds(name: str) -> bool | None:
    """Whether numba's cache holds compiled code of kernel ``name`` (``module.qualname`` of a module-level kernel of
    this package), told from its index file without importing the kernel's module: the answer of
    :func:`_has_valid_index` for its dispatcher (an index written by this numba version for the kernel's source as it
    is now, holding at least one signature).

    numba (``UserProvidedCacheLocator``, ``CacheImpl``, ``IndexDataCacheFile``) keeps the index of a function of file
    ``F`` in ``NUMBA_CACHE_DIR/<F's folder name>_<SHA-1 of F's folder>/<F's stem>.<qualname>-<first line>.pyXY.nbi``,
    starting with the numba version and then the source stamp and the signatures. The first line of the function is
    not known without its module, so every index of the name is read: one of another first line has another
    source's stamp. None when this cannot be told here: the cache is not in ``NUMBA_CACHE_DIR`` (numba's in-tree or
    user-wide folders, or other locator classes), ``name`` is not of this package, or numba's internals differ. Used
    by the background compile (:mod:`dynslam2d.jitwarm`), which would otherwise import every kernel module to see
    what the run has compiled."""
    import glob
    import pickle

    try:
        import numba
        from numba.core import caching, config
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    module, _, qualname = name.rpartition(".")
    package, _, rest = module.partition(".")
    if package != __name__.partition(".")[0] or not rest or not config.CACHE_DIR or config.CACHE_LOCATOR_CLASSES:
        return None
    loaded = sys.modules.get(module)
    source = getattr(loaded, "__file__", None) or os.path.join(os.path.dirname(__file__), *rest.split(".")) + ".py"
    try:
        folder = os.path.join(config.CACHE_DIR, caching._CacheLocator.get_suitable_cache_subpath(source))
        st = os.stat(source)
        stamp = caching._hash_source_file(source, st.st_mtime, st.st_size)
        stem = os.path.splitext(os.path.basename(source))[0]
        base = f"{stem}.{qualname}".replace("<", "").replace(">", "")
        tail = f".py{sys.version_info[0]}{sys.version_info[1]}{getattr(sys, 'abiflags', '')}.nbi"
        for path in glob.glob(os.path.join(glob.escape(folder), glob.escape(base + "-") + "*" + glob.escape(tail))):
            if not path[len(folder) + len(base) + 2:-len(tail)].isdigit():
                continue
            try:
                with open(path, "rb") as f:
                    if pickle.load(f) != numba.__version__:
                        continue
                    data = f.read()
            except FileNotFoundError:
                continue
            found, overloads = pickle.loads(data)
            if found == stamp and overloads:
                return True
        return False
    except Exception:  # noqa: BLE001 - numba internals changed: the caller imports the module and asks numba
        return None


def kernel_cache_state(prefix: str = "dynslam2d", needed: frozenset[str] | None = None) -> KernelCacheState:
    """Count the module-level numba kernels of the loaded ``prefix`` modules that a run needs and those whose
    compiled code numba's cache holds (import the pipeline first to load them all). ``needed``: the kernels'
    "module.qualname"; by default those of :mod:`dynslam2d.jitmanifest` (what a run of ``dynslam2d run``
    compiles), every loaded kernel when it is empty. Kernels no run calls from Python (a reference kept for the
    tests, a callee compiled inside its caller) would otherwise count as missing after every run and make a warm
    cache look cold."""
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:  # pragma: no cover - numba is a dependency
        return KernelCacheState(0, 0)
    if needed is None:
        from dynslam2d.jitmanifest import KERNELS

        needed = frozenset(k for k, _ in KERNELS)
    total = cached = 0
    for name, module in list(sys.modules.items()):
        if module is None or not (name == prefix or name.startswith(prefix + ".")):
            continue
        for obj in list(vars(module).values()):
            if isinstance(obj, CPUDispatcher) and getattr(obj, "__module__", None) == name:
                if needed and f"{name}.{obj.py_func.__qualname__}" not in needed:
                    continue
                state = _has_valid_index(obj)
                if state is None:
                    continue
                total += 1
                cached += state
    return KernelCacheState(total, cached)
