"""Screen candidate matches on chosen stars, then verify the best with every star that
screened (shared by ``pso`` and ``multifov``).

The verifier's own ``screen_and_check`` predicts the frame's brightest stars from a triangle.
When the hypothesis is compact in a wide field (``pso``'s stars lie within a few degrees of
each other in a 20 deg image) or spans two cameras (``multifov``'s masters), the method knows
better which stars to screen on: those near the hypothesis, or those of every camera. The
stars that land on a catalogue star join the hypothesis handed to ``Verifier.check``, so the
attitude it starts from is already spread over them.
"""

from __future__ import annotations

import numpy as np

from ..types import FloatArray, IntArray
from ..verify import Verified, star_tree
from .base import SolveContext

MAX_CHECKS = 8
"""At most this many screened candidates go on to full verification."""


def wahba_batch(obs: FloatArray, ref: FloatArray) -> FloatArray:
    """Rotations ``(K, 3, 3)`` best mapping each ``ref[k]`` ``(n, 3)`` onto ``obs`` ``(n, 3)``
    (SVD solution of Wahba's problem, vectorised over K; ``n >= 2``)."""
    b = np.einsum("ni,knj->kij", obs, ref)
    u, _, vt = np.linalg.svd(b)
    det = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    u[:, :, 2] *= det[:, None]
    return u @ vt


def screen_and_grow(ctx: SolveContext, obs_idx: IntArray, cands: IntArray, others: IntArray, *,
                    min_hits: int = 1) -> Verified | None:
    """Candidates ``cands`` ``(K, n)`` (catalogue rows) for observed rows ``obs_idx`` ``(n,)``:
    fit each one's attitude, predict the observed rows ``others`` and count those landing
    unambiguously on a catalogue star (one within the match radius, no other within twice
    it); verify the ``MAX_CHECKS`` best with at least ``min_hits`` hits, each with its hits
    added to the hypothesis. Every candidate counts as a trial of the coincidence bound."""
    verifier = ctx.verifier
    obs = ctx.obs
    obs_idx = np.asarray(obs_idx, np.int64)
    cands = np.asarray(cands, np.int64).reshape(-1, len(obs_idx))
    others = np.setdiff1d(np.asarray(others, np.int64), obs_idx)
    verifier.patterns += 1
    if len(cands) == 0:
        return None
    verifier.trials += len(cands)
    att = wahba_batch(obs.vec[obs_idx], verifier.db.stars.vec[cands])  # (K, 3, 3) ICRS -> body
    pred = np.einsum("kji,mj->kmi", att, obs.vec[others])  # (K, M, 3) ICRS
    radius = verifier.match_radius_px * obs.pixel_scale_rad
    if len(others):
        dist, near = star_tree(verifier.db).query(pred.reshape(-1, 3), k=2, distance_upper_bound=2 * radius)
        ok = ((dist[:, 0] <= radius) & ~np.isfinite(dist[:, 1])).reshape(len(cands), len(others))
        near = near[:, 0].reshape(len(cands), len(others))
    else:
        ok = np.zeros((len(cands), 0), bool)
        near = np.zeros((len(cands), 0), np.int64)
    hits = ok.sum(axis=1)
    for row in np.argsort(-hits, kind="stable")[:MAX_CHECKS]:
        if hits[row] < min_hits:
            break
        cat = np.concatenate([cands[row], near[row][ok[row]]])
        hyp = np.concatenate([obs_idx, others[ok[row]]])
        _, first = np.unique(cat, return_index=True)
        first = np.sort(first)
        verifier.trials -= 1  # check() counts itself
        found = verifier.check(hyp[first], cat[first])
        if found is not None:
            return found
    return None
