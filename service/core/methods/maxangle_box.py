"""The density box read from a ``cells`` triangle table: every catalogue triple within ``w`` of an
observed triangle on all three sides (:func:`box_cells`).

``triangle``'s unique-triangle proof (:mod:`service.core.sparse_proof`) counts the triples of a
box ~30 tolerances wide (~2,000 of them, from ~500 cells); the small frame's screen
(:mod:`service.core.sparse_screen`) counts those of each triangle at the pattern tolerance. The
table (:mod:`.maxangle_index`'s ``cells`` layout) is larger than the caches and a box's cells lie
apart in it, so, as :func:`~.maxangle_index.query_cells` does, the cells are gone through in
passes, each requesting what the next reads: their starts, their keys, then (after the binary
search) their slices' sides and stars. The records read, their order and the answer are those
of one pass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..prefetch import prefetch
from ..screen import triple_product
from .maxangle_index import _EDGE, _FRAC_CLIP, THETA_LO, THETA_SPAN, _cell_range, _prefetch_span

_BOX_MARGIN = 1e-7
"""Radians by which :func:`box_cells` widens the stored sides' and ``theta``'s ranges: more than
their float32 rounding (~4e-9 rad at 3.5 deg) and the key's; the records it reads are then
decided by their stars' own angles."""


@njit(cache=True, nogil=True, inline="always")
def _cos_range(a_lo: float, a_hi: float, b_lo: float, b_hi: float, c_lo: float, c_hi: float) -> tuple[float, float]:
    """Bounds of ``(b^2 + c^2 - a^2) / (2 b c)`` (``cos theta_max``) over a box of sides (all
    positive), each of its three terms bounded on its own."""
    lo = b_lo / (2 * c_hi) + c_lo / (2 * b_hi) - a_hi * a_hi / (2 * b_lo * c_lo)
    hi = b_hi / (2 * c_lo) + c_hi / (2 * b_lo) - a_lo * a_lo / (2 * b_hi * c_hi)
    return lo, hi


@njit(cache=True, nogil=True, inline="always")
def _pair_angle(u: np.ndarray, v: np.ndarray) -> float:
    """Angle (rad) between unit vectors as the pair table stores it (``2 asin(chord / 2)``)."""
    dx, dy, dz = u[0] - v[0], u[1] - v[1], u[2] - v[2]
    return 2.0 * math.asin(min(max(math.sqrt(dx * dx + dy * dy + dz * dz) / 2.0, 0.0), 1.0))


_CHORD_SLACK = 1e-9
"""Relative margin in squared chord about a window's bounds, inside which :func:`box_cells`
measures the angle itself (float rounding of either form is ~1e-16 relative)."""


@njit(cache=True, nogil=True, inline="always")
def _chord2(u: np.ndarray, v: np.ndarray) -> float:
    """Squared chord between unit vectors, summed as :func:`_pair_angle` sums it."""
    dx, dy, dz = u[0] - v[0], u[1] - v[1], u[2] - v[2]
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, nogil=True, inline="always")
def _chord2_window(lo: float, hi: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """The angle window ``[lo, hi]`` (rad) in squared chord: bounds outside which a pair is out
    of it and inside which it is in, whatever the rounding (``_CHORD_SLACK`` apart)."""
    q_lo = -1.0
    if lo > 0.0:
        c = 2.0 * math.sin(lo / 2.0)
        q_lo = c * c
    c = 2.0 * math.sin(min(hi, math.pi) / 2.0)
    q_hi = c * c
    s = _CHORD_SLACK
    return (q_lo * (1.0 - s) if q_lo > 0 else -1.0, q_hi * (1.0 + s)), (q_lo * (1.0 + s) if q_lo > 0 else -1.0,
                                                                       q_hi * (1.0 - s))


@njit(cache=True, nogil=True, inline="always")
def _rank(x: float, y: float, z: float) -> int:
    """How many of ``y``, ``z`` are smaller than ``x`` (0 for the shortest of three sides)."""
    return (1 if y < x else 0) + (1 if z < x else 0)


_PERMS = ((0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2))
"""The six vertex orders, the even (handedness-keeping) three first."""
_EVEN = (True, True, True, False, False, False)


@njit(cache=True, nogil=True, inline="always")
def _of(j: int, x0: float, x1: float, x2: float) -> float:
    """``(x0, x1, x2)[j]`` without a tuple indexed at run time."""
    return x0 if j == 0 else (x1 if j == 1 else x2)


_AHEAD = 8
"""Records ahead of the one read whose stars' vectors :func:`box_cells` requests."""


@njit(cache=True, nogil=True)
def box_cells(key: np.ndarray, cell_start: np.ndarray, b_tab: np.ndarray, c_tab: np.ndarray, ids: np.ndarray,
              star_vec: np.ndarray, obs_vec: np.ndarray, s01: float, s02: float, s12: float, w: float,
              n_cells: int, b_scale: float, d_max: float, xi: float, theta_max: float) -> tuple[bool, np.ndarray]:
    """Every catalogue triple ``(p0, p1, p2)`` whose pair angles lie within ``w`` of the observed
    triangle's (``|angle(p0, p1) - s01| <= w``, likewise ``s02``, ``s12``; radians, as the pair
    table's windows ``[s - w, s + w]`` hold them) with the handedness of ``obs_vec`` (3, 3), read
    from a ``cells`` table: the join of three pair windows
    (:meth:`~.triangle.TriangleMatcher.triples`) as a look-up, in another order.

    A triangle whose sides lie within ``w`` of the observed ones has its sorted sides within
    ``w`` of the sorted observed ones, so the records read are those of the cells covering the
    sorted ``b +- w``, ``c +- w``, and in each cell the ``theta_max`` range its sides allow
    (:func:`_cos_range`); each record's stars then decide in every vertex order. Returns
    ``(False, empty)`` where the table cannot hold every such triple: a side beyond ``d_max``
    or at most ``xi``, or ``theta_max`` possibly at or past ``theta_max`` (the table's limits)."""
    none = np.zeros((0, 3), np.int64)
    sides = sorted([s01, s02, s12])
    a0, b0, c0 = sides[2], sides[1], sides[0]
    m = _BOX_MARGIN
    if a0 + w + m >= d_max or c0 - w - m <= xi:
        return False, none
    # theta_max grows with a and falls with b and c wherever a >= b >= c, so no triangle of the
    # box has a larger one than the box's corner (a + w, b - w, c - w): the table holds them all
    # if that corner is under its limit
    a1, b1, c1 = a0 + w + m, b0 - w - m, c0 - w - m
    cos_lo = (b1 * b1 + c1 * c1 - a1 * a1) / (2 * b1 * c1)
    if theta_max < math.pi and (cos_lo <= -1.0 or math.acos(cos_lo) >= theta_max):
        return False, none  # (a table of every theta_max, 180 deg, holds them whatever the box)
    lo01, hi01, lo02, hi02, lo12, hi12 = s01 - w, s01 + w, s02 - w, s02 + w, s12 - w, s12 + w
    h_obs = triple_product(obs_vec[0], obs_vec[1], obs_vec[2])
    # sides more than 2 (w + m) apart: a triangle within w of them on every side keeps their
    # order, so only one vertex order can match a record (the one that pairs sides by rank: the
    # record's vertex opposite its shortest side, q2, to the observed vertex opposite the
    # shortest, and so on): its stars decide in that order alone (the loop over six finds no other)
    single = a0 - b0 > 2 * (w + m) and b0 - c0 > 2 * (w + m)
    o0 = 2 - _rank(s12, s01, s02)  # the record vertex observed vertices 0 and 1 map to (so is vertex 2's)
    o1 = 2 - _rank(s02, s01, s12)
    out01, in01 = _chord2_window(lo01, hi01)
    out02, in02 = _chord2_window(lo02, hi02)
    out12, in12 = _chord2_window(lo12, hi12)
    width = b_scale / n_cells
    ib0, ib1 = _cell_range(b0, w + m, b_scale, n_cells)
    ic0, ic1 = _cell_range(c0, w + m, b_scale, n_cells)
    n_max = (ib1 - ib0 + 1) * (ic1 - ic0 + 1)
    q_cell = np.empty(n_max, np.int64)  # the cells read, in scan order, and their theta fractions
    q_flo = np.empty(n_max)
    q_fhi = np.empty(n_max)
    n_q = 0
    for i_b in range(ib0, ib1 + 1):  # the cells, their starts requested
        b_lo = max(i_b * width, b0 - w) - m
        b_hi = min((i_b + 1) * width, b0 + w) + m
        top = min(ic1, i_b)
        if top >= ic0:
            prefetch(cell_start, np.int64(i_b * n_cells + ic0))
            prefetch(cell_start, np.int64(i_b * n_cells + top + 1))
        for i_c in range(ic0, top + 1):
            c_lo = max(i_c * width, c0 - w) - m
            c_hi = min((i_c + 1) * width, c0 + w) + m
            if c_lo > b_hi or c_lo <= 0.0:
                continue
            cl, ch = _cos_range(a0 - w - m, a0 + w + m, b_lo, b_hi, c_lo, c_hi)
            th_lo = math.acos(min(max(ch, -1.0), 1.0))
            th_hi = math.acos(min(max(cl, -1.0), 1.0))
            q_cell[n_q] = i_b * n_cells + i_c
            q_flo[n_q] = min((th_lo - THETA_LO) / THETA_SPAN, _FRAC_CLIP)  # (records past the clip are stored at it)
            q_fhi[n_q] = (th_hi - THETA_LO) / THETA_SPAN
            n_q += 1
    q_start = np.empty(n_q, np.int64)
    q_end = np.empty(n_q, np.int64)
    for iq in range(n_q):  # their starts read, their keys requested
        q_start[iq], q_end[iq] = cell_start[q_cell[iq]], cell_start[q_cell[iq] + 1]
        _prefetch_span(key, q_start[iq], q_end[iq], 64 // key.itemsize)
    ids_flat = ids.reshape(-1)
    for iq in range(n_q):  # their theta slices found, the slices' sides and stars requested
        lo, hi = q_start[iq], q_end[iq]
        if lo == hi:
            continue
        part = key[lo:hi]
        q_start[iq] = lo + np.searchsorted(part, q_cell[iq] + q_flo[iq] - _EDGE, side="left")
        q_end[iq] = lo + np.searchsorted(part, q_cell[iq] + q_fhi[iq] + _EDGE, side="right")
        _prefetch_span(b_tab, q_start[iq], q_end[iq], 64 // b_tab.itemsize)
        _prefetch_span(c_tab, q_start[iq], q_end[iq], 64 // c_tab.itemsize)
        _prefetch_span(ids_flat, 3 * q_start[iq], 3 * q_end[iq], 64 // ids.itemsize)
    out = np.empty((64, 3), np.int64)
    n = 0
    vec_flat = star_vec.reshape(-1)
    for iq in range(n_q):  # the records
        end = q_end[iq]
        for r in range(q_start[iq], end):
            if r + _AHEAD < end:  # the stars of a record ahead requested: they lie all over the sky
                for t in range(3):
                    prefetch(vec_flat, np.int64(3 * ids[r + _AHEAD, t]))
            if abs(float(b_tab[r]) - b0) > w + m or abs(float(c_tab[r]) - c0) > w + m:
                continue
            q0, q1, q2 = ids[r, 0], ids[r, 1], ids[r, 2]
            right = triple_product(star_vec[q0], star_vec[q1], star_vec[q2]) > 0
            # the record's pairs in squared chord, once; each vertex order's windows tested on
            # them away from their bounds (no asin), and near one on the angles themselves, as
            # the pair table measures them
            e0 = _chord2(star_vec[q0], star_vec[q1])
            e1 = _chord2(star_vec[q0], star_vec[q2])
            e2 = _chord2(star_vec[q1], star_vec[q2])
            for k in range(6):
                if (right == (h_obs > 0)) != _EVEN[k]:
                    continue  # an odd order mirrors the triangle
                i0, i1, i2 = _PERMS[k]
                if single and (i0 != o0 or i1 != o1):
                    continue  # the one order that pairs sides by rank (see ``single``)
                j01, j02, j12 = i0 + i1 - 1, i0 + i2 - 1, i1 + i2 - 1  # vertex pair (i, j): side i + j - 1
                d01, d02, d12 = _of(j01, e0, e1, e2), _of(j02, e0, e1, e2), _of(j12, e0, e1, e2)
                if d01 < out01[0] or d01 > out01[1] or d02 < out02[0] or d02 > out02[1] or d12 < out12[0] \
                        or d12 > out12[1]:
                    continue
                if not (in01[0] < d01 < in01[1] and in02[0] < d02 < in02[1] and in12[0] < d12 < in12[1]) \
                        and not _in_windows(star_vec, q0, q1, q2, j01, j02, j12, lo01, hi01, lo02, hi02, lo12,
                                            hi12):
                    continue
                out = _push(out, n, _of(i0, q0, q1, q2), _of(i1, q0, q1, q2), _of(i2, q0, q1, q2))
                n += 1
    return True, out[:n].copy()


@njit(cache=True, nogil=True, inline="always")
def _in_windows(star_vec: np.ndarray, q0: int, q1: int, q2: int, j01: int, j02: int, j12: int, lo01: float,
                hi01: float, lo02: float, hi02: float, lo12: float, hi12: float) -> bool:
    """Do the angles of stars ``q0``-``q1``, ``q0``-``q2`` and ``q1``-``q2`` (sides 0, 1, 2, as the pair
    table measures them) taken as the sides ``j01``, ``j02``, ``j12`` lie in their windows?"""
    e0 = _pair_angle(star_vec[q0], star_vec[q1])
    e1 = _pair_angle(star_vec[q0], star_vec[q2])
    e2 = _pair_angle(star_vec[q1], star_vec[q2])
    d01, d02, d12 = _of(j01, e0, e1, e2), _of(j02, e0, e1, e2), _of(j12, e0, e1, e2)
    return lo01 <= d01 <= hi01 and lo02 <= d02 <= hi02 and lo12 <= d12 <= hi12


@njit(cache=True, nogil=True, inline="always")
def _push(out: np.ndarray, n: int, a: int, b: int, c: int) -> np.ndarray:
    """``out`` (grown by doubling when full) with row ``n`` set to ``(a, b, c)``."""
    if n == len(out):
        grown = np.empty((2 * n, 3), np.int64)
        grown[:n] = out
        out = grown
    out[n, 0], out[n, 1], out[n, 2] = a, b, c
    return out


__all__ = ["box_cells"]
