"""Brightness consistency of identified stars: a pair whose observed star is far brighter than
its catalogue star's magnitude allows is a false detection paired by position alone.

The camera's response is fitted as ``inst = a + b * mag`` (``inst = -2.5 log10(flux)``) by the
Theil-Sen estimator over the pairs, which bends to neither saturated bright stars nor a few
wrong pairs. A pair is refused when its observed star is brighter than the fit predicts by
more than ``max(threshold_mag, 4 robust sigma)``. Only this one direction is tested: a star
fainter than predicted is ordinary (saturation, a blend split by the catalogue, vignetting).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .types import FloatArray

THRESHOLD_MAG = 2.0
"""Least excess brightness (magnitudes) that refuses a pair."""
FIT_PAIRS = 24
"""At most this many pairs enter the response fit (all are judged)."""
MIN_PAIRS = 6
"""Fewer pairs than this are not tested (the fit would rest on the pair it judges)."""


@lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n, k=1)


def theil_sen(x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Theil-Sen line ``y = intercept + slope x``: the median of the pairwise slopes, then the
    intercept of the medians (what ``scipy.stats.theilslopes`` returns, ~100x faster for a few dozen
    points since it skips the confidence interval)."""
    i, j = _pairs(len(x))
    dx = x[j] - x[i]
    keep = dx != 0
    if not keep.any():
        return float("nan"), float("nan")
    slope = float(np.median((y[j] - y[i])[keep] / dx[keep]))
    return slope, float(np.median(y) - slope * np.median(x))


def too_bright(flux: FloatArray, cat_mag: FloatArray, *, threshold_mag: float = THRESHOLD_MAG,
               min_pairs: int = MIN_PAIRS) -> np.ndarray:
    """Mask of pairs whose observed star (``flux``, any linear unit) is brighter than the
    catalogue magnitude ``cat_mag`` (V) allows under the fitted response."""
    flux = np.asarray(flux, dtype=np.float64)
    mag = np.asarray(cat_mag, dtype=np.float64)
    out = np.zeros(len(flux), dtype=bool)
    ok = np.isfinite(flux) & (flux > 0) & np.isfinite(mag)
    if ok.sum() < min_pairs or np.ptp(mag[ok]) < 0.5:
        return out
    inst = -2.5 * np.log10(flux[ok])
    m = mag[ok]
    step = -(-len(m) // FIT_PAIRS)  # the fit on at most FIT_PAIRS evenly spread pairs: as robust, cheaper
    slope, intercept = theil_sen(m[::step], inst[::step])
    if not np.isfinite(slope) or slope <= 0:
        return out  # no usable brightness information (e.g. fluxes that are only a rank)
    resid = inst - (intercept + slope * mag[ok])  # negative: brighter than predicted
    sigma = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
    out[np.flatnonzero(ok)] = resid < -max(threshold_mag, 4.0 * sigma)
    return out


COMPLETENESS_MIN_MISSED = 6
"""Least number of unobserved brighter catalogue stars that makes a faint pair implausible."""
COMPLETENESS_MAX_MISSED_FRACTION = 0.5
"""A pair is implausible when more than this share of the catalogue stars in the field that are
brighter than it went unobserved (a partly obscured field loses a third, not most)."""
FAINT_GATE_MAG = 1.0
"""Only pairs fainter than the median pair by this much are tested."""


def beyond_completeness(pair_mag: FloatArray, field_mag: FloatArray, field_paired: np.ndarray) -> np.ndarray:
    """Mask of pairs whose catalogue star is fainter than the frame shows it could see.

    A camera that detects a star of magnitude ``m`` detects nearly every star brighter than
    ``m`` in its field. A pair whose catalogue star has most of the field's brighter stars
    unobserved is a false detection that fell near a faint catalogue star (a database deeper
    than the camera holds many). ``field_mag`` are the magnitudes of the catalogue stars
    predicted inside the image, ``field_paired`` which of them are paired.
    """
    pair_mag = np.asarray(pair_mag, dtype=np.float64)
    out = np.zeros(len(pair_mag), dtype=bool)
    if len(pair_mag) < 3:
        return out
    field_mag = np.asarray(field_mag, dtype=np.float64)
    missed_mag = np.sort(field_mag[~np.asarray(field_paired, dtype=bool)])
    paired_mag = np.sort(field_mag[np.asarray(field_paired, dtype=bool)])
    gate = float(np.median(pair_mag)) + FAINT_GATE_MAG
    for j in np.flatnonzero(pair_mag > gate):
        missed = int(np.searchsorted(missed_mag, pair_mag[j], side="left"))
        seen = int(np.searchsorted(paired_mag, pair_mag[j], side="left"))
        if missed >= COMPLETENESS_MIN_MISSED and missed > COMPLETENESS_MAX_MISSED_FRACTION * (missed + seen):
            out[j] = True
    return out
