"""Four float64 lanes as one numba value (LLVM ``<4 x double>``) and the lane-wise operations the shape fit needs.

numba's compiler does not turn four independent scalar chains into vector instructions by itself (neither its loop
nor its SLP vectoriser did for the rectangle search, docs/speed.md pass det39), so a kernel that runs the same
arithmetic for four values at once (four candidate angles of a rectangle fit) says so with these: ``vec4`` is a
value type whose LLVM type is ``<4 x double>``, and each function below is one LLVM instruction (or a few) on it.

Every operation is the IEEE operation of the scalar code on each lane: ``vadd`` / ``vsub`` / ``vmul`` are ``fadd``,
``fsub``, ``fmul`` without fast-math flags (no contraction into FMA, as numba's scalar code), ``vneg`` is ``fneg``
(numba's unary minus of a float), ``vmin(acc, u)`` / ``vmax(acc, u)`` are numba's ``min(acc, u)`` / ``max(acc, u)``
of two floats (``select(u < acc, u, acc)``, ``select(u > acc, u, acc)``: the second argument only when the ordered
comparison holds), ``vabs`` is ``fabs`` (numba's ``abs`` of a float), so a kernel written with them gives the bits of
the same kernel written per lane. ``vall`` tells whether every lane of a 0.0 / 1.0 flag vector is set (one branch for
four lanes).
"""

from __future__ import annotations

from dynslam2d.jitbox import numba_import  # numba's names, or inert stand-ins when the AOT kernels replace numba

ir, types, cgutils, intrinsic, models, register_model = numba_import(
    "llvmlite.ir", "numba.types", "numba.core.cgutils", "numba.extending.intrinsic", "numba.extending.models",
    "numba.extending.register_model")

_VT = ir.VectorType(ir.DoubleType(), 4)
_I32 = ir.IntType(32)


class Vec4Type(types.Type):
    """numba type of four float64 lanes."""

    def __init__(self) -> None:
        super().__init__(name="vec4")


vec4 = Vec4Type()


@register_model(Vec4Type)
class _Vec4Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type) -> None:  # noqa: ANN001 - numba's model signature
        super().__init__(dmm, fe_type, _VT)


@intrinsic
def vsplat(typingctx, x):  # noqa: ANN001, ANN201 - numba intrinsic
    """The float ``x`` in all four lanes."""
    def codegen(context, builder, sig, args):
        v = ir.Constant(_VT, ir.Undefined)
        for k in range(4):
            v = builder.insert_element(v, args[0], ir.Constant(_I32, k))
        return v
    return vec4(types.float64), codegen


@intrinsic
def vset(typingctx, a, b, c, d):  # noqa: ANN001, ANN201 - numba intrinsic
    """The floats ``a``, ``b``, ``c``, ``d`` as lanes 0–3."""
    def codegen(context, builder, sig, args):
        v = ir.Constant(_VT, ir.Undefined)
        for k in range(4):
            v = builder.insert_element(v, args[k], ir.Constant(_I32, k))
        return v
    return vec4(types.float64, types.float64, types.float64, types.float64), codegen


@intrinsic
def vget(typingctx, v, k):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane ``k`` (0–3) of ``v``."""
    def codegen(context, builder, sig, args):
        return builder.extract_element(args[0], builder.trunc(args[1], _I32))
    return types.float64(vec4, types.int64), codegen


def _binop(name: str):  # noqa: ANN202
    @intrinsic
    def op(typingctx, a, b):  # noqa: ANN001, ANN201 - numba intrinsic
        def codegen(context, builder, sig, args):
            return getattr(builder, name)(args[0], args[1])
        return vec4(vec4, vec4), codegen
    return op


vadd = _binop("fadd")
vadd.__doc__ = "Lane-wise a + b."
vsub = _binop("fsub")
vsub.__doc__ = "Lane-wise a − b."
vmul = _binop("fmul")
vmul.__doc__ = "Lane-wise a · b."
vdiv = _binop("fdiv")
vdiv.__doc__ = "Lane-wise a / b."


@intrinsic
def vneg(typingctx, a):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise −a (the sign bit flipped, as numba's unary minus of a float)."""
    def codegen(context, builder, sig, args):
        return builder.fneg(args[0])
    return vec4(vec4), codegen


@intrinsic
def vabs(typingctx, a):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise |a| (LLVM's ``fabs``: the sign bit cleared, as numba's ``abs`` of a float)."""
    def codegen(context, builder, sig, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_VT, [_VT]), "llvm.fabs.v4f64")
        return builder.call(fn, [args[0]])
    return vec4(vec4), codegen


@intrinsic
def vall(typingctx, m):  # noqa: ANN001, ANN201 - numba intrinsic
    """True when no lane of ``m`` is 0.0 (``m``: lanes of 0.0 / 1.0 flags, as :func:`vwhere` reads them)."""
    def codegen(context, builder, sig, args):
        zero = ir.Constant(_VT, [0.0, 0.0, 0.0, 0.0])
        bits = builder.bitcast(builder.fcmp_unordered("!=", args[0], zero), ir.IntType(4))
        return builder.icmp_unsigned("==", bits, ir.Constant(ir.IntType(4), 15))
    return types.boolean(vec4), codegen


@intrinsic
def vmin(typingctx, acc, u):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise numba ``min(acc, u)``: u where u < acc (ordered), else acc."""
    def codegen(context, builder, sig, args):
        return builder.select(builder.fcmp_ordered("<", args[1], args[0]), args[1], args[0])
    return vec4(vec4, vec4), codegen


@intrinsic
def vmax(typingctx, acc, u):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise numba ``max(acc, u)``: u where u > acc (ordered), else acc."""
    def codegen(context, builder, sig, args):
        return builder.select(builder.fcmp_ordered(">", args[1], args[0]), args[1], args[0])
    return vec4(vec4, vec4), codegen


@intrinsic
def vwhere_lt(typingctx, x, y, a, b):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise ``a if x < y else b`` (ordered comparison: b where either is NaN)."""
    def codegen(context, builder, sig, args):
        return builder.select(builder.fcmp_ordered("<", args[0], args[1]), args[2], args[3])
    return vec4(vec4, vec4, vec4, vec4), codegen


@intrinsic
def vwhere(typingctx, m, a, b):  # noqa: ANN001, ANN201 - numba intrinsic
    """Lane-wise ``a if m != 0 else b`` (``m``: lanes of 0.0 / 1.0 flags, :func:`vset`)."""
    def codegen(context, builder, sig, args):
        zero = ir.Constant(_VT, [0.0, 0.0, 0.0, 0.0])
        return builder.select(builder.fcmp_unordered("!=", args[0], zero), args[1], args[2])
    return vec4(vec4, vec4, vec4), codegen


@intrinsic
def vload(typingctx, arr, i):  # noqa: ANN001, ANN201 - numba intrinsic
    """``arr[i:i + 4]`` of a C-contiguous 1-D float64 array as lanes (no bounds check: i + 4 ≤ len(arr))."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.ndim == 1):
        return None

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        p = builder.bitcast(builder.gep(a.data, [args[1]]), _VT.as_pointer())
        return builder.load(p, align=8)
    return vec4(arr, types.int64), codegen


@intrinsic
def vstore(typingctx, arr, i, v):  # noqa: ANN001, ANN201 - numba intrinsic
    """``arr[i:i + 4] = v`` for a C-contiguous 1-D float64 array (no bounds check: i + 4 ≤ len(arr))."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.ndim == 1):
        return None

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        p = builder.bitcast(builder.gep(a.data, [args[1]]), _VT.as_pointer())
        builder.store(args[2], p, align=8)
        return context.get_dummy_value()
    return types.none(arr, types.int64, vec4), codegen
