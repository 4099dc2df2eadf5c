"""Give freed memory back to the system promptly during large builds (glibc only).

glibc serves allocations above its mmap threshold with their own mappings, returned to the
system when freed; but it raises that threshold (up to 32 MB) each time such a block is
freed, so a build that makes and frees many arrays of a few MB ends up carving them from the
heap, where freed memory stays with the process. Building the 20-deg maxangle table that way
held a GB more than its arrays. Fixing the threshold at 1 MB keeps every array of 1 MB or more
in its own mapping.
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_MMAP_THRESHOLD = -3
THRESHOLD_BYTES = 1 << 20


def map_large_allocations() -> bool:
    """Fix glibc's mmap threshold at 1 MB for this process; False where there is no glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):  # musl, macOS: no mallopt
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, THRESHOLD_BYTES))
