"""Star detection and sub-pixel centroiding: image -> :class:`Detections`.

The chain (after the seed paper's "filtering, threshold segmentation, connected components"):

1. **Matched filter** (detection only): a Gaussian of ``filter_sigma_px`` (about the PSF sigma)
   lifts faint stars out of pixel noise; centroids are measured on the unfiltered pixels.
2. **Local background and noise** per tile (``background_kernel_px``): median and
   ``1.4826 * MAD`` of a subsample, median-smoothed over 3 x 3 tiles, bilinear between tiles
   (:mod:`.background`).
3. **Threshold** the filtered image at ``background + sigma_threshold * sigma`` (both of the
   filtered image, so correlated noise is accounted for).
4. **Connected components** (8-connected) of the sparse mask pixels (:mod:`.sparse`); per-blob
   area, extent, peak and centre of light are reduced over the mask pixels, never the full
   frame. Blobs holding several
   prominent maxima of the filtered image are **deblended** into one source per maximum
   (:mod:`.blobs`).
5. Reject sources of implausible blob area and **hot pixels**: a spike whose 8 neighbours hold
   almost nothing, relative to it (``1 - mean8 / centre > max_sharpness``) or within their noise.
   Flag **saturated** sources.
6. Reject **non-stellar blobs**: sources whose SNR is below ``min_significance_ratio`` of what
   a compact source of the same flux reaches in this frame (wider than the PSF, or in clutter
   such as lit foliage; :mod:`.stellar`).
7. **Centroid**: Gaussian-windowed centroid of the background-subtracted raw pixels (SExtractor's
   ``XWIN``: unbiased for symmetric PSFs, near-optimal noise), started from the blob's centre of
   light; a lone saturated blob keeps its centre of light.
8. Sort by windowed flux (brightest first) and keep ``max_stars``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..types import Centroids
from .background import tile_statistics
from .blobs import find_sources
from .measure import gather_stamps, psf_sigma_from_stamps, sharpness, windowed_centroid
from .sparse import label_pixels, threshold_pixels
from .stellar import quiet_noise, significance_deficit

__all__ = ["Detections", "extract"]

FloatArray = NDArray[np.float64]

# A spike whose 8 neighbours average less than 2 of their own noise sigmas (sigma / sqrt(8))
# above background has no PSF around it.
_HOT_NOISE = 2.0 / math.sqrt(8.0)
# Centroid window: 0.9 x the PSF sigma (the estimate runs ~7 % high), but never narrower than
# 1.2 px, where the windowed centroid starts to lock onto pixel centres (0.1 px bias for a
# 0.6 px PSF with a matched window, 0.007 px with a 1.2 px one; see docs/centroiding.md).
_WINDOW_PER_PSF = 0.9
_MIN_WINDOW_PX = 1.2
_WHITE_RATIO = 1.25


@dataclass(frozen=True, slots=True)
class Detections:
    """Stars found in one image, brightest first.

    Attributes
    ----------
    centroids : Centroids
        ``xy`` (N, 2) float64 px (x = column, y = row, centre of the top-left pixel at (0, 0))
        and ``flux`` (N,) float64 in image units: the Gaussian-windowed flux scaled to the total
        of a Gaussian star of the estimated PSF sigma (far less noisy than an aperture sum), or
        for a lone saturated star the sum of its blob.
    saturated : (N,) bool
        Some pixel of the star reached ``saturation``; its centroid is the plain
        intensity-weighted centre and less accurate.
    area_px : (N,) int64
        Pixels of the star's blob above the detection threshold (shared by deblended stars).
    peak : (N,) float64
        Highest raw pixel of the star above the local background (image units).
    snr : (N,) float64
        Detection significance: peak of the matched-filtered image above background, in units
        of its local noise sigma.
    background : (N,) float64
        Local background level under the star (image units).
    background_sigma : (N,) float64
        Local pixel noise sigma around the star (image units).
    """

    centroids: Centroids
    saturated: NDArray[np.bool_]
    area_px: NDArray[np.int64]
    peak: FloatArray
    snr: FloatArray
    background: FloatArray
    background_sigma: FloatArray

    def __len__(self) -> int:
        return len(self.centroids)

    @classmethod
    def empty(cls) -> Detections:
        z = np.zeros(0)
        return cls(Centroids(np.zeros((0, 2)), z.copy()), np.zeros(0, bool), np.zeros(0, np.int64),
                   z.copy(), z.copy(), z.copy(), z.copy())


def extract(
    image: NDArray[Any],
    *,
    sigma_threshold: float = 5.0,
    filter_sigma_px: float | None = 1.0,
    background_kernel_px: int = 64,
    min_area_px: int = 2,
    max_area_px: int = 2500,
    max_stars: int | None = 200,
    saturation: float | None = None,
    max_sharpness: float | None = 0.95,
    window_sigma_px: float | None = None,
    min_significance_ratio: float | None = 0.4,
) -> Detections:
    """Detect stars and measure their sub-pixel centroids.

    Parameters
    ----------
    image : (H, W) ndarray
        Monochrome pixels: uint8, uint16 (kept native), other integers or floats.
    sigma_threshold : float
        Detection threshold in local noise sigmas of the (filtered) detection image.
    filter_sigma_px : float or None
        Sigma (px) of the Gaussian matched filter used for detection; ``None`` or 0 thresholds
        the raw pixels. Raise it (e.g. 1.5) for wide or very faint, noisy stars.
    background_kernel_px : int
        Tile side (px) over which background and noise are estimated.
    min_area_px, max_area_px : int
        Accepted blob areas (pixels above threshold).
    max_stars : int or None
        Keep at most this many stars, brightest first (``None``: all).
    saturation : float or None
        Pixel value at which a star counts as saturated; default the dtype's maximum for
        integer images and no flagging for float images.
    max_sharpness : float or None
        Hot-pixel cut on ``1 - mean(8 neighbours) / centre`` (0.5 for a 1 px Gaussian PSF,
        0.85 for 0.5 px, ~1 for a hot pixel); spikes whose neighbours are within 2 sigma of the
        background are rejected too. ``None`` keeps every spike.
    window_sigma_px : float or None
        Sigma (px) of the centroiding window; default ``max(1.2, 0.9 * PSF sigma)`` with the PSF
        sigma estimated from the most significant stars.
    min_significance_ratio : float or None
        Reject unsaturated sources whose ``snr / flux`` is below this fraction of the frame's
        reference (the 90th percentile over sources of SNR >= 10): blobs wider than the PSF or
        in clutter (branches, lit foliage). ``None`` keeps them.

    Returns
    -------
    Detections
        Brightest first.

    Raises
    ------
    InvalidInputError
        ``image`` is not a non-empty 2-D real array, or a knob is out of range.
    """
    img = _validate_image(image)
    _check_knobs(sigma_threshold, filter_sigma_px, background_kernel_px, min_area_px, max_area_px,
                 max_stars, max_sharpness, window_sigma_px, min_significance_ratio)
    height, width = img.shape
    tile = int(background_kernel_px)
    raw_grid = tile_statistics(img, tile_px=tile)
    quant = 1.0 if img.dtype.kind in "ui" else 0.0
    raw_floor = max(quant / math.sqrt(12.0), _float_floor(img) if quant == 0.0 else 0.0)
    raw_sigma = np.maximum(raw_grid.sigma, raw_floor)

    det, det_norm = _detection_image(img, filter_sigma_px, float(np.median(raw_sigma)))
    det_grid = tile_statistics(det, tile_px=tile)
    det_floor = raw_floor * det_norm if det.dtype.kind == "f" else 0.5
    det_sigma = np.maximum(det_grid.sigma, det_floor)
    thr_grid = det_grid.level + np.float32(sigma_threshold) * det_sigma
    # Integer detection image: raw counts d > t <=> d > floor(t); a filtered image rounded to
    # whole counts, round(v) > floor(t + 1/2) <=> v >= floor(t + 1/2) + 1/2 >= t.
    shift = None if det.dtype.kind == "f" else (0.5 if det is not img else 0.0)
    lin = threshold_pixels(det, det_grid, thr_grid, shift=shift)
    n_labels, labels = label_pixels(lin, width)
    if n_labels == 0:
        return Detections.empty()
    sat_level = _saturation_level(img, saturation)
    src = find_sources(lin, labels, img, det, raw_grid, det_grid, det_sigma, saturation=sat_level)
    cand = np.flatnonzero((src.area >= min_area_px) & (src.area <= max_area_px))
    if max_stars is not None:  # measure only the most significant candidates
        cand = cand[np.argsort(-src.height[cand], kind="stable")[: max(1000, 5 * max_stars)]]
    if cand.size == 0:
        return Detections.empty()
    src = src.take(cand)

    px, py = src.x, src.y
    bkg = raw_grid.at(raw_grid.level, px, py)
    bkg_sigma = raw_grid.at(raw_sigma, px, py)
    snr = src.height / det_grid.at(det_sigma, px, py)
    small, _ = gather_stamps(img, px, py, 3)  # 7x7 raw pixels around each filtered peak
    # Saturation: anywhere in a lone blob; in a blended blob, next to the source's own peak.
    saturated = np.zeros(len(src), bool)
    if sat_level is not None:
        saturated = np.where(src.n_peaks == 1, src.raw_max >= sat_level,
                             small[:, 2:5, 2:5].max(axis=(1, 2)) >= sat_level)
    small -= bkg[:, None, None]
    peak = np.where(src.n_peaks == 1, src.raw_max - bkg, small[:, 2:5, 2:5].max(axis=(1, 2)))

    # Hot pixels: the 8 neighbours hold (almost) nothing, relative to the centre or within
    # their noise.
    hot = np.zeros(len(src), bool)
    if max_sharpness is not None:
        centre, mean8 = sharpness(small)
        hot = (centre > 0) & ((mean8 < (1.0 - max_sharpness) * centre) | (mean8 < _HOT_NOISE * bkg_sigma))
    star = ~hot
    good = star & ~saturated
    psf_sigma = _estimate_psf_sigma(small[good], snr[good], filter_sigma_px)
    sigma_w = window_sigma_px or max(_MIN_WINDOW_PX, _WINDOW_PER_PSF * psf_sigma)

    # Centroids: Gaussian-windowed, started from the blob's centre of light (lone blobs) or the
    # peak (blended ones). A lone saturated blob keeps its centre of light; a blended saturated
    # one gets a window as wide as its saturated core.
    xy = np.stack([src.cog_x, src.cog_y], axis=1).astype(np.float64)
    flux = src.mask_flux.copy()
    single = src.n_peaks == 1
    core = np.sqrt(src.n_saturated / np.pi)
    for group in (star & ~saturated, star & saturated & ~single):
        if not group.any():
            continue
        idx = np.flatnonzero(group)
        sig = np.maximum(sigma_w, np.where(saturated[idx], core[idx], 0.0))
        radius = max(3, int(math.ceil(4.0 * sig.max())))
        stamps, valid = gather_stamps(img, px[idx], py[idx], radius)
        stamps -= bkg[idx, None, None]
        stamps[~valid] = 0.0
        x0 = np.where(single[idx], src.cog_x[idx] - px[idx], 0.0)
        y0 = np.where(single[idx], src.cog_y[idx] - py[idx], 0.0)
        xw, yw, weighted, ok = windowed_centroid(stamps, valid, x0, y0, window_sigma_px=sig)
        xy[idx, 0] = px[idx] + np.where(ok, xw, x0)
        xy[idx, 1] = py[idx] + np.where(ok, yw, y0)
        flux[idx] = weighted * (psf_sigma**2 + sig**2) / sig**2  # total of a Gaussian star
    if min_significance_ratio is not None:
        # Clutter-free noise: at most that of the quiet tiles at this background level (shot
        # noise of glare is forgiven) and at most what white noise of the local raw sigma would
        # leave after the filter (texture survives the filter, pixel noise does not).
        ratio = det_sigma / raw_sigma  # filtered / raw noise: higher where texture, not pixel noise
        quiet = quiet_noise(det_grid.level, det_sigma, det_grid.at(det_grid.level, px, py),
                            ratio <= _WHITE_RATIO * float(np.median(ratio)))
        star &= ~significance_deficit(snr, flux, star & ~saturated, quiet, min_ratio=min_significance_ratio)

    sel = np.flatnonzero(star)
    sel = sel[np.argsort(-flux[sel], kind="stable")]
    if max_stars is not None:
        sel = sel[:max_stars]
    return Detections(
        centroids=Centroids(np.ascontiguousarray(xy[sel]), flux[sel].astype(np.float64)),
        saturated=saturated[sel],
        area_px=src.area[sel].astype(np.int64),
        peak=peak[sel],
        snr=snr[sel].astype(np.float64),
        background=bkg[sel].astype(np.float64),
        background_sigma=bkg_sigma[sel].astype(np.float64),
    )


# --------------------------------------------------------------------------- helpers


def _validate_image(image: NDArray[Any]) -> NDArray[Any]:
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InvalidInputError("image", f"expected a 2-D array, got shape {arr.shape}")
    if arr.shape[0] < 3 or arr.shape[1] < 3:
        raise InvalidInputError("image", f"image too small: {arr.shape}")
    if arr.dtype in (np.uint8, np.uint16):
        return np.ascontiguousarray(arr)
    if arr.dtype.kind not in "uifb":
        raise InvalidInputError("image", f"unsupported dtype {arr.dtype}")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    finite = np.isfinite(out)
    if not finite.all():
        if not finite.any():
            raise InvalidInputError("image", "no finite pixel values")
        out = np.where(finite, out, np.float32(np.median(out[finite])))
    return out


def _check_knobs(sigma_threshold: float, filter_sigma_px: float | None, background_kernel_px: int,
                 min_area_px: int, max_area_px: int, max_stars: int | None, max_sharpness: float | None,
                 window_sigma_px: float | None, min_significance_ratio: float | None) -> None:
    def bad(name: str, msg: str) -> InvalidInputError:
        return InvalidInputError(name, msg)

    if not (math.isfinite(sigma_threshold) and sigma_threshold > 0):
        raise bad("sigma_threshold", "must be a positive number")
    if filter_sigma_px is not None and not (math.isfinite(filter_sigma_px) and 0 <= filter_sigma_px <= 20):
        raise bad("filter_sigma_px", "must be in [0, 20] px or None")
    if not 4 <= int(background_kernel_px) <= 4096:
        raise bad("background_kernel_px", "must be in [4, 4096] px")
    if not 1 <= int(min_area_px) <= int(max_area_px):
        raise bad("min_area_px", "need 1 <= min_area_px <= max_area_px")
    if max_stars is not None and int(max_stars) < 1:
        raise bad("max_stars", "must be >= 1 or None")
    if max_sharpness is not None and not 0 < max_sharpness <= 1:
        raise bad("max_sharpness", "must be in (0, 1] or None")
    if window_sigma_px is not None and not (math.isfinite(window_sigma_px) and 0.2 <= window_sigma_px <= 20):
        raise bad("window_sigma_px", "must be in [0.2, 20] px or None")
    if min_significance_ratio is not None and not 0 < min_significance_ratio <= 1:
        raise bad("min_significance_ratio", "must be in (0, 1] or None")


def _float_floor(img: NDArray[Any]) -> float:
    """Noise floor for float images with (nearly) no noise: a tiny fraction of the range."""
    lo, hi = float(img.min()), float(img.max())
    return max(1e-6 * max(abs(lo), abs(hi)), 1e-30)


def _detection_image(img: NDArray[Any], filter_sigma_px: float | None,
                     raw_sigma: float) -> tuple[NDArray[Any], float]:
    """The (matched-filtered) image to threshold, and its white-noise gain sqrt(sum k^2)."""
    if not filter_sigma_px:
        return (img if img.dtype in (np.uint8, np.uint16) else img.astype(np.float32, copy=False)), 1.0
    ksize = 2 * int(math.ceil(3.0 * filter_sigma_px)) + 1
    k1 = cv2.getGaussianKernel(ksize, filter_sigma_px, cv2.CV_64F).ravel()
    norm = float(np.sum(k1**2))  # 2-D: sum(k^2) = (sum k1^2)^2, so sqrt = sum k1^2
    # Filter uint16 natively (fast, fixed point) only when the rounding to whole counts is
    # negligible against the filtered noise; otherwise work in float32.
    if img.dtype == np.uint16 and raw_sigma * norm >= 2.0:
        return cv2.GaussianBlur(img, (ksize, ksize), filter_sigma_px, borderType=cv2.BORDER_REFLECT), norm
    src = img if img.dtype == np.float32 else img.astype(np.float32)
    return cv2.GaussianBlur(src, (ksize, ksize), filter_sigma_px, borderType=cv2.BORDER_REFLECT), norm


def _saturation_level(img: NDArray[Any], saturation: float | None) -> float | None:
    if saturation is not None:
        return float(saturation)
    if img.dtype.kind in "ui":
        return float(np.iinfo(img.dtype).max)
    return None


def _estimate_psf_sigma(stamps: FloatArray, snr: FloatArray, filter_sigma_px: float | None) -> float:
    """Median PSF sigma of up to 30 of the most significant unsaturated stars (SNR >= 15, or
    >= 8 when there are none); the matched-filter sigma (or 1 px) when there is no such star."""
    fallback = float(filter_sigma_px) if filter_sigma_px else 1.0
    good = np.flatnonzero(snr >= 15.0)
    if good.size == 0:
        good = np.flatnonzero(snr >= 8.0)
    good = good[np.argsort(-snr[good])[:30]]
    sig = psf_sigma_from_stamps(stamps[good])
    sig = sig[np.isfinite(sig)]
    if sig.size == 0:
        return fallback
    return float(np.clip(np.median(sig), 0.6, 5.0))
