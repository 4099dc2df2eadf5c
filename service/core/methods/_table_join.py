"""Pair-window joins read from a triangle table.

``pyramid`` and ``triangle`` find the catalogue triples of an observed triangle by joining three
windows of the pair table (:func:`~._pairs.join_windows`): every pair within ``w`` of each side,
~1,000-15,000 rows a window on the default set's ``sparse`` member, ~35-450 us a join. A table of
every triangle of the member's stars holds the same triples, read by cell
(:func:`~.maxangle_box.box_cells`, ~10-80 us): the member's ``maxangle`` table when it is made
of every star (``cells`` layout), or ``triangle``'s own box table (build parameter
``box_d_max_deg``). Where the triangle could reach past the table's limits the callers join.

:func:`table_join` gives the join's triples in the join's order (by pivot star, then the pivot's
pair with the second vertex, then with the third, each pair by its place in the pair table:
orientation, then angle), so that the candidates a caller checks, and the answers, are those of
the join; the density box (:meth:`~.triangle.TriangleMatcher.box_triples`) takes them in any order.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from ..geometry import pairwise_angles_kernel
from ..navdb.reader import NavDatabase
from ..star_index import star_vec64
from .maxangle import PATTERN_PARAMS, THETA_MAX_USABLE, MaxAngle
from .maxangle_box import _pair_angle, box_cells
from .maxangle_index import bucket_starts

_THETA_MAX_DEG = math.degrees(THETA_MAX_USABLE)
"""The ``theta_max`` limit of a table built before its ``theta_max_deg`` was recorded."""

BOX_CELL_DEG = 3.5 / 256
"""Cell side (deg) of a box table's ``(b, c)`` grid: the default set's ``maxangle`` cells."""

TableArgs = tuple[Any, ...]
""":func:`~.maxangle_box.box_cells`'s table arguments: ``key, cell_start, b, c, ids, star_vec``,
then ``n_cells, b_scale, d_max, xi, theta_max``."""


def build_box_table(stars: Any, config: Any, d_max_deg: float, progress: Any) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, Any]]:
    """``triangle``'s own box table: every triangle of ``stars`` with sides up to ``d_max_deg``
    (``maxangle``'s builder, cells about :data:`BOX_CELL_DEG` wide), as arrays ``box_*`` and
    their manifest entries ``box_*``."""
    n_cells = max(16, round(d_max_deg / BOX_CELL_DEG))
    box, meta = MaxAngle().build_tables(stars, config, {"d_max_deg": d_max_deg, "n_cells": n_cells,
                                                        "theta_max_deg": 180.0}, progress)
    return ({f"box_{name}": box[name] for name in ("key", "ids", "b", "c")},
            {f"box_{name}": meta[name] for name in ("d_max_deg", "xi_deg", "theta_max_deg", "n_cells", "b_scale",
                                                    "n_triangles")})


def triangle_table(db: NavDatabase) -> TableArgs | None:
    """The triangle table of ``db`` that reaches furthest (``triangle``'s own box table, or a
    ``maxangle`` table in the ``cells`` layout made of every star of ``db``), as
    :func:`~.maxangle_box.box_cells` takes it; None without one. Kept on ``db``."""
    cache = db.__dict__.setdefault("_cache", {})
    if "triangle_table" not in cache:
        cache["triangle_table"] = _find_table(db)
    return cache["triangle_table"]


def _find_table(db: NavDatabase) -> TableArgs | None:
    from . import get_matcher  # (the registry imports the methods that import this module)

    reach = {}  # the tables db holds that can stand in for the join, by their sides' reach (deg)
    if "box_key" in db.tables.get("triangle", {}):
        reach["triangle"] = float(db.method_params("triangle")["box_d_max_deg"])
    if "maxangle" in db.tables:
        prm = db.method_params("maxangle")
        if (prm.get("layout") == "cells" and not any(k in prm for k in PATTERN_PARAMS)
                and int(prm.get("n_pattern_stars", -1)) == len(db.stars)):
            reach["maxangle"] = float(prm["d_max_deg"])
    if not reach:
        return None
    name = max(reach, key=reach.__getitem__)
    t, prm = db.tables[name], db.method_params(name)
    if name == "triangle":
        n_cells = int(prm["box_n_cells"])
        key, b, c, ids = t["box_key"], t["box_b"], t["box_c"], t["box_ids"]
        cell_start = bucket_starts(np.asarray(key), n_cells * n_cells)
        b_scale, xi_deg, theta_deg = prm["box_b_scale"], prm["box_xi_deg"], prm.get("box_theta_max_deg", _THETA_MAX_DEG)
    else:  # its cell starts are its matcher's own
        n_cells = int(prm["n_cells"])
        key, b, c, ids = t["key"], t["b"], t["c"], t["ids"]
        cell_start = get_matcher(db, "maxangle").bucket_start
        b_scale, xi_deg, theta_deg = prm["b_scale"], prm["xi_deg"], prm.get("theta_max_deg", _THETA_MAX_DEG)
    return (key, cell_start, b, c, ids, star_vec64(db), n_cells, float(b_scale), math.radians(reach[name]),
            math.radians(float(xi_deg)), math.radians(float(theta_deg)))


def table_triples(table: TableArgs, v: np.ndarray, s_ab: float, s_ac: float, s_bc: float, w: float
                  ) -> np.ndarray | None:
    """The triples ``(a, b, c)`` the pair table's windows ``[s - w, s + w]`` of sides ``a-b``,
    ``a-c``, ``b-c`` join into, with the handedness of ``v`` (3, 3: the observed vectors in that
    vertex order; radians), in any order; None where the table may not hold them all."""
    ok, out = box_cells(*table[:6], np.array(v, dtype=np.float64), float(s_ab), float(s_ac), float(s_bc),
                        float(w), *table[6:])  # (a writable copy of v: one compiled signature)
    return out if ok else None


def table_join(table: TableArgs, v: np.ndarray, s_ab: float, s_ac: float, s_bc: float, w: float
               ) -> np.ndarray | None:
    """:func:`table_triples` in the order of :func:`~._pairs.join_windows` (then
    :func:`~._pairs.same_handedness`) on the same windows: by ``a``, then the ``a-b`` pair's
    orientation in the pair table (``a`` its smaller row first) and angle, then the ``a-c``
    pair's (the table's rows are sorted by angle, as the pair table built them). One compiled
    call (:func:`join_kernel`)."""
    ok, out = join_kernel(*table[:6], np.array(v, dtype=np.float64), float(s_ab), float(s_ac), float(s_bc),
                          float(w), False, *table[6:])
    return out if ok else None


def pivot_join(table: TableArgs, v: np.ndarray, w: float) -> np.ndarray | None:
    """The join's triples of the observed triangle ``v`` (3, 3) at ``w`` (rad) pivoted as
    :meth:`~.triangle.TriangleMatcher.triples` pivots them (on the vertex opposite the shortest
    side, the first such), in its order and with the columns in ``v``'s vertex order; None where
    the table may not hold them all. One compiled call (:func:`join_kernel`)."""
    ok, out = join_kernel(*table[:6], np.array(v, dtype=np.float64), 0.0, 0.0, 0.0, float(w), True, *table[6:])
    return out if ok else None


@njit(cache=True, nogil=True)
def join_kernel(key: np.ndarray, cell_start: np.ndarray, b_tab: np.ndarray, c_tab: np.ndarray, ids: np.ndarray,
                star_vec: np.ndarray, v: np.ndarray, s_ab: float, s_ac: float, s_bc: float, w: float, pivot: bool,
                n_cells: int, b_scale: float, d_max: float, xi: float, theta_max: float) -> tuple[bool, np.ndarray]:
    """:func:`table_join` of ``v`` with sides ``s_ab``, ``s_ac``, ``s_bc``, or with ``pivot``
    :func:`pivot_join` of ``v`` (the sides its own): ``(ok, triples)``, ``ok`` False where the
    table may not hold them all. (One kernel for both: the table's read is compiled once.)"""
    p, q, r = 0, 1, 2
    if pivot:
        d = pairwise_angles_kernel(v)
        shortest = d[1, 2]  # the vertex opposite the shortest side, the first of equals (tuple.index(min))
        if d[0, 2] < shortest:
            p, shortest = 1, d[0, 2]
        if d[0, 1] < shortest:
            p = 2
        q, r = (1, 2) if p == 0 else ((0, 2) if p == 1 else (0, 1))
        s_ab, s_ac, s_bc = d[p, q], d[p, r], d[q, r]
    vp = np.empty((3, 3))
    for a in range(3):
        vp[0, a], vp[1, a], vp[2, a] = v[p, a], v[q, a], v[r, a]
    ok, got = box_cells(key, cell_start, b_tab, c_tab, ids, star_vec, vp, s_ab, s_ac, s_bc, w, n_cells, b_scale,
                        d_max, xi, theta_max)
    if not ok:
        return False, got
    if len(got) >= 2:
        got = got[_join_order(star_vec, got)]
    if not pivot:
        return True, got
    out = np.empty_like(got)
    for i in range(len(got)):
        out[i, p], out[i, q], out[i, r] = got[i, 0], got[i, 1], got[i, 2]
    return True, out


@njit(cache=True, nogil=True)
def _join_order(star_vec: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The permutation of ``out``'s rows ``(a, b, c)`` that ``np.lexsort((angle(a, c), a > c,
    angle(a, b), a > b, a))`` gives: stable sorts from the last key to the first."""
    n = len(out)
    keys = np.empty((5, n))
    for i in range(n):
        a, b, c = out[i, 0], out[i, 1], out[i, 2]
        keys[0, i] = _pair_angle(star_vec[a], star_vec[c])
        keys[1, i] = 1.0 if a > c else 0.0
        keys[2, i] = _pair_angle(star_vec[a], star_vec[b])
        keys[3, i] = 1.0 if a > b else 0.0
        keys[4, i] = a
    order = np.arange(n)
    for k in range(5):
        order = order[np.argsort(keys[k][order], kind="mergesort")]
    return order
