"""Calling a big compiled kernel past numba's dispatcher, once its one signature is known.

numba's dispatcher types every argument of every call to pick the compiled signature: ~0.15 us
an argument, so 14 us of a ~45-us call of ``fallback_pass.chain_kernel`` (104 arguments; seed
002's 7-star frames, measured with ``/work/s29/chain_disp.py``). A kernel that holds exactly one
signature can be called through that signature's native entry point instead, which unboxes the
arguments without typing them. It checks each array's dtype (a float32 array raises) but not its
layout, number of dimensions or writability, so a caller takes the entry only with arguments of
the kernel's usual types (its own checks), and the dispatcher otherwise.
(:func:`service.core.first_pass.kernel_entry` does the same for the first pass.)
"""

from __future__ import annotations

from typing import Any

import numpy as np


def sole_entry(kernel: Any) -> Any | None:
    """The native entry point of numba dispatcher ``kernel`` if it holds exactly one compiled
    signature, else None."""
    overloads = kernel.overloads
    if len(overloads) != 1:
        return None
    return next(iter(overloads.values())).entry_point


def plain(*arrays: np.ndarray) -> bool:
    """Are these arrays C-contiguous and writable (the layout the kernels are compiled for)?"""
    for a in arrays:
        flags = a.flags
        if not (flags.c_contiguous and flags.writeable):
            return False
    return True


class EntryCall:
    """Calls ``kernel`` through its dispatcher until a call leaves it with one signature, then
    through that signature's entry point (:func:`sole_entry`). Call it only with arguments of
    the kernel's usual types; call ``kernel`` itself with any others."""

    def __init__(self, kernel: Any) -> None:
        self.kernel = kernel
        self.entry: Any | None = None

    def __call__(self, *args: Any) -> Any:
        entry = self.entry
        if entry is not None:
            return entry(*args)
        out = self.kernel(*args)
        self.entry = sole_entry(self.kernel)  # None while the kernel holds several signatures
        return out


__all__ = ["EntryCall", "plain", "sole_entry"]
