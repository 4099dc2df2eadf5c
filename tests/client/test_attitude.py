"""Pure-Python quaternion math: conventions checked against the engine's numpy version."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from client import attitude_error
from client._attitude import quat_conj, quat_mul, quat_normalize, quat_rotate, quat_to_matrix
from service.core.attitude import quat_to_matrix as engine_quat_to_matrix

ARCSEC = math.pi / 180 / 3600
unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(lambda q: sum(c * c for c in q) > 0.01)


def axis_angle(axis: tuple[float, float, float], angle_rad: float) -> tuple[float, float, float, float]:
    n = math.sqrt(sum(a * a for a in axis))
    s = math.sin(angle_rad / 2) / n
    return (math.cos(angle_rad / 2), axis[0] * s, axis[1] * s, axis[2] * s)


@given(unit)
def test_matrix_matches_engine(q: tuple[float, ...]) -> None:
    qn = quat_normalize(q)
    np.testing.assert_allclose(quat_to_matrix(qn), engine_quat_to_matrix(np.array(qn)), atol=1e-12)


@given(unit, unit)
def test_product_composes_rotations(a: tuple[float, ...], b: tuple[float, ...]) -> None:
    a, b = quat_normalize(a), quat_normalize(b)
    lhs = np.array(quat_to_matrix(quat_mul(a, b)))
    np.testing.assert_allclose(lhs, np.array(quat_to_matrix(a)) @ np.array(quat_to_matrix(b)), atol=1e-12)


@given(unit, st.tuples(*[st.floats(-10, 10, allow_nan=False)] * 3))
def test_rotate_is_matrix_times_vector(q: tuple[float, ...], v: tuple[float, float, float]) -> None:
    q = quat_normalize(q)
    np.testing.assert_allclose(quat_rotate(q, v), np.array(quat_to_matrix(q)) @ np.array(v), atol=1e-9)


@given(unit)
def test_no_error_against_itself_or_its_negative(q: tuple[float, ...]) -> None:
    e = attitude_error(q, q)
    assert e.total_arcsec < 1e-3
    e = attitude_error([-c for c in q], q)
    assert e.cross_boresight_arcsec < 1e-3 and abs(e.roll_arcsec) < 1e-3


@pytest.mark.parametrize("arcsec", [1.0, 60.0, 3600.0, -500.0])
def test_pure_roll_is_roll(arcsec: float) -> None:
    truth = quat_normalize((0.3, -0.2, 0.8, 0.4))
    solved = quat_mul(axis_angle((0, 0, 1), arcsec * ARCSEC), truth)  # R_err = R_z
    e = attitude_error(solved, truth)
    assert e.roll_arcsec == pytest.approx(arcsec, abs=1e-6)
    assert e.cross_boresight_arcsec < 1e-6


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (1, 1, 0)])
def test_pure_tilt_is_cross_boresight(axis: tuple[float, float, float]) -> None:
    truth = quat_normalize((0.1, 0.7, -0.1, 0.7))
    solved = quat_mul(axis_angle(axis, 30 * ARCSEC), truth)
    e = attitude_error(solved, truth)
    assert e.cross_boresight_arcsec == pytest.approx(30.0, abs=1e-6)
    assert abs(e.roll_arcsec) < 1e-6


def test_error_is_in_the_camera_frame() -> None:
    """A tilt applied in ICRS (right multiplication) shows as whatever it is in the camera."""
    truth = axis_angle((1, 0, 0), math.pi / 2)  # camera z = ICRS -y... any non-trivial attitude
    icrs_rot = axis_angle((0, 1, 0), 10 * ARCSEC)
    solved = quat_mul(truth, icrs_rot)  # R_s = R_t R_icrs -> R_err = R_t R_icrs R_t^T
    e = attitude_error(solved, truth)
    cam_axis = quat_rotate(truth, (0, 1, 0))
    assert e.total_arcsec == pytest.approx(10.0, abs=1e-6)
    assert abs(cam_axis[2]) == pytest.approx(1.0)  # the ICRS y axis is the boresight here: pure roll
    assert abs(e.roll_arcsec) == pytest.approx(10.0, abs=1e-6)


@given(unit, unit)
def test_components_bounded_by_total(a: tuple[float, ...], b: tuple[float, ...]) -> None:
    e = attitude_error(a, b)
    assert e.cross_boresight_arcsec <= e.total_arcsec + 1e-6
    assert abs(e.roll_arcsec) <= 180 * 3600 + 1e-6
    assert quat_conj(quat_conj(a)) == tuple(a)
