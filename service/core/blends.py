"""Close doubles: an observed blob that holds a bright star and a much fainter companion.

Two catalogue stars closer than about 1.5 px are one blob on the detector. The verifier pairs
only unambiguous stars, so such a blob is left out of the answer although its position is the
bright star's to within a fraction of a pixel when the companion is much fainter (a companion
1.5 mag fainter moves the flux-weighted centre by a fifth of their separation). This pass adds
those pairs to an attitude that is already proven: the blob is named as its brightest star
when every other catalogue star within the crowding radius is at least ``MIN_DELTA_MAG``
fainter and none of them lies farther than ``RESOLVED_PX`` from it (a star the detector would
have split off: the blob may be that one), and no other observed star competes for it.
The candidates include the stars predicted just past the image's edge, which crowd a blob but
are never named (``match.EDGE_CROWDS``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .types import FloatArray, IntArray

MIN_DELTA_MAG = 1.5
"""A companion at least this much fainter leaves the blob at the bright star's position."""
RESOLVED_PX = 2.0
"""Two catalogue stars farther apart than this (px) are two blobs on the detector (a star
camera's defocused image is ~1.5-2 px across). A blob within the match radius of two such
stars may be either of them, so it is not named: at the image border, the bright one's own blob
can fall off the detector while the faint one stays (the six wrong stars of 100,000 frames of
``bench.bench_wrong``, session 8: a blob 0.6-6 px from a 5.1-6.4 Mv star named as a 2.8-5.9 Mv
star 1.1-7 px away, past or at the border)."""


def dominant_pairs(obs_xy: FloatArray, free_obs: IntArray, pred_xy: FloatArray, pred_mag: FloatArray,
                   free_pred: np.ndarray, radius_px: float, crowd: float = 2.0,
                   min_delta_mag: float = MIN_DELTA_MAG) -> tuple[IntArray, IntArray]:
    """Pairs ``(observed row, predicted row)`` for blobs dominated by one catalogue star.

    Parameters
    ----------
    obs_xy : (N, 2)
        Observed positions (px) of one camera.
    free_obs : (k,) int
        Rows of ``obs_xy`` not yet paired.
    pred_xy, pred_mag : (M, 2), (M,)
        Predicted positions (px) and magnitudes of the catalogue stars in the image.
    free_pred : (M,) bool
        Predicted stars not yet paired.
    radius_px, crowd : float
        The verifier's match radius and crowding factor.
    """
    free = np.ascontiguousarray(free_pred, dtype=np.bool_)
    o, p, n = dominant_kernel(np.ascontiguousarray(obs_xy, dtype=np.float64), np.ascontiguousarray(free_obs, np.int64),
                              np.ascontiguousarray(pred_xy, dtype=np.float64).reshape(-1, 2),
                              np.ascontiguousarray(pred_mag, dtype=np.float64), free, float(radius_px), float(crowd),
                              float(min_delta_mag))
    free_pred[...] = free
    return o[:n].copy(), p[:n].copy()


@njit(cache=True, nogil=True)
def dominant_kernel(obs_xy: np.ndarray, free_obs: np.ndarray, pred_xy: np.ndarray, pred_mag: np.ndarray,
                    free_pred: np.ndarray, radius_px: float, crowd: float,
                    min_delta_mag: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Compiled body of :func:`dominant_pairs`: ``(obs rows, pred rows, count)``; clears the
    ``free_pred`` entries it pairs."""
    out_o = np.empty(len(free_obs), np.int64)
    out_p = np.empty(len(free_obs), np.int64)
    n_out = 0
    if len(free_obs) == 0 or len(pred_xy) == 0:
        return out_o, out_p, 0
    wide = crowd * radius_px
    d = np.empty(len(pred_xy))
    for k in range(len(free_obs)):
        i = free_obs[k]
        best = -1
        for j in range(len(pred_xy)):
            d[j] = math.hypot(obs_xy[i, 0] - pred_xy[j, 0], obs_xy[i, 1] - pred_xy[j, 1])
            if d[j] <= radius_px and (best < 0 or pred_mag[j] < pred_mag[best]):
                best = j
        if best < 0 or not free_pred[best]:
            continue
        crowded = False
        for j in range(len(pred_xy)):
            if j == best or d[j] > wide:
                continue
            # not much fainter, or one the detector splits from the bright one (the blob may be its image)
            if pred_mag[j] - pred_mag[best] < min_delta_mag or \
                    math.hypot(pred_xy[j, 0] - pred_xy[best, 0], pred_xy[j, 1] - pred_xy[best, 1]) > RESOLVED_PX:
                crowded = True
                break
        if crowded:
            continue
        # no other observed star may lie as near the bright star's prediction
        rivals = 0
        for r in range(len(obs_xy)):
            if math.hypot(obs_xy[r, 0] - pred_xy[best, 0], obs_xy[r, 1] - pred_xy[best, 1]) <= wide:
                rivals += 1
        if rivals != 1:
            continue
        out_o[n_out] = i
        out_p[n_out] = best
        n_out += 1
        free_pred[best] = False
    return out_o, out_p, n_out
