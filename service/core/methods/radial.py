"""``radial``: radial-feature pre-identification, then triangles among the candidates (seed 002).

Radial feature of a star S: rings of width ``dr`` around S out to radius ``R``
(``G_1 ... G_Nq``, ``Nq = ceil(R / dr)``); bit ``B_h`` is set when any star lies in ring ``h``.
The database holds it for every catalogue star as a packed bit array; the frame's stars get
theirs from the other observed stars. Each observed star's initial candidates are the
catalogue stars whose feature agrees with its own (below); then side-side-side triangle
matching (``|d_cat - d_obs| <= eps`` on all three sides) runs only over the candidates of the
triangle's three stars, ``m1 m2 m3`` combinations instead of the whole catalogue, and every
surviving triple goes to the shared verifier (a fourth star must agree).

Table: ``codes`` ``(Nq / 64, N)`` uint64, word-major (word ``h >> 6`` of all stars is one
contiguous row, so scoring reads whole rows): bit ``h & 63`` of ``codes[h >> 6, s]`` is ``B_h``
of star ``s``.

Where the paper is vague or weak, and what we chose (measured in docs/methods.md):

- **R and dr.** The paper takes ``R`` = the largest and ``dr`` = the smallest angular distance
  in the frame; codes built per frame cannot be stored. We fix ``R`` = the image diagonal (the
  largest distance a frame can hold) and ``dr = R / n_rings`` with ``n_rings`` = 1024 (~20" on
  the 4x4 deg camera, ~2 pattern tolerances).
- **Score.** ``score="paper"``: ``l = popcount(B_cat AND B_obs)`` with one bit per observed
  neighbour, candidate when ``l >= 3/4 Nq``. Read literally (``Nq`` = all rings) no star of a
  sparse frame can pass (an observed star with 4 neighbours sets 4 of 1024 bits), so ``Nq`` is
  read as the number of rings the observed feature occupies. ``score="neighbours"`` (default):
  the number of observed neighbours whose ring window ``[d - eps, d + eps]`` holds a catalogue
  bit (a neighbour on a ring edge is not lost to noise, and each neighbour counts once);
  candidate when at least ``min_fraction`` (3/4) of them match (``threshold="fraction"``).
- **Threshold** (ours, the default ``threshold="significance"``): a candidate when fewer than
  ``MAX_EXPECTED_FALSE`` catalogue stars are expected to score as well by chance (binomial in
  the share of the candidate's rings that are set); a fixed 3/4 rejects real stars beside false
  ones. Either threshold keeps the ``MAX_CANDIDATES`` best. ``score="paper", threshold="fraction"``
  is the faithful reading.
- **Triangle order.** Observed triangles with the fewest ``m1 m2 m3`` combinations first;
  candidates are scored lazily, star by star.
- **Informative radius** (issue 16). A neighbour at distance ``r`` matches a catalogue star by
  chance when any catalogue neighbour falls in its window ``2 eps + dr``; on a wide field with
  coarse pixels the outer windows are all occupied (seed 004: ~4.5 catalogue stars expected in
  a window at 25 deg) and no candidate can be significant (0% before this). Only neighbours
  within :func:`informative_radius` (where the window's chance occupancy is below one half)
  score, and a candidate's fill is counted over the rings inside it: the same rings out to a
  smaller ``R``, as the paper's ``R`` is the frame's own largest distance.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from itertools import combinations
from typing import Any

import numpy as np
from numba import njit
from scipy.special import bdtrc

from ..catalog import StarTable
from ..geometry import pairwise_angles
from ..navdb.reader import NavDatabase
from ..verify import Verified
from ._pairs import build_pair_table, same_handedness
from .base import Progress, SolveContext

MAX_CANDIDATES = 64
"""At most this many catalogue candidates per observed star (best scores first)."""
MAX_TRIPLES = 64
"""Triangles matching more candidate triples than this are skipped as uninformative."""
MAX_EXPECTED_FALSE = 256.0
"""``threshold="significance"``: a score is kept when fewer than this many catalogue stars are
expected to reach it by chance. The binomial estimate runs high: on 4- and 5-star frames of the
8.0 Mv seed-002 camera 2-16 catalogue stars reached the full score where it predicted 69-83, and
a bound of 64 dropped the true star (ranked 0-2) from 2 of 1996 such frames; at 256 none is
lost, and ``MAX_CANDIDATES`` still caps the list."""
MAX_NEIGHBOURS = 24
"""Observed neighbours used in a star's feature: the nearest within :meth:`RadialMatcher.reach`
(all the frame's stars are candidates: in a 20 deg field at 6.5 Mv the 24 brightest leave
about 3 within the 3.9 deg that score)."""
CHANCE_OCCUPANCY = 0.5
"""A ring window whose chance of holding a catalogue neighbour is above this carries too little
information to score (see :func:`informative_radius`)."""


def informative_radius(n_stars: int, ring_rad: float, eps_rad: float, radius_rad: float) -> float:
    """Radius (rad) out to which a ring window ``2 eps + dr`` around a star is more likely empty
    than occupied by chance, for ``n_stars`` spread evenly over the sphere; at most ``radius_rad``.

    The expected catalogue neighbours in the window at distance ``r`` are ``n / 2 sin(r) w``;
    the window is occupied with chance ``1 - exp(-that)``, which reaches ``CHANCE_OCCUPANCY`` at
    ``sin(r) = -2 ln(1 - CHANCE_OCCUPANCY) / (n w)``.
    """
    w = 2.0 * eps_rad + ring_rad
    s = -2.0 * math.log(1.0 - CHANCE_OCCUPANCY) / max(n_stars * w, 1e-300)
    return radius_rad if s >= 1.0 else min(math.asin(s), radius_rad)


def ring_codes(pairs: np.ndarray, angles: np.ndarray, n_stars: int, ring_rad: float,
               n_rings: int) -> np.ndarray:
    """Packed radial features ``(ceil(n_rings / 64), n_stars)`` uint64 from star pairs."""
    n_words = -(-n_rings // 64)
    h = (angles / ring_rad).astype(np.int64)
    keep = h < n_rings
    i = np.concatenate([pairs[keep, 0], pairs[keep, 1]]).astype(np.int64)
    h = np.concatenate([h[keep], h[keep]])
    # one bit a (ring, star), repeats harmless: a boolean map packed 64 rings to a word (bit b of
    # word w is ring 64 w + b); np.unique of the (word, star, bit) keys took 4.7 s of 7.9 on
    # seed 002's acceptance database
    occupied = np.zeros((n_words * 64, n_stars), dtype=bool)
    occupied[h, i] = True
    packed = np.packbits(occupied, axis=0, bitorder="little").reshape(n_words, 8, n_stars)
    return np.ascontiguousarray(packed.transpose(0, 2, 1)).view("<u8")[..., 0].astype(np.uint64)


class Radial:
    name = "radial"
    summary = "radial ring bit-codes pick candidates per star, then triangles among them (seed 002)"

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        radius_deg = float(params.get("radius_deg", config.fov_max_deg))
        n_rings = int(params.get("n_rings", 1024))
        ring_rad = math.radians(radius_deg) / n_rings
        progress("star pairs", 0.0)
        pairs, angles = build_pair_table(stars.vec, math.radians(radius_deg))
        progress("ring codes", 0.5)
        codes = ring_codes(pairs, angles, len(stars), ring_rad, n_rings)
        progress(f"{len(stars)} codes of {n_rings} rings", 1.0)
        meta = {"radius_deg": radius_deg, "n_rings": n_rings, "ring_deg": math.degrees(ring_rad),
                "n_pairs": int(len(pairs))}
        return {"codes": codes}, meta

    def matcher(self, db: NavDatabase) -> RadialMatcher:
        return RadialMatcher(db)


class RadialMatcher:
    """Radial matcher over one database.

    ``score`` is ``"neighbours"`` or ``"paper"``; ``min_fraction`` the share of the observed
    neighbours (or occupied rings) a candidate must match.
    """

    def __init__(self, db: NavDatabase, *, score: str = "neighbours", threshold: str = "significance",
                 min_fraction: float = 0.75) -> None:
        prm = db.method_params("radial")
        self.codes = db.tables["radial"]["codes"]
        self.vec = db.stars.vec
        self.n_rings = int(prm["n_rings"])
        self.ring_rad = math.radians(prm["ring_deg"])
        self.radius = math.radians(prm["radius_deg"])
        if score not in ("neighbours", "paper"):
            raise ValueError(f"radial: unknown score {score!r}")
        if threshold not in ("significance", "fraction"):
            raise ValueError(f"radial: unknown threshold {threshold!r}")
        self.score = score
        self.threshold = threshold
        self.min_fraction = min_fraction
        self._fills: dict[int, np.ndarray] = {}

    def reach(self, eps: float) -> float:
        """Largest neighbour distance (rad) that scores at tolerance ``eps``
        (:func:`informative_radius`, kept one tolerance inside the stored radius)."""
        return min(informative_radius(self.codes.shape[1], self.ring_rad, eps, self.radius), self.radius - eps)

    def fill(self, n_rings: int) -> np.ndarray:
        """Per catalogue star, the share of its first ``n_rings`` rings that are set (cached)."""
        if n_rings not in self._fills:
            n_rings = max(1, min(n_rings, self.n_rings))
            full, part = divmod(n_rings, 64)
            codes = np.asarray(self.codes)
            count = np.bitwise_count(codes[:full]).sum(axis=0, dtype=np.int64)
            if part:
                count += np.bitwise_count(codes[full] & np.uint64((1 << part) - 1))
            self._fills[n_rings] = count / n_rings
        return self._fills[n_rings]

    # -- pre-identification ----------------------------------------------------------------
    def candidates(self, dist: np.ndarray, eps: float) -> np.ndarray:
        """Catalogue candidates (rows, best first) of an observed star whose neighbours lie at
        angular distances ``dist`` (radians)."""
        reach = self.reach(eps)
        dist = dist[dist < reach]
        if len(dist) == 0:
            return np.zeros(0, np.int64)
        if self.score == "paper":
            h = np.unique((dist / self.ring_rad).astype(np.int64))
            score, n_feat, window = self._popcount_and(h), len(h), 1.0
        else:
            score, n_feat = self._matched_neighbours(dist, eps), len(dist)
            window = 2 * eps / self.ring_rad + 1
        if self.threshold == "fraction":
            rows = np.flatnonzero(score >= max(math.ceil(self.min_fraction * n_feat), 1))
            rank = -score[rows].astype(np.float64)
        else:
            # chance that a random catalogue star matches this many: binomial in the share of
            # its rings that are set; keep those expected to turn up by chance fewer than
            # MAX_EXPECTED_FALSE times in the whole catalogue
            rows = np.flatnonzero(score >= 2)
            fill = self.fill(math.ceil((reach + eps) / self.ring_rad))
            p = np.minimum(fill[rows] * window, 1.0)
            # the tail is computed only where it can pass: below each score's crossing p
            near = p <= _passing_p(n_feat, MAX_EXPECTED_FALSE / len(fill))[score[rows] - 2]
            rows, p = rows[near], p[near]
            pval = bdtrc(score[rows] - 1, n_feat, p)
            keep = pval * len(fill) <= MAX_EXPECTED_FALSE
            rows, rank = rows[keep], pval[keep]
        order = np.argsort(rank, kind="stable")[:MAX_CANDIDATES]
        return rows[order].astype(np.int64)

    def _popcount_and(self, rings: np.ndarray) -> np.ndarray:
        """``popcount(B_cat AND B_obs)`` for every catalogue star, ``B_obs`` having ``rings`` set."""
        words = rings >> 6
        uw = np.unique(words)
        obs = np.zeros(len(uw), dtype=np.uint64)
        bit = np.left_shift(np.uint64(1), (rings & 63).astype(np.uint64))
        np.bitwise_or.at(obs, np.searchsorted(uw, words), bit)
        return np.bitwise_count(self.codes[uw] & obs[:, None]).sum(axis=0, dtype=np.int64)

    def _matched_neighbours(self, dist: np.ndarray, eps: float) -> np.ndarray:
        """Per catalogue star: how many observed neighbours have a catalogue bit in the rings
        their distance window ``[d - eps, d + eps]`` covers (a window spans at most two
        words when ``eps < 32 dr``; wider windows are clipped to that)."""
        lo = np.maximum((dist - eps) / self.ring_rad, 0).astype(np.int64)
        hi = np.minimum((dist + eps) / self.ring_rad, self.n_rings - 1).astype(np.int64)
        hi = np.minimum(hi, lo + 63)
        w1, w2 = lo >> 6, hi >> 6
        one = np.uint64(1)
        # bits lo..end-of-word in the first word, bits 0..hi in the second (when it differs)
        top1 = np.where(w1 == w2, hi & 63, 63).astype(np.uint64)
        top2 = (hi & 63).astype(np.uint64)
        m1 = ((one << top1) - one + (one << top1)) & ~((one << (lo & 63).astype(np.uint64)) - one)
        m2 = np.where(w1 == w2, np.uint64(0), (one << top2) - one + (one << top2))
        return _window_hits(np.asarray(self.codes), w1, m1, w2, m2.astype(np.uint64))

    # -- identification ----------------------------------------------------------------------
    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        d_all = pairwise_angles(obs.vec)
        d = d_all[:n, :n]
        eps = ctx.tol_rad
        cands: dict[int, np.ndarray] = {}

        def cand(i: int) -> np.ndarray:
            if i not in cands:
                others = np.sort(np.delete(d_all[i], i))[:MAX_NEIGHBOURS]
                cands[i] = self.candidates(others, eps)
            return cands[i]

        tried: set[tuple[int, int, int]] = set()
        m = 3  # triangles are drawn from the m brightest stars; m grows when they are used up
        while not ctx.expired():
            tri = self._next_triangle(d, m, eps, cand, tried)
            if tri is None:
                if m >= n:
                    break
                m += 1
                continue
            tried.add(tri)
            i, j, k = tri
            triples = self.match_triangle(obs.vec[[i, j, k]], cand(i), cand(j), cand(k), eps)
            if len(triples) == 0 or len(triples) > MAX_TRIPLES:
                continue
            found = ctx.verifier.screen_and_check(np.array(tri), triples)
            if found is not None:
                return found
        return None

    def _next_triangle(self, d: np.ndarray, m: int, eps: float, cand: Callable[[int], np.ndarray],
                       tried: set[tuple[int, int, int]]) -> tuple[int, int, int] | None:
        """The untried usable triangle of the ``m`` brightest stars with the fewest candidate
        combinations ``m1 m2 m3``."""
        best, best_cost = None, math.inf
        for tri in combinations(range(m), 3):
            if tri in tried:
                continue
            i, j, k = tri
            sides = (d[i, j], d[i, k], d[j, k])
            if max(sides) > self.radius - eps or min(sides) < 4 * eps:
                tried.add(tri)
                continue
            cost = len(cand(i)) * len(cand(j)) * len(cand(k))
            if cost == 0:
                tried.add(tri)
                continue
            if cost < best_cost:
                best, best_cost = tri, cost
        return best

    def match_triangle(self, v: np.ndarray, ci: np.ndarray, cj: np.ndarray, ck: np.ndarray,
                       eps: float) -> np.ndarray:
        """Candidate triples ``(a, b, c)``, ``a`` in ``ci`` ..., whose three sides match the
        observed triangle ``v`` ``(3, 3)`` within ``eps`` and whose handedness agrees."""
        if len(ci) == 0 or len(cj) == 0 or len(ck) == 0:
            return np.zeros((0, 3), np.int64)
        d = pairwise_angles(v)
        vec = self.vec

        def ok(a: np.ndarray, b: np.ndarray, target: float) -> np.ndarray:
            chord = np.linalg.norm(vec[a][:, None, :] - vec[b][None, :, :], axis=2)
            return np.abs(2 * np.arcsin(np.minimum(chord / 2, 1.0)) - target) <= eps

        m = ok(ci, cj, d[0, 1])[:, :, None] & ok(ci, ck, d[0, 2])[:, None, :]
        m &= ok(cj, ck, d[1, 2])[None, :, :]
        a, b, c = np.nonzero(m)
        out = np.column_stack([ci[a], cj[b], ck[c]])
        out = out[(out[:, 0] != out[:, 1]) & (out[:, 0] != out[:, 2]) & (out[:, 1] != out[:, 2])]
        if len(out) == 0:
            return out
        return out[same_handedness(vec, v, out)]


@njit(cache=True, nogil=True)
def _window_hits(codes: np.ndarray, w1: np.ndarray, m1: np.ndarray, w2: np.ndarray, m2: np.ndarray) -> np.ndarray:
    """Per catalogue star (column of ``codes`` ``(words, N)``): how many windows ``q`` have a bit
    in ``codes[w1[q]] & m1[q]`` or ``codes[w2[q]] & m2[q]``. The numpy version held a
    ``(windows, N)`` array: 10 of a deep frame's 27 ms (seed 002 at 8 Mv, 41,878 stars)."""
    n = codes.shape[1]
    out = np.zeros(n, np.int64)
    for q in range(len(w1)):
        a, b = codes[w1[q]], codes[w2[q]]
        ma, mb = m1[q], m2[q]
        for s in range(n):
            if (a[s] & ma) | (b[s] & mb):
                out[s] += 1
    return out


@functools.lru_cache(maxsize=256)
def _passing_p(n_feat: int, threshold: float) -> np.ndarray:
    """For each score ``2..n_feat``, a ring share above which ``bdtrc(score - 1, n_feat, p)``
    exceeds ``threshold`` (bisected to ~1e-18, then widened: a pre-filter only, the exact tail
    decides). The tail of every catalogue star took 14 of a deep frame's 27 ms."""
    k = np.arange(1, max(n_feat, 2), dtype=np.float64)
    lo, hi = np.zeros(len(k)), np.ones(len(k))
    for _ in range(64):
        mid = (lo + hi) / 2
        over = bdtrc(k, n_feat, mid) > threshold
        hi, lo = np.where(over, mid, hi), np.where(over, lo, mid)
    out = np.minimum(hi * (1 + 1e-9) + 1e-12, 1.0)
    out.flags.writeable = False  # (cached)
    return out
