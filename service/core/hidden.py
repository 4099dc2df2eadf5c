"""Stars a member of a database set left out, which a camera still sees.

A member keeps the stars of its magnitude limit under a density cap, so a camera whose stars
reach that limit sees stars the member does not hold. The verifier pairs an observed star only
when no other catalogue star lies within its crowding reach, but it sees only the member's
stars: the blob of a left-out star can be paired with a held star a few pixels away. At 2 px of
centroid noise on the 15- and 20-deg cameras, 3 of the 6 wrong stars in 100,000 frames of
``bench.bench_wrong`` (session 8) were such blobs: a 5.5-6.3 Mv star the ``wide`` member left out
(its cap), named as a brighter held star 2.6-7 px away.

So each star of a member knows its nearest neighbour among the stars that some other member of
the set holds and it does not (:func:`hidden_neighbours`), and a pair whose observed star lies
within the crowding reach of that neighbour is dropped from the answer (:func:`hidden_kernel`),
as the verifier would have left it had the member held the star. Until session 22 the
neighbours came from the member holding the most stars alone (the deep ``narrow``, V <= 8), but
its own density cap leaves out brighter stars in crowded fields that ``sparse`` (V <= 7, no cap)
holds: a 6.3-Mv star that both ``wide`` and ``narrow`` left out was named as the 5.3-Mv star
3.5 px away (seed 004, 2 px, ``bench_wrong --frames 20000 --seed 2``). The neighbours now come
from every star any member holds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from .blends import RESOLVED_PX
from .geometry import chord_from_angle
from .navdb.reader import NavDatabase

REACH_MAX_DEG = 1.0
"""Hidden neighbours farther than this (degrees) are not looked for (a crowding reach of twice a
6-px match radius plus the pair's distance spans 0.35 deg at 70 "/px)."""
MERGE_DEG = 0.025
"""Neighbours nearer than this are the other half of a double that the member merged (the
default set merges doubles within 0.01-0.02 deg): one blob, not a second star."""
MAG_STEPS = (-1.5, -1.0, -0.5, 0.0, 0.5)
"""Magnitudes, relative to the member's limit, at which the nearest hidden neighbour is kept:
a frame counts only those that its faintest paired star (+ 0.5) says it could have seen."""
NONE = np.zeros((0, len(MAG_STEPS)))


def hidden_neighbours(member: NavDatabase) -> tuple[np.ndarray, np.ndarray]:
    """``(separation, limits)``: ``separation[i, k]`` is the angle (radians) from star ``i`` of
    ``member`` to its nearest neighbour of magnitude at most ``limits[k]`` among the stars the
    set's other members hold and ``member`` does not (inf where there is none within
    ``REACH_MAX_DEG``), ``limits`` = ``member``'s limit + ``MAG_STEPS``. Empty outside a set, or
    for a member that holds every star of the set; kept on ``member``."""
    cache = member.__dict__.setdefault("_cache", {})
    if "hidden" not in cache:
        together = member.__dict__.get("_set_members", ())
        limits = member.mag_limit + np.asarray(MAG_STEPS)
        cache["hidden"] = (_nearest_hidden(member, together, limits), limits)
    return cache["hidden"]


def set_stars(together: tuple[NavDatabase, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(hip, vec, mag)`` of every star some member of ``together`` holds, once each (by HIP,
    from the first member holding it); made once per set (~7 ms) and kept on its members."""
    got = together[0].__dict__.get("_set_stars")
    if got is not None and got[0] is together:
        return got[1]
    hip = np.concatenate([np.asarray(m.stars.hip) for m in together])
    vec = np.concatenate([np.asarray(m.stars.vec, np.float64) for m in together])
    mag = np.concatenate([np.asarray(m.stars.mag, np.float64) for m in together])
    _, first = np.unique(hip, return_index=True)
    first.sort()
    stars = hip[first], vec[first], mag[first]
    for m in together:
        m.__dict__["_set_stars"] = (together, stars)
    return stars


def _nearest_hidden(member: NavDatabase, together: tuple[NavDatabase, ...], limits: np.ndarray) -> np.ndarray:
    if len(together) < 2:
        return NONE
    hip, vec, mag = set_stars(together)
    held = np.isin(hip, np.asarray(member.stars.hip))
    if held.all():
        return NONE
    own = np.asarray(member.stars.vec, np.float64)
    sep = np.full((len(own), len(limits)), np.inf)
    reach = chord_from_angle(math.radians(REACH_MAX_DEG))
    for k, limit in enumerate(limits):
        hidden = np.flatnonzero(~held & (mag <= limit))
        if len(hidden) == 0:
            continue
        dist, _ = cKDTree(vec[hidden]).query(own, k=4, distance_upper_bound=reach)
        with np.errstate(invalid="ignore"):
            ang = np.where(np.isfinite(dist), 2 * np.arcsin(np.minimum(dist / 2, 1.0)), np.inf)  # none: inf
        ang[ang < math.radians(MERGE_DEG)] = np.inf
        sep[:, k] = ang.min(axis=1)
    return sep


@njit(cache=True, nogil=True)
def hidden_kernel(m_cat: np.ndarray, dist_px: np.ndarray, pair_mag: np.ndarray, hidden_sep: np.ndarray,
                  limits: np.ndarray, pixel_scale: float, reach_px: float) -> np.ndarray:
    """Mask of pairs (catalogue rows ``m_cat`` of magnitudes ``pair_mag``, observed star
    ``dist_px`` from its catalogue star) whose catalogue star has a hidden neighbour
    (:func:`hidden_neighbours`) that the frame could see (at most 0.5 mag fainter than its
    faintest pair) and that may lie within ``reach_px`` of the observed star, not blended with
    the catalogue star (``RESOLVED_PX``)."""
    bad = np.zeros(len(m_cat), np.bool_)
    if len(hidden_sep) == 0 or len(m_cat) == 0:
        return bad
    seen = pair_mag.max() + 0.5
    col = len(limits) - 1
    for k in range(len(limits)):
        if limits[k] >= seen:  # the first column holding every star as bright as ``seen``
            col = k
            break
    for k in range(len(m_cat)):
        s = hidden_sep[m_cat[k], col] / pixel_scale  # px
        d = dist_px[k] if dist_px[k] == dist_px[k] else 0.0  # NaN: the star's prediction not found
        if RESOLVED_PX < s <= reach_px + d:
            bad[k] = True
    return bad
