"""Brightness and completeness checks of an answer's pairs (the wrong answers they fixed:
tests/core/test_found_wrong.py)."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.photometry import beyond_completeness, faintest_inverted, faintest_inverted_among, too_bright


def test_too_bright_flags_a_false_star_on_a_faint_catalogue_star() -> None:
    rng = np.random.default_rng(1)
    mag = np.array([3.1, 5.3, 5.5, 5.4, 6.3, 6.0, 6.3, 6.3, 6.5, 7.2])
    flux = 10 ** (-0.4 * (mag - 13.3 + rng.normal(0, 0.3, len(mag))))
    flux[-1] = 10 ** (-0.4 * (4.1 - 13.3))  # observed as a 4.1 mag star, named as a 7.2 mag one
    assert too_bright(flux, mag).tolist() == [False] * 9 + [True]
    saturated = flux.copy()
    saturated[0] /= 30  # a saturated bright star is fainter than predicted: never flagged
    assert not too_bright(saturated[:-1], mag[:-1]).any()
    assert not too_bright(flux[:4], mag[:4]).any()  # too few pairs to judge


def test_beyond_completeness_needs_most_brighter_stars_unseen() -> None:
    pairs = np.array([4.0, 4.5, 5.0, 5.5, 6.0, 7.5])
    field = np.concatenate([pairs, np.linspace(6.6, 7.4, 12)])
    paired = np.concatenate([np.ones(6, bool), np.zeros(12, bool)])
    assert beyond_completeness(pairs, field, paired).tolist() == [False] * 5 + [True]
    # the same faint pair in a field where the brighter stars were seen is kept
    assert not beyond_completeness(pairs, field, np.ones(len(field), bool)).any()
    # a third of the field hidden (trees, a roof): kept
    partly = np.ones(len(field), bool)
    partly[6:10] = False
    assert not beyond_completeness(pairs, field, partly).any()


def test_theil_sen_matches_scipy() -> None:
    from scipy.stats import theilslopes

    from service.core.photometry import theil_sen

    rng = np.random.default_rng(4)
    x = rng.uniform(2, 7, 25)
    y = 1.0 * x - 13.3 + rng.normal(0, 0.3, 25)
    y[3] -= 4  # an outlier the fit ignores
    slope, intercept = theil_sen(x, y)
    ref = theilslopes(y, x)
    assert slope == pytest.approx(ref.slope) and intercept == pytest.approx(ref.intercept)


def test_faintest_inverted_flags_a_faint_catalogue_star_seen_bright() -> None:
    mag = np.linspace(3.0, 6.0, 20)
    flux = 10 ** (-0.4 * mag)  # a camera that sees each star as its magnitude says
    assert not faintest_inverted(flux, mag).any()
    mag_false = np.append(mag, 6.4)  # a false star of middling brightness named after a 6.4 Mv star
    flux_false = np.append(flux, 10 ** (-0.4 * 4.5))
    assert np.flatnonzero(faintest_inverted(flux_false, mag_false)).tolist() == [20]
    flux_false[-1] = 10 ** (-0.4 * 6.2)  # seen as faint as it is: kept
    assert not faintest_inverted(flux_false, mag_false).any()
    mag_false[-1] = 6.02  # not past the next pair by FAINTEST_GAP_MAG: kept, however bright
    flux_false[-1] = 10 ** (-0.4 * 3.5)
    assert not faintest_inverted(flux_false, mag_false).any()


def test_faintest_inverted_spares_real_stars_with_photometric_noise() -> None:
    rng = np.random.default_rng(3)
    refused = 0
    for _ in range(2000):
        mag = np.sort(6.0 - rng.exponential(1 / (0.45 * np.log(10)), 25))  # counts grow 10^0.45 a magnitude
        flux = 10 ** (-0.4 * (mag + rng.normal(0, 0.2, 25)))
        refused += int(faintest_inverted(flux, mag).any())
    assert refused / 2000 < 0.02


def test_faintest_inverted_among_weighs_the_pairs_the_other_checks_keep() -> None:
    """A false star named after a catalogue star past every other pair's, outshining 7 of 17 real
    pairs (41%, refused) but 7 of 18 when a bright pair that another check drops is counted
    (39%: kept before session 30)."""
    mag = np.linspace(4.0, 6.0, 17)
    flux = 10 ** (-0.4 * mag)
    mag_f = np.append(mag, 6.35)
    flux_f = np.append(flux, flux[9] * 0.99)  # brighter than the 7 faintest of the 17
    assert np.flatnonzero(faintest_inverted(flux_f, mag_f)).tolist() == [17]
    mag_b = np.append(mag_f, 4.8)  # a bright pair, which another check drops
    flux_b = np.append(flux_f, 10 ** (-0.4 * 3.0))
    assert not faintest_inverted(flux_b, mag_b).any()
    dropped = np.zeros(len(mag_b), bool)
    dropped[-1] = True
    assert np.flatnonzero(faintest_inverted_among(flux_b, mag_b, dropped)).tolist() == [17]
    assert not faintest_inverted_among(flux_b, mag_b, np.zeros(len(mag_b), bool)).any()
