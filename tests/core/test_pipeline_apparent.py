"""The frame's epoch and the observer's velocity are applied before the final attitude fit:
a frame rendered from the stars' apparent places (proper motion to 2045, aberration by a
low-orbit observer on the Earth's orbit) gives the true inertial attitude only with them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from service.core.apparent import apparent_directions
from service.core.attitude import quat_to_matrix, random_rotations
from service.core.pipeline import DEFAULT_OPTIONS, solve
from service.core.types import Centroids
from tests.conftest import SEED000_CAMERA

VELOCITY = np.array([-12.0, 26.5, 11.4])  # km/s, ICRS: ~29.8 km/s + a 7.6 km/s orbit's worth below


def _frame(db, q: np.ndarray, epoch: float, velocity: np.ndarray | None, rng) -> Centroids:
    """Centroids of the database's stars at their apparent places, 0.02 px noise, no false stars."""
    dt = epoch - db.epoch
    seen = apparent_directions(np.asarray(db.stars.vec), pm_mas_yr=np.asarray(db.stars.pm), dt_years=dt,
                               velocity_km_s=velocity)
    v_cam = seen @ quat_to_matrix(q).T
    front = v_cam[:, 2] > 0.9
    xy, ok = SEED000_CAMERA.vector_to_pixel(v_cam[front])
    inside = ok & SEED000_CAMERA.contains(xy)
    mag = np.asarray(db.stars.mag)[front][inside]
    xy = xy[inside] + rng.normal(0, 0.02, size=(int(inside.sum()), 2))
    return Centroids(np.ascontiguousarray(xy), 10 ** (-0.4 * mag.astype(np.float64)))


def _boresight_error_arcsec(q_est, q_true) -> float:
    """Angle between the estimated and true boresights (roll is loose in a narrow field)."""
    z_est = quat_to_matrix(np.asarray(q_est, dtype=float))[2]
    z_true = quat_to_matrix(np.asarray(q_true, dtype=float))[2]
    return float(np.degrees(np.arccos(np.clip(z_est @ z_true, -1, 1))) * 3600)


@pytest.fixture(scope="module")
def attitudes() -> np.ndarray:
    rng = np.random.default_rng(11)
    return random_rotations(30, rng)


def test_epoch_and_aberration_give_the_inertial_attitude(seed000_db, attitudes) -> None:
    rng = np.random.default_rng(5)
    epoch = seed000_db.epoch + 19.0
    with_both = dataclasses.replace(DEFAULT_OPTIONS, centroid_sigma_px=0.5, epoch=epoch,
                                    observer_velocity_km_s=tuple(VELOCITY))
    plain = dataclasses.replace(DEFAULT_OPTIONS, centroid_sigma_px=0.5)
    err_plain, err_applied, n = [], [], 0
    for q in attitudes:
        cents = _frame(seed000_db, q, epoch, VELOCITY, rng)
        if len(cents) < 8:
            continue
        a = solve(cents, SEED000_CAMERA, seed000_db, options=with_both)
        b = solve(cents, SEED000_CAMERA, seed000_db, options=plain)
        if not (a.solved and b.solved):
            continue
        n += 1
        err_applied.append(_boresight_error_arcsec(a.quaternion, q))
        err_plain.append(_boresight_error_arcsec(b.quaternion, q))
    assert n >= 20
    # aberration by ~30 km/s moves the field by up to ~20" (and proper motion over 19 years adds
    # a little): ignored, it is the pointing error
    assert np.median(err_plain) > 8.0, np.median(err_plain)
    # applied, what is left is the centroid noise (0.02 px of 30"/px, averaged over the stars)
    assert np.max(err_applied) < 1.0, np.max(err_applied)


def test_epoch_moves_the_reported_stars(seed000_db, attitudes) -> None:
    """The stars' ra/dec are reported at the frame's epoch (proper motion applied)."""
    rng = np.random.default_rng(6)
    q = attitudes[0]
    epoch = seed000_db.epoch + 30.0
    cents = _frame(seed000_db, q, epoch, None, rng)
    opts = dataclasses.replace(DEFAULT_OPTIONS, centroid_sigma_px=0.5, epoch=epoch)
    sol = solve(cents, SEED000_CAMERA, seed000_db, options=opts)
    assert sol.solved
    hip = np.asarray(seed000_db.stars.hip)
    pm = np.asarray(seed000_db.stars.pm)
    for star in sol.stars:
        row = int(np.flatnonzero(hip == star.hip)[0])
        moved = apparent_directions(np.asarray(seed000_db.stars.vec[row:row + 1]), pm_mas_yr=pm[row:row + 1],
                                    dt_years=30.0)[0]
        ra = np.degrees(np.arctan2(moved[1], moved[0])) % 360
        dec = np.degrees(np.arcsin(moved[2]))
        assert star.ra_deg == pytest.approx(ra, abs=1e-7)
        assert star.dec_deg == pytest.approx(dec, abs=1e-7)
    assert _boresight_error_arcsec(sol.quaternion, q) < 1.0
