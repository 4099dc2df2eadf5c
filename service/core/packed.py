"""A compiled kernel's fixed arguments as one object that crosses into compiled code at once.

numba unboxes every argument of every call: ~35 ns an array, even through a kernel's native
entry point (:mod:`._entry`), and as much again for each array of a tuple. ``auto``'s first
pass takes ~60 fixed arguments after the frame's own (the member's tables, grids, bounds), the
fallback chain ~75: 2-3 us a call spent handing the same arrays over again (a numba
micro-benchmark of 74 arrays: 2.6 us as a tuple through the entry point, 0.12 us as one
:class:`Packed`; ``/work/s36/srt/run2.py``). A :class:`Packed` is a numba ``StructRef`` whose one
field holds the tuple: the tuple is unboxed once, when it is packed, and a call passes a single
pointer; inside, the kernel spreads ``packed.args`` into its callee (``f(..., *packed.args)``).

The fields' types are part of the ``StructRef``'s type, so one kernel still gets one compiled
signature as long as its tuples' element types do not change (the callers keep them so:
``tests/core/test_compile_signatures.py``). :func:`pack` is compiled and cached, so a fresh
process types the tuple once (~0.2 s) instead of compiling the constructor (~1 s).
"""

from __future__ import annotations

from typing import Any

from numba import njit, types
from numba.experimental import structref


@structref.register
class PackedType(types.StructRef):
    """The numba type of a :class:`Packed` (its field's tuple type is part of it)."""

    def preprocess_fields(self, fields: Any) -> tuple[tuple[str, Any], ...]:
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Packed(structref.StructRefProxy):
    """A tuple of a kernel's fixed arguments, held in compiled code (``.args`` there)."""

    def __new__(cls, args: tuple[Any, ...]) -> Packed:
        return structref.StructRefProxy.__new__(cls, args)


structref.define_constructor(Packed, PackedType, ["args"])
structref.define_boxing(PackedType, Packed)


@njit(cache=True)
def _pack(args):
    return Packed(args)


def pack(args: tuple[Any, ...]) -> Packed:
    """``args`` (a tuple of arrays and numbers) as one :class:`Packed` for a compiled call."""
    return _pack(tuple(args))


__all__ = ["Packed", "PackedType", "pack"]
