"""A uniquely matched triangle proven together with the frame's other stars.

The shortcut of :func:`~service.core.sparse_proof.check_unique_triangle` for a 4-star frame
whose fourth star the match explains. The full proof counts, in a density box ~100 tolerances
wide (thousands of catalogue triples), the triangles whose attitude would also explain that
star, and nearly always finds none: its bound is then set by the Poisson floor of an empty
count, ``k_up(0) (delta / W)^3``, so only a box that wide can pass it. Here the other stars
enter as the shared verifier's binomial tail instead (:mod:`service.core.verify`): under the
null hypothesis (the observed triangle unrelated to the sky), the catalogue triangles within
``delta`` on all three sides number ``lambda`` on average, and each such triangle's attitude
pairs the frame's other stars as it pairs random points, with chance ``tail = P[Binomial(n_free,
p) >= n_extra]``. So ``P <= n_looks * lambda * tail``.

``lambda`` is bounded from the box the caller already searched: the match was alone within
``eps`` (the pattern tolerance) on all three sides, so the box of half-width ``eps`` holds no
other triple (k = 0) and ``lambda <= k_up(0) (delta / eps)^3`` at ``SPARSE_CONFIDENCE``.
Where that is not enough, one small box is read at the width where an empty count would pass
with room (a few triples, not thousands), and its own count is used. The result is reported
with a factor of 2 for trying this test before the full one.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.special import betainc, gammaincinv

from .attitude import wahba_svd
from .star_index import star_vec64
from .types import FloatArray, IntArray
from .verify import Verified, Verifier

SPARSE_CONFIDENCE = 0.95
"""Confidence of the Poisson upper bound on the density of catalogue triangles (this test's and the
full proof's, :mod:`service.core.sparse_proof`)."""
K_UP_EMPTY = float(gammaincinv(1, SPARSE_CONFIDENCE))
"""The Poisson upper bound at ``SPARSE_CONFIDENCE`` on a count of none (3.0)."""
TESTS = 2
"""Tests a unique triangle may pass (this one, then the full proof): the factor on this one's bound."""
BOX_ROOM = 8.0
"""The small box is read where an empty count would give ``max_false_prob / BOX_ROOM``."""
BOX_MAX_EPS = 12.0
"""The small box's half-width stays at most this many pattern tolerances (the full proof's first box)."""


def prove_with_others(verifier: Verifier, r: FloatArray, obs_idx: IntArray, cat_idx: IntArray, delta: float,
                      n_looks: int, unique_within_rad: float,
                      sample_box: Callable[[float], IntArray] | None = None,
                      max_width_rad: float = math.inf,
                      pairing: tuple[IntArray, IntArray, float] | None = None) -> Verified | None:
    """The triangle ``obs_idx -> cat_idx`` (attitude ``r``, ICRS -> body; largest side mismatch
    ``delta``, rad) proven with the frame's other stars, or None (the full proof may still).

    Parameters
    ----------
    unique_within_rad : float
        Half-width (rad) of the box on the three sides in which the caller found this match and
        no other triple (same vertex order and handedness).
    sample_box : callable, optional
        ``sample_box(W)``: the catalogue triples (K, 3) within ``W`` (rad) of the observed sides,
        the match among them. None: only the caller's box is used.
    max_width_rad : float
        The widest box read (the full proof's limit: a quarter of the shortest side).
    pairing : (obs rows, catalogue rows, p), optional
        ``verifier._match_all(r)``, if the caller has it.
    """
    obs = verifier.obs
    if not 0 < delta <= unique_within_rad:
        return None
    m_obs, m_cat, p_single = verifier._match_all(r) if pairing is None else pairing
    mine = set(np.asarray(obs_idx).tolist())
    if not mine <= set(m_obs.tolist()):
        return None
    n_extra = len(m_obs) - 3
    n_free = len(obs) - 3
    if n_extra < 1 or n_free < n_extra:
        return None
    tail = float(betainc(n_extra, n_free - n_extra + 1, min(float(p_single), 1.0)))
    factor = TESTS * max(n_looks, 1) * tail
    limit = verifier.max_false_prob
    prob = factor * K_UP_EMPTY * (delta / unique_within_rad) ** 3
    if prob > limit and sample_box is not None:
        width = delta * (BOX_ROOM * factor * K_UP_EMPTY / limit) ** (1 / 3)
        width = min(width, BOX_MAX_EPS * unique_within_rad, max_width_rad)
        if width > unique_within_rad:
            box = np.asarray(sample_box(width), dtype=np.int64).reshape(-1, 3)
            k = int(np.count_nonzero((box != np.asarray(cat_idx)).any(axis=1)))  # the match left out
            prob = factor * float(gammaincinv(k + 1, SPARSE_CONFIDENCE)) * (delta / width) ** 3
    if prob > limit:
        return None
    stars = star_vec64(verifier.db)
    return Verified(m_obs, m_cat, wahba_svd(obs.vec[m_obs], stars[m_cat]), min(prob, 1.0), max(n_looks, 1))


__all__ = ["K_UP_EMPTY", "SPARSE_CONFIDENCE", "TESTS", "prove_with_others"]
