"""A uniform 3-D grid over catalogue star vectors, for "is there a star near here?" inside
compiled kernels.

scipy's ``cKDTree`` answers that question well from Python, but a compiled hot loop (the
verifier's screen, run for hundreds of hypotheses a frame) cannot call it. The grid cuts the
cube ``[-1, 1]^3`` into cells of side ``cell`` (unit-vector coordinates, i.e. about radians);
each occupied cell is one sorted int64 key ``(ix * K + iy) * K + iz`` with its stars stored
contiguously (CSR). A dense ``(ix, iy)`` column index points at each column's few occupied
cells (a column crosses the sphere at most twice), so a lookup is two array reads and a short
scan per touched column, without a binary search. Any query radius works: a lookup scans every
cell the query ball overlaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .types import FloatArray

DEFAULT_CELL_RAD = math.radians(0.25)
"""Cell side: 0.25 deg, about ten times the widest screen radius of a fine camera and a few
stars a cell at 8 Mv."""


@dataclass(frozen=True)
class SkyGrid:
    """Catalogue stars bucketed by 3-D cell.

    Attributes
    ----------
    cell : float
        Cell side in unit-vector coordinates (~radians).
    n_side : int
        Cells along each axis.
    keys : (C,) int64
        Sorted keys of the occupied cells.
    starts : (C + 1,) int64
        Cell ``i`` holds ``stars[starts[i]:starts[i + 1]]``.
    stars : (N,) int64
        Star rows, grouped by cell.
    columns : (n_side * n_side + 1,) int64
        Column ``ix * n_side + iy`` holds the cells ``keys[columns[c]:columns[c + 1]]``.
    vec : (N, 3) float64
        The star vectors (rows of the star table), for distance checks.
    """

    cell: float
    n_side: int
    keys: np.ndarray
    starts: np.ndarray
    stars: np.ndarray
    vec: np.ndarray
    columns: np.ndarray

    def kernel_args(self) -> tuple[float, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(cell, n_side, keys, starts, stars, columns)``: the grid as the compiled kernels
        take it (the star vectors are passed apart)."""
        return self.cell, self.n_side, self.keys, self.starts, self.stars, self.columns


def build_sky_grid(vec: FloatArray, cell_rad: float = DEFAULT_CELL_RAD) -> SkyGrid:
    """Bucket unit vectors ``vec`` ``(N, 3)`` into cells of side ``cell_rad``."""
    vec = np.ascontiguousarray(vec, dtype=np.float64)
    n_side = int(math.ceil(2.0 / cell_rad)) + 1
    cells = np.clip(np.floor((vec + 1.0) / cell_rad).astype(np.int64), 0, n_side - 1)
    key = (cells[:, 0] * n_side + cells[:, 1]) * n_side + cells[:, 2]
    order = np.argsort(key, kind="stable")
    keys, first = np.unique(key[order], return_index=True)
    starts = np.append(first, len(order)).astype(np.int64)
    columns = np.searchsorted(keys // n_side, np.arange(n_side * n_side + 1)).astype(np.int64)
    return SkyGrid(float(cell_rad), n_side, keys.astype(np.int64), starts, order.astype(np.int64), vec, columns)


@njit(cache=True, nogil=True, inline="always")
def has_star_within(px: float, py: float, pz: float, chord: float, cell: float, n_side: int,
                    keys: np.ndarray, starts: np.ndarray, stars: np.ndarray, vec: np.ndarray,
                    columns: np.ndarray, skip0: int, skip1: int, skip2: int) -> bool:
    """True if some star other than rows ``skip0..2`` lies within ``chord`` (unit-vector
    distance) of the point ``(px, py, pz)``: every cell the query ball overlaps, up to the first
    such star."""
    lo_x = max(int(math.floor((px - chord + 1.0) / cell)), 0)
    hi_x = min(int(math.floor((px + chord + 1.0) / cell)), n_side - 1)
    lo_y = max(int(math.floor((py - chord + 1.0) / cell)), 0)
    hi_y = min(int(math.floor((py + chord + 1.0) / cell)), n_side - 1)
    lo_z = max(int(math.floor((pz - chord + 1.0) / cell)), 0)
    hi_z = min(int(math.floor((pz + chord + 1.0) / cell)), n_side - 1)
    r2 = chord * chord
    for ix in range(lo_x, hi_x + 1):
        for iy in range(lo_y, hi_y + 1):
            col = ix * n_side + iy
            for pos in range(columns[col], columns[col + 1]):
                iz = keys[pos] - col * n_side
                if iz < lo_z:
                    continue
                if iz > hi_z:
                    break
                for s in range(starts[pos], starts[pos + 1]):
                    row = stars[s]
                    if row == skip0 or row == skip1 or row == skip2:
                        continue
                    dx = vec[row, 0] - px
                    dy = vec[row, 1] - py
                    dz = vec[row, 2] - pz
                    if not dx * dx + dy * dy + dz * dz > r2:
                        return True
    return False


@njit(cache=True, nogil=True, inline="always")
def ball_cells(px: float, py: float, pz: float, chord: float, cell: float, n_side: int
               ) -> tuple[int, int, int, int, int, int]:
    """The grid's cell ranges ``(lo_x, hi_x, lo_y, hi_y, lo_z, hi_z)``, inclusive, that the ball
    of radius ``chord`` about ``(px, py, pz)`` overlaps. (:func:`has_star_within`, on every proven
    frame's path, spells them out: through this tuple seed 000's proven frames took 6-8% longer,
    session 42.)"""
    return (max(int(math.floor((px - chord + 1.0) / cell)), 0), min(int(math.floor((px + chord + 1.0) / cell)), n_side - 1),
            max(int(math.floor((py - chord + 1.0) / cell)), 0), min(int(math.floor((py + chord + 1.0) / cell)), n_side - 1),
            max(int(math.floor((pz - chord + 1.0) / cell)), 0), min(int(math.floor((pz + chord + 1.0) / cell)), n_side - 1))


def stars_within(grid: SkyGrid, points: FloatArray, chord: float) -> np.ndarray:
    """Mask ``(M,)``: has each point ``(M, 3)`` a star within ``chord``? (Python entry, for
    tests and occasional use; the kernels call :func:`has_star_within` directly.)"""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return _stars_within(pts, float(chord), grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars, grid.vec,
                         grid.columns)


@njit(cache=True, nogil=True)
def _stars_within(pts: np.ndarray, chord: float, cell: float, n_side: int, keys: np.ndarray,
                  starts: np.ndarray, stars: np.ndarray, vec: np.ndarray, columns: np.ndarray) -> np.ndarray:
    out = np.zeros(len(pts), dtype=np.bool_)
    for i in range(len(pts)):
        out[i] = has_star_within(pts[i, 0], pts[i, 1], pts[i, 2], chord, cell, n_side, keys, starts,
                                 stars, vec, columns, -1, -1, -1)
    return out


@njit(cache=True, nogil=True, inline="always")
def collect_within(px: float, py: float, pz: float, chord: float, cell: float, n_side: int,
                   keys: np.ndarray, starts: np.ndarray, stars: np.ndarray, vec: np.ndarray,
                   columns: np.ndarray, out: np.ndarray) -> int:
    """Rows of the stars within ``chord`` of ``(px, py, pz)`` written to ``out`` (room for all);
    returns how many. A grid of cells about the query's size keeps the scan short."""
    lo_x = max(int(math.floor((px - chord + 1.0) / cell)), 0)
    hi_x = min(int(math.floor((px + chord + 1.0) / cell)), n_side - 1)
    lo_y = max(int(math.floor((py - chord + 1.0) / cell)), 0)
    hi_y = min(int(math.floor((py + chord + 1.0) / cell)), n_side - 1)
    lo_z = max(int(math.floor((pz - chord + 1.0) / cell)), 0)
    hi_z = min(int(math.floor((pz + chord + 1.0) / cell)), n_side - 1)
    r2 = chord * chord
    n = 0
    for ix in range(lo_x, hi_x + 1):
        for iy in range(lo_y, hi_y + 1):
            col = ix * n_side + iy
            for pos in range(columns[col], columns[col + 1]):
                iz = keys[pos] - col * n_side
                if iz < lo_z:
                    continue
                if iz > hi_z:
                    break
                for s in range(starts[pos], starts[pos + 1]):
                    row = stars[s]
                    dx = vec[row, 0] - px
                    dy = vec[row, 1] - py
                    dz = vec[row, 2] - pz
                    if dx * dx + dy * dy + dz * dz <= r2:
                        out[n] = row
                        n += 1
    return n


def fields_within(grid: SkyGrid, points: FloatArray, chords: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the stars within ``chords[c]`` (unit-vector distance) of ``points[c]`` ``(C, 3)``,
    each point's concatenated in turn, with offsets ``(C + 1,)``: one compiled call (a k-d tree's
    ball queries and the lists' conversion took ~30 us a frame in the verifier)."""
    return _fields_within(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(chords, np.float64),
                          grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars, grid.vec, grid.columns)


@njit(cache=True, nogil=True)
def _fields_within(points: np.ndarray, chords: np.ndarray, cell: float, n_side: int, keys: np.ndarray,
                   starts: np.ndarray, stars: np.ndarray, vec: np.ndarray,
                   columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fields_within`."""
    n_c = len(points)
    off = np.zeros(n_c + 1, np.int64)
    buf = np.empty(n_c * len(vec), np.int64)
    for c in range(n_c):
        n = collect_within(points[c, 0], points[c, 1], points[c, 2], chords[c], cell, n_side, keys, starts, stars,
                           vec, columns, buf[off[c]:])
        off[c + 1] = off[c] + n
    return buf[:off[n_c]].copy(), off
