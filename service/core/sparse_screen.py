"""A 3-4-star frame that no catalogue triangle fits: given up before ``auto``'s fallbacks search it.

On a frame of 3 or 4 stars the fallbacks (``maxangle``, ``pyramid``, ``triangle``) can name the
stars in two ways only:

- the verifier's proof, which pairs at least 4 stars (``Verifier.min_matches``): on a 4-star
  frame every star, so each of its 4 triangles is a catalogue triangle of the member;
- ``triangle``'s unique-triangle proof (:func:`~.sparse_proof.check_unique_triangle`), which needs
  a triangle matching exactly one catalogue triple.

Both start from the catalogue triples whose sides lie within the pattern tolerance of an
observed triangle's: the triples ``pyramid`` and ``triangle`` join, read from the member's
triangle table (:func:`~.methods._table_join.triangle_table`). One compiled call counts them for
every triangle of the frame (:func:`triangle_match_counts`). Where no triangle of a 4-star frame
fits a single triple, or a 3-star frame's one triangle fits none or several, no method could
prove the frame on that member, and its fallbacks are not searched (:func:`screen`'s
``HOPELESS``).

Measured on seed 002's camera (4 deg, 4096 px, 7.0 Mv; the default set's ``sparse`` member;
bench_peers' 15 points, seed 0; ``/work/s27/cand4.py``): 175 of the 249 unsolved 4-star frames and
103 of the 114 unsolved 3-star frames have no triangle fitting any triple; every solved frame has
one. Those frames cost 0.16-0.5 ms each in the three fallbacks (tetra3rs at 0.002: 5 us). Of the
rest, a 4-star frame whose triangles but one fit nothing (6 of 15 unsolved 4-star frames at 1 px
and 2 false stars) is left to ``triangle``'s unique-triangle proof alone (:data:`SPARSE_ONLY`).
``maxangle`` reads its own table with a ``theta_max`` window propagated from the same tolerance,
which can admit a triple one side of which is a little beyond it; a proof through such a triple
would pair a star beyond the match radius it is checked against, so none is lost (the answers of
the benchmark's frames before and after are compared in the commit that made this module).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .methods._table_join import triangle_table
from .methods.maxangle_box import box_cells
from .methods.quad_build import row_angle
from .navdb.reader import NavDatabase

SCREENED_METHODS = frozenset({"maxangle", "pyramid", "triangle"})
"""The fallbacks :func:`screen` stands for: their proofs start from a catalogue triple fitting an
observed triangle."""

MAX_SCREENED_STARS = 4
"""Frames of at most this many stars are screened: the verifier's proof pairs them all."""


@njit(cache=True, nogil=True)
def triangle_match_counts(key: np.ndarray, cell_start: np.ndarray, b_tab: np.ndarray, c_tab: np.ndarray,
                          ids: np.ndarray, star_vec: np.ndarray, obs_vec: np.ndarray, tol: float,
                          n_cells: int, b_scale: float, d_max: float, xi: float,
                          theta_max: float) -> np.ndarray:
    """For each triangle of the stars ``obs_vec`` ``(N, 3)`` (unit vectors, any frame; the
    triangles ``(i, j, k)``, ``i < j < k``, in lexicographic order), the number of catalogue
    triples with the same handedness whose three sides lie within ``tol`` (rad) of its own, read
    from a ``cells`` triangle table (:func:`~.methods.maxangle_box.box_cells`); -1 where the
    table may not hold them all (a side beyond its reach)."""
    n = len(obs_vec)
    out = np.full(n * (n - 1) * (n - 2) // 6, -1, np.int64)
    tri = np.empty((3, 3))
    t = 0
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                for a in range(3):
                    tri[0, a], tri[1, a], tri[2, a] = obs_vec[i, a], obs_vec[j, a], obs_vec[k, a]
                ok, got = box_cells(key, cell_start, b_tab, c_tab, ids, star_vec, tri, row_angle(tri, 0, 1),
                                    row_angle(tri, 0, 2), row_angle(tri, 1, 2), tol, n_cells, b_scale, d_max,
                                    xi, theta_max)
                if ok:
                    out[t] = len(got)
                t += 1
    return out


SEARCH, SPARSE_ONLY, HOPELESS = 0, 1, 2
""":func:`screen`'s verdicts: search the frame as before; only ``triangle``'s unique-triangle
proof could name it; nothing could."""


def screen(obs_vec: np.ndarray, db: NavDatabase, tol: float) -> int:
    """What could prove this frame of 3-4 stars (``obs_vec`` ``(N, 3)``, body frame) on member
    ``db`` at pattern tolerance ``tol`` (rad), from the catalogue triples fitting each of its
    triangles (:func:`triangle_match_counts`):

    - ``HOPELESS``: no triangle of a 4-star frame fits any triple, or only one does and it fits
      several, or a 3-star frame's one triangle fits none or several;
    - ``SPARSE_ONLY``: three triangles of a 4-star frame fit none, the fourth exactly one. The
      three share the star outside the fourth: a verifier's proof would pair it within the match
      radius (3 sigma) while every side it makes misses by more than the tolerance
      (``3 sqrt(2) sigma + 0.5 px``) in all three. ``pyramid`` gives up after two such
      triangles already (``EMPTY_TRIANGLES_TO_REFUSE``); the unique triangle may still be its
      own proof;
    - ``SEARCH`` otherwise, or where the member has no triangle table or a triangle reaches
      past it."""
    n = len(obs_vec)
    table = triangle_table(db) if 3 <= n <= MAX_SCREENED_STARS else None
    if table is None:
        return SEARCH
    counts = triangle_match_counts(*table[:6], np.ascontiguousarray(obs_vec, dtype=np.float64), float(tol),
                                   *table[6:]).tolist()  # 1 or 4 counts: Python's min and list, not
    # numpy's reductions (``(counts < 0).any()`` took 4.6 us of a 17-us screen on this VM)
    if min(counts) < 0:
        return SEARCH
    if n == 3:
        return SEARCH if counts[0] == 1 else HOPELESS
    fitting = [c for c in counts if c > 0]
    if not fitting:
        return HOPELESS
    if len(fitting) == 1:
        return SPARSE_ONLY if fitting[0] == 1 else HOPELESS
    return SEARCH

