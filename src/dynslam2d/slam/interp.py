"""Bilinear interpolation of occupancy probability and its gradient (Kohlbrecher et al., SSRR 2011 Eqs. 4–6;
hector_mapping OccGridMapUtil::interpMapValueWithDerivatives).

Coordinates are array map coordinates of one level (cells; array cell (col, row) is
centred at (col, row)). A point is in bounds when ``0 ≤ px ≤ W−2`` and ``0 ≤ py ≤ H−2``;
out-of-bounds points get value 0 and gradient 0, as in the reference.
"""

from __future__ import annotations

import numpy as np

from dynslam2d.jitbox import njit, numba_import  # numba's njit, arrays returned without a per-array unpickle

_lir, _nbtypes, _intrinsic = numba_import("llvmlite.ir", "numba.types", "numba.extending.intrinsic")

#: the bits of float32 0.5 (slam/grid.py's ``PROB_HALF_BITS``: a probability cache word is a float32's bits XOR them)
_HALF_BITS = 0x3F000000


@_intrinsic
def cell_prob(typingctx, word):
    """In a kernel: the float32 probability of a probability cache word (uint32; slam/grid.py ``encode_probs``):
    ``word`` XOR the bits of 0.5, bit cast to float32 (no conversion: every bit kept). Typed for uint32 only: a
    kernel given a float array fails to compile instead of converting its values."""
    if word != _nbtypes.uint32:
        return None
    sig = _nbtypes.float32(_nbtypes.uint32)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        i32 = _lir.IntType(32)
        return builder.bitcast(builder.xor(args[0], i32(_HALF_BITS)), _lir.FloatType())

    return sig, codegen


@_intrinsic
def cell_prob_pair(typingctx, flat, k):
    """In a kernel: ``(cell_prob(flat[k]), cell_prob(flat[k + 1]))`` of a probability cache's C-order words ``flat``
    (1-D uint32, C-contiguous; ``k`` an integer, ``k + 1`` inside the array: not checked) from ONE 8-byte load of the
    two adjacent words (a cell and its right neighbour: the bilinear interpolation's two cells of a row). The same
    words, decoded as :func:`cell_prob` decodes each (XOR the bits of 0.5, bit cast): the same float32 values."""
    if not (isinstance(flat, _nbtypes.Array) and flat.dtype == _nbtypes.uint32 and flat.ndim == 1
            and flat.layout == "C" and isinstance(k, _nbtypes.Integer)):
        return None
    sig = _nbtypes.UniTuple(_nbtypes.float32, 2)(flat, k)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        i32 = _lir.IntType(32)
        vec = _lir.VectorType(i32, 2)
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        idx = context.cast(builder, args[1], signature.args[1], _nbtypes.intp)
        ptr = builder.bitcast(builder.gep(ary.data, [idx]), vec.as_pointer())
        words = builder.load(ptr, align=4)  # (the array's words are 4-byte aligned; no 8-byte alignment assumed)
        half = _lir.Constant(vec, [i32(_HALF_BITS), i32(_HALF_BITS)])
        probs = builder.bitcast(builder.xor(words, half), _lir.VectorType(_lir.FloatType(), 2))
        out = [builder.extract_element(probs, i32(i)) for i in range(2)]
        return context.make_tuple(builder, signature.return_type, out)

    return sig, codegen


@njit(cache=True)
def interp_value_grad(prob, px, py, swapped):  # pragma: no cover - numba
    """(M, ∂M/∂x, ∂M/∂y, inside) at map point (px, py) of probability cache ``prob`` ((H, W) uint32 words,
    slam/grid.py ``encode_probs``), gradient per cell.

    ``swapped`` reproduces the reference's swapped weights (interpMapValueWithDerivatives,
    hector_slam issue #16);
    otherwise the exact derivative of the bilinear surface (paper Eqs. 5–6).
    """
    h, w = prob.shape
    if not (px >= 0.0 and py >= 0.0 and px <= w - 2 and py <= h - 2):  # also rejects NaN
        return 0.0, 0.0, 0.0, False
    x0 = int(px)
    y0 = int(py)
    fx = px - x0
    fy = py - y0
    p00 = cell_prob(prob[y0, x0])
    p10 = cell_prob(prob[y0, x0 + 1])
    p01 = cell_prob(prob[y0 + 1, x0])
    p11 = cell_prob(prob[y0 + 1, x0 + 1])
    m = (1.0 - fy) * ((1.0 - fx) * p00 + fx * p10) + fy * ((1.0 - fx) * p01 + fx * p11)
    if swapped:
        mx = (1.0 - fx) * (p10 - p00) + fx * (p11 - p01)
        my = (1.0 - fy) * (p01 - p00) + fy * (p11 - p10)
    else:
        mx = (1.0 - fy) * (p10 - p00) + fy * (p11 - p01)
        my = (1.0 - fx) * (p01 - p00) + fx * (p11 - p10)
    return m, mx, my, True


@njit(cache=True)
def interpolate(prob: np.ndarray, pts: np.ndarray, swapped: bool = False):  # pragma: no cover - numba
    """Vectorised :func:`interp_value_grad` over (n, 2) map points → three (n,) arrays."""
    n = pts.shape[0]
    m = np.empty(n)
    m[:] = 0.0
    gx = np.empty(n)
    gx[:] = 0.0
    gy = np.empty(n)
    gy[:] = 0.0
    for i in range(n):
        v, a, b, _ = interp_value_grad(prob, pts[i, 0], pts[i, 1], swapped)
        m[i] = v
        gx[i] = a
        gy[i] = b
    return m, gx, gy
