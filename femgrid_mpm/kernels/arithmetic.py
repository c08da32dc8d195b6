"""Fused multiply-add as an explicit operation: ``fused(a, b, c) = a * b + c`` rounded once.

The kernels are compiled with ``fastmath=False``: the compiler may not
reassociate or contract ``a * b + c`` by itself, so the results do not
depend on where it would have chosen to.  ``fused`` asks for the IEEE 754
operation by name (LLVM's ``llvm.fma.f64``): one instruction where the CPU
has it, a correctly rounded library call where it has not, so every machine
computes the same bits.  The accumulations of the transfers use it: a
product and a sum per node and component, the bulk of their arithmetic.

>>> import numba
>>> @numba.njit
... def residual(a, b, c):
...     return fused(a, b, c)
>>> residual(0.1, 10.0, -1.0)  # 0.1 * 10 is 1 + 2^-54 exactly, which a separate product rounds to 1
5.551115123125783e-17
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic


@intrinsic
def fused(typingctx, a, b, c):
    """``a * b + c`` with one rounding (float64)."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, sig, args):
        return builder.fma(*args)

    return signature, codegen
