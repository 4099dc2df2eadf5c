"""Sort a large table by a key whose integer part is a small bucket number, in place.

The maxangle table (up to ~10^8 triangles) is ordered by ``key = block + fraction`` with
``block`` in ``[0, n_blocks)`` and ``0 <= fraction < 1``. ``np.argsort`` plus fancy indexing
needs an 8-byte permutation and a copy of each column beside the table; here a counting pass
gives each row its destination (4 bytes a row), every column is permuted in place (4-byte ones
through a 4-byte buffer, the key by following the permutation's cycles with 1 byte a row of
marks), and each bucket is then sorted on its own (small). The result is the stable sort by
``key``: rows of equal key keep their order.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _destinations(key: np.ndarray, n_buckets: int, dest: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Fill ``dest[i]``, row ``i``'s place in the stable order by bucket; return the buckets' starts."""
    n = key.shape[0]
    starts = np.zeros(n_buckets + 1, np.int64)
    for i in range(n):
        starts[int(key[i]) + 1] += 1
    for b in range(n_buckets):
        starts[b + 1] += starts[b]
    cursor = starts[:-1].copy()
    for i in range(n):
        b = int(key[i])
        dest[i] = cursor[b]
        cursor[b] += 1
    return starts


@njit(cache=True, nogil=True)
def _scatter(a: np.ndarray, dest: np.ndarray, done: np.ndarray) -> None:  # pragma: no cover - numba
    """Move ``a[i]`` to ``a[dest[i]]`` for every ``i``, in place (``dest`` a permutation)."""
    n = a.shape[0]
    done[:] = False
    for start in range(n):
        if done[start]:
            continue
        cur = start
        val = a[start]
        while True:
            nxt = dest[cur]
            done[cur] = True
            if nxt == start:
                a[start] = val
                break
            tmp = a[nxt]
            a[nxt] = val
            val = tmp
            cur = nxt


@njit(cache=True, nogil=True)
def _scatter_through(a: np.ndarray, dest: np.ndarray, tmp: np.ndarray) -> None:  # pragma: no cover - numba
    """Move ``a[i]`` to ``a[dest[i]]`` through ``tmp`` (same length and dtype): independent
    writes, which the memory system overlaps, where following the permutation's cycles waits on
    every load in turn (~4x slower on a 10^6-10^7-row table)."""
    for i in range(a.shape[0]):
        tmp[dest[i]] = a[i]
    for i in range(a.shape[0]):
        a[i] = tmp[i]


def sort_by_bucket_key(key: np.ndarray, columns: list[np.ndarray], n_buckets: int) -> None:
    """Stable-sort ``key`` (float64, ``0 <= key < n_buckets``) and the rows of ``columns``
    (1-D or 2-D, ``len == len(key)``) by ``key``, all in place."""
    if len(key) == 0:
        return
    if not (np.all(key >= 0) and np.all(key < n_buckets)):
        raise ValueError("keys must lie in [0, n_buckets)")
    dest = np.empty(len(key), np.int32 if len(key) < 2**31 else np.int64)
    starts = _destinations(key, n_buckets, dest)
    # columns of 4-byte items through one 4-byte buffer; wider ones (the float64 key) by their
    # cycles in place, so the sort holds 9 bytes a row beside the table (dest, the buffer, marks)
    done = np.empty(len(key), np.bool_)
    buffer = np.empty(len(key), np.int32)
    for arr in (key, *columns):
        for col in ([arr] if arr.ndim == 1 else [arr[:, c] for c in range(arr.shape[1])]):
            if col.dtype.itemsize == 4:
                _scatter_through(col, dest, buffer.view(col.dtype))
            else:
                _scatter(col, dest, done)
    del dest, done, buffer
    for b in range(n_buckets):
        s, e = int(starts[b]), int(starts[b + 1])
        if e - s < 2:
            continue
        order = np.argsort(key[s:e], kind="stable")
        key[s:e] = key[s:e][order]
        for arr in columns:
            arr[s:e] = arr[s:e][order]
