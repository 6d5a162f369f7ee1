"""numba's boxing of returned arrays without a per-array unpickle, one LLVM optimisation of the kernels instead of
two, and ``njit`` for the kernel modules.

numba (0.54 and later, ``numba.core.boxing.box_array``) hands every NumPy array a compiled function returns to
Python through ``PythonAPI.nrt_adapt_ndarray_to_python``, which embeds the array's Python class (``np.ndarray``)
as pickled bytes and calls ``numba.core.serialize._numba_unpickle`` at run time, once per returned array: two
bytes objects, an int and a Python call to a memo lookup, 0.2–0.5 µs (docs/speed.md, pass unpickle). The
pipeline's kernels return about 86 arrays per scan. :func:`box_arrays_from_env` registers a boxer that reads the
class from the compiled function's environment constants instead (a list look-up, as numba already does for the
array's dtype): the same array object, no Python call. It changes only how kernels compiled after it box their
returned arrays; the kernel modules import ``njit`` from here so that it is in place before any kernel compiles,
and the numba cache keys entries by the source file, so those modules' kernels are compiled again with it.

:func:`one_llvm_optimisation` drops the first of numba's two LLVM optimisations of a kernel's own code (the
per-function pipeline run on each IR module as it is added, before the module-level pipeline that numba runs on
the linked library anyway): about 5 % of a cold compile, the same results (docs/speed.md, pass cold21).
"""

from __future__ import annotations

from typing import Any

from numba import njit  # noqa: F401 - re-exported: the kernel modules' njit, with the boxer below in place
from numba.core import boxing, pythonapi, types


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


def one_llvm_optimisation() -> bool:
    """Have numba skip its per-function LLVM optimisation of the IR modules it adds while compiling a dynslam2d
    kernel; returns whether it did (False when called again or when numba's code library differs).

    numba (``CPUCodeLibrary.add_ir_module``) runs LLVM's function pipeline at ``NUMBA_OPT`` on every function
    of each IR module it adds to a library (the kernel's own code, its Python wrapper, the subroutines it
    lowers), links the modules and the callees' optimised modules, then optimises the whole library with the
    module pipeline at the same level (``_optimize_final_module``), which runs the function pipeline on
    every function again, after inlining. The first pass is about 4 s of a cold run's 15–18 s of LLVM CPU.
    Only compiles inside a dynslam2d kernel's (numba's ``numba:compile`` event of a dispatcher of this
    package on the stack: the kernel, its callees, numba's helpers it compiles) skip it, so a kernel's
    code does not depend on which process, or in which order, compiled it; any other numba function
    compiled in the process is left as numba does it. Installed when this module is imported, i.e. by
    every process that compiles a kernel (the run, its background compile, tests, a library user): numba's
    cache does not record how an entry was optimised, so no process may cache a kernel optimised another
    way. Neither pipeline allows floating-point reassociation or contraction (no ``fastmath``), so the
    kernels compute the same numbers (``bench_digest.py``)."""
    from numba.core import codegen, event

    library = codegen.CPUCodeLibrary
    optimise = getattr(library, "_optimize_functions", None)
    if optimise is None or getattr(optimise, "_dynslam2d_once", False):
        return False
    depth = [0]  # dynslam2d kernels being compiled in this process (nested: a kernel compiles its callees)

    class _Kernels(event.Listener):
        def on_start(self, ev: Any) -> None:
            func = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
            depth.append(depth[-1] + (getattr(func, "__module__", "") or "").startswith("dynslam2d."))

        def on_end(self, ev: Any) -> None:
            if len(depth) > 1:
                depth.pop()

    def optimise_once(self: Any, ll_module: Any) -> None:
        if depth[-1] > 0:
            ll_module.data_layout = self._codegen._data_layout  # (what numba's pass does first)
            return
        optimise(self, ll_module)

    optimise_once._dynslam2d_once = True  # type: ignore[attr-defined]
    optimise_once.__wrapped__ = optimise  # type: ignore[attr-defined]
    library._optimize_functions = optimise_once
    event.register("numba:compile", _Kernels())
    return True


box_arrays_from_env()
one_llvm_optimisation()
