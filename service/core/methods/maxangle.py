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
from ._pairs import build_pair_table, pattern_order, same_handedness
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

    def _block(self, theta: float) -> int:
        return min(max(int(self.n_blocks * (theta - THETA_LO) / THETA_SPAN), 0), self.n_blocks - 1)

    def query(self, a: float, b: float, c: float, eps: float) -> np.ndarray:
        """Record rows matching an observed triangle with sides ``a >= b >= c`` (radians)."""
        theta = float(triangle_features(np.array(a), np.array(b), np.array(c)))
        # |d theta / d side| from the law of cosines, summed over the three sides
        s = max(math.sin(theta), 1e-3)
        da = a / (b * c * s)
        db_ = abs(c - b * math.cos(theta)) / (b * c * s)
        dc = abs(b - c * math.cos(theta)) / (b * c * s)
        tol_t = eps * (da + db_ + dc)
        blocks = np.arange(self._block(theta - tol_t), self._block(theta + tol_t) + 1)
        starts = np.searchsorted(self.key, blocks + (b - eps) / self.b_scale, side="left")
        ends = np.searchsorted(self.key, blocks + (b + eps) / self.b_scale, side="right")
        counts = ends - starts
        total = int(counts.sum())
        if total == 0:
            return np.zeros(0, np.int64)
        rows = np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(total)
        ok = (np.abs(self.c[rows] - c) <= eps) & (np.abs(self.theta[rows] - theta) <= tol_t)
        return rows[ok]

    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        v = obs.vec[:n]
        d = pairwise_angles(v)
        eps = ctx.tol_rad
        for i, j, k in pattern_order(n):
            if ctx.expired():
                break
            sides, ids = _sorted_sides(np.array([d[j, k]]), np.array([d[i, k]]), np.array([d[i, j]]),
                                       np.array([i]), np.array([j]), np.array([k]))
            a, b, c = sides[0]
            if a > self.d_max - eps or c < self.xi + eps or c < 4 * eps:
                continue
            if triangle_features(np.array(a), np.array(b), np.array(c)) > THETA_MAX_USABLE:
                continue
            o = ids[0]
            labelings = [(o, (a, b, c))]
            if a - b < 2 * eps:
                labelings.append((o[[1, 0, 2]], (a, b, c)))
            if b - c < 2 * eps:
                labelings += [(lab[[0, 2, 1]], abc) for lab, abc in list(labelings)]
            for lab, (sa, sb, sc) in labelings:
                rows = self.query(sa, sb, sc, eps)
                if len(rows) == 0:
                    continue
                cand = self.ids[rows].astype(np.int64)
                cand = cand[same_handedness(self.vec, v[lab], cand)]
                if len(cand) > MAX_CANDIDATES:
                    continue
                found = ctx.verifier.screen_and_check(lab.astype(np.int64), cand)
                if found is not None:
                    return found
        return None
