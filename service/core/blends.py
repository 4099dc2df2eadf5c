"""Close doubles: an observed blob that holds a bright star and a much fainter companion.

Two catalogue stars closer than about 1.5 px are one blob on the detector. The verifier pairs
only unambiguous stars, so such a blob is left out of the answer although its position is the
bright star's to within a fraction of a pixel when the companion is much fainter (a companion
1.5 mag fainter moves the flux-weighted centre by a fifth of their separation). This pass adds
those pairs to an attitude that is already proven: the blob is named as its brightest star
when every other catalogue star within the crowding radius is at least ``MIN_DELTA_MAG``
fainter and no other observed star competes for it.
"""

from __future__ import annotations

import numpy as np

from .types import FloatArray, IntArray

MIN_DELTA_MAG = 1.5
"""A companion at least this much fainter leaves the blob at the bright star's position."""


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
    out_o: list[int] = []
    out_p: list[int] = []
    if len(free_obs) == 0 or len(pred_xy) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    wide = crowd * radius_px
    # distances of every free observed star to every predicted one, at once
    d = np.hypot(obs_xy[free_obs, 0][:, None] - pred_xy[None, :, 0], obs_xy[free_obs, 1][:, None] - pred_xy[None, :, 1])
    for k in np.flatnonzero((d <= radius_px).any(axis=1)):
        i = int(free_obs[k])
        near = np.flatnonzero(d[k] <= wide)
        within = near[d[k, near] <= radius_px]
        best = within[np.argmin(pred_mag[within])]
        others = near[near != best]
        if not free_pred[best] or (len(others) and pred_mag[others].min() - pred_mag[best] < min_delta_mag):
            continue
        # no other observed star may lie as near the bright star's prediction
        rivals = np.hypot(obs_xy[:, 0] - pred_xy[best, 0], obs_xy[:, 1] - pred_xy[best, 1]) <= wide
        if rivals.sum() != 1:
            continue
        out_o.append(i)
        out_p.append(int(best))
        free_pred[best] = False
    return np.asarray(out_o, np.int64), np.asarray(out_p, np.int64)
