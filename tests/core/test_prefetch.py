"""The prefetch hint compiles for the arrays the kernels probe and changes no result."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from service.core.prefetch import prefetch


@njit(cache=False)
def _gather(table: np.ndarray, idx: np.ndarray, hint: bool) -> int:
    total = 0
    for i in range(len(idx)):
        if hint and i + 4 < len(idx):
            prefetch(table, idx[i + 4])
        total += table[idx[i]]
    return total


@pytest.mark.parametrize("dtype", [np.uint64, np.int64, np.int32])
def test_prefetch_changes_no_result(dtype) -> None:
    rng = np.random.default_rng(2)
    table = rng.integers(0, 1 << 30, 1 << 16).astype(dtype)
    idx = rng.integers(0, len(table), 5000)
    table.flags.writeable = False  # the database's tables are read-only maps
    assert _gather(table, idx, True) == _gather(table, idx, False) == int(table[idx].astype(np.int64).sum())


def test_prefetch_takes_one_dimensional_arrays_only() -> None:
    @njit(cache=False)
    def two_d(a: np.ndarray) -> None:
        prefetch(a, 0)

    with pytest.raises(TypingError):
        two_d(np.zeros((2, 2)))
