"""The third stars of a rig proof's base pairs, looked up where they must lie.

:func:`~.rig_proof.cross_triples` needs, for each catalogue pair ``(I, J)``, every star ``K``
with ``I . K`` in ``[lo1, hi1]`` and ``J . K`` in ``[lo2, hi2]`` (cosines of the observed sides
and their tolerances) on the side of the plane ``(I, J)`` the observed triangle's handedness
gives. Its first version intersected two rings found by a dense product with every catalogue
star (~13 ms for ~1,000 first stars and 7,670 stars). Here each pair's region is bounded by a
ball (3-D chord) and gathered from the sky grid (:func:`~..skygrid.collect_within`):

- In the frame ``e1 = I``, ``e2`` (``J`` less its ``I`` part), ``e3 = e1 x e2``, a star is
  ``K = x e1 + y e2 + z e3`` with ``x = I . K`` and ``J . K = x cos t + y sin t`` (``t`` the angle
  ``IJ``): the region is a parallelogram ``P`` in ``(x, y)``, lifted to the sphere with ``z = s
  sqrt(1 - x^2 - y^2)``, ``s`` the handedness' sign.
- When ``P``'s four corners lie inside the unit disc, so does ``P`` (both are convex), ``z`` keeps
  its sign on it, and the region is a quadrilateral whose sides are arcs of the four small
  circles. The chord distance from the centre's lift to any point of it is at most the largest
  to a corner plus the largest sagitta of a side (``L^2 / (4 R)`` for a chord ``L`` of a circle
  of radius ``R``; the distance to a point, a linear function on the sphere, is largest on the
  region's boundary).
- A pair whose region cannot be bounded so (a corner outside the disc: the circles nearly touch,
  or a side longer than its circle's radius) makes the call fail, and the caller takes the
  dense path for it.

The caller applies the same exact tests to the candidates as before, so the triples are the
same, in the same order (by pair, then by star row).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..skygrid import collect_within


@njit(cache=True, nogil=True)
def third_star_candidates(pairs: np.ndarray, vec: np.ndarray, lo1: float, hi1: float, lo2: float, hi2: float,
                          sign: float, cell: float, n_side: int, keys: np.ndarray, starts: np.ndarray,
                          stars: np.ndarray, columns: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray]:
    """``(ok, pair, k)``: for each row ``p`` of ``pairs`` (M, 2) (catalogue rows ``I, J`` of
    ``vec``), the stars ``k`` within the ball that bounds its region (see the module), sorted,
    as parallel arrays; ``ok`` False (and nothing else meant) if some pair's region could not
    be bounded. ``sign`` (+1 or -1) is the side of the plane ``(I, J)`` the third star lies on;
    the grid arguments those of a :class:`~..skygrid.SkyGrid` over ``vec``."""
    n_p = len(pairs)
    buf = np.empty(len(vec), np.int64)
    cap = 64 + 4 * n_p
    out_p = np.empty(cap, np.int64)
    out_k = np.empty(cap, np.int64)
    cnt = 0
    xs = np.array([lo1, lo1, hi1, hi1])
    bs = np.array([lo2, hi2, lo2, hi2])
    corner = np.empty((4, 3))
    for p in range(n_p):
        a, b = pairs[p, 0], pairs[p, 1]
        c = vec[a, 0] * vec[b, 0] + vec[a, 1] * vec[b, 1] + vec[a, 2] * vec[b, 2]
        s2 = 1.0 - c * c
        if s2 < 1e-12:
            return False, out_p[:0], out_k[:0]
        s = math.sqrt(s2)
        e1 = vec[a]
        e2 = (vec[b] - c * e1) / s
        e3 = np.array([e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]])
        for q in range(4):
            x = xs[q]
            y = (bs[q] - x * c) / s
            r2 = 1.0 - x * x - y * y
            if r2 <= 1e-12:
                return False, out_p[:0], out_k[:0]
            z = sign * math.sqrt(r2)
            for d in range(3):
                corner[q, d] = x * e1[d] + y * e2[d] + z * e3[d]
        x0 = 0.5 * (lo1 + hi1)
        y0 = (0.5 * (lo2 + hi2) - x0 * c) / s
        z0 = sign * math.sqrt(max(1.0 - x0 * x0 - y0 * y0, 0.0))
        centre = x0 * e1 + y0 * e2 + z0 * e3
        reach = 0.0
        for q in range(4):
            reach = max(reach, math.sqrt(np.sum((corner[q] - centre) ** 2)))
        # the sides: x = lo1 (corners 0-1), x = hi1 (2-3), J.K = lo2 (0-2), J.K = hi2 (1-3)
        sag = 0.0
        for q0, q1, cosine in ((0, 1, lo1), (2, 3, hi1), (0, 2, lo2), (1, 3, hi2)):
            radius2 = 1.0 - cosine * cosine
            length2 = np.sum((corner[q0] - corner[q1]) ** 2)
            if radius2 <= 0.0 or length2 > radius2:
                return False, out_p[:0], out_k[:0]
            sag = max(sag, length2 / (4.0 * math.sqrt(radius2)))
        chord = reach + sag + 1e-9
        n = collect_within(centre[0], centre[1], centre[2], chord, cell, n_side, keys, starts, stars, vec,
                           columns, buf)
        if n == 0:
            continue
        found = np.sort(buf[:n])
        if cnt + n > cap:
            cap = 2 * (cnt + n)
            grown_p = np.empty(cap, np.int64)
            grown_k = np.empty(cap, np.int64)
            grown_p[:cnt] = out_p[:cnt]
            grown_k[:cnt] = out_k[:cnt]
            out_p, out_k = grown_p, grown_k
        out_p[cnt:cnt + n] = p
        out_k[cnt:cnt + n] = found
        cnt += n
    return True, out_p[:cnt], out_k[:cnt]


__all__ = ["third_star_candidates"]
