"""An answer proven on a shallower member of a database set, re-verified against the deepest.

The general path's counterpart of what :func:`~.first_pass.settle_kernel` does in its compiled
call: the answer's stars that the deeper member also holds are the hypothesis, the stars newly
paired there the evidence (:func:`refine_deeper`); skipped when no observed star outside the
answer lies near a deeper star (:func:`could_pair_more_deeper`), or when too few lie near one for
the evidence to reach the bound it asks (:func:`~.check_kernel.recheck_could_pass`).
"""

from __future__ import annotations

import numpy as np

from .answer import recheck
from .check_kernel import DEEPER_REACH, could_pair_more, pairable_count, recheck_could_pass
from .first_pass import deeper_arrays
from .navdb.reader import NavDatabase
from .star_index import field_grid, star_vec64
from .verify import NEAR_MARGIN_DEG, Observation, Verified, Verifier


def refine_deeper(obs: Observation, db: NavDatabase, deeper: NavDatabase, found: Verified, sigma_px: float,
                  match_radius_px: float | None, max_false_prob: float) -> Verified | None:
    """Re-verify an answer found in ``db`` against the deeper star table of ``deeper``: its
    stars that ``deeper`` also holds are the hypothesis, the newly matched ones the evidence,
    and every hypothesis already tried still counts. ``sigma_px``: the declared centroid error
    (px). None if it adds nothing provable."""
    rows = deeper_arrays(db, deeper).rows[found.cat]  # by HIP, the map built once per pair of members
    known = rows >= 0
    if known.sum() < 3:
        return None
    radius = match_radius_px or max(2.5, 3.0 * sigma_px)
    if len(obs.cameras) == 1 and not could_pair_more_deeper(obs, deeper, found, radius):
        return None
    if len(obs.cameras) == 1 and not recheck_could_be_strong(obs, deeper, found, found.obs[known], radius,
                                                             max_false_prob):
        return None  # no recheck could name more stars with a strong bound (first_pass.settle_kernel's test)
    compiled = recheck(obs, deeper, found.obs[known], rows[known], found.n_trials, radius)  # one camera
    if compiled is None:
        verifier = Verifier(deeper, obs, match_radius_px=radius, max_false_prob=max_false_prob,
                            trials=found.n_trials)
        refined = verifier.check(found.obs[known], rows[known], n_trials=found.n_trials)
    else:  # a proof as strong as Verifier.check asks of an answer (a marginal one adds nothing here)
        ok, m_obs, m_cat, r, prob = compiled
        strong = ok and prob <= min(max_false_prob, Verifier.strong_false_prob)
        refined = Verified(m_obs, m_cat, r, prob, found.n_trials) if strong else None
    if refined is None or len(refined.obs) <= len(found.obs):
        return None
    return refined


def could_pair_more_deeper(obs: Observation, deeper: NavDatabase, found: Verified, radius_px: float) -> bool:
    """False if no observed star outside ``found`` lies near a star of ``deeper`` under its
    attitude, so that re-verifying there cannot name more stars (one camera; see
    :func:`~.check_kernel.could_pair_more`)."""
    return bool(could_pair_more(obs.vec, found.obs.astype(np.int64), *_near_args(obs, deeper, found, radius_px)))


def recheck_could_be_strong(obs: Observation, deeper: NavDatabase, found: Verified, hypothesis: np.ndarray,
                            radius_px: float, max_false_prob: float) -> bool:
    """:func:`~.check_kernel.recheck_could_pass` for a recheck of ``hypothesis`` (observed rows)
    in ``deeper`` (one camera): whether it could end with more pairs than ``found`` and a bound
    as strong as :func:`refine_deeper` accepts."""
    hyp = np.asarray(hypothesis, dtype=np.int64)
    n_pairable = pairable_count(obs.vec, hyp, *_near_args(obs, deeper, found, radius_px))
    cam = obs.cameras[0]
    n = np.int64  # one compiled signature (a literal 0 would be typed apart)
    return bool(recheck_could_pass(n(len(obs.vec)), n(len(hyp)), n(n_pairable), n(len(found.obs)), float(radius_px),
                                   float(cam.width * cam.height), n(found.n_trials),
                                   min(max_false_prob, Verifier.strong_false_prob)))


def _near_args(obs: Observation, deeper: NavDatabase, found: Verified, radius_px: float) -> tuple:
    """The screens' arguments after the observed rows: ``found``'s attitude, the chord of
    :data:`~.check_kernel.DEEPER_REACH` match radii, and ``deeper``'s grid (the recheck's own)."""
    g = field_grid(deeper, obs.cameras[0].diagonal_fov_deg / 2 + NEAR_MARGIN_DEG)
    return (np.array(found.matrix, np.float64), DEEPER_REACH * radius_px * obs.pixel_scale_rad,
            *g.kernel_args()[:5], star_vec64(deeper), g.columns)


__all__ = ["could_pair_more_deeper", "recheck_could_be_strong", "refine_deeper"]
