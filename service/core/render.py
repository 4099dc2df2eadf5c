"""Synthetic star images with known truth: Gaussian PSFs, shot and read noise, hot pixels.

Units: fluxes, background and noise are in counts (electrons at unit gain, so also ADU). Pixel
convention as everywhere: x = column, y = row, the centre of the top-left pixel is (0, 0), and
pixel ``(i, j)`` covers ``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)``.

>>> import numpy as np
>>> img = render_image([[10.25, 7.5]], [5000.0], width=24, height=16, rng=1)
>>> img.shape, img.dtype
((16, 24), dtype('uint16'))
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.special import erf

from .errors import InvalidInputError

__all__ = ["flux_from_magnitude", "random_positions", "render_image", "star_snr"]

FloatArray = NDArray[np.float64]


def flux_from_magnitude(mag: ArrayLike, *, zero_point_flux: float) -> FloatArray:
    """Total counts of stars of magnitude ``mag``, given the counts of a magnitude-0 star."""
    return np.asarray(zero_point_flux * 10.0 ** (-0.4 * np.asarray(mag, dtype=np.float64)))


def _pixel_fractions(centres: FloatArray, first: NDArray[np.int64], size: int, sigma: float) -> FloatArray:
    """Fraction of a unit 1-D Gaussian falling in pixels ``first .. first+size-1``: (N, size)."""
    edges = first[:, None] + np.arange(size + 1)[None, :] - 0.5
    cdf = 0.5 * (1.0 + erf((edges - centres[:, None]) / (math.sqrt(2.0) * sigma)))
    return np.diff(cdf, axis=1)


def render_expected(xy: ArrayLike, flux: ArrayLike, *, width: int, height: int, psf_sigma_px: float = 1.0,
                    background: float = 100.0) -> FloatArray:
    """Noise-free expected counts ``(height, width)`` float64: background plus each star's
    circular Gaussian PSF integrated over the pixels (erf), truncated at 6 sigma."""
    pos = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    f = np.asarray(flux, dtype=np.float64).reshape(-1)
    if pos.shape[0] != f.shape[0]:
        raise InvalidInputError("flux", f"{f.shape[0]} fluxes for {pos.shape[0]} positions")
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(f))):
        raise InvalidInputError("xy", "positions and fluxes must be finite")
    if psf_sigma_px <= 0:
        raise InvalidInputError("psf_sigma_px", "must be positive")
    out = np.full(height * width, float(background), dtype=np.float64)
    if pos.shape[0] == 0:
        return out.reshape(height, width)
    r = int(math.ceil(6.0 * psf_sigma_px)) + 1
    size = 2 * r + 1
    x0 = np.floor(pos[:, 0] + 0.5).astype(np.int64) - r
    y0 = np.floor(pos[:, 1] + 0.5).astype(np.int64) - r
    fx = _pixel_fractions(pos[:, 0], x0, size, psf_sigma_px)
    fy = _pixel_fractions(pos[:, 1], y0, size, psf_sigma_px)
    patch = f[:, None, None] * fy[:, :, None] * fx[:, None, :]  # (N, rows, cols)
    cols = x0[:, None] + np.arange(size)[None, :]
    rows = y0[:, None] + np.arange(size)[None, :]
    valid = ((rows >= 0) & (rows < height))[:, :, None] & ((cols >= 0) & (cols < width))[:, None, :]
    flat = rows[:, :, None] * width + cols[:, None, :]
    out += np.bincount(flat[valid], weights=patch[valid], minlength=height * width)
    return out.reshape(height, width)


def render_image(
    xy: ArrayLike,
    flux: ArrayLike,
    *,
    width: int,
    height: int,
    psf_sigma_px: float = 1.0,
    background: float = 100.0,
    read_noise: float = 5.0,
    shot_noise: bool = True,
    hot_pixels: int | ArrayLike = 0,
    hot_pixel_value: float | None = None,
    saturation: float | None = None,
    bit_depth: int = 16,
    rng: np.random.Generator | int | None = None,
) -> NDArray[np.unsignedinteger]:
    """Render a star image with noise, quantised like a camera's output.

    Parameters
    ----------
    xy : (N, 2) array_like
        Star positions (x, y) in px.
    flux : (N,) array_like
        Total counts per star (see :func:`flux_from_magnitude`).
    width, height : int
        Image size in px.
    psf_sigma_px : float
        Sigma of the circular Gaussian PSF (px).
    background : float
        Sky background (counts per pixel); it also carries shot noise.
    read_noise : float
        Gaussian read noise sigma (counts per pixel).
    shot_noise : bool
        Draw the counts from a Poisson distribution (else use the expectation).
    hot_pixels : int or (K, 2) array_like
        Number of hot pixels at random positions, or their integer (x, y) positions.
    hot_pixel_value : float, optional
        Counts a hot pixel adds; default a quarter of ``saturation``.
    saturation : float, optional
        Clip level (full well) in counts; default ``2**bit_depth - 1``.
    bit_depth : {8, 16}
        Output dtype uint8 or uint16.
    rng : numpy.random.Generator or int or None
        Random source or seed.

    Returns
    -------
    (height, width) uint8 or uint16
    """
    if bit_depth not in (8, 16):
        raise InvalidInputError("bit_depth", "must be 8 or 16")
    if width < 1 or height < 1 or width * height > 100_000_000:
        raise InvalidInputError("width", "image size must be between 1 and 1e8 pixels")
    if read_noise < 0 or background < 0:
        raise InvalidInputError("read_noise", "noise and background must be >= 0")
    top = float(2**bit_depth - 1)
    sat = top if saturation is None else float(min(saturation, top))
    gen = np.random.default_rng(rng)
    expected = render_expected(xy, flux, width=width, height=height, psf_sigma_px=psf_sigma_px,
                               background=background)
    img = gen.poisson(np.clip(expected, 0.0, None)).astype(np.float64) if shot_noise else expected
    if read_noise > 0:
        img = img + gen.normal(0.0, read_noise, size=img.shape)
    hot = _hot_positions(hot_pixels, width, height, gen)
    if hot.shape[0]:
        img[hot[:, 1], hot[:, 0]] += sat / 4.0 if hot_pixel_value is None else float(hot_pixel_value)
    np.clip(np.rint(img), 0.0, sat, out=img)
    return img.astype(np.uint8 if bit_depth == 8 else np.uint16)


def _hot_positions(
    hot_pixels: int | ArrayLike, width: int, height: int, gen: np.random.Generator
) -> NDArray[np.int64]:
    if np.ndim(hot_pixels) == 0:
        count = int(hot_pixels)  # type: ignore[arg-type]
        if count < 0:
            raise InvalidInputError("hot_pixels", "must be >= 0")
        flat = gen.choice(width * height, size=min(count, width * height), replace=False)
        return np.stack([flat % width, flat // width], axis=1).astype(np.int64)
    pos = np.asarray(hot_pixels, dtype=np.int64).reshape(-1, 2)
    if np.any((pos[:, 0] < 0) | (pos[:, 0] >= width) | (pos[:, 1] < 0) | (pos[:, 1] >= height)):
        raise InvalidInputError("hot_pixels", "positions must lie inside the image")
    return pos


def star_snr(flux: ArrayLike, *, psf_sigma_px: float = 1.0, background: float = 100.0,
             read_noise: float = 5.0, shot_noise: bool = True) -> FloatArray:
    """Optimal (PSF-weighted) signal-to-noise ratio of each star as :func:`render_image` draws it.

    ``SNR^2 = sum_i s_i^2 / var_i`` over the pixels of a star centred on a pixel, with ``s_i``
    its expected counts and ``var_i = s_i + background + read_noise^2`` (only ``read_noise^2``
    without shot noise). This is the SNR of an ideal PSF fit; a star's position can be measured
    to about ``psf_sigma_px / SNR`` per axis at best.

    Returns
    -------
    (N,) float64
    """
    f = np.atleast_1d(np.asarray(flux, dtype=np.float64))
    r = int(math.ceil(6.0 * psf_sigma_px)) + 1
    edges = np.arange(-r, r + 2) - 0.5
    p1 = np.diff(0.5 * (1.0 + erf(edges / (math.sqrt(2.0) * psf_sigma_px))))
    p = np.outer(p1, p1).ravel()  # (P,) fractions of the flux per pixel
    s = f[:, None] * p[None, :]
    var = (s + background + read_noise**2) if shot_noise else np.full_like(s, read_noise**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.sqrt(np.sum(np.where(var > 0, s * s / np.where(var > 0, var, 1.0), 0.0), axis=1))
    return np.asarray(out)


def random_positions(
    n: int,
    *,
    width: int,
    height: int,
    margin_px: float = 5.0,
    min_separation_px: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> FloatArray:
    """``n`` uniform random (x, y) positions at least ``margin_px`` inside the image, at least
    ``min_separation_px`` apart (dart throwing; fewer than ``n`` if the field is too full)."""
    gen = np.random.default_rng(rng)
    lo = np.array([margin_px, margin_px])
    span = np.array([width - 1 - 2 * margin_px, height - 1 - 2 * margin_px])
    if np.any(span <= 0):
        raise InvalidInputError("margin_px", "margin leaves no room in the image")
    if min_separation_px <= 0 or n < 2:
        return np.asarray(lo + gen.random((n, 2)) * span)
    kept = np.zeros((0, 2))
    for _ in range(20):
        new = lo + gen.random((2 * (n - len(kept)), 2)) * span
        if len(kept):  # drop candidates too close to a kept point
            dist, _ = cKDTree(kept).query(new, k=1)
            new = new[dist >= min_separation_px]
        pairs = cKDTree(new).query_pairs(min_separation_px, output_type="ndarray")
        drop = np.zeros(len(new), bool)
        drop[pairs[:, 1] if len(pairs) else []] = True  # of each close pair drop the later one
        kept = np.concatenate([kept, new[~drop]])[:n]
        if len(kept) == n:
            break
    return kept
