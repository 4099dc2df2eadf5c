"""The answer's columns (service.core.solution.answer_columns): the compiled attitude and star
figures equal the Python ones they replace."""

import math

import numpy as np
import pytest

from service.core.attitude import (
    matrix_from_radec_roll,
    matrix_to_quat,
    quat_to_matrix,
    radec_roll,
    random_rotations,
)
from service.core.solution import CAMERA_SHIFT, answer_columns, solution_of


def test_quaternion_and_boresight_of_the_matrix() -> None:
    """The quaternion is the one the matrix was made from (w >= 0; the four branches of
    Shepperd's method), and RA, Dec and roll give the matrix back."""
    rng = np.random.default_rng(8)
    qs = np.vstack([random_rotations(500, rng), np.eye(4)])
    ref = np.array([[1.0, 0.0, 0.0]])
    for q in qs:
        r = quat_to_matrix(q)
        _, floats = answer_columns(r, ref, np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1),
                                   np.zeros(1, np.int64), np.zeros(1))
        np.testing.assert_allclose(floats[:4], q, atol=1e-12)
        ra, dec, roll = floats[4:7]
        assert 0 <= ra < 360 and -90 <= dec <= 90 and 0 <= roll < 360
        np.testing.assert_allclose(matrix_from_radec_roll(ra, dec, roll), r, atol=1e-9)
        assert radec_roll(r) == tuple(floats[4:7].tolist()) and matrix_to_quat(r).tolist() == floats[:4].tolist()


def test_stars_by_camera_then_centroid_with_their_catalogue_figures() -> None:
    vec = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.6, 0.0, 0.8]])
    mag = np.array([1.23456, 2.0, 3.0, 4.00049])
    hip = np.array([10, 20, 30, 40])
    cat = np.array([3, 0, 2, 1])
    key = np.array([(1 << CAMERA_SHIFT) + 2, 7, 3, (1 << CAMERA_SHIFT) + 0])  # (camera, centroid)
    res = np.array([0.12345, 1.0, 2.0, 3.0])
    ints, floats = answer_columns(np.eye(3), vec[cat], key, cat, mag, hip, res)
    sol = solution_of(ints, floats, 1.5, (1.0, 2.0, 3.0), 1e-9, "quad")
    assert [(s.camera, s.centroid, s.hip) for s in sol.stars] == [(0, 3, 30), (0, 7, 10), (1, 0, 20), (1, 2, 40)]
    by_hip = {s.hip: s for s in sol.stars}
    assert by_hip[10].mag == 1.235 and by_hip[40].mag == 4.0 and by_hip[40].residual_arcsec == 0.123
    assert (by_hip[20].ra_deg, by_hip[20].dec_deg) == (90.0, 0.0)
    assert (by_hip[30].ra_deg, by_hip[30].dec_deg) == (180.0, 0.0)
    assert by_hip[40].dec_deg == pytest.approx(math.degrees(math.asin(0.8)))
    assert sol.quaternion == (1.0, 0.0, 0.0, 0.0) and (sol.ra_deg, sol.dec_deg) == (0.0, 90.0)
