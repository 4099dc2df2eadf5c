"""``maxangle``: star triangles hashed by their maximum interior angle (seed 000).

Magnitude-free. A triangle's sides (angular distances) are sorted ``a >= b >= c`` and its
feature is ``theta_max = arccos((b^2 + c^2 - a^2) / (2 b c))``, the angle opposite the longest
side, in [60, 180) degrees. The catalogue keeps every triangle of stars whose sides lie in
``(xi, d_max]`` as ``(ID_max, ID_sec, ID_thi, b, c, theta_max)``. The paper sorts them by
``theta_max`` and cuts them into ``n_blocks`` blocks ``H(theta) = floor(N (theta - 60) / 120)``;
a query reads the blocks covering ``theta_obs +- tol_theta`` and keeps records with ``|b -
b_obs| <= eps`` and ``|c - c_obs| <= eps``. That is the ``paper`` layout (with ``b`` as a
secondary sort inside each block, ~100x cheaper than reading whole blocks). The default
``cells`` layout stores the same records by ``(b, c)`` cell, ``theta_max`` inside each: a query
returns the same records 3-8x faster, as it reads a few cells instead of ~100 blocks
(:mod:`.maxangle_index`; build parameter ``layout``).

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
from numba import njit

from .._malloc import map_large_allocations
from ..catalog import StarTable
from ..geometry import pairwise_angles_kernel
from ..navdb.reader import NavDatabase
from ..verify import Verified
from . import maxangle_search
from ._bucket_sort import sort_by_bucket_key
from ._pairs import build_pair_table, pattern_order
from .base import Progress, SolveContext
from .maxangle_index import (
    LAYOUTS,
    N_BLOCKS,
    N_CELLS,
    bucket_starts,
    cell_key,
    paper_bucket_starts,
    paper_key,
    query_cells,
    query_paper,
)

THETA_MAX_USABLE = math.radians(175.0)
MAX_CANDIDATES = 1000
COMPILED_SEARCH = True
"""Search a one-camera frame through :mod:`.maxangle_search`'s compiled calls; False takes the
Python loop that rigs take (the tests compare the two)."""


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


def _concat_consuming(pieces: list[np.ndarray], empty: np.ndarray) -> np.ndarray:
    """``np.concatenate(pieces)``, emptying ``pieces`` as it goes: each piece is freed once
    copied, so the memory held is the result plus one piece (not the pieces and the result)."""
    if not pieces:
        return empty
    out = np.empty((sum(len(x) for x in pieces), *pieces[0].shape[1:]), dtype=pieces[0].dtype)
    pos = 0
    while pieces:
        x = pieces.pop(0)
        out[pos:pos + len(x)] = x
        pos += len(x)
        del x
    return out


PATTERN_PARAMS = ("pattern_mag_limit", "pattern_cap", "pattern_radius_deg")


def pattern_stars(stars: StarTable, params: dict[str, Any]) -> np.ndarray:
    """Rows of ``stars`` (brightest first) that the triangles are made of: all of them, or those
    at most ``pattern_mag_limit`` (V) and, with ``pattern_cap``, having fewer than that many
    brighter pattern stars within ``pattern_radius_deg``. A database whose table must reach
    across a wide field (``d_max_deg``) keeps it tractable this way: a camera forms its
    triangles of its brightest stars only, which such a cap keeps."""
    from scipy.spatial import cKDTree

    from ..geometry import chord_from_angle

    keep = np.ones(len(stars.vec), dtype=bool)
    if "pattern_mag_limit" in params:
        keep &= np.asarray(stars.mag) <= float(params["pattern_mag_limit"])
    rows = np.flatnonzero(keep)
    if "pattern_cap" in params and len(rows):
        radius = chord_from_angle(math.radians(float(params.get("pattern_radius_deg", 5.0))))
        pairs = cKDTree(stars.vec[rows]).query_pairs(float(radius), output_type="ndarray")
        brighter = np.bincount(pairs.max(axis=1), minlength=len(rows)) if len(pairs) else np.zeros(len(rows), int)
        rows = rows[brighter < int(params["pattern_cap"])]
    return rows.astype(np.int64)


class MaxAngle:
    name = "maxangle"
    summary = "triangles hashed by their maximum interior angle into N blocks (seed 000)"

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        map_large_allocations()  # freed chunks go back to the system, not to glibc's heap
        d_max_deg = float(params.get("d_max_deg", config.fov_min_deg))
        xi_deg = float(params.get("xi_deg", 0.05))
        # triangles at or past theta_limit are not kept (maxangle's search never forms them; a
        # table read for every triangle, as _table_join's box table, keeps them all: 180)
        theta_limit = math.radians(float(params.get("theta_max_deg", math.degrees(THETA_MAX_USABLE))))
        n_blocks = int(params.get("n_blocks", N_BLOCKS))
        layout = str(params.get("layout", "cells"))
        n_cells = int(params.get("n_cells", N_CELLS))
        if layout not in LAYOUTS:
            raise ValueError(f"maxangle layout {layout!r}: expected one of {', '.join(LAYOUTS)}")
        cells = layout == "cells"
        rows_kept = pattern_stars(stars, params)
        vec = stars.vec[rows_kept]
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
        # Each chunk's triangles go straight into their stored form (28 bytes a triangle: key
        # float64, three int32 ids, two float32 (c and theta, or b and c: maxangle_index's
        # layouts)), not a float64 record of 48 bytes
        # concatenated, sorted and copied whole: for a 20-deg d_max at V 6.5 (~78 million
        # triangles) that took the build to 15.6 GB; this way the peak is the tables plus a few
        # bytes a triangle for the sort. The values and their order are unchanged.
        b_scale = math.radians(d_max_deg) * 1.001
        names = ("key", "ids", "b", "c") if cells else ("key", "ids", "c", "theta")
        parts: dict[str, list[np.ndarray]] = {name: [] for name in names}
        chunk = max(1, n // 50)
        for s0 in range(0, n, chunk):
            progress("triangles", s0 / n)
            lo, hi = starts[s0], starts[min(s0 + chunk, n)]
            seg = p[lo:hi]
            seg_ang = ang[lo:hi]
            # pairs (i, j), (i, k) with j < k sharing i: all combinations inside each i-group
            g = seg[:, 0]
            g_end = np.searchsorted(g, g, side="right")
            cnt = g_end - np.arange(len(g)) - 1  # partners after this row in the same group
            rows = np.repeat(np.arange(len(g)), cnt)
            offs = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            other = rows + 1 + offs
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
            keep = theta < theta_limit if theta_limit < math.pi else np.ones(len(theta), bool)
            theta = theta[keep]
            c32 = sides[keep, 2].astype(np.float32)
            parts["ids"].append(rows_kept[ids[keep]].astype(np.int32))
            parts["c"].append(c32)
            if cells:
                b32 = sides[keep, 1].astype(np.float32)
                parts["key"].append(cell_key(theta, b32, c32, n_cells, b_scale))
                parts["b"].append(b32)
            else:
                parts["key"].append(paper_key(theta, sides[keep, 1], n_blocks, b_scale))
                parts["theta"].append(theta.astype(np.float32))
            del rows, offs, other, i_, j_, k_, jj, kk, q, pos, hit, sides, ids, theta, keep, c32
        empty = {"key": np.zeros(0), "ids": np.zeros((0, 3), np.int32), "b": np.zeros(0, np.float32),
                 "c": np.zeros(0, np.float32), "theta": np.zeros(0, np.float32)}
        tables = {name: _concat_consuming(parts[name], empty[name]) for name in names}
        del pairs, angles, p, ang, keys, key_order, keys_sorted, ang_by_key
        # key = bucket (cell or block) + a fraction below 1: sorted in place, bucket by bucket,
        # with 9 bytes a triangle beside the tables (np.argsort and copies took 16)
        sort_by_bucket_key(tables["key"], [tables[name] for name in names[1:]],
                           n_cells * n_cells if cells else n_blocks)
        key = tables["key"]
        progress(f"{len(key)} triangles", 1.0)
        layout_meta = {"layout": layout, "n_cells": n_cells} if cells else {"layout": layout, "n_blocks": n_blocks}
        meta = {"d_max_deg": d_max_deg, "xi_deg": xi_deg, "theta_max_deg": math.degrees(theta_limit), **layout_meta,
                "b_scale": b_scale,
                "n_triangles": int(len(key)), "n_pattern_stars": int(n),
                **{k: params[k] for k in PATTERN_PARAMS if k in params}}
        return tables, meta

    def matcher(self, db: NavDatabase) -> MaxAngleMatcher:
        return MaxAngleMatcher(db)


class MaxAngleMatcher:
    def __init__(self, db: NavDatabase) -> None:
        t = db.tables["maxangle"]
        prm = db.method_params("maxangle")
        self.layout = str(prm.get("layout", "paper"))  # databases built before layouts: the paper's
        self.ids, self.key, self.c = t["ids"], t["key"], t["c"]
        self.b_scale = float(prm["b_scale"])
        self.d_max = math.radians(prm["d_max_deg"])
        self.xi = math.radians(prm["xi_deg"])
        self.vec = db.stars.vec
        if self.layout == "cells":
            self.b, self.n_cells = t["b"], int(prm["n_cells"])
            self.bucket_start = bucket_starts(np.asarray(self.key), self.n_cells * self.n_cells)
        else:
            self.theta, self.n_blocks = t["theta"], int(prm["n_blocks"])
            self.bucket_start = paper_bucket_starts(np.asarray(self.key), self.n_blocks)

    def observed_triangles(self, d: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Usable triangles of the observed stars with pairwise angles ``d`` ``(n, n)``, best
        conditioned (smallest theta tolerance) first, with near-tie relabellings.

        Returns ``labels`` (T, 3) observed rows as (max, sec, thi) vertices, ``sides`` (T, 3)
        ``a >= b >= c`` radians, ``theta`` (T,) and its tolerance ``tol`` (T,).
        """
        tri = _pattern_array(len(d))
        return _best_conditioned_first(*_observed_triangles(np.ascontiguousarray(d, dtype=np.float64), tri,
                                                             float(eps), self.d_max, self.xi))

    def query_many(self, sides: np.ndarray, theta: np.ndarray, tol: np.ndarray, eps: float,
                   labels: np.ndarray, obs_vec: np.ndarray,
                   max_per_triangle: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Record rows matching each observed triangle (vertices ``labels``, rows of the
        observed vectors ``obs_vec``) with the same handedness; returns ``(rows, which)`` with
        ``which`` the index of the observed triangle of each row (ascending). With
        ``max_per_triangle > 0`` every candidate of a triangle matching more than that many
        catalogue triangles is dropped (it carries no information)."""
        args = (self.vec, np.ascontiguousarray(obs_vec, dtype=np.float64),
                np.ascontiguousarray(labels, dtype=np.int64), np.ascontiguousarray(sides, dtype=np.float64),
                np.ascontiguousarray(theta, dtype=np.float64), np.ascontiguousarray(tol, dtype=np.float64),
                float(eps))
        if self.layout == "cells":
            return query_cells(self.key, self.bucket_start, self.b, self.c, self.ids, *args, self.n_cells,
                               self.b_scale, int(max_per_triangle))
        return query_paper(self.key, self.bucket_start, self.c, self.theta, self.ids, *args, self.n_blocks,
                           self.b_scale, int(max_per_triangle))

    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        tri_ext = _extension_array(n, len(obs))
        v = obs.vec[:max(n, min(len(obs), EXTEND_STARS))]  # the stars tri_ext may name
        eps = ctx.tol_rad
        labels, sides, theta, tol, n_first = _triangles_extended(v, n, _pattern_array(n), tri_ext, float(eps),
                                                                 self.d_max, self.xi)
        if COMPILED_SEARCH and len(obs.cameras) == 1 and ctx.verifier.min_matches == 4:
            return maxangle_search.search(self, ctx, labels, sides, theta, tol, eps, MAX_CANDIDATES, n_first,
                                          EXTENSION_TRIALS)
        ver = ctx.verifier
        held = len(ver.marginal)
        found = self._search_loop(ctx, labels, sides, theta, tol, eps, v, 0, n_first)
        if found is not None or len(ver.marginal) > held or n_first == len(labels) or ver.over_limit() \
                or ctx.expired():
            return found
        # the extension's triangles (maxangle_search.search): at most EXTENSION_TRIALS more hypotheses
        limit = ver.trial_limit
        ver.trial_limit = maxangle_search.extension_limit(ver.trials, limit, EXTENSION_TRIALS)
        try:
            return self._search_loop(ctx, labels, sides, theta, tol, eps, v, n_first, len(labels))
        finally:
            ver.trial_limit = limit

    def _search_loop(self, ctx: SolveContext, labels: np.ndarray, sides: np.ndarray, theta: np.ndarray,
                     tol: np.ndarray, eps: float, v: np.ndarray, start: int, end: int) -> Verified | None:
        """The triangles ``[start, end)`` in chunks through the verifier (a rig's frame; one
        camera's runs :func:`~.maxangle_search.search`)."""
        bounds = start + maxangle_search.chunk_bounds(end - start)
        for lo, hi in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
            if ctx.expired() or ctx.verifier.over_limit():
                break
            sl = slice(lo, hi)
            rows, which = self.query_many(sides[sl], theta[sl], tol[sl], eps, labels[sl], v, MAX_CANDIDATES)
            if len(rows) == 0:
                ctx.verifier.patterns += hi - lo
                continue
            found = ctx.verifier.screen_and_check_many(labels[sl][which], self.ids[rows], n_patterns=hi - lo)
            if found is not None:
                return found
        return None


_PATTERNS: dict[int, np.ndarray] = {}


def _pattern_array(n: int) -> np.ndarray:
    if n not in _PATTERNS:
        _PATTERNS[n] = np.array(pattern_order(n), dtype=np.int64).reshape(-1, 3)
    return _PATTERNS[n]


EXTEND_STARS = 16
"""Where fewer of the brightest stars' triangles fit the table than their number (a wide field's
brightest spread beyond ``d_max``), triangles of up to this many brightest stars that do fit
follow them, up to that number (:func:`_triangles_extended`)."""
EXTENSION_TRIALS = 120
"""Hypotheses the triangles of :data:`EXTEND_STARS` may add to a search that the brightest
stars' own left without an answer (none where they left a marginal one). Seeds 003-004 at
0.75-1 mag of magnitude noise: the 14 frames of bench_peers they name took 8-90. bench_wrong's
99,960 frames: 232 more identified at 120 (240 at 250, 247 at 500, 272 unbounded); random points
on seeds 003-004: 0.56-0.65 -> 0.68-0.80 ms median at 120 (~0.85 at 250, 2.3 unbounded: ~4,500
hypotheses)."""
_EXTENSIONS: dict[tuple[int, int], np.ndarray] = {}


def _extension_array(n_tri: int, n_obs: int) -> np.ndarray:
    """The triangles of the ``min(n_obs, EXTEND_STARS)`` brightest stars with a star past the
    ``n_tri`` brightest, in pattern order (none when there is no such star)."""
    n_all = min(n_obs, EXTEND_STARS)
    key = (n_tri, n_all)
    if key not in _EXTENSIONS:
        tri = _pattern_array(n_all) if n_all > n_tri else np.zeros((0, 3), np.int64)
        _EXTENSIONS[key] = np.ascontiguousarray(tri[tri.max(axis=1) >= n_tri]) if len(tri) else tri
    return _EXTENSIONS[key]


@njit(cache=True, nogil=True)
def _triangles_extended(v: np.ndarray, n_tri: int, tri: np.ndarray, tri_ext: np.ndarray, eps: float, d_max: float,
                        xi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`_triangles_of` of the ``n_tri`` brightest of ``v`` (``tri``: their pattern order),
    then, where fewer entries than ``len(tri)`` fit the table, the best-conditioned that fit among
    ``tri_ext`` (triangles with a fainter star, :func:`_extension_array`) up to that number. The
    first part is the list without the extension, in its order: the extension only adds
    triangles after it, whose number it returns last (a search gives the rest at most
    :data:`EXTENSION_TRIALS` hypotheses). The 8 brightest detections of a 20-28-deg field fill few
    triangles of a 9-deg table (1-3 of 56 where 1 mag of magnitude noise scatters the brightest:
    seed 004), the 16 brightest tens."""
    labels, sides, theta, tol = _triangles_of(v[:n_tri], tri, eps, d_max, xi)
    room = len(tri) - len(labels)
    if room <= 0 or len(tri_ext) == 0:
        return labels, sides, theta, tol, len(labels)
    l2, s2, t2, o2 = _triangles_of(v[:min(len(v), EXTEND_STARS)], tri_ext, eps, d_max, xi)  # tri_ext's stars
    k = min(room, len(l2))
    n = len(labels)
    out_l = np.empty((n + k, 3), np.int64)
    out_s = np.empty((n + k, 3))
    out_t = np.empty(n + k)
    out_o = np.empty(n + k)
    out_l[:n], out_s[:n], out_t[:n], out_o[:n] = labels, sides, theta, tol
    out_l[n:], out_s[n:], out_t[n:], out_o[n:] = l2[:k], s2[:k], t2[:k], o2[:k]
    return out_l, out_s, out_t, out_o, n


@njit(cache=True, nogil=True)
def _triangles_of(v: np.ndarray, tri: np.ndarray, eps: float, d_max: float,
                  xi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`MaxAngleMatcher.observed_triangles` of the unit vectors ``v`` ``(n, 3)``, their
    pairwise angles included (one compiled call: the numpy steps cost ~10 us on 6 stars)."""
    return _best_conditioned_first(*_observed_triangles(pairwise_angles_kernel(v), tri, eps, d_max, xi))


@njit(cache=True, nogil=True)
def _best_conditioned_first(labels: np.ndarray, sides: np.ndarray, theta: np.ndarray,
                            tol: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The paper's advice, made quantitative: best-conditioned triangles first (the tolerance on
    theta_max sets how many catalogue triangles a query returns); a stable sort."""
    first = np.argsort(tol, kind="mergesort")
    return labels[first], sides[first], theta[first], tol[first]


@njit(cache=True, nogil=True)
def _observed_triangles(d: np.ndarray, tri: np.ndarray, eps: float, d_max: float,
                        xi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled body of :meth:`MaxAngleMatcher.observed_triangles`, before the sort by
    tolerance: usable triangles in pattern order, each followed by its near-tie relabellings
    (``a ~ b``: max/sec swapped; ``b ~ c``: sec/thi swapped; both: rotated)."""
    cap = 4 * len(tri)
    labels = np.empty((cap, 3), np.int64)
    sides = np.empty((cap, 3))
    theta = np.empty(cap)
    tol = np.empty(cap)
    n_out = 0
    s = np.empty(3)
    ids = np.empty(3, np.int64)
    for t in range(len(tri)):
        i, j, k = tri[t, 0], tri[t, 1], tri[t, 2]
        s[0], s[1], s[2] = d[j, k], d[i, k], d[i, j]  # each side opposite its vertex
        ids[0], ids[1], ids[2] = i, j, k
        for m in range(1, 3):  # stable insertion sort, descending
            q = m
            while q > 0 and s[q] > s[q - 1]:
                s[q], s[q - 1] = s[q - 1], s[q]
                ids[q], ids[q - 1] = ids[q - 1], ids[q]
                q -= 1
        a, b, c = s[0], s[1], s[2]
        if not (a <= d_max - eps and c >= xi + eps and c >= 4 * eps):
            continue
        th = math.acos(min(max((b * b + c * c - a * a) / (2 * b * c), -1.0), 1.0))
        if th > THETA_MAX_USABLE:
            continue
        sn = max(math.sin(th), 1e-3)
        cs = math.cos(th)
        tl = eps * (a + abs(c - b * cs) + abs(b - c * cs)) / (b * c * sn)  # |d theta / d side| summed
        ab = a - b < 2 * eps
        bc = b - c < 2 * eps
        for variant in range(4):
            if (variant == 1 and not ab) or (variant == 2 and not bc) or (variant == 3 and not (ab and bc)):
                continue
            if variant == 0:
                v0, v1, v2 = ids[0], ids[1], ids[2]
            elif variant == 1:
                v0, v1, v2 = ids[1], ids[0], ids[2]
            elif variant == 2:
                v0, v1, v2 = ids[0], ids[2], ids[1]
            else:
                v0, v1, v2 = ids[1], ids[2], ids[0]
            labels[n_out, 0], labels[n_out, 1], labels[n_out, 2] = v0, v1, v2
            sides[n_out, 0], sides[n_out, 1], sides[n_out, 2] = a, b, c
            theta[n_out] = th
            tol[n_out] = tl
            n_out += 1
    return labels[:n_out], sides[:n_out], theta[:n_out], tol[:n_out]
