"""The ``quad`` search as one compiled call: body vectors in, the first verified attitude out.

Patterns of the brightest observed stars (4-combinations in brightness order: every pattern of
stars ``0..3``, then those adding star 4, ...: :data:`COMBOS`) are keyed like the table's (see
:mod:`.quad_build`), looked up in every key bin their tolerance reaches (a key's spill list
from its first entry whose largest edge can match to its last: the list is sorted by that edge),
and each candidate whose six angles all agree within ``tol`` is labelled (the vertex order of
the 24 that fits best) and tried as a hypothesis exactly as :class:`~service.core.verify.Verifier`
would:

1. attitude by Wahba's problem (:func:`~service.core.attitude.wahba_kernel`);
2. screen: the brightest other stars must hit a catalogue star within 1.5 match radii
   (:func:`~service.core.skygrid.has_star_within`, the verifier's screen);
3. pairing and refits (:func:`~service.core.match._refine`), the near-miss test
   (``_settle``, the verifier's ``SETTLE_FACTORS``) and the coincidence bound
   ``P = trials * P[Binomial(n_free, p) >= n_extra]``.

Every candidate that passes the angle test is a trial. A strong answer (``P <=
strong_false_prob``) ends the search; a marginal one (``P <= max_false_prob``) is kept, and the
search goes on for ``confirm_patterns`` more patterns, as the verifier does. A candidate whose
four pairs a kept marginal answer already makes is counted as a trial but not checked
(:func:`~service.core.check_kernel.names_marginal`) when that answer is *closed*: it pairs
every star of the frame, or no unpaired star lies within
:data:`~service.core.check_kernel.RECHECK_REACH` match radii of a catalogue star under its
attitude (:func:`~service.core.check_kernel.could_pair_more`), so a check from another pattern
could only reach the same pairs again. (Seed 002's 6-star frames, where 4 + 2 stars are
marginal at 4096 px, checked the same identification through each of their 15 patterns: 82 ->
36 us a search. Without the closed condition a later check sometimes pairs one more star, and 14
frames of 47,500 named one star fewer.) The work is bounded inside the loop (``max_probes`` hash
probes, ``max_checks`` full verifications), not by a clock between Python batches. The checks
themselves are :mod:`service.core.check_kernel`'s.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from ..attitude import wahba_kernel
from ..check_kernel import RECHECK_REACH, could_pair_more, keep_marginal, names_marginal, verify_pairs
from ..match import MIN_MATCHES, needed_hits
from ..prefetch import prefetch
from ..screen import hits_under
from ..verify import NEED_SCREEN_FACTOR
from .quad_build import (
    FINE_BITS,
    FINE_STEPS,
    FINGER_BITS,
    N_RATIO_BINS,
    SPILL_COUNT_MASK,
    SPILL_OFFSET_MASK,
    combine_key,
    key_hash,
    row_angle,
    sorted_edges,
)

PERMS = np.array([[a, b, c, d] for a in range(4) for b in range(4) for c in range(4) for d in range(4)
                  if len({a, b, c, d}) == 4], dtype=np.int64)
"""The 24 vertex orders of a pattern."""
EDGE_PAIRS = np.array([[i, j] for i in range(4) for j in range(i + 1, 4)], dtype=np.int64)
MAX_MARGINAL = 8
PATTERN_PROBE_CAP = 4096
"""Hash probes above which a pattern is looked up only after every cheaper pattern of the frame:
a small pattern at 2 px of noise has its ratios known so loosely that its bins multiply across
the six coordinates (9 bins a ratio: 9^5 x 3 = 177,000 probes), each probe a likely cache miss,
and it matches hundreds of catalogue patterns. Skipping such patterns lost frames that only a
tight cluster proves (the Pleiades' brightest, 50,000-65,000 probes a pattern), so they wait."""

LONG_LISTS = 1.0
"""A table whose spill list holds more entries than this many times its slots (the default set's
deep ``narrow`` member: 2.9 million entries, 23 in the list a probe meets on average) has each
pattern's lists requested a pattern ahead (:func:`_prefetch_lists`): they cost a cache miss
each, after the table word that points at them. It walks the next pattern's probes once more,
which a table of short lists (``mid``: 0.4 million, 4 a list) does not repay: on seed 000's
random points, in sequence, narrow's pass 253-262 -> 235-237 us, mid's 173-175 -> 219-220."""
FINGER_MASK = (1 << FINGER_BITS) - 1
STATUS_NONE, STATUS_FOUND, STATUS_MARGINAL = 0, 1, 2


@njit(cache=True, nogil=True, inline="always")
def _label(obs_vec: np.ndarray, o: np.ndarray, star_vec: np.ndarray, c: np.ndarray, tol: float,
           out: np.ndarray) -> bool:
    """The vertex order of catalogue stars ``c`` that best fits observed ``o`` (every angle
    within ``tol``), written to ``out``; False if none fits."""
    eo = np.empty(6)
    ec = np.empty((4, 4))
    for k in range(6):
        i, j = EDGE_PAIRS[k, 0], EDGE_PAIRS[k, 1]
        eo[k] = row_angle(obs_vec, o[i], o[j])
        ec[i, j] = ec[j, i] = row_angle(star_vec, c[i], c[j])
    best = tol
    found = False
    for p in range(24):
        worst = 0.0
        for k in range(6):
            err = abs(eo[k] - ec[PERMS[p, EDGE_PAIRS[k, 0]], PERMS[p, EDGE_PAIRS[k, 1]]])
            if err > worst:
                worst = err
                if worst > best:
                    break
        if worst <= best:
            best = worst
            found = True
            for i in range(4):
                out[i] = c[PERMS[p, i]]
    return found


MAX_QUERY_STARS = 16
"""Most observed stars whose patterns a search may form (``n_use`` is capped here)."""
COMBOS = np.array([[a, b, c, d] for d in range(3, MAX_QUERY_STARS) for a in range(d) for b in range(a + 1, d)
                   for c in range(b + 1, d)], dtype=np.int64)
"""Every 4-combination of the brightest stars in search order: those of stars 0..3, then those
adding star 4, ... (so those of the ``n`` brightest are the first ``COMBO_COUNT[n]``)."""
COMBO_COUNT = np.array([math.comb(n, 4) for n in range(MAX_QUERY_STARS + 1)], dtype=np.int64)
LOOK_AHEAD = 2
"""Patterns whose first table words are requested before the current one is scanned (pattern
``k + 2``'s at pattern ``k``), so that their misses overlap the scan: a pattern's own ~7 probes
alone kept too few misses in flight."""


KEY_STRIDES = np.array([N_RATIO_BINS ** 4, N_RATIO_BINS ** 3, N_RATIO_BINS ** 2, N_RATIO_BINS, 1, N_RATIO_BINS ** 5],
                       dtype=np.int64)
"""What one step of each bin coordinate adds to :func:`~.quad_build.combine_key`'s key (it is
linear in the bins): a box's keys are stepped through, not recombined at each probe."""


@njit(cache=True, nogil=True, inline="always")
def _next_key(cur: np.ndarray, bins: np.ndarray, row: int, key: np.int64) -> np.int64:
    """Advance the bin combination ``cur`` (6,) over ``bins[row, :6]..bins[row, 6:]`` (first
    coordinate fastest) and return the key of the new one, from ``key``, the old one's."""
    for i in range(6):
        if cur[i] < bins[row, 6 + i]:
            cur[i] += 1
            return key + KEY_STRIDES[i]
        key -= (cur[i] - bins[row, i]) * KEY_STRIDES[i]
        cur[i] = bins[row, i]
    return key


@njit(cache=True, nogil=True, inline="always")
def _probe(key: np.int64, mask: np.uint64) -> tuple[np.uint64, np.int64]:
    """A key's first table slot (its hash's low bits) and its finger (the hash's top
    ``FINGER_BITS``, as :func:`~.quad_build.slot_word` stores them)."""
    h = key_hash(key)
    return h & mask, np.int64(h >> np.uint64(64 - FINGER_BITS))


@njit(cache=True, nogil=True, inline="always")
def _finger_of(word: np.int64) -> np.int64:
    """The finger a table word holds (entry and pointer words alike)."""
    return (word >> (6 * FINE_BITS)) & FINGER_MASK


@njit(cache=True, nogil=True, inline="always")
def _first_edge_step(spill, first, end, step):
    """The first entry of ``spill[first:end]`` (sorted by the largest edge's fine step, the
    word's low bits) whose step is at least ``step``."""
    while end - first > 8:  # bisect a long list, then step
        mid = (first + end) // 2
        if spill[mid] & (FINE_STEPS - 1) >= step:
            end = mid
        else:
            first = mid + 1
    while first < end and spill[first] & (FINE_STEPS - 1) < step:
        first += 1
    return first


@njit(cache=True, nogil=True, inline="always")
def _pattern_box(angles, k, tol, ratio_bin, edge_bin, edge_max, r_f, r_b, row):
    """Pattern ``COMBOS[k]``'s sorted edges ``e`` (radians, from the observed stars' ``angles``),
    key coordinates ``x`` +- ``t`` and bins ``lo..hi``, into ``row`` of the rings ``r_f`` (``e``,
    ``x``, ``t``: columns 0-5, 6-11, 12-17) and ``r_b`` (``lo``, ``hi``: 0-5, 6-11); returns the
    probes it needs, or -1 if its size is outside the table's. (Rows indexed, no row view, one
    return, two arrays: where it is inlined, a view or a second exit kept numba's reference
    counts of its arrays, taken and given back every pattern, and each array left a pair.)"""
    n = 0
    for i in range(4):
        for j in range(i + 1, 4):
            v = angles[COMBOS[k, i], COMBOS[k, j]]
            m = n
            while m > 0 and r_f[row, m - 1] > v:  # insertion: the six angles ascending, as sorted_edges
                r_f[row, m] = r_f[row, m - 1]
                m -= 1
            r_f[row, m] = v
            n += 1
    big = r_f[row, 5]
    total = -1
    if big <= edge_max + tol and big > 4 * tol:
        total = 1
        for i in range(6):
            if i < 5:
                x = r_f[row, i] / big / ratio_bin
                t = tol * (1.0 + r_f[row, i] / big) / big / ratio_bin
            else:
                x = big / edge_bin
                t = tol / edge_bin
            r_f[row, 6 + i], r_f[row, 12 + i] = x, t
            r_b[row, i] = max(int(x - t), 0)
            r_b[row, 6 + i] = int(x + t)
            if i < 5:
                r_b[row, 6 + i] = min(r_b[row, 6 + i], N_RATIO_BINS - 1)
            total *= r_b[row, 6 + i] - r_b[row, i] + 1
    return total


@njit(cache=True, nogil=True, inline="always")
def _prefetch_slots(table, mask, r_b, total, row, cur):
    """Request the first table words of each of the ``total`` probes of box ``row``: the slot's
    cache line and the next one (a probe walks its key's cluster until an empty slot, 3-12 words
    on the default set's tables; with the next line requested too, the quad pass on seed 000's
    random points took 7-10% less in sequence)."""
    for i in range(6):
        cur[i] = r_b[row, i]
    key = combine_key(cur)
    for _ in range(total):
        slot, _ = _probe(key, mask)
        prefetch(table, np.int64(slot))
        prefetch(table, np.int64((slot + np.uint64(8)) & mask))  # the next line: a walk crosses into it
        key = _next_key(cur, r_b, row, key)


@njit(cache=True, nogil=True, inline="always")
def _look_ahead(angles, k, tol, ratio_bin, edge_bin, edge_max, r_f, r_b, r_total, table, mask, cur):
    """Box pattern ``k`` into its ring row and request its slots if it is a cheap one."""
    row = k % (LOOK_AHEAD + 1)
    total = _pattern_box(angles, k, tol, ratio_bin, edge_bin, edge_max, r_f, r_b, row)
    r_total[row] = total
    if 0 <= total <= PATTERN_PROBE_CAP:
        _prefetch_slots(table, mask, r_b, total, row, cur)


@njit(cache=True, nogil=True, inline="always")
def _prefetch_lists(table, spill, mask, r_b, total, row, cur):
    """Walk box ``row``'s probes (its table words requested a pattern ago) and request the first,
    middle and last lines of each spill list they point at (:func:`_first_edge_step` bisects it)."""
    for i in range(6):
        cur[i] = r_b[row, i]
    key = combine_key(cur)
    for _ in range(total):
        sl, finger = _probe(key, mask)
        while table[sl] != 0:
            word = table[sl]
            sl = (sl + np.uint64(1)) & mask
            if word < 0 and _finger_of(word) == finger:
                first = (word >> 32) & SPILL_OFFSET_MASK
                n = word & SPILL_COUNT_MASK
                prefetch(spill, np.int64(first))
                if n > 8:
                    prefetch(spill, np.int64(first + n // 2))
                if n > 16:
                    prefetch(spill, np.int64(first + n - 1))
        key = _next_key(cur, r_b, row, key)


@njit(cache=True, nogil=True)
def quad_search(obs_vec, obs_xy, n_use, tol, patterns, table, spill, ratio_bin, edge_bin, edge_max,
                star_vec, s_cell, s_side, s_keys, s_starts, s_stars, s_columns,
                g_cell, g_side, g_keys, g_starts, g_stars, g_columns, near_chord,
                mounts, cams, dist, rows, row_off, radius_px, pixel_scale, max_false_prob, strong_false_prob,
                confirm_patterns, screen_stars, trials0, max_probes, max_checks):
    """Search ``obs_vec`` ``(N, 3)`` (brightest first; one camera) for a verified attitude.

    ``patterns``, ``table`` and ``spill`` are the database's pattern table (:mod:`.quad_build`;
    ``spill`` is empty for a table of the layout before it, every entry in ``table``); ``tol``
    is the angle tolerance (radians).

    Returns ``(status, hyp_obs, hyp_cat, m_obs, m_cat, r, prob, trials, n_patterns, exhausted,
    marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials)``: ``status`` 1 with the
    strong answer, 2 with marginal answers only (``marg_*``: matrices, bounds, pairs of each
    ``k`` in ``marg_off[k]:marg_off[k + 1]``, trials), 0 with none. ``exhausted``: every
    pattern of the ``n_use`` brightest stars was looked up within the work bounds.
    """
    n_obs = len(obs_vec)
    n_use = min(n_use, n_obs)
    mask = np.uint64(len(table) - 1)
    radius_rad = radius_px * pixel_scale
    quick_tol = radius_rad * 1.5
    screen_chord = 1.5 * radius_rad
    n_screen = min(n_obs, screen_stars + 3)
    mount = mounts[0]
    buf = np.empty(len(star_vec), np.int64)
    near_state = np.zeros(4)  # the gathered field's size and boresight (_field): updated in place, so no
    # array is reassigned inside the lookup loop (numba would count references on every table word)
    o = np.empty(4, np.int64)
    c = np.empty(4, np.int64)
    lab = np.empty(4, np.int64)
    e = np.empty(6)
    ec = np.empty(6)
    x = np.empty(6)
    t = np.empty(6)
    f_lo = np.empty(6, np.int64)
    lo_fine = np.empty(6, np.int64)
    hi_fine = np.empty(6, np.int64)
    f_hi = np.empty(6, np.int64)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cur = np.empty(6, np.int64)
    trials = trials0
    probes = 0
    checks = 0
    cands = 0
    n_pat = 0
    first_marg = -1
    marg_r = np.zeros((MAX_MARGINAL, 3, 3))
    marg_prob = np.zeros(MAX_MARGINAL)
    marg_trials = np.zeros(MAX_MARGINAL, np.int64)
    marg_closed = np.zeros(MAX_MARGINAL, np.bool_)  # no check could pair more (see the docstring)
    reach_chord = RECHECK_REACH * radius_rad
    marg_off = np.zeros(MAX_MARGINAL + 1, np.int64)
    marg_obs = np.zeros(MAX_MARGINAL * n_obs, np.int64)
    marg_cat = np.zeros(MAX_MARGINAL * n_obs, np.int64)
    n_marg = np.int64(0)  # (an int64 from the start: a literal 0 gave its callees a second signature)
    exhausted = True
    empty = np.zeros(0, np.int64)
    deferred = 0
    n_comb = COMBO_COUNT[min(n_use, MAX_QUERY_STARS)]
    long_lists = len(spill) > LONG_LISTS * len(table)
    r_f = np.empty((LOOK_AHEAD + 1, 18))  # the boxes of the pattern looked up and the next LOOK_AHEAD:
    r_b = np.empty((LOOK_AHEAD + 1, 12), np.int64)  # e, x, t and lo, hi (see _pattern_box)
    r_total = np.empty(LOOK_AHEAD + 1, np.int64)
    n_ang = min(n_use, MAX_QUERY_STARS)
    angles = np.empty((n_ang, n_ang))  # between the brightest stars, each computed once
    for i in range(n_ang):
        for j in range(i + 1, n_ang):
            angles[i, j] = angles[j, i] = row_angle(obs_vec, i, j)
    for phase in range(2):  # cheap patterns, then the deferred costly ones
        if phase == 1 and (deferred == 0 or not exhausted):
            break
        if phase == 0:  # the look-ahead: see _look_ahead
            for k in range(min(LOOK_AHEAD, n_comb)):
                _look_ahead(angles, k, tol, ratio_bin, edge_bin, edge_max, r_f, r_b, r_total, table, mask,
                            cur)
        for k in range(n_comb):
            if first_marg >= 0 and n_pat - first_marg >= confirm_patterns:
                return (STATUS_MARGINAL, o, c, empty, empty, np.eye(3), 1.0, trials, n_pat, False,
                        marg_r[:n_marg], marg_prob[:n_marg], marg_off[:n_marg + 1],
                        marg_obs[:marg_off[n_marg]], marg_cat[:marg_off[n_marg]], marg_trials[:n_marg], probes, cands)
            if probes > max_probes or checks > max_checks:
                exhausted = False
                break
            for i in range(4):
                o[i] = COMBOS[k, i]
            row = k % (LOOK_AHEAD + 1)
            if phase == 0:
                if k + LOOK_AHEAD < n_comb:  # _look_ahead, written out: an inlined call here took and
                    # gave back a reference count for each of its ten arrays, every pattern
                    ahead = (k + LOOK_AHEAD) % (LOOK_AHEAD + 1)
                    n_ahead = _pattern_box(angles, k + LOOK_AHEAD, tol, ratio_bin, edge_bin, edge_max, r_f,
                                           r_b, ahead)
                    r_total[ahead] = n_ahead
                    if 0 <= n_ahead <= PATTERN_PROBE_CAP:
                        _prefetch_slots(table, mask, r_b, n_ahead, ahead, cur)
                if long_lists and k + 1 < n_comb:  # the next pattern's lists (LONG_LISTS)
                    nxt = (k + 1) % (LOOK_AHEAD + 1)
                    if 0 <= r_total[nxt] <= PATTERN_PROBE_CAP:
                        _prefetch_lists(table, spill, mask, r_b, r_total[nxt], nxt, cur)
                total = r_total[row]
                if total < 0:
                    n_pat += 1  # counted once, never looked up
                    continue
                if total > PATTERN_PROBE_CAP:
                    deferred += 1
                    continue  # costly patterns after every cheap one (PATTERN_PROBE_CAP)
            else:
                total = _pattern_box(angles, k, tol, ratio_bin, edge_bin, edge_max, r_f, r_b, row)
                if total <= PATTERN_PROBE_CAP:
                    continue  # a cheap pattern, looked up in phase 0 (or outside the table's sizes)
                r_total[row] = total
                _prefetch_slots(table, mask, r_b, total, row, cur)
            n_pat += 1
            probes += total
            for i in range(6):
                e[i], x[i], t[i] = r_f[row, i], r_f[row, 6 + i], r_f[row, 12 + i]
                lo[i], hi[i] = r_b[row, i], r_b[row, 6 + i]
            for i in range(6):  # where the query's range lies inside its first and last bin
                lo_fine[i] = max(int((x[i] - t[i] - lo[i]) * FINE_STEPS), 0)
                hi_fine[i] = min(int((x[i] + t[i] - hi[i]) * FINE_STEPS), FINE_STEPS - 1)
            for i in range(6):  # the box's first bin; then its key and fine bounds move with it
                cur[i] = lo[i]
                f_lo[i] = lo_fine[i]
                f_hi[i] = hi_fine[i] if lo[i] == hi[i] else FINE_STEPS - 1
            key = combine_key(cur)
            for _ in range(total):
                sl, finger = _probe(key, mask)
                while table[sl] != 0:
                    word = table[sl]
                    sl = (sl + np.uint64(1)) & mask
                    if _finger_of(word) != finger:
                        continue
                    first, end = 0, 1
                    if word < 0:  # a key's entries in the spill list (quad_build.SPILL_OVER), by edge step
                        first = (word >> 32) & SPILL_OFFSET_MASK
                        end = first + (word & SPILL_COUNT_MASK)
                        first = _first_edge_step(spill, first, end, f_lo[5])
                    for j in range(first, end):
                        entry = spill[j] if word < 0 else word
                        if word < 0 and entry & (FINE_STEPS - 1) > f_hi[5]:
                            break  # the rest lie past the query's largest edge
                        inside = True
                        for i in range(6):
                            fi = (entry >> (FINE_BITS * (5 - i))) & (FINE_STEPS - 1)
                            if fi < f_lo[i] or fi > f_hi[i]:
                                inside = False
                                break
                        if not inside:
                            continue
                        p = (entry >> 32) - 1
                        cands += 1
                        for i in range(4):
                            c[i] = patterns[p, i]
                        sorted_edges(star_vec, c, ec)
                        fits = True
                        for i in range(6):
                            if abs(ec[i] - e[i]) > tol:
                                fits = False
                                break
                        if fits and _label(obs_vec, o, star_vec, c, tol, lab):
                            trials += 1
                            if n_marg > 0 and names_marginal(o, lab, marg_off, marg_obs, marg_cat, n_marg,
                                                             marg_closed):
                                continue  # a closed answer reached again: see the docstring
                            checks += 1
                            res = _verify(obs_vec, obs_xy, star_vec, o, lab, n_screen, screen_chord,
                                          s_cell, s_side, s_keys, s_starts, s_stars, s_columns,
                                          g_cell, g_side, g_keys, g_starts, g_stars, g_columns,
                                          near_chord, mount, buf, near_state, mounts, cams, dist,
                                          rows, row_off, radius_px, quick_tol, trials, max_false_prob)
                            ok, m_obs, m_cat, r, prob = res
                            if ok and prob <= max_false_prob:
                                if prob <= strong_false_prob:
                                    return (STATUS_FOUND, o.copy(), lab.copy(), m_obs, m_cat, r, prob,
                                            trials, n_pat, False, marg_r[:0], marg_prob[:0],
                                            marg_off[:1], empty, empty, marg_trials[:0], probes, cands)
                                if n_marg < MAX_MARGINAL:
                                    n_marg = keep_marginal(marg_r, marg_prob, marg_trials, marg_off, marg_obs,
                                                           marg_cat, n_marg, r, prob, trials, m_obs, m_cat)
                                    marg_closed[n_marg - 1] = len(m_obs) == n_obs or not could_pair_more(
                                        obs_vec, m_obs, r, reach_chord, s_cell, s_side, s_keys, s_starts,
                                        s_stars, star_vec, s_columns)
                                if first_marg < 0:
                                    first_marg = n_pat
                for i in range(6):  # the next bin (first coordinate fastest), as _next_key
                    if cur[i] < hi[i]:
                        cur[i] += 1
                        key += KEY_STRIDES[i]
                        f_lo[i] = 0
                        f_hi[i] = hi_fine[i] if cur[i] == hi[i] else FINE_STEPS - 1
                        break
                    key -= (cur[i] - lo[i]) * KEY_STRIDES[i]
                    cur[i] = lo[i]
                    f_lo[i] = lo_fine[i]
                    f_hi[i] = hi_fine[i] if lo[i] == hi[i] else FINE_STEPS - 1
    status = STATUS_MARGINAL if n_marg else STATUS_NONE
    return (status, o, c, empty, empty, np.eye(3), 1.0, trials, n_pat, exhausted and n_marg == 0,
            marg_r[:n_marg], marg_prob[:n_marg], marg_off[:n_marg + 1], marg_obs[:marg_off[n_marg]],
            marg_cat[:marg_off[n_marg]], marg_trials[:n_marg], probes, cands)


_PATTERN = np.int64(4)
"""A pattern's stars as ``needed_hits`` takes them: an int64 (see ``match.MIN_MATCHES``)."""


@njit(cache=True, nogil=True)
def _verify(obs_vec, obs_xy, star_vec, o, lab, n_screen, screen_chord, s_cell, s_side, s_keys, s_starts,
            s_stars, s_columns, g_cell, g_side, g_keys, g_starts, g_stars, g_columns, near_chord, mount, buf,
            near_state, mounts, cams, dist, rows, row_off, radius_px, quick_tol, trials, max_false_prob):
    """One hypothesis (observed rows ``o`` are catalogue rows ``lab``) through the verifier's
    steps. Returns ``(ok, m_obs, m_cat, r, prob)``."""
    empty = np.zeros(0, np.int64)
    r = wahba_kernel(obs_vec[o], star_vec[lab], np.ones(4))
    n_obs = len(obs_vec)
    if n_obs > 4:
        # the screen: some other bright star must land on a catalogue star, and as many as a
        # check would need to pass the bound (needed_hits) unless the wide screen finds them
        # (the verifier's NEED_SCREEN_FACTOR)
        need = max(1, needed_hits(n_obs, _PATTERN, n_screen, radius_px, cams[0, 3] * cams[0, 4], trials,
                                  max_false_prob, MIN_MATCHES))
        hits = hits_under(obs_vec, o, r, n_screen, screen_chord, need, lab[0], lab[1], lab[2], s_cell, s_side,
                          s_keys, s_starts, s_stars, star_vec, s_columns)
        if hits == 0:
            return False, empty, empty, r, 1.0
        if hits < need and hits_under(obs_vec, o, r, n_screen, NEED_SCREEN_FACTOR * screen_chord, need, lab[0],
                                      lab[1], lab[2], s_cell, s_side, s_keys, s_starts, s_stars, star_vec,
                                      s_columns) < need:
            return False, empty, empty, r, 1.0
    return verify_pairs(obs_vec, obs_xy, star_vec, o, lab, r, g_cell, g_side, g_keys, g_starts, g_stars, g_columns,
                        near_chord, mount, buf, near_state, mounts, cams, dist, rows, row_off, radius_px,
                        quick_tol, trials)


def unpack_search(ints: np.ndarray, floats: np.ndarray) -> tuple[Any, ...]:
    """:func:`quad_search`'s result from :func:`pack_search`'s arrays (an unsolved
    :class:`~service.core.first_pass.FirstPass`'s ``search``; unpacked only where it is used:
    ~5 us)."""
    status, trials, n_pat, exhausted, probes, cands, n_m, k, n_l = ints[:9].tolist()
    i = 9
    hyp_obs, hyp_cat = ints[i:i + 4], ints[i + 4:i + 8]
    i += 8
    m_obs, m_cat = ints[i:i + n_m], ints[i + n_m:i + 2 * n_m]
    i += 2 * n_m
    marg_off = ints[i:i + k + 1]
    i += k + 1
    marg_obs, marg_cat = ints[i:i + n_l], ints[i + n_l:i + 2 * n_l]
    marg_trials = ints[i + 2 * n_l:i + 2 * n_l + k]
    return (status, hyp_obs, hyp_cat, m_obs, m_cat, floats[:9].reshape(3, 3), float(floats[9]), trials, n_pat,
            bool(exhausted), floats[10:10 + 9 * k].reshape(k, 3, 3), floats[10 + 9 * k:10 + 10 * k], marg_off,
            marg_obs, marg_cat, marg_trials, probes, cands)


@njit(cache=True, nogil=True)
def pack_search(search):
    """:func:`quad_search`'s result as one int64 and one float64 array
    (a compiled call returns each array it hands to Python at ~0.3 us apiece; the search has 11)."""
    status, hyp_obs, hyp_cat, m_obs, m_cat, r, prob, trials, n_pat, exhausted = search[:10]
    marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials, probes, cands = search[10:]
    n_m, k, n_l = len(m_obs), len(marg_prob), len(marg_obs)
    ints = np.empty(9 + 8 + 2 * n_m + k + 1 + 2 * n_l + k, np.int64)
    ints[0], ints[1], ints[2], ints[3], ints[4], ints[5] = status, trials, n_pat, exhausted, probes, cands
    ints[6], ints[7], ints[8] = n_m, k, n_l
    i = 9
    ints[i:i + 4] = hyp_obs
    ints[i + 4:i + 8] = hyp_cat
    i += 8
    ints[i:i + n_m] = m_obs
    ints[i + n_m:i + 2 * n_m] = m_cat
    i += 2 * n_m
    ints[i:i + k + 1] = marg_off
    i += k + 1
    ints[i:i + n_l] = marg_obs
    ints[i + n_l:i + 2 * n_l] = marg_cat
    ints[i + 2 * n_l:] = marg_trials
    floats = np.empty(10 + 10 * k)
    floats[:9] = r.ravel()
    floats[9] = prob
    floats[10:10 + 9 * k] = marg_r.ravel()
    floats[10 + 9 * k:] = marg_prob
    return ints, floats
