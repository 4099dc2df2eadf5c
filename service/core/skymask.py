"""Where on the sky a catalogue star may lie within a given reach: one bit per cell.

The verifier's screen asks, for hundreds of hypotheses a frame, whether a predicted star
direction lands within ``chord`` of a catalogue star (:func:`~.skygrid.has_star_within`). Almost
every answer is no (a random direction is near a star a few times in a thousand), and each
answer costs a scan of the sky grid's cells, ~45 ns. A :class:`SkyMask` answers most of them
with one bit: the sky is cut into the cells of a cube map (six faces of ``n x n`` cells in
gnomonic coordinates), and a cell's bit is set when some star lies within ``reach`` of a point
of the cell. A clear bit proves "no star within ``reach``"; a set one sends the direction to the
exact test. So the mask never changes an answer; it only skips scans.

Frames: ICRS unit vectors. Face ``2a + s`` looks along axis ``a`` (``s`` = 0: +, 1: -); its
gnomonic coordinates are ``(u, v) = (p[a + 1], p[a + 2]) / |p[a]|`` (axes cyclic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

MAX_CELLS = 512
"""Cells along a face's side at most: 6 x 512^2 bits (197 kB) keep the mask in cache (1024
screened seed 000's random frames no faster, at 0.8 MB)."""
MIN_CELLS = 64


@dataclass(frozen=True)
class SkyMask:
    """Cube-map cells (``n`` per face side) with a bit set where a star may lie within
    ``reach`` (unit-vector distance, ~radians) of the cell: ``words`` holds bit
    ``(face * n + i) * n + j`` as bit ``b & 63`` of word ``b >> 6``."""

    n: int
    reach: float
    words: np.ndarray


def build_sky_mask(vec: np.ndarray, reach: float, n: int | None = None) -> SkyMask:
    """The mask of the unit vectors ``vec`` ``(N, 3)`` for queries of chord up to ``reach``;
    ``n`` cells a face side (default: a cell about twice ``reach`` wide, within
    ``MIN_CELLS..MAX_CELLS``)."""
    if n is None:
        n = int(min(max(math.ceil(1.0 / max(reach, 1e-9)), MIN_CELLS), MAX_CELLS))
    angle = 2.0 * math.asin(min(reach / 2.0, 1.0))  # the chord's arc
    words = _build(np.ascontiguousarray(vec, dtype=np.float64), angle, int(n))
    return SkyMask(int(n), float(reach), words)


@njit(cache=True, nogil=True)
def _build(vec: np.ndarray, angle: float, n: int) -> np.ndarray:
    """Set the bit of every cell a point within ``angle`` (rad) of a star may fall in.

    Gnomonic coordinates stretch arcs by at most ``1 + r^2`` (``r`` the distance from the
    face's centre), so a point within ``angle`` of a star at ``r_s`` lies within
    ``angle * (1 + (r_s + 4 angle)^2)`` of it in ``u`` and in ``v`` (along the way ``r`` grows by
    at most the stretch, < 4, times ``angle``). A point on a face has at least 1/sqrt(3) of its
    length along the face's axis, so a star near it has a positive component there too."""
    words = np.zeros((6 * n * n + 63) // 64, np.uint64)
    one = np.uint64(1)
    for s in range(len(vec)):
        for a in range(3):
            b, c = (a + 1) % 3, (a + 2) % 3
            for sign in range(2):
                comp = vec[s, a] if sign == 0 else -vec[s, a]
                if comp <= 0.4:  # farther than ~30 deg from every point of this face
                    continue
                u, v = vec[s, b] / comp, vec[s, c] / comp
                r = math.sqrt(u * u + v * v)
                h = angle * (1.0 + (r + 4.0 * angle) ** 2) * (1.0 + 1e-9) + 1e-12
                if abs(u) > 1.0 + h or abs(v) > 1.0 + h:
                    continue
                i0 = max(int(math.floor((u - h + 1.0) * 0.5 * n)), 0)
                i1 = min(int(math.floor((u + h + 1.0) * 0.5 * n)), n - 1)
                j0 = max(int(math.floor((v - h + 1.0) * 0.5 * n)), 0)
                j1 = min(int(math.floor((v + h + 1.0) * 0.5 * n)), n - 1)
                face = 2 * a + sign
                for i in range(i0, i1 + 1):
                    for j in range(j0, j1 + 1):
                        bit = (face * n + i) * n + j
                        words[bit >> 6] |= one << np.uint64(bit & 63)
    return words


@njit(cache=True, nogil=True, inline="always")
def may_hold_star(px: float, py: float, pz: float, n: int, words: np.ndarray) -> bool:
    """False if no star of the mask lies within its ``reach`` of the unit vector ``(px, py, pz)``
    (True: maybe; ask :func:`~.skygrid.has_star_within`)."""
    ax, ay, az = abs(px), abs(py), abs(pz)
    if ax >= ay and ax >= az:
        face, u, v = (0 if px > 0 else 1), py / ax, pz / ax
    elif ay >= az:
        face, u, v = (2 if py > 0 else 3), pz / ay, px / ay
    else:
        face, u, v = (4 if pz > 0 else 5), px / az, py / az
    i = min(max(int((u + 1.0) * 0.5 * n), 0), n - 1)
    j = min(max(int((v + 1.0) * 0.5 * n), 0), n - 1)
    bit = (face * n + i) * n + j
    return (words[bit >> 6] >> np.uint64(bit & 63)) & np.uint64(1) != np.uint64(0)
