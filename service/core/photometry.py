"""Brightness consistency of identified stars: a pair whose observed star is far brighter than
its catalogue star's magnitude allows is a false detection paired by position alone.

The camera's response is fitted as ``inst = a + b * mag`` (``inst = -2.5 log10(flux)``) by the
Theil-Sen estimator over the pairs, which bends to neither saturated bright stars nor a few
wrong pairs. A pair is refused when its observed star is brighter than the fit predicts by
more than ``max(threshold_mag, 4 robust sigma)``. Only this one direction is tested: a star
fainter than predicted is ordinary (saturation, a blend split by the catalogue, vignetting).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .medians import median
from .types import FloatArray

THRESHOLD_MAG = 2.0
"""Least excess brightness (magnitudes) that refuses a pair."""
FIT_PAIRS = 24
"""At most this many pairs enter the response fit (all are judged)."""
MIN_PAIRS = 6
"""Fewer pairs than this are not tested (the fit would rest on the pair it judges)."""


def theil_sen(x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Theil-Sen line ``y = intercept + slope x``: the median of the pairwise slopes, then the
    intercept of the medians (what ``scipy.stats.theilslopes`` returns, without its confidence
    interval)."""
    slope, intercept = _theil_sen(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(y, dtype=np.float64))
    return float(slope), float(intercept)


@njit(cache=True, nogil=True)
def _theil_sen(xs: np.ndarray, ys: np.ndarray) -> tuple[float, float]:
    k = len(xs)
    slopes = np.empty(k * (k - 1) // 2)
    n_s = 0
    for i in range(k):
        for j in range(i + 1, k):
            dx = xs[j] - xs[i]
            if dx != 0:
                slopes[n_s] = (ys[j] - ys[i]) / dx
                n_s += 1
    if n_s == 0:
        return np.nan, np.nan
    slope = median(slopes[:n_s])
    return slope, median(ys) - slope * median(xs)


def too_bright(flux: FloatArray, cat_mag: FloatArray, *, threshold_mag: float = THRESHOLD_MAG,
               min_pairs: int = MIN_PAIRS) -> np.ndarray:
    """Mask of pairs whose observed star (``flux``, any linear unit) is brighter than the
    catalogue magnitude ``cat_mag`` (V) allows under the fitted response (compiled:
    :func:`too_bright_kernel`)."""
    return too_bright_kernel(np.ascontiguousarray(flux, dtype=np.float64),
                             np.ascontiguousarray(cat_mag, dtype=np.float64), float(threshold_mag), int(min_pairs))


@njit(cache=True, nogil=True)
def too_bright_kernel(flux: np.ndarray, mag: np.ndarray, threshold_mag: float, min_pairs: int) -> np.ndarray:
    """Compiled body of :func:`too_bright` (the Theil-Sen fit on at most ``FIT_PAIRS`` evenly
    spread pairs: as robust, cheaper)."""
    n = len(flux)
    out = np.zeros(n, dtype=np.bool_)
    ok = np.empty(n, np.int64)
    n_ok = 0
    for i in range(n):
        if np.isfinite(flux[i]) and flux[i] > 0 and np.isfinite(mag[i]):
            ok[n_ok] = i
            n_ok += 1
    if n_ok < min_pairs:
        return out
    m = mag[ok[:n_ok]]
    if m.max() - m.min() < 0.5:
        return out
    inst = -2.5 * np.log10(flux[ok[:n_ok]])
    step = -(-n_ok // FIT_PAIRS)
    slope, intercept = _theil_sen(m[::step], inst[::step])
    if not np.isfinite(slope) or slope <= 0:
        return out  # no usable brightness information (e.g. fluxes that are only a rank)
    resid = inst - (intercept + slope * m)  # negative: brighter than predicted
    sigma = 1.4826 * median(np.abs(resid - median(resid)))
    limit = -max(threshold_mag, 4.0 * sigma)
    for i in range(n_ok):
        out[ok[i]] = resid[i] < limit
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
    predicted inside the image, ``field_paired`` which of them are paired (compiled:
    :func:`completeness_kernel`).
    """
    return completeness_kernel(np.ascontiguousarray(pair_mag, dtype=np.float64),
                               np.ascontiguousarray(field_mag, dtype=np.float64),
                               np.ascontiguousarray(field_paired, dtype=np.bool_))


@njit(cache=True, nogil=True)
def completeness_kernel(pair_mag: np.ndarray, field_mag: np.ndarray, field_paired: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`beyond_completeness`."""
    out = np.zeros(len(pair_mag), dtype=np.bool_)
    if len(pair_mag) < 3:
        return out
    missed_mag = np.sort(field_mag[~field_paired])
    paired_mag = np.sort(field_mag[field_paired])
    gate = median(pair_mag) + FAINT_GATE_MAG
    for j in range(len(pair_mag)):
        if pair_mag[j] <= gate:
            continue
        missed = np.searchsorted(missed_mag, pair_mag[j], side="left")
        seen = np.searchsorted(paired_mag, pair_mag[j], side="left")
        if missed >= COMPLETENESS_MIN_MISSED and missed > COMPLETENESS_MAX_MISSED_FRACTION * (missed + seen):
            out[j] = True
    return out


FAINTEST_BRIGHTER_THAN = 0.4
"""The catalogue-faintest pair is refused when its observed star is brighter than this share of
the other pairs' observed stars ..."""
FAINTEST_GAP_MAG = 0.05
"""... and its catalogue star is this much fainter than every other pair's (V mag)."""


def faintest_inverted(flux: FloatArray, pair_mag: FloatArray) -> np.ndarray:
    """Mask (at most one pair) of the pair whose catalogue star is fainter than every other
    pair's (by ``FAINTEST_GAP_MAG``) yet whose observed star outshines ``FAINTEST_BRIGHTER_THAN``
    of theirs.

    The faintest pair is where a false detection lands most often: most catalogue stars are
    faint, and a database deeper than the camera holds many the camera cannot see. A real star
    there is observed among the faintest (it needs a brightening of a magnitude or more to pass
    40 % of the frame's stars); a false detection has any brightness. Found by
    ``python -m bench.bench_wrong --frames 100000``: 11 of 17 wrong answers (the right attitude,
    a false star named after a catalogue star 0.06-0.45 mag past every other pair) were this.
    Compiled: :func:`faintest_inverted_kernel`.
    """
    return faintest_inverted_kernel(np.ascontiguousarray(flux, dtype=np.float64),
                                    np.ascontiguousarray(pair_mag, dtype=np.float64))


@njit(cache=True, nogil=True)
def faintest_inverted_kernel(flux: np.ndarray, pair_mag: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`faintest_inverted`."""
    n = len(flux)
    out = np.zeros(n, dtype=np.bool_)
    if n < MIN_PAIRS:
        return out
    at = 0
    for i in range(1, n):
        if pair_mag[i] > pair_mag[at]:
            at = i
    for i in range(n):
        if i != at and pair_mag[i] > pair_mag[at] - FAINTEST_GAP_MAG:
            return out  # not past every other pair
    if not (np.isfinite(flux[at]) and flux[at] > 0):
        return out
    outshone = 0
    for i in range(n):
        if i != at and flux[i] < flux[at]:
            outshone += 1
    out[at] = outshone >= FAINTEST_BRIGHTER_THAN * (n - 1)
    return out


def faintest_inverted_among(flux: FloatArray, pair_mag: FloatArray, bad: np.ndarray) -> np.ndarray:
    """:func:`faintest_inverted` of the pairs the other checks keep (``~bad``), as a mask of all
    pairs. The test weighs the faintest pair against the other pairs; a pair those checks drop
    is not one of them. Run on every pair, the faintest pair of a seed 003 frame (a false star
    named after a 6.35-Mv star, 2 px, 5 false stars) outshone 7 of 18 others, under the 40%; the
    19th, a 4.8-Mv pair another check dropped, then left it outshining 7 of 17 in the answer
    (``python -m bench.bench_wrong --frames 100000 --seed 2``). Compiled:
    :func:`faintest_inverted_among_kernel`."""
    return faintest_inverted_among_kernel(np.ascontiguousarray(flux, dtype=np.float64),
                                          np.ascontiguousarray(pair_mag, dtype=np.float64),
                                          np.ascontiguousarray(bad, dtype=np.bool_))


@njit(cache=True, nogil=True)
def faintest_inverted_among_kernel(flux: np.ndarray, pair_mag: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`faintest_inverted_among`."""
    keep = np.flatnonzero(~bad)
    out = np.zeros(len(flux), dtype=np.bool_)
    got = faintest_inverted_kernel(flux[keep], pair_mag[keep])
    for i in range(len(keep)):
        out[keep[i]] = got[i]
    return out


BAND_MISSED = 2
"""The catalogue-faintest pair is refused when at least this many catalogue stars of the field,
unpaired, lie between it and the next-faintest pair in magnitude ..."""
SHARP_WINDOW_MAG = 0.3
SHARP_PAIRED = 0.9
"""... and the frame shows a sharp limit: this share of the field's stars within
``SHARP_WINDOW_MAG`` below the next-faintest pair (V) are paired."""


def faintest_past_missed(pair_mag: FloatArray, field_mag: FloatArray, field_paired: np.ndarray,
                         bad: np.ndarray) -> np.ndarray:
    """Mask (at most one pair) of the catalogue-faintest of the pairs the other checks keep
    (``~bad``) when ``BAND_MISSED`` or more of the field's catalogue stars (``field_mag``, V;
    ``field_paired``: which are paired) went unobserved between it and the next-faintest pair.

    A camera with a sharp limit that sees a star of magnitude ``m`` sees the field's stars just
    brighter than ``m``: a real faintest star has the stars between it and the next-faintest pair
    paired (the band is a few hundredths of a magnitude wide where stars are dense). A false
    detection that fell near a catalogue star past the camera's limit has every star of that band
    unseen: a 20-deg field at 6 Mv holds ~6 stars in 0.1 mag. :func:`beyond_completeness` weighs
    all the brighter stars, where a band of missed stars is a small share.

    Only a frame whose own stars show a sharp limit is tested (``SHARP_PAIRED`` of those within
    ``SHARP_WINDOW_MAG`` below the next-faintest pair paired). Where detection fades over a few
    tenths of a magnitude (colour, vignetting, noise), the faintest real star sits past unseen
    stars as often as a false one does: in a model field of 25-60 stars whose detection falls as a
    logistic of width 0.1-0.3 mag, the test without this gate refused the real faintest star in
    50-90 % of frames; with it 0-11 % (``/work/s33/soft.py``), and it then refuses next to no false pair either, which the
    magnitudes cannot tell apart there. At least ``MIN_PAIRS`` kept pairs. Compiled:
    :func:`faintest_past_missed_kernel`.
    """
    return faintest_past_missed_kernel(np.ascontiguousarray(pair_mag, dtype=np.float64),
                                       np.ascontiguousarray(field_mag, dtype=np.float64),
                                       np.ascontiguousarray(field_paired, dtype=np.bool_),
                                       np.ascontiguousarray(bad, dtype=np.bool_))


@njit(cache=True, nogil=True)
def faintest_past_missed_kernel(pair_mag: np.ndarray, field_mag: np.ndarray, field_paired: np.ndarray,
                                bad: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`faintest_past_missed`."""
    n = len(pair_mag)
    out = np.zeros(n, dtype=np.bool_)
    at = -1
    kept = 0
    for i in range(n):
        if not bad[i]:
            kept += 1
            if at < 0 or pair_mag[i] > pair_mag[at]:
                at = i
    if kept < MIN_PAIRS:
        return out
    next_mag = -np.inf
    for i in range(n):
        if not bad[i] and i != at and pair_mag[i] > next_mag:
            next_mag = pair_mag[i]
    missed = 0
    window = 0
    window_paired = 0
    for j in range(len(field_mag)):
        m = field_mag[j]
        if not field_paired[j] and next_mag < m < pair_mag[at]:
            missed += 1
        elif next_mag - SHARP_WINDOW_MAG <= m <= next_mag:
            window += 1
            window_paired += field_paired[j]
    out[at] = missed >= BAND_MISSED and window_paired >= SHARP_PAIRED * window
    return out
