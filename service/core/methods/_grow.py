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

from ..attitude import wahba_batch
from ..star_index import star_tree
from ..types import FloatArray, IntArray
from ..verify import Verified
from .base import SolveContext

MAX_CHECKS = 8
"""At most this many screened candidates go on to full verification."""
SCREEN_STARS = 8
"""Candidates are screened on this many stars (the nearest to the hypothesis)."""


def screen_and_grow(ctx: SolveContext, obs_idx: IntArray, cands: IntArray, others: IntArray, *,
                    min_hits: int = 1) -> Verified | None:
    """Candidates ``cands`` ``(K, n)`` (catalogue rows) for observed rows ``obs_idx`` ``(n,)``:
    fit each one's attitude, predict the ``SCREEN_STARS`` rows of ``others`` nearest the first
    hypothesis star and count those landing unambiguously on a catalogue star (one within the
    match radius, no other within twice it). The ``MAX_CHECKS`` best with at least
    ``min_hits`` hits grow outwards over the rest of ``others`` (refit, predict the next
    ring, keep the unambiguous hits) and go to ``Verifier.check`` with every star they
    gathered. Every candidate counts as a trial of the coincidence bound.

    Growing ring by ring keeps the extrapolation short: a compact hypothesis with 1 px of
    noise predicts stars 5 deg away several pixels off, where a wrong catalogue star can be
    the only one in reach; refitted on the near stars first, it lands on the right ones.
    """
    verifier = ctx.verifier
    obs = ctx.obs
    obs_idx = np.asarray(obs_idx, np.int64)
    cands = np.asarray(cands, np.int64).reshape(-1, len(obs_idx))
    others = np.setdiff1d(np.asarray(others, np.int64), obs_idx)
    others = others[np.argsort(-(obs.vec[others] @ obs.vec[obs_idx[0]]), kind="stable")]  # nearest first
    verifier.patterns += 1
    if len(cands) == 0:
        return None
    verifier.trials += len(cands)
    stars = verifier.db.stars.vec
    first = others[:SCREEN_STARS]
    att = wahba_batch(obs.vec[obs_idx], stars[cands])  # (K, 3, 3) ICRS -> body
    ok, near = _landing(ctx, att, first)
    hits = ok.sum(axis=1)
    for row in np.argsort(-hits, kind="stable")[:MAX_CHECKS]:
        if hits[row] < min_hits:
            break
        hyp = np.concatenate([obs_idx, first[ok[row]]])
        cat = np.concatenate([cands[row], near[row][ok[row]]])
        for stop in (2 * SCREEN_STARS, 4 * SCREEN_STARS, len(others)):
            ring = np.setdiff1d(others[:stop], hyp)
            if len(ring) == 0 or len(np.unique(cat)) < 2:
                continue
            keep = _first_of_each(cat)
            r = wahba_batch(obs.vec[hyp[keep]], stars[cat[keep]][None])
            ok_r, near_r = _landing(ctx, r, ring)
            hyp = np.concatenate([hyp, ring[ok_r[0]]])
            cat = np.concatenate([cat, near_r[0][ok_r[0]]])
        keep = _first_of_each(cat)
        verifier.trials -= 1  # check() counts itself
        found = verifier.check(hyp[keep], cat[keep])
        if found is not None:
            return found
    return None


def _landing(ctx: SolveContext, att: FloatArray, rows: IntArray) -> tuple[np.ndarray, IntArray]:
    """For attitudes ``att`` ``(K, 3, 3)``: which observed ``rows`` land unambiguously on a
    catalogue star ``(K, M)``, and on which."""
    verifier = ctx.verifier
    if len(rows) == 0:
        return np.zeros((len(att), 0), bool), np.zeros((len(att), 0), np.int64)
    pred = np.einsum("kji,mj->kmi", att, ctx.obs.vec[rows])  # (K, M, 3) ICRS
    radius = verifier.match_radius_px * ctx.obs.pixel_scale_rad
    dist, near = star_tree(verifier.db).query(pred.reshape(-1, 3), k=2, distance_upper_bound=2 * radius)
    ok = ((dist[:, 0] <= radius) & ~np.isfinite(dist[:, 1])).reshape(len(att), len(rows))
    return ok, near[:, 0].reshape(len(att), len(rows))


def _first_of_each(cat: IntArray) -> IntArray:
    """Positions of the first occurrence of each catalogue star, in order."""
    _, first = np.unique(cat, return_index=True)
    return np.sort(first)
