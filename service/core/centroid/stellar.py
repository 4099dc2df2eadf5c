"""Point-source test: is a source as significant as a star of its flux would be?

For a point source the matched-filter detection SNR is proportional to its flux divided by the
local noise, with one constant per frame (the PSF). A blob that is wider than the PSF (a lit
leaf, a branch edge, a patch of sky between branches) collects a star's flux in the centroid
window but a much lower filtered peak; a blob in clutter (foliage, where the local noise is
several times the sky's) has a high noise under its peak. Either way its SNR falls short of
``snr_per_flux * flux`` of the frame's compact sources on clean sky.

The reference ``snr_per_flux`` is a high quantile over the significant, unsaturated sources
(the most compact ones on the cleanest sky are point sources), so it holds up when most of the
detections are clutter: on ``cedar-solve/tree.jpg`` the stars reach 0.6-1.0 of the reference,
the foliage 0.1-0.6 (docs/centroiding.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["quiet_noise", "significance_deficit"]

FloatArray = NDArray[np.float64]

# Sources that set the reference: at least this SNR (a ratio measured to ~10 %), and at least
# this many of them, or the test is skipped.
_REF_MIN_SNR = 10.0
_REF_MIN_COUNT = 5
_REF_QUANTILE = 90.0
# Quiet-noise model: tiles sorted by background level, cut into up to this many bins of at
# least _BIN_TILES tiles; per bin the noise of its quietest quarter.
_MAX_BINS = 8
_BIN_TILES = 4
_QUIET_QUANTILE = 25.0


def quiet_noise(level: NDArray[Any], sigma: NDArray[Any], at_level: FloatArray,
                use: NDArray[np.bool_] | None = None) -> FloatArray:
    """Noise sigma that a tile of background ``at_level`` has without clutter.

    Shot noise grows with the background (glare, moonlight, twilight); clutter (foliage, a
    roof) raises the noise without raising the level much. Per bin of background level, the
    25th percentile of the tiles' noise variance, made non-decreasing with level, and
    interpolated.

    Parameters
    ----------
    level, sigma : (ny, nx) float
        Background level and noise sigma per tile (image units).
    at_level : (N,) float64
        Background levels to evaluate at (image units).

    Returns
    -------
    (N,) float64
        Quiet noise sigma (image units).
    """
    lv = np.asarray(level, np.float64).ravel()
    var = np.asarray(sigma, np.float64).ravel() ** 2
    if use is not None and np.count_nonzero(use) >= _BIN_TILES:
        lv, var = lv[use.ravel()], var[use.ravel()]
    order = np.argsort(lv, kind="stable")
    bins = max(1, min(_MAX_BINS, lv.size // _BIN_TILES))
    edges = np.linspace(0, lv.size, bins + 1).astype(np.intp)
    spans = list(zip(edges[:-1], edges[1:], strict=True))
    knots = np.array([np.median(lv[order[a:b]]) for a, b in spans])
    quiet = np.array([np.percentile(var[order[a:b]], _QUIET_QUANTILE) for a, b in spans])
    return np.asarray(np.sqrt(np.interp(at_level, knots, np.maximum.accumulate(quiet))))


def significance_deficit(
    snr: FloatArray, flux: FloatArray, usable: NDArray[np.bool_], quiet: FloatArray, *, min_ratio: float
) -> NDArray[np.bool_]:
    """Sources whose SNR is below ``min_ratio`` times that of a compact source of equal flux
    on a quiet background of the same level.

    Parameters
    ----------
    snr : (N,) float64
        Detection significance (matched-filter peak / local noise, dimensionless).
    flux : (N,) float64
        Windowed flux (image units).
    usable : (N,) bool
        Sources that may set the reference and may be rejected (e.g. not saturated: a
        saturated star's flux is a lower bound and its peak is clipped).
    quiet : (N,) float64
        Noise the source's background would have without clutter (:func:`quiet_noise`, in the
        units of the noise behind ``snr``): the test forgives the shot noise of a bright
        background, not clutter.
    min_ratio : float
        Least accepted ``(snr * quiet / flux) / reference`` (dimensionless, in (0, 1]).

    Returns
    -------
    (N,) bool
        True for a source to reject; all False when fewer than 5 usable sources reach SNR 10.
    """
    positive = usable & (flux > 0) & (quiet > 0)
    ref_pool = np.flatnonzero(positive & (snr >= _REF_MIN_SNR))
    if ref_pool.size < _REF_MIN_COUNT:
        return np.zeros(snr.shape, bool)
    score = snr * quiet / np.where(positive, flux, 1.0)
    ref = float(np.percentile(score[ref_pool], _REF_QUANTILE))
    return np.asarray(positive & (score < min_ratio * ref))
