"""Position consistency of identified stars: a pair whose observed star lies farther from its
catalogue star than the frame's centroid noise allows is a false detection paired by position.

The match radius has a floor (2.5 px) so that a frame whose declared noise is too small still
pairs its stars; at a declared 0.25 px that floor is 10 sigma, and a false detection landing
within it of a catalogue star is paired (found by ``python -m bench.bench_wrong``: the right
attitude with one false star named after a faint catalogue star). After the fit, the frame's
own noise is known: ``sigma = max(declared, measured)``, the measured one robust
(``sqrt(median(d^2) / ln 4)``, the median of a 2-D Gaussian's squared distance being
``2 ln 2 sigma^2``). A pair is refused when its distance ``d`` is

- beyond ``Z_ANY`` sigma (a real star: probability ``exp(-Z^2 / 2)``, 4e-6 at 5), or
- beyond ``Z_FAINTEST`` sigma and its catalogue star is fainter than every other pair's: the
  faintest pair is where a false detection lands most often (most catalogue stars are faint,
  and one fainter than everything else the frame shows is past the camera's reach), and there
  a distant position is more likely a coincidence than a real star's error (a uniform landing
  within the radius against a Rayleigh tail: about 5:1 at 2.5 sigma for a 3-sigma radius);
  beyond ``Z_BEYOND`` sigma when it is also fainter than every other pair by ``GAP_MAG`` or
  more (past the magnitude the rest of the frame reaches: a real star seldom is);
- beyond ``Z_OUTSIDE`` sigma when its catalogue star is predicted outside the image under the
  answer's attitude. The pairing pairs only predictions inside (the final fit can move one
  out), and a real star's blob lies farther inside than its prediction only by its centroid
  error, while a false detection near the edge lands anywhere: seed 000's camera at 0.5 px
  named a false star 2.5 px (5 sigma) from a 5.5-Mv star predicted 1.3 px outside the image,
  whose distance the test did not see (``python -m bench.bench_wrong --frames 100000 --seed 21``).

Refusing a real star costs one identified star; keeping a false one is a wrong answer.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .medians import median
from .types import FloatArray

Z_ANY = 5.0
"""Distance (sigma) beyond which any pair is refused."""
Z_FAINTEST = 2.5
"""Distance (sigma) beyond which the pair of the faintest catalogue star is refused."""
Z_BEYOND = 2.0
"""Distance (sigma) beyond which the faintest pair is refused when it is ``GAP_MAG`` fainter
than every other pair."""
Z_OUTSIDE = 2.0
"""Distance (sigma) beyond which a pair whose catalogue star is predicted outside the image is
refused."""
GAP_MAG = 0.3
"""Magnitudes by which the faintest pair must pass every other pair for ``Z_BEYOND``."""
MIN_PAIRS = 6
"""Fewer pairs than this are not tested (too few to know the frame's noise or its faintest star)."""


def distant_pairs(d_px: FloatArray, pair_mag: FloatArray, sigma_px: float,
                  outside: np.ndarray | None = None) -> np.ndarray:
    """Mask of pairs too far from their catalogue star for the frame's noise.

    ``d_px`` are the distances (px) of the observed stars from their catalogue stars projected
    under the answer's attitude (NaN: unknown, never refused), ``pair_mag`` the catalogue
    magnitudes, ``sigma_px`` the declared centroid error per axis (px), ``outside`` which
    catalogue stars are predicted outside the image (default: none). Compiled:
    :func:`distant_kernel`.
    """
    d = np.ascontiguousarray(d_px, dtype=np.float64)
    out = np.zeros(len(d), np.bool_) if outside is None else np.ascontiguousarray(outside, dtype=np.bool_)
    return distant_kernel(d, np.ascontiguousarray(pair_mag, dtype=np.float64), float(sigma_px), out)


@njit(cache=True, nogil=True)
def distant_kernel(d_px: np.ndarray, pair_mag: np.ndarray, sigma_px: float, outside: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`distant_pairs` (the frame's noise measured on the pairs inside)."""
    n = len(d_px)
    out = np.zeros(n, np.bool_)
    known = d_px[np.isfinite(d_px) & ~outside]
    if len(known) < MIN_PAIRS:
        return out
    measured = math.sqrt(median(known * known) / math.log(4.0))
    sigma = max(measured, sigma_px)
    faintest, second = -np.inf, -np.inf
    at = -1
    for i in range(n):
        if pair_mag[i] > faintest:
            second, faintest, at = faintest, pair_mag[i], i
        elif pair_mag[i] > second:
            second = pair_mag[i]
    for i in range(n):
        if not np.isfinite(d_px[i]):
            continue
        z = d_px[i] / sigma
        if i == at and faintest > second:
            limit = Z_BEYOND if faintest - second >= GAP_MAG else Z_FAINTEST
        else:
            limit = Z_ANY
        if outside[i]:
            limit = min(limit, Z_OUTSIDE)
        if z > limit:
            out[i] = True
    return out


__all__ = ["GAP_MAG", "MIN_PAIRS", "Z_ANY", "Z_BEYOND", "Z_FAINTEST", "Z_OUTSIDE", "distant_kernel", "distant_pairs"]
