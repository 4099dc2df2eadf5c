"""Detection and centroiding scored against rendered truth (service.core.render)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from service.core.centroid import Detections, extract
from service.core.errors import InvalidInputError
from service.core.render import random_positions, render_expected, render_image, star_snr

BACKGROUND, READ_NOISE = 100.0, 5.0


def flux_for_snr(snr: np.ndarray, *, psf_sigma_px: float, background: float = BACKGROUND,
                 read_noise: float = READ_NOISE) -> np.ndarray:
    """Invert :func:`star_snr` (monotonic) by interpolation."""
    grid = np.geomspace(1.0, 1e8, 4000)
    return np.interp(snr, star_snr(grid, psf_sigma_px=psf_sigma_px, background=background,
                                   read_noise=read_noise), grid)


def random_field(
    seed: int, *, n: int = 300, size: int = 1024, psf_sigma_px: float = 1.0, min_separation_px: float = 5.0,
    **render_kw: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stars with log-uniform SNR in [3, 300] at random positions -> (image, xy, snr)."""
    rng = np.random.default_rng(seed)
    xy = random_positions(n, width=size, height=size, min_separation_px=min_separation_px, rng=rng)
    bg = float(render_kw.pop("background", BACKGROUND))
    rn = float(render_kw.pop("read_noise", READ_NOISE))
    snr = 10 ** rng.uniform(np.log10(3), np.log10(300), len(xy))
    flux = flux_for_snr(snr, psf_sigma_px=psf_sigma_px, background=bg, read_noise=rn)
    img = render_image(xy, flux, width=size, height=size, psf_sigma_px=psf_sigma_px, background=bg,
                       read_noise=rn, rng=rng, **render_kw)  # type: ignore[arg-type]
    return img, xy, snr


def match(det: Detections, xy: np.ndarray, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each true star to the nearest detection, and which detections are false."""
    if len(det) == 0:
        return np.full(len(xy), np.inf), np.zeros(0, bool)
    dist, _ = cKDTree(det.centroids.xy).query(xy)
    back, _ = cKDTree(xy).query(det.centroids.xy) if len(xy) else (np.full(len(det), np.inf), None)
    return dist, back > 2.0


# --------------------------------------------------------------------------- closed form


@pytest.mark.parametrize("sigma", [0.8, 1.0, 2.0])
@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.1, 0.3), (0.25, 0.75), (0.5, 0.5), (0.9, 0.45)])
def test_noise_free_gaussian_spot(sigma: float, offset: tuple[float, float]) -> None:
    x, y = 20.0 + offset[0], 17.0 + offset[1]
    img = render_expected([(x, y)], [5e4], width=41, height=35, psf_sigma_px=sigma, background=50.0)
    det = extract(img)
    assert len(det) == 1
    np.testing.assert_allclose(det.centroids.xy[0], (x, y), atol=2e-3)
    np.testing.assert_allclose(det.centroids.flux[0], 5e4, rtol=0.1)  # windowed flux
    assert not det.saturated[0]


@settings(max_examples=30, deadline=None)
@given(x=st.floats(8.0, 24.0), y=st.floats(8.0, 24.0), sigma=st.floats(0.7, 2.5), flux=st.floats(1e3, 1e6))
def test_noise_free_spot_anywhere(x: float, y: float, sigma: float, flux: float) -> None:
    img = render_expected([(x, y)], [flux], width=33, height=33, psf_sigma_px=sigma, background=10.0)
    det = extract(img.astype(np.float32))
    assert len(det) == 1
    assert np.hypot(*(det.centroids.xy[0] - (x, y))) < 5e-3


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.3, 0.6), (0.5, 0.5), (0.77, 0.12)])
def test_noisy_spot_centroid_within_a_few_hundredths(offset: tuple[float, float]) -> None:
    rng = np.random.default_rng(7)
    x, y = 31.0 + offset[0], 28.0 + offset[1]
    errors = []
    for _ in range(20):  # SNR 100: Cramer-Rao bound ~0.014 px per axis
        flux = flux_for_snr(np.array([100.0]), psf_sigma_px=1.0)
        img = render_image([(x, y)], flux, width=64, height=64, rng=rng)
        det = extract(img)
        assert len(det) == 1
        errors.append(det.centroids.xy[0] - (x, y))
    err = np.asarray(errors)
    assert np.abs(err.mean(axis=0)).max() < 0.01  # unbiased at any pixel phase
    assert np.sqrt((err**2).sum(axis=1).mean()) < 0.04


# --------------------------------------------------------------------------- rendered fields


@pytest.mark.parametrize(("psf_sigma_px", "min_sep", "seeds"), [(1.0, 5.0, range(4)), (1.6, 7.0, range(2))])
def test_random_fields_accuracy_and_completeness(psf_sigma_px: float, min_sep: float, seeds: range) -> None:
    dists, snrs, false = [], [], 0
    for seed in seeds:
        img, xy, snr = random_field(seed, psf_sigma_px=psf_sigma_px, min_separation_px=min_sep)
        det = extract(img, max_stars=None)
        dist, is_false = match(det, xy)
        dists.append(dist)
        snrs.append(snr)
        false += int(is_false.sum())
    dist, snr = np.concatenate(dists), np.concatenate(snrs)
    bright = snr >= 20
    found = dist[bright] <= 1.0
    assert bright.sum() > 250
    assert found.mean() >= 0.99, f"completeness {found.mean():.4f}"
    rms = np.sqrt(np.mean(dist[bright][found] ** 2))
    assert rms <= 0.1, f"centroid RMS {rms:.3f} px"
    assert false <= len(seeds) * 3  # false detections: noise peaks and blend debris


def test_detections_sorted_by_flux_and_capped() -> None:
    img, xy, _ = random_field(11, n=150, size=512)
    det = extract(img, max_stars=40)
    assert len(det) == 40
    assert np.all(np.diff(det.centroids.flux) <= 0)
    full = extract(img, max_stars=None)
    np.testing.assert_array_equal(full.centroids.xy[:40], det.centroids.xy)
    assert np.all(full.snr > 5.0 - 1e-9) and np.all(full.area_px >= 2)
    np.testing.assert_allclose(np.median(full.background), BACKGROUND, atol=1.5)
    pixel_noise = np.hypot(BACKGROUND**0.5, READ_NOISE)
    np.testing.assert_allclose(np.median(full.background_sigma), pixel_noise, rtol=0.1)


def test_blended_pair_is_split() -> None:
    # 5.4 px apart at 3:1 (PSF sigma 1 px): one blob above threshold, two peaks in it. The
    # separable limit is 4 px at 1:1, 5 at 3:1, 6 at 10:1, 7 at 30:1 (docs/centroiding.md).
    xy = np.array([[30.0, 30.0], [35.2, 31.5], [60.2, 40.7]])
    img = render_image(xy, [30000.0, 10000.0, 20000.0], width=96, height=80, rng=3)
    det = extract(img)
    dist, is_false = match(det, xy)
    assert np.all(dist < 0.3) and not is_false.any()


# --------------------------------------------------------------------------- false alarms, hot, saturated


def test_pure_noise_false_detection_rate() -> None:
    frames, count = 12, 0
    for seed in range(frames):
        img = render_image(np.zeros((0, 2)), [], width=1024, height=1024, rng=100 + seed)
        count += len(extract(img, max_stars=None))
    for seed in range(4):  # 8-bit, faint background: quantised noise
        img = render_image(np.zeros((0, 2)), [], width=1024, height=1024, bit_depth=8, background=8.0,
                           read_noise=2.0, rng=200 + seed)
        count += len(extract(img, max_stars=None))
    megapixels = 16 * 1024 * 1024 / 1e6
    assert count / megapixels <= 1.0  # measured: ~0.1 per megapixel (docs/centroiding.md)


def test_hot_pixels_are_rejected() -> None:
    rng = np.random.default_rng(5)
    stars = random_positions(120, width=512, height=512, min_separation_px=12, rng=rng)
    hot = random_positions(200, width=512, height=512, rng=rng)
    hot = hot[cKDTree(stars).query(hot)[0] > 8].round().astype(int)
    flux = flux_for_snr(10 ** rng.uniform(np.log10(20), np.log10(300), len(stars)), psf_sigma_px=1.0)
    base = render_image(stars, flux, width=512, height=512, rng=6)
    img = base.astype(np.float64)
    amp = np.geomspace(150, 60000, len(hot))  # ~13 noise sigma up to saturation
    img[hot[:, 1], hot[:, 0]] += amp
    img = np.clip(img, 0, 65535).astype(np.uint16)
    det = extract(img, max_stars=None)
    d_hot = cKDTree(det.centroids.xy).query(hot)[0]
    assert np.all(d_hot > 1.5), f"{np.sum(d_hot <= 1.5)} hot pixels detected"
    dist, _ = match(det, stars)
    assert np.mean(dist < 1.0) >= 0.99
    unfiltered = extract(img, max_stars=None, max_sharpness=None)
    assert np.sum(cKDTree(unfiltered.centroids.xy).query(hot)[0] <= 1.5) > 0.9 * len(hot)


@pytest.mark.parametrize(("bit_depth", "saturation"), [(16, None), (16, 4095.0), (8, None)])
def test_saturated_stars_are_flagged_and_centred(bit_depth: int, saturation: float | None) -> None:
    full = (2**bit_depth - 1) if saturation is None else saturation
    xy = np.array([[40.3, 40.6], [100.8, 60.1], [70.5, 100.5], [130.2, 120.9]])
    flux = np.array([300.0, 60.0, 3.0, 0.3]) * full * 2 * np.pi  # peaks ~ 300, 60, 3, 0.3 x full well
    bg = 100.0 if bit_depth == 16 else 10.0
    img = render_image(xy, flux, width=170, height=160, background=bg, read_noise=2.0,
                       saturation=saturation, bit_depth=bit_depth, rng=1)
    det = extract(img, saturation=saturation)
    dist, j = cKDTree(det.centroids.xy).query(xy)
    assert np.all(dist < 0.25), dist
    np.testing.assert_array_equal(det.saturated[j], [True, True, True, False])
    assert j[0] == 0  # the brightest saturated star still sorts first


# --------------------------------------------------------------------------- inputs


def test_float_uint8_and_nan_inputs() -> None:
    img, xy, snr = random_field(3, n=60, size=256, background=20.0, read_noise=3.0, bit_depth=8)
    for arr in (img, img.astype(np.float32), img.astype(np.float64), img.astype(np.int32)):
        dist, _ = match(extract(arr, max_stars=None), xy)
        assert np.mean(dist[snr >= 20] < 1.0) >= 0.95
    with_nan = img.astype(np.float32)
    with_nan[10:20, 10:20] = np.nan
    assert len(extract(with_nan)) > 0


def test_empty_and_flat_images_give_no_stars() -> None:
    for img in (np.zeros((64, 64), np.uint16), np.full((5, 7), 3.5), np.zeros((64, 64), np.uint8)):
        det = extract(img)
        assert len(det) == 0 and det.centroids.xy.shape == (0, 2)


@pytest.mark.parametrize(
    ("image", "kwargs", "field"),
    [
        (np.zeros((8, 8, 3)), {}, "image"),
        (np.zeros(64), {}, "image"),
        (np.zeros((2, 64)), {}, "image"),
        (np.array([["a"] * 8] * 8), {}, "image"),
        (np.full((8, 8), np.nan), {}, "image"),
        (np.zeros((8, 8)), {"sigma_threshold": 0.0}, "sigma_threshold"),
        (np.zeros((8, 8)), {"filter_sigma_px": -1.0}, "filter_sigma_px"),
        (np.zeros((8, 8)), {"min_area_px": 5, "max_area_px": 4}, "min_area_px"),
        (np.zeros((8, 8)), {"max_stars": 0}, "max_stars"),
        (np.zeros((8, 8)), {"background_kernel_px": 2}, "background_kernel_px"),
    ],
)
def test_bad_input_names_the_field(image: np.ndarray, kwargs: dict[str, float], field: str) -> None:
    with pytest.raises(InvalidInputError) as err:
        extract(image, **kwargs)  # type: ignore[arg-type]
    assert err.value.field == field


def test_detection_without_matched_filter() -> None:
    img, xy, snr = random_field(4, n=100, size=512)
    dist, _ = match(extract(img, filter_sigma_px=None, max_stars=None), xy)
    assert np.mean(dist[snr >= 20] < 1.0) >= 0.97
