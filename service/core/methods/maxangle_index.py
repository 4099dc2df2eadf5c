"""How ``maxangle``'s triangle table is stored and read: two layouts, one query semantics.

A query for an observed triangle (sides ``a >= b >= c``, ``theta_max`` with tolerance ``tol``)
returns every record with ``|b - b_obs| <= eps``, ``|c - c_obs| <= eps``, ``|theta - theta_obs|
<= tol``, the longest side rebuilt from ``(b, c, theta)`` within ``eps`` and the same
handedness. The layouts differ only in the order the records are stored in:

``paper``
    The paper's hash: sorted by ``theta_max`` and cut into ``n_blocks`` blocks ``H(theta) =
    floor(N (theta - 60) / 120)``, sorted by ``b`` inside each block (``key = H + b /
    b_scale``). Columns ``key, ids, c, theta``. A query reads the ``b +- eps`` slice of every
    block covering ``theta +- tol``: ~120 blocks a triangle on seed 000's camera at 1 px, each
    a few cache misses into a table of 10^6-10^7 records.
``cells``
    Sorted by cell of ``(b, c)`` (``n_cells`` x ``n_cells`` cells over ``[0, b_scale)``), then
    by ``theta`` inside each cell (``key = cell + (theta - 60) / 120``). Columns ``key, ids, b,
    c``. A query reads the ``theta +- tol`` slice of the few cells covering ``b +- eps``,
    ``c +- eps``: the same records 3-8x faster (``python -m bench.bench_maxangle_layout``;
    docs/performance.md, session 10).

Databases built before the ``layout`` parameter existed hold the ``paper`` layout and are read
as such.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..prefetch import prefetch
from ..screen import triple_product

THETA_LO = math.pi / 3
THETA_SPAN = 2 * math.pi / 3
LAYOUTS = ("cells", "paper")
N_BLOCKS = 1024
"""``paper`` layout: the paper's N, theta blocks over [60, 180) deg (its faster choice)."""
N_CELLS = 256
"""Cells per side of the ``cells`` layout's ``(b, c)`` grid (65,536 cells, half of them empty as
``c <= b``): a cell is ``d_max / 256`` wide (0.05 deg for a 12.5-deg table), about a query's
``2 eps`` at 1 px on a 1024-px, 8-deg camera."""
SUB_BUCKETS = 64
"""``paper`` layout: each theta block's ``b`` range is cut into this many buckets for the
query's slice search."""
_FRAC_CLIP = 0.999
"""``cells`` layout: ``theta_max`` is stored as the fraction of its span, clipped here (179.88 deg)."""
_EDGE = 1e-9
"""Margin (in cells, or in fractions of the theta span) by which a query widens the cells and
key range it reads, so that a record on a boundary is decided by the exact checks on its stored
values, never by rounding in the cell arithmetic."""


def paper_key(theta: np.ndarray, b: np.ndarray, n_blocks: int, b_scale: float) -> np.ndarray:
    """``paper`` layout key: theta block plus ``b / b_scale`` (float64)."""
    block = np.clip((n_blocks * (theta - THETA_LO) / THETA_SPAN).astype(np.int64), 0, n_blocks - 1)
    return block + b / b_scale


def cell_key(theta: np.ndarray, b: np.ndarray, c: np.ndarray, n_cells: int, b_scale: float) -> np.ndarray:
    """``cells`` layout key: ``(b, c)`` cell plus the fraction of the theta span (float64).
    ``b`` and ``c`` are the values stored (float32), so the cell agrees with them exactly."""
    ib = np.minimum((np.asarray(b, np.float64) / b_scale * n_cells).astype(np.int64), n_cells - 1)
    ic = np.minimum((np.asarray(c, np.float64) / b_scale * n_cells).astype(np.int64), n_cells - 1)
    frac = np.clip((theta - THETA_LO) / THETA_SPAN, 0.0, _FRAC_CLIP)  # theta < 175 deg: below 0.96
    return (ib * n_cells + ic) + frac


def bucket_starts(key: np.ndarray, n_buckets: int) -> np.ndarray:
    """``cells`` layout: where each cell (integer part of the sorted ``key``) begins,
    ``(n_buckets + 1,)`` int64, built once per opened table."""
    return np.searchsorted(key, np.arange(n_buckets + 1, dtype=np.float64)).astype(np.int64)


def paper_bucket_starts(key: np.ndarray, n_blocks: int) -> np.ndarray:
    """``paper`` layout: where each ``b`` sub-bucket of each theta block begins."""
    edges = np.arange(n_blocks * SUB_BUCKETS + 1, dtype=np.float64) / SUB_BUCKETS
    return np.searchsorted(key, edges).astype(np.int64)


@njit(cache=True, nogil=True, inline="always")
def _slice(key: np.ndarray, starts: np.ndarray, blk: int, b: float, eps: float, b_scale: float
           ) -> tuple[int, int]:
    """``paper`` layout: ``(start, count)`` of block ``blk``'s records with side ``b +- eps``,
    by binary search inside the few buckets the slice spans."""
    f_lo = (b - eps) / b_scale
    f_hi = (b + eps) / b_scale
    s_lo = min(max(int(f_lo * SUB_BUCKETS), 0), SUB_BUCKETS - 1)
    s_hi = min(max(int(f_hi * SUB_BUCKETS), 0), SUB_BUCKETS - 1)
    lo = starts[blk * SUB_BUCKETS + s_lo]
    hi = starts[blk * SUB_BUCKETS + s_hi + 1]
    part = key[lo:hi]
    start = np.searchsorted(part, blk + f_lo, side="left")
    end = np.searchsorted(part, blk + f_hi, side="right")
    return lo + start, max(end - start, 0)


@njit(cache=True, nogil=True, inline="always")
def _accept(a_obs: float, b_rec: float, c_rec: float, th_rec: float, eps: float, h_obs: float,
            star_vec: np.ndarray, i0: int, i1: int, i2: int) -> bool:
    """The longest side rebuilt from the record within ``eps`` of the observed one, and the same
    handedness."""
    a_rec = math.sqrt(max(b_rec * b_rec + c_rec * c_rec - 2 * b_rec * c_rec * math.cos(th_rec), 0.0))
    if abs(a_rec - a_obs) > eps:
        return False
    h_cat = triple_product(star_vec[i0], star_vec[i1], star_vec[i2])
    return (h_cat > 0) == (h_obs > 0)


@njit(cache=True, nogil=True, inline="always")
def _emit(rows: np.ndarray, which: np.ndarray, n_out: int, r: int, t: int, first: int, max_per_triangle: int
          ) -> tuple[int, bool]:
    """Append record ``r`` of triangle ``t``; returns the new count and whether the triangle
    has passed ``max_per_triangle`` rows (> 0), at which its scan stops."""
    rows[n_out] = r
    which[n_out] = t
    n_out += 1
    return n_out, max_per_triangle > 0 and n_out - first > max_per_triangle


@njit(cache=True, nogil=True)
def query_paper(key: np.ndarray, bucket_start: np.ndarray, c_tab: np.ndarray, th_tab: np.ndarray, ids: np.ndarray,
                star_vec: np.ndarray, obs_vec: np.ndarray, labels: np.ndarray, sides: np.ndarray,
                theta: np.ndarray, tol: np.ndarray, eps: float, n_blocks: int, b_scale: float,
                max_per_triangle: int) -> tuple[np.ndarray, np.ndarray]:
    """``paper`` layout query: the blocks covering ``theta +- tol``, the ``b +- eps`` slice of
    each, then ``c``, ``theta``, ``a`` and handedness. Returns ``(rows, which)``; a triangle with
    more than ``max_per_triangle`` rows (> 0) returns none, and its scan stops there."""
    n_tri = len(theta)
    blocks = np.empty((n_tri, 2), np.int64)
    cap = 0
    for t in range(n_tri):
        th, tl = theta[t], tol[t]
        blocks[t, 0] = min(max(int(n_blocks * (th - tl - THETA_LO) / THETA_SPAN), 0), n_blocks - 1)
        blocks[t, 1] = min(max(int(n_blocks * (th + tl - THETA_LO) / THETA_SPAN), 0), n_blocks - 1)
        if max_per_triangle > 0:
            cap += max_per_triangle + 1
        else:
            for blk in range(blocks[t, 0], blocks[t, 1] + 1):
                cap += _slice(key, bucket_start, blk, sides[t, 1], eps, b_scale)[1]
    rows = np.empty(cap, np.int64)
    which = np.empty(cap, np.int64)
    n_out = 0
    for t in range(n_tri):
        first = n_out
        a_obs, b_obs, c_obs = sides[t, 0], sides[t, 1], sides[t, 2]
        th, tl = theta[t], tol[t]
        h_obs = triple_product(obs_vec[labels[t, 0]], obs_vec[labels[t, 1]], obs_vec[labels[t, 2]])
        full = False
        for blk in range(blocks[t, 0], blocks[t, 1] + 1):
            start, count = _slice(key, bucket_start, blk, b_obs, eps, b_scale)
            for r in range(start, start + count):
                if abs(c_tab[r] - c_obs) > eps or abs(th_tab[r] - th) > tl:
                    continue
                b_rec = (key[r] - math.floor(key[r])) * b_scale
                if not _accept(a_obs, b_rec, float(c_tab[r]), float(th_tab[r]), eps, h_obs, star_vec,
                               ids[r, 0], ids[r, 1], ids[r, 2]):
                    continue
                n_out, full = _emit(rows, which, n_out, r, t, first, max_per_triangle)
                if full:
                    break
            if full:
                break
        if full:
            n_out = first
    return rows[:n_out].copy(), which[:n_out].copy()


@njit(cache=True, nogil=True, inline="always")
def _cell_range(v: float, eps: float, b_scale: float, n_cells: int) -> tuple[int, int]:
    """The cells along one side whose values may lie within ``eps`` of ``v``."""
    lo = min(max(int(math.floor((v - eps) / b_scale * n_cells - _EDGE)), 0), n_cells - 1)
    hi = min(max(int(math.floor((v + eps) / b_scale * n_cells + _EDGE)), 0), n_cells - 1)
    return lo, hi


PREFETCH_CAP_LINES = 16
"""Cache lines of one array a look-up requests ahead for one cell (a cell of the 12.5-deg table
holds ~200 records: 25 lines of keys; most cells of the 3.5-deg ones fit in 1-5)."""


@njit(cache=True, nogil=True, inline="always")
def _prefetch_span(arr: np.ndarray, lo: int, hi: int, per_line: int) -> None:
    """Request the cache lines of ``arr[lo:hi]`` (1-d; ``per_line`` items a line), at most
    :data:`PREFETCH_CAP_LINES` of them from ``lo``."""
    if hi <= lo:
        return
    i, n = lo, 0
    while i < hi and n < PREFETCH_CAP_LINES:
        prefetch(arr, np.int64(i))
        i += per_line
        n += 1
    if n < PREFETCH_CAP_LINES:
        prefetch(arr, np.int64(hi - 1))


@njit(cache=True, nogil=True)
def query_cells(key: np.ndarray, cell_start: np.ndarray, b_tab: np.ndarray, c_tab: np.ndarray, ids: np.ndarray,
                star_vec: np.ndarray, obs_vec: np.ndarray, labels: np.ndarray, sides: np.ndarray,
                theta: np.ndarray, tol: np.ndarray, eps: float, n_cells: int, b_scale: float,
                max_per_triangle: int) -> tuple[np.ndarray, np.ndarray]:
    """``cells`` layout query: the ``(b, c)`` cells covering ``b +- eps``, ``c +- eps`` (``c <=
    b``), the ``theta +- tol`` slice of each by binary search, then the exact ``b``, ``c``,
    ``theta``, ``a`` and handedness checks. Returns what :func:`query_paper` returns on the
    same records.

    The table is far larger than the caches, and each cell's reads depend on the one before
    (its start, the binary search, the slice's sides and stars), so the cells of every triangle
    are first gone through three times, each pass requesting what the next will read: the cells'
    starts, then their keys, then (after the binary search) the slices' sides and stars. Their
    misses then overlap instead of following one another; the records read, and the answer,
    are the same."""
    n_tri = len(theta)
    q_off = np.zeros(n_tri + 1, np.int64)  # triangle t's cells are q_off[t]:q_off[t + 1], in scan order
    for t in range(n_tri):  # the cells' starts requested
        ib0, ib1 = _cell_range(sides[t, 1], eps, b_scale, n_cells)
        ic0, ic1 = _cell_range(sides[t, 2], eps, b_scale, n_cells)
        n_q = 0
        for i_b in range(ib0, ib1 + 1):
            top = min(ic1, i_b)
            if top >= ic0:
                prefetch(cell_start, np.int64(i_b * n_cells + ic0))
                prefetch(cell_start, np.int64(i_b * n_cells + top + 1))
                n_q += top - ic0 + 1
        q_off[t + 1] = q_off[t] + n_q
    q_cell = np.empty(q_off[n_tri], np.int64)
    q_start = np.empty(q_off[n_tri], np.int64)  # the cell's records, then its theta slice's
    q_end = np.empty(q_off[n_tri], np.int64)
    for t in range(n_tri):  # the cells' keys requested
        ib0, ib1 = _cell_range(sides[t, 1], eps, b_scale, n_cells)
        ic0, ic1 = _cell_range(sides[t, 2], eps, b_scale, n_cells)
        q = q_off[t]
        for i_b in range(ib0, ib1 + 1):
            for i_c in range(ic0, min(ic1, i_b) + 1):
                cell = i_b * n_cells + i_c
                q_cell[q], q_start[q], q_end[q] = cell, cell_start[cell], cell_start[cell + 1]
                _prefetch_span(key, q_start[q], q_end[q], 8)
                q += 1
    ids_flat = ids.reshape(-1)
    cap = 0
    for t in range(n_tri):  # the theta slices found, their sides and stars requested
        f_lo = (theta[t] - tol[t] - THETA_LO) / THETA_SPAN - _EDGE
        f_hi = (theta[t] + tol[t] - THETA_LO) / THETA_SPAN + _EDGE
        for q in range(q_off[t], q_off[t + 1]):
            lo, hi = q_start[q], q_end[q]
            if lo < hi:
                part = key[lo:hi]
                q_start[q] = lo + np.searchsorted(part, q_cell[q] + f_lo, side="left")
                q_end[q] = lo + np.searchsorted(part, q_cell[q] + f_hi, side="right")
                _prefetch_span(b_tab, q_start[q], q_end[q], 16)
                _prefetch_span(c_tab, q_start[q], q_end[q], 16)
                _prefetch_span(ids_flat, 3 * q_start[q], 3 * q_end[q], 8)
                cap += max(q_end[q] - q_start[q], 0)
    if max_per_triangle > 0:
        cap = min(cap, n_tri * (max_per_triangle + 1))
    rows = np.empty(cap, np.int64)
    which = np.empty(cap, np.int64)
    n_out = 0
    for t in range(n_tri):
        first = n_out
        a_obs, b_obs, c_obs = sides[t, 0], sides[t, 1], sides[t, 2]
        th, tl = theta[t], tol[t]
        h_obs = triple_product(obs_vec[labels[t, 0]], obs_vec[labels[t, 1]], obs_vec[labels[t, 2]])
        full = False
        for q in range(q_off[t], q_off[t + 1]):
            cell = q_cell[q]
            for r in range(q_start[q], q_end[q]):
                if abs(b_tab[r] - b_obs) > eps or abs(c_tab[r] - c_obs) > eps:
                    continue
                th_rec = THETA_LO + (key[r] - cell) * THETA_SPAN
                if abs(th_rec - th) > tl:
                    continue
                if not _accept(a_obs, float(b_tab[r]), float(c_tab[r]), th_rec, eps, h_obs, star_vec,
                               ids[r, 0], ids[r, 1], ids[r, 2]):
                    continue
                n_out, full = _emit(rows, which, n_out, r, t, first, max_per_triangle)
                if full:
                    break
            if full:
                break
        if full:
            n_out = first
    return rows[:n_out].copy(), which[:n_out].copy()
