"""The synthetic star renderer: flux, position and noise are what they claim to be."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from service.core.errors import InvalidInputError
from service.core.render import (
    flux_from_magnitude,
    random_positions,
    render_expected,
    render_image,
    star_snr,
)


@pytest.mark.parametrize("sigma", [0.6, 1.0, 2.5])
@pytest.mark.parametrize("pos", [(20.0, 15.0), (20.37, 15.81), (19.5, 14.5)])
def test_expected_image_conserves_flux_and_centre(sigma: float, pos: tuple[float, float]) -> None:
    img = render_expected([pos], [1000.0], width=48, height=32, psf_sigma_px=sigma, background=0.0)
    assert_allclose(img.sum(), 1000.0, rtol=1e-6)  # truncated at 6 sigma
    yy, xx = np.mgrid[0:32, 0:48]
    # The first moment of the pixel values is the centre up to the pixel-phase (aliasing) term,
    # of relative size exp(-2 pi^2 sigma^2): 1e-4 px at sigma = 0.6, nothing at 1 px and up.
    atol = 2e-3 if sigma < 1 else 1e-6
    assert_allclose([(img * xx).sum() / img.sum(), (img * yy).sum() / img.sum()], pos, atol=atol)


def test_expected_image_is_symmetric_about_a_pixel_centre() -> None:
    img = render_expected([(10.0, 10.0)], [1.0], width=21, height=21, background=0.0)
    assert_allclose(img, img[::-1, :], atol=1e-15)
    assert_allclose(img, img.T, atol=1e-15)
    assert img.argmax() == 10 * 21 + 10


def test_stars_partly_outside_are_clipped_not_wrapped() -> None:
    img = render_expected([(-0.5, 5.0), (30.0, 5.0)], [100.0, 100.0], width=10, height=10, background=0.0)
    assert_allclose(img.sum(), 50.0, rtol=1e-4)  # half of the first star; none of the second
    assert img[:, -1].max() < 1e-6


def test_render_dtypes_clipping_and_reproducibility() -> None:
    xy, flux = [(16.0, 16.0)], [1e7]
    img16 = render_image(xy, flux, width=32, height=32, rng=3)
    assert img16.dtype == np.uint16 and img16.shape == (32, 32)
    assert img16.max() == 65535
    img8 = render_image(xy, flux, width=32, height=32, bit_depth=8, background=10, rng=3)
    assert img8.dtype == np.uint8 and img8.max() == 255
    capped = render_image(xy, flux, width=32, height=32, saturation=4095, rng=3)
    assert capped.max() == 4095
    assert np.array_equal(render_image(xy, [500.0], width=32, height=32, rng=7),
                          render_image(xy, [500.0], width=32, height=32, rng=7))


def test_noise_statistics_match_poisson_plus_read_noise() -> None:
    img = render_image(np.zeros((0, 2)), [], width=256, height=256, background=400.0, read_noise=10.0, rng=1)
    assert_allclose(img.mean(), 400.0, atol=0.5)
    assert_allclose(img.std(), np.sqrt(400.0 + 100.0), rtol=0.02)
    quiet = render_image(np.zeros((0, 2)), [], width=64, height=64, background=400.0, read_noise=0.0,
                         shot_noise=False, rng=1)
    assert np.all(quiet == 400)


def test_hot_pixels_at_given_and_random_positions() -> None:
    pos = np.array([[3, 4], [10, 20]])
    img = render_image(np.zeros((0, 2)), [], width=32, height=32, hot_pixels=pos, hot_pixel_value=5000,
                       read_noise=0, shot_noise=False, rng=0)
    assert img[4, 3] == 5100 and img[20, 10] == 5100
    assert (img > 100).sum() == 2
    img = render_image(np.zeros((0, 2)), [], width=32, height=32, hot_pixels=7, rng=0)
    assert (img > 10000).sum() == 7


def test_flux_from_magnitude() -> None:
    assert_allclose(flux_from_magnitude([0.0, 5.0, -2.5], zero_point_flux=1e6), [1e6, 1e4, 1e7])


def test_star_snr_closed_forms() -> None:
    sigma, f = 1.0, np.array([100.0, 1000.0])
    # Read noise only: SNR = F sqrt(sum p_i^2) / RN, and sum p_i^2 -> 1 / (4 pi sigma^2) when
    # the PSF is well sampled (pixel integration lowers it slightly).
    snr = star_snr(f, psf_sigma_px=sigma, background=0.0, read_noise=5.0, shot_noise=False)
    assert_allclose(snr[1] / snr[0], 10.0)
    assert 0.9 < snr[0] / (100.0 / 5.0 / np.sqrt(4 * np.pi)) < 1.0
    # Bright star, no background: photon-limited, SNR -> sqrt(F).
    assert_allclose(star_snr([1e8], background=0.0, read_noise=0.0), [1e4], rtol=1e-6)
    assert np.all(np.diff(star_snr(np.geomspace(10, 1e6, 20))) > 0)


def test_random_positions_margin_and_separation() -> None:
    pts = random_positions(400, width=300, height=200, margin_px=7, min_separation_px=6, rng=2)
    assert pts.shape == (400, 2)
    assert pts[:, 0].min() >= 7 and pts[:, 0].max() <= 300 - 1 - 7
    assert pts[:, 1].min() >= 7 and pts[:, 1].max() <= 200 - 1 - 7
    d = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)) + np.eye(len(pts)) * 1e9
    assert d.min() >= 6


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"bit_depth": 12}, "bit_depth"), ({"width": 0}, "width"), ({"hot_pixels": [[99, 0]]}, "hot_pixels"),
     ({"psf_sigma_px": 0.0}, "psf_sigma_px")],
)
def test_bad_arguments_name_their_field(kwargs: dict[str, object], field: str) -> None:
    args: dict[str, object] = {"width": 16, "height": 16, **kwargs}
    with pytest.raises(InvalidInputError) as err:
        render_image([(5.0, 5.0)], [100.0], **args)  # type: ignore[arg-type]
    assert err.value.field == field
