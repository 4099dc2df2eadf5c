"""Position consistency of an answer's pairs (the wrong answers it fixed:
tests/core/test_found_wrong.py)."""

from __future__ import annotations

import numpy as np

from service.core.residuals import GAP_MAG, Z_ANY, Z_BEYOND, Z_FAINTEST, Z_OUTSIDE, distant_pairs


def _frame(n: int, sigma: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    d = np.hypot(*rng.normal(0, sigma, (2, n)))
    mag = np.linspace(3.0, 6.0, n)
    return d, mag


def test_far_pairs_are_refused_near_ones_kept() -> None:
    rng = np.random.default_rng(1)
    d, mag = _frame(30, 0.25, rng)
    d = np.minimum(d, 2.0 * 0.25)  # every real star within 2 sigma
    assert not distant_pairs(d, mag, 0.25).any()
    d[10] = (Z_ANY + 0.5) * 0.25  # a bright pair far off: refused whatever its magnitude
    assert np.flatnonzero(distant_pairs(d, mag, 0.25)).tolist() == [10]


def test_the_declared_noise_bounds_the_measured_one_from_below() -> None:
    d, mag = np.full(20, 0.05), np.linspace(3.0, 6.0, 20)  # a frame fitting far better than declared
    d[5] = 1.0  # 20 measured sigma, 2 declared: kept
    assert not distant_pairs(d, mag, 0.5).any()
    assert distant_pairs(d, mag, 0.0)[5]  # with no declared noise the measured one rules


def test_the_faintest_pair_needs_less_and_more_so_past_the_rest() -> None:
    mag = np.linspace(3.0, 6.0, 20)
    d = np.full(20, 1.0)  # measured sigma = 1 / sqrt(ln 4) ~ 0.85 px; declared 1 px rules
    d[-1] = (Z_FAINTEST + Z_BEYOND) / 2  # between the two thresholds
    assert not distant_pairs(d, mag, 1.0).any()  # the faintest, but close to the next one
    mag[-1] = mag[-2] + GAP_MAG + 0.05  # past every other pair
    assert distant_pairs(d, mag, 1.0)[-1]
    d[-1] = Z_FAINTEST + 0.2
    mag[-1] = mag[-2] + 0.05
    assert distant_pairs(d, mag, 1.0)[-1]
    d[3] = Z_FAINTEST + 0.2  # the same distance on a brighter pair is kept
    assert not distant_pairs(d, mag, 1.0)[3]


def test_few_pairs_or_unknown_distances_are_not_judged() -> None:
    assert not distant_pairs(np.array([0.1, 0.1, 0.1, 9.0]), np.array([3.0, 4.0, 5.0, 6.0]), 0.1).any()
    d = np.array([0.1] * 7 + [np.nan])
    assert not distant_pairs(d, np.linspace(3, 6, 8), 0.1).any()


def test_real_stars_are_seldom_refused() -> None:
    rng = np.random.default_rng(7)
    refused = total = 0
    for _ in range(2000):
        d, mag = _frame(20, 1.0, rng)
        refused += int(distant_pairs(d, mag, 1.0).sum())
        total += len(d)
    # the faintest of 20 beyond 2.5 sigma: exp(-3.125) / 20 ~ 0.2 % of the pairs
    assert refused / total < 0.005


def test_a_pair_predicted_outside_the_image_is_held_to_z_outside() -> None:
    """A pair whose catalogue star is predicted outside the image is refused beyond Z_OUTSIDE
    sigma, where one inside is kept to Z_ANY; its distance does not enter the frame's noise."""
    d, mag = _frame(12, 0.5, np.random.default_rng(3))
    d = np.minimum(d, 2.0 * 0.5)
    d[4] = (Z_OUTSIDE + 1.0) * 0.5  # between Z_OUTSIDE and Z_ANY sigma; not the faintest pair
    assert Z_OUTSIDE + 1.0 < Z_ANY and not distant_pairs(d, mag, 0.5)[4]  # inside: kept
    outside = np.zeros(12, bool)
    outside[4] = True
    assert np.flatnonzero(distant_pairs(d, mag, 0.5, outside)).tolist() == [4]
    d[4] = 0.6  # within Z_OUTSIDE of its prediction: a real star's blob just inside the edge
    assert not distant_pairs(d, mag, 0.5, outside).any()
    d[4] = 50.0  # far, and outside: it does not raise the measured noise that judges the others
    assert np.flatnonzero(distant_pairs(d, mag, 0.0, outside)).tolist() == [4]
