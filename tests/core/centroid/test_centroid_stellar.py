"""Non-stellar blobs (clutter such as lit foliage) are rejected; stars are kept."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core.centroid import extract
from service.core.centroid.stellar import quiet_noise, significance_deficit
from service.core.errors import InvalidInputError
from service.core.render import random_positions, render_expected, render_image

SIZE = 512


def foliage_field(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """30 stars (PSF 1 px, flux 1e3-1e4) on the left two thirds; on the right third 1500 lit
    "leaves": Gaussian blobs of 1.2-2.5 px and flux 500-3000, packed like a tree's crown."""
    rng = np.random.default_rng(seed)
    xy = random_positions(30, width=340, height=SIZE, rng=rng)
    flux = 10 ** rng.uniform(3.0, 4.0, len(xy))
    img = render_image(xy, flux, width=SIZE, height=SIZE, background=100.0, read_noise=5.0, rng=rng)
    leaves = np.zeros((SIZE, SIZE))
    for sigma in (1.2, 1.6, 2.0, 2.5):
        pos = np.c_[rng.uniform(360, SIZE, 375), rng.uniform(0, SIZE, 375)]
        leaves += render_expected(pos, rng.uniform(500, 3000, 375), width=SIZE, height=SIZE,
                                  psf_sigma_px=sigma, background=0.0)
    return (img + leaves).astype(np.float32), xy


@pytest.mark.parametrize("seed", range(4))
def test_foliage_is_rejected_and_stars_lead(seed: int) -> None:
    img, xy = foliage_field(seed)
    det = extract(img)
    is_star = cKDTree(xy).query(det.centroids.xy)[0] < 1.0
    assert is_star.sum() >= 29  # of 30
    assert is_star[:20].sum() >= 19
    assert len(det) <= 50  # of ~1500 leaves a few are left
    # Without the test the leaves outrank and crowd out the stars.
    loose = extract(img, min_significance_ratio=None)
    is_star = cKDTree(xy).query(loose.centroids.xy)[0] < 1.0
    assert is_star[:20].sum() <= 17
    assert is_star.sum() <= 26


@pytest.mark.parametrize("top", [1000.0, 4000.0])
def test_stars_in_glare_are_kept(top: float) -> None:
    """A background rising from 100 to ``top`` counts across the frame (moonlight, twilight)
    raises the shot noise, not clutter: the test must not drop the stars there."""
    rng = np.random.default_rng(1)
    size = 768
    xy = random_positions(200, width=size, height=size, rng=rng)
    xx = np.arange(size)[None, :]
    glare = 100.0 * (top / 100.0) ** (xx / (size - 1)) * np.ones((size, 1))
    light = render_expected(xy, 10 ** rng.uniform(3.0, 5.0, len(xy)), width=size, height=size,
                            background=0.0) + glare
    img = np.clip(rng.poisson(light) + rng.normal(0, 5.0, light.shape), 0, 65535).astype(np.uint16)
    kept = cKDTree(extract(img, max_stars=None).centroids.xy).query(xy)[0] < 1.0
    loose = cKDTree(extract(img, max_stars=None, min_significance_ratio=None).centroids.xy).query(xy)[0] < 1.0
    bright_side = xy[:, 0] > 2 * size / 3
    assert loose[bright_side].sum() >= 10  # there are stars to lose
    assert kept.sum() >= loose.sum() - 1


def test_quiet_noise_follows_shot_noise_not_clutter() -> None:
    level = np.repeat(100.0 * 16.0 ** (np.arange(8) / 7.0)[None, :], 8, axis=0)  # 100 ... 1600
    sigma = np.sqrt(level)  # shot noise
    sigma[:2, :3] = 40.0  # clutter: a tree in a corner, noisy at the sky's level
    at = np.array([100.0, 400.0, 1600.0])
    np.testing.assert_allclose(quiet_noise(level, sigma, at), np.sqrt(at), rtol=0.1)


def test_deficit_rule() -> None:
    snr = np.array([50.0, 40.0, 30.0, 20.0, 10.0, 5.0, 4.0, 100.0])
    flux = np.array([500.0, 400.0, 300.0, 200.0, 100.0, 50.0, 200.0, 3000.0])
    usable = np.array([True] * 7 + [False])  # the last one saturated: never judged
    quiet = np.ones(8)
    rejected = significance_deficit(snr, flux, usable, quiet, min_ratio=0.4)
    # snr / flux is 0.1 for the first six, 0.02 for the seventh (a fifth of the reference).
    assert rejected.tolist() == [False] * 6 + [True, False]
    # The seventh sits on a background whose quiet noise is 5x higher: no deficit then.
    quiet[6] = 5.0
    assert not significance_deficit(snr, flux, usable, quiet, min_ratio=0.4).any()
    # Fewer than 5 sources of SNR >= 10 to set the reference: nothing is judged.
    few = usable & (np.arange(8) >= 3)
    assert not significance_deficit(snr, flux, few, np.ones(8), min_ratio=0.4).any()


@pytest.mark.parametrize("value", [0.0, -0.1, 1.5, float("nan")])
def test_bad_ratio_names_the_knob(value: float) -> None:
    with pytest.raises(InvalidInputError) as err:
        extract(np.zeros((16, 16)), min_significance_ratio=value)
    assert err.value.field == "min_significance_ratio"
