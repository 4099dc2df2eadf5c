"""``maxangle``'s search on one camera as compiled calls.

:meth:`MaxAngleMatcher.identify <service.core.methods.maxangle.MaxAngleMatcher.identify>` walks
the frame's observed triangles in chunks (2, 4, 8, then 16 at a time). For each chunk it looks
the triangles up, screens every candidate, and fully verifies the best eight
(:meth:`~service.core.verify.Verifier.screen_and_check_many`). Through Python that took about
four calls a chunk and ten a candidate checked. On a frame of one camera, the same steps run here,
many chunks per call (:func:`search_chunks`):

- the look-up (:func:`~.maxangle_index.query_cells` or :func:`~.maxangle_index.query_paper`);
- the screen (:func:`~service.core.screen._screen`);
- up to ``max_checks`` candidates checked best first
  (:func:`~service.core.check_kernel.verify_pairs`, what ``Verifier.check`` calls for one camera);
- the verifier's counting: every candidate is a trial, a hypothesis a marginal answer already
  names is counted and skipped, a marginal answer is kept aside, and the search stops once one
  has had ``confirm_patterns`` patterns to be beaten or ``trial_limit`` hypotheses were tried.

Python checks the clock between calls (:data:`TRIANGLES_PER_CALL` triangles apart), as it
checked it between chunks. The answers are those of the Python loop, which rigs still take;
``tests/core/methods/test_maxangle_search.py`` compares the two frame by frame.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from numba import njit

from ..attitude import wahba_kernel
from ..check_kernel import keep_marginal, names_marginal, verify_pairs
from ..match import MIN_MATCHES, needed_hits
from ..screen import _screen, could_pass_bound, hits_under
from ..star_index import field_grid, sky_grid, sky_mask, star_vec64
from ..verify import CHECKS_PER_CHUNK, NEAR_MARGIN_DEG, NEED_SCREEN_FACTOR, Verified
from .base import SolveContext
from .maxangle_index import query_cells, query_paper

TRIANGLES_PER_CALL = 64
"""Observed triangles one call may search before Python checks the clock again (a 7-star frame's
35 triangles and most of their near-tie relabellings fit in one call)."""

STOP_NONE = 0
STOP_SETTLED = 1
"""A marginal answer has had its ``confirm_patterns`` patterns (``Verifier.settled``)."""
STOP_LIMIT = 2
"""``trial_limit`` hypotheses were tried (``Verifier.over_limit``)."""
STOP_FOUND = 3


def chunk_bounds(total: int) -> np.ndarray:
    """Start of each chunk of ``total`` triangles and the end: sizes 2, 4, 8, then 16 (the
    first triangles usually solve a frame)."""
    bounds, size, done = [0], 2, 0
    while done < total:
        done += min(size, total - done)
        bounds.append(done)
        size = min(2 * size, 16)
    return np.array(bounds, np.int64)


def calls(bounds: np.ndarray) -> list[tuple[int, int]]:
    """Chunk ranges ``[c0, c1)`` of one call each: about :data:`TRIANGLES_PER_CALL` triangles."""
    out, c0 = [], 0
    n_chunks = len(bounds) - 1
    while c0 < n_chunks:
        c1 = c0 + 1
        while c1 < n_chunks and bounds[c1 + 1] - bounds[c0] <= TRIANGLES_PER_CALL:
            c1 += 1
        out.append((c0, c1))
        c0 = c1
    return out


_TRIANGLE = np.int64(3)
"""A hypothesis's stars as ``needed_hits`` takes them: an int64 (see ``match.MIN_MATCHES``)."""


@njit(cache=True, nogil=True)
def search_chunks(obs_vec, obs_xy, labels, sides, theta, tol, bounds, c0, c1, eps, n_others, mounts, cams, dist,
                  rows, row_off, state, trial_limit, confirm_patterns, max_false_prob, strong_false_prob, max_checks,
                  max_candidates, marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials, radius_px,
                  pixel_scale, cells, key, bucket_start, tab_x, tab_y, ids, n_buckets, b_scale, screen_chord, s_cell,
                  s_side, s_keys, s_starts, s_stars, s_columns, mask_n, mask_words, star_vec,
                  g_cell, g_side, g_keys, g_starts, g_stars, g_columns, near_chord):
    """Chunks ``c0`` to ``c1`` (of ``bounds``) of the observed triangles ``labels`` (sorted as
    ``MaxAngleMatcher.observed_triangles`` sorts them) through the look-up, the screen and the
    checks. ``state`` (int64: trials, patterns, first marginal's pattern count or -1, marginal
    answers held, why the search stopped) is read and updated in place, and so are the
    marginal answers' arrays (``marg_*``, room for every check of these chunks). Returns
    ``(found, obs rows, catalogue rows, ICRS -> body matrix, bound, trials)``."""
    empty = np.zeros(0, np.int64)
    trials, patterns, first_marg, n_marg = state[0], state[1], state[2], state[3]
    buf = np.empty(len(star_vec), np.int64)
    near_state = np.zeros(4)
    quick_tol = 1.5 * radius_px * pixel_scale
    wide_chord = NEED_SCREEN_FACTOR * screen_chord
    others = np.arange(n_others)
    stop = STOP_NONE
    for ci in range(c0, c1):
        if first_marg >= 0 and patterns - first_marg >= confirm_patterns:
            stop = STOP_SETTLED
            break
        if trial_limit >= 0 and trials >= trial_limit:
            stop = STOP_LIMIT
            break
        lo, hi = bounds[ci], bounds[ci + 1]
        if cells:
            found_rows, which = query_cells(key, bucket_start, tab_x, tab_y, ids, star_vec, obs_vec, labels[lo:hi],
                                            sides[lo:hi], theta[lo:hi], tol[lo:hi], eps, n_buckets, b_scale,
                                            max_candidates)
        else:
            found_rows, which = query_paper(key, bucket_start, tab_x, tab_y, ids, star_vec, obs_vec, labels[lo:hi],
                                            sides[lo:hi], theta[lo:hi], tol[lo:hi], eps, n_buckets, b_scale,
                                            max_candidates)
        patterns += hi - lo
        k = len(found_rows)
        if k == 0:
            continue
        tris = np.empty((k, 3), np.int64)
        cands = np.empty((k, 3), np.int64)
        for i in range(k):
            for j in range(3):
                tris[i, j] = labels[lo + which[i], j]
                cands[i, j] = ids[found_rows[i], j]
        trials += k - 1  # the last one is counted by its check, as Verifier.check counts it
        hits = _screen(obs_vec, tris, cands, others, screen_chord, s_cell, s_side, s_keys, s_starts, s_stars,
                       star_vec, s_columns, mask_n, mask_words)
        order = np.argsort(-hits, kind="mergesort")
        least = 1 if len(obs_vec) > 3 else 0
        need = needed_hits(len(obs_vec), _TRIANGLE, n_others, radius_px, cams[0, 3] * cams[0, 4], trials + 1,
                           max_false_prob, MIN_MATCHES)
        for oi in range(min(k, max_checks)):
            row = order[oi]
            if hits[row] < least:
                break
            if trial_limit >= 0 and trials >= trial_limit:
                break
            o, c = tris[row], cands[row]
            if n_marg > 0 and names_marginal(o, c, marg_off, marg_obs, marg_cat, n_marg):
                trials += 1
                continue
            trials += 1
            if c[0] == c[1] or c[0] == c[2] or c[1] == c[2]:
                continue
            r = wahba_kernel(obs_vec[o], star_vec[c], np.ones(3))
            if hits[row] < need and hits_under(obs_vec, o, r, n_others, wide_chord, need, c[0], c[1], c[2], s_cell,
                                               s_side, s_keys, s_starts, s_stars, star_vec, s_columns) < need:
                continue  # too few stars even in the wide screen to pass the bound (NEED_SCREEN_FACTOR)
            if not could_pass_bound(obs_vec, o, r, n_others, wide_chord, radius_px, cams[0, 3] * cams[0, 4], trials,
                                    max_false_prob, MIN_MATCHES, c[0], c[1], c[2], s_cell, s_side, s_keys, s_starts,
                                    s_stars, star_vec, s_columns):
                continue  # a big frame: too few of all its stars in the wide screen (screen.could_pass_bound)
            near_state[0] = 0.0  # a fresh gathering, as each Verifier.check's own call does
            ok, m_obs, m_cat, r, prob = verify_pairs(obs_vec, obs_xy, star_vec, o.copy(), c.copy(), r, g_cell,
                                                     g_side, g_keys, g_starts, g_stars, g_columns, near_chord,
                                                     mounts[0], buf, near_state, mounts, cams, dist, rows, row_off,
                                                     radius_px, quick_tol, trials)
            if not ok or prob > max_false_prob:
                continue
            if prob <= strong_false_prob:
                state[0], state[1], state[2], state[3], state[4] = trials, patterns, first_marg, n_marg, STOP_FOUND
                return True, m_obs, m_cat, r, prob, trials
            n_marg = keep_marginal(marg_r, marg_prob, marg_trials, marg_off, marg_obs, marg_cat, n_marg, r, prob,
                                   trials, m_obs, m_cat)
            if first_marg < 0:
                first_marg = patterns
    state[0], state[1], state[2], state[3], state[4] = trials, patterns, first_marg, n_marg, stop
    return False, empty, empty, np.eye(3), 1.0, trials


@functools.lru_cache(maxsize=256)
def _call_plan(total: int) -> tuple[np.ndarray, tuple[tuple[int, int], ...]]:
    """:func:`chunk_bounds` of ``total`` triangles and its :func:`calls`, kept per ``total`` (~2 us
    of Python a search; callers do not write to them: a read-only array would be another type
    for the compiled search)."""
    bounds = chunk_bounds(total)
    return bounds, tuple(calls(bounds))


def search(matcher: Any, ctx: SolveContext, labels: np.ndarray, sides: np.ndarray, theta: np.ndarray,
           tol: np.ndarray, eps: float, max_candidates: int, n_first: int | None = None,
           extension_trials: int = 0) -> Verified | None:
    """:func:`_search` of the first ``n_first`` triangles (all by default), then, where they left
    no answer, marginal answer or stop, of the rest with at most ``extension_trials`` more
    hypotheses (``maxangle._triangles_extended``)."""
    n_first = len(labels) if n_first is None else n_first
    ver = ctx.verifier
    held = len(ver.marginal)
    found, stop = _search(matcher, ctx, labels[:n_first], sides[:n_first], theta[:n_first], tol[:n_first], eps,
                          max_candidates, ver.trial_limit)
    if found is not None or stop != STOP_NONE or len(ver.marginal) > held or n_first == len(labels) \
            or ctx.expired():
        return found
    return _search(matcher, ctx, labels[n_first:], sides[n_first:], theta[n_first:], tol[n_first:], eps,
                   max_candidates, extension_limit(ver.trials, ver.trial_limit, extension_trials))[0]


def extension_limit(trials: int, trial_limit: int | None, extension_trials: int) -> int:
    """The trial limit of the extension's triangles: ``extension_trials`` past ``trials``,
    within the search's own ``trial_limit`` (None: none)."""
    limit = trials + extension_trials
    return limit if trial_limit is None else min(limit, trial_limit)


def _search(matcher: Any, ctx: SolveContext, labels: np.ndarray, sides: np.ndarray, theta: np.ndarray,
            tol: np.ndarray, eps: float, max_candidates: int, trial_limit: int | None) -> tuple[Verified | None, int]:
    """:meth:`MaxAngleMatcher.identify`'s search of a one-camera frame's observed triangles
    (sorted, with their sides, ``theta_max`` and its tolerance, radians; a triangle with more
    than ``max_candidates`` catalogue matches is dropped) through :func:`search_chunks`; the
    verifier's counts and marginal answers are updated as its own steps would update them."""
    ver, obs = ctx.verifier, ctx.obs
    k = obs.kernel_arrays
    static = _static_args(matcher, ver.db, obs.cameras[0], float(ver.match_radius_px))
    bounds, plan = _call_plan(len(labels))
    held = ver.marginal
    state = np.array([ver.trials, ver.patterns, -1 if ver._first_marginal_at is None else ver._first_marginal_at,
                      len(held), STOP_NONE], np.int64)
    limit = -1 if trial_limit is None else int(trial_limit)
    n_others = min(len(obs), ver.screen_stars + 3)
    for c0, c1 in plan:
        if ctx.expired():
            break
        room = len(held) + CHECKS_PER_CHUNK * (c1 - c0)  # each check may keep a marginal answer
        marg = _marginal_arrays(held, room, len(obs))
        found, m_obs, m_cat, r, prob, trials = search_chunks(
            obs.vec, obs.xy, labels, sides, theta, tol, bounds, c0, c1, float(eps), n_others, k.mounts, k.cams,
            k.dist, k.rows, k.row_off, state, limit, int(ver.confirm_patterns), float(ver.max_false_prob),
            float(ver.strong_false_prob), CHECKS_PER_CHUNK, int(max_candidates), *marg, *static)
        ver.trials, ver.patterns = int(state[0]), int(state[1])
        if state[2] >= 0:
            ver._first_marginal_at = int(state[2])
        marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials = marg
        for j in range(len(held), int(state[3])):
            lo, hi = marg_off[j], marg_off[j + 1]
            held.append(Verified(marg_obs[lo:hi].copy(), marg_cat[lo:hi].copy(), marg_r[j].copy(),
                                 float(marg_prob[j]), int(marg_trials[j])))
        if found:
            return Verified(m_obs, m_cat, r, float(prob), int(trials)), int(state[4])
        if state[4] != STOP_NONE:
            break
    return None, int(state[4])


STATIC_CACHE_SIZE = 64


def _static_args(matcher: Any, db: Any, cam: Any, radius_px: float) -> tuple[Any, ...]:
    """The kernel's arguments that depend only on the database, the camera and the match radius
    (px), kept on the matcher (every frame of a camera passes the same)."""
    cache = matcher.__dict__.setdefault("_search_args", {})
    key = (cam.diagonal_fov_deg, cam.pixel_scale_rad, radius_px)
    got = cache.get(key)
    if got is None:
        screen_chord = radius_px * 1.5 * cam.pixel_scale_rad
        grid, mask = sky_grid(db), sky_mask(db, screen_chord)
        near_deg = cam.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
        g = field_grid(db, near_deg)
        cells = matcher.layout == "cells"
        tab_x, tab_y = (matcher.b, matcher.c) if cells else (matcher.c, matcher.theta)
        got = (radius_px, float(cam.pixel_scale_rad), cells, matcher.key, matcher.bucket_start, tab_x, tab_y,
               matcher.ids, matcher.n_cells if cells else matcher.n_blocks, float(matcher.b_scale), screen_chord,
               grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars, grid.columns, mask.n, mask.words,
               star_vec64(db), g.cell, g.n_side, g.keys, g.starts, g.stars, g.columns,
               2 * math.sin(math.radians(near_deg) / 2))
        if len(cache) >= STATIC_CACHE_SIZE:
            cache.clear()
        cache[key] = got
    return got


def _marginal_arrays(held: list[Verified], room: int, n_obs: int) -> tuple[np.ndarray, ...]:
    """The marginal answers ``held`` as :func:`search_chunks` takes them, with room for
    ``room`` answers of up to ``n_obs`` pairs."""
    marg_r = np.empty((room, 3, 3))  # each answer's slots are written before they are read
    marg_prob = np.empty(room)
    marg_off = np.zeros(room + 1, np.int64)
    marg_obs = np.empty(room * n_obs, np.int64)
    marg_cat = np.empty(room * n_obs, np.int64)
    marg_trials = np.empty(room, np.int64)
    for j, v in enumerate(held):
        lo = marg_off[j]
        marg_r[j] = v.matrix
        marg_prob[j] = v.false_prob
        marg_trials[j] = v.n_trials
        marg_obs[lo:lo + len(v.obs)] = v.obs
        marg_cat[lo:lo + len(v.obs)] = v.cat
        marg_off[j + 1] = lo + len(v.obs)
    return marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials
