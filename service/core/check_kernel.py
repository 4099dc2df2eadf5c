"""A hypothesis checked in one compiled call (one camera), and the marginal answers' books.

The steps of :meth:`~service.core.verify.Verifier.check` after its screen, for the compiled
searches (``quad``'s :func:`~.methods.quad_kernel.quad_search`, ``maxangle``'s
:func:`~.methods.maxangle_search.search_chunks`) and the answer's finish
(:func:`~.first_pass.settle_kernel`):

- :func:`verify_pairs`: the catalogue field gathered near the boresight (:func:`_field`, reused
  while the boresight moves less than 0.3 deg), pairing and refits
  (:func:`~service.core.match._refine`), the near-miss test (:data:`SETTLE`, the verifier's
  ``SETTLE_FACTORS``) and the coincidence bound ``P = trials * P[Binomial(n_free, p) >= n_extra]``;
- :func:`recheck_pairs`: an answer re-verified against another member's star table, and
  :func:`could_pair_more`, which says when that cannot name more stars;
- :func:`keep_marginal`, :func:`names_marginal`: the marginal answers a search holds, as
  ``Verifier.marginal`` holds them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .attitude import wahba_kernel
from .match import _match_rig, _refine, _wahba_pairs, binomial_tail
from .skygrid import collect_within, has_star_within
from .verify import SETTLE_FACTORS

SETTLE = np.array(SETTLE_FACTORS, dtype=np.float64)
"""The near-miss test's wider match radii, in match radii (``Verifier._settle``)."""
NEAR_REUSE_COS = math.cos(math.radians(0.3))
"""A gathered field is reused while the boresight moves less than this (its margin is 0.5 deg)."""


@njit(cache=True, nogil=True)
def names_marginal(o, c, marg_off, marg_obs, marg_cat, n_marg, closed=None):
    """Does one of the ``n_marg`` marginal answers (pairs ``marg_obs``/``marg_cat`` of answer ``k``
    in ``marg_off[k]:marg_off[k + 1]``) pair every observed row ``o[i]`` with catalogue row
    ``c[i]`` (:meth:`~service.core.verify.Verifier.names_marginal`)? With ``closed``, only the
    answers it marks count (``quad``'s kernel: those no check could grow)."""
    for k in range(n_marg):
        if closed is not None and not closed[k]:
            continue
        every = True
        for i in range(len(o)):
            hit = False
            for j in range(marg_off[k], marg_off[k + 1]):
                if marg_obs[j] == o[i]:
                    hit = marg_cat[j] == c[i]
                    break
            if not hit:
                every = False
                break
        if every:
            return True
    return False


@njit(cache=True, nogil=True)
def keep_marginal(marg_r, marg_prob, marg_trials, marg_off, marg_obs, marg_cat, n_marg, r, prob, trials, m_obs,
                  m_cat):
    """Store a marginal answer (attitude ``r``, bound ``prob`` after ``trials`` hypotheses, pairs
    ``m_obs`` -> ``m_cat``) as answer ``n_marg`` of the ``marg_*`` arrays; returns the count."""
    marg_r[n_marg] = r
    marg_prob[n_marg] = prob
    marg_trials[n_marg] = trials
    k0 = marg_off[n_marg]
    marg_obs[k0:k0 + len(m_obs)] = m_obs
    marg_cat[k0:k0 + len(m_obs)] = m_cat
    marg_off[n_marg + 1] = k0 + len(m_obs)
    return n_marg + 1


@njit(cache=True, nogil=True)
def verify_pairs(obs_vec, obs_xy, star_vec, o, lab, r, g_cell, g_side, g_keys, g_starts, g_stars, g_columns,
                 near_chord, mount, buf, near_state, mounts, cams, dist, rows, row_off, radius_px, quick_tol, trials):
    """The hypothesis "observed rows ``o`` are catalogue rows ``lab``" (any number of pairs; one
    camera) at attitude ``r`` through :meth:`~service.core.verify.Verifier.check`'s steps after
    its screen: pairing and refits, the near-miss test, and the coincidence bound multiplied by
    ``trials``. Returns ``(ok, m_obs, m_cat, r, prob)``. ``buf`` (a row per catalogue star) and
    ``near_state`` (4,) hold the gathered field between calls (:func:`_field`)."""
    empty = np.zeros(0, np.int64)
    n_obs = len(obs_vec)
    near = _field(r, mount, near_state, near_chord, g_cell, g_side, g_keys, g_starts, g_stars, star_vec,
                  g_columns, buf)
    near_off = np.array([0, len(near)], np.int64)
    ok, m_obs, m_cat, p_single, r = _refine(obs_vec, obs_xy, star_vec, o, lab, r, quick_tol, near, near_off,
                                            mounts, cams, dist, rows, row_off, radius_px, np.int64(4))
    if not ok:
        return False, empty, empty, r, 1.0
    n_pairs = len(m_obs)
    for f in range(len(SETTLE)):  # the verifier's near-miss test (Verifier._settle)
        if n_obs <= n_pairs + max(3, n_pairs // 3):
            break  # the wide pairing cannot grow enough: too few stars are left unpaired
        near = _field(r, mount, near_state, near_chord, g_cell, g_side, g_keys, g_starts, g_stars, star_vec,
                      g_columns, buf)
        near_off[1] = len(near)
        w_obs, w_cat, _ = _match_rig(r, obs_xy, star_vec, near, near_off, mounts, cams, dist, rows, row_off,
                                     SETTLE[f] * radius_px, 1.0)
        if len(w_obs) <= n_pairs + max(3, n_pairs // 3):
            continue
        r2 = _wahba_pairs(obs_vec, star_vec, w_obs, w_cat)
        near = _field(r2, mount, near_state, near_chord, g_cell, g_side, g_keys, g_starts, g_stars, star_vec,
                      g_columns, buf)
        near_off[1] = len(near)
        ok2, s_obs, s_cat, p2, r2 = _refine(obs_vec, obs_xy, star_vec, w_obs[:0], w_cat[:0], r2, 1.0, near,
                                            near_off, mounts, cams, dist, rows, row_off, radius_px, np.int64(4))
        if not ok2 or len(s_obs) <= n_pairs:
            continue
        m_obs, m_cat, p_single, r = s_obs, s_cat, p2, r2
        n_pairs = len(m_obs)
    n_hyp = 0
    for i in range(len(m_obs)):
        for j in range(len(o)):
            if m_obs[i] == o[j]:
                n_hyp += 1
                break
    n_extra = len(m_obs) - n_hyp
    n_free = n_obs - len(o)
    if len(m_obs) < 4 or n_extra < 1:
        return False, empty, empty, r, 1.0
    tail = binomial_tail(n_free, n_extra, min(p_single, 1.0)) if n_free >= n_extra else 1.0
    prob = min(1.0, tail * max(trials, 1))
    return True, m_obs, m_cat, r, prob


@njit(cache=True, nogil=True)
def recheck_pairs(obs_vec, obs_xy, star_vec, obs_idx, cat_idx, g_cell, g_side, g_keys, g_starts, g_stars, g_columns,
                  near_chord, mounts, cams, dist, rows, row_off, radius_px, pixel_scale, trials):
    """:func:`verify_pairs` of the pairs ``obs_idx`` -> ``cat_idx`` at their own Wahba attitude
    (re-verifying an answer against another member's star table: ``star_vec`` and its grid).
    Returns ``(ok, m_obs, m_cat, r, prob)``."""
    r = wahba_kernel(obs_vec[obs_idx], star_vec[cat_idx], np.ones(len(obs_idx)))
    return verify_pairs(obs_vec, obs_xy, star_vec, obs_idx, cat_idx, r, g_cell, g_side, g_keys, g_starts, g_stars,
                        g_columns, near_chord, mounts[0], np.empty(len(star_vec), np.int64), np.zeros(4), mounts,
                        cams, dist, rows, row_off, radius_px, 1.5 * radius_px * pixel_scale, trials)


RECHECK_REACH = SETTLE[-1] + 1.0
"""Match radii around an unpaired observed star within which another member's star must lie
for :func:`recheck_pairs` to pair more stars (the near-miss test's widest radius, and one more
for the refit's move)."""


DEEPER_REACH = 2.0
"""Match radii around an unpaired observed star within which a deeper member's star must lie for
a proven answer to be re-verified there (:func:`recheck_pairs`, from ``first_pass.settle_kernel``
and ``deeper.refine_deeper``): the recheck pairs at one match radius from the answer's own
refit, which a proof of four or more pairs moves by a fraction of a radius. With
:data:`RECHECK_REACH` (7 radii, still what the quad search asks of a closed answer), seeds 000's
and 001's frames at 2 px with 5 false stars rechecked against ``narrow`` where no star lay
within one radius (71 and 45 of ~250 proven frames; ~15 us each), and none of those rechecks
named a star more. The same answers on 27,000 frames of the five cameras (session 38,
docs/performance.md)."""

_NO_ROW = np.int64(-1)
"""No catalogue row to skip, as an int64 (a literal ``-1`` in a compiled call is typed
``Literal[int]``: ``has_star_within`` compiled a second time)."""


@njit(cache=True, nogil=True)
def could_pair_more(obs_vec, paired, r, chord, cell, n_side, keys, starts, stars, star_vec, columns):
    """True if some observed star not in ``paired`` lies within ``chord`` (unit-vector
    distance) of a star of ``star_vec`` under ``r`` (ICRS -> body).

    An answer re-verified against another member (:func:`recheck_pairs`) can name more stars
    only through such a star: with ``chord`` at :data:`RECHECK_REACH` match radii, a frame
    whose every unpaired star is farther from that member's stars skips the recheck (~15 us).
    """
    return _free_near(obs_vec, paired, r, chord, cell, n_side, keys, starts, stars, star_vec, columns, True) > 0


@njit(cache=True, nogil=True)
def pairable_count(obs_vec, hypothesis, r, chord, cell, n_side, keys, starts, stars, star_vec, columns):
    """How many observed stars outside ``hypothesis`` (rows) lie within ``chord`` (unit-vector
    distance) of a star of ``star_vec`` under ``r`` (ICRS -> body): at most that many can be
    newly paired by a recheck of that hypothesis (:func:`recheck_could_pass`)."""
    return _free_near(obs_vec, hypothesis, r, chord, cell, n_side, keys, starts, stars, star_vec, columns, False)


@njit(cache=True, nogil=True, inline="always")
def _free_near(obs_vec, paired, r, chord, cell, n_side, keys, starts, stars, star_vec, columns, first_only):
    """The observed stars outside ``paired`` within ``chord`` of a catalogue star under ``r``
    (counting stops at the first with ``first_only``)."""
    taken = np.zeros(len(obs_vec), np.bool_)
    for i in paired:
        taken[i] = True
    n = 0
    for m in range(len(obs_vec)):
        if taken[m]:
            continue
        v = obs_vec[m]
        px = r[0, 0] * v[0] + r[1, 0] * v[1] + r[2, 0] * v[2]
        py = r[0, 1] * v[0] + r[1, 1] * v[1] + r[2, 1] * v[2]
        pz = r[0, 2] * v[0] + r[1, 2] * v[1] + r[2, 2] * v[2]
        if has_star_within(px, py, pz, chord, cell, n_side, keys, starts, stars, star_vec, columns, _NO_ROW, _NO_ROW,
                           _NO_ROW):
            n += 1
            if first_only:
                return n
    return n


@njit(cache=True, nogil=True)
def recheck_could_pass(n_obs, n_hypothesis, n_pairable, n_pairs, radius_px, area_px, trials, limit):
    """False if no :func:`recheck_pairs` of a hypothesis of ``n_hypothesis`` pairs could end with
    a bound at most ``limit`` and more than ``n_pairs`` pairs, when at most ``n_pairable`` observed
    stars outside it can be paired (:func:`pairable_count`; ``n_obs`` stars in all).

    :func:`verify_pairs`'s bound is ``trials * P[Binomial(n_obs - n_hypothesis, p) >= n_extra]``
    with ``n_extra`` the stars paired outside the hypothesis (at most ``n_pairable``) and ``p``
    the share of the image (``area_px``) within ``radius_px`` of a catalogue star predicted inside
    it: every paired star is one, and an answer with more pairs has at least ``n_pairs + 1``, so
    ``p >= (n_pairs + 1) * pi * radius_px**2 / area_px``. The tail falls with ``n_extra`` and
    rises with ``p``: with both at their bounds it is the least the recheck's bound can be."""
    if n_pairable < 1:
        return False
    p = min((n_pairs + 1) * math.pi * radius_px * radius_px / max(area_px, 1.0), 1.0)
    n_free = n_obs - n_hypothesis
    tail = binomial_tail(n_free, n_pairable, p) if n_free >= n_pairable else 1.0
    return min(1.0, tail * max(trials, 1)) <= limit


@njit(cache=True, nogil=True)
def _field(r, mount, state, chord, g_cell, g_side, g_keys, g_starts, g_stars, star_vec, g_columns, buf):
    """The catalogue rows near the boresight under ``r`` (a view of ``buf``), reusing the last
    gathering while the boresight stays within 0.3 deg of it (the verifier's ``_near`` cache).
    ``state`` (4,): the gathering's size and boresight, updated in place."""
    rc = mount @ r
    n = int(state[0])
    dot = rc[2, 0] * state[1] + rc[2, 1] * state[2] + rc[2, 2] * state[3]
    if n > 0 and dot >= NEAR_REUSE_COS:
        return buf[:n]
    n = collect_within(rc[2, 0], rc[2, 1], rc[2, 2], chord, g_cell, g_side, g_keys, g_starts, g_stars, star_vec,
                       g_columns, buf)
    state[0] = n
    state[1], state[2], state[3] = rc[2, 0], rc[2, 1], rc[2, 2]
    return buf[:n]
