"""``auto``'s fallbacks as one compiled call, after the first pass's miss.

When :mod:`service.core.first_pass` looked up every pattern of a one-camera frame on the plan's
first member and proved nothing, :func:`service.core.pipeline.solve_rig` goes on through the
rest of the plan. On a frame of 5 to ``QUERY_STARS`` stars: the first member's first fallback
(``maxangle``), the next member's ``quad``, that member's ``maxangle``
(``SMALL_FRAME_FALLBACK_FIRST``), within ``FEW_STARS_MAX_TRIALS`` hypotheses; on a larger
frame (since session 18) in the plan's order: the next member's ``quad``, then each member's
``maxangle``, within ``MANY_STARS_MAX_TRIALS``. Through Python each pass cost a ``Verifier``, a
method's wrapper, its compiled calls and the answer's choice among marginal ones: about 60 us
of a ~100-150 us frame of seed 002 (docs/performance.md, session 17), ~50 us of a random-point
frame of 11-39 points on seed 000's camera (session 18). Here the same passes run in one
compiled call (:func:`chain_kernel`):

- ``maxangle``: the frame's triangles (:func:`~.methods.maxangle._triangles_extended`), every chunk
  through :func:`~.methods.maxangle_search.search_chunks` (one call where Python made one per
  64 triangles to check the clock: the passes' work is bounded by the hypothesis budget), then
  the likeliest marginal answer if all agree (:func:`~.verify.marginal_choice`); skipped where
  no answer could pass the bound (``Verifier.could_prove``);
- ``quad``: :func:`~.methods.quad_kernel.quad_search` with the hypotheses so far, the same
  marginal choice;
- the count: every pass adds its hypotheses to the bound; the budget starts at the first
  fallback and grows by what each ``quad`` pass tried; a pass is not started once it is spent.

Python builds the pass list as the general loop would order it, then the answer. A ``quad``
pass that stops short of every pattern (its probe or check bounds) or leaves answers that
disagree hands the frame back: the general loop then runs it from the start (the call changed
nothing), as it runs frames of a rig, a retry sigma, a hint, or a plan of another shape.
``tests/core/test_fallback_pass.py`` compares the two frame by frame.
"""

from __future__ import annotations

import math
import time
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ._entry import EntryCall, plain
from .methods import get_matcher
from .methods.maxangle import (
    EXTENSION_TRIALS,
    MAX_CANDIDATES,
    _extension_array,
    _pattern_array,
    _triangles_extended,
)
from .methods.maxangle_search import STOP_NONE, search_chunks
from .methods.maxangle_search import _static_args as maxangle_args
from .methods.quad import MAX_CHECKS, MAX_PROBES, QUERY_STARS
from .methods.quad_kernel import STATUS_FOUND, quad_search
from .navdb.reader import NavDatabase
from .packed import Packed, pack
from .plan import fallback_next
from .star_index import field_grid
from .verify import (
    CHECKS_PER_CHUNK,
    NEAR_MARGIN_DEG,
    Observation,
    Verified,
    Verifier,
    _image_probes,
    marginal_choice,
)

KIND_QUAD, KIND_MAXANGLE = 0, 1
KIND_NAMES = ("quad", "maxangle")
"""The method of each kind of pass."""
RAN, UNPROVABLE, SPENT = 1, 2, 3
"""What became of each pass: it ran; it was skipped because no answer of it could pass the
bound (the pipeline's ``unprovable``); it was not started, the budget being spent."""
CHAIN_FOUND, CHAIN_NONE, CHAIN_BACK = 1, 0, -1
MIN_CLOCK_S = 0.05
"""Time the frame must have left for the call: it does not look at the clock (its work is
bounded by the hypothesis budget: ~10 ms at most on a small frame, ~25 ms on a larger one, whose
``MANY_STARS_MAX_TRIALS`` bounds it so), so a frame nearer its deadline takes the general loop,
which checks the clock between passes."""


class Chain(NamedTuple):
    """What :func:`fallbacks` did: the answer (None if none) with its member and method, the
    hypotheses tried in all, the methods that ran and those skipped as unprovable, in order."""

    found: Verified | None
    member: NavDatabase | None
    method: str
    trials: int
    tried: list[str]
    unprovable: list[str]


def fallback_passes(plan: list[tuple[NavDatabase, list[str]]], small: bool = True,
                    first_quad_only: bool = False) -> list[tuple[NavDatabase, int]] | None:
    """The passes the general loop runs after the first member's exhaustive ``quad`` miss, if
    every ``quad`` pass after it misses exhaustively too: ``(member, kind)``; on a ``small``
    frame (5 to ``QUERY_STARS`` stars) each member's first fallback right after its ``quad``
    (``pipeline.SMALL_FRAME_FALLBACK_FIRST``), on a larger one in the plan's order (every
    ``quad``, then the fallbacks). None for a plan this call does not take (more than two
    members, a first fallback other than ``maxangle``). ``first_quad_only``: no later member's
    ``quad`` pass (``pipeline.FIRST_QUAD_ONLY_STARS``)."""
    order = list(plan)
    first = order[0][0]
    if small:
        fallback_next(order, 0)
    passes: list[tuple[NavDatabase, int]] = []
    for i in range(1, len(order)):
        member, methods = order[i]
        if methods == ["quad"] and member is not first:
            passes.append((member, KIND_QUAD))
            if small:
                fallback_next(order, i)
        elif methods and methods[0] == "maxangle" and "quad" not in methods:
            passes.append((member, KIND_MAXANGLE))
        else:
            return None
    if first_quad_only:
        passes = [(m, kind) for m, kind in passes if kind != KIND_QUAD]
    if not passes or len({id(m) for m, _ in passes} | {id(first)}) > 2:
        return None
    if any(("maxangle" if kind == KIND_MAXANGLE else "quad") not in m.tables for m, kind in passes):
        return None
    return passes


def fallbacks(obs: Observation, plan: list[tuple[NavDatabase, list[str]]], trials: int, few_trials: int,
              sigma_px: float, match_radius_px: float | None, max_false_prob: float, max_stars: int,
              deadline: float, small: bool = True, first_quad_only: bool = False) -> Chain | None:
    """The fallback passes of ``plan`` (:func:`fallback_passes`, on a ``small`` frame or a
    larger one) on ``obs`` after ``trials`` hypotheses of the first pass, the budget
    ``few_trials`` hypotheses from the first fallback (``pipeline.FEW_STARS_MAX_TRIALS``, or
    ``MANY_STARS_MAX_TRIALS``), in one compiled call. None where the general loop must run them
    (see the module's docstring)."""
    if deadline - time.perf_counter() < MIN_CLOCK_S:
        return None
    cam = obs.cameras[0]
    bounds = chain_bounds(cam, obs.pixel_scale_rad, sigma_px, match_radius_px, max_false_prob)
    setup = _setup(plan, cam, bounds[1], small, first_quad_only)
    if setup is None:
        return None
    passes, kinds, members, static = setup
    n_tri = min(len(obs), max_stars)
    k = obs.kernel_arrays
    call = _CHAIN if plain(obs.vec, obs.xy) else chain_kernel  # (_entry: the entry point's argument types)
    status, at, m_obs, m_cat, r, prob, n_trials, trials_out, ran = call(
        obs.vec, obs.xy, k.mounts, k.cams, k.dist, k.rows, k.row_off, _image_probes(obs), kinds, members, int(trials),
        int(few_trials), n_tri, _pattern_array(n_tri), _extension_array(n_tri, len(obs)), *bounds, static)
    if status == CHAIN_BACK:
        return None
    tried, unprovable = passes_by_fate(kinds, ran, RAN), passes_by_fate(kinds, ran, UNPROVABLE)
    if status != CHAIN_FOUND:
        return Chain(None, None, KIND_NAMES[kinds[-1]], int(trials_out), tried, unprovable)
    found = Verified(m_obs, m_cat, r, float(prob), int(n_trials))
    return Chain(found, passes[at][0], KIND_NAMES[kinds[at]], int(trials_out), tried, unprovable)


def chain_bounds(cam: Any, scale: float, sigma_px: float, match_radius_px: float | None,
                 max_false_prob: float) -> tuple[Any, ...]:
    """:func:`chain_kernel`'s arguments from ``tol`` to ``max_checks`` for camera ``cam`` at pixel
    scale ``scale`` (rad) and centroid error ``sigma_px``: the pattern tolerance (rad), the match
    radius (px), the verifier's bounds and the searches' limits (``[1]`` is the radius)."""
    radius = float(match_radius_px or max(2.5, 3.0 * sigma_px))
    tol = (3.0 * math.sqrt(2.0) * sigma_px + 0.5) * scale
    return (float(tol), radius, float(scale), float(max_false_prob), float(Verifier.strong_false_prob),
            int(Verifier.confirm_patterns), int(Verifier.screen_stars), int(Verifier.min_matches),
            float(cam.width) * float(cam.height), 3.0 * radius * scale, MAX_CANDIDATES, CHECKS_PER_CHUNK, QUERY_STARS,
            MAX_PROBES, MAX_CHECKS)


def passes_by_fate(kinds: np.ndarray, fates: Any, fate: int) -> list[str]:
    """The methods of the passes ``kinds`` whose fate (``fates[i]``: :data:`RAN`, :data:`UNPROVABLE`
    or :data:`SPENT`) is ``fate``, in order."""
    return [KIND_NAMES[kinds[i]] for i in range(len(fates)) if fates[i] == fate]


SETUP_CACHE_SIZE = 64


def _setup(plan: list[tuple[NavDatabase, list[str]]], cam: Any, radius_px: float, small: bool,
           first_quad_only: bool = False
           ) -> tuple[list[tuple[NavDatabase, int]], np.ndarray, np.ndarray, Packed] | None:
    """The passes of ``plan`` (:func:`fallback_passes`) as the kernel takes them: kinds and
    members, and every member's arrays (one :class:`~.packed.Packed`); kept per plan, frame size class, camera and match radius
    (px) on the first member (every frame of a camera asks the same; building them costs ~5 us)."""
    first = plan[0][0]
    cache = first.__dict__.setdefault("_chain_setup", {})
    key = (id(plan), small, first_quad_only, cam.diagonal_fov_deg, cam.pixel_scale_rad, radius_px)
    got = cache.get(key)
    if got is not None and got[0] is plan:
        return got[1]
    passes = fallback_passes(plan, small, first_quad_only)
    setup = None
    if passes is not None:
        second = next((m for m, _ in passes if m is not first), first)
        kinds = np.array([kind for _, kind in passes], np.int64)
        members = np.array([0 if m is first else 1 for m, _ in passes], np.int64)
        # a member without the method has no such pass: another's arrays fill its arguments
        first_ma = first if "maxangle" in first.tables else second
        second_ma = second if "maxangle" in second.tables else first_ma
        quad_of = second if "quad" in second.tables else first
        static = pack((*_quad_args(quad_of, cam), *_maxangle_args(first_ma, cam, radius_px),
                       *_maxangle_args(second_ma, cam, radius_px)))
        setup = (passes, kinds, members, static)
    if len(cache) >= SETUP_CACHE_SIZE:
        cache.clear()
    cache[key] = (plan, setup)
    return setup


def _quad_args(member: NavDatabase, cam: Any) -> tuple[Any, ...]:
    """``quad_search``'s arguments of ``member`` for this camera (kept on the member)."""
    cache = member.__dict__.setdefault("_chain_quad_args", {})
    key = cam.diagonal_fov_deg
    got = cache.get(key)
    if got is None:
        qm = get_matcher(member, "quad")
        near_deg = cam.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
        got = cache[key] = (qm.patterns, qm.table, qm.spill, qm.ratio_bin, qm.edge_bin, qm.edge_max, qm.star_vec,
                            *qm.screen,
                            *field_grid(member, near_deg).kernel_args(), 2 * math.sin(math.radians(near_deg) / 2))
    return got


def _maxangle_args(member: NavDatabase, cam: Any, radius_px: float) -> tuple[Any, ...]:
    """``search_chunks``' arguments of ``member`` past the pixel scale, with ``d_max`` and
    ``xi`` (radians) for the frame's triangles."""
    matcher = get_matcher(member, "maxangle")
    return (*maxangle_args(matcher, member, cam, float(radius_px))[2:], matcher.d_max, matcher.xi)


@njit(cache=True, nogil=True)
def _chunk_bounds(total):
    """:func:`~.methods.maxangle_search.chunk_bounds`, compiled."""
    n = 1
    done, size = 0, 2
    while done < total:
        done += min(size, total - done)
        n += 1
        size = min(2 * size, 16)
    out = np.empty(n, np.int64)
    out[0] = 0
    done, size, i = 0, 2, 1
    while done < total:
        done += min(size, total - done)
        out[i] = done
        i += 1
        size = min(2 * size, 16)
    return out


_FIRST_CHUNK = np.int64(0)
"""``search_chunks``' first chunk, as an int64: a literal ``0`` there made numba compile a second
signature of that big kernel (``Literal[int](0)`` where the Python path passes an int64), ~10 s
more on an empty cache (tests/core/test_compile_signatures.py on a cold cache)."""


@njit(cache=True, nogil=True)
def _maxangle_pass(obs_vec, obs_xy, mounts, cams, dist, rows, row_off, trials, limit, n_tri, tri, tri_ext, tol,
                   radius_px,
                   pixel_scale, max_false_prob, strong_false_prob, confirm_patterns, screen_stars, max_candidates,
                   checks_per_chunk, cells, key, bucket_start, tab_x, tab_y, ids, n_buckets, b_scale, screen_chord,
                   s_cell, s_side, s_keys, s_starts, s_stars, s_columns, mask_n, mask_words, star_vec, g_cell, g_side,
                   g_keys, g_starts, g_stars, g_columns, near_chord, d_max, xi):
    """One ``maxangle`` pass (``MaxAngleMatcher.identify``). Returns ``(found, m_obs, m_cat, r,
    prob, trials, marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials)``: the marginal
    answers held, as ``quad_search`` returns its own."""
    n_obs = len(obs_vec)
    labels, sides, theta, tol_t, n_first = _triangles_extended(obs_vec, n_tri, tri, tri_ext, tol, d_max, xi)
    bounds = _chunk_bounds(n_first)
    n_chunks = len(bounds) - 1
    bounds_ext = _chunk_bounds(len(labels) - n_first)  # the extension's triangles, searched after
    room = checks_per_chunk * (n_chunks + len(bounds_ext) - 1)
    marg_r = np.empty((room, 3, 3))
    marg_prob = np.empty(room)
    marg_off = np.zeros(room + 1, np.int64)
    marg_obs = np.empty(room * n_obs, np.int64)
    marg_cat = np.empty(room * n_obs, np.int64)
    marg_trials = np.empty(room, np.int64)
    state = np.array([trials, 0, -1, 0, STOP_NONE], np.int64)
    n_others = min(n_obs, screen_stars + 3)
    found, m_obs, m_cat, r, prob, _ = search_chunks(
        obs_vec, obs_xy, labels[:n_first], sides[:n_first], theta[:n_first], tol_t[:n_first], bounds, _FIRST_CHUNK,
        n_chunks, tol, n_others, mounts, cams, dist, rows, row_off, state, limit, confirm_patterns, max_false_prob,
        strong_false_prob, checks_per_chunk, max_candidates, marg_r, marg_prob, marg_off, marg_obs, marg_cat,
        marg_trials, radius_px, pixel_scale, cells, key, bucket_start, tab_x, tab_y, ids, n_buckets, b_scale,
        screen_chord, s_cell, s_side, s_keys, s_starts, s_stars, s_columns, mask_n, mask_words, star_vec, g_cell,
        g_side, g_keys, g_starts, g_stars, g_columns, near_chord)
    if not found and state[4] == STOP_NONE and state[3] == 0 and n_first < len(labels):
        # (maxangle_search.search: the extension's triangles, at most EXTENSION_TRIALS more hypotheses)
        limit_ext = state[0] + EXTENSION_TRIALS if limit < 0 else min(limit, state[0] + EXTENSION_TRIALS)
        found, m_obs, m_cat, r, prob, _ = search_chunks(
            obs_vec, obs_xy, labels[n_first:], sides[n_first:], theta[n_first:], tol_t[n_first:], bounds_ext,
            _FIRST_CHUNK, len(bounds_ext) - 1, tol, n_others, mounts, cams, dist, rows, row_off, state, limit_ext,
            confirm_patterns, max_false_prob, strong_false_prob, checks_per_chunk, max_candidates, marg_r, marg_prob,
            marg_off, marg_obs, marg_cat, marg_trials, radius_px, pixel_scale, cells, key, bucket_start, tab_x,
            tab_y, ids, n_buckets, b_scale, screen_chord, s_cell, s_side, s_keys, s_starts, s_stars, s_columns,
            mask_n, mask_words, star_vec, g_cell, g_side, g_keys, g_starts, g_stars, g_columns, near_chord)
    n_marg = state[3]
    return (found, m_obs, m_cat, r, prob, state[0], marg_r[:n_marg], marg_prob[:n_marg], marg_off[:n_marg + 1],
            marg_obs[:marg_off[n_marg]], marg_cat[:marg_off[n_marg]], marg_trials[:n_marg])


@njit(cache=True, nogil=True)
def chain_kernel(obs_vec, obs_xy, mounts, cams, dist, rows, row_off, probes, kinds, members, trials, few_trials, n_tri,
                 tri, tri_ext, tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns,
                 screen_stars, min_matches, area, agree_limit, max_candidates, checks_per_chunk, n_use, max_probes,
                 max_checks, static):
    """:func:`_chain` with the members' arrays (``q_*``, ``a_*``, ``b_*``) as one
    :class:`~.packed.Packed` (``static``; one pointer to hand over, not ~75 arrays)."""
    return _chain(obs_vec, obs_xy, mounts, cams, dist, rows, row_off, probes, kinds, members, trials, few_trials, n_tri,
                  tri, tri_ext, tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns,
                  screen_stars, min_matches, area, agree_limit, max_candidates, checks_per_chunk, n_use, max_probes,
                  max_checks, *static.args)


@njit(cache=True, nogil=True)
def _chain(obs_vec, obs_xy, mounts, cams, dist, rows, row_off, probes, kinds, members, trials, few_trials, n_tri,
          tri, tri_ext,
          tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns, screen_stars,
          min_matches, area, agree_limit, max_candidates, checks_per_chunk, n_use, max_probes, max_checks,
          q_patterns, q_table, q_spill, q_ratio_bin, q_edge_bin, q_edge_max, q_star_vec, q_s_cell, q_s_side,
          q_s_keys,
          q_s_starts, q_s_stars, q_s_columns, q_g_cell, q_g_side, q_g_keys, q_g_starts, q_g_stars, q_g_columns,
          q_near_chord,
          a_cells, a_key, a_bucket_start, a_tab_x, a_tab_y, a_ids, a_n_buckets, a_b_scale, a_screen_chord,
          a_s_cell, a_s_side, a_s_keys, a_s_starts, a_s_stars, a_s_columns, a_mask_n, a_mask_words, a_star_vec,
          a_g_cell, a_g_side, a_g_keys, a_g_starts, a_g_stars, a_g_columns, a_near_chord, a_d_max, a_xi,
          b_cells, b_key, b_bucket_start, b_tab_x, b_tab_y, b_ids, b_n_buckets, b_b_scale, b_screen_chord,
          b_s_cell, b_s_side, b_s_keys, b_s_starts, b_s_stars, b_s_columns, b_mask_n, b_mask_words, b_star_vec,
          b_g_cell, b_g_side, b_g_keys, b_g_starts, b_g_stars, b_g_columns, b_near_chord, b_d_max, b_xi):
    """The passes ``kinds`` (:data:`KIND_QUAD`, :data:`KIND_MAXANGLE`) on ``members`` (0: the
    first member, ``a_*``; 1: the other, ``q_*`` and ``b_*``) after ``trials`` hypotheses.
    Returns ``(status, pass, m_obs, m_cat, r, prob, n_trials, trials, ran)``: ``status``
    :data:`CHAIN_FOUND` with the answer of pass ``pass``, :data:`CHAIN_NONE`, or
    :data:`CHAIN_BACK` for the general loop; ``ran`` what became of each pass."""
    n_obs = len(obs_vec)
    ran = np.zeros(len(kinds), np.int64)
    limit = -1
    empty = np.zeros(0, np.int64)
    for i in range(len(kinds)):
        before = trials
        if kinds[i] == KIND_MAXANGLE:
            if limit < 0:
                limit = trials + few_trials  # the budget starts at the first fallback
            # Verifier.could_prove(3): every star paired is the best case
            extra = n_obs - 3
            p = min(1.0, n_obs * math.pi * radius_px * radius_px / area)
            if n_obs < min_matches or extra < 1 or p ** extra * max(trials, 1) > max_false_prob:
                ran[i] = UNPROVABLE
                continue
        if limit >= 0 and trials >= limit:
            ran[i] = SPENT
            continue
        ran[i] = RAN
        exhausted = True
        if kinds[i] == KIND_MAXANGLE:
            # one call site (the search's code is compiled into each)
            if members[i] == 0:
                member = (a_cells, a_key, a_bucket_start, a_tab_x, a_tab_y, a_ids, a_n_buckets, a_b_scale,
                          a_screen_chord, a_s_cell, a_s_side, a_s_keys, a_s_starts, a_s_stars, a_s_columns, a_mask_n,
                          a_mask_words, a_star_vec, a_g_cell, a_g_side, a_g_keys, a_g_starts, a_g_stars, a_g_columns,
                          a_near_chord, a_d_max, a_xi)
            else:
                member = (b_cells, b_key, b_bucket_start, b_tab_x, b_tab_y, b_ids, b_n_buckets, b_b_scale,
                          b_screen_chord, b_s_cell, b_s_side, b_s_keys, b_s_starts, b_s_stars, b_s_columns, b_mask_n,
                          b_mask_words, b_star_vec, b_g_cell, b_g_side, b_g_keys, b_g_starts, b_g_stars, b_g_columns,
                          b_near_chord, b_d_max, b_xi)
            found, m_obs, m_cat, r, prob, trials, marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials = \
                _maxangle_pass(obs_vec, obs_xy, mounts, cams, dist, rows, row_off, trials, limit, n_tri, tri, tri_ext,
                               tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns,
                               screen_stars, max_candidates, checks_per_chunk, *member)
        else:  # quad on the other member
            search = quad_search(obs_vec, obs_xy, n_use, tol, q_patterns, q_table, q_spill, q_ratio_bin, q_edge_bin,
                                 q_edge_max, q_star_vec, q_s_cell, q_s_side, q_s_keys, q_s_starts, q_s_stars,
                                 q_s_columns, q_g_cell, q_g_side, q_g_keys, q_g_starts, q_g_stars, q_g_columns,
                                 q_near_chord, mounts, cams, dist, rows, row_off, radius_px, pixel_scale,
                                 max_false_prob, strong_false_prob, confirm_patterns, screen_stars, trials, max_probes,
                                 max_checks)
            found = search[0] == STATUS_FOUND
            m_obs, m_cat, r, prob, trials, exhausted = search[3], search[4], search[5], search[6], search[7], search[9]
            marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials = search[10:16]
        if found:
            return CHAIN_FOUND, i, m_obs, m_cat, r, prob, trials, trials, ran
        if len(marg_prob):  # Verifier.best_marginal: the likeliest, if all agree
            k = marginal_choice(marg_r, marg_prob, marg_off, marg_obs, marg_cat, probes, agree_limit)
            if k >= 0:
                lo, hi = marg_off[k], marg_off[k + 1]
                return CHAIN_FOUND, i, marg_obs[lo:hi].copy(), marg_cat[lo:hi].copy(), marg_r[k].copy(), \
                    marg_prob[k], marg_trials[k], trials, ran
        if kinds[i] == KIND_QUAD:
            if not exhausted:  # not every pattern (or answers that disagree): the general loop
                return CHAIN_BACK, i, empty, empty, np.eye(3), 1.0, trials, trials, ran
            if limit >= 0:
                limit += trials - before  # the budget is the fallbacks' own
    return CHAIN_NONE, -1, empty, empty, np.eye(3), 1.0, trials, trials, ran


_CHAIN = EntryCall(chain_kernel)
"""``chain_kernel`` past the dispatcher once its signature is known (:mod:`._entry`: 14 of
~45 us a call)."""
