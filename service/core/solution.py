"""The :class:`~service.core.types.Solution` of an identified frame: its attitude, boresight and
the named stars, built from the answer's pairs and fit (the general path and the compiled first
pass both end here)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .answer import star_mags
from .attitude import matrix_to_quat, radec_roll
from .navdb.reader import NavDatabase
from .types import MatchedStars, Solution, SolveStatus
from .verify import Observation

def _zeros_list(n: int, _zeros: list[int] = [0] * 256) -> list[int]:  # noqa: B006 (read only)
    return _zeros[:n] if n <= len(_zeros) else [0] * n


def _hips(db: NavDatabase) -> np.ndarray:
    """The star table's HIP numbers in memory (once per opened database; indexing the
    memory map costs more)."""
    cache = db.__dict__.setdefault("_cache", {})
    if "hip" not in cache:
        cache["hip"] = np.array(db.stars.hip)
    return cache["hip"]


@njit(cache=True, nogil=True)
def _star_columns(ref: np.ndarray, order: np.ndarray, mag: np.ndarray, cat: np.ndarray,
                  residuals_arcsec: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """RA and Dec (deg) of the catalogue directions ``ref[order]``, the stars' magnitudes and
    the residuals (arcsec, ``residuals_arcsec[order]``), rounded as the answer reports them."""
    n = len(order)
    ra = np.empty(n)
    dec = np.empty(n)
    res = np.empty(n)
    for i in range(n):
        v = ref[order[i]]
        ra[i] = math.degrees(math.atan2(v[1], v[0]) % (2 * math.pi))
        dec[i] = math.degrees(math.asin(min(max(v[2], -1.0), 1.0)))
        res[i] = residuals_arcsec[order[i]]
    return ra, dec, np.round(mag[cat], 3), np.round(res, 3)


def answer(obs: Observation, db: NavDatabase, obs_rows: np.ndarray, cat_rows: np.ndarray, ref: np.ndarray,
           matrix: np.ndarray, residuals_arcsec: np.ndarray, rms_arcsec: float,
           sigma_arcsec: tuple[float, float, float], false_prob: float, method: str) -> Solution:
    """The :class:`Solution` of pairs ``obs_rows`` -> ``cat_rows`` (of ``db``) fitted as
    ``matrix`` (ICRS -> body); ``ref`` the catalogue directions reported per star."""
    ra, dec, roll = radec_roll(matrix)
    index = obs.index[obs_rows]
    if len(obs.cameras) == 1:
        order = index.argsort(kind="stable")
        camera = _zeros_list(len(order))
    else:
        cam_rows = obs.camera[obs_rows]
        order = np.lexsort((index, cam_rows))
        camera = cam_rows[order].tolist()
    cat = cat_rows[order]
    star_ra, star_dec, star_mag, star_res = _star_columns(ref, order, star_mags(db), cat, residuals_arcsec)
    stars = MatchedStars(index[order], _hips(db)[cat], star_ra, star_dec, star_mag, star_res, camera)  # by camera,
    # then by centroid index; made tuples when first read
    q = matrix_to_quat(matrix)
    return Solution(
        SolveStatus.SOLVED,
        method,
        quaternion=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        ra_deg=ra,
        dec_deg=dec,
        roll_deg=roll,
        stars=stars,
        rms_arcsec=rms_arcsec,
        false_match_probability=false_prob,
        attitude_sigma_arcsec=sigma_arcsec,
    )


__all__ = ["answer"]
