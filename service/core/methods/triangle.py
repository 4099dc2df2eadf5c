"""``triangle``: Liebe's classic triangle method (the baseline every paper compares against).

Tables: every catalogue star pair closer than ``max_angle_deg`` (the image diagonal), sorted
by angular separation: the rows of the database's shared pair table (``pairs/``) within that
limit, plus the method's own k-vector over them when built with ``index="kvector"``.
Identification: observed triangles of the brightest stars; for each, the three sides are
looked up in the pair table (``|d_cat - d_obs| <= eps`` on all three), the three windows
are joined into catalogue triples, the mirror images dropped, and the redundant matches
resolved by a fourth star: the shared verifier projects each candidate's attitude and keeps
the one that explains further stars.

Faithful parts and the choices made where the classic is vague:

- **Range index.** Liebe/Mortari use a k-vector (``k[i] = #{y_j <= m i + q}``) to turn a
  range query on the sorted angles into two table reads. ``build_kvector``/``kvector_range``
  implement it; measured against ``np.searchsorted`` on the seed-002 table (373k pairs),
  the k-vector is slower for the 20-60 windows one frame needs (11 us vs 1.6-3 us a batch)
  and only wins for batches above ~300 windows, so the matcher uses ``searchsorted`` and the
  database stores no k-vector unless built with ``index="kvector"`` (docs/methods.md).
- **Triangle order.** The classic takes triangles of the brightest stars in lexicographic
  order (``order="brightness"``). The default ``order="selective"`` sorts all triangles of the
  brightest stars by the number of catalogue triples they can match (the product of the three
  pair-window counts, normalised) and tries the most distinctive first: fewer candidates per
  triangle, fewer look-elsewhere trials, and a false star spoils a triangle only when it is
  the most distinctive one. Measured in docs/methods.md.
- **Sparse fields.** With three stars there is no fourth star. When a frame's triangle
  matches exactly one catalogue triple, the matcher asks the verifier for the sparse proof
  (``sparse_proof.check_unique_triangle``): the expected number of catalogue triangles, consistent
  with the frame, inside the box of the measured mismatch, estimated from the pair table.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from itertools import combinations
from typing import Any

import numpy as np
from numba import njit

from ..catalog import StarTable
from ..geometry import pairwise_angles
from ..navdb.reader import NavDatabase
from ..sparse_proof import check_unique_triangle, triangle_mismatch
from ..star_index import star_vec64
from ..verify import Verified
from ._pairs import (
    PairLimits,
    SharedPairs,
    empty_triangles,
    join_windows,
    pair_limits,
    require_shared,
    same_handedness,
    upper_pairs,
)
from ._table_join import build_box_table, pivot_join, table_triples, triangle_table
from .base import Progress, SolveContext

MAX_CANDIDATES = 64
"""Triangles matching more catalogue triples than this are skipped as uninformative."""
SPARSE_MAX_STARS = 4
"""Frames with at most this many stars may be proven by a unique triangle alone."""
BOX_START, BOX_MAX, BOX_TARGET = 12.0, 160.0, 2000
"""Density box (see ``_density_box``): first and largest half-width in pattern tolerances, and
the number of catalogue triples it aims to hold."""


# ---- k-vector (Mortari) ------------------------------------------------------------------
def build_kvector(y: np.ndarray) -> tuple[np.ndarray, float, float]:
    """k-vector of sorted values ``y`` ``(M,)``: ``k`` ``(M,)`` int64 with
    ``k[i] = #{y_j <= m (i + 1) + q}`` and the line ``(m, q)``."""
    m_len = len(y)
    if m_len < 2:
        return np.arange(m_len, dtype=np.int64), 1.0, 0.0
    eps = 2.2e-16 * max(abs(float(y[0])), abs(float(y[-1])), 1.0)
    m = (float(y[-1]) - float(y[0]) + 2 * eps) / (m_len - 1)
    q = float(y[0]) - m - eps
    k = np.searchsorted(y, m * np.arange(1, m_len + 1) + q, side="right").astype(np.int64)
    return k, m, q


def kvector_range(k: np.ndarray, m: float, q: float, lo: np.ndarray,
                  hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index ranges ``[start, end)`` of a k-vector holding every value in ``[lo, hi]``
    (a few extra values at both ends; callers filter by value)."""
    last = len(k) - 1
    jb = np.clip(np.floor((np.asarray(lo) - q) / m).astype(np.int64) - 2, 0, last)
    jt = np.clip(np.ceil((np.asarray(hi) - q) / m).astype(np.int64), 0, last)
    return k[jb], k[jt]


# ---- the method ----------------------------------------------------------------------------
class Triangle:
    name = "triangle"
    summary = "Liebe's classic: star pairs by angle, three sides within tolerance, a fourth star decides"

    def pair_limits(self, config: Any, params: dict[str, Any]) -> PairLimits:
        """Pairs up to ``max_angle_deg`` (default: the database's largest field), degrees."""
        return pair_limits(config, params)

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress,
        *, shared: SharedPairs | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Own arrays: the k-vector over its rows of the shared pair table (``index="kvector"``)."""
        limits = self.pair_limits(config, params)
        index = str(params.get("index", "searchsorted"))
        if index not in ("searchsorted", "kvector"):
            raise ValueError(f"triangle: unknown index {index!r}")
        _, angles = require_shared(shared, self.name).view(limits)
        tables: dict[str, np.ndarray] = {}
        meta: dict[str, Any] = {"max_angle_deg": limits.max_angle_deg, "n_pairs": int(len(angles)),
                                "index": index}
        if index == "kvector":
            k, m, q = build_kvector(angles)
            tables["kvector"] = k
            meta.update(kvector_m=m, kvector_q=q)
        box_deg = float(params.get("box_d_max_deg", 0.0))
        if box_deg > 0:  # a table of every triangle to box_deg, read instead of joining (_table_join)
            box, box_meta = build_box_table(stars, config, box_deg, progress)
            tables.update(box)
            meta.update(box_meta)
        progress(f"{len(angles)} pairs", 1.0)
        return tables, meta

    def matcher(self, db: NavDatabase) -> TriangleMatcher:
        return TriangleMatcher(db)


class TriangleMatcher:
    """Triangle matcher over one database; ``order`` is ``"selective"`` or ``"brightness"``."""

    def __init__(self, db: NavDatabase, *, order: str = "selective", sparse: bool = True) -> None:
        t = db.tables["triangle"]
        prm = db.method_params("triangle")
        self.pairs = t["pairs"]
        self.angles = t["angles"]
        self.vec = db.stars.vec
        self.n_stars = len(db.stars)
        self.max_angle = math.radians(prm["max_angle_deg"])
        self.kvector = t.get("kvector")
        self.kv_line = (float(prm.get("kvector_m", 1.0)), float(prm.get("kvector_q", 0.0)))
        self.order = order
        self.sparse = sparse
        self.box_table = triangle_table(db)

    def box_triples(self, v: np.ndarray, w: float) -> np.ndarray:
        """:meth:`triples` of ``v`` at half-width ``w`` (rad), in some order: the density box,
        read from the member's triangle table where it holds them all
        (:func:`~._table_join.table_triples`), else joined."""
        if self.box_table is not None:
            d = pairwise_angles(v)
            out = table_triples(self.box_table, v, d[0, 1], d[0, 2], d[1, 2], w)
            if out is not None:
                return out
        return self.triples(v, w, pivot_longest=True)

    # -- pair windows --------------------------------------------------------------------
    def windows(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row ranges ``[start, end)`` of the pair table with angle in ``[lo, hi]``."""
        if self.kvector is None:
            y = self.angles
            return np.searchsorted(y, lo, side="left"), np.searchsorted(y, hi, side="right")
        s, e = kvector_range(self.kvector, *self.kv_line, lo, hi)
        # trim the k-vector's slack by value (a handful of rows at each end)
        seg = [np.asarray(self.angles[a:b]) for a, b in zip(s, e, strict=True)]
        start = np.array([a + np.count_nonzero(y < x) for a, y, x in zip(s, seg, lo, strict=True)], np.int64)
        end = np.array([a + np.count_nonzero(y <= x) for a, y, x in zip(s, seg, hi, strict=True)], np.int64)
        return start, end

    def triples(self, v: np.ndarray, eps: float, pivot_longest: bool = False) -> np.ndarray:
        """Catalogue triples ``(K, 3)`` matching the observed triangle ``v`` ``(3, 3)`` on all
        three sides within ``eps`` (radians) with the same handedness (vertex order kept).

        The join pivots on the vertex opposite the shortest side, whose order the search's
        candidates keep; with ``pivot_longest``, on the vertex opposite the longest side, the
        same triples in another order, found faster in wide windows: the pivot's sides are the
        two shorter ones, whose windows hold the fewest pairs (a window's pairs grow with its
        angle), and the join's outer loop walks the shortest."""
        if self.box_table is not None and not pivot_longest:  # the join's triples, in its order, looked up
            got = pivot_join(self.box_table, v, eps)  # (the pivot below, in one compiled call)
            if got is not None:
                return got
        d = pairwise_angles(v)
        opposite = (d[1, 2], d[0, 2], d[0, 1])
        # the vertex opposite the shortest (longest) side, np.argmin's (argmax's) first
        p = opposite.index(max(opposite) if pivot_longest else min(opposite))
        q, r = [x for x in range(3) if x != p]
        if pivot_longest and d[p, q] > d[p, r]:
            q, r = r, q  # the outer loop walks the a-b window: the shortest side's, the fewest pairs
        sides = np.array([d[p, q], d[p, r], d[q, r]])
        s, e = self.windows(sides - eps, sides + eps)
        cand = join_windows(self.pairs, int(s[0]), int(e[0]), int(s[1]), int(e[1]), int(s[2]), int(e[2]),
                            self.n_stars)
        if len(cand) == 0:
            return cand
        out = np.empty_like(cand)
        out[:, [p, q, r]] = cand
        return out[same_handedness(self.vec, v, out)]

    # -- identification ------------------------------------------------------------------
    def _triangle_order(self, d: np.ndarray, n: int, eps: float) -> list[tuple[int, int, int]]:
        tris = list(combinations(range(n), 3))
        if self.order == "brightness" or len(tris) <= 1:
            return tris
        if self.kvector is None:  # the pair table's windows by binary search: one compiled call
            return [tris[r] for r in _selective_order(np.asarray(self.angles), np.ascontiguousarray(d, np.float64),
                                                      n, float(eps))]
        iu = upper_pairs(n)
        s, e = self.windows(d[iu] - eps, d[iu] + eps)
        count = np.zeros((n, n))
        count[iu] = np.maximum(e - s, 1)
        count += count.T
        # expected triples ~ c_ij c_ik c_jk / N^2 (up to a common factor): most distinctive first
        cost = [count[i, j] * count[i, k] * count[j, k] for i, j, k in tris]
        return [tris[r] for r in np.argsort(cost, kind="stable")]

    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        v = obs.vec[:n]
        d = pairwise_angles(v)
        eps = ctx.tol_rad
        unique: list[tuple[np.ndarray, np.ndarray]] = []
        known_empty = empty_triangles(obs, self.pairs, eps)  # pyramid's, on this member's table
        for i, j, k in self._triangle_order(d, n, eps):
            if ctx.expired():
                break
            sides = (d[i, j], d[i, k], d[j, k])
            if max(sides) > self.max_angle - eps or min(sides) < 4 * eps or (i, j, k) in known_empty:
                continue
            idx = np.array([i, j, k])
            cand = self.triples(v[idx], eps)
            if len(cand) == 1:
                unique.append((idx, cand[0]))
            if len(cand) == 0 or len(cand) > MAX_CANDIDATES:
                continue
            if ctx.sparse_only or not ctx.verifier.could_prove(3):
                # no check of a triangle could pass the bound any more (a 3-4 star frame past a
                # trial or two), or the frame's other triangles fit no catalogue triple (the
                # pipeline's sparse screen): counted as tried, as the screen would count them,
                # and not checked
                ctx.verifier.count_unchecked(len(cand))
                continue
            found = ctx.verifier.screen_and_check(idx, cand)
            if found is not None:
                return found
        if self.sparse and len(obs) <= SPARSE_MAX_STARS and unique and not ctx.verifier.marginal:
            return self._sparse(ctx, unique, n, eps)
        return None

    def _sparse(self, ctx: SolveContext, unique: list[tuple[np.ndarray, np.ndarray]], n: int,
                eps: float) -> Verified | None:
        """Prove a 3-4 star frame by a triangle that matched exactly one catalogue triple.

        Triangles are tried in order of their side mismatch (the smallest gives the smallest
        bound, all else equal). One whose three stars a proven answer already names the same way
        is skipped: its proof would name the same sky. Two proofs naming different skies are
        ambiguous: no answer."""
        n_looks = math.comb(n, 3)
        vec = star_vec64(ctx.verifier.db)
        obs_vec = np.ascontiguousarray(ctx.obs.vec, dtype=np.float64)

        def mismatch(tri: tuple[np.ndarray, np.ndarray]) -> float:
            idx, cat = tri
            return triangle_mismatch(obs_vec, vec, np.asarray(idx, np.int64), np.asarray(cat, np.int64))

        best: Verified | None = None
        for idx, cat in sorted(unique, key=mismatch):
            if best is not None and _names(best, idx, cat):
                continue
            v = obs_vec[idx]
            found = check_unique_triangle(ctx.verifier, idx, cat, n_looks=n_looks,
                                          density_box=functools.partial(self._density_box, v, eps),
                                          unique_within_rad=eps,
                                          sample_box=functools.partial(self.box_triples, v),
                                          max_width_rad=_widest_box(v))
            if found is None:
                continue
            if best is not None and not np.array_equal(np.sort(best.cat), np.sort(found.cat)):
                return None  # two unique triangles, two different skies: ambiguous
            if best is None or found.false_prob < best.false_prob:
                best = found
        return best

    def _density_box(self, v: np.ndarray, eps: float,
                     worth: Callable[[float], bool]) -> tuple[np.ndarray, float] | None:
        """Catalogue triples in a box of half-width ``W`` around the observed sides: the sample
        the verifier estimates the local density of consistent triangles from. ``W`` is grown
        until the box holds about ``BOX_TARGET`` triples (the test's power is set by how many
        triples it examines), but stays below a quarter of the shortest side, so that the
        density is smooth across the box. None, without gathering, where ``worth(W)`` says no
        box that wide could prove the match (see ``check_unique_triangle``)."""
        w_max = _widest_box(v)
        if not worth(min(w_max, max(BOX_START, BOX_MAX) * eps)):
            return None  # not even the widest box this triangle allows
        w = min(BOX_START * eps, w_max)
        box = self.box_triples(v, w)
        if len(box) < BOX_TARGET / 2 and w < w_max:
            w = min(w * (BOX_TARGET / max(len(box), 8)) ** (1 / 3), w_max, BOX_MAX * eps)
            if not worth(w):
                return None
            box = self.box_triples(v, w)
        return box, w


@njit(cache=True, nogil=True)
def _selective_order(angles: np.ndarray, d: np.ndarray, n: int, eps: float) -> np.ndarray:
    """The triangles of ``n`` stars (``itertools.combinations`` order) most distinctive first, as
    :meth:`TriangleMatcher._triangle_order` orders them: by ``c_ij c_ik c_jk`` (``c`` a pair's
    window count in the sorted pair ``angles``, at least 1; ``d`` the pair angles, rad), stably."""
    count = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            lo = np.searchsorted(angles, d[i, j] - eps, side="left")
            hi = np.searchsorted(angles, d[i, j] + eps, side="right")
            count[i, j] = count[j, i] = max(hi - lo, 1)
    cost = np.empty(n * (n - 1) * (n - 2) // 6)
    t = 0
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                cost[t] = count[i, j] * count[i, k] * count[j, k]
                t += 1
    return np.argsort(cost, kind="mergesort")


def _widest_box(v: np.ndarray) -> float:
    """The widest density box (half-width, rad) of the observed triangle ``v`` (3, 3): a quarter
    of its shortest side, so that the density is smooth across the box."""
    d = pairwise_angles(v)
    return float(min(d[0, 1], d[0, 2], d[1, 2])) / 4


def _names(v: Verified, obs_idx: np.ndarray, cat_idx: np.ndarray) -> bool:
    """Does answer ``v`` pair each of the observed rows ``obs_idx`` with ``cat_idx``?"""
    paired = dict(zip(v.obs.tolist(), v.cat.tolist(), strict=True))
    return all(paired.get(int(o)) == int(c) for o, c in zip(obs_idx, cat_idx, strict=True))
