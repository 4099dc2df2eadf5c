"""A proven answer whose fit is pulled off by a few wrong pairs, moved to the basin its right pairs give.

A compact hypothesis in a wide field (``multifov``'s distance triangle on one camera: a star and
its two nearest neighbours of a 20-deg image) extrapolates its attitude poorly. Refitted while
the pairs grow, it can settle where a cluster of right pairs near the hypothesis and one or two
wrong pairs far from it balance: every residual 2-5 sigma, none an outlier, and the coincidence
bound passed (a cluster of right stars is no coincidence). Found by ``python -m
bench.bench_every_method`` on seed 004 (70 "/px, 0.5 px): 16 pairs, 14 right within 4 deg of
each other and 2 ten degrees away named after a neighbour of their star; residuals 19-188"
against 35" of noise; the attitude 576" off.

The sign is the fit's own noise: ``sigma = sqrt(median(d^2) / ln 4)`` over the pairs (the
median of a 2-D Gaussian's squared distance is ``2 ln 2 sigma^2``) far above the declared
centroid error. Then the attitude is fitted to every triple of pairs (at most
``MAX_TRIPLES``, a seeded sample), the triple whose fit holds the most pairs within
``INLIER_SIGMA`` declared sigma wins, the attitude is refitted to those pairs and every pair it
implies is found again (``Verifier.rematch``). The new basin replaces the answer only if it
keeps every one of those pairs and pairs more stars in all; otherwise the answer stands.
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
from numba import njit

from .attitude import wahba_batch, wahba_svd
from .medians import median
from .navdb.reader import NavDatabase
from .star_index import star_vec64
from .verify import Verified, Verifier

SUSPECT_SIGMA = 2.5
"""The fit's own noise (robust) over the declared centroid error beyond which it is re-examined."""
MIN_SIGMA_PX = 0.25
"""Declared errors below this (px) count as this (optics and blends leave ~0.1-0.2 px)."""
INLIER_SIGMA = 3.0
"""A pair lies on a triple's fit within this many declared sigma (per axis, as a distance)."""
MIN_PAIRS = 6
"""Answers of fewer pairs are left as they are (too few to tell a cluster from the rest)."""
MAX_TRIPLES = 600
"""Triples of pairs fitted at most (all of them up to 16 pairs; a seeded sample beyond)."""


def trimmed_basin(obs, db: NavDatabase, v: Verified, radius_px: float, sigma_px: float) -> Verified | None:
    """``v`` moved to the basin of its largest consistent cluster of pairs, or None when it stays
    (see the module's docstring). ``obs`` is the frame's :class:`~service.core.verify.Observation`,
    ``radius_px`` the match radius, ``sigma_px`` the declared centroid error."""
    n = len(v.obs)
    if n < MIN_PAIRS:
        return None
    sigma = max(float(sigma_px), MIN_SIGMA_PX)
    vec = star_vec64(db)
    if _robust_sigma_px(obs.vec, vec, np.asarray(v.obs, np.int64), np.asarray(v.cat, np.int64),
                        np.ascontiguousarray(v.matrix, np.float64), float(obs.pixel_scale_rad)) <= SUSPECT_SIGMA * sigma:
        return None  # the usual case: one compiled call (the numpy steps took ~20 us an answer)
    o = np.asarray(obs.vec[v.obs], np.float64)
    c = np.asarray(vec[v.cat], np.float64)
    triples = np.array(list(combinations(range(n), 3)), np.int64) if math.comb(n, 3) <= MAX_TRIPLES else \
        np.sort(np.random.default_rng(n).random((MAX_TRIPLES, n)).argsort(axis=1)[:, :3], axis=1)
    att = wahba_batch(o[triples], c[triples])  # (K, 3, 3)
    err = np.linalg.norm(np.einsum("kij,nj->kni", att, c) - o[None], axis=2) / obs.pixel_scale_rad
    inliers = err <= INLIER_SIGMA * sigma
    best = inliers[int(np.argmax(inliers.sum(axis=1)))]
    if best.sum() < 4 or best.all():
        return None
    verifier = Verifier(db, obs, match_radius_px=radius_px)
    ok, m_obs, m_cat, _, r = verifier.rematch(wahba_svd(o[best], c[best]))
    if not ok or len(m_obs) <= n:
        return None
    kept = set(zip(m_obs.tolist(), m_cat.tolist(), strict=True))
    if not all((int(a), int(b)) in kept for a, b in zip(v.obs[best], v.cat[best], strict=True)):
        return None
    return Verified(m_obs, m_cat, r, v.false_prob, v.n_trials)


@njit(cache=True, nogil=True)
def _robust_sigma_px(obs_vec: np.ndarray, star_vec: np.ndarray, obs_idx: np.ndarray, cat_idx: np.ndarray,
                     r: np.ndarray, pixel_scale: float) -> float:
    """The fit's own noise per axis, px: ``sqrt(median(d^2) / ln 4)`` over the pairs' distances
    ``d`` between observed and predicted (``r`` ICRS -> body) directions."""
    d2 = np.empty(len(obs_idx))
    for i in range(len(obs_idx)):
        o, c = obs_vec[obs_idx[i]], star_vec[cat_idx[i]]
        s = 0.0
        for a in range(3):
            e = r[a, 0] * c[0] + r[a, 1] * c[1] + r[a, 2] * c[2] - o[a]
            s += e * e
        d2[i] = s / (pixel_scale * pixel_scale)
    return math.sqrt(median(d2) / math.log(4.0))
