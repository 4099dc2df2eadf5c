"""The verifier's screen as a compiled kernel: cheap evidence for many hypotheses at once.

A hypothesis pairs an observed star triangle with a catalogue triple. Its attitude is the
rotation between the two triangles' frames (first axis the mean direction, second towards the
first vertex: errors averaged over the three stars). Under it, the brightest other observed
stars are mapped into ICRS; each that lands within ``chord`` of a catalogue star is a *hit*.
Hypotheses are then fully verified best-first by :class:`~service.core.verify.Verifier`.
A mirror-image match (opposite handedness) can never be right and scores -1.

One loop per hypothesis in numba: no (K, m, 3) temporaries and no k-d tree round trips, so
screening hundreds of hypotheses costs microseconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .match import NEED_MAX_UNSCREENED, least_extras
from .skygrid import SkyGrid, has_star_within
from .skymask import SkyMask, may_hold_star
from .types import FloatArray, IntArray


def screen_hits(obs_vec: FloatArray, obs_tris: IntArray, cands: IntArray, others: IntArray,
                grid: SkyGrid, chord: float, mask: SkyMask) -> IntArray:
    """Hits per hypothesis ``k``: rows ``others`` (not in ``obs_tris[k]``) whose ICRS direction
    under the attitude of ``obs_tris[k] -> cands[k]`` lies within ``chord`` (unit-vector
    distance, ~radians) of a catalogue star other than the triple's own; -1 for a mirror image.

    Parameters
    ----------
    obs_vec : (N, 3) float64
        Observed unit vectors (body frame).
    obs_tris, cands : (K, 3) int
        Observed rows and the catalogue rows (of ``grid.vec``) they are hypothesised to be.
    others : (M,) int
        Observed rows to predict.
    mask : SkyMask
        The same stars' mask for a reach of at least ``chord`` (most predictions land where it
        proves no star is, and skip the grid's scan).
    """
    if mask.reach < chord:
        raise ValueError(f"the sky mask's reach {mask.reach} is below the screen's chord {chord}")
    return _screen(np.ascontiguousarray(obs_vec, dtype=np.float64),
                   np.ascontiguousarray(obs_tris, dtype=np.int64).reshape(-1, 3),
                   np.ascontiguousarray(cands, dtype=np.int64).reshape(-1, 3),
                   np.ascontiguousarray(others, dtype=np.int64), float(chord),
                   grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars, grid.vec, grid.columns, mask.n,
                   mask.words)


@njit(cache=True, nogil=True, inline="always")
def _frame(a: np.ndarray, b: np.ndarray, c: np.ndarray, out: np.ndarray) -> float:
    """Columns of ``out`` (3, 3): the triangle frame of ``a, b, c``; returns the triple
    product ``a . (b x c)`` (its sign is the handedness)."""
    frame_columns(a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2], a, out)
    return triple_product(a, b, c)


@njit(cache=True, nogil=True, inline="always")
def frame_columns(ux: float, uy: float, uz: float, w: np.ndarray, out: np.ndarray) -> None:
    """Columns of ``out`` (3, 3): ``u`` normalised, ``u x w`` normalised, and their cross
    product (a right-handed frame with its first axis along ``u``)."""
    n = math.sqrt(ux * ux + uy * uy + uz * uz)
    t1x, t1y, t1z = ux / n, uy / n, uz / n
    t2x = t1y * w[2] - t1z * w[1]
    t2y = t1z * w[0] - t1x * w[2]
    t2z = t1x * w[1] - t1y * w[0]
    n = math.sqrt(t2x * t2x + t2y * t2y + t2z * t2z)
    if n == 0.0:
        n = 1e-300
    t2x, t2y, t2z = t2x / n, t2y / n, t2z / n
    out[0, 0], out[1, 0], out[2, 0] = t1x, t1y, t1z
    out[0, 1], out[1, 1], out[2, 1] = t2x, t2y, t2z
    out[0, 2] = t1y * t2z - t1z * t2y
    out[1, 2] = t1z * t2x - t1x * t2z
    out[2, 2] = t1x * t2y - t1y * t2x


@njit(cache=True, nogil=True, inline="always")
def triple_product(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """``a . (b x c)`` of 3-vectors: its sign is a triangle's handedness."""
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))


@njit(cache=True, nogil=True)
def _screen(obs_vec: np.ndarray, obs_tris: np.ndarray, cands: np.ndarray, others: np.ndarray,
            chord: float, cell: float, n_side: int, keys: np.ndarray, starts: np.ndarray,
            stars: np.ndarray, star_vec: np.ndarray, columns: np.ndarray, mask_n: int,
            mask_words: np.ndarray) -> np.ndarray:
    k_total = len(cands)
    hits = np.zeros(k_total, dtype=np.int64)
    fo = np.empty((3, 3))
    fc = np.empty((3, 3))
    local = np.empty((len(others), 3))  # O^T v of each of ``others``, for the observed triangle at hand
    p0, p1, p2 = -1, -1, -1
    h_obs = 0.0
    for k in range(k_total):
        o0, o1, o2 = obs_tris[k, 0], obs_tris[k, 1], obs_tris[k, 2]
        c0, c1, c2 = cands[k, 0], cands[k, 1], cands[k, 2]
        if o0 != p0 or o1 != p1 or o2 != p2:  # a chunk's candidates come triangle by triangle
            h_obs = _frame(obs_vec[o0], obs_vec[o1], obs_vec[o2], fo)
            for m in range(len(others)):
                v = obs_vec[others[m]]
                local[m, 0] = fo[0, 0] * v[0] + fo[1, 0] * v[1] + fo[2, 0] * v[2]
                local[m, 1] = fo[0, 1] * v[0] + fo[1, 1] * v[1] + fo[2, 1] * v[2]
                local[m, 2] = fo[0, 2] * v[0] + fo[1, 2] * v[1] + fo[2, 2] * v[2]
            p0, p1, p2 = o0, o1, o2
        h_cat = _frame(star_vec[c0], star_vec[c1], star_vec[c2], fc)
        if (h_obs > 0) != (h_cat > 0):
            hits[k] = -1
            continue
        # v_icrs = C O^T v_obs
        count = 0
        for m in range(len(others)):
            row = others[m]
            if row == o0 or row == o1 or row == o2:
                continue
            l0, l1, l2 = local[m, 0], local[m, 1], local[m, 2]
            px = fc[0, 0] * l0 + fc[0, 1] * l1 + fc[0, 2] * l2
            py = fc[1, 0] * l0 + fc[1, 1] * l1 + fc[1, 2] * l2
            pz = fc[2, 0] * l0 + fc[2, 1] * l1 + fc[2, 2] * l2
            if not may_hold_star(px, py, pz, mask_n, mask_words):  # ~15 ns where the scan takes ~50
                continue
            if has_star_within(px, py, pz, chord, cell, n_side, keys, starts, stars, star_vec, columns, c0, c1, c2):
                count += 1
        hits[k] = count
    return hits


@njit(cache=True, nogil=True)
def hits_under(obs_vec: np.ndarray, hyp: np.ndarray, r: np.ndarray, n_screen: int, chord: float, enough: int,
               skip0: int, skip1: int, skip2: int, cell: float, n_side: int, keys: np.ndarray, starts: np.ndarray,
               stars: np.ndarray, star_vec: np.ndarray, columns: np.ndarray) -> int:
    """How many of the ``n_screen`` brightest observed stars (rows not in ``hyp``) land within
    ``chord`` of a catalogue star (not rows ``skip0..2``) under the attitude ``r`` (ICRS ->
    body), counted up to ``enough``: the screen of a hypothesis at the attitude its check starts
    from (Wahba's on its own stars), where :func:`_screen`'s triangle frame, cheaper for many
    candidates at once, puts a star far from a small triangle several match radii off."""
    hits = 0
    for m in range(n_screen):
        if _holds(hyp, m):
            continue
        if _lands(obs_vec, m, r, chord, cell, n_side, keys, starts, stars, star_vec, columns, skip0, skip1, skip2):
            hits += 1
            if hits >= enough:
                break
    return hits


@njit(cache=True, nogil=True, inline="always")
def _holds(hyp: np.ndarray, m: int) -> bool:
    """Is observed row ``m`` one of the hypothesis's rows ``hyp``?"""
    for h in hyp:
        if m == h:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _lands(obs_vec: np.ndarray, m: int, r: np.ndarray, chord: float, cell: float, n_side: int, keys: np.ndarray,
           starts: np.ndarray, stars: np.ndarray, star_vec: np.ndarray, columns: np.ndarray, skip0: int, skip1: int,
           skip2: int) -> bool:
    """Does observed row ``m`` (body), mapped to ICRS by ``r`` (ICRS -> body), lie within
    ``chord`` of a catalogue star other than rows ``skip0..2``?"""
    v = obs_vec[m]
    px = r[0, 0] * v[0] + r[1, 0] * v[1] + r[2, 0] * v[2]
    py = r[0, 1] * v[0] + r[1, 1] * v[1] + r[2, 1] * v[2]
    pz = r[0, 2] * v[0] + r[1, 2] * v[1] + r[2, 2] * v[2]
    return has_star_within(px, py, pz, chord, cell, n_side, keys, starts, stars, star_vec, columns, skip0, skip1,
                           skip2)


@njit(cache=True, nogil=True)
def could_pass_bound(obs_vec: np.ndarray, hyp: np.ndarray, r: np.ndarray, n_screened: int, chord: float,
                     radius_px: float, area_px: float, trials: int, max_false_prob: float, min_matches: int,
                     skip0: int, skip1: int, skip2: int, cell: float, n_side: int, keys: np.ndarray,
                     starts: np.ndarray, stars: np.ndarray, star_vec: np.ndarray, columns: np.ndarray) -> bool:
    """Could the check of hypothesis ``hyp`` (observed rows) at attitude ``r`` (ICRS -> body,
    Wahba's on its own stars) pass the coincidence bound after ``trials`` hypotheses, on a frame
    of more stars than :func:`~service.core.match.needed_hits` asks of (over ``n_screened +
    NEED_MAX_UNSCREENED``)? False when fewer of *all* the other observed stars land within the
    wide screen's ``chord`` of a catalogue star (not rows ``skip0..2``) than the extra pairs the
    bound needs (:func:`~service.core.match.least_extras`). True on a smaller frame (the screen
    of ``needed_hits`` covers it). Stops as soon as the answer is known.

    ``needed_hits`` asks nothing of a big frame, whose unscreened stars could supply the pairs,
    so every hypothesis with one screen hit was checked in full (its field gathered and paired,
    ~25 us on a 20-deg field): 11.7 checks per random-point frame of seed 003's camera in
    ``maxangle``'s search, 1.3 with this test (session 28; the search 20% faster there and on
    frames of 2 px with 5 false stars that reach it, the same answers on 95,904 frames of
    ``bench_wrong``'s grid). ``quad``'s kernel does not call it: its hypotheses of four stars
    rarely reach a check on such frames, and the call slowed its loop by 4-12%."""
    n_obs = len(obs_vec)
    if n_obs <= n_screened + NEED_MAX_UNSCREENED:
        return True
    pair_p = math.pi * radius_px * radius_px / max(area_px, 1.0)
    need = least_extras(n_obs - len(hyp), pair_p, trials, max_false_prob, min_matches)
    left = n_obs - len(hyp)  # stars not yet looked at
    hits = 0
    for m in range(n_obs):
        if _holds(hyp, m):
            continue
        if hits + left < need:
            return False
        left -= 1
        if _lands(obs_vec, m, r, chord, cell, n_side, keys, starts, stars, star_vec, columns, skip0, skip1, skip2):
            hits += 1
            if hits >= need:
                return True
    return hits >= need
