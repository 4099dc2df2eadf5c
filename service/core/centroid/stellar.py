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

import numpy as np
from numpy.typing import NDArray

__all__ = ["significance_deficit"]

FloatArray = NDArray[np.float64]

# Sources that set the reference: at least this SNR (a ratio measured to ~10 %), and at least
# this many of them, or the test is skipped.
_REF_MIN_SNR = 10.0
_REF_MIN_COUNT = 5
_REF_QUANTILE = 90.0


def significance_deficit(
    snr: FloatArray, flux: FloatArray, usable: NDArray[np.bool_], *, min_ratio: float
) -> NDArray[np.bool_]:
    """Sources whose SNR is below ``min_ratio`` times that of a compact source of equal flux.

    Parameters
    ----------
    snr : (N,) float64
        Detection significance (matched-filter peak / local noise, dimensionless).
    flux : (N,) float64
        Windowed flux (image units).
    usable : (N,) bool
        Sources that may set the reference and may be rejected (e.g. not saturated: a
        saturated star's flux is a lower bound and its peak is clipped).
    min_ratio : float
        Least accepted ``(snr / flux) / reference`` (dimensionless, in (0, 1]).

    Returns
    -------
    (N,) bool
        True for a source to reject; all False when fewer than 5 usable sources reach SNR 10.
    """
    positive = usable & (flux > 0)
    ref_pool = np.flatnonzero(positive & (snr >= _REF_MIN_SNR))
    if ref_pool.size < _REF_MIN_COUNT:
        return np.zeros(snr.shape, bool)
    ref = float(np.percentile(snr[ref_pool] / flux[ref_pool], _REF_QUANTILE))
    return np.asarray(positive & (snr < min_ratio * ref * flux))
