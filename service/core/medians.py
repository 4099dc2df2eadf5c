"""The median of a short array, compiled: the answer's checks take ~8 of them a frame.

numba's ``np.median`` copies its input and runs a quickselect, ~0.6 us for 10-19 values; an
insertion sort into a scratch array takes ~0.1 us there (``/work/s30/med.py``). Beyond
:data:`SHORT` values the quickselect is the faster, and :func:`median` hands over to it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

SHORT = 32
"""Values up to which :func:`median` sorts by insertion."""


@njit(cache=True, nogil=True)
def median(a: np.ndarray) -> float:
    """``np.median(a)`` of a 1-D float array, the same value bit for bit: the middle value, or the
    mean of the two middle values; NaN if any value is NaN or ``a`` is empty."""
    n = len(a)
    if n == 0 or n > SHORT:
        return np.median(a)
    b = np.empty(n)
    for i in range(n):
        v = a[i]
        if v != v:
            return np.nan
        j = i
        while j > 0 and b[j - 1] > v:
            b[j] = b[j - 1]
            j -= 1
        b[j] = v
    h = n // 2
    if n % 2:
        return b[h]
    return (b[h - 1] + b[h]) / 2
