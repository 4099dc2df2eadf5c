"""The :class:`~service.core.types.Solution` of an identified frame: its attitude, boresight and
the named stars, built from the answer's pairs and fit (the general path and the compiled first
pass both end here)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .answer import star_mags
from .attitude import boresight_into, quaternion_into
from .navdb.reader import NavDatabase
from .types import MatchedStars, Solution, solved_solution_of
from .verify import Observation


def star_hips(db: NavDatabase) -> np.ndarray:
    """The star table's HIP numbers in memory (once per opened database; indexing the
    memory map costs more)."""
    cache = db.__dict__.setdefault("_cache", {})
    if "hip" not in cache:
        cache["hip"] = np.array(db.stars.hip, dtype=np.int64)
    return cache["hip"]


CAMERA_SHIFT = 32
"""A pair's sort key is ``camera << CAMERA_SHIFT | centroid index``."""


@njit(cache=True, nogil=True)
def answer_columns(matrix: np.ndarray, ref: np.ndarray, key: np.ndarray, cat: np.ndarray, mag: np.ndarray,
                   hip: np.ndarray, residuals_arcsec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Everything an answer reports, as two arrays (one compiled call: the first pass makes it
    inside its own, the general path from :func:`answer`).

    Pairs are ordered by ``key`` (camera, then centroid index; see ``CAMERA_SHIFT``); ``ref``
    holds their catalogue directions (ICRS, as reported) and ``cat`` their catalogue rows.
    Returns ``ints`` = centroid indices, HIPs and cameras (n each) and ``floats`` = the
    quaternion ``[w, x, y, z]`` (``w >= 0``, Shepperd's method), boresight RA, Dec and roll
    (deg, RA in [0, 360), roll from north through east), then RA, Dec (deg), magnitude and
    residual (arcsec) per star (n each; magnitude and residual rounded to 3 decimals).
    """
    n = len(key)
    order = np.argsort(key, kind="mergesort")
    ints = np.empty(3 * n, np.int64)
    floats = np.empty(7 + 4 * n)
    low = (1 << CAMERA_SHIFT) - 1
    for i in range(n):
        k = order[i]
        ints[i] = key[k] & low
        ints[n + i] = hip[cat[k]]
        ints[2 * n + i] = key[k] >> CAMERA_SHIFT
        x, y, z = ref[k, 0], ref[k, 1], ref[k, 2]
        floats[7 + i] = math.degrees(math.atan2(y, x) % (2 * math.pi))
        floats[7 + n + i] = math.degrees(math.asin(min(max(z, -1.0), 1.0)))
        floats[7 + 2 * n + i] = mag[cat[k]]
        floats[7 + 3 * n + i] = residuals_arcsec[k]
    floats[7 + 2 * n:] = np.round(floats[7 + 2 * n:], 3)
    quaternion_into(matrix, floats)
    boresight_into(matrix, floats)
    return ints, floats


def answer(obs: Observation, db: NavDatabase, obs_rows: np.ndarray, cat_rows: np.ndarray, ref: np.ndarray,
           matrix: np.ndarray, residuals_arcsec: np.ndarray, rms_arcsec: float,
           sigma_arcsec: tuple[float, float, float], false_prob: float, method: str) -> Solution:
    """The :class:`Solution` of pairs ``obs_rows`` -> ``cat_rows`` (of ``db``) fitted as
    ``matrix`` (ICRS -> body); ``ref`` the catalogue directions reported per star."""
    key = obs.index[obs_rows]
    if len(obs.cameras) > 1:
        key = key + (obs.camera[obs_rows] << CAMERA_SHIFT)
    ints, floats = answer_columns(np.ascontiguousarray(matrix, dtype=np.float64),
                                  np.ascontiguousarray(ref, dtype=np.float64), key, cat_rows, star_mags(db),
                                  star_hips(db), np.asarray(residuals_arcsec, dtype=np.float64))
    return solution_of(ints, floats, rms_arcsec, sigma_arcsec, false_prob, method)


def solution_of(ints: np.ndarray, floats: np.ndarray, rms_arcsec: float, sigma_arcsec: tuple[float, float, float],
                false_prob: float, method: str) -> Solution:
    """The :class:`Solution` of :func:`answer_columns`' arrays and the fit's figures."""
    q0, q1, q2, q3, ra, dec, roll = floats[:7].tolist()
    return solved_solution_of(method, (q0, q1, q2, q3), ra, dec, roll, MatchedStars.packed(ints, floats, 0, 0),
                              rms_arcsec, false_prob, sigma_arcsec)


__all__ = ["answer", "answer_columns", "solution_of", "star_hips"]
