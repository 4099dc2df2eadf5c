"""A memory prefetch hint for compiled kernels (LLVM's ``llvm.prefetch``).

numba exposes no prefetch, and a hash-table probe loop cannot rely on the processor to run
ahead: each probe is a data-dependent branchy scan, so the next probe's load waits for the last
one's miss. Issuing the loads of every probe of a pattern first lets their misses overlap
(``quad``'s search over a 32-64 MB table: see :mod:`.methods.quad_kernel`).

The hint never changes a result: it reads nothing back and may be dropped by the processor.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch(typingctx, arr, index):  # noqa: ARG001 (numba's intrinsic signature)
    """Hint that ``arr[index]`` (a 1-d array, an integer index within it) will be read soon."""
    if not isinstance(arr, types.Array) or arr.ndim != 1 or not isinstance(index, types.Integer):
        return None
    sig = types.void(arr, index)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0i8")
        # read (0), high temporal locality (3), data cache (1)
        builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


__all__ = ["prefetch"]
