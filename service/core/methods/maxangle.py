"""``maxangle``: star triangles hashed by their maximum interior angle (seed 000).

Magnitude-free. A triangle's sides (angular distances) are sorted ``a >= b >= c`` and its
feature is ``theta_max = arccos((b^2 + c^2 - a^2) / (2 b c))``, the angle opposite the longest
side, in [60, 180) degrees. The catalogue keeps every triangle of stars whose sides lie in
``(xi, d_max]`` as ``(ID_max, ID_sec, ID_thi, b, c, theta_max)``, sorted by ``theta_max`` and
cut into ``n_blocks`` blocks ``H(theta) = floor(N (theta - 60) / 120)``; a query reads the
blocks covering ``theta_obs +- tol_theta`` and keeps records with ``|b - b_obs| <= eps`` and
``|c - c_obs| <= eps``. Inside each block the records are sorted by ``b`` (the composite key
``H + b / b_scale``), so a query reads only the ``b +- eps`` slice of each block instead of the
whole block: the paper's hash, with a secondary sort that makes a query ~100x cheaper.

Where the paper is vague we chose:
- ``d_max`` is the field side (the paper's faster "side" library); triangles whose sides do not
  fit are never formed from the image;
- ``tol_theta`` is propagated from ``eps`` through the law of cosines (not a fixed angle);
- near-ties (``a ~ b`` or ``b ~ c`` within ``2 eps``) are also queried with the vertices
  swapped, because noise can swap which vertex is ``ID_max``/``ID_sec``/``ID_thi``;
- candidates are proven by the shared verifier (projection + coincidence bound) rather than by
  a second triangle alone; the first main triangles are those of the brightest stars in
  pyramid order (so one false star spoils few of them) and theta_max near 180 is skipped.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..geometry import pairwise_angles
from ..navdb.reader import NavDatabase
from ..verify import Verified
from ._pairs import build_pair_table, pattern_order, same_handedness_many
from .base import Progress, SolveContext

THETA_LO = math.pi / 3
THETA_SPAN = 2 * math.pi / 3
THETA_MAX_USABLE = math.radians(175.0)
MAX_CANDIDATES = 1000


def triangle_features(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``theta_max`` (radians) of triangles with sides ``a >= b >= c`` (angles, radians)."""
    cos_t = (b * b + c * c - a * a) / (2 * b * c)
    return np.arccos(np.clip(cos_t, -1.0, 1.0))


def _sorted_sides(d_jk: np.ndarray, d_ik: np.ndarray, d_ij: np.ndarray, i: np.ndarray, j: np.ndarray,
                  k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sides sorted descending with the vertex opposite each: returns ``(sides (M,3), ids (M,3))``."""
    sides = np.column_stack([d_jk, d_ik, d_ij])
    ids = np.column_stack([i, j, k])
    order = np.argsort(-sides, axis=1, kind="stable")
    return np.take_along_axis(sides, order, 1), np.take_along_axis(ids, order, 1)


class MaxAngle:
    name = "maxangle"
    summary = "triangles hashed by their maximum interior angle into N blocks (seed 000)"

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        d_max_deg = float(params.get("d_max_deg", config.fov_min_deg))
        xi_deg = float(params.get("xi_deg", 0.05))
        n_blocks = int(params.get("n_blocks", 1024))
        vec = stars.vec
        n = len(vec)
        pairs, angles = build_pair_table(vec, math.radians(d_max_deg), math.radians(xi_deg))
        # adjacency with the lower index first; group by the lower index
        order = np.lexsort((pairs[:, 1], pairs[:, 0]))
        p = pairs[order].astype(np.int64)
        ang = angles[order]
        keys = p[:, 0] * n + p[:, 1]
        key_order = np.argsort(keys)
        keys_sorted = keys[key_order]
        ang_by_key = ang[key_order]
        starts = np.searchsorted(p[:, 0], np.arange(n + 1))
        recs: list[np.ndarray] = []
        chunk = max(1, n // 50)
        for s0 in range(0, n, chunk):
            progress("triangles", s0 / n)
            lo, hi = starts[s0], starts[min(s0 + chunk, n)]
            seg = p[lo:hi]
            seg_ang = ang[lo:hi]
            # pairs (i, j), (i, k) with j < k sharing i: all combinations inside each i-group
            g = seg[:, 0]
            g_start = np.searchsorted(g, g, side="left")
            g_end = np.searchsorted(g, g, side="right")
            cnt = g_end - np.arange(len(g)) - 1  # partners after this row in the same group
            rows = np.repeat(np.arange(len(g)), cnt)
            offs = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            other = rows + 1 + offs
            del g_start
            i_ = seg[rows, 0]
            j_ = seg[rows, 1]
            k_ = seg[other, 1]
            jj, kk = np.minimum(j_, k_), np.maximum(j_, k_)
            q = jj * n + kk
            pos = np.minimum(np.searchsorted(keys_sorted, q), len(keys_sorted) - 1)
            hit = keys_sorted[pos] == q
            d_ij, d_ik, d_jk = seg_ang[rows][hit], seg_ang[other][hit], ang_by_key[pos[hit]]
            sides, ids = _sorted_sides(d_jk, d_ik, d_ij, i_[hit], j_[hit], k_[hit])
            theta = triangle_features(sides[:, 0], sides[:, 1], sides[:, 2])
            keep = theta < THETA_MAX_USABLE
            recs.append(np.column_stack([ids[keep].astype(np.float64), sides[keep, 1], sides[keep, 2],
                                         theta[keep]]))
        allrec = np.concatenate(recs) if recs else np.zeros((0, 6))
        b_scale = math.radians(d_max_deg) * 1.001
        block = np.clip((n_blocks * (allrec[:, 5] - THETA_LO) / THETA_SPAN).astype(np.int64), 0, n_blocks - 1)
        key = block + allrec[:, 3] / b_scale
        order = np.argsort(key, kind="stable")
        allrec, key = allrec[order], key[order]
        progress(f"{len(key)} triangles", 1.0)
        tables = {
            "ids": allrec[:, :3].astype(np.int32),
            "key": key,
            "c": allrec[:, 4].astype(np.float32),
            "theta": allrec[:, 5].astype(np.float32),
        }
        meta = {"d_max_deg": d_max_deg, "xi_deg": xi_deg, "n_blocks": n_blocks, "b_scale": b_scale,
                "n_triangles": int(len(key))}
        return tables, meta

    def matcher(self, db: NavDatabase) -> MaxAngleMatcher:
        return MaxAngleMatcher(db)


class MaxAngleMatcher:
    def __init__(self, db: NavDatabase) -> None:
        t = db.tables["maxangle"]
        prm = db.method_params("maxangle")
        self.ids, self.key, self.c, self.theta = t["ids"], t["key"], t["c"], t["theta"]
        self.n_blocks = int(prm["n_blocks"])
        self.b_scale = float(prm["b_scale"])
        self.d_max = math.radians(prm["d_max_deg"])
        self.xi = math.radians(prm["xi_deg"])
        self.vec = db.stars.vec

    def observed_triangles(self, d: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Usable triangles of the observed stars with pairwise angles ``d`` ``(n, n)``, best
        conditioned (smallest theta tolerance) first, with near-tie relabellings.

        Returns ``labels`` (T, 3) observed rows as (max, sec, thi) vertices, ``sides`` (T, 3)
        ``a >= b >= c`` radians, ``theta`` (T,) and its tolerance ``tol`` (T,).
        """
        n = len(d)
        tri = _pattern_array(n)
        i, j, k = tri[:, 0], tri[:, 1], tri[:, 2]
        sides, labels = _sorted_sides(d[j, k], d[i, k], d[i, j], i, j, k)
        a, b, c = sides[:, 0], sides[:, 1], sides[:, 2]
        theta = triangle_features(a, b, c)
        ok = (a <= self.d_max - eps) & (c >= self.xi + eps) & (c >= 4 * eps) & (theta <= THETA_MAX_USABLE)
        sides, labels, theta = sides[ok], labels[ok], theta[ok]
        order = np.arange(len(theta), dtype=np.float64)
        # noise may swap which vertex is ID_max / ID_sec (a ~ b) or ID_sec / ID_thi (b ~ c)
        ab = sides[:, 0] - sides[:, 1] < 2 * eps
        extra_l = [labels, labels[ab][:, [1, 0, 2]]]
        extra_o = [order, order[ab] + 0.25]
        bc = sides[:, 1] - sides[:, 2] < 2 * eps
        extra_l += [labels[bc][:, [0, 2, 1]], labels[ab & bc][:, [1, 2, 0]]]
        extra_o += [order[bc] + 0.5, order[ab & bc] + 0.75]
        src = np.concatenate([np.arange(len(theta))[m] for m in (np.ones(len(theta), bool), ab, bc, ab & bc)])
        labels = np.concatenate(extra_l)
        keyorder = np.argsort(np.concatenate(extra_o), kind="stable")
        labels, src = labels[keyorder], src[keyorder]
        sides, theta = sides[src], theta[src]
        a, b, c = sides[:, 0], sides[:, 1], sides[:, 2]
        sn = np.maximum(np.sin(theta), 1e-3)
        cs = np.cos(theta)
        tol = eps * (a + np.abs(c - b * cs) + np.abs(b - c * cs)) / (b * c * sn)  # |d theta / d side| summed
        # the paper's advice, made quantitative: best-conditioned triangles first (the
        # tolerance on theta_max sets how many catalogue triangles a query returns)
        first = np.argsort(tol, kind="stable")
        return labels[first], sides[first], theta[first], tol[first]

    def query_many(self, sides: np.ndarray, theta: np.ndarray, tol: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
        """Record rows matching each observed triangle; returns ``(rows, which)`` with
        ``which`` the index of the observed triangle of each row."""
        blk_lo = np.clip((self.n_blocks * (theta - tol - THETA_LO) / THETA_SPAN).astype(np.int64), 0, self.n_blocks - 1)
        blk_hi = np.clip((self.n_blocks * (theta + tol - THETA_LO) / THETA_SPAN).astype(np.int64), 0, self.n_blocks - 1)
        nb = blk_hi - blk_lo + 1
        t_of_block = np.repeat(np.arange(len(theta)), nb)
        blocks = blk_lo[t_of_block] + (np.arange(int(nb.sum())) - np.repeat(np.cumsum(nb) - nb, nb))
        b = sides[t_of_block, 1]
        starts = np.searchsorted(self.key, blocks + (b - eps) / self.b_scale, side="left")
        ends = np.searchsorted(self.key, blocks + (b + eps) / self.b_scale, side="right")
        counts = ends - starts
        total = int(counts.sum())
        if total == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        rows = np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(total)
        which = np.repeat(t_of_block, counts)
        c_rec = self.c[rows]
        th_rec = self.theta[rows]
        ok = (np.abs(c_rec - sides[which, 2]) <= eps) & (np.abs(th_rec - theta[which]) <= tol[which])
        rows, which, c_rec, th_rec = rows[ok], which[ok], c_rec[ok], th_rec[ok]
        # finally all three sides (the paper's check): the longest from b, c and theta_max
        key = self.key[rows]
        b_rec = (key - np.floor(key)) * self.b_scale
        a_rec = np.sqrt(b_rec * b_rec + c_rec * c_rec - 2 * b_rec * c_rec * np.cos(th_rec))
        ok = np.abs(a_rec - sides[which, 0]) <= eps
        return rows[ok], which[ok]

    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        v = obs.vec[:n]
        eps = ctx.tol_rad
        labels, sides, theta, tol = self.observed_triangles(pairwise_angles(v), eps)
        lo = 0
        for size in _chunks(len(labels)):
            if ctx.expired():
                break
            sl = slice(lo, lo + size)
            lo += size
            rows, which = self.query_many(sides[sl], theta[sl], tol[sl], eps)
            if len(rows) == 0:
                ctx.verifier.patterns += size
                continue
            lab = labels[sl][which]
            cand = self.ids[rows].astype(np.int64)
            keep = same_handedness_many(self.vec, v, lab, cand)
            # a triangle matching too many catalogue triangles is uninformative: drop it
            per_tri = np.bincount(which[keep], minlength=size)
            keep &= per_tri[which] <= MAX_CANDIDATES
            found = ctx.verifier.screen_and_check_many(lab[keep], cand[keep], n_patterns=size)
            if found is not None:
                return found
        return None


_PATTERNS: dict[int, np.ndarray] = {}


def _pattern_array(n: int) -> np.ndarray:
    if n not in _PATTERNS:
        _PATTERNS[n] = np.array(pattern_order(n), dtype=np.int64).reshape(-1, 3)
    return _PATTERNS[n]


def _chunks(total: int) -> list[int]:
    """Batch sizes over the triangle list: small first (the first triangles usually solve a
    frame), then doubling up to 16, so a hard frame costs few Python round trips and the time
    limit is still checked between batches."""
    sizes, size, done = [], 2, 0
    while done < total:
        sizes.append(min(size, total - done))
        done += sizes[-1]
        size = min(2 * size, 16)  # bounded, so the time limit is checked often
    return sizes
