"""The in-place bucket sort of maxangle's tables is numpy's stable sort by key."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.methods._bucket_sort import sort_by_bucket_key


@pytest.mark.parametrize("n_buckets", [1, 7, 4096])
def test_equals_a_stable_argsort_of_every_column(n_buckets: int) -> None:
    rng = np.random.default_rng(n_buckets)
    n = 20_000
    key = rng.integers(0, n_buckets, n) + np.round(rng.random(n) * 0.99, 2)  # ties within buckets
    ids = rng.integers(0, 9_000, (n, 3)).astype(np.int32)
    b, c = rng.random(n).astype(np.float32), rng.random(n).astype(np.float32)
    wide = rng.random(n)  # an 8-byte column takes the other path
    order = np.argsort(key, kind="stable")
    expected = [a[order] for a in (key, ids, b, c, wide)]
    sort_by_bucket_key(key, [ids, b, c, wide], n_buckets)
    for got, want in zip((key, ids, b, c, wide), expected, strict=True):
        assert np.array_equal(got, want)


def test_refuses_keys_outside_the_buckets() -> None:
    with pytest.raises(ValueError, match="n_buckets"):
        sort_by_bucket_key(np.array([0.5, 3.2]), [], 3)
