"""The stop flag a live cut raises, as numba kernels read it.

A kernel that reads its ``(1,) int64`` stop flag with a plain load may read
it once: LLVM assumes that no other thread writes memory without atomics,
so it can keep the first value for the rest of the kernel, across a
parallel loop's launch (measured: ``_newton_kernels.node_neighbours`` ran
on 55 ms past a raised flag).  :func:`flag_up` is an atomic (monotonic)
load, read again at every call, at the cost of a plain load.
"""

from __future__ import annotations

from numba import njit, types
from numba.extending import intrinsic

__all__ = ["flag_up"]


@intrinsic
def _load_first(typingctx, flag):
    """``flag[0]`` of a C-contiguous int64 array, by an atomic monotonic load."""
    if not (isinstance(flag, types.Array) and flag.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.load_atomic(array.data, "monotonic", 8)

    return types.int64(flag), codegen


@njit(cache=True, nogil=True, inline="always")
def flag_up(flag) -> bool:
    """Whether the stop flag ``flag`` ((1,) int64) is non-zero now (read atomically)."""
    return _load_first(flag) != 0
