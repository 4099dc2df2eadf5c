"""Apparent star directions: proper motion to a frame's epoch and stellar aberration.

The navigation database stores ICRS unit vectors at its build epoch. A camera sees each star
where it is at the frame's epoch, displaced by the aberration of light due to the observer's
velocity (up to ~20 arcsec for the Earth's orbital motion, plus ~5 arcsec for a low orbit).
Fitting the attitude to the *apparent* catalogue directions makes the quaternion the true
inertial attitude of the camera.

All vectors are ICRS (BCRS axes), unit length, shape ``(N, 3)``; velocities are km/s in the
same axes; proper motions are mas/yr with ``pmra`` = mu_alpha* (already times cos(dec)).
"""

from __future__ import annotations

import numpy as np

from .geometry import normalize

C_KM_S = 299_792.458
"""Speed of light, km/s."""
MAS_TO_RAD = np.pi / (180.0 * 3600.0 * 1000.0)


def local_east_north(vec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors toward increasing RA (east) and Dec (north) at each direction ``(N, 3)``.

    At the celestial poles east is taken along +y, north along -x.
    """
    v = np.atleast_2d(np.asarray(vec, dtype=np.float64))
    east = np.stack([-v[:, 1], v[:, 0], np.zeros(len(v))], axis=1)
    norm = np.linalg.norm(east, axis=1)
    polar = norm < 1e-12
    east[polar] = (0.0, 1.0, 0.0)
    east /= np.where(polar, 1.0, norm)[:, None]
    north = np.cross(v, east)
    return east, north


def apply_proper_motion(
    vec: np.ndarray, pmra_mas_yr: np.ndarray, pmdec_mas_yr: np.ndarray, dt_years: float
) -> np.ndarray:
    """Directions ``(N, 3)`` moved by proper motion over ``dt_years`` (decimal years).

    The star moves on a straight line in space at constant velocity with no radial velocity:
    ``u(t) = normalize(u + mu t)`` with ``mu`` the angular-velocity vector on the tangent plane,
    which is what astropy's ``apply_space_motion`` gives for a distant star.
    """
    v = np.atleast_2d(np.asarray(vec, dtype=np.float64))
    if dt_years == 0.0:
        return v.copy()
    east, north = local_east_north(v)
    pmra = np.asarray(pmra_mas_yr, dtype=np.float64)[:, None]
    pmdec = np.asarray(pmdec_mas_yr, dtype=np.float64)[:, None]
    motion = (pmra * east + pmdec * north) * (MAS_TO_RAD * float(dt_years))
    return normalize(v + motion)


def aberrate(vec: np.ndarray, velocity_km_s: np.ndarray) -> np.ndarray:
    """Apparent directions ``(N, 3)`` of stars at ``vec`` seen by an observer moving at
    ``velocity_km_s`` (3,), ICRS axes, km/s: special-relativistic aberration.

    ``u' = (u / gamma + beta + (u . beta) beta / (1 + 1 / gamma)) / (1 + u . beta)``
    with ``beta = v / c`` (the form erfa's ``ab`` evaluates, less its solar-potential term of
    order 1e-8 rad).
    """
    v = np.atleast_2d(np.asarray(vec, dtype=np.float64))
    beta = np.asarray(velocity_km_s, dtype=np.float64).reshape(3) / C_KM_S
    b2 = float(beta @ beta)
    if b2 == 0.0:
        return v.copy()
    if b2 >= 1.0:
        raise ValueError("observer speed must be below the speed of light")
    inv_gamma = np.sqrt(1.0 - b2)
    ub = v @ beta
    out = (v * inv_gamma + beta[None, :] + (ub / (1.0 + inv_gamma))[:, None] * beta[None, :]) / (1.0 + ub)[:, None]
    return normalize(out)


def apparent_directions(
    vec: np.ndarray,
    *,
    pm_mas_yr: np.ndarray | None = None,
    dt_years: float = 0.0,
    velocity_km_s: np.ndarray | None = None,
) -> np.ndarray:
    """Catalogue directions ``(N, 3)`` as the camera sees them.

    Parameters
    ----------
    vec : (N, 3)
        ICRS unit vectors at the catalogue's epoch.
    pm_mas_yr : (N, 2), optional
        Proper motions ``(mu_alpha*, mu_delta)``, mas/yr; ignored when ``dt_years`` is 0.
    dt_years : float
        Frame epoch minus catalogue epoch, decimal years.
    velocity_km_s : (3,), optional
        Observer's velocity relative to the solar-system barycentre, ICRS axes, km/s.
    """
    out = np.atleast_2d(np.asarray(vec, dtype=np.float64))
    if pm_mas_yr is not None and dt_years != 0.0:
        pm = np.asarray(pm_mas_yr, dtype=np.float64).reshape(-1, 2)
        out = apply_proper_motion(out, pm[:, 0], pm[:, 1], dt_years)
    if velocity_km_s is not None:
        out = aberrate(out, velocity_km_s)
    return out
