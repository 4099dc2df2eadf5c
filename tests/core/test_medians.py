"""The compiled short-array median is numpy's, value for value (service/core/medians.py)."""

from __future__ import annotations

import numpy as np

from service.core.medians import SHORT, median


def test_the_same_value_as_numpy_at_every_length() -> None:
    rng = np.random.default_rng(3)
    for n in range(1, 2 * SHORT + 3):
        for _ in range(20):
            a = rng.normal(size=n) * 10 ** rng.uniform(-6, 6)
            if rng.random() < 0.3:  # ties
                a = np.round(a, 1)
            assert median(a) == np.median(a)


def test_nan_and_inf_as_numpy() -> None:
    assert np.isnan(median(np.array([1.0, np.nan, 3.0])))
    assert np.isnan(median(np.zeros(0)))
    assert median(np.array([np.inf, 1.0, 2.0])) == 2.0
    assert np.isnan(median(np.array([-np.inf, np.inf])))  # numpy's NaN (with its warning)
