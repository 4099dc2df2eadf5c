"""Apparent directions against astropy: proper motion (apply_space_motion) and aberration
(the ICRS -> GCRS transform, which applies the Earth's aberration and light deflection)."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.apparent import aberrate, apparent_directions, apply_proper_motion
from service.core.catalog import HIPPARCOS_EPOCH, load_hipparcos
from service.core.geometry import angle_between, radec_to_vector

ARCSEC = np.pi / 180 / 3600

astropy_units = pytest.importorskip("astropy.units")
coordinates = pytest.importorskip("astropy.coordinates")
Time = pytest.importorskip("astropy.time").Time


def _vec_from_skycoord(c) -> np.ndarray:
    return radec_to_vector(np.asarray(c.ra.rad), np.asarray(c.dec.rad))


@pytest.fixture(scope="module")
def fast_movers():
    """Real Hipparcos stars with the largest proper motions (up to ~10 arcsec/yr) and a spread."""
    cat = load_hipparcos()
    pm = np.hypot(cat.pmra_mas_yr, cat.pmdec_mas_yr)
    ok = np.isfinite(pm)
    idx = np.flatnonzero(ok)
    order = idx[np.argsort(pm[idx])[::-1]]
    pick = np.concatenate([order[:20], order[1000:1020], order[50000:50020]])
    return cat, pick


def test_proper_motion_matches_astropy_space_motion(fast_movers):
    cat, pick = fast_movers
    u = astropy_units
    t0 = Time(HIPPARCOS_EPOCH, format="jyear", scale="tdb")
    sc = coordinates.SkyCoord(
        ra=cat.ra_rad[pick] * u.rad,
        dec=cat.dec_rad[pick] * u.rad,
        pm_ra_cosdec=cat.pmra_mas_yr[pick] * u.mas / u.yr,
        pm_dec=cat.pmdec_mas_yr[pick] * u.mas / u.yr,
        distance=10 * u.pc,  # with no radial velocity the direction follows the tangential motion
        radial_velocity=0 * u.km / u.s,
        obstime=t0,
        frame="icrs",
    )
    for epoch in (2000.0, 2026.9, 2040.0):
        want = _vec_from_skycoord(sc.apply_space_motion(new_obstime=Time(epoch, format="jyear", scale="tdb")))
        got = apply_proper_motion(
            radec_to_vector(cat.ra_rad[pick], cat.dec_rad[pick]),
            cat.pmra_mas_yr[pick],
            cat.pmdec_mas_yr[pick],
            epoch - HIPPARCOS_EPOCH,
        )
        err = angle_between(got, want) / ARCSEC
        assert err.max() < 0.1, (epoch, err.max())
        # and the motion is real: the fastest movers shift by minutes of arc
        moved = angle_between(got, radec_to_vector(cat.ra_rad[pick], cat.dec_rad[pick])) / ARCSEC
        assert moved.max() > 60.0


def test_aberration_matches_astropy_gcrs():
    """Stars >= 45 deg from the Sun, so the Sun's light deflection (< 0.01") stays below the
    tolerance; the observer velocity is the Earth's barycentric velocity from astropy."""
    u = astropy_units
    rng = np.random.default_rng(3)
    t = Time("2026-11-24T12:00:00", scale="tdb")
    sun = coordinates.get_body_barycentric("sun", t).xyz.to_value(u.au)
    earth_pos, earth_vel = coordinates.get_body_barycentric_posvel("earth", t)
    to_sun = sun - earth_pos.xyz.to_value(u.au)
    to_sun /= np.linalg.norm(to_sun)
    v_kms = earth_vel.xyz.to_value(u.km / u.s)

    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dirs = dirs[dirs @ to_sun < np.cos(np.radians(45))][:100]
    ra = np.arctan2(dirs[:, 1], dirs[:, 0])
    dec = np.arcsin(dirs[:, 2])
    sc = coordinates.SkyCoord(ra=ra * u.rad, dec=dec * u.rad, frame="icrs")
    # GCRS at the geocentre (obsgeoloc 0): aberration by the Earth's barycentric velocity
    want = _vec_from_skycoord(sc.transform_to(coordinates.GCRS(obstime=t)))
    got = aberrate(dirs, v_kms)
    err = angle_between(got, want) / ARCSEC
    assert err.max() < 0.1, err.max()
    shift = angle_between(got, dirs) / ARCSEC
    assert 5.0 < shift.max() < 21.0  # the effect is real: up to ~20.5"


def test_aberration_is_along_velocity_and_zero_velocity_is_identity():
    v = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    out = aberrate(v, np.array([0.0, 30.0, 0.0]))
    # a star at 90 deg from the apex moves toward it by ~ v/c rad (20.6")
    assert angle_between(out[0], v[0]) / ARCSEC == pytest.approx(30.0 / 299792.458 / ARCSEC, rel=1e-6)
    assert out[0, 1] > 0
    assert angle_between(out[1], v[1]) < 1e-12  # the apex itself does not move
    np.testing.assert_allclose(apparent_directions(v), v)
    with pytest.raises(ValueError):
        aberrate(v, np.array([3e5, 0.0, 0.0]))
