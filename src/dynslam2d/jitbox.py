"""numba's boxing of returned arrays without a per-array unpickle, one LLVM optimisation of the kernels instead of
three, and ``njit`` for the kernel modules.

numba (0.54 and later, ``numba.core.boxing.box_array``) hands every NumPy array a compiled function returns to
Python through ``PythonAPI.nrt_adapt_ndarray_to_python``, which embeds the array's Python class (``np.ndarray``)
as pickled bytes and calls ``numba.core.serialize._numba_unpickle`` at run time, once per returned array: two
bytes objects, an int and a Python call to a memo lookup, 0.2–0.5 µs (docs/speed.md, pass unpickle). The
pipeline's kernels return about 86 arrays per scan. :func:`box_arrays_from_env` registers a boxer that reads the
class from the compiled function's environment constants instead (a list look-up, as numba already does for the
array's dtype): the same array object, no Python call. It changes only how kernels compiled after it box their
returned arrays; the kernel modules import ``njit`` from here so that it is in place before any kernel compiles,
and the numba cache keys entries by the source file, so those modules' kernels are compiled again with it.

:func:`one_llvm_optimisation` leaves of numba's three LLVM optimisations of a kernel's code (the function pipeline
on each IR module as it is added, a cheap and the full module pipeline on the linked library) the full module
pipeline only: 5–10 % less cold compile CPU, the same results (docs/speed.md, pass cold21). The kernels in
:data:`LOOPS_NOT_VECTORISED` go through that pipeline without LLVM's loop vectoriser, where it costs compile time
and buys no run time (pass cmp50).

:func:`float_bits`, :func:`float_from_bits` and :func:`word_at` reinterpret bits inside a kernel as NumPy's
``.view`` does, lowered in place: numba compiles its ``.view`` of an array once per (array type, dtype) as a
helper of its own with a compatibility check (≈ 0.1 s of cold compile CPU each; docs/speed.md, pass cold28).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any

from dynslam2d import jitaot as _jitaot
from dynslam2d.errors import DynSlamError


def inert_intrinsic(*args: Any, **kwargs: Any) -> Any:
    """numba's ``intrinsic`` when the AOT module replaces numba: the intrinsic lives in the compiled kernels only;
    the name holds a function that raises when called from Python."""
    def stand_in(fn: Callable[..., Any]) -> Callable[..., Any]:
        def intrinsic_stand_in(*a: Any, **k: Any) -> Any:
            raise DynSlamError(f"{fn.__module__}.{fn.__qualname__} is a numba intrinsic: only kernels call it")

        intrinsic_stand_in.__name__ = fn.__name__
        intrinsic_stand_in.__qualname__ = fn.__qualname__
        intrinsic_stand_in.__module__ = fn.__module__
        intrinsic_stand_in.aot_stand_in = True  # type: ignore[attr-defined]
        return intrinsic_stand_in

    if len(args) == 1 and callable(args[0]) and not kwargs:
        return stand_in(args[0])
    return stand_in


#: The AOT-compiled kernels this process uses instead of numba (:mod:`dynslam2d.jitaot`), or None: numba's JIT.
AOT = _jitaot.table()

if AOT is None:
    from numba import njit  # noqa: F401 - re-exported: the kernel modules' njit, with the boxer below in place
    from numba.core import boxing, pythonapi, types
    from numba.extending import intrinsic
else:  # no numba in this process: the kernels are the AOT module's, numba's names inert stand-ins
    njit = AOT.decorator
    boxing = pythonapi = types = _jitaot.INERT
    intrinsic = inert_intrinsic
    from dynslam2d import jitcache as _jitcache

    _jitcache._CLOCK._installed = True  # nothing compiles: compile_seconds() stays 0 without importing numba


def numba_import(*names: str) -> Any:
    """The numba / llvmlite objects named (``"numba.core.cgutils"``, ``"numba.extending.intrinsic"``, a module or
    a module's attribute) for a kernel module's import lines: imported as ``from ... import ...`` would, or, when
    the AOT module replaces numba (:data:`AOT`), inert stand-ins (``intrinsic``: one whose intrinsics raise when
    called from Python) and nothing imported. One name gives the object, several a tuple."""
    out = []
    for name in names:
        parent, _, attr = name.rpartition(".")
        if AOT is not None:
            _jitaot.note_module(sys._getframe(1).f_globals.get("__name__", ""))
            out.append(inert_intrinsic if attr == "intrinsic" else _jitaot.INERT)
            continue
        module = importlib.import_module(parent)
        out.append(getattr(module, attr) if hasattr(module, attr) else importlib.import_module(name))
    return out[0] if len(out) == 1 else tuple(out)


def _box_array_from_env(typ: Any, val: Any, c: Any) -> Any:
    """numba's ``box_array`` (NRT path), with the array's Python class read from the environment's constants.

    ``NRT_adapt_ndarray_to_python_acqref`` borrows the class (``PyArray_NewFromDescr`` does not steal it), and
    ``read_const`` returns a borrowed reference, as for the dtype on the line before."""
    if not c.context.enable_nrt:
        return boxing.box_array(typ, val, c)
    from llvmlite import ir
    from numba.core import cgutils
    from numba.np import numpy_support

    np_dtype = numpy_support.as_dtype(typ.dtype)
    dtypeptr = c.env_manager.read_const(c.env_manager.add_const(np_dtype))
    pytype = c.env_manager.read_const(c.env_manager.add_const(typ.box_type))
    api = c.pyapi
    intty = ir.IntType(32)
    fnty = ir.FunctionType(api.pyobj, [api.voidptr, api.pyobj, intty, intty, api.pyobj])
    # numba also marks the first argument as not captured; that hint's spelling differs between llvmlite
    # versions ("nocapture", "captures(none)"), and the call is the same without it.
    fn = api._get_function(fnty, name="NRT_adapt_ndarray_to_python_acqref")
    ndim = c.context.get_constant(types.int32, typ.ndim)
    writable = c.context.get_constant(types.int32, int(typ.mutable))
    aryptr = cgutils.alloca_once_value(c.builder, val)
    newary = c.builder.call(fn, [c.builder.bitcast(aryptr, api.voidptr), pytype, ndim, writable, dtypeptr])
    c.context.nrt.decref(c.builder, typ, val)  # NRT_adapt... acquired its own reference (numba's box_array)
    return newary


def box_arrays_from_env() -> bool:
    """Register :func:`_box_array_from_env` as numba's boxer of arrays (``types.Array``) in this process.

    Returns whether it did; does nothing when called again or when numba's registry differs."""
    registry = getattr(pythonapi, "_boxers", None)
    functions = getattr(registry, "functions", None)
    if not isinstance(functions, dict) or functions.get(types.Array) is not boxing.box_array:
        return False
    functions[types.Array] = _box_array_from_env
    return True


#: Kernels (``module.qualname``) whose module pipeline runs without LLVM's loop vectoriser (its interleaving of scalar
#: loops left on), each with the SHA-256 (16 hex digits) of its Python source as measured: a kernel whose source is
#: another one (edited since) gets numba's pipeline again until its stage is measured anew and the hash renewed
#: (``tests/test_jitbox_vectoriser.py`` says which). ``detect_rows`` (with ``measure_batch``, which it optimises first
#: for its three callers): ≈ 0.2–0.55 s of cold compile CPU (pass cmp50); ``record_cells``, ``assign_groups``: ≈ 0.1 s
#: each (pass cmp51); ``fit_cluster_rows``: ≈ 0.02 s (pass cmp60); the track stage's time per scan unchanged.
#: ``vacated_scan_kernel`` no longer (listed from pass cmp60 to pass vac77: with the inverse seen-through form the
#: vectoriser pays on negative_2, ×1.06 of the previous kernel against ×1.23 without). ``detect_scan``, which links
#: ``detect_rows``, ``fit_cluster_rows`` and the segmentation and optimises them in its own pipeline (pass trk72), so
#: that those two keep theirs. Not ``association_gates``, ``update_pairs`` (the track stage's median ×1.02–1.03 without
#: it) nor the body filter's ``_drop_body`` (+10–25 µs a sim:paper scan), nor the matcher's and the loop closer's
#: kernels, whose loops need it (pass cmp50; the map update's below since pass cmp148), nor kernels whose optimised
#: code holds no vector loop (listing them changes nothing). The vectoriser keeps the order of floating-point
#: operations without ``fastmath``, so the numbers are the same either way. ``associate_update`` (pass cmp144: its 14
#: vector loops, the pairs' gathers and the gates' rows over a few tracks, ≈ 7 % of its machine code), whose big
#: callees LLVM keeps out of line already.
#: The map update's ``integrate_levels`` (pass cmp148: its 2 vector loops, with the ray kernel it links; ≈ 0.05–0.08 s
#: of LLVM CPU, the map update per scan unchanged). Not the loop closer's correlative search (``_search_table``,
#: ``branch_and_bound``, ``_search_cells``: MIT CSAIL's front-end search ×1.12–1.27 without it, pass cmp148), nor
#: the clean-up's ``_add_scan`` (≈ 0.02–0.04 s of LLVM CPU for its 4 vector loops; the clean-up recorder ×2.2 a scan
#: without them, pass cmp148).
LOOPS_NOT_VECTORISED = {
    "dynslam2d.detect.kernels.detect_rows": "9e8f98ec441beb51",
    "dynslam2d.detect.kernels_assign.assign_groups": "231f863e608ec456",
    "dynslam2d.slam.ledgerkernels.record_cells": "c8c25345ff44f334",
    "dynslam2d.detect.shapes.fit_cluster_rows": "4df79f952e43f675",
    "dynslam2d.detect.segment.detect_scan": "5813f765c424848a",
    "dynslam2d.detect.kernels_assign.associate_update": "8bb27e16e01cd920",
    "dynslam2d.slam.raycast.integrate_levels": "007bbf5a2f274cfe",
}


def source_hash(func: Any) -> str:
    """SHA-256 (16 hex digits) of the Python source of ``func`` ("" when it has none)."""
    import hashlib
    import inspect

    try:
        source = inspect.getsource(func)
    except (OSError, TypeError):
        return ""
    return hashlib.sha256(source.encode()).hexdigest()[:16]


#: SHA-256 (16 hex digits) of numba's functions whose module pipeline :func:`_module_pipeline` builds, as checked;
#: any other numba source: numba's pipeline for every kernel.
PIPELINE_SOURCES = {
    "CPUCodegen._module_pass_manager": "3f01da96a94f708b",
    "CPUCodegen._pass_builder": "035dd9dd5f6dedc5",
    "create_pass_builder": "0386a7194196ad35",
}

#: Study knob (benchmarks only, with an empty ``NUMBA_CACHE_DIR``: numba's cache does not record the pipeline):
#: comma-separated kernel qualnames, or ``*`` for every kernel, compiled without the loop vectoriser too.
STUDY_ENV = "DYNSLAM2D_LOOPS_NOT_VECTORISED"


def _pipeline_sources_checked() -> bool:
    from numba.core import codegen, llvm_bindings

    found = {
        "CPUCodegen._module_pass_manager": codegen.CPUCodegen._module_pass_manager,
        "CPUCodegen._pass_builder": codegen.CPUCodegen._pass_builder,
        "create_pass_builder": llvm_bindings.create_pass_builder,
    }
    return all(source_hash(func) == PIPELINE_SOURCES.get(name) for name, func in found.items())


def _not_vectorised(kernel: str, func: Any) -> bool:
    """Whether the kernel ``kernel`` (``module.qualname``), the Python function ``func``, goes without the loop
    vectoriser: listed in :data:`LOOPS_NOT_VECTORISED` with its source's hash, or named by :data:`STUDY_ENV`."""
    import os

    listed = LOOPS_NOT_VECTORISED.get(kernel)
    if listed and source_hash(func) == listed:
        return True
    study = {name.strip() for name in os.environ.get(STUDY_ENV, "").split(",") if name.strip()}
    return "*" in study or kernel.rsplit(".", 1)[-1] in study


def _module_pipeline(library: Any, kernel: str, checked: bool, func: Any = None) -> Any:
    """numba's full module pipeline (``CPUCodegen._module_pass_manager()``) for ``library``, the code of the kernel
    ``kernel`` (``module.qualname``, "" for a library of another function; ``func`` its Python function); for a
    kernel :func:`_not_vectorised` (and numba's sources as ``checked``) the same pipeline with LLVM's loop
    vectoriser off."""
    codegen = library._codegen
    if not (kernel and checked and _not_vectorised(kernel, func)):
        return codegen._module_pass_manager()
    import llvmlite.binding as ll
    from numba.core import config
    from numba.core.codegen import _parse_refprune_flags

    tuning = ll.create_pipeline_tuning_options()  # (numba's create_pass_builder, loop vectoriser off)
    tuning.speed_level = config.OPT
    tuning.slp_vectorization = config.SLP_VECTORIZE
    tuning.loop_vectorization = False
    builder = ll.create_pass_builder(codegen._tm, tuning)
    passes = builder.getModulePassManager()
    passes.add_refprune_pass(_parse_refprune_flags())  # (one_llvm_optimisation runs only with numba's refprune)
    return passes, builder


def one_llvm_optimisation() -> bool:
    """Have numba optimise a dynslam2d kernel's LLVM IR once, with its full module pipeline only; returns whether it
    installed that (False when called again or when numba's code library differs).

    numba (``CPUCodeLibrary.add_ir_module``) runs LLVM's function pipeline at ``NUMBA_OPT`` on every function
    of each IR module it adds to a library (the kernel's own code, its Python wrapper, the subroutines it
    lowers), links the modules and the callees' optimised modules, then (``_optimize_final_module``) runs a
    "cheap" module pipeline (inlining and a few clean-ups, so that numba's reference-count pruning pass sees
    the operations in one function) and the full module pipeline at the same level, which runs the function
    pipeline on every function again after inlining and ends with the same pruning pass. The first two are
    4.5–5 s of a cold run's 15–18 s of LLVM CPU and the full pipeline takes ≈ 1.5 s more without them. Only
    compiles inside a dynslam2d kernel's (numba's ``numba:compile`` event of a dispatcher of this package on
    the stack: the kernel, its callees, numba's helpers it compiles) skip them, and only with numba's pruning
    pass on (``NUMBA_LLVM_REFPRUNE_PASS``, its default), so a kernel's code does not depend on which process,
    or in which order, compiled it; any other numba function compiled in the process is left as numba does
    it. Installed when this module is imported, i.e. by every process that compiles a kernel (the run, its
    background compile, tests, a library user): numba's cache does not record how an entry was optimised,
    so no process may cache a kernel optimised another way. No pipeline allows floating-point reassociation
    or contraction (no ``fastmath``), so the kernels compute the same numbers (``bench_digest.py``)."""
    from numba.core import codegen, config, event

    library = codegen.CPUCodeLibrary
    optimise = getattr(library, "_optimize_functions", None)
    final = getattr(library, "_optimize_final_module", None)
    if optimise is None or final is None or getattr(optimise, "_dynslam2d_once", False):
        return False
    depth = [0]  # dynslam2d kernels being compiled in this process (nested: a kernel compiles its callees)
    checked = _pipeline_sources_checked()
    names: list[tuple[str, str, Any]] = [("", "", None)]  # (qualname, module.qualname, function) of the innermost
    # dynslam2d kernel being compiled

    class _Kernels(event.Listener):
        def on_start(self, ev: Any) -> None:
            func = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
            module = getattr(func, "__module__", "") or ""
            ours = module.startswith("dynslam2d.")
            depth.append(depth[-1] + ours)
            qualname = getattr(func, "__qualname__", "") if ours else ""
            names.append((qualname, f"{module}.{qualname}", func) if ours else names[-1])

        def on_end(self, ev: Any) -> None:
            if len(depth) > 1:
                depth.pop()
                names.pop()

    def optimise_once(self: Any, ll_module: Any) -> None:
        if depth[-1] > 0:
            ll_module.data_layout = self._codegen._data_layout  # (what numba's pass does first)
            return
        optimise(self, ll_module)

    def optimise_final_once(self: Any) -> None:
        if depth[-1] > 0 and config.LLVM_REFPRUNE_PASS:  # (numba's refprune pass ends the module pipeline too)
            qualname, kernel, func = names[-1]
            passes, builder = _module_pipeline(self, kernel if self.name == qualname else "", checked, func)
            passes.run(self._final_module, builder)
            return
        final(self)

    optimise_once._dynslam2d_once = True  # type: ignore[attr-defined]
    optimise_once.__wrapped__ = optimise  # type: ignore[attr-defined]
    optimise_final_once.__wrapped__ = final  # type: ignore[attr-defined]
    library._optimize_functions = optimise_once
    library._optimize_final_module = optimise_final_once
    event.register("numba:compile", _Kernels())
    return True


@intrinsic
def float_bits(typingctx: Any, x: Any) -> Any:
    """In a kernel: the int64 whose bits are those of the float64 ``x`` (``np.float64(x).view(np.int64)``; NaN
    payloads and signed zeros kept)."""
    if x != types.float64:
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        from llvmlite import ir

        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(x), codegen


@intrinsic
def float_from_bits(typingctx: Any, i: Any) -> Any:
    """In a kernel: the float64 whose bits are those of the int64 ``i`` (``np.int64(i).view(np.float64)``; the
    inverse of :func:`float_bits`)."""
    if i != types.int64:
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        from llvmlite import ir

        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(i), codegen


@intrinsic
def word_at(typingctx: Any, a: Any, i: Any) -> Any:
    """In a kernel: the uint64 made of the 8 bytes ``a[i:i + 8]`` of a C-contiguous 1-D uint8 array, in the
    machine's byte order (``a[i:i + 8].view(np.uint64)[0]``). No bounds check: ``0 <= i`` and ``i + 8 <=
    a.shape[0]`` are the caller's."""
    if not (isinstance(a, types.Array) and a.dtype == types.uint8 and a.ndim == 1 and a.layout == "C"
            and isinstance(i, types.Integer)):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        from llvmlite import ir

        ary = context.make_array(sig.args[0])(context, builder, args[0])
        at = context.cast(builder, args[1], sig.args[1], types.intp)
        ptr = builder.bitcast(builder.gep(ary.data, [at]), ir.IntType(64).as_pointer())
        return builder.load(ptr, align=1)

    return types.uint64(a, i), codegen


if AOT is None:
    box_arrays_from_env()
    one_llvm_optimisation()
